#include "motion/axis_group.hpp"

namespace beamctl::motion {

AxisGroup::AxisGroup(std::vector<std::unique_ptr<Axis>> axes, std::size_t queue)
    : axes_(std::move(axes)), commands_(queue), results_(queue) {
    std::size_t n = axes_.size();
    statuses_.init([n](std::vector<AxisStatus>& v) { v.assign(n, AxisStatus{}); });
    kinematics_of_.assign(n, -1);
}

std::size_t AxisGroup::add_kinematics(std::unique_ptr<Kinematics> k) {
    std::size_t id = kinematics_.size();
    for (std::size_t i : k->spec().virt)
        if (i < kinematics_of_.size()) kinematics_of_[i] = int(id);
    kinematics_.push_back(std::move(k));
    return id;
}

void AxisGroup::run(const rt::CycleInfo& c) noexcept {
    Queued q;
    while (commands_.pop(q)) {
        Result res{q.cmd.tag, error_id::kVelocityZero, q.index};
        if (q.index < axes_.size()) {
            int k = kinematics_of_[q.index];
            if (k >= 0) {
                res.verdict = kinematics_[std::size_t(k)]->check(axes_, q.index, q.cmd);
                if (res.verdict.code) res.kinematics = k;
            }
            res.code = res.verdict.code ? axes_[q.index]->refuse(q.cmd, res.verdict.code) : axes_[q.index]->command(q.cmd);
        }
        if (!results_.push(res)) dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    double dt = double(c.period_ns) * 1e-9;
    for (std::size_t i = 0; i < axes_.size(); ++i) {
        if (hook_) hook_->before_axis(i, c);
        axes_[i]->run(dt);
    }
    for (std::size_t k = 0; k < kinematics_.size(); ++k) {
        KinematicsVerdict v = kinematics_[k]->supervise(axes_);
        if (v.code && !results_.push(Result{0, v.code, kinematics_[k]->spec().virt.front(), int(k), v}))
            dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    std::vector<AxisStatus>& out = statuses_.write_buffer();
    for (std::size_t i = 0; i < axes_.size(); ++i) out[i] = axes_[i]->status();
    statuses_.publish();
}

bool AxisGroup::send(std::size_t index, const AxisCommand& c) noexcept {
    if (commands_.push(Queued{index, c})) return true;
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
}

const std::vector<AxisStatus>& AxisGroup::snapshot() noexcept {
    statuses_.update();
    return statuses_.read_buffer();
}

} // namespace beamctl::motion
