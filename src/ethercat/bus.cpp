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
        if (c.cycle == 0) return; // nothing in flight yet
        int timeout_us = int(c.period_ns / 2000); // half a period at most
        b.last_ = b.master_->receive_process_data(timeout_us);
    }
};

struct Bus::SendStage : rt::Stage {
    Bus& b;
    explicit SendStage(Bus& bus) : b(bus) {}
    const char* name() const noexcept override { return "bus send"; }
    void run(const rt::CycleInfo& c) noexcept override {
        (void)c;
        b.master_->send_process_data();
    }
};

struct Bus::PublishStage : rt::Stage {
    Bus& b;
    explicit PublishStage(Bus& bus) : b(bus) {}
    const char* name() const noexcept override { return "publish"; }
    void run(const rt::CycleInfo& c) noexcept override {
        BusSnapshot& s = b.snap_.write_buffer();
        Master& m = *b.master_;
        std::memcpy(s.image.data(), m.image(), s.image.size());
        s.cycle = c.cycle;
        s.wkc = m.wkc();
        s.expected_wkc = m.expected_wkc();
        s.frames_lost = m.frames_lost();
        s.frames_late = m.frames_late();
        s.wkc_errors = m.wkc_errors();
        s.link_up = b.last_ != CycleStatus::FrameLost && b.last_ != CycleStatus::LinkError;
        s.wkc_ok = b.last_ == CycleStatus::Ok;
        s.responding = m.responding();
        for (std::size_t i = 0; i < s.slave_al.size(); ++i) {
            s.slave_al[i] = m.slave_al_status(i);
            s.slave_online[i] = m.slave_online(i) && s.link_up;
            s.slave_valid[i] = m.slave_valid(i);
        }
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

Bus::Bus(int id, std::unique_ptr<Link> link, std::vector<SlaveConfig> slaves, const Catalog& catalog)
    : id_(id), link_(std::move(link)) {
    master_ = std::make_unique<Master>(*link_, id, std::move(slaves), catalog);
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
    watch_last_.push_back(registry::image_read(master_->image(), s.bit_offset, s.bits));
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
    master_->start_cycling();
    health_stop_ = false;
    health_ = std::thread([this, period_s] {
        // A pass every period, and at once (within 10 ms) when the cycle shows a slave lost or
        // the number of slaves answering changed (a slave plugged in or powered up).
        while (!health_stop_.load()) {
            master_->check_and_recover();
            for (double t = 0; t < period_s && !health_stop_.load() && !master_->health_due(); t += 0.01)
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    });
}

void Bus::stop_health() {
    health_stop_ = true;
    if (health_.joinable()) health_.join();
}

void Bus::bring_up() {
    master_->bring_up();
    std::size_t n = master_->image_size(), k = master_->slaves().size();
    snap_.init([n, k](BusSnapshot& s) {
        s.image.assign(n, 0);
        s.slave_al.assign(k, 0);
        s.slave_online.assign(k, 0);
        s.slave_valid.assign(k, 0);
    });
}

void Bus::add_stages(rt::Engine& e) {
    master_->set_cycle_time_ns(e.period_ns());
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
    uint8_t* img = master_->image();
    while (writes_.pop(w)) registry::image_write(img, w.bit_offset, w.bits, w.value);
}

const BusSnapshot& Bus::snapshot() noexcept {
    snap_.update();
    return snap_.read_buffer();
}

uint64_t Bus::get(const std::vector<uint8_t>& image, const SignalInfo& s) noexcept {
    return registry::image_read(image.data(), s.bit_offset, s.bits);
}

} // namespace beamctl::ethercat
