#include "ethercat/bus.hpp"

#include <chrono>
#include <cstring>
#include <sys/eventfd.h>
#include <unistd.h>

namespace beamctl::ethercat {

struct Bus::ReceiveStage : rt::Stage {
    Bus& b;
    explicit ReceiveStage(Bus& bus) : b(bus) {}
    const char* name() const noexcept override { return "bus receive"; }
    void run(const rt::CycleInfo& c) noexcept override {
        b.last_ = b.backend_->receive(c);
        if (b.follow_int_) b.steer();
    }
};

struct Bus::SendStage : rt::Stage {
    Bus& b;
    explicit SendStage(Bus& bus) : b(bus) {}
    const char* name() const noexcept override { return "bus send"; }
    void run(const rt::CycleInfo& c) noexcept override {
        b.backend_->send(c);
    }
};

struct Bus::PublishStage : rt::Stage {
    Bus& b;
    explicit PublishStage(Bus& bus) : b(bus) {}
    const char* name() const noexcept override { return "publish"; }
    void run(const rt::CycleInfo& c) noexcept override {
        BusSnapshot& s = b.snap_.write_buffer();
        BusBackend& m = *b.backend_;
        std::memcpy(s.image.data(), m.image(), s.image.size());
        s.cycle = c.cycle;
        m.fill(s, b.last_);
        const std::size_t nw = b.watch_offset_.size();
        bool changed = detect_changes(m.image(), b.watch_offset_.data(), b.watch_bits_.data(), b.watch_last_.data(),
                                      b.watch_changes_.data(), nw);
        if (nw) std::memcpy(s.changes.data(), b.watch_changes_.data(), nw * sizeof(uint32_t));
        b.snap_.publish();
        // Wake the IOC loop once per drain: a non-blocking eventfd write, only when it is not
        // already awake for an earlier change.
        if (changed && b.change_fd_ >= 0 && !b.change_pending_.exchange(true, std::memory_order_acq_rel)) {
            uint64_t one = 1;
            (void)!::write(b.change_fd_, &one, sizeof one);
        }
        b.apply_writes(); // for the next cycle's send
    }
};

bool detect_changes(const uint8_t* img, const uint32_t* bit_offset, const uint8_t* bits, uint64_t* last,
                    uint32_t* changes, std::size_t n) noexcept {
    bool changed = false;
    for (std::size_t i = 0; i < n; ++i) {
        uint32_t off = bit_offset[i];
        uint64_t v = bits[i] == 1 ? uint64_t(img[off >> 3] >> (off & 7) & 1) : registry::image_read(img, off, bits[i]);
        if (v != last[i]) {
            last[i] = v;
            ++changes[i];
            changed = true;
        }
    }
    return changed;
}

LocalBackend::LocalBackend(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog)
    : link_(std::move(link)) {
    master_ = std::make_unique<Master>(*link_, id, std::move(slaves), catalog);
}

CycleStatus LocalBackend::receive(const rt::CycleInfo& c) noexcept {
    if (c.cycle == 0) return CycleStatus::Ok; // nothing in flight yet
    int timeout_us = int(c.period_ns / 2000); // half a period at most
    return master_->receive_process_data(timeout_us);
}

void LocalBackend::send(const rt::CycleInfo&) noexcept { master_->send_process_data(); }

void LocalBackend::fill(BusSnapshot& s, CycleStatus last) noexcept {
    Master& m = *master_;
    s.wkc = m.wkc();
    s.expected_wkc = m.expected_wkc();
    s.frames_lost = m.frames_lost();
    s.frames_late = m.frames_late();
    s.wkc_errors = m.wkc_errors();
    s.link_up = last != CycleStatus::FrameLost && last != CycleStatus::LinkError;
    s.wkc_ok = last == CycleStatus::Ok;
    s.responding = m.responding();
    for (std::size_t i = 0; i < s.slave_al.size(); ++i) {
        s.slave_al[i] = m.slave_al_status(i);
        s.slave_online[i] = m.slave_online(i) && s.link_up;
        s.slave_valid[i] = m.slave_valid(i);
    }
}

std::vector<uint8_t> LocalBackend::sdo_read(int position, uint16_t index, uint8_t sub) {
    return master_->sdo_upload(position, index, sub);
}

void LocalBackend::sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) {
    master_->sdo_download(position, index, sub, data.data(), data.size());
}

Bus::Bus(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog)
    : Bus(id, std::make_unique<LocalBackend>(id, std::move(link), std::move(slaves), catalog)) {}

Bus::Bus(int id, std::unique_ptr<BusBackend> backend) : id_(id), backend_(std::move(backend)) {
    receive_ = std::make_unique<ReceiveStage>(*this);
    send_ = std::make_unique<SendStage>(*this);
    publish_ = std::make_unique<PublishStage>(*this);
    change_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
}

Bus::~Bus() {
    stop_health();
    if (change_fd_ >= 0) ::close(change_fd_);
}

int Bus::watch(const SignalInfo& s) {
    if (watches_frozen_) return -1;
    for (std::size_t i = 0; i < watch_offset_.size(); ++i)
        if (watch_offset_[i] == s.bit_offset && watch_bits_[i] == s.bits) return int(i);
    watch_offset_.push_back(s.bit_offset);
    watch_bits_.push_back(s.bits);
    watch_last_.push_back(registry::image_read(backend_->image(), s.bit_offset, s.bits));
    watch_changes_.push_back(0);
    std::size_t n = watch_offset_.size();
    snap_.init([n](BusSnapshot& b) { b.changes.assign(n, 0); });
    return int(n - 1);
}

void Bus::drain_changes() noexcept {
    uint64_t v = 0;
    while (::read(change_fd_, &v, sizeof v) > 0) {
    }
    change_pending_.store(false, std::memory_order_release);
}

void Bus::start_health(double period_s) {
    if (health_.joinable()) return;
    backend_->start_cycling();
    health_stop_ = false;
    health_ = std::thread([this, period_s] {
        // A pass every period, and at once (within 10 ms) when the cycle shows a slave lost or
        // the number of slaves answering changed (a slave plugged in or powered up).
        while (!health_stop_.load()) {
            backend_->health_pass();
            for (double t = 0; t < period_s && !health_stop_.load() && !backend_->health_due(); t += 0.01)
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    });
}

void Bus::stop_health() {
    health_stop_ = true;
    if (health_.joinable()) health_.join();
}

void Bus::follow_dc(const std::string& slave_prefix) {
    if (!backend_->set_dc_steering(true))
        throw Error(SB() << "ec" << id_ << ": a bus behind a scanner cannot steer its distributed clock (the scanner runs it)");
    follow_ = slave_prefix;
}

// RT (receive stage): a new pair of the EL6692's time stamps, the other side connected: the skew.
void Bus::steer() noexcept {
    const uint8_t* img = backend_->image();
    if (follow_nc_ && registry::image_read(img, follow_nc_->bit_offset, follow_nc_->bits)) return;
    const uint64_t in = registry::image_read(img, follow_int_->bit_offset, follow_int_->bits);
    if (in == 0 || in == follow_seen_) return;
    follow_seen_ = in;
    backend_->steer_dc(int64_t(registry::image_read(img, follow_ext_->bit_offset, follow_ext_->bits) - in));
}

void Bus::bring_up() {
    backend_->bring_up();
    if (!follow_.empty()) {
        follow_int_ = backend_->find_signal(follow_ + "internalTimestamp01");
        follow_ext_ = backend_->find_signal(follow_ + "externalTimestamp01");
        follow_nc_ = backend_->find_signal(follow_ + "externalDeviceNotConnected01");
        if (!follow_int_ || !follow_ext_)
            throw Error(SB() << follow_.substr(0, follow_.size() - 1) << ": dc_follow needs the EL6692's time stamps: assign "
                             << "0x1A02 (startup SDOs 0x1C13 = {0x1A00, 0x1A02}, docs/ethercat.md)");
    }
    std::size_t n = backend_->image_size(), k = backend_->slaves().size();
    snap_.init([n, k](BusSnapshot& s) {
        s.image.assign(n, 0);
        s.slave_al.assign(k, 0);
        s.slave_online.assign(k, 0);
        s.slave_valid.assign(k, 0);
    });
}

void Bus::add_stages(rt::Engine& e) {
    backend_->set_cycle_time_ns(e.period_ns());
    if (rt::TickSource* t = backend_->tick_source()) e.set_tick_source(t, backend_->tick_grace_ns());
    e.add_stage(rt::StageOrder::BusReceive, *receive_);
    e.add_stage(rt::StageOrder::BusSend, *send_);
    e.add_stage(rt::StageOrder::Publish, *publish_);
}

bool Bus::write(const SignalInfo& s, uint64_t value) noexcept {
    if (!s.output) return false;
    if (writes_.push(OutputWrite{s.bit_offset, s.bits, value})) return true;
    writes_dropped_++;
    return false;
}

void Bus::apply_writes() noexcept {
    OutputWrite w;
    uint8_t* img = backend_->image();
    while (writes_.pop(w)) registry::image_write(img, w.bit_offset, w.bits, w.value);
}

const BusSnapshot& Bus::snapshot() noexcept {
    snap_.update();
    return snap_.read_buffer();
}

registry::BoundSignal Bus::bind(std::string_view name, int bit) {
    const SignalInfo* s = backend_->find_signal(name);
    if (!s || (bit >= 0 && bit >= s->bits)) return {};
    return registry::BoundSignal{backend_->image(), s->bit_offset, s->bits, s->is_signed, bit};
}

Master& Bus::master() {
    Master* m = backend_->local_master();
    if (!m) throw Error(SB() << "ec" << id_ << ": the bus is run by a scanner, not by this process");
    return *m;
}

uint64_t Bus::get(const std::vector<uint8_t>& image, const SignalInfo& s) noexcept {
    return registry::image_read(image.data(), s.bit_offset, s.bits);
}

} // namespace beamctl::ethercat
