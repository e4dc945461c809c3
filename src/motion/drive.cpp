#include "motion/drive.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::motion {

namespace {
// CiA402 state from the status word (bits 0-3, 5, 6).
enum class Ds402 { NotReady, SwitchOnDisabled, Ready, SwitchedOn, OperationEnabled, QuickStop, FaultReaction, Fault };
Ds402 ds402_state(uint64_t sw) {
    if ((sw & 0x4F) == 0x00) return Ds402::NotReady;
    if ((sw & 0x4F) == 0x40) return Ds402::SwitchOnDisabled;
    if ((sw & 0x6F) == 0x21) return Ds402::Ready;
    if ((sw & 0x6F) == 0x23) return Ds402::SwitchedOn;
    if ((sw & 0x6F) == 0x27) return Ds402::OperationEnabled;
    if ((sw & 0x6F) == 0x07) return Ds402::QuickStop;
    if ((sw & 0x4F) == 0x0F) return Ds402::FaultReaction;
    if ((sw & 0x4F) == 0x08) return Ds402::Fault;
    return Ds402::NotReady;
}
} // namespace

void Drive::step(bool enable, double velocity, bool standstill, double dt) noexcept { // velocity: the setpoint
    uint64_t sw = status_.get_raw();
    warning_ = p_.warning_bit >= 0 && (sw >> p_.warning_bit & 1);
    bool reset_now = false;
    if (reset_pending_) { // hold the reset bit for two cycles so the terminal sees the edge
        reset_now = true;
        if (++reset_cycles_ >= 2) {
            reset_pending_ = false;
            reset_cycles_ = 0;
            timed_out_ = false;
            enabling_s_ = 0;
        }
    }
    if (p_.type == DriveParams::Type::Stepper) {
        error_ = false;
        error_input_ = -1;
        for (int i = 0; i < 3; ++i)
            if (p_.error_bits[i] >= 0 && (sw >> p_.error_bits[i] & 1) && !error_) {
                error_ = true;
                error_input_ = i;
            }
        uint16_t cw = 0;
        if (enable) cw |= uint16_t(1u << p_.enable_bit);
        if (reset_now && p_.reset_bit >= 0) cw |= uint16_t(1u << p_.reset_bit);
        if (standstill && p_.reduce_torque_bit >= 0) cw |= uint16_t(1u << p_.reduce_torque_bit);
        cw_ = cw;
        enabled_ = enable && (sw >> p_.enabled_bit & 1) && !error_;
    } else {
        Ds402 s = ds402_state(sw);
        error_ = s == Ds402::Fault || s == Ds402::FaultReaction;
        uint16_t cw = 0;
        if (reset_now && error_) {
            cw = 0x80; // fault reset
        } else if (enable && !error_) {
            switch (s) {
            case Ds402::NotReady:
            case Ds402::SwitchOnDisabled:
            case Ds402::QuickStop: cw = 0x06; break;
            case Ds402::Ready: cw = 0x07; break;
            default: cw = 0x0F; break; // switched on / operation enabled
            }
        } else {
            cw = 0x06; // shutdown: power stage off, ready to switch on again
        }
        cw_ = cw;
        enabled_ = enable && s == Ds402::OperationEnabled;
    }
    // Either kind has enable_timeout to report enabled (summed cycle times: a small tolerance).
    if (enable && !enabled_ && !error_) {
        enabling_s_ += dt;
        if (enabling_s_ >= p_.enable_timeout - 1e-9) timed_out_ = true;
    } else {
        enabling_s_ = 0;
    }
    control_.set(cw_);
    uint8_t bits = setpoint_.bits ? setpoint_.bits : 32;
    if (p_.position_mode) { // a position: wraps in the entry's width like the drive's counter
        raw_ = std::isfinite(velocity) ? int64_t(std::llround(velocity * p_.denominator / p_.numerator)) : raw_;
        setpoint_.set(raw_);
        return;
    }
    // velocity setpoint in the entry's range
    double raw = enabled_ && std::isfinite(velocity) ? velocity * p_.denominator / p_.numerator : 0;
    double hi = setpoint_.is_signed ? std::ldexp(1.0, bits - 1) - 1 : std::ldexp(1.0, bits) - 1;
    double lo = setpoint_.is_signed ? -std::ldexp(1.0, bits - 1) : 0;
    raw_ = int64_t(std::llround(std::clamp(raw, lo, hi)));
    setpoint_.set(raw_);
}

} // namespace beamctl::motion
