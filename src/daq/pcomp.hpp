// Position compare: PandA's PCOMP block (specs/records.md §7; PandABlocks-FPGA modules/pcomp)
// evaluated once per engine cycle on any engine value (an encoder, a virtual axis's actpos, the
// engine clock for time-based pulse trains).
//
// Semantics as PandA's: a rising ENABLE latches INP and arms; a falling ENABLE sets OUT=0 and
// ACTIVE=0. The block waits for the pre-start condition, then OUT rises at START, START+s·STEP, ...
// (s = +1 forward, -1 backward; >=/<= comparisons) and falls WIDTH after each rise; PULSES = 0 is
// unlimited. RELATIVE compares INP minus INP at enable. DIR Either guesses the direction (absolute:
// from which side of START INP is; relative: from the sign of INP once |INP| >= START+PRE_START).
// Skipping a whole STEP stops the block with HEALTH 1; a relative guess with START=PRE_START=0
// stops it with HEALTH 2.
//
// One difference of time scale: PandA's FPGA takes one state transition per 8 ns clock, this block
// evaluates once per engine cycle and follows transitions that leave OUT unchanged within the
// same cycle (WAIT_DIR -> WAIT_PRE_START -> WAIT_RISING -> rise), but at most one edge of OUT per
// cycle: every pulse is high for at least one cycle and low for at least one cycle, as a digital
// output must be to be seen. The observable sequence (OUT, PRODUCED, ACTIVE, HEALTH at each input)
// is PandA's whenever the input holds still for two of PandA's clocks between changes.
//
// The block also says where in the cycle its edge fell: edge_fraction() is the fraction (0, 1] of
// the way from the previous input to this one at which the compare point was crossed (linear
// interpolation), so a timestamped output can place the edge between cycles.
// Threading: RT thread only (plain data, no allocation).
#pragma once

#include <cstdint>

namespace beamctl::daq {

enum class PcompDir : uint8_t { Positive = 0, Negative = 1, Either = 2 };
enum class PcompState : uint8_t { WaitEnable = 0, WaitDir = 1, WaitPreStart = 2, WaitRising = 3, WaitFalling = 4 };
enum class PcompHealth : uint8_t { Ok = 0, JumpError = 1, GuessError = 2 };
const char* to_string(PcompState s) noexcept;
const char* to_string(PcompHealth h) noexcept;

// The block's parameters (PandA's fields); read live every evaluation, as PandA's.
struct PcompParams {
    double pre_start = 0, start = 0, width = 0, step = 0; // in INP's units
    uint32_t pulses = 0;                                  // 0: unlimited
    bool relative = false;
    PcompDir dir = PcompDir::Positive;
};

// The block's names in PLC code (pcomp<n>.<item>), in this order: the first kPcompPlcWritable
// are parameters PLC code may write, the rest are results it reads.
inline constexpr const char* kPcompPlcItems[] = {"enable", "start", "step", "width", "pulses", "pre_start", "relative",
                                                 "dir", "out", "active", "produced", "health", "state"};
inline constexpr int kPcompPlcWritable = 8;

class Pcomp {
public:
    PcompParams params;

    // One evaluation: the ENABLE level and INP of this cycle. Returns OUT.
    bool step(bool enable, double inp) noexcept;

    bool out() const noexcept { return out_; }
    bool active() const noexcept { return active_; }
    uint32_t produced() const noexcept { return produced_; }
    PcompHealth health() const noexcept { return health_; }
    PcompState state() const noexcept { return state_; }
    bool forward() const noexcept { return dir_pos_; }
    // This evaluation raised OUT / lowered it.
    bool rose() const noexcept { return rose_; }
    bool fell() const noexcept { return fell_; }
    // Where the edge of this evaluation lay between the previous INP (0) and this one (1); 1 when
    // there was no previous INP or it did not move.
    double edge_fraction() const noexcept { return edge_fraction_; }
    // The compare point of the last edge, in INP's units (absolute, also when RELATIVE).
    double edge_position() const noexcept { return edge_position_; }

private:
    double posn(double inp) const noexcept { return params.relative ? inp - latched_ : inp; }
    double pulse_start() const noexcept { return dir_pos_ || !params.relative ? params.start : -params.start; }
    double pulse_step() const noexcept { return dir_pos_ ? params.step : -params.step; }
    double pulse_width() const noexcept { return dir_pos_ ? params.width : -params.width; }
    // A compare point is reached also when INP is within a rounding error of it (1e-9 of STEP or
    // WIDTH): a time train's INP is a difference of clock readings in seconds.
    double tolerance() const noexcept { return 1e-9 * (params.step != 0 ? (params.step < 0 ? -params.step : params.step) : (params.width < 0 ? -params.width : params.width)); }
    bool reached(double p) const noexcept { return next_ >= last_ ? p >= next_ - tolerance() : p <= next_ + tolerance(); }
    bool jumped(double p) const noexcept;
    void edge(bool up, double crossing, double p) noexcept;

    bool enable_ = false, out_ = false, active_ = false, dir_pos_ = true;
    bool rose_ = false, fell_ = false;
    uint32_t produced_ = 0;
    PcompHealth health_ = PcompHealth::Ok;
    PcompState state_ = PcompState::WaitEnable;
    double latched_ = 0;            // INP at enable
    double last_ = 0, next_ = 0;    // compare points (posn units): the last crossing and the next
    double prev_posn_ = 0;          // posn of the previous evaluation
    bool have_prev_ = false;
    double edge_fraction_ = 1, edge_position_ = 0;
};

} // namespace beamctl::daq
