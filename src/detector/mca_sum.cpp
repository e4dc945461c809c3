#include "detector/mca_sum.hpp"

#include <algorithm>
#include <cstdint>

namespace beamctl::detector {

McaSum::McaSum(std::vector<McaDevice*> elements, std::string name) : elements_(std::move(elements)), name_(std::move(name)) {}

bool McaSum::setup(const Setup& s) {
    bool ok = true;
    for (McaDevice* e : elements_) ok = e->setup(s) && ok;
    return ok;
}

bool McaSum::start() {
    bool ok = true;
    for (McaDevice* e : elements_) ok = e->start() && ok;
    return ok;
}

bool McaSum::stop() {
    bool ok = true;
    for (McaDevice* e : elements_) ok = e->stop() && ok;
    return ok;
}

bool McaSum::erase() {
    bool ok = true;
    for (McaDevice* e : elements_) ok = e->erase() && ok;
    return ok;
}

bool McaSum::status(Status& s) {
    s = Status{};
    if (elements_.empty()) return false;
    int64_t total = 0;
    double live = 0;
    for (McaDevice* e : elements_) {
        Status st;
        if (!e->status(st)) return false;
        s.real = std::max(s.real, st.real);
        live += st.live;
        total += st.total;
        s.acquiring = s.acquiring || st.acquiring;
        s.dwell = st.dwell;
    }
    s.live = live / double(elements_.size());
    s.total = int32_t(std::min<int64_t>(total, INT32_MAX));
    return true;
}

uint32_t McaSum::read(int32_t* data, uint32_t n) {
    sum_.assign(n, 0);
    part_.resize(n);
    uint32_t got = 0;
    for (McaDevice* e : elements_) {
        const uint32_t m = e->read(part_.data(), n);
        for (uint32_t i = 0; i < m; ++i) sum_[i] += part_[i];
        got = std::max(got, m);
    }
    for (uint32_t i = 0; i < got; ++i) data[i] = int32_t(std::min<int64_t>(sum_[i], INT32_MAX));
    return got;
}

std::string McaSum::describe() const { return name_ + ": the sum of " + std::to_string(elements_.size()) + " elements"; }

} // namespace beamctl::detector
