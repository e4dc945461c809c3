// An axis drive (ECMC `drive:`): turns enable requests and a velocity command into the terminal's
// control word and setpoint, and its status word into enabled / warning / error.
//   stepper  one control bit enables (`enable`), one status bit says enabled (`enabled`)
//   DS402    the CiA402 state machine is walked: 0x06 shutdown -> 0x07 switch on -> 0x0F enable
//            operation; a fault needs reset (bit 7 rising edge); not enabled within 15 s is an error
// Setpoint raw = velocity [units/s] * denominator / numerator, clamped to the entry's range.
// Threading: RT thread; noexcept, no allocation.
#pragma once

#include "registry/signal.hpp"

#include <array>
#include <cstdint>

namespace beamctl::motion {

struct DriveParams {
    enum class Type : uint8_t { Stepper = 0, Ds402 = 1 };
    Type type = Type::Stepper;
    double numerator = 1, denominator = 1; // numerator [units/s] at raw = denominator
    int enable_bit = 0;          // stepper: control-word bit that enables the power stage
    int enabled_bit = 1;         // stepper: status-word bit set while enabled
    int reset_bit = -1;          // stepper: control-word bit pulsed by reset (-1: none)
    int warning_bit = -1;        // status-word bit (-1: none)
    std::array<int, 3> error_bits{-1, -1, -1}; // status-word bits that mean a drive error
    int reduce_torque_bit = -1;  // control-word bit set while standing still (-1: none)
    double enable_timeout = 15;  // DS402: operation enabled within this [s]
    bool position_mode = false;  // CSP: the setpoint is a position (raw = position * den / num,
                                 // wrapping in the entry's width) instead of a velocity
};

class Drive {
public:
    Drive() = default;
    Drive(const DriveParams& p, registry::BoundSignal control, registry::BoundSignal status,
          registry::BoundSignal setpoint)
        : p_(p), control_(control), status_(status), setpoint_(setpoint) {}

    // Per cycle, after the status word arrived: walks the enable sequence towards `enable`,
    // writes the control word and the setpoint: a velocity (0 unless enabled) or, in position
    // mode, a position (always written, so that enabling does not jump). `standstill` sets
    // reduce torque where configured.
    void step(bool enable, double setpoint, bool standstill, double dt) noexcept;
    // Rising edge of the drive's reset (stepper reset bit, DS402 fault reset) on the next step.
    void reset() noexcept { reset_pending_ = true; }

    bool enabled() const noexcept { return enabled_; }
    bool warning() const noexcept { return warning_; }
    bool error() const noexcept { return error_; }       // drive reports an error / fault
    int error_input() const noexcept { return error_input_; } // stepper: which error[] bit (0..2), else -1
    bool timed_out() const noexcept { return timed_out_; } // DS402 not enabled in time
    uint16_t control_word() const noexcept { return cw_; }
    int64_t raw_setpoint() const noexcept { return raw_; }
    const DriveParams& params() const noexcept { return p_; }

private:
    DriveParams p_;
    registry::BoundSignal control_, status_, setpoint_;
    bool enabled_ = false, warning_ = false, error_ = false, timed_out_ = false;
    bool reset_pending_ = false;
    int error_input_ = -1;
    int reset_cycles_ = 0;
    double enabling_s_ = 0;
    uint16_t cw_ = 0;
    int64_t raw_ = 0;
};

} // namespace beamctl::motion
