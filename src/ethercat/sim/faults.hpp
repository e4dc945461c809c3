// Faults injected into a running simulated segment, from outside (docs/ethercat.md, "Fault
// injection"): the IOC shell's `sim` command for an in-process segment, `beamctl sim fault` for a
// `beamctl sim` process, and `link.faults` in the IOC file to start with them. Each names what it
// does on the wire and what the master should do about it.
//   power K off|on        slave K loses power (bypassed: frames pass it, later positions shift) /
//                         is powered again (INIT, no station address, SDOs and SMs lost)
//   break K | repair      the line is cut after slave K (frames come back from K; K+1.. are gone)
//   loss F | corrupt F    drop / corrupt that fraction of frames (0..1)
//   delay MS              answers come back MS milliseconds later (0..1000; 0 ends it)
//   refuse-state K STATE CODE   slave K refuses the next change to STATE (SAFEOP, OP, PREOP) with
//                         AL status code CODE (e.g. 0x001D), until cleared
//   refuse-sdo K INDEX:SUB ABORT  slave K aborts downloads of that object with ABORT, until cleared
//   replace K TYPE        slave K is swapped for another device type (power cycle with a new identity)
//   glitch K COUNTS       the first encoder channel of slave K jumps by COUNTS
//   drive-fault K         the drive at slave K faults (as its own protection would)
//   clear                 every fault above lifted (power, line, loss, refusals)
// Threading: parse_fault() on any thread; Segment::post() from one producer thread; the segment
// applies posted faults on its own thread at the next frame.
#pragma once

#include "ethercat/device.hpp"

#include <cstdint>
#include <string>
#include <string_view>

namespace beamctl::ethercat {
class Catalog;
}

namespace beamctl::ethercat::sim {

struct Fault {
    enum class Kind : uint8_t { PowerOff, PowerOn, BreakAfter, Repair, Loss, Corrupt, Delay, RefuseState, RefuseSdo,
                                Replace, Glitch, DriveFault, Clear };
    Kind kind = Kind::Clear;
    int position = -1;
    double fraction = 0;          // loss, corrupt: 0..1; delay: [ms]
    uint8_t state = 0;            // refuse-state: AL state refused
    uint16_t al_code = 0;         // refuse-state: AL status code given
    uint16_t index = 0;           // refuse-sdo
    uint8_t sub = 0;
    uint32_t abort = 0;           // refuse-sdo: abort code
    int64_t counts = 0;           // glitch
    const DeviceDesc* desc = nullptr; // replace
};

// Parses one fault command. Throws Error naming what is wrong, with the usage. `slaves`: the
// segment's size (positions are checked against it).
Fault parse_fault(std::string_view text, const Catalog& catalog, std::size_t slaves);
std::string fault_usage();
// The command as text again ("power 3 off").
std::string describe(const Fault& f);

} // namespace beamctl::ethercat::sim
