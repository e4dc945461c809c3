#include "motion/axis_group.hpp"

namespace beamctl::motion {

AxisGroup::AxisGroup(std::vector<std::unique_ptr<Axis>> axes, std::size_t queue)
    : axes_(std::move(axes)), commands_(queue), results_(queue) {
    std::size_t n = axes_.size();
    statuses_.init([n](std::vector<AxisStatus>& v) { v.assign(n, AxisStatus{}); });
}

void AxisGroup::run(const rt::CycleInfo& c) noexcept {
    Queued q;
    while (commands_.pop(q)) {
        uint32_t code = q.index < axes_.size() ? axes_[q.index]->command(q.cmd) : error_id::kVelocityZero;
        if (!results_.push(Result{q.cmd.tag, code})) dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    double dt = double(c.period_ns) * 1e-9;
    std::vector<AxisStatus>& out = statuses_.write_buffer();
    for (std::size_t i = 0; i < axes_.size(); ++i) {
        if (hook_) hook_->before_axis(i, c);
        axes_[i]->run(dt);
        out[i] = axes_[i]->status();
    }
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
