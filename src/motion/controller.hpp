// The position controller of an axis (ECMC `controller:`): PID on the position error plus
// velocity feed-forward, output and integral limits, and a deadband in which the output is the
// feed-forward only. Output is a velocity [units/s] for a CSV drive.
// Threading: RT thread; noexcept.
#pragma once

#include <algorithm>
#include <cmath>

namespace beamctl::motion {

struct ControllerParams {
    double kp = 1, ki = 0, kd = 0, kff = 1;   // kp [1/s], ki [1/s^2], kd [-], kff [-]
    double min_output = -HUGE_VAL, max_output = HUGE_VAL;       // [units/s]
    double min_integral = -HUGE_VAL, max_integral = HUGE_VAL;   // [units/s]
    double deadband = 0;                       // |error| below this [units] ...
    int deadband_cycles = 0;                   // ... for this many cycles: PID part held at 0
};

class Controller {
public:
    Controller() = default;
    explicit Controller(const ControllerParams& p) : p_(p) {}
    // error = setpoint - actual [units]; feed_forward = trajectory velocity [units/s]; dt [s].
    // The error has stayed within the deadband for longer than its time (ECMC ctrlWithinDeadband).
    bool in_deadband() const noexcept { return p_.deadband > 0 && in_band_ > p_.deadband_cycles; }
    // Counts the cycles the error stayed within the deadband (step() does it too).
    void track(double error) noexcept {
        if (std::fabs(error) < p_.deadband) ++in_band_;
        else in_band_ = 0;
    }
    double step(double error, double feed_forward, double dt) noexcept {
        track(error);
        double pid = 0;
        if (p_.deadband <= 0 || in_band_ <= p_.deadband_cycles) {
            integral_ = std::clamp(integral_ + p_.ki * error * dt, p_.min_integral, p_.max_integral);
            double d = dt > 0 && started_ ? (error - last_error_) / dt : 0;
            pid = p_.kp * error + integral_ + p_.kd * d;
        }
        started_ = true;
        last_error_ = error;
        output_ = std::clamp(pid + p_.kff * feed_forward, p_.min_output, p_.max_output);
        return output_;
    }
    void reset() noexcept {
        integral_ = 0;
        last_error_ = 0;
        started_ = false;
        in_band_ = 0;
        output_ = 0;
    }
    double output() const noexcept { return output_; }
    ControllerParams& params() noexcept { return p_; }

private:
    ControllerParams p_;
    double integral_ = 0, last_error_ = 0, output_ = 0;
    bool started_ = false;
    int in_band_ = 0;
};

} // namespace beamctl::motion
