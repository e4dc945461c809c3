// Planning: every command is solved from the current state (p0, v0, a0) as
//   [brake to rest] + ramp to a peak velocity vp + cruise at vp + ramp to rest
// where a ramp is <= 3 constant-jerk phases (jerk +-J, 0, +-J) taking (v, a) to (vt, 0) with the
// acceleration limit of its peak (speeding up: acceleration, slowing down: deceleration). The
// brake comes first only when the motion must reverse (moving away from the target, or unable to
// stop before it); velocity never crosses zero inside a ramp, so each phase knows its limit.
// Trapezoid solves vp in closed form. S-curve bisects vp on the closed-form travel, which is
// monotone for vp at or above the velocity reached by flattening the current acceleration; a
// target short of that is reached by one brake ramp whose peak deceleration is bisected instead
// (its travel falls monotonically as the peak rises). Bisection runs a bounded number of steps.
#include "motion/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace beamctl::motion {
namespace {

constexpr int kBisections = 80; // vp to ~2^-80 of the velocity limit; stops early at 1 ulp

struct Limits {
    double velocity, acceleration, deceleration, jerk; // validated; jerk 0 = trapezoid
};

bool positive_finite(double x) {
    return std::isfinite(x) && x > 0;
}

bool resolve(const TrajectoryLimits& l, Limits& out) {
    if (!positive_finite(l.velocity) || !positive_finite(l.acceleration)) return false;
    if (!std::isfinite(l.deceleration) || l.deceleration < 0) return false;
    if (!std::isfinite(l.jerk) || l.jerk < 0) return false;
    out = {l.velocity, l.acceleration, l.deceleration > 0 ? l.deceleration : l.acceleration,
           l.jerk};
    return true;
}

double sign(double x) {
    return double((x > 0) - (x < 0));
}

// Velocity when the acceleration a0 is brought to 0 at once with jerk j (j 0: no jerk limit).
double flat_velocity(double v0, double a0, double jerk) {
    return jerk > 0 ? v0 + a0 * std::fabs(a0) / (2 * jerk) : v0;
}

// Phases taking (v, a) to (vt, 0). Jerk-limited: value[] is the jerk of each phase [units/s^3];
// trapezoid: value[] is the constant acceleration of its single phase [units/s^2].
struct Ramp {
    bool smooth = false;
    int count = 0;
    double duration[3] = {};
    double value[3] = {};
    double vt = 0;
    void push(double t, double x) {
        duration[count] = std::max(t, 0.0);
        value[count] = x;
        ++count;
    }
};

// Peak acceleration limit of a ramp towards vt whose acceleration points along `dir`: speeding up
// if vt lies that way from zero, slowing down otherwise. Valid because no ramp crosses v = 0.
double peak_limit(double dir, double vt, double acc, double dec) {
    return dir * vt > 0 ? acc : dec;
}

Ramp ramp_smooth(double v0, double a0, double vt, double acc, double dec, double jerk) {
    Ramp r;
    r.smooth = true;
    r.vt = vt;
    double dir = sign(vt - flat_velocity(v0, a0, jerk));
    if (dir == 0) {
        r.push(std::fabs(a0) / jerk, -sign(a0) * jerk);
        return r;
    }
    double amax = peak_limit(dir, vt, acc, dec);
    double dv = dir * (vt - v0); // in the frame where the peak acceleration is positive
    double a = dir * a0;
    double peak = std::sqrt(std::max(0.0, jerk * dv + 0.5 * a * a)); // triangular acceleration
    double hold = 0;
    if (peak > amax) { // trapezoidal acceleration (also when a0 itself exceeds the limit)
        peak = amax;
        double dv_ramps = 0.5 * (a + peak) * std::fabs(peak - a) / jerk + peak * peak / (2 * jerk);
        hold = (dv - dv_ramps) / peak;
    }
    r.push(std::fabs(peak - a) / jerk, dir * sign(peak - a) * jerk);
    r.push(hold, 0);
    r.push(peak / jerk, -dir * jerk);
    return r;
}

Ramp ramp_trapezoid(double v0, double vt, double acc, double dec) {
    Ramp r;
    r.vt = vt;
    double dir = sign(vt - v0);
    if (dir == 0) return r;
    double amax = peak_limit(dir, vt, acc, dec);
    r.push(std::fabs(vt - v0) / amax, dir * amax);
    return r;
}

Ramp ramp(double v0, double a0, double vt, const Limits& l) {
    return l.jerk > 0 ? ramp_smooth(v0, a0, vt, l.acceleration, l.deceleration, l.jerk)
                      : ramp_trapezoid(v0, vt, l.acceleration, l.deceleration);
}

// Travel of a ramp started at (v, a) [units].
double travel(const Ramp& r, double v, double a) {
    double p = 0;
    for (int i = 0; i < r.count; ++i) {
        double t = r.duration[i];
        double j = r.smooth ? r.value[i] : 0;
        if (!r.smooth) a = r.value[i];
        p += t * (v + t * (0.5 * a + t * j / 6));
        v += t * (a + 0.5 * t * j);
        a += t * j;
    }
    return p;
}

// Appends segments, carrying the state at the end of the last one.
template <typename Segment> struct Builder {
    Segment* out;
    int count = 0;
    double p = 0, v = 0, a = 0;

    void add(double t, double j) {
        if (!(t > 0) || count == Trajectory::kMaxSegments) return;
        out[count++] = {t, j, p, v, a};
        p += t * (v + t * (0.5 * a + t * j / 6));
        v += t * (a + 0.5 * t * j);
        a += t * j;
    }
    void add(const Ramp& r) {
        for (int i = 0; i < r.count; ++i) {
            if (r.smooth) {
                add(r.duration[i], r.value[i]);
            } else {
                a = r.value[i];
                add(r.duration[i], 0);
            }
        }
        v = r.vt; // exact end of the ramp: no rounding carried into the next segment
        a = 0;
    }
    void cruise(double t) {
        a = 0;
        add(t, 0);
    }
    void hold() {
        a = 0;
        if (count < Trajectory::kMaxSegments)
            out[count++] = {std::numeric_limits<double>::infinity(), 0, p, v, 0};
    }

    // Ramp to s*vp, cruise, ramp to rest (or one softer brake ramp), covering `distance` >= 0
    // along s; the current velocity is not against s nor reverses when its acceleration is
    // flattened, and the target is not before the full-deceleration stop.
    void forward(double s, double distance, const Limits& l) {
        double vp = l.velocity;
        double cruise_time = 0;
        if (l.jerk > 0) {
            const double v0 = v, a0 = a;
            auto reach = [&](double peak) {
                return s * (travel(ramp(v0, a0, s * peak, l), v0, a0) +
                            travel(ramp(s * peak, 0, 0, l), s * peak, 0));
            };
            // Below the flat velocity the ramp would end decelerating and the stop decelerate
            // again (a notch), and the travel is not monotone in vp: peaks start there.
            const double lowest = std::min(s * flat_velocity(v0, a0, l.jerk), l.velocity);
            if (reach(lowest) > distance) {
                // The target comes before flatten-then-brake: one brake ramp whose peak
                // deceleration (travel falls monotonically as it rises) ends on the target.
                double lo = 0, hi = l.deceleration;
                for (int k = 0; k < kBisections; ++k) {
                    double mid = 0.5 * (lo + hi);
                    if (mid <= lo || mid >= hi) break;
                    double t = s * travel(ramp_smooth(v0, a0, 0, mid, mid, l.jerk), v0, a0);
                    (t > distance ? lo : hi) = mid;
                }
                add(ramp_smooth(v0, a0, 0, hi, hi, l.jerk));
                return;
            }
            double at_max = reach(l.velocity);
            if (at_max <= distance) {
                cruise_time = (distance - at_max) / l.velocity;
            } else {
                double lo = lowest, hi = l.velocity;
                for (int k = 0; k < kBisections; ++k) {
                    double mid = 0.5 * (lo + hi);
                    if (mid <= lo || mid >= hi) break;
                    (reach(mid) <= distance ? lo : hi) = mid;
                }
                vp = lo;
            }
        } else {
            const double w = s * v; // >= 0
            const double acc = l.acceleration, dec = l.deceleration, vmax = l.velocity;
            if (w > vmax) {
                cruise_time = (distance - w * w / (2 * dec)) / vmax;
            } else {
                vp = std::sqrt((distance + w * w / (2 * acc)) / (0.5 / acc + 0.5 / dec));
                if (vp > vmax) {
                    vp = vmax;
                    cruise_time =
                        (distance - (vmax * vmax - w * w) / (2 * acc) - vmax * vmax / (2 * dec)) /
                        vmax;
                }
            }
        }
        add(ramp(v, a, s * vp, l));
        cruise(std::max(cruise_time, 0.0));
        add(ramp(v, 0, 0, l));
    }

    // Positioning move from the current state to `target`.
    void move(double target, const Limits& l) {
        Ramp brake = ramp(v, a, 0, Limits{l.velocity, l.deceleration, l.deceleration, l.jerk});
        double d = target - (p + travel(brake, v, a));
        if (d == 0) {
            add(brake);
            return;
        }
        double s = sign(d);
        if (s * v < 0 || s * flat_velocity(v, a, l.jerk) < 0) {
            add(brake); // the motion has to reverse: come to rest first
            d = target - p;
            if (d == 0) return;
            s = sign(d);
        }
        forward(s, s * (target - p), l);
    }

    // Ramp to velocity vt and hold it (vt 0: stop).
    void velocity(double vt, const Limits& l) {
        double s = sign(vt);
        if (s == 0 || s * v < 0 || s * flat_velocity(v, a, l.jerk) < 0)
            add(ramp(v, a, 0, Limits{l.velocity, l.deceleration, l.deceleration, l.jerk}));
        if (s == 0) return;
        add(ramp(v, a, vt, l));
        hold();
    }
};

double finite_or_zero(double x) {
    return std::isfinite(x) ? x : 0;
}

} // namespace

void Trajectory::reset(const TrajectoryState& s) noexcept {
    state_ = {finite_or_zero(s.position), finite_or_zero(s.velocity),
              finite_or_zero(s.acceleration)};
    target_ = state_.position;
    count_ = 0;
    index_ = 0;
    elapsed_ = 0;
    busy_ = false;
    holding_ = false;
}

void Trajectory::start(int count, double end_position, bool holding) noexcept {
    count_ = count;
    index_ = 0;
    elapsed_ = 0;
    target_ = end_position;
    holding_ = holding;
    busy_ = true;
}

TrajectoryResult Trajectory::move_to(double target, const TrajectoryLimits& l) noexcept {
    Limits lim{};
    if (!resolve(l, lim)) return TrajectoryResult::InvalidLimits;
    if (!std::isfinite(target)) return TrajectoryResult::InvalidTarget;
    Builder<Segment> b{segments_.data(), 0, state_.position, state_.velocity, state_.acceleration};
    b.move(target, lim);
    start(b.count, target, false);
    return TrajectoryResult::Ok;
}

TrajectoryResult Trajectory::move_velocity(double v, const TrajectoryLimits& l) noexcept {
    Limits lim{};
    if (!resolve(l, lim)) return TrajectoryResult::InvalidLimits;
    if (!std::isfinite(v)) return TrajectoryResult::InvalidTarget;
    v = std::clamp(v, -lim.velocity, lim.velocity);
    Builder<Segment> b{segments_.data(), 0, state_.position, state_.velocity, state_.acceleration};
    b.velocity(v, lim);
    start(b.count, b.p, v != 0);
    return TrajectoryResult::Ok;
}

TrajectoryResult Trajectory::stop(double deceleration, double jerk) noexcept {
    if (!positive_finite(deceleration) || !std::isfinite(jerk) || jerk < 0)
        return TrajectoryResult::InvalidLimits;
    if (!busy_ && state_.velocity == 0 && state_.acceleration == 0) return TrajectoryResult::Ok;
    Limits lim{std::numeric_limits<double>::max(), deceleration, deceleration, jerk};
    Builder<Segment> b{segments_.data(), 0, state_.position, state_.velocity, state_.acceleration};
    b.velocity(0, lim);
    start(b.count, b.p, false);
    return TrajectoryResult::Ok;
}

TrajectoryResult Trajectory::step(double dt) noexcept {
    if (!busy_) return TrajectoryResult::Ok;
    if (dt > 0 && std::isfinite(dt)) elapsed_ += dt;
    while (index_ < count_ && elapsed_ >= segments_[index_].duration) {
        elapsed_ -= segments_[index_].duration;
        ++index_;
    }
    if (index_ == count_) {
        state_ = {target_, 0, 0};
        busy_ = false;
        holding_ = false;
        count_ = 0;
        index_ = 0;
        elapsed_ = 0;
        return TrajectoryResult::Finished;
    }
    const Segment& s = segments_[index_];
    const double t = elapsed_;
    state_.position = s.position + t * (s.velocity + t * (0.5 * s.acceleration + t * s.jerk / 6));
    state_.velocity = s.velocity + t * (s.acceleration + 0.5 * t * s.jerk);
    state_.acceleration = s.acceleration + t * s.jerk;
    return TrajectoryResult::Working;
}

double Trajectory::remaining() const noexcept {
    if (!busy_) return 0;
    if (holding_) return std::numeric_limits<double>::infinity();
    double t = -elapsed_;
    for (int i = index_; i < count_; ++i) t += segments_[i].duration;
    return std::max(t, 0.0);
}

double modulo_target(double current, double target, double range, int type) noexcept {
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    if (range == 0) return target;
    if (!positive_finite(range) || !std::isfinite(current) || !std::isfinite(target)) return kNaN;
    auto wrap = [range](double x) {
        double m = std::fmod(x, range);
        if (m < 0) m += range;
        return m < range ? m : 0.0; // -tiny + range rounds to range, which is 0 in the turn
    };
    const double diff = wrap(target) - wrap(current); // (-range, range): within the turn
    const double forward = diff < 0 ? diff + range : diff;
    const double backward = diff > 0 ? diff - range : diff;
    double delta;
    switch (type) {
    case 0:
        delta = diff;
        break;
    case 1:
        delta = forward;
        break;
    case 2:
        delta = backward;
        break;
    case 3:
        delta = -backward < forward ? backward : forward;
        break;
    default:
        return kNaN;
    }
    return current + delta;
}

} // namespace beamctl::motion
