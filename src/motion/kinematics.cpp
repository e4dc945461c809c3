#include "motion/kinematics.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::motion {
namespace {

double tolerance(double limit) { return 1e-9 * std::max(1.0, std::fabs(limit)); }


// The target of a motion command as Axis::command() will compute it; false for commands that have
// no target (velocity, homing): those are supervised while they run.
bool target_of(const Axis& a, const AxisCommand& c, double& target) {
    const AxisStatus& s = a.status();
    switch (c.type) {
    case CommandType::MoveAbsolute: target = c.position; return true;
    case CommandType::MoveRelative: {
        bool chained = s.busy && s.command == CommandType::MoveRelative && !s.following;
        target = (chained ? s.target_pos : s.set_pos) + c.position;
        return true;
    }
    default: return false;
    }
}

bool is_motion(CommandType t) {
    return t == CommandType::MoveAbsolute || t == CommandType::MoveRelative || t == CommandType::MoveVelocity ||
           t == CommandType::Home;
}

} // namespace

RealLimits real_limits(const AxisParams& p, const AxisStatus& s) noexcept {
    RealLimits l;
    l.soft_fwd_enable = p.soft_fwd_enable;
    l.soft_bwd_enable = p.soft_bwd_enable;
    l.soft_fwd = p.soft_fwd;
    l.soft_bwd = p.soft_bwd;
    l.switch_fwd = s.limit_fwd;
    l.switch_bwd = s.limit_bwd;
    l.position = s.set_pos;
    return l;
}

uint32_t real_violation(const RealLimits& l, double x, double* limit) noexcept {
    if (!std::isfinite(x)) {
        if (limit) *limit = NAN;
        return error_id::kSoftLimitFwd;
    }
    const double cur = l.position;
    if (x > cur + tolerance(cur)) {
        if (l.switch_fwd) {
            if (limit) *limit = cur;
            return error_id::kHardLimitFwd;
        }
        if (l.soft_fwd_enable && x > l.soft_fwd + tolerance(l.soft_fwd)) {
            if (limit) *limit = l.soft_fwd;
            return error_id::kSoftLimitFwd;
        }
    } else if (x < cur - tolerance(cur)) {
        if (l.switch_bwd) {
            if (limit) *limit = cur;
            return error_id::kHardLimitBwd;
        }
        if (l.soft_bwd_enable && x < l.soft_bwd - tolerance(l.soft_bwd)) {
            if (limit) *limit = l.soft_bwd;
            return error_id::kSoftLimitBwd;
        }
    }
    return 0;
}

Kinematics::Kinematics(KinematicsSpec spec, std::unique_ptr<Inverse> inverse)
    : spec_(std::move(spec)), inverse_(std::move(inverse)) {
    start_.assign(spec_.virt.size(), 0);
    end_.assign(spec_.virt.size(), 0);
    pose_.assign(spec_.virt.size(), 0);
    real_.assign(spec_.real.size(), 0);
    limits_.assign(spec_.real.size(), RealLimits{});
}

KinematicsVerdict Kinematics::check(std::span<const std::unique_ptr<Axis>> axes, std::size_t index,
                                    const AxisCommand& c) noexcept {
    KinematicsVerdict v;
    if (!is_motion(c.type)) return v;
    // Real axes that cannot follow: the move is refused with their reason.
    for (std::size_t k = 0; k < spec_.real.size(); ++k) {
        const AxisStatus& s = axes[spec_.real[k]]->status();
        if (s.error_id) return {s.error_id, int(k), s.act_pos, 0};
        if (!s.enabled) return {error_id::kNotEnabled, int(k), s.act_pos, 0};
        limits_[k] = real_limits(axes[spec_.real[k]]->params(), s);
    }
    std::size_t me = spec_.virt.size();
    for (std::size_t i = 0; i < spec_.virt.size(); ++i) {
        const AxisStatus& s = axes[spec_.virt[i]]->status();
        start_[i] = s.set_pos;
        end_[i] = s.busy && !s.following ? s.target_pos : s.set_pos;
        if (spec_.virt[i] == index) me = i;
    }
    double target = 0;
    if (me == spec_.virt.size() || !target_of(*axes[index], c, target)) return v;
    end_[me] = target;
    const uint32_t dir_code = target >= start_[me] ? error_id::kSoftLimitFwd : error_id::kSoftLimitBwd;
    for (int n = 1; n <= kPathSamples; ++n) {
        double f = double(n) / kPathSamples;
        for (std::size_t i = 0; i < pose_.size(); ++i) pose_[i] = start_[i] + (end_[i] - start_[i]) * f;
        if (!inverse_->evaluate(pose_.data(), real_.data())) return {dir_code, -1, 0, 0};
        for (std::size_t k = 0; k < real_.size(); ++k) {
            double limit = 0;
            if (uint32_t why = real_violation(limits_[k], real_[k], &limit)) {
                (void)why;
                return {dir_code, int(k), real_[k], limit};
            }
        }
    }
    return v;
}

KinematicsVerdict Kinematics::supervise(std::span<const std::unique_ptr<Axis>> axes) noexcept {
    bool coupled = false;
    for (std::size_t i : spec_.virt) {
        const AxisStatus& s = axes[i]->status();
        coupled = coupled || (s.busy && !s.following);
    }
    if (!coupled || stopping_) {
        if (stopping_ && !coupled) { // the group is at rest: the real axes follow again
            stopping_ = false;
            for (std::size_t k : spec_.real) axes[k]->hold_external(false);
        }
        return {};
    }
    KinematicsVerdict v;
    for (std::size_t k = 0; k < spec_.real.size() && !v.code; ++k) {
        const AxisStatus& s = axes[spec_.real[k]]->status();
        if (s.error_id) v = {s.error_id, int(k), s.act_pos, 0};
        else if (s.ext_limited) v = {s.warning_id ? s.warning_id : error_id::kSoftLimitFwd, int(k), s.set_pos, 0};
    }
    if (!v.code) return v;
    for (std::size_t i : spec_.virt) {
        const AxisStatus& s = axes[i]->status();
        if (s.busy && !s.following) axes[i]->abort_motion(v.code, Interlock::Plc);
    }
    for (std::size_t k : spec_.real) axes[k]->hold_external(true); // every real axis stops at once
    stopping_ = true;
    return v;
}

Range allowed_range(Inverse& inverse, std::span<const double> pose_in, std::size_t which, double lo_cfg,
                    double hi_cfg, std::span<const RealLimits> limits, double tol) {
    std::vector<double> pose(pose_in.begin(), pose_in.end()), real(limits.size());
    const double here = pose[which];
    auto ok = [&](double x) {
        pose[which] = x;
        if (!inverse.evaluate(pose.data(), real.data())) return false;
        for (std::size_t k = 0; k < limits.size(); ++k)
            if (real_violation(limits[k], real[k], nullptr)) return false;
        return true;
    };
    if (!ok(here)) return {here, here};
    // Walk from `here` to the configured limit in steps; bisect the first step that fails.
    auto edge = [&](double to) {
        constexpr int kSteps = 64;
        double last_ok = here;
        for (int n = 1; n <= kSteps; ++n) {
            double x = here + (to - here) * double(n) / kSteps;
            if (ok(x)) {
                last_ok = x;
                continue;
            }
            double bad = x;
            while (std::fabs(bad - last_ok) > tol) {
                double mid = 0.5 * (last_ok + bad);
                (ok(mid) ? last_ok : bad) = mid;
            }
            return last_ok;
        }
        return to;
    };
    double lo = here > lo_cfg ? edge(lo_cfg) : here;
    double hi = here < hi_cfg ? edge(hi_cfg) : here;
    return {lo, hi};
}

} // namespace beamctl::motion
