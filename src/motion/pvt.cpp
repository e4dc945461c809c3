#include "motion/pvt.hpp"

#include "core/error.hpp"
#include "motion/axis.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::motion {

// ---- path -----------------------------------------------------------------------------------

PvtPath PvtPath::build(const std::vector<double>& pos, const std::vector<double>& dt, double ta) {
    const std::size_t n = pos.size();
    if (n < 2) throw Error(SB() << n << " point(s): a profile needs at least 2");
    if (dt.size() + 1 < n) throw Error(SB() << dt.size() << " segment time(s) for " << n << " points (need " << n - 1 << ")");
    if (!(ta > 0) || !std::isfinite(ta)) throw Error(SB() << "acceleration time " << ta << " s: it should be > 0");
    for (std::size_t i = 0; i < n; ++i)
        if (!std::isfinite(pos[i])) throw Error(SB() << "position " << i + 1 << " is not a number");
    for (std::size_t i = 0; i + 1 < n; ++i)
        if (!(dt[i] > 0) || !std::isfinite(dt[i])) throw Error(SB() << "time " << i + 1 << " is " << dt[i] << " s: it should be > 0");
    // ECMC (ecmcMotorRecordAxis::buildProfile): segment velocities v_i = (P[i+1]-P[i])/dt_i;
    // interior points take the mean of their two segments'; the first and last real points their
    // own segment's; a ramp of Ta from/to standstill before and after.
    std::vector<double> v(n - 1);
    for (std::size_t i = 0; i + 1 < n; ++i) v[i] = (pos[i + 1] - pos[i]) / dt[i];
    PvtPath p;
    p.pts_.reserve(n + 2);
    p.pts_.push_back({0, pos[0] - v[0] * ta / 2, 0});
    double t = ta;
    for (std::size_t i = 0; i < n; ++i) {
        double vel = i == 0 ? v[0] : i == n - 1 ? v[n - 2] : (v[i - 1] + v[i]) / 2;
        p.pts_.push_back({t, pos[i], vel});
        if (i + 1 < n) t += dt[i];
    }
    p.pts_.push_back({t + ta, pos[n - 1] + v[n - 2] * ta / 2, 0});
    return p;
}

void PvtPath::eval(double t, std::size_t& seg, double& p, double& v, double& a) const noexcept {
    if (pts_.size() < 2) {
        p = pts_.empty() ? 0 : pts_[0].p, v = a = 0;
        return;
    }
    t = std::clamp(t, 0.0, end_time());
    if (seg + 1 >= pts_.size()) seg = 0;
    while (seg + 2 < pts_.size() && t > pts_[seg + 1].t) ++seg;
    while (seg > 0 && t < pts_[seg].t) --seg;
    const Point& s = pts_[seg];
    const Point& e = pts_[seg + 1];
    double T = e.t - s.t, tau = t - s.t;
    if (!(T > 0)) {
        p = e.p, v = e.v, a = 0;
        return;
    }
    // cubic Hermite: p(tau) = k0 + k1 tau + k2 tau^2 + k3 tau^3 with p, v given at both ends
    double d = e.p - s.p;
    double k2 = 3 * d / (T * T) - (2 * s.v + e.v) / T;
    double k3 = -2 * d / (T * T * T) + (s.v + e.v) / (T * T);
    p = s.p + tau * (s.v + tau * (k2 + tau * k3));
    v = s.v + tau * (2 * k2 + 3 * k3 * tau);
    a = 2 * k2 + 6 * k3 * tau;
}

void PvtPath::extremes(double step, double& pmin, double& pmax, double& vmax) const noexcept {
    pmin = pmax = pts_.empty() ? 0 : pts_[0].p;
    vmax = 0;
    std::size_t seg = 0;
    auto look = [&](double t) {
        double p = 0, v = 0, a = 0;
        eval(t, seg, p, v, a);
        pmin = std::min(pmin, p), pmax = std::max(pmax, p), vmax = std::max(vmax, std::fabs(v));
    };
    double end = end_time();
    step = step > 0 ? std::max(step, end / 1e6) : end / 1000;
    std::size_t k = 0;
    for (double t = 0; t < end && step > 0; t = double(++k) * step) look(t);
    seg = 0;
    for (const Point& pt : pts_) look(pt.t);
}

// ---- controller -----------------------------------------------------------------------------

PvtController::Status PvtController::status() const noexcept {
    Status s;
    s.state = state_.load(std::memory_order_acquire);
    s.result = result_.load(std::memory_order_acquire);
    s.why = why_.load(std::memory_order_acquire);
    s.axis = fail_axis_.load(std::memory_order_relaxed);
    s.id = fail_id_.load(std::memory_order_relaxed);
    s.current_point = current_point_.load(std::memory_order_relaxed);
    s.pulses = pulses_.load(std::memory_order_relaxed);
    s.runs = runs_.load(std::memory_order_acquire);
    return s;
}

void PvtController::stop_all() noexcept {
    for (std::size_t k = 0; k < job_.n; ++k) {
        Axis& ax = *job_.axes[k].axis;
        if (ax.status().busy) {
            AxisCommand h{CommandType::Halt};
            (void)ax.command(h);
        }
    }
}

void PvtController::fail(Why why, std::size_t k, uint32_t id) noexcept {
    why_.store(why, std::memory_order_relaxed);
    fail_axis_.store(k < job_.n ? job_.axes[k].index : -1, std::memory_order_relaxed);
    fail_id_.store(id, std::memory_order_relaxed);
    stop_all();
    pending_result_ = Result::Failure;
    st_ = State::Stopping;
}

void PvtController::finish(Result r) noexcept {
    if (trigger_.bound()) trigger_.set(0);
    pulse_high_ = false;
    st_ = State::Idle;
    result_.store(r, std::memory_order_release);
    runs_.fetch_add(1, std::memory_order_release);
}

// Readbacks (actual position, following error) into each axis's buffer, at most k_limit samples.
void PvtController::sample(std::size_t k_limit) noexcept {
    for (std::size_t k = 0; k < job_.n; ++k) {
        AxisJob& j = job_.axes[k];
        if (!j.count) continue;
        uint32_t c = j.count->load(std::memory_order_relaxed);
        if (c >= j.capacity || c >= k_limit) continue;
        const AxisStatus& s = j.axis->status();
        if (j.readback) j.readback[c] = s.act_pos;
        if (j.ferror) j.ferror[c] = s.pos_err;
        j.count->store(c + 1, std::memory_order_release);
    }
}

void PvtController::pulses_and_readbacks() noexcept {
    if (job_.pulses == 0) { // a readback at every point, when the path reaches it
        const PvtPath& p = *job_.axes[0].path;
        while (next_point_ < p.real_points() && t_ >= p.point_time(next_point_) - dt_ / 2) {
            sample(p.real_points());
            ++next_point_;
        }
        return;
    }
    // ECMC's trigger: pulse k at start_t + k*between (k < pulses), high for duration_s; a
    // readback at each rising edge.
    while (pulse_id_ < job_.pulses && t_ >= job_.start_t + double(pulse_id_) * job_.between - dt_ / 2) {
        high_until_ = job_.start_t + double(pulse_id_) * job_.between + std::max(job_.duration_s, dt_);
        ++pulse_id_;
        pulses_.fetch_add(1, std::memory_order_relaxed);
        sample(job_.pulses);
    }
    bool high = pulse_id_ > 0 && t_ < high_until_ - dt_ / 2;
    pulse_high_ = high;
    if (trigger_.bound()) trigger_.set(high ? 1 : 0);
}

void PvtController::run(const rt::CycleInfo&) noexcept {
    Cmd cmd;
    while (cmds_.pop(cmd)) {
        if (cmd.kind == Cmd::Abort) {
            if (st_ == State::Idle) continue;
            why_.store(Why::None, std::memory_order_relaxed);
            stop_all();
            pending_result_ = Result::Abort;
            st_ = State::Stopping;
        } else if (st_ == State::Idle && cmd.job.n > 0) {
            job_ = cmd.job;
            result_.store(Result::Undefined, std::memory_order_relaxed);
            why_.store(Why::None, std::memory_order_relaxed);
            fail_axis_.store(-1, std::memory_order_relaxed);
            fail_id_.store(0, std::memory_order_relaxed);
            pulses_.store(0, std::memory_order_relaxed);
            current_point_.store(0, std::memory_order_relaxed);
            for (std::size_t k = 0; k < job_.n; ++k)
                if (job_.axes[k].count) job_.axes[k].count->store(0, std::memory_order_relaxed);
            t_ = waited_ = 0;
            next_point_ = 0;
            pulse_id_ = 0;
            pulse_high_ = false;
            st_ = State::EnableAxes;
        }
    }
    switch (st_) {
    case State::Idle: break;
    case State::EnableAxes: { // enable what is not; an axis in error stops it all
        bool all = true;
        for (std::size_t k = 0; k < job_.n; ++k) {
            Axis& ax = *job_.axes[k].axis;
            if (ax.status().error_id) {
                fail(Why::AxisError, k, ax.status().error_id);
                break;
            }
            if (!ax.status().enable_cmd) {
                AxisCommand on{CommandType::Power};
                on.on = true;
                (void)ax.command(on);
            }
            all = all && ax.status().enabled;
        }
        if (st_ != State::EnableAxes) break;
        waited_ += dt_;
        if (all) st_ = State::MoveToStart;
        else if (waited_ > job_.enable_timeout_s) fail(Why::EnableTimeout, 0, error_id::kNotEnabled);
        break;
    }
    case State::MoveToStart: // each axis to the point Ta before its first position
        for (std::size_t k = 0; k < job_.n; ++k) {
            Axis& ax = *job_.axes[k].axis;
            offset_[k] = job_.relative ? ax.status().set_pos : 0;
            start_[k] = job_.axes[k].path->start_position() + offset_[k];
            AxisCommand mv{CommandType::MoveAbsolute, start_[k]};
            if (uint32_t id = ax.command(mv)) {
                fail(Why::StartRefused, k, id);
                break;
            }
        }
        if (st_ == State::MoveToStart) st_ = State::WaitAtStart;
        break;
    case State::WaitAtStart: {
        bool all = true;
        for (std::size_t k = 0; k < job_.n && st_ == State::WaitAtStart; ++k) {
            const AxisStatus& s = job_.axes[k].axis->status();
            if (s.error_id) fail(Why::AxisError, k, s.error_id);
            else if (!s.busy && (s.move_failed || std::fabs(s.set_pos - start_[k]) > 1e-9 * std::max(1.0, std::fabs(start_[k]))))
                fail(Why::StartMissed, k, s.warning_id);
            all = all && !s.busy;
        }
        if (st_ != State::WaitAtStart || !all) break;
        for (std::size_t k = 0; k < job_.n; ++k) // every path starts in this same cycle
            if (uint32_t id = job_.axes[k].axis->start_pvt(job_.axes[k].path, offset_[k])) {
                fail(Why::PathRefused, k, id);
                break;
            }
        if (st_ != State::WaitAtStart) break;
        t_ = 0;
        point_ = 0;
        st_ = State::Executing;
        break;
    }
    case State::Executing: {
        // The axes ran this cycle's step of their paths (they run before this stage): the time
        // they are at now is t_ + dt.
        t_ += dt_;
        bool running = false;
        for (std::size_t k = 0; k < job_.n; ++k) {
            const AxisStatus& s = job_.axes[k].axis->status();
            Axis& ax = *job_.axes[k].axis;
            if (ax.in_pvt()) {
                running = true;
                continue;
            }
            if (s.move_failed || s.error_id || t_ + dt_ / 2 < job_.axes[k].path->end_time()) {
                fail(Why::EndedShort, k, s.error_id ? s.error_id : s.warning_id);
                break;
            }
        }
        if (st_ != State::Executing) break;
        const PvtPath& p = *job_.axes[0].path;
        while (point_ < p.real_points() && t_ >= p.point_time(point_)) ++point_; // cursor: t only grows
        current_point_.store(int32_t(point_), std::memory_order_relaxed);
        pulses_and_readbacks();
        if (!running) finish(Result::Success);
        break;
    }
    case State::Stopping: { // the axes ramp down; the result once they stand
        bool any = false;
        for (std::size_t k = 0; k < job_.n; ++k) any = any || job_.axes[k].axis->status().busy;
        if (!any) finish(pending_result_);
        break;
    }
    }
    state_.store(st_, std::memory_order_release);
}

} // namespace beamctl::motion
