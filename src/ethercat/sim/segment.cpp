#include "ethercat/sim/segment.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>

#include "ethercat/sii.hpp"

namespace beamctl::ethercat::sim {

void Segment::add_configured(const std::vector<std::pair<int, std::string>>& slaves, const Catalog& catalog) {
    int last = -1;
    for (const auto& [pos, type] : slaves) last = std::max(last, pos);
    for (int p = 0; p <= last; ++p) {
        std::string type = "EK1100";
        for (const auto& [pos, t] : slaves)
            if (pos == p) type = t;
        const DeviceDesc* d = catalog.find(type);
        if (!d) throw Error(SB() << "position " << p << ": " << catalog.unknown_type_error(type));
        add(*d);
    }
}

Esc& Segment::add(const DeviceDesc& desc) {
    descs_.push_back(std::make_unique<DeviceDesc>(desc));
    const DeviceDesc& d = *descs_.back();
    slaves_.push_back(Slot{std::make_unique<Esc>(d, build_sii(d)), &d, true});
    slaves_.back().esc->set_local_time(local_ns_);
    slaves_.back().esc->set_hop_delay(kHopDelayNs * (slaves_.size() - 1));
    return *slaves_.back().esc;
}

void Segment::set_time(uint64_t ns) noexcept {
    time_ns_ = ns;
    if (!clock_t0_) clock_t0_ = ns;
    const double since = double(int64_t(ns - clock_t0_));
    local_ns_ = uint64_t(int64_t(ns) + clock_offset_ns_ + steer_ns_ + int64_t(std::llround(since * drift_ppm_ * 1e-6)));
    for (auto& s : slaves_) s.esc->set_local_time(local_ns_);
}

uint64_t Segment::dc_system_time() noexcept {
    for (auto& s : slaves_)
        if (s.plugged && s.desc->dc_assign_activate) return s.esc->system_time();
    return local_ns_;
}

void Segment::unplug(std::size_t position) { slaves_.at(position).plugged = false; }

void Segment::replug(std::size_t position) {
    Slot& s = slaves_.at(position);
    s.esc = std::make_unique<Esc>(*s.desc, build_sii(*s.desc));
    s.esc->set_local_time(local_ns_);
    s.esc->set_hop_delay(kHopDelayNs * position);
    s.plugged = true;
}

void Segment::replace(std::size_t position, const DeviceDesc& desc) {
    Slot& s = slaves_.at(position);
    replaced_.push_back(std::make_unique<DeviceDesc>(desc));
    s.desc = replaced_.back().get();
    replug(position);
}

bool Segment::apply(const Fault& f) {
    ++faults_applied;
    std::size_t k = std::size_t(f.position);
    switch (f.kind) {
    case Fault::Kind::PowerOff: unplug(k); return true;
    case Fault::Kind::PowerOn:
        if (!plugged(k)) replug(k);
        return true;
    case Fault::Kind::BreakAfter: break_after_ = f.position; return true;
    case Fault::Kind::Repair: break_after_ = -1; return true;
    case Fault::Kind::Loss: set_frame_loss(f.fraction); return true;
    case Fault::Kind::Corrupt: set_frame_corruption(f.fraction); return true;
    case Fault::Kind::Delay: set_answer_delay_us(uint32_t(f.fraction * 1000.0 + 0.5)); return true;
    case Fault::Kind::RefuseState: slave(k).refuse_state(f.state, f.al_code); return true;
    case Fault::Kind::RefuseSdo:
        if (slave(k).coe()) slave(k).coe()->refuse_download(f.index, f.sub, f.abort);
        return true;
    case Fault::Kind::Replace: replace(k, *f.desc); return true;
    case Fault::Kind::Clear:
        for (std::size_t i = 0; i < slaves_.size(); ++i) {
            if (!plugged(i)) replug(i);
            slave(i).refuse_state(0, 0);
            if (slave(i).coe()) slave(i).coe()->refuse_download(0, 0, 0);
        }
        break_after_ = -1;
        answer_delay_us_ = 0;
        set_frame_loss(0);
        set_frame_corruption(0);
        return true;
    case Fault::Kind::Glitch:
    case Fault::Kind::DriveFault: return on_plant_fault && on_plant_fault(f);
    }
    return false;
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
    for (Fault f; faults_.pop(f);) {
        try {
            apply(f);
        } catch (...) { // a fault that cannot be applied changes nothing
        }
    }
    if (loss_ > 0 && std::uniform_real_distribution<double>(0, 1)(loss_rng_) < loss_) {
        ++frames_lost;
        return false;
    }
    // Slaves up to a break (the frame turns back there), each one powered in the line.
    std::size_t reach = break_after_ < 0 ? slaves_.size() : std::min(slaves_.size(), std::size_t(break_after_) + 1);
    for_each_datagram(frame, len, [&](Datagram& d) {
        for (std::size_t i = 0; i < reach; ++i)
            if (slaves_[i].plugged) slaves_[i].esc->process(d);
    });
    for (std::size_t i = 0; i < reach; ++i)
        if (slaves_[i].plugged) slaves_[i].esc->run_firmware();
    if (corrupt_ > 0 && len >= 2 &&
        std::uniform_real_distribution<double>(0, 1)(corrupt_rng_) < corrupt_) {
        ++frames_corrupted;
        frame[1] ^= 0x50; // breaks the header type and length
    }
    // The master wrote a time into the reference clock: the segment's clock follows it.
    for (std::size_t i = 0; i < slaves_.size(); ++i) {
        if (!slaves_[i].plugged || !slaves_[i].desc->dc_assign_activate) continue;
        Esc& ref = *slaves_[i].esc;
        if (ref_seen_ != int(i)) { // a new reference (or a replugged one): count from here
            ref_seen_ = int(i);
            ref_writes_seen_ = ref.system_time_writes;
        } else if (ref.system_time_writes != ref_writes_seen_) {
            ref_writes_seen_ = ref.system_time_writes;
            const int64_t pull = std::clamp<int64_t>(ref.system_time_diff_ns, -kMaxSteerNs, kMaxSteerNs);
            steer_ns_ += pull;
            local_ns_ = uint64_t(int64_t(local_ns_) + pull);
            for (auto& s : slaves_) s.esc->set_local_time(local_ns_);
        }
        break;
    }
    if (on_frame) on_frame(*this);
    return true;
}

} // namespace beamctl::ethercat::sim
