// The axis as PLC code sees it: ECMC's ax<n>.* variables (specs/ecmc.md §2), all doubles. The
// axis publishes the readable ones at the end of each cycle; PLC code writes the writable ones,
// which the axis takes at the start of its next cycle (so a general PLC's extsetpos acts in the
// next cycle, as in ECMC). Booleans are 0/1.
// Threading: RT thread only (axes and PLCs run in the same cycle).
#pragma once

#include <cstddef>
#include <span>
#include <string_view>

namespace beamctl::motion {

struct AxisVariables {
    double reset = 0;       // rw: rising edge resets errors
    double error = 0;       // r: error id
    double allowplccmd = 1; // rw: PLC commands allowed
    struct {
        double actpos = 0, extactpos = 0, actvel = 0;
        double source = 0; // rw: 0 encoder, 1 PLC (extactpos)
        double homed = 0;
    } enc;
    struct {
        double setpos = 0, targetpos = 0, extsetpos = 0, targetvel = 0, targetacc = 0;
        double command = 0, cmddata = 0; // rw: 1 VEL, 2 REL, 3 ABS, 10 HOME; homing sequence
        double source = 0;               // rw: 0 internal trajectory, 1 PLC (extsetpos)
        double execute = 0;              // rw: rising edge runs `command`, falling edge halts
        double busy = 0;
    } traj;
    struct {
        double enable = 0, enabled = 0; // rw / r
    } drv;
    struct {
        double ilock = 1, ilockfwd = 1, ilockbwd = 1; // rw: 1 = motion allowed (PLC interlocks)
        double attarget = 0;
        double lowlim = 1, highlim = 1; // 1 = OK (not on the switch); rw with plcOverride
        double homesensor = 0;          // rw with plcOverride
        double lowsoftlim = 0, highsoftlim = 0, lowsoftlimenable = 0, highsoftlimenable = 0; // rw
    } mon;
    struct {
        double kp = 0, ki = 0, kd = 0, kff = 0; // rw
    } ctrl;
};

struct AxisVariableInfo {
    const char* name;   // after "ax<n>.": "enc.actpos", "traj.extsetpos", ...
    std::size_t offset; // of the double in AxisVariables
    bool writable;
};

// Every variable, for binding names at compile time.
std::span<const AxisVariableInfo> axis_variables();
const AxisVariableInfo* find_axis_variable(std::string_view name);

inline double* axis_variable(AxisVariables& v, const AxisVariableInfo& info) {
    return reinterpret_cast<double*>(reinterpret_cast<char*>(&v) + info.offset);
}

} // namespace beamctl::motion
