// Trajectory generator of one motion axis: trapezoid (jerk 0, ECMC trajectory.type 0) or
// jerk-limited S-curve (jerk > 0, ECMC trajectory.type 1). Each command plans the whole motion
// analytically from the current state (which may be moving) as at most 10 constant-jerk segments;
// step() evaluates them in closed form, so nothing drifts and nothing allocates.
// Threading: not thread-safe; a Trajectory belongs to its axis and only the RT thread calls it.
#pragma once

#include <array>
#include <cstdint>

namespace beamctl::motion {

struct TrajectoryLimits {
    double velocity = 0;     // max |v| [units/s], > 0
    double acceleration = 0; // max |a| while speeding up [units/s^2], > 0
    double deceleration = 0; // max |a| while slowing down [units/s^2]; 0 = same as acceleration
    double jerk = 0;         // max |da/dt| [units/s^3]; 0 = trapezoid (acceleration may jump)
};

struct TrajectoryState {
    double position = 0;     // [units]
    double velocity = 0;     // [units/s]
    double acceleration = 0; // [units/s^2]
};

enum class TrajectoryResult : uint8_t {
    Ok,            // command accepted; step() while idle
    Working,       // step(): moving (or holding a velocity)
    Finished,      // step(): arrived at the target or stopped in this step
    InvalidLimits, // command rejected: a limit is <= 0 (< 0 where 0 has a meaning), NaN or inf
    InvalidTarget, // command rejected: target position or velocity is NaN or inf
};

class Trajectory {
public:
    // Adopt `s` as the current setpoint and drop any plan. A moving state is only the start of the
    // next command (step() does not advance it). Non-finite fields are taken as 0.
    void reset(const TrajectoryState& s) noexcept;
    // Positioning move to `target` [units] from the current state; also retargets mid-move. If the
    // target cannot be reached without overshoot, brakes within the limits and comes back. From a
    // state beyond `l` (speed above a lowered velocity limit, or mid emergency stop) it first
    // brings speed and acceleration back within `l` at the deceleration and jerk limits.
    [[nodiscard]] TrajectoryResult move_to(double target, const TrajectoryLimits& l) noexcept;
    // Ramp to the signed velocity `v` [units/s] (clamped to +-l.velocity) and hold it until the
    // next command; v = 0 ramps to standstill and finishes there.
    [[nodiscard]] TrajectoryResult move_velocity(double v, const TrajectoryLimits& l) noexcept;
    // Ramp to standstill with `deceleration` [units/s^2] > 0 and `jerk` [units/s^3] (0 = no jerk
    // limit: acceleration jumps to -deceleration). Ok and no change when idle at rest.
    [[nodiscard]] TrajectoryResult stop(double deceleration, double jerk = 0) noexcept;
    // Advance by `dt` [s] (<= 0 or non-finite: no advance). Working while moving, Finished on the
    // step that ends the motion (state is then exactly {target(), 0, 0}), Ok while idle.
    TrajectoryResult step(double dt) noexcept;

    const TrajectoryState& state() const noexcept { return state_; }
    bool busy() const noexcept { return busy_; }
    // End position of the planned motion [units]; while holding a velocity the current position
    // (as ECMC's targetPosition in velocity mode).
    double target() const noexcept { return holding_ ? state_.position : target_; }
    // Time until the planned motion ends [s]: 0 when idle, +inf while holding a velocity.
    double remaining() const noexcept;

    static constexpr int kMaxSegments = 10; // brake (3) + ramp (3) + cruise (1) + ramp (3)

private:
    struct Segment {
        double duration;                         // [s]; +inf for a velocity hold
        double jerk;                             // [units/s^3]
        double position, velocity, acceleration; // at the start of the segment
    };
    void start(int count, double end_position, bool holding) noexcept;

    std::array<Segment, kMaxSegments> segments_{};
    int count_ = 0;
    int index_ = 0;      // current segment
    double elapsed_ = 0; // time into the current segment [s]
    TrajectoryState state_{};
    double target_ = 0;
    bool busy_ = false;
    bool holding_ = false;
};

// ECMC modulo motion: the absolute (unwrapped) target for a move from `current` [units] to the
// position `target` taken modulo `range` [units] (mapped into [0, range)). ECMC keeps its setpoint
// wrapped into [0, range) and picks the target in ecmcTrajectoryBase::setTargetPos; we keep
// positions unwrapped (encoders and PVs stay continuous) and make the same choice within the turn
// of `current`, so moves are the ones ECMC makes. Types as ECMC's ecmcMotionModType:
//   0 normal:   stay within the turn (the move never crosses a multiple of range), direction from
//               the sign of the difference;
//   1 forward:  never move backward (a full turn forward if the target is just behind);
//   2 backward: never move forward;
//   3 closest:  the shorter way round, forward on a tie.
// Equal positions within the turn give `current` itself (no move). range 0 = modulo off: returns
// `target` unchanged. Any other range <= 0, non-finite input or unknown type returns NaN, which
// move_to() rejects with InvalidTarget.
double modulo_target(double current, double target, double range, int type) noexcept;

} // namespace beamctl::motion
