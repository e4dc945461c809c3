#include "ethercat/sim/plant.hpp"

#include "ethercat/sim/faults.hpp"

#include "ethercat/sim/segment.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace beamctl::ethercat::sim {

namespace {
// Velocity loop of a drive: PI on the velocity error, i.e. stiffness on the following error
// (integral of the velocity error) plus damping, critically damped at kLoopHz.
constexpr double kLoopHz = 100;
constexpr double kOmega = 2 * std::numbers::pi * kLoopHz;
constexpr double kMmPerM = 1000; // stage units are read as mm in F = m a
} // namespace

// ---- switches -------------------------------------------------------------------------------

bool SwitchModel::active(double x) const noexcept {
    switch (kind) {
    case Kind::Forward: return x >= at;
    case Kind::Backward: return x <= at;
    case Kind::Home: return std::fabs(x - at) <= width / 2;
    }
    return false;
}

void SwitchModel::update(Segment& seg, double x) const noexcept {
    input.set(seg, active(x) != normally_closed ? 1 : 0);
}

// ---- stage ----------------------------------------------------------------------------------

Stage::Stage(StageParams p, std::unique_ptr<DriveTerminal> drive)
    : p_(std::move(p)), drive_(std::move(drive)), x_(std::clamp(p_.start, p_.min, p_.max)) {}

void Stage::set_position(double x) noexcept {
    x_ = std::clamp(x, p_.min, p_.max);
    v_ = 0;
    lag_ = 0;
}

void Stage::integrate(const DriveCommand& c, double dt) noexcept {
    if (dt <= 0) return;
    const double m = p_.mass / kMmPerM; // N per (unit/s^2)
    double force = 0;
    saturated_ = false;
    if (c.powered) {
        lag_ += (c.velocity - v_) * dt; // following error [units]
        double want = m * (kOmega * kOmega * lag_ + 2 * kOmega * (c.velocity - v_));
        if (std::fabs(want) > c.force_limit) {
            saturated_ = true;
            force = std::copysign(c.force_limit, want);
            // anti-windup (a stepper slips, a servo's integrator clamps): keep the stiffness
            // term within what the motor can push
            double lag_max = c.force_limit / (m * kOmega * kOmega);
            lag_ = std::clamp(lag_, -lag_max, lag_max);
        } else {
            force = want;
        }
    } else {
        lag_ = 0;
    }
    // Friction: dry friction holds the stage until the force exceeds it; viscous ~ v.
    double v = v_;
    if (v == 0 && std::fabs(force) <= p_.friction) {
        v = 0;
    } else {
        double dir = v != 0 ? std::copysign(1.0, v) : std::copysign(1.0, force);
        double a = (force - dir * p_.friction - p_.damping * v) / m;
        double nv = v + a * dt;
        if (v != 0 && std::signbit(nv) != std::signbit(v) && std::fabs(force) <= p_.friction) nv = 0; // came to rest
        v = nv;
    }
    double x = x_ + v * dt;
    if (x <= p_.min) { // hard stop
        x = p_.min;
        if (v < 0) v = 0;
    } else if (x >= p_.max) {
        x = p_.max;
        if (v > 0) v = 0;
    }
    x_ = x;
    v_ = v;
}

// ---- signals --------------------------------------------------------------------------------

double SignalModel::volts(double t, std::mt19937_64& rng) const noexcept {
    double arg = 2 * std::numbers::pi * frequency * t + phase * std::numbers::pi / 180;
    double v = offset;
    switch (shape) {
    case Shape::Constant: break;
    case Shape::Sine: v += amplitude * std::sin(arg); break;
    case Shape::Square: v += amplitude * (std::sin(arg) >= 0 ? 1 : -1); break;
    case Shape::Ramp: {
        double cyc = frequency * t + phase / 360;
        v += amplitude * (2 * (cyc - std::floor(cyc)) - 1);
        break;
    }
    case Shape::Noise: v += amplitude * std::normal_distribution<double>(0, 1)(rng); break;
    case Shape::StagePosition: v += gain * (stage ? stage->position() : 0); break;
    case Shape::Beam: v += gain * (beam ? beam->diode(diode, t) : 0); break;
    }
    if (noise > 0) v += noise * std::normal_distribution<double>(0, 1)(rng);
    return v;
}

// ---- plant ----------------------------------------------------------------------------------

Stage* Plant::find_stage(const std::string& name) {
    for (auto& s : stages_)
        if (s->params().name == name) return s.get();
    return nullptr;
}

void Plant::entered_op(Segment& seg) {
    if (was_op_.size() != stages_.size()) was_op_.assign(stages_.size(), 0); // first frame only
    for (std::size_t i = 0; i < stages_.size(); ++i) {
        DriveTerminal* d = stages_[i]->drive();
        bool op = d && seg.slave(std::size_t(d->slave())).al_state() == kOp;
        if (op && !was_op_[i]) d->entered_op(seg); // reads CoE parameters (may allocate; once)
        was_op_[i] = op;
    }
}

void Plant::step(Segment& seg) noexcept {
    uint64_t now = seg.time();
    double dt = 0;
    if (!started_) started_ = true;
    else if (now > last_ns_) dt = std::min(double(now - last_ns_) * 1e-9, kMaxGap);
    last_ns_ = now;
    if (dt > 0) ++steps;
    try {
        entered_op(seg);
    } catch (...) { // a failed CoE read leaves the drive's defaults
    }
    for (auto& sp : stages_) {
        Stage& st = *sp;
        DriveTerminal* d = st.drive();
        DriveCommand c = d ? d->command(seg, dt, st.position()) : DriveCommand{};
        if (dt > 0) {
            int n = int(std::ceil(dt / kMaxSubstep));
            for (int k = 0; k < n; ++k) st.integrate(c, dt / n);
        }
        if (d) d->report(seg, DriveFeedback{st.velocity(), st.saturated(), dt});
        for (auto& e : st.encoders) e.update(seg, st.position());
        for (auto& s : st.switches) s.update(seg, st.position());
    }
    t_ += dt;
    if (beam) beam->update(seg, t_, dt);
    for (auto& s : signals) {
        // An oversampling channel takes its n samples at its SYNC0 events across the step.
        unsigned n = s.channel->samples(seg);
        for (unsigned k = 0; k < n; ++k)
            s.channel->set_volts(seg, s.volts(t_ - dt + dt * double(k + 1) / double(n), rng_), dt > 0, k);
    }
    for (auto& t : timed_outputs) t->update(seg);
    for (auto& w : wires) {
        if (w.timed) {
            w.to.set(seg, w.timed->level[w.timed_channel]);
            continue;
        }
        unsigned n = std::min(w.from.samples(seg), w.to.samples(seg)); // oversampled ends: every sample
        for (unsigned k = 0; k < n; ++k) w.to.sample(k).set(seg, w.from.sample(k).get(seg));
    }
    if (dt > 0)
        for (auto& c : cycle_counters) c.update(seg);
    for (auto& l : latches) l.update(seg);
    for (auto& b : bridges) b->step(seg);
}

bool Plant::apply_fault(const Fault& f) noexcept {
    for (auto& st : stages_) {
        if (f.kind == Fault::Kind::DriveFault && st->drive() && st->drive()->slave() == f.position) {
            st->drive()->inject_fault();
            return true;
        }
        if (f.kind == Fault::Kind::Glitch)
            for (auto& e : st->encoders)
                if (e.slave() == f.position) {
                    e.glitch(f.counts);
                    return true;
                }
    }
    return false;
}

} // namespace beamctl::ethercat::sim
