// Trajectory generator: limits, continuity and exact arrival over seeded random moves (trapezoid
// and S-curve, from rest and from moving states, with retargets and lowered limits), known
// durations (ECMC acceptance move, closed-form S-curve optimum), velocity mode and stops, invalid
// input, modulo targets, and no allocation.
#include "../alloc_counter.hpp"
#include "motion/trajectory.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::motion;

namespace {

constexpr double kRel = 1e-9;                   // relative tolerance on limits (rounding)
constexpr double kDtMin = 50e-6, kDtMax = 1e-3; // cycle times [s]
constexpr double kInf = std::numeric_limits<double>::infinity();

struct Rng {
    std::mt19937_64 gen;
    explicit Rng(uint64_t seed)
        : gen(seed) {}
    double uniform(double lo, double hi) {
        return std::uniform_real_distribution<double>(lo, hi)(gen);
    }
    double log_uniform(double lo, double hi) {
        return std::exp(uniform(std::log(lo), std::log(hi)));
    }
    bool chance(double p) { return uniform(0, 1) < p; }
    double sign() { return chance(0.5) ? 1.0 : -1.0; }
};

double dec_of(const TrajectoryLimits& l) {
    return l.deceleration > 0 ? l.deceleration : l.acceleration;
}

// Random limits over several decades of units; the time scales (time to full speed, to full
// acceleration) stay between 0.5 ms and 0.1 s so that a move takes tens to thousands of cycles.
TrajectoryLimits random_limits(Rng& r, bool smooth) {
    TrajectoryLimits l;
    l.velocity = r.log_uniform(1e-3, 1e3);
    l.acceleration = l.velocity / r.log_uniform(0.002, 0.1);
    l.deceleration = r.chance(0.3) ? 0 : l.velocity / r.log_uniform(0.002, 0.1);
    if (smooth) l.jerk = std::max(l.acceleration, dec_of(l)) / r.log_uniform(0.0005, 0.05);
    return l;
}

// A random state that a valid motion under `l` can be in: |v| <= V, |a| within the limit of its
// direction, and (S-curve) flattening the acceleration neither exceeds V nor reverses the motion.
TrajectoryState random_state(Rng& r, const TrajectoryLimits& l) {
    TrajectoryState s;
    s.position = l.velocity * r.uniform(-100, 100);
    if (r.chance(0.25)) return s;
    s.velocity = l.velocity * r.uniform(-1, 1);
    if (l.jerk == 0) { // acceleration of a trapezoid is free to jump: any value
        s.acceleration = r.uniform(-1, 1) * l.acceleration;
        return s;
    }
    const double a_dir = r.sign();
    const bool speeding_up = a_dir * s.velocity > 0;
    double a = r.uniform(0, 1) * (speeding_up ? l.acceleration : dec_of(l));
    for (int k = 0; k < 60; ++k, a *= 0.5) {
        const double dv = a * a / (2 * l.jerk);
        if (speeding_up ? std::fabs(s.velocity) + dv <= l.velocity : std::fabs(s.velocity) >= dv)
            break;
    }
    s.acceleration = a_dir * a;
    return s;
}

// Upper bound on the time to finish a move from `s`: bring the acceleration to 0, brake to rest,
// then a rest-to-rest move over the remaining distance (<= distance + braking travel), each term
// an upper bound of its phase.
double time_bound(const TrajectoryState& s, double target, const TrajectoryLimits& l) {
    const double V = l.velocity, A = l.acceleration, D = dec_of(l), J = l.jerk;
    const double a0 = J > 0 ? std::fabs(s.acceleration) : 0;
    const double v1 = std::fabs(s.velocity) + (J > 0 ? a0 * a0 / (2 * J) : 0);
    const double brake = (J > 0 ? a0 / J + D / J : 0) + v1 / D;
    const double distance = std::fabs(target - s.position) + v1 * brake;
    return brake + distance / V + V / A + V / D + (J > 0 ? A / J + D / J : 0);
}

// Checks every step of a motion against the limits in force; remembers the first violation.
struct Checker {
    TrajectoryLimits lim;
    TrajectoryState prev;
    double max_speed = 0; // |v| allowed (defaults to lim.velocity)
    std::string failure;

    void begin(const TrajectoryLimits& l, const TrajectoryState& s) {
        lim = l;
        prev = s;
        max_speed = l.velocity;
    }
    bool fail(const std::string& what, const TrajectoryState& s, double dt) {
        if (failure.empty()) {
            std::ostringstream o;
            o.precision(17);
            o << what << ": prev {" << prev.position << ", " << prev.velocity << ", "
              << prev.acceleration << "} now {" << s.position << ", " << s.velocity << ", "
              << s.acceleration << "} dt " << dt << " limits {" << lim.velocity << ", "
              << lim.acceleration << ", " << lim.deceleration << ", " << lim.jerk << "}";
            failure = o.str();
        }
        return false;
    }
    bool step(const TrajectoryState& s, double dt) {
        const double A = lim.acceleration, D = dec_of(lim), J = lim.jerk;
        const double amax = std::max(A, D);
        if (!(std::fabs(s.velocity) <= max_speed * (1 + kRel)))
            return fail("|v| over limit", s, dt);
        const double a_lim = s.acceleration * s.velocity < 0 ? D : A;
        if (!(std::fabs(s.acceleration) <= a_lim * (1 + kRel)))
            return fail("|a| over limit", s, dt);
        if (!(std::fabs(s.velocity - prev.velocity) <= amax * dt * (1 + kRel) + 1e-12 * max_speed))
            return fail("velocity jump", s, dt);
        double gap = 0; // |dx - trapezoid rule| for a motion within the limits
        if (J > 0) {
            if (!(std::fabs(s.acceleration - prev.acceleration) <=
                  J * dt * (1 + kRel) + 1e-12 * amax))
                return fail("jerk over limit", s, dt);
            gap = J * dt * dt * dt / 12;
        } else {
            gap = (A + D) * dt * dt / 4;
        }
        const double dx = s.position - prev.position;
        const double rule = 0.5 * (s.velocity + prev.velocity) * dt;
        const double rounding = 1e-13 * (std::fabs(s.position) + std::fabs(prev.position));
        if (!(std::fabs(dx - rule) <= gap * (1 + kRel) + rounding))
            return fail("position jump", s, dt);
        prev = s;
        return true;
    }
};

// Steps a trajectory with random cycle times under a Checker.
struct Drive {
    Trajectory& tr;
    Checker& check;
    Rng& rng;
    double elapsed = 0; // since the last command [s]
    bool finished = false;

    // Steps until the motion finishes or `duration` [s] passes. False on a violation.
    bool run(double duration) {
        double until = elapsed + duration;
        while (elapsed < until) {
            const double dt = rng.uniform(kDtMin, kDtMax);
            const TrajectoryResult res = tr.step(dt);
            elapsed += dt;
            if (!check.step(tr.state(), dt)) return false;
            if (res == TrajectoryResult::Finished) {
                finished = true;
                return true;
            }
            if (res != TrajectoryResult::Working)
                return check.fail("step() neither Working nor Finished", tr.state(), dt);
        }
        return true;
    }
    // Runs to the end; checks the arrival (bitwise target, at rest, idle) and the time bound.
    bool finish(double target, double bound) {
        if (!finished && !run(bound + 2 * kDtMax)) return false;
        const TrajectoryState& s = tr.state();
        if (!finished) return check.fail("not finished within the time bound", s, 0);
        if (elapsed > bound + kDtMax) return check.fail("finished after the time bound", s, 0);
        if (!(s.position == target)) return check.fail("final position != target", s, 0);
        if (s.velocity != 0 || s.acceleration != 0)
            return check.fail("not at rest at the end", s, 0);
        if (tr.busy()) return check.fail("busy after Finished", s, 0);
        if (tr.step(kDtMax) != TrajectoryResult::Ok)
            return check.fail("step() when idle not Ok", s, 0);
        return true;
    }
};

TrajectoryState at_rest(double p) {
    return {p, 0, 0};
}

// One random positioning move from a random (possibly moving) state. Returns the failure or "".
std::string random_move(Rng& rng, bool smooth) {
    const TrajectoryLimits l = random_limits(rng, smooth);
    const TrajectoryState s0 = random_state(rng, l);
    double target = s0.position;
    if (!rng.chance(0.02)) target += rng.sign() * l.velocity * rng.log_uniform(1e-6, 1);
    Trajectory tr;
    tr.reset(s0);
    Checker check;
    check.begin(l, s0);
    if (tr.move_to(target, l) != TrajectoryResult::Ok) return "move_to rejected valid limits";
    if (tr.target() != target) return "target() != commanded target";
    Drive drive{tr, check, rng};
    drive.finish(target, time_bound(s0, target, l));
    return check.failure;
}

// A move from rest retargeted 1-3 times at random times: further on, back behind the current
// position (reversal), or just ahead (usually too close to stop: overshoot and return).
// `overshoots` counts the moves that passed their final target and came back.
std::string random_retargets(Rng& rng, bool smooth, int& overshoots) {
    const TrajectoryLimits l = random_limits(rng, smooth);
    const double scale = l.velocity * 0.1; // a typical travel [units]
    Trajectory tr;
    tr.reset(at_rest(rng.uniform(-10, 10) * scale));
    Checker check;
    check.begin(l, tr.state());
    Drive drive{tr, check, rng};
    double target = tr.state().position + rng.sign() * scale * rng.log_uniform(0.01, 3);
    if (tr.move_to(target, l) != TrajectoryResult::Ok) return "move_to rejected valid limits";
    const int retargets = 1 + int(rng.uniform(0, 3));
    double bound = time_bound(tr.state(), target, l);
    for (int k = 0; k < retargets; ++k) {
        if (!drive.run(rng.uniform(0, 0.8) * bound)) return check.failure;
        if (drive.finished) break;
        const TrajectoryState& s = tr.state();
        const double heading = s.velocity != 0 ? (s.velocity > 0 ? 1.0 : -1.0) : rng.sign();
        const double kind = rng.uniform(0, 3);
        if (kind < 1)
            target = s.position + heading * scale * rng.log_uniform(0.1, 3);
        else if (kind < 2)
            target = s.position - heading * scale * rng.log_uniform(0.001, 3);
        else
            target = s.position + heading * std::fabs(s.velocity) * rng.uniform(0, kDtMax * 20);
        if (tr.move_to(target, l) != TrajectoryResult::Ok) return "move_to rejected valid limits";
        bound = time_bound(s, target, l);
        drive.elapsed = 0;
    }
    const double from = tr.state().position;
    double furthest = 0; // largest travel beyond the target, along the approach direction
    const double approach = target > from ? 1.0 : -1.0;
    while (!drive.finished) {
        if (!drive.run(kDtMax)) return check.failure;
        if (drive.elapsed > bound + 2 * kDtMax) return "retargeted move not finished in time";
        furthest = std::max(furthest, approach * (tr.state().position - target));
    }
    if (furthest > 0) ++overshoots;
    const TrajectoryState& s = tr.state();
    if (!(s.position == target) || s.velocity != 0 || s.acceleration != 0)
        return "retargeted move did not end at rest on the target";
    return check.failure;
}

void expect_no_failures(const char* what, bool smooth, int cases, uint64_t seed,
                        std::string (*one)(Rng&, bool)) {
    Rng rng(seed);
    int failures = 0;
    std::string first;
    for (int i = 0; i < cases; ++i) {
        std::string f = one(rng, smooth);
        if (!f.empty() && failures++ == 0) first = "case " + std::to_string(i) + ": " + f;
    }
    EXPECT_EQ(failures, 0) << what << (smooth ? " S-curve" : " trapezoid") << ", seed " << seed
                           << "; first: " << first;
}

} // namespace

TEST(Trajectory, RandomMovesTrapezoid) {
    expect_no_failures("random moves", false, 100000, 20240611, random_move);
}

TEST(Trajectory, RandomMovesSCurve) {
    expect_no_failures("random moves", true, 100000, 20240612, random_move);
}

TEST(Trajectory, RandomRetargets) {
    for (bool smooth : {false, true}) {
        Rng rng(smooth ? 77 : 78);
        int failures = 0, overshoots = 0;
        std::string first;
        const int cases = 20000;
        for (int i = 0; i < cases; ++i) {
            std::string f = random_retargets(rng, smooth, overshoots);
            if (!f.empty() && failures++ == 0) first = "case " + std::to_string(i) + ": " + f;
        }
        EXPECT_EQ(failures, 0) << (smooth ? "S-curve" : "trapezoid") << "; first: " << first;
        // The "just ahead" retargets must really have exercised overshoot and return.
        EXPECT_GT(overshoots, cases / 40) << (smooth ? "S-curve" : "trapezoid");
    }
}

namespace {

// Steps with a fixed dt until Finished; returns the busy time [s] (inf if not within max_time).
double busy_time(Trajectory& tr, double dt, double max_time) {
    double t = 0;
    while (t < max_time) {
        t += dt;
        if (tr.step(dt) == TrajectoryResult::Finished) return t;
    }
    return kInf;
}

// Closed-form time-optimal rest-to-rest S-curve (7 phases): time to ramp to a peak vp with limit a
// is vp/a + a/J if a is reached, else 2 sqrt(vp/J); the travel of the two ramps is
// vp * (ta + td) / 2. NaN in the one regime without a short closed form here (peak velocity
// below V, one acceleration limit reached and the other not).
double ramp_time(double vp, double a, double J) {
    return vp * J >= a * a ? vp / a + a / J : 2 * std::sqrt(vp / J);
}
double scurve_optimum(double d, double V, double A, double D, double J) {
    const double ta = ramp_time(V, A, J), td = ramp_time(V, D, J);
    if (V * (ta + td) / 2 <= d) return d / V + (ta + td) / 2;
    const double qa = (1 / A + 1 / D) / 2, qb = (A + D) / (2 * J); // both limits reached
    double vp = (-qb + std::sqrt(qb * qb + 4 * qa * d)) / (2 * qa);
    if (vp * J >= std::max(A, D) * std::max(A, D)) return ramp_time(vp, A, J) + ramp_time(vp, D, J);
    vp = std::cbrt(d * d * J / 4); // neither reached
    if (vp * J <= std::min(A, D) * std::min(A, D)) return 4 * std::sqrt(vp / J);
    return std::nan("");
}

TrajectoryLimits limits(double v, double a, double d, double j) {
    return {v, a, d, j};
}

} // namespace

TEST(Trajectory, EcmcAcceptanceMoveTakesTwoAndAHalfSeconds) {
    // ECMC: mc_move_abs(1, edge, 10, 5, 10, 10) from 0 is busy for 2.5 s.
    Trajectory tr;
    tr.reset(at_rest(0));
    ASSERT_EQ(tr.move_to(10, limits(5, 10, 10, 0)), TrajectoryResult::Ok);
    EXPECT_DOUBLE_EQ(tr.remaining(), 2.5);
    double t = 0;
    for (int k = 0; k < 500; ++k) t += 0.001, (void)tr.step(0.001); // end of acceleration
    EXPECT_NEAR(tr.state().position, 1.25, 1e-9);
    EXPECT_NEAR(tr.state().velocity, 5, 1e-9);
    for (int k = 0; k < 500; ++k) t += 0.001, (void)tr.step(0.001);
    EXPECT_NEAR(tr.state().position, 3.75, 1e-9);
    EXPECT_EQ(tr.state().acceleration, 0);
    double rest = busy_time(tr, 0.001, 10);
    EXPECT_GE(t + rest, 2.5 - 1e-9);
    EXPECT_LE(t + rest, 2.501 + 1e-9);
    EXPECT_EQ(tr.state().position, 10);
}

TEST(Trajectory, TrapezoidRestToRestIsTimeOptimal) {
    Rng rng(5);
    for (int i = 0; i < 2000; ++i) {
        const TrajectoryLimits l = random_limits(rng, false);
        const double V = l.velocity, A = l.acceleration, D = dec_of(l);
        const double target = 1 + rng.sign() * l.velocity * rng.log_uniform(1e-5, 1);
        const double d = std::fabs(target - 1); // the distance as commanded
        // Bang-bang: peak velocity sqrt(2 d A D / (A + D)) if below V, else cruise at V.
        const double vp = std::sqrt(2 * d * A * D / (A + D));
        const double optimum = vp <= V ? vp / A + vp / D : d / V + V / (2 * A) + V / (2 * D);
        Trajectory tr;
        tr.reset(at_rest(1));
        ASSERT_EQ(tr.move_to(target, l), TrajectoryResult::Ok);
        EXPECT_NEAR(tr.remaining(), optimum, 1e-12 * optimum) << "case " << i;
        const double dt = optimum / 1000;
        const double t = busy_time(tr, dt, 2 * optimum);
        EXPECT_GE(t, optimum * (1 - 1e-9)) << "case " << i;
        EXPECT_LE(t, optimum + dt * (1 + 1e-9)) << "case " << i;
    }
}

TEST(Trajectory, SCurveRestToRestWithinOnePercentOfOptimum) {
    Rng rng(6);
    int checked = 0, cruising = 0, both = 0, neither = 0;
    for (int i = 0; i < 3000; ++i) {
        TrajectoryLimits l = random_limits(rng, true);
        if (rng.chance(0.5)) l.deceleration = 0; // symmetric: every regime has a closed form
        const double V = l.velocity, A = l.acceleration, D = dec_of(l), J = l.jerk;
        const double target = -3 + rng.sign() * l.velocity * rng.log_uniform(1e-5, 1);
        const double d = std::fabs(target + 3);
        const double optimum = scurve_optimum(d, V, A, D, J);
        if (std::isnan(optimum)) continue;
        ++checked;
        const double ta = ramp_time(V, A, J), td = ramp_time(V, D, J);
        if (V * (ta + td) / 2 <= d) ++cruising;
        Trajectory tr;
        tr.reset(at_rest(-3));
        ASSERT_EQ(tr.move_to(target, l), TrajectoryResult::Ok);
        const double dt = optimum / 2000;
        const double t = busy_time(tr, dt, 2 * optimum);
        EXPECT_GE(t, optimum * (1 - 1e-9)) << "faster than optimal, case " << i;
        EXPECT_LE(t, optimum * 1.01 + dt) << "case " << i;
        if (V * (ta + td) / 2 > d) { // regime from the peak velocity 2 d / T
            if (d / optimum * 2 >= std::max(A, D) * std::max(A, D) / J)
                ++both;
            else
                ++neither;
        }
    }
    EXPECT_GT(checked, 2000);
    EXPECT_GT(cruising, 100);
    EXPECT_GT(both, 100);
    EXPECT_GT(neither, 100);
}

TEST(Trajectory, SCurveStopDistanceIsClosedForm) {
    // Cruising at v, a jerk-limited stop with deceleration D travels v/2 (v/D + D/J) when D is
    // reached (v >= D^2/J), else v sqrt(v/J).
    for (double v : {0.2, 4.0}) {
        Trajectory tr;
        tr.reset(at_rest(0));
        ASSERT_EQ(tr.move_velocity(v, limits(5, 2, 0, 10)), TrajectoryResult::Ok);
        for (int k = 0; k < 5000; ++k) (void)tr.step(0.001);
        ASSERT_EQ(tr.state().velocity, v);
        ASSERT_EQ(tr.state().acceleration, 0);
        const double p0 = tr.state().position;
        const double D = 1, J = 10;
        ASSERT_EQ(tr.stop(D, J), TrajectoryResult::Ok);
        const double expected = v >= D * D / J ? v / 2 * (v / D + D / J) : v * std::sqrt(v / J);
        EXPECT_NEAR(tr.target() - p0, expected, 1e-12);
        EXPECT_NEAR(busy_time(tr, 0.001, 100) * 0, 0, 1);
        EXPECT_NEAR(tr.state().position - p0, expected, 1e-12);
        EXPECT_EQ(tr.state().position, tr.target());
    }
}

TEST(Trajectory, VelocityModeThenHaltAndEmergencyStop) {
    for (bool smooth : {false, true}) {
        for (double emergency : {1.0, 10.0}) { // halt at D, emergency stop at 10 D
            const TrajectoryLimits l = limits(5, 10, 20, smooth ? 400 : 0);
            const double D = 20 * emergency, J = smooth ? 400 * emergency : 0;
            Trajectory tr;
            tr.reset(at_rest(2));
            Rng rng(9);
            Checker check;
            check.begin(l, tr.state());
            Drive drive{tr, check, rng};
            ASSERT_EQ(tr.move_velocity(-3, l), TrajectoryResult::Ok);
            ASSERT_TRUE(drive.run(1.0)) << check.failure;
            ASSERT_FALSE(drive.finished);
            EXPECT_TRUE(tr.busy());
            EXPECT_EQ(tr.state().velocity, -3); // held exactly
            EXPECT_EQ(tr.remaining(), kInf);
            EXPECT_EQ(tr.target(), tr.state().position); // ECMC: target follows in velocity mode
            const double p0 = tr.state().position;
            ASSERT_EQ(tr.stop(D, J), TrajectoryResult::Ok);
            check.lim.deceleration = D;
            check.lim.jerk = J;
            drive.elapsed = 0;
            const double v = 3; // stop travel: v^2/2D, jerk-limited as in SCurveStopDistance...
            const double expected = !smooth          ? v * v / (2 * D)
                                    : v >= D * D / J ? v / 2 * (v / D + D / J)
                                                     : v * std::sqrt(v / J);
            EXPECT_NEAR(tr.target() - p0, -expected, 1e-12);
            EXPECT_TRUE(drive.finish(tr.target(), time_bound(tr.state(), tr.target(), check.lim)))
                << check.failure;
            EXPECT_NEAR(tr.state().position - p0, -expected, 1e-12);
        }
    }
}

TEST(Trajectory, JogReversalAndVelocityClamp) {
    for (int i = 0; i < 4; ++i) {
        const bool smooth = i % 2;
        const double acc = i < 2 ? 10 : 30, dec = i < 2 ? 30 : 10; // reversal must use both
        const TrajectoryLimits l = limits(5, acc, dec, smooth ? 200 : 0);
        Trajectory tr;
        tr.reset(at_rest(0));
        Rng rng(10);
        Checker check;
        check.begin(l, tr.state());
        Drive drive{tr, check, rng};
        ASSERT_EQ(tr.move_velocity(4, l), TrajectoryResult::Ok);
        ASSERT_TRUE(drive.run(0.05)) << check.failure; // still accelerating
        ASSERT_GT(tr.state().acceleration, 0);
        ASSERT_EQ(tr.move_velocity(-100, l), TrajectoryResult::Ok); // clamped to -5
        ASSERT_TRUE(drive.run(3)) << check.failure;
        EXPECT_EQ(tr.state().velocity, -5);
        ASSERT_EQ(tr.move_velocity(0, l), TrajectoryResult::Ok);
        const double end = tr.target();
        drive.elapsed = 0;
        EXPECT_TRUE(drive.finish(end, 2)) << check.failure;
    }
}

namespace {

// A random sequence of commands at random times from a random state: positioning moves, jogs,
// halts and emergency stops (up to 10x deceleration and jerk, or no jerk limit), ending with a
// move, a halt, a jog to 0 or an emergency stop.
std::string random_commands(Rng& rng, bool smooth) {
    const TrajectoryLimits l = random_limits(rng, smooth);
    const TrajectoryState s0 = random_state(rng, l);
    Trajectory tr;
    tr.reset(s0);
    Checker check;
    check.begin(l, s0);
    Drive drive{tr, check, rng};
    const int commands = 1 + int(rng.uniform(0, 4));
    double target = 0, bound = 0;
    bool emergency = false;
    for (int k = 0; k < commands && !emergency; ++k) {
        const bool last = k == commands - 1;
        const TrajectoryState s = tr.state();
        check.lim = l;
        const double kind = rng.uniform(0, last ? 3 : 4);
        TrajectoryResult res;
        if (kind < 1) {
            target = s.position + rng.sign() * l.velocity * rng.log_uniform(1e-4, 0.3);
            res = tr.move_to(target, l);
        } else if (kind < 2) {
            const double gain = rng.chance(0.5) ? 1 : rng.uniform(1, 10);
            check.lim.deceleration = dec_of(l) * gain;
            check.lim.jerk = rng.chance(0.2) ? 0 : l.jerk * gain;
            res = tr.stop(check.lim.deceleration, check.lim.jerk);
            // Beyond the normal limits the state cannot be handed back to them (it may even have
            // to reverse): an emergency stop runs to standstill, as in ECMC.
            emergency = gain > 1 || check.lim.jerk != l.jerk;
        } else if (kind < 3) {
            res = tr.move_velocity(0, l);
        } else {
            res = tr.move_velocity(rng.uniform(-1.2, 1.2) * l.velocity, l);
        }
        if (res != TrajectoryResult::Ok) return "valid command rejected";
        if (kind >= 1) target = tr.target();
        bound = time_bound(s, target, check.lim);
        drive.elapsed = 0;
        drive.finished = !tr.busy(); // a halt when idle at rest plans nothing
        if (last || emergency) break;
        if (drive.finished) {
            if (!(tr.state().position == target)) return "idle off target";
            continue;
        }
        if (!drive.run(rng.uniform(0, 0.5) * std::min(bound, 0.2))) return check.failure;
    }
    if (drive.finished && tr.busy()) return "busy after a finished command";
    drive.finish(target, bound);
    return check.failure;
}

} // namespace

TEST(Trajectory, RandomCommandSequences) {
    expect_no_failures("command sequences", false, 15000, 31, random_commands);
    expect_no_failures("command sequences", true, 15000, 32, random_commands);
}

TEST(Trajectory, SCurveAccelerationIsUnimodalWithoutReversal) {
    // A jerk-limited move that never reverses speeds up at most once and slows down at most
    // once: along the direction of motion the acceleration has at most one maximum, followed by
    // at most one minimum. A decelerate-pause-decelerate notch would add a second minimum.
    Rng rng(17);
    int checked = 0;
    for (int i = 0; i < 20000; ++i) {
        const TrajectoryLimits l = random_limits(rng, true);
        const TrajectoryState s0 = random_state(rng, l);
        if (s0.velocity == 0) continue;
        const double dir = s0.velocity > 0 ? 1.0 : -1.0;
        // Targets around the stopping point, where softer braking and notches compete.
        const double stop = s0.velocity * s0.velocity / (2 * dec_of(l));
        const double target = s0.position + dir * stop * rng.uniform(0.5, 3);
        Trajectory tr;
        tr.reset(s0);
        ASSERT_EQ(tr.move_to(target, l), TrajectoryResult::Ok);
        const double eps = 1e-9 * std::max(l.acceleration, dec_of(l));
        double a_prev = dir * s0.acceleration;
        int trend = 0; // +1 rising, -1 falling
        std::string shape;
        bool reversed = false;
        while (tr.step(rng.uniform(kDtMin, kDtMax)) == TrajectoryResult::Working) {
            if (tr.state().velocity * dir < 0) reversed = true;
            const double a = dir * tr.state().acceleration, da = a - a_prev;
            a_prev = a;
            if (std::fabs(da) <= eps) continue;
            const int now = da > 0 ? 1 : -1;
            if (trend != 0 && now != trend) shape += now < 0 ? "max " : "min ";
            trend = now;
        }
        if (reversed) continue;
        ++checked;
        EXPECT_TRUE(shape == "" || shape == "max " || shape == "min " || shape == "max min ")
            << "case " << i << ": acceleration extrema " << shape;
    }
    EXPECT_GT(checked, 5000);
}

TEST(Trajectory, OvershootAndReturnWhenTargetTooClose) {
    for (bool smooth : {false, true}) {
        const TrajectoryLimits l = limits(10, 50, 25, smooth ? 500 : 0);
        Trajectory tr;
        tr.reset(at_rest(0));
        Rng rng(11);
        Checker check;
        check.begin(l, tr.state());
        Drive drive{tr, check, rng};
        ASSERT_EQ(tr.move_to(100, l), TrajectoryResult::Ok);
        ASSERT_TRUE(drive.run(1)) << check.failure;
        ASSERT_EQ(tr.state().velocity, 10); // cruising; stopping takes >= 2 units
        const double target = tr.state().position + 0.5;
        ASSERT_EQ(tr.move_to(target, l), TrajectoryResult::Ok);
        double furthest = -kInf;
        bool came_back = false;
        while (!drive.finished) {
            ASSERT_TRUE(drive.run(kDtMax)) << check.failure;
            furthest = std::max(furthest, tr.state().position);
            came_back = came_back || tr.state().velocity < 0;
        }
        // Braking at most at D travels v^2/2D = 2 > 0.5 (sampled: up to D dt^2 short of the peak).
        EXPECT_GE(furthest, target + 1.5 - 1e-4);
        EXPECT_TRUE(came_back);
        EXPECT_EQ(tr.state().position, target);
    }
}

TEST(Trajectory, RetargetToSameTargetChangesNothing) {
    // Replanning mid-move to the same target from the current state must continue the same
    // (optimal) motion: same arrival time, same positions.
    Rng rng(12);
    for (int i = 0; i < 400; ++i) {
        const bool smooth = i % 2;
        const TrajectoryLimits l = random_limits(rng, smooth);
        const double target = l.velocity * rng.uniform(-0.5, 0.5);
        Trajectory a, b;
        a.reset(at_rest(0));
        ASSERT_EQ(a.move_to(target, l), TrajectoryResult::Ok);
        b = a;
        const double total = a.remaining(), dt = total / 500.5; // no step ends on the end
        const int at = int(rng.uniform(1, 499));
        double worst = 0;
        for (int k = 1; k <= 501; ++k) {
            if (k == at) {
                ASSERT_EQ(b.move_to(target, l), TrajectoryResult::Ok);
            }
            (void)a.step(dt);
            (void)b.step(dt);
            worst = std::max(worst, std::fabs(a.state().position - b.state().position));
        }
        EXPECT_LE(worst, 1e-9 * std::max(std::fabs(target), l.velocity * dt)) << "case " << i;
        EXPECT_EQ(a.busy(), b.busy()) << "case " << i;
    }
}

TEST(Trajectory, LoweredVelocityLimitMidMove) {
    // Deterministic: lowered while cruising, the speed falls monotonically to the new limit at the
    // deceleration limit and never exceeds it afterwards.
    for (bool smooth : {false, true}) {
        const TrajectoryLimits fast = limits(10, 40, 20, smooth ? 400 : 0);
        TrajectoryLimits slow = fast;
        slow.velocity = 4;
        Trajectory tr;
        tr.reset(at_rest(0));
        Rng rng(13);
        Checker check;
        check.begin(fast, tr.state());
        Drive drive{tr, check, rng};
        ASSERT_EQ(tr.move_to(50, fast), TrajectoryResult::Ok);
        ASSERT_TRUE(drive.run(1)) << check.failure;
        ASSERT_EQ(tr.state().velocity, 10);
        ASSERT_EQ(tr.move_to(50, slow), TrajectoryResult::Ok);
        check.lim = slow;
        check.max_speed = 10;
        double v_prev = 10;
        drive.elapsed = 0;
        while (tr.state().velocity > 4) {
            ASSERT_TRUE(drive.run(kDtMin)) << check.failure; // one step
            EXPECT_LE(tr.state().velocity, v_prev);
            v_prev = tr.state().velocity;
            ASSERT_LT(drive.elapsed, 1.0);
        }
        EXPECT_GE(drive.elapsed, 6.0 / 20); // 10 -> 4 not faster than the deceleration limit
        EXPECT_LE(drive.elapsed, 6.0 / 20 + (smooth ? 20.0 / 400 : 0) + kDtMax); // but promptly
        check.max_speed = 4;
        drive.elapsed = 0;
        EXPECT_TRUE(drive.finish(50, time_bound(tr.state(), 50, slow))) << check.failure;
    }
    // Random: lowered at a random time of a random move (accelerating too: then the speed may
    // first rise by a^2/2J while the acceleration is brought down).
    Rng rng(14);
    for (int i = 0; i < 4000; ++i) {
        const bool smooth = i % 2;
        const TrajectoryLimits l = random_limits(rng, smooth);
        TrajectoryLimits slow = l;
        slow.velocity *= rng.uniform(0.05, 0.95);
        Trajectory tr;
        tr.reset(at_rest(0));
        Checker check;
        check.begin(l, tr.state());
        Drive drive{tr, check, rng};
        const double target = rng.sign() * l.velocity * rng.log_uniform(0.01, 1);
        ASSERT_EQ(tr.move_to(target, l), TrajectoryResult::Ok);
        ASSERT_TRUE(drive.run(rng.uniform(0, 0.7) * tr.remaining())) << check.failure;
        if (drive.finished) continue;
        const TrajectoryState s = tr.state();
        ASSERT_EQ(tr.move_to(target, slow), TrajectoryResult::Ok);
        const double J = l.jerk, D = dec_of(l), a = std::fabs(s.acceleration);
        const double peak = std::fabs(s.velocity) + (smooth ? a * a / (2 * J) : 0);
        const double settle =
            (smooth ? a / J + D / J : 0) + std::max(0.0, peak - slow.velocity) / D;
        check.lim = slow;
        check.max_speed = std::max(peak, slow.velocity);
        drive.elapsed = 0;
        ASSERT_TRUE(drive.run(settle + kDtMax)) << "case " << i << ": " << check.failure;
        check.max_speed = slow.velocity;
        EXPECT_TRUE(drive.finish(target, time_bound(s, target, slow)))
            << "case " << i << ": " << check.failure;
    }
}

TEST(Trajectory, InvalidInputIsRejectedAndChangesNothing) {
    const TrajectoryLimits good = limits(5, 10, 0, 100);
    const double nan = std::nan(""), inf = kInf;
    std::vector<TrajectoryLimits> bad;
    for (double x : {0.0, -1.0, nan, inf}) {
        bad.push_back({x, 10, 0, 100});
        bad.push_back({5, x, 0, 100});
        if (x != 0) bad.push_back({5, 10, x, 100});
        if (x != 0) bad.push_back({5, 10, 0, x});
    }
    Trajectory tr;
    tr.reset(at_rest(1));
    ASSERT_EQ(tr.move_to(3, good), TrajectoryResult::Ok);
    for (int k = 0; k < 100; ++k) (void)tr.step(0.001); // mid-move
    // The motion after rejected commands is bitwise the one without them.
    Trajectory with = tr, without = tr;
    for (const TrajectoryLimits& l : bad) {
        EXPECT_EQ(with.move_to(0, l), TrajectoryResult::InvalidLimits);
        EXPECT_EQ(with.move_velocity(-1, l), TrajectoryResult::InvalidLimits);
    }
    EXPECT_EQ(with.move_to(nan, good), TrajectoryResult::InvalidTarget);
    EXPECT_EQ(with.move_to(-inf, good), TrajectoryResult::InvalidTarget);
    EXPECT_EQ(with.move_velocity(nan, good), TrajectoryResult::InvalidTarget);
    for (double d : {0.0, -1.0, nan, inf}) EXPECT_EQ(with.stop(d), TrajectoryResult::InvalidLimits);
    for (double j : {-1.0, nan, inf}) EXPECT_EQ(with.stop(10, j), TrajectoryResult::InvalidLimits);
    EXPECT_EQ(with.target(), 3);
    for (;;) {
        TrajectoryResult a = with.step(0.001), b = without.step(0.001);
        ASSERT_EQ(a, b);
        ASSERT_EQ(with.state().position, without.state().position);
        ASSERT_EQ(with.state().velocity, without.state().velocity);
        ASSERT_EQ(with.state().acceleration, without.state().acceleration);
        if (a != TrajectoryResult::Working) break;
    }
    EXPECT_EQ(with.state().position, 3);
    // Rejected commands do not start an idle trajectory.
    Trajectory idle;
    idle.reset(at_rest(4));
    for (const TrajectoryLimits& l : bad)
        EXPECT_EQ(idle.move_to(0, l), TrajectoryResult::InvalidLimits);
    EXPECT_EQ(idle.move_to(nan, good), TrajectoryResult::InvalidTarget);
    EXPECT_FALSE(idle.busy());
    EXPECT_EQ(idle.step(0.001), TrajectoryResult::Ok);
    EXPECT_EQ(idle.state().position, 4);
}

TEST(Trajectory, IdleAndZeroLengthCommands) {
    Trajectory tr;
    tr.reset(at_rest(7.25));
    EXPECT_FALSE(tr.busy());
    EXPECT_EQ(tr.step(0.001), TrajectoryResult::Ok);
    EXPECT_EQ(tr.stop(10), TrajectoryResult::Ok); // nothing to stop
    EXPECT_FALSE(tr.busy());
    EXPECT_EQ(tr.remaining(), 0);
    // A move to where it stands completes on the next step (a done edge for the axis).
    ASSERT_EQ(tr.move_to(7.25, limits(1, 1, 0, 1)), TrajectoryResult::Ok);
    EXPECT_TRUE(tr.busy());
    EXPECT_EQ(tr.step(0.001), TrajectoryResult::Finished);
    EXPECT_EQ(tr.state().position, 7.25);
    EXPECT_EQ(tr.step(0.001), TrajectoryResult::Ok);
    // A non-positive or non-finite dt does not advance.
    ASSERT_EQ(tr.move_to(8, limits(1, 1, 0, 1)), TrajectoryResult::Ok);
    for (double dt : {0.0, -1.0, std::nan(""), kInf}) {
        EXPECT_EQ(tr.step(dt), TrajectoryResult::Working);
        EXPECT_EQ(tr.state().position, 7.25);
    }
    // A moving state adopted by reset() is the start of the next command.
    tr.reset({0, 2, 0});
    EXPECT_FALSE(tr.busy());
    ASSERT_EQ(tr.stop(4), TrajectoryResult::Ok);
    EXPECT_DOUBLE_EQ(tr.target(), 0.5); // v^2 / 2D
    EXPECT_NEAR(busy_time(tr, 0.0001, 1), 0.5, 0.0002);
    EXPECT_EQ(tr.state().position, tr.target());
}

TEST(Trajectory, PlanningAndSteppingDoNotAllocate) {
    Rng rng(15);
    Trajectory tr;
    tr.reset(at_rest(0));
    test::count_allocations(true);
    for (int i = 0; i < 2000; ++i) {
        const TrajectoryLimits l = random_limits(rng, i % 2);
        if (i % 3 == 0)
            (void)tr.move_velocity(rng.uniform(-1, 1) * l.velocity, l);
        else if (i % 7 == 0)
            (void)tr.stop(dec_of(l), l.jerk);
        else
            (void)tr.move_to(rng.uniform(-1, 1) * l.velocity, l);
        for (int k = 0; k < 20; ++k) (void)tr.step(0.0005);
    }
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
}

TEST(Trajectory, ModuloTargets) {
    // ECMC modulo types: 0 normal, 1 forward, 2 backward, 3 closest; range 360.
    struct Case {
        double current, target;
        int type;
        double expected;
    };
    const Case cases[] = {
        {10, 350, 0, 350},    {350, 10, 0, 10},   // normal: within the turn, no wrap
        {10, 350, 1, 350},    {350, 10, 1, 370},  // forward: wraps forward
        {10, 350, 2, -10},    {350, 10, 2, 10},   // backward: wraps backward
        {10, 350, 3, -10},    {350, 10, 3, 370},  // closest: the short way
        {100, 280, 3, 280},   {280, 100, 3, 460}, // tie (180 both ways): forward
        {730, 20, 0, 740},    {730, 5, 0, 725},   // current in its third turn
        {730, 5, 1, 1085},    {730, 5, 2, 725},   {730, 5, 3, 725},
        {-350, 355, 3, -365}, {-350, -5, 1, -5},  // negative currents and targets
        {-10, 3610, 1, 10},   {-10, -725, 0, -5}, // targets outside [0, range)
        {45, 405, 1, 45},     {45, 45, 2, 45},    {45, -315, 3, 45}, // same place: no move
    };
    for (const Case& c : cases) {
        EXPECT_DOUBLE_EQ(modulo_target(c.current, c.target, 360, c.type), c.expected)
            << "current " << c.current << " target " << c.target << " type " << c.type;
    }
    // No move means bitwise the current position, even many turns out.
    for (int type = 0; type < 4; ++type)
        EXPECT_EQ(modulo_target(1e6 + 0.1, 1e6 + 0.1 - 100.0 * 360, 360, type), 1e6 + 0.1);
    // A target a hair behind the 0/range seam maps into [0, range), not onto range.
    EXPECT_DOUBLE_EQ(modulo_target(0, -1e-300, 360, 0), 0);
    EXPECT_EQ(modulo_target(5, 1234.5, 0, 1), 1234.5); // range 0: modulo off
    EXPECT_TRUE(std::isnan(modulo_target(5, 10, -360, 0)));
    EXPECT_TRUE(std::isnan(modulo_target(5, 10, 360, 4)));
    EXPECT_TRUE(std::isnan(modulo_target(5, std::nan(""), 360, 0)));
    Trajectory tr;
    EXPECT_EQ(tr.move_to(modulo_target(5, 10, 360, 7), limits(1, 1, 0, 0)),
              TrajectoryResult::InvalidTarget);
    // Random: the result is congruent to the target, within one turn of current, in the
    // direction the type asks for.
    Rng rng(16);
    for (int i = 0; i < 10000; ++i) {
        const double range = rng.log_uniform(0.1, 1000);
        const double cur = rng.uniform(-5, 5) * range, tgt = rng.uniform(-5, 5) * range;
        const int type = int(rng.uniform(0, 4));
        const double r = modulo_target(cur, tgt, range, type);
        const double tol = 1e-12 * 10 * range;
        double off = std::fmod(r - tgt, range);
        off = std::min(std::fabs(off), range - std::fabs(off));
        ASSERT_LE(off, tol) << "not congruent, case " << i;
        ASSERT_LT(std::fabs(r - cur), range + tol);
        if (type == 1) {
            ASSERT_GE(r, cur);
        } else if (type == 2) {
            ASSERT_LE(r, cur);
        } else if (type == 3) {
            ASSERT_LE(std::fabs(r - cur), range / 2 + tol);
        } else { // stays within the turn [k range, (k+1) range) of current
            ASSERT_EQ(std::floor(cur / range), std::floor((r - tol * (r > cur)) / range))
                << "case " << i;
        }
    }
}
