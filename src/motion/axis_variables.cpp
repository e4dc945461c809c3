#include "motion/axis_variables.hpp"

#include <array>

namespace beamctl::motion {

namespace {
#define BEAMCTL_AXVAR(name, member, rw) AxisVariableInfo{name, offsetof(AxisVariables, member), rw}
const std::array kVariables = {
    BEAMCTL_AXVAR("id", id, false),
    BEAMCTL_AXVAR("reset", reset, true),
    BEAMCTL_AXVAR("counter", counter, false),
    BEAMCTL_AXVAR("error", error, false),
    BEAMCTL_AXVAR("blockcom", blockcom, true),
    BEAMCTL_AXVAR("allowplccmd", allowplccmd, true),
    BEAMCTL_AXVAR("enc.actpos", enc.actpos, true),
    BEAMCTL_AXVAR("enc.rawpos", enc.rawpos, false),
    BEAMCTL_AXVAR("enc.homepos", enc.homepos, true),
    BEAMCTL_AXVAR("enc.extactpos", enc.extactpos, true),
    BEAMCTL_AXVAR("enc.actvel", enc.actvel, false),
    BEAMCTL_AXVAR("enc.source", enc.source, true),
    // rw: a write marks the primary encoder referenced or not (ECMC setAxisHomed); the PLC
    // runtime applies it after the scan (the axis publishes the encoder's state)
    BEAMCTL_AXVAR("enc.homed", enc.homed, true),
    BEAMCTL_AXVAR("traj.setpos", traj.setpos, true),
    BEAMCTL_AXVAR("traj.targetdec", traj.targetdec, true),
    BEAMCTL_AXVAR("traj.setvel", traj.setvel, false),
    BEAMCTL_AXVAR("traj.setvelffraw", traj.setvelffraw, false),
    BEAMCTL_AXVAR("traj.dir", traj.dir, false),
    BEAMCTL_AXVAR("drv.setvelraw", drv.setvelraw, false),
    BEAMCTL_AXVAR("cntrl.poserror", cntrl.poserror, false),
    // ECMC's cntrlError, the error the controller works on: setpoint - actual taken across a
    // modulo wrap (ecmcMotionUtils::getPosErrorModWithSign). beamctl keeps setpoint and actual
    // unwrapped, so it is the same value as cntrl.poserror (ECMC's plain setpoint - actual).
    // ECMC 11.0.8 defines the name but its PLC parser never matches it; the manual lists it.
    BEAMCTL_AXVAR("cntrl.error", cntrl.poserror, false),
    BEAMCTL_AXVAR("cntrl.output", cntrl.output, false),
    BEAMCTL_AXVAR("seq.state", seq.state, false),
    BEAMCTL_AXVAR("traj.targetpos", traj.targetpos, true),
    BEAMCTL_AXVAR("traj.extsetpos", traj.extsetpos, true),
    BEAMCTL_AXVAR("traj.targetvel", traj.targetvel, true),
    BEAMCTL_AXVAR("traj.targetacc", traj.targetacc, true),
    BEAMCTL_AXVAR("traj.command", traj.command, true),
    BEAMCTL_AXVAR("traj.cmddata", traj.cmddata, true),
    BEAMCTL_AXVAR("traj.source", traj.source, true),
    BEAMCTL_AXVAR("traj.execute", traj.execute, true),
    BEAMCTL_AXVAR("traj.busy", traj.busy, false),
    BEAMCTL_AXVAR("drv.enable", drv.enable, true),
    BEAMCTL_AXVAR("drv.enabled", drv.enabled, false),
    BEAMCTL_AXVAR("mon.ilock", mon.ilock, true),
    BEAMCTL_AXVAR("mon.ilockfwd", mon.ilockfwd, true),
    BEAMCTL_AXVAR("mon.ilockbwd", mon.ilockbwd, true),
    BEAMCTL_AXVAR("mon.attarget", mon.attarget, false),
    BEAMCTL_AXVAR("mon.lowlim", mon.lowlim, true),
    BEAMCTL_AXVAR("mon.highlim", mon.highlim, true),
    BEAMCTL_AXVAR("mon.homesensor", mon.homesensor, true),
    BEAMCTL_AXVAR("mon.lowsoftlim", mon.lowsoftlim, true),
    BEAMCTL_AXVAR("mon.highsoftlim", mon.highsoftlim, true),
    BEAMCTL_AXVAR("mon.lowsoftlimenable", mon.lowsoftlimenable, true),
    BEAMCTL_AXVAR("mon.highsoftlimenable", mon.highsoftlimenable, true),
    BEAMCTL_AXVAR("ctrl.kp", ctrl.kp, true),
    BEAMCTL_AXVAR("ctrl.ki", ctrl.ki, true),
    BEAMCTL_AXVAR("ctrl.kd", ctrl.kd, true),
    BEAMCTL_AXVAR("ctrl.kff", ctrl.kff, true),
};
#undef BEAMCTL_AXVAR
} // namespace

std::span<const AxisVariableInfo> axis_variables() { return kVariables; }

const AxisVariableInfo* find_axis_variable(std::string_view name) {
    for (const auto& v : kVariables)
        if (name == v.name) return &v;
    return nullptr;
}

} // namespace beamctl::motion
