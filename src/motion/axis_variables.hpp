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
    double id = 0;          // r: the axis id
    double reset = 0;       // rw: rising edge resets errors
    double counter = 0;     // r: the axis's cycle counter
    double error = 0;       // r: error id
    double blockcom = 0;    // rw: commands blocked (ECMC features.blockCom; error 0x20039)
    double allowplccmd = 1; // rw: PLC commands allowed
    struct {
        // actpos: r, and w as ECMC: a write stores the external actual position (extactpos),
        // the axis's actual position while enc.source is 1
        double actpos = 0, extactpos = 0, actvel = 0;
        double rawpos = 0;  // r: raw counter of the primary encoder
        double source = 0;  // rw: 0 encoder, 1 PLC (extactpos)
        double homed = 0;   // r, and w as ECMC: marks the primary encoder homed (PLC runtime)
        double homepos = 0; // rw: the homing position [EGU]
    } enc;
    struct {
        // setpos: r, and w as ECMC: a write sets the external setpoint (extsetpos)
        double setpos = 0, targetpos = 0, extsetpos = 0, targetvel = 0, targetacc = 0, targetdec = 0;
        double setvel = 0, setvelffraw = 0; // r: setpoint velocity; feed-forward part [EGU/s]
        double command = 0, cmddata = 0; // rw: 1 VEL, 2 REL, 3 ABS, 10 HOME; homing sequence
        double source = 0;               // rw: 0 internal trajectory, 1 PLC (extsetpos)
        double execute = 0;              // rw: rising edge runs `command`, falling edge halts
        double busy = 0;
        double dir = 0; // r: -1 backward, 0 standing (or disabled), 1 forward
    } traj;
    struct {
        double enable = 0, enabled = 0; // rw / r
        double setvelraw = 0;           // r: drive velocity setpoint [EGU/s]
    } drv;
    struct {
        // r: following error [EGU] (also named cntrl.error), controller output [EGU/s]
        double poserror = 0, output = 0;
    } cntrl;
    struct {
        double state = 0; // r: homing sequence state
    } seq;
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

// A readback the axis publishes every cycle (enc.actpos, traj.setpos, ...): an input for records
// and the registry, even where ECMC lets PLC code write it (enc.actpos, traj.setpos, enc.homed).
inline bool is_readback(const AxisVariableInfo& info) {
    std::string_view n = info.name;
    return !info.writable || n == "enc.actpos" || n == "traj.setpos" || n == "enc.homed";
}

inline double* axis_variable(AxisVariables& v, const AxisVariableInfo& info) {
    return reinterpret_cast<double*>(reinterpret_cast<char*>(&v) + info.offset);
}

} // namespace beamctl::motion
