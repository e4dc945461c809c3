#include "ethercat/sim/segment.hpp"

#include "ethercat/sii.hpp"

namespace beamctl::ethercat::sim {

Esc& Segment::add(const DeviceDesc& desc) {
    descs_.push_back(std::make_unique<DeviceDesc>(desc));
    const DeviceDesc& d = *descs_.back();
    slaves_.push_back(Slot{std::make_unique<Esc>(d, build_sii(d)), &d, true});
    slaves_.back().esc->set_local_time(time_ns_);
    slaves_.back().esc->set_hop_delay(kHopDelayNs * (slaves_.size() - 1));
    return *slaves_.back().esc;
}

void Segment::set_time(uint64_t ns) noexcept {
    time_ns_ = ns;
    for (auto& s : slaves_) s.esc->set_local_time(ns);
}

void Segment::unplug(std::size_t position) { slaves_.at(position).plugged = false; }

void Segment::replug(std::size_t position) {
    Slot& s = slaves_.at(position);
    s.esc = std::make_unique<Esc>(*s.desc, build_sii(*s.desc));
    s.esc->set_local_time(time_ns_);
    s.esc->set_hop_delay(kHopDelayNs * position);
    s.plugged = true;
}

void Segment::set_frame_loss(double fraction, uint64_t seed) {
    loss_ = fraction;
    loss_rng_.seed(seed);
}

void Segment::set_frame_corruption(double fraction, uint64_t seed) {
    corrupt_ = fraction;
    corrupt_rng_.seed(seed);
}

bool Segment::process(uint8_t* frame, std::size_t len) noexcept {
    ++frames;
    if (loss_ > 0 && std::uniform_real_distribution<double>(0, 1)(loss_rng_) < loss_) {
        ++frames_lost;
        return false;
    }
    for_each_datagram(frame, len, [&](Datagram& d) {
        for (auto& s : slaves_)
            if (s.plugged) s.esc->process(d);
    });
    for (auto& s : slaves_)
        if (s.plugged) s.esc->run_firmware();
    if (corrupt_ > 0 && len >= 2 &&
        std::uniform_real_distribution<double>(0, 1)(corrupt_rng_) < corrupt_) {
        ++frames_corrupted;
        frame[1] ^= 0x50; // breaks the header type and length
    }
    if (on_frame) on_frame(*this);
    return true;
}

} // namespace beamctl::ethercat::sim
