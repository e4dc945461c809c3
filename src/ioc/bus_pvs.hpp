// The bus and engine status PVs of `beamctl run`, as ecmccfg names them, made from declarative
// tables (pv_table.hpp) on IOC-loop items of the registry:
//   per bus, ECMC's names where ECMC has them: ec<m>.ok, ec<m>.linkup, ec<m>.slavecounter,
//     ec<m>.dom0.wc, .dom0.wcexpected, .dom0.wccomplete, ec<m>.framesmissed, .frameslate,
//     .wkcerrors; beamctl's ec<m>.slavesresponding, ec<m>.slavesop; per slave ec<m>.s<k>.slavestatus
//     (bit 0 online, 1 operational, 2-5 AL state INIT/PREOP/SAFEOP/OP; beamctl's bit 6 data valid)
//     and beamctl's ec<m>.s<k>.state (Master SlaveState: 0 OP, 1 MISSING, 2 WRONG_ID, 3 ERROR,
//     4 LOST, 5 CONFIGURING), .lostcounter, .reconfigcounter, .errorid (ECMC's slave error ids)
//   the engine's: ecmc.thread.latency.max, .latency.mean, .execute.max, .cycles, .missed (µs,
//     counts) and ecmc.thread.reset (a write of 1 clears them; reads 1 until the cycle did): the
//     IOC's cycle; ec<m>.thread.* the same of the cycle bus m runs in (its own with rate_hz)
// $(P)m<m>-Stat-OK -LinkUp -SlvCntr -Dom-WC -Dom-WC-Exp -Dom-WC-Complete -MissedFrames
// -LateFrames -WkcErrors -ThdLatMax -ThdExeMax -ThdLatMean -ThdCycles -ThdMissedCycles
// -ThdStat-Reset -SlvRsp -SlvOP; $(P)m<m>s<kkk>-Online -Operational -HWType -Valid -State -LostCntr
// -ReconfCntr -ErrId. The latency histogram
// (-ThdLatHist, -ThdLatHistEdges: arrays) is published by the IOC. These items live in the IOC
// loop: records read them, PLC code and axes (the cycle) cannot.
// Threading: IOC loop thread.
#pragma once

#include "ethercat/bus.hpp"
#include "module/pv_table.hpp"
#include "pv/link.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

const module::PvTable& bus_table();   // $(P) = "<prefix>m<m>", signals "ec<m>." (the thread PVs: "ec<m>.thread.")
const module::PvTable& slave_table(); // $(P) = "<prefix>m<m>s<kkk>", signals "ec<m>.s<k>."
// A scanner link's bus (ec<m>.scanner.attached, .cycle, .missed, .drops, .attaches):
// $(P)m<m>-ScnConn -ScnCycle -ScnMissed -ScnDrops -ScnAttaches.
const module::PvTable& scanner_table();

// Declares the items of bus `id` with its configured slave positions; `engine` once per IOC.
void declare_bus_items(registry::Registry& r, int id, const std::vector<int>& slave_positions);
void declare_engine_items(registry::Registry& r);

// Device support on those items; `stats` is the engine's statistics as the IOC loop last read
// them (refreshed before each look). Null with `why` if `name` is not such an item or is
// written where it cannot be.
std::unique_ptr<pv::LinkDevice> make_bus_item_device(const std::string& name, int bit, bool output, ethercat::Bus* bus,
                                                     const std::vector<int>& slave_positions, rt::Engine& engine,
                                                     const rt::EngineStats& stats, std::string& why);

} // namespace beamctl::ioc
