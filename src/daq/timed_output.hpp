// A position-compare block's edges placed between cycles, on outputs that can: a DC-timestamped
// digital output (EL2252) switches at a DC time it is given; an oversampled analog output (EL4732)
// plays n samples per cycle, so the edge goes into the sample where the crossing falls.
//
// The crossing is known only after it happened, so the edges come from a shadow of the block (the
// same parameters and ENABLE) fed with INP extrapolated to a time ahead (PcompPredictor): INP's
// velocity over the last 2 ms (or the last cycle, if longer) carries it to the predicted sample,
// and the shadow's edge time is interpolated within its cycle (Pcomp::edge_fraction). A prediction
// is exact for an input moving at constant velocity (a trajectory, the clock); an input that
// changes velocity inside the horizon moves the edge by the extrapolation error. The block itself
// (OUT, PRODUCED, capture rows) runs on the real INP and is not changed by any of this.
// Threading: RT thread only (plain data, no allocation).
#pragma once

#include "daq/pcomp.hpp"

#include <cstdint>

namespace beamctl::daq {

// The shadow block on INP extrapolated to `target_ns`.
class PcompPredictor {
public:
    // x: INP, standing for DC time x_ns; returns true if the shadow has an edge this cycle, at
    // edge_ns() (between target_ns - period_ns and target_ns), rising if rose().
    bool step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t target_ns, uint64_t period_ns) noexcept;
    void reset() noexcept;
    uint64_t edge_ns() const noexcept { return edge_ns_; }
    bool rose() const noexcept { return shadow_.rose(); }

private:
    static constexpr uint64_t kWindowNs = 2'000'000; // the velocity's baseline
    static constexpr unsigned kHistory = 32;         // at most this many cycles
    Pcomp shadow_;
    double history_[kHistory] = {};
    unsigned samples_ = 0, newest_ = 0;
    uint64_t edge_ns_ = 0;
};

// EL2252: each edge goes to the terminal in ecmccfg's sequence (examples/test/el1252Toel2252):
// startTime, the output level and activate 0 in one frame, activate 3 in the next, which arms the
// terminal's SYNC0 single shot; the next edge can be loaded once the frame time passed the armed
// one. The shadow predicts three frames after the one that sampled INP, so an edge lies between the
// next frame and the one after. Edges must be at least two cycles apart; an edge whose time would
// already have passed when armed is not sent and is counted (late).
class TimedPcompOutput {
public:
    static constexpr int kHorizon = 3; // frames from the one that sampled INP to the predicted sample

    // One cycle. dc_ns: the DC time of the frame received this cycle (when bus inputs were
    // sampled); x_ns: the DC time INP stands for (dc_ns for bus and axis values, one period later
    // for the engine clock, whose value is this cycle's); period_ns: the cycle. Then start_time(),
    // level() and activate() are what this cycle's frame carries.
    void step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t dc_ns, uint64_t period_ns) noexcept;
    // INP was rebound: forget the previous samples and pending edges.
    void reset() noexcept;

    uint64_t start_time() const noexcept { return start_; }
    bool level() const noexcept { return level_; }
    uint8_t activate() const noexcept { return activate_; }

    uint64_t scheduled() const noexcept { return scheduled_; } // edges sent to the terminal
    uint64_t late() const noexcept { return late_; }           // edges not sent: their time had passed

private:
    struct Edge {
        uint64_t at;
        bool level;
    };
    static constexpr unsigned kQueue = 8;
    PcompPredictor predictor_;
    Edge queue_[kQueue] = {};
    unsigned head_ = 0, size_ = 0;
    enum class Phase : uint8_t { Idle, Loaded, Armed } phase_ = Phase::Idle;
    uint64_t start_ = 0, armed_at_ = 0;
    bool level_ = false;
    uint8_t activate_ = 0;
    uint64_t scheduled_ = 0, late_ = 0;
};

// EL4732 (oversampling n): the samples of a frame are played at its SYNC0 events across the cycle
// after it, sample k (0-based) at frame + (k + 1) * period / n. The shadow predicts two frames after
// the one that sampled INP, i.e. the end of this frame's play window; an edge there switches
// samples from the first whose time is at or after it. Every edge is placed (one per cycle at most,
// as the block's).
class OversampledPcompOutput {
public:
    // As TimedPcompOutput::step; then sample(k) for k < n is what this frame carries.
    void step(const PcompParams& p, bool enable, double x, uint64_t x_ns, uint64_t dc_ns, uint64_t period_ns, unsigned n) noexcept;
    void reset() noexcept { predictor_.reset(); }
    bool sample(unsigned k) const noexcept { return k < first_changed_ ? before_ : level_; }
    bool level() const noexcept { return level_; } // at the end of the window
    uint64_t edges() const noexcept { return edges_; }

private:
    PcompPredictor predictor_;
    bool level_ = false, before_ = false;
    unsigned first_changed_ = 0;
    uint64_t edges_ = 0;
};

} // namespace beamctl::daq
