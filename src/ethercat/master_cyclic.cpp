// EtherCAT master, the cyclic path (RT thread): LRW frames, send, receive, working counters,
// per-slave status bytes and validity words.
#include "ethercat/master.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/coe.hpp"
#include "ethercat/master_internal.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <cstring>
#include <iomanip>
#include <map>
#include <sstream>
#include <thread>

namespace beamctl::ethercat {
using namespace master_detail;
namespace {
log::Logger lg("ethercat.master");
} // namespace

void Master::build_cyclic_frames() {
    // One LRW per chunk of the image; chunks packed into as few frames as fit.
    cyclic_.clear();
    expected_wkc_ = 0;
    uint32_t off = 0, total = bus_bytes_;
    cyclic_.emplace_back();
    while (off < total) {
        CyclicFrame* cf = &cyclic_.back();
        std::size_t room = cf->frame.room();
        if (room < 16) {
            cyclic_.emplace_back();
            cf = &cyclic_.back();
            room = cf->frame.room();
        }
        uint32_t len = uint32_t(std::min<std::size_t>(room, total - off));
        int at = cf->frame.add(kLrw, 0, off, uint16_t(len)); // index set per cycle when sent
        cf->parts.push_back({uint32_t(at), off, len});
        off += len;
    }
    if (cyclic_.back().parts.empty()) cyclic_.pop_back();
    // What each slave adds to the working counter when it takes part: per LRW datagram, +2 if its
    // outputs overlap it, +1 if its inputs or its status byte do.
    contrib_.assign(slaves_.size(), 0);
    for (auto& cf : cyclic_)
        for (auto& p : cf.parts)
            for (std::size_t i = 0; i < slaves_.size(); ++i) {
                const SlaveInfo& s = slaves_[i];
                auto overlaps = [&](uint32_t o, uint32_t n) { return n && o < p.image_offset + p.len && o + n > p.image_offset; };
                uint16_t c = 0;
                if (overlaps(s.out_offset, s.out_bytes)) c += 2;
                if (overlaps(s.in_offset, s.in_bytes) || overlaps(status_bytes_ + uint32_t(i), 1)) c += 1;
                contrib_[i] = uint16_t(contrib_[i] + c);
                expected_wkc_ = uint16_t(expected_wkc_ + c);
            }
    // One BRD of AL status (0x0130) per cycle: its working counter is the number of slaves
    // answering, configured or not; a change tells the health pass to look.
    count_frame_ = -1;
    if (cyclic_.empty() || cyclic_.back().frame.room() < 2) cyclic_.emplace_back();
    {
        int at = cyclic_.back().frame.add(kBrd, 0, 0, kAlStatus, 2);
        count_frame_ = int(cyclic_.size() - 1);
        count_offset_ = uint32_t(at);
    }
    // The reference clock's time travels with the cycle (FRMW 0x0910): read at the reference,
    // written to every later slave, which compares it with its own system time.
    dc_frame_ = -1;
    steer_frame_ = -1;
    if (dc_ref_ >= 0 && dc_steer_) { // the time written into the reference (set_dc_steering)
        if (cyclic_.empty() || cyclic_.back().frame.room() < 8 + 8 + kDatagramOverhead) cyclic_.emplace_back(); // with the FRMW after it
        int at = cyclic_.back().frame.add(kNop, 0, slaves_[std::size_t(dc_ref_)].station, 0x0910, 8);
        steer_frame_ = int(cyclic_.size() - 1);
        steer_offset_ = uint32_t(at);
    }
    if (dc_ref_ >= 0) {
        if (cyclic_.empty() || cyclic_.back().frame.room() < 8) cyclic_.emplace_back();
        int at = cyclic_.back().frame.add(kFrmw, 0, slaves_[std::size_t(dc_ref_)].station, 0x0910, 8);
        dc_frame_ = int(cyclic_.size() - 1);
        dc_offset_ = uint32_t(at);
    }
    if (cyclic_.size() > kMaxCyclicFrames)
        throw Error(SB() << "ec" << bus_ << ": process image of " << image_.size() << " bytes needs more than "
                         << kMaxCyclicFrames << " frames per cycle");
    std::size_t n = slaves_.size();
    slave_al_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    slave_online_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    valid_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    admit_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    for (std::size_t i = 0; i < n; ++i) {
        slave_al_[i] = 0;
        slave_online_[i] = 0;
        valid_[i] = 0;
        admit_[i] = 0;
    }
    last_stat_.assign(n, 0xFF); // never a status byte: the first cycle walks
    last_consistent_ = -1;
}

void Master::set_admitted(std::size_t i, bool yes) {
    admit_[i].store(yes, std::memory_order_relaxed);
    admit_gen_.fetch_add(1, std::memory_order_release);
}

CycleStatus Master::send_process_data() noexcept {
    CycleStatus st = CycleStatus::Ok;
    seq_ = uint8_t((seq_ + 1) & 0x0F);
    for (std::size_t fi = 0; fi < cyclic_.size(); ++fi) {
        auto& cf = cyclic_[fi];
        uint8_t* f = cf.frame.data();
        uint8_t tag = uint8_t(seq_ << 3 | fi);
        for_each_datagram(f, cf.frame.size(), [&](Datagram& d) { d.hdr[1] = tag; });
        for (auto& p : cf.parts) {
            // The image as it is: outputs, and inputs as last received (a slave absent from this
            // cycle passes them back unchanged: its inputs keep their last values). Status bytes
            // are sent as 0: only a slave that takes part fills its own.
            std::memcpy(f + p.data_offset, image_.data() + p.image_offset, p.len);
            uint32_t st_lo = std::max(p.image_offset, status_bytes_), st_hi = std::min(p.image_offset + p.len, bus_bytes_);
            if (st_lo < st_hi) std::memset(f + p.data_offset + (st_lo - p.image_offset), 0, st_hi - st_lo);
            put_le16(f + p.data_offset + p.len, 0); // WKC
        }
        if (count_frame_ >= 0 && &cf == &cyclic_[std::size_t(count_frame_)]) std::memset(f + count_offset_, 0, 4);
        if (dc_frame_ >= 0 && &cf == &cyclic_[std::size_t(dc_frame_)]) std::memset(f + dc_offset_, 0, 10);
        if (steer_frame_ >= 0 && &cf == &cyclic_[std::size_t(steer_frame_)]) {
            const uint64_t last = dc_time_.load(std::memory_order_relaxed);
            const bool steer = steer_now_ && last != 0;
            f[steer_offset_ - (kDatagramOverhead - 2)] = steer ? kFpwr : kNop;
            put_le64(f + steer_offset_, steer ? last + cycle_ns_ + uint64_t(std::llround(double(steer_skew_ns_) * kDcSteerGain)) : 0);
            put_le16(f + steer_offset_ + 8, 0);
            steer_now_ = false;
        }
        if (!link_.send(f, cf.frame.size())) st = CycleStatus::LinkError;
    }
    send_ok_.store(st == CycleStatus::Ok, std::memory_order_relaxed);
    if (!acyc_in_flight_ && acyc_req_.pop(acyc_cur_)) {
        acyc_frame_.reset();
        int at = acyc_frame_.add(acyc_cur_.cmd, kAcyclicIdx, acyc_cur_.addr, acyc_cur_.len, acyc_cur_.data);
        if (at >= 0 && link_.send(acyc_frame_.data(), acyc_frame_.size())) {
            acyc_in_flight_ = true;
        } else {
            AcyclicReply r;
            r.wkc = -1;
            acyc_rep_.push(r);
        }
    }
    return st;
}

CycleStatus Master::receive_process_data(int timeout_us) noexcept {
    CycleStatus st = CycleStatus::Ok;
    uint32_t wkc = 0;
    std::size_t got = 0;
    std::size_t expect = cyclic_.size() + (acyc_in_flight_ ? 1 : 0);
    for (std::size_t k = 0, guard = 0; k < expect && guard < expect + 16; ++k, ++guard) {
        std::size_t n = link_.receive(rx_.data(), rx_.size(), timeout_us);
        if (n == 0) {
            if (got < cyclic_.size()) {
                bump(frames_lost_, cyclic_.size() - got);
                st = CycleStatus::FrameLost;
            }
            break;
        }
        // A frame of an earlier cycle that came back after its time-out: too old, drop it.
        if (n >= 2 + kDatagramOverhead) {
            uint8_t idx = rx_[3];
            if (idx != kAcyclicIdx && (idx >> 3 & 0x0F) != seq_) {
                frames_late_++;
                --k;
                continue;
            }
        }
        bool ok = for_each_datagram(rx_.data(), n, [&](Datagram& d) {
            if (d.cmd() == kBrd && d.ado() == kAlStatus && d.len() == 2) {
                responding_.store(d.wkc(), std::memory_order_relaxed);
                return;
            }
            if (d.cmd() == kFrmw && d.ado() == 0x0910 && d.len() == 8) {
                if (d.wkc()) dc_time_.store(le64(d.data), std::memory_order_relaxed);
                return;
            }
            if (d.idx() == kAcyclicIdx && acyc_in_flight_) {
                AcyclicReply r;
                r.wkc = d.wkc();
                std::memcpy(r.data, d.data, std::min<std::size_t>(d.len(), kMaxAcyclic));
                acyc_rep_.push(r);
                acyc_in_flight_ = false;
                return;
            }
            if (d.cmd() != kLrw || (d.idx() & 7) >= cyclic_.size()) return;
            const CyclicFrame& cf = cyclic_[d.idx() & 7];
            for (auto& p : cf.parts) {
                if (d.logical() != p.image_offset || d.len() != p.len) continue;
                wkc += d.wkc();
                // Inputs into the image (never overwrite outputs).
                uint32_t from = std::max(p.image_offset, outputs_bytes_);
                if (from < p.image_offset + p.len)
                    std::memcpy(image_.data() + from, d.data + (from - p.image_offset),
                                p.image_offset + p.len - from);
            }
        });
        if (!ok) {
            bump(frames_lost_, 1);
            st = CycleStatus::FrameLost;
        }
        ++got;
    }
    if (acyc_in_flight_) { // its frame did not come back: the requester retries
        AcyclicReply r;
        r.wkc = -1;
        acyc_rep_.push(r);
        acyc_in_flight_ = false;
    }
    wkc_.store(uint16_t(wkc), std::memory_order_relaxed);
    frames_back_.store(st == CycleStatus::Ok, std::memory_order_relaxed);
    // Which slaves took part (status byte != 0: its status FMMU answered), and the working counter
    // they give: those admitted and in OP must all count (lo); a slave present but not (yet) trusted
    // - joining, in SAFEOP after an error - may or may not count (hi).
    bool consistent = false;
    const uint8_t* stat = image_.data() + status_bytes_;
    const std::size_t n = slaves_.size();
    if (st == CycleStatus::Ok) {
        // The per-slave walk only when a status byte or an admission changed (rare): otherwise
        // the sums of the last walk hold.
        uint32_t gen = admit_gen_.load(std::memory_order_acquire);
        bool changed = gen != admit_seen_ || std::memcmp(stat, last_stat_.data(), n) != 0;
        if (changed) {
            admit_seen_ = gen;
            std::memcpy(last_stat_.data(), stat, n);
            uint32_t lo = 0, extra = 0;
            for (std::size_t i = 0; i < n; ++i) {
                uint8_t b = stat[i];
                slave_online_[i].store(b != 0, std::memory_order_relaxed);
                if (b == 0) continue;
                slave_al_[i].store(b, std::memory_order_relaxed);
                if ((b & 0x1F) == 8 && admit_[i].load(std::memory_order_relaxed)) lo += contrib_[i];
                else extra += contrib_[i];
            }
            wkc_lo_ = lo;
            wkc_hi_ = lo + extra;
        }
        consistent = wkc >= wkc_lo_ && wkc <= wkc_hi_;
        if (!consistent) {
            bump(wkc_errors_, 1);
            st = CycleStatus::WkcMismatch;
        }
        if (!changed && consistent == (last_consistent_ == 1)) {
            cycle_ok_.store(consistent, std::memory_order_relaxed);
            return st; // valid flags, masterstatus as they are
        }
    }
    last_consistent_ = consistent ? 1 : 0;
    cycle_ok_.store(consistent, std::memory_order_relaxed);
    for (std::size_t i = 0; i < n; ++i) {
        uint32_t v = consistent && (stat[i] & 0x1F) == 8 && admit_[i].load(std::memory_order_relaxed) ? 1 : 0;
        valid_[i].store(uint8_t(v), std::memory_order_relaxed);
        std::memcpy(image_.data() + valid_offset_ + 12 * i + 8, &v, 4);
    }
    uint32_t ok = consistent ? 1 : 0;
    std::memcpy(image_.data() + masterstatus_offset_, &ok, 4); // little-endian host, as the bus part
    return st;
}

// ---- CoE -------------------------------------------------------------------------------------


} // namespace beamctl::ethercat
