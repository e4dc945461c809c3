// A position-compare block's edges on a DC-timestamped digital output (EL2252): the edge is
// switched by the terminal at the DC system time where the compare point is crossed, between
// cycles, instead of with the next frame.
//
// The crossing is known only after it happened, so the edges come from a shadow of the block (the
// same parameters and ENABLE) fed with INP extrapolated at its last velocity to the time three
// frames after the one that sampled INP: an edge of the shadow lies in the window between the
// next frame and the one after, and its time is interpolated there (Pcomp::edge_fraction); the
// velocity is INP's over the last 2 ms (or the last cycle, if longer). Each
// edge goes to the terminal in ecmccfg's sequence (examples/test/el1252Toel2252): startTime, the
// output level and activate 0 in one frame, activate 3 in the next, which arms the terminal's
// SYNC0 single shot; the next edge can be loaded once the frame time passed the armed one. So
// edges must be at least two cycles apart; an edge whose time would already have passed when armed
// is not sent and is counted (late). A prediction is exact for an input moving at constant
// velocity (a trajectory, the clock); an input that changes velocity inside the horizon moves the
// edge by the extrapolation error. The block itself (OUT, PRODUCED, capture rows) runs on the real
// INP and is not changed by any of this.
// Threading: RT thread only (plain data, no allocation).
#pragma once

#include "daq/pcomp.hpp"

#include <cstdint>

namespace beamctl::daq {

class TimedPcompOutput {
public:
    // Frames from the one that sampled INP to the predicted sample.
    static constexpr int kHorizon = 3;

    // One cycle. dc_ns: the DC time of the frame received this cycle (when bus inputs were
    // sampled); x_ns: the DC time INP stands for (dc_ns for bus and axis values, one period later
    // for the engine clock, whose value is this cycle's); period_ns: the cycle. Then start_time(),
    // level() and activate() are what this cycle's frame carries.
    void step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t dc_ns, uint64_t period_ns) noexcept;
    // INP was rebound or the bus restarted: forget the previous sample and pending edges.
    void reset() noexcept;

    uint64_t start_time() const noexcept { return start_; }
    bool level() const noexcept { return level_; }
    uint8_t activate() const noexcept { return activate_; }

    uint64_t scheduled() const noexcept { return scheduled_; } // edges sent to the terminal
    uint64_t late() const noexcept { return late_; }           // edges not sent: their time had passed
    // The predicted time [DC ns] of the shadow's last edge (tests, benchmarks).
    uint64_t last_edge_ns() const noexcept { return last_edge_ns_; }

private:
    struct Edge {
        uint64_t at;
        bool level;
    };
    static constexpr unsigned kQueue = 8;
    // INP's velocity over the last kWindowNs (at least one cycle, at most kHistory cycles): a
    // longer baseline than one cycle keeps an encoder's quantization out of the prediction at
    // high rates, a short one follows acceleration.
    static constexpr uint64_t kWindowNs = 2'000'000;
    static constexpr unsigned kHistory = 32;
    Pcomp shadow_;
    double history_[kHistory] = {};
    unsigned samples_ = 0, newest_ = 0;
    Edge queue_[kQueue] = {};
    unsigned head_ = 0, size_ = 0;
    enum class Phase : uint8_t { Idle, Loaded, Armed } phase_ = Phase::Idle;
    uint64_t start_ = 0, armed_at_ = 0;
    bool level_ = false;
    uint8_t activate_ = 0;
    uint64_t scheduled_ = 0, late_ = 0, last_edge_ns_ = 0;
};

} // namespace beamctl::daq
