// The homing sequences of an axis (ECMC's ecmcAxisSequencer seqHoming*; specs/ecmc.md §5), one
// function per family. Every move is a velocity move at "to" (towards the switch) or "from" (off
// it); the reference is the encoder position at the sequence's edge, and the axis is re-referenced
// bumplessly once it stands still (position = actual - edge + homing position):
//   limit family   1/2    to the low/high limit, back off it: leaving the switch is the edge
//                  3/4    the same, then the first change of the home switch
//                  5/6    the same, then through the home cam and back: the cam's centre
//                  11/12  the same, then the latchCount-th index mark latched by the terminal
//                  21/22  the same, stopped where it left the switch: the latchCount-th overflow of
//                         the encoder's absolute bits after the switch is the homing position
//                         (resolvers, single-turn absolute encoders)
//   cam family     7/8    backward/forward at "from" to the home switch's rising edge
//                  9/10   through the cam and back to its rising edge: the cam's centre
//   external       26     the drive homes itself: `trigg` set, `ready` rising ends it (the
//                         following error is not checked meanwhile); the homing position is set
// With axis.autoMode the drive is switched to its homing mode when a homing command starts
// (sequence 26 waits until it reports that mode) and back to its motion mode at the end.
// Threading: RT thread (Axis::run), noexcept.
#pragma once

#include <cstdint>

namespace beamctl::motion {

class Axis;

class Homing {
public:
    explicit Homing(Axis& axis) : a_(axis) {}
    // A homing command was accepted: sequence `seq` (1..12, 21, 22, 26) starts.
    void start(int seq) noexcept;
    // One cycle of the running sequence.
    void step() noexcept;
    // The sequence ended early (a stop, a disable, an error): outputs back to rest.
    void abort() noexcept;
    int sequence() const noexcept { return seq_; }

    // Sequences this implementation runs (for the command's check).
    static bool supported(int seq) noexcept {
        return (seq >= 1 && seq <= 12) || seq == 21 || seq == 22 || seq == 26;
    }

private:
    void limit_family() noexcept;
    void cam_family() noexcept;
    void external() noexcept;
    void finish() noexcept; // re-reference (step 10), post move (11), motion mode (12), done (13)
    void fail(uint32_t id) noexcept;
    void centre_reached() noexcept;
    void go(double velocity) noexcept;
    void halt() noexcept;
    bool motion_mode_reached() noexcept; // autoMode: motion mode written and reported

    Axis& a_;
    int seq_ = 0, step_ = 0;
    bool bwd_ = true;             // the first direction is backward
    double v_to_ = 0, v_from_ = 0;
    double edge_ = 0, edge2_ = 0; // [units] latched reference positions
    double reference_ = 0;        // [units] what the encoder reads at the reference (seq 21/22: at standstill)
    int latch_count_ = 0;
    bool last_latch_valid_ = false, last_ready_ = false;
};

} // namespace beamctl::motion
