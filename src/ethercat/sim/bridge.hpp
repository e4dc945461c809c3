// The EL6692 EtherCAT bridge terminal in the simulator: its two sides (primary, revision
// 0x001x0000, and secondary, 0x001x0002) are slaves of two different segments, each driven by its
// own master, joined by a name that both segments' plants give it (`bridges: [{slave, pair}]`,
// docs/simulator.md). The bridge's microcontroller copies each side's user outputs (0x7000:k) to
// the other side's user inputs (0x6000:k, the same sub-index and width) in both directions:
//   after each frame on segment A, A's side takes the latest outputs B's side left (when B is in
//   OP) into its inputs, then leaves its own; the master of A reads them with its next frame.
//   So a value written in one master's frame reaches the other master in the frame after the
//   other side's next one: one cycle when the two cycles run together.
// Status (0x1A01 SYNC Inputs): externalDeviceNotConnected01 (0x10F4:10) and txPdoState01 (0x1800:07)
// are 1 while the other side is not in OP (not powered, unplugged, not configured, or no such side
// in this process); txPdoToggle01 (0x1800:09) flips each time new data arrived. While the other
// side is not in OP the inputs hold their last values (an assumption: Beckhoff does not document
// it).
// Distributed clocks (0x1A02, assigned instead of 0x1A01 by startup SDOs): each side latches its
// own segment's DC system time (internalTimestamp01, 0x10F4:11) and the other segment's at the
// same instant (externalTimestamp01, 0x10F4:12) after each frame, and flips timestampToggle01;
// the other's time is carried from its last frame at its clock's rate (Segment::set_clock), so
// externalTimestamp01 - internalTimestamp01 is the skew between the two time bases.
// controlValue01 (0x10F4:13, for TwinCAT's DC master clock control) stays 0: not simulated.
// The entries are located under the PDO assignment the side has when it enters SAFEOP.
// Threading: the pair's shared buffers are behind a mutex: the two segments may run on different
// threads (a simulator process with two UDP segments). Each side is used on its segment's thread.
#pragma once

#include "ethercat/sim/io_point.hpp"

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace beamctl::ethercat::sim {

class Segment;

// The shared state of one EL6692: what each side last left for the other.
struct BridgePair {
    std::mutex mu;
    struct Side {
        bool joined = false;       // a segment holds this side
        bool op = false;           // in OP at its last frame
        uint64_t seq = 0;          // counts the outputs it left
        std::vector<uint64_t> out; // raw 0x7000:k values, by k - 1
        uint64_t t_ns = 0, dc_ns = 0; // at its last frame: simulated time, its segment's DC time
        double rate = 1;              // its segment's clock rate (DC ns per simulated ns)
    } side[2];
};

// One side of an EL6692 on a segment (made by the plant builder).
class BridgeSide {
public:
    // Joins side `me` (0 primary, 1 secondary) of the pair named `pair` in this process, for the
    // slave at `position`; its user entries are the 0x7000/0x6000 entries of the device's default
    // PDOs. Throws Error if that side of the pair is already held by another segment.
    BridgeSide(Segment& seg, int position, const std::string& pair, int me);
    ~BridgeSide();
    BridgeSide(const BridgeSide&) = delete;
    BridgeSide& operator=(const BridgeSide&) = delete;

    // After each frame of the segment: the other side's news in, this side's outputs out.
    void step(Segment& seg) noexcept;
    int position() const { return position_; }

    // 1 for a secondary side (revision ...0002), 0 for a primary.
    static int side_of(uint32_t revision) { return (revision & 0xFFFF) == 0x0002 ? 1 : 0; }

private:
    void bind(Segment& seg); // the entries, under the slave's PDO assignment now

    int position_, me_;
    std::shared_ptr<BridgePair> pair_;
    std::vector<IoPoint> out_, in_; // by sub-index - 1 (unbound where the device has none)
    IoPoint toggle_, state_, not_connected_;
    IoPoint ts_toggle_, int_ts_, ext_ts_; // 0x1A02
    uint8_t al_seen_ = 0; // the AL state the entries were located in
    uint64_t seen_seq_ = 0;
    bool toggled_ = false, ts_toggled_ = false;
    std::vector<uint64_t> scratch_;
};

} // namespace beamctl::ethercat::sim
