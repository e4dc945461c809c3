// EtherCAT master, distributed clocks: delays, offsets, SYNC0/SYNC1.
#include "ethercat/master.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/coe.hpp"
#include "ethercat/master_internal.hpp"

#include <algorithm>
#include <chrono>
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


namespace {
uint64_t master_time_ns() { // [ns] since the EtherCAT epoch 2000-01-01, from the system clock
    auto t = std::chrono::system_clock::now().time_since_epoch();
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(t).count()) - 946684800ull * 1000000000ull;
}
} // namespace

bool master_detail::uses_dc_time(const SiiInfo& sii) {
    // A DC opmode, or process data mapped onto the ESC's DC registers (0x0900-0x09FF: an EL1252's
    // latch times, an EL2252's start time): its system time must be the bus's (IgH writes the
    // offset of every DC-capable slave for this reason; SYNC0 only for those with an opmode).
    if (sii.dc_assign_activate) return true;
    for (const SyncManagerDesc& sm : sii.sms)
        if (sm.start >= 0x0900 && sm.start < 0x0A00) return true;
    return false;
}

void Master::configure_dc(const std::vector<std::size_t>& which) {
    // Minimal distributed clocks (ethercat.md §4): the reference is the first configured slave with
    // DC (its cyclic FRMW 0x0910 is in the frame even while it is absent); each DC slave present
    // gets its delay, offset and SYNC0 in configure_dc_slave().
    dc_ref_ = -1;
    int n = 0;
    for (std::size_t i = 0; i < slaves_.size(); ++i)
        if (slaves_[i].sii.dc_assign_activate) {
            if (dc_ref_ < 0) dc_ref_ = int(i);
            n += std::count(which.begin(), which.end(), i) ? 1 : 0;
        }
    // One latch and one master timestamp for all of them, delays from the first present.
    std::vector<std::size_t> dc;
    for (std::size_t i : which)
        if (uses_dc_time(slaves_[i].sii)) dc.push_back(i);
    if (!dc.empty()) {
        uint32_t latch = 0;
        if (transact(kBwr, 0, 0x0900, &latch, 4) < 1) throw Error(SB() << "ec" << bus_ << ": DC receive-time latch got no answer");
        uint64_t master_ns = master_time_ns();
        uint8_t rr[4] = {};
        if (transact(kFprd, slaves_[dc.front()].station, 0x0900, rr, 4) != 1)
            throw Error(SB() << slave_name(slaves_[dc.front()]) << ": no answer reading DC receive times");
        uint32_t t_ref = le32(rr);
        for (std::size_t i : dc) dc_pending_.push_back({i, t_ref, master_ns});
    }
    if (dc_ref_ >= 0)
        LOG_INFO(lg, "ec" << bus_ << ": distributed clocks on " << n << " slave(s), reference "
                          << slave_name(slaves_[std::size_t(dc_ref_)]) << ", SYNC0 every " << cycle_ns_ << " ns");
}

void Master::configure_dc_slave(std::size_t i) {
    // Receive times latched on every slave (harmless to those running); the delay from the
    // reference (from the slave itself if the reference does not answer).
    uint32_t latch = 0;
    if (transact(kBwr, 0, 0x0900, &latch, 4) < 1) throw Error(SB() << "ec" << bus_ << ": DC receive-time latch got no answer");
    uint64_t master_ns = master_time_ns();
    uint32_t t_ref = 0;
    bool have_ref = false;
    if (dc_ref_ >= 0 && std::size_t(dc_ref_) != i) {
        uint8_t rr[4] = {};
        if (transact(kFprd, slaves_[std::size_t(dc_ref_)].station, 0x0900, rr, 4) == 1) {
            t_ref = le32(rr);
            have_ref = true;
        }
    }
    configure_dc_at(i, have_ref ? &t_ref : nullptr, master_ns);
}

void Master::configure_dc_at(std::size_t i, const uint32_t* t_ref, uint64_t master_ns) {
    // Delay (line topology), offset so its system time is the master's time at the latch, SYNC0 at
    // the cycle time starting 100 ms ahead on a cycle boundary.
    SlaveInfo& s = slaves_[i];
    uint8_t rt[4] = {};
    if (transact(kFprd, s.station, 0x0900, rt, 4) != 1)
        throw Error(SB() << slave_name(s) << ": no answer reading DC receive times");
    uint32_t t0 = le32(rt);
    uint32_t d = t_ref ? t0 - *t_ref : 0;
    uint8_t delay[4];
    put_le32(delay, d);
    uint8_t local[8] = {};
    if (transact(kFprd, s.station, 0x0918, local, 8) != 1 || transact(kFpwr, s.station, 0x0928, delay, 4) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring DC delay");
    uint8_t offset[8]; // system time = master time, seen through this slave's delay
    put_le64(offset, master_ns + d - le64(local));
    if (transact(kFpwr, s.station, 0x0920, offset, 8) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring DC offset");
    uint16_t aa = s.sii.dc_assign_activate;
    if (!aa) return; // system time only (latches), no SYNC signals
    uint16_t off = 0;
    // An oversampling terminal takes n samples per cycle: SYNC0 every cycle/n, SYNC1 the rest of
    // the cycle (ecmccfg's ecmcEL3702.cmd).
    uint32_t sync0 = uint32_t(cycle_ns_ / std::max(s.oversampling, 1u));
    uint8_t cyc[8];
    put_le32(cyc, sync0);
    put_le32(cyc + 4, s.oversampling > 1 ? uint32_t(cycle_ns_) - sync0 : 0);
    uint8_t st[8] = {};
    transact(kFprd, s.station, 0x0910, st, 8);
    uint64_t start = (le64(st) + 100'000'000ull) / cycle_ns_ * cycle_ns_;
    uint8_t start_b[8];
    put_le64(start_b, start);
    uint8_t act[2] = {uint8_t(aa), uint8_t(aa >> 8)};
    if (transact(kFpwr, s.station, 0x0980, &off, 2) != 1 || transact(kFpwr, s.station, 0x09A0, cyc, s.oversampling > 1 ? 8 : 4) != 1 ||
        transact(kFpwr, s.station, 0x0990, start_b, 8) != 1 || transact(kFpwr, s.station, 0x0980, act, 2) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring SYNC0");
}


} // namespace beamctl::ethercat
