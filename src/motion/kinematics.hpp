// Kinematics groups: virtual axes whose moves drive real axes through an inverse transform (the
// slit's centre/gap, a mirror's pitch/yaw/roll, a spiral). Whatever code drives the real axes in
// the cycle (a PLC), the group is what makes a virtual move safe:
//   - before a virtual move starts, its path (the straight line in virtual space from the present
//     setpoints to the target, sampled) is taken through the inverse transform; a move that would
//     take a real axis past an enabled soft limit, further into an active limit switch, or that
//     needs a real axis that is disabled or in error, is refused (the virtual axis raises the
//     soft-limit warning, or the real axis's error, and the command ends as refused);
//   - during a coupled move, a real axis held at a limit (Axis: ext_limited) or in error stops
//     every real axis of the group at once where it is (the geometry holds) and every moving
//     virtual axis with its emergency deceleration; the virtual moves end short (move_failed)
//     with the real axis's warning or error;
//   - off the RT thread, the same transform gives each virtual axis the range its real axes allow
//     (derived soft limits: the IOC applies them to the virtual motor records).
// Threading: check() and supervise() on the RT thread (AxisGroup::run); range() on one non-RT
// thread, each with its own Inverse.
#pragma once

#include "motion/axis.hpp"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace beamctl::motion {

// Real-axis positions from virtual-axis positions. RT-safe: no allocation, no exception.
class Inverse {
public:
    virtual ~Inverse() = default;
    // virt[i]: position of the group's virtual axis i [its units]; writes real[k]. False when the
    // transform failed (a PLC run-time fault, a non-finite result).
    [[nodiscard]] virtual bool evaluate(const double* virt, double* real) noexcept = 0;
};

struct KinematicsSpec {
    std::string name;               // for messages ("slit vertical")
    std::vector<std::size_t> virt;  // AxisGroup indices of the virtual axes (inputs)
    std::vector<std::size_t> real;  // AxisGroup indices of the real axes (outputs)
};

// Why a virtual move was refused or stopped: the real axis (index into KinematicsSpec::real, -1
// when none) and where the transform would take it.
struct KinematicsVerdict {
    uint32_t code = 0;  // 0: allowed; else the warning/error id (error_id::)
    int real = -1;
    double position = 0; // where the real axis would go [its units]
    double limit = 0;    // the limit it would cross [its units]
};

// The limits of one real axis as a check sees them.
struct RealLimits {
    bool soft_fwd_enable = false, soft_bwd_enable = false;
    double soft_fwd = 0, soft_bwd = 0; // [units]
    bool switch_fwd = false, switch_bwd = false; // limit switch active
    double position = 0;                         // present setpoint [units]
};

// A real axis's limits from its parameters (soft limits, which PLC code may change: read them from
// the axis on the RT thread) and its latest status (switches, setpoint).
RealLimits real_limits(const AxisParams& p, const AxisStatus& s) noexcept;

// 0, or the id why a real axis may not go to `x` from where it is (moving back in is allowed).
uint32_t real_violation(const RealLimits& l, double x, double* limit) noexcept;

class Kinematics {
public:
    static constexpr int kPathSamples = 16; // points checked along a move's path (and its end)

    Kinematics(KinematicsSpec spec, std::unique_ptr<Inverse> inverse);
    const KinematicsSpec& spec() const noexcept { return spec_; }

    // RT: may command `c` run on virtual axis group index `index` (one of spec().virt)?
    KinematicsVerdict check(std::span<const std::unique_ptr<Axis>> axes, std::size_t index,
                            const AxisCommand& c) noexcept;
    // RT, after the group's axes ran: stops the group's moving virtual axes when a real axis is
    // held at a limit or in error. Returns the verdict that stopped them (code 0: nothing did).
    KinematicsVerdict supervise(std::span<const std::unique_ptr<Axis>> axes) noexcept;

private:
    KinematicsSpec spec_;
    std::unique_ptr<Inverse> inverse_;
    std::vector<double> start_, end_, pose_, real_; // scratch, sized once
    std::vector<RealLimits> limits_;
    bool stopping_ = false; // supervise() stopped the group; it has not come to rest yet
};

// Non-RT: the interval [lo, hi] of virtual axis `which` (index into the virtual inputs) inside
// [lo_cfg, hi_cfg] over which the inverse keeps every real axis inside its soft limits, with the
// other virtual axes at `pose`. The interval contains pose[which] when that point is allowed;
// when it is not, returns {pose[which], pose[which]}. Resolution `tol` [units].
struct Range {
    double lo = 0, hi = 0;
};
Range allowed_range(Inverse& inverse, std::span<const double> pose, std::size_t which, double lo_cfg,
                    double hi_cfg, std::span<const RealLimits> limits, double tol);

} // namespace beamctl::motion
