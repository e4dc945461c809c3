#include "ethercat/sim/terminals.hpp"

#include "ethercat/sim/segment.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::ethercat::sim {

namespace {
constexpr double kStallTime = 0.020;    // stepper: force saturated this long and lagging = stalled [s]
constexpr double kMovingEpsilon = 1e-6; // [units/s]

// "positionActual01" -> "01" (the channel suffix shared by a channel's entries)
std::string channel_of(const std::string& entry) {
    std::size_t i = entry.size();
    while (i > 0 && std::isdigit(static_cast<unsigned char>(entry[i - 1]))) --i;
    return entry.substr(i);
}
} // namespace

// ---- EL70x1 stepper -------------------------------------------------------------------------

StepperTerminal::StepperTerminal(Segment& seg, int slave, const MotorParams& p)
    : DriveTerminal(slave, p),
      control_(bind_io(seg, slave, "driveControl01")),
      status_(bind_io(seg, slave, "driveStatus01")),
      setpoint_(bind_io(seg, slave, "velocitySetpoint01")) {}

void StepperTerminal::entered_op(Segment& seg) {
    speed_range_ = 2000;
    if (CoeServer* coe = seg.slave(std::size_t(slave_)).coe()) {
        std::vector<uint8_t> v;
        if (coe->upload(0x8012, 0x05, v) == 0 && !v.empty() && v[0] <= 5) speed_range_ = 1000.0 * (1 << v[0]);
    }
}

DriveCommand StepperTerminal::command(Segment& seg, double, double) noexcept {
    uint64_t cw = control_.get(seg);
    bool reset = cw >> 1 & 1;
    if (reset && !last_reset_) { // rising edge of reset clears the latched error
        error_ = false;
        stalled_ = false;
        saturated_s_ = 0;
    }
    last_reset_ = reset;
    enabled_ = (cw & 1) && !error_;
    reduced_ = cw >> 2 & 1;
    DriveCommand c;
    c.powered = enabled_;
    if (enabled_) {
        double steps_per_s = double(setpoint_.get_signed(seg)) / 32767.0 * speed_range_;
        c.velocity = steps_per_s / p_.steps_per_rev * p_.units_per_rev;
    }
    c.force_limit = p_.max_force * (reduced_ ? 0.5 : 1.0);
    return c;
}

void StepperTerminal::report(Segment& seg, const DriveFeedback& fb) noexcept {
    if (enabled_ && fb.saturated) saturated_s_ += fb.dt;
    else saturated_s_ = 0;
    stalled_ = saturated_s_ >= kStallTime;
    if (fb.dt > 0) toggle_ = !toggle_;
    uint16_t sw = 0;
    if (!error_) sw |= 1u << 0;             // ready to enable
    if (enabled_) sw |= 1u << 1;            // ready (power stage on)
    if (stalled_) sw |= 1u << 2 | 1u << 7;  // warning + motor stall
    if (error_) sw |= 1u << 3;
    if (fb.velocity > kMovingEpsilon) sw |= 1u << 4;
    if (fb.velocity < -kMovingEpsilon) sw |= 1u << 5;
    if (reduced_) sw |= 1u << 6;
    if (toggle_) sw |= 1u << 15;
    status_.set(seg, sw);
}

// ---- EL72x1 servo, CiA402 -------------------------------------------------------------------

Cia402Terminal::Cia402Terminal(Segment& seg, int slave, const MotorParams& p)
    : DriveTerminal(slave, p),
      control_(bind_io(seg, slave, "driveControl01")),
      status_(bind_io(seg, slave, "driveStatus01")),
      setpoint_(bind_optional(seg, slave, "velocitySetpoint01")),
      actual_(bind_optional(seg, slave, "velocityActual01")),
      target_(bind_optional(seg, slave, "positionSetpoint01")) {}

uint16_t Cia402Terminal::statusword(State s) noexcept {
    switch (s) {
    case State::NotReadyToSwitchOn: return 0x0000;
    case State::SwitchOnDisabled: return 0x0040;
    case State::ReadyToSwitchOn: return 0x0021;
    case State::SwitchedOn: return 0x0023;
    case State::OperationEnabled: return 0x0027;
    case State::QuickStopActive: return 0x0007;
    case State::FaultReactionActive: return 0x000F;
    case State::Fault: return 0x0008;
    }
    return 0;
}

const char* Cia402Terminal::name(State s) noexcept {
    static const char* names[] = {"NOT READY TO SWITCH ON", "SWITCH ON DISABLED", "READY TO SWITCH ON",
                                  "SWITCHED ON", "OPERATION ENABLED", "QUICK STOP ACTIVE",
                                  "FAULT REACTION ACTIVE", "FAULT"};
    return names[int(s)];
}

void Cia402Terminal::inject_fault() noexcept {
    if (state_ == State::Fault || state_ == State::FaultReactionActive) return;
    state_ = State::FaultReactionActive;
    ramp_velocity_ = last_velocity_;
}

DriveCommand Cia402Terminal::command(Segment& seg, double dt, double position) noexcept {
    // Control word commands (CiA402 table): masks over bits 0-3 and 7.
    uint16_t cw = uint16_t(control_.get(seg));
    bool fault_reset = cw >> 7 & 1;
    bool shutdown = (cw & 0x87) == 0x06, switch_on = (cw & 0x8F) == 0x07;
    bool enable_op = (cw & 0x8F) == 0x0F, disable_voltage = (cw & 0x82) == 0x00;
    bool quick_stop = (cw & 0x86) == 0x02;
    State s = state_;
    switch (s) {
    case State::NotReadyToSwitchOn: s = State::SwitchOnDisabled; break; // self test done
    case State::SwitchOnDisabled:
        if (shutdown) s = State::ReadyToSwitchOn;
        break;
    case State::ReadyToSwitchOn:
        if (disable_voltage || quick_stop) s = State::SwitchOnDisabled;
        else if (switch_on) s = State::SwitchedOn;
        else if (enable_op) s = State::OperationEnabled; // transitions 3 + 4 at once
        break;
    case State::SwitchedOn:
        if (disable_voltage || quick_stop) s = State::SwitchOnDisabled;
        else if (shutdown) s = State::ReadyToSwitchOn;
        else if (enable_op) s = State::OperationEnabled;
        break;
    case State::OperationEnabled:
        if (disable_voltage) s = State::SwitchOnDisabled;
        else if (quick_stop) s = State::QuickStopActive;
        else if (shutdown) s = State::ReadyToSwitchOn;
        else if (switch_on) s = State::SwitchedOn;
        break;
    case State::QuickStopActive:
        if (disable_voltage) s = State::SwitchOnDisabled;
        break;
    case State::FaultReactionActive: break;
    case State::Fault:
        if (fault_reset && !last_reset_) s = State::SwitchOnDisabled;
        break;
    }
    last_reset_ = fault_reset;
    if ((s == State::QuickStopActive || s == State::FaultReactionActive) && state_ != s)
        ramp_velocity_ = last_velocity_; // the ramp starts from where the stage is
    state_ = s;
    voltage_ = s == State::SwitchedOn || s == State::OperationEnabled || s == State::QuickStopActive ||
               s == State::FaultReactionActive || (s == State::ReadyToSwitchOn && (cw & 0x02));

    DriveCommand c;
    c.force_limit = p_.max_force;
    if (s == State::OperationEnabled && target_.bound()) {
        // CSP: the target position (32-bit counts, wrapping) relative to where the stage stands,
        // followed with velocity feed-forward and a 100/s position loop
        double units_per_count = p_.units_per_rev / p_.position_scale;
        int64_t actual_counts = std::llround((position - p_.position_start) / units_per_count);
        int32_t diff = int32_t(uint32_t(target_.get(seg)) - uint32_t(actual_counts));
        double target = position + double(diff) * units_per_count;
        double ff = std::isfinite(last_target_) && dt > 0 ? (target - last_target_) / dt : 0;
        last_target_ = target;
        c.powered = true;
        c.velocity = ff + 100.0 * (target - position);
    } else if (s == State::OperationEnabled) {
        c.powered = true;
        c.velocity = double(int32_t(setpoint_.get(seg))) / p_.velocity_scale * p_.units_per_rev;
    } else if (s == State::QuickStopActive || s == State::FaultReactionActive) {
        // ramp the last actual velocity down to standstill
        double step = p_.quick_stop_decel * dt;
        if (std::fabs(ramp_velocity_) <= step) {
            ramp_velocity_ = 0;
            state_ = s == State::QuickStopActive ? State::SwitchOnDisabled : State::Fault;
        } else {
            ramp_velocity_ -= std::copysign(step, ramp_velocity_);
        }
        c.powered = state_ == s;
        c.velocity = ramp_velocity_;
    }
    if (s != State::OperationEnabled) last_target_ = NAN;
    target_reached_ = false;
    return c;
}

void Cia402Terminal::report(Segment& seg, const DriveFeedback& fb) noexcept {
    if (state_ == State::OperationEnabled && fb.saturated) {
        overload_s_ += fb.dt;
        if (overload_s_ >= p_.overload_time) inject_fault(); // I2t: motor overload
    } else {
        overload_s_ = 0;
    }
    last_velocity_ = fb.velocity;
    uint16_t sw = statusword(state_);
    if (voltage_) sw |= 1u << 4;
    sw |= 1u << 9; // remote: controlled over EtherCAT
    if (state_ == State::OperationEnabled && !fb.saturated) sw |= 1u << 10; // velocity followed
    status_.set(seg, sw);
    actual_.set(seg, uint64_t(int64_t(std::llround(fb.velocity / p_.units_per_rev * p_.velocity_scale))));
}

// ---- encoders -------------------------------------------------------------------------------

EncoderChannel::EncoderChannel(Segment& seg, int slave, const std::string& entry, double counts_per_unit,
                               bool absolute, double zero, double start_position, double index_every,
                               double index_offset)
    : slave_(slave), value_(bind_io(seg, slave, entry)), counts_per_unit_(counts_per_unit), zero_(absolute ? zero : start_position),
      index_every_(index_every), index_offset_(index_offset), last_position_(start_position) {
    std::string ch = channel_of(entry);
    control_ = bind_optional(seg, slave, "encoderControl" + ch);
    setval_ = bind_optional(seg, slave, "encoderValue" + ch);
    status_ = bind_optional(seg, slave, "encoderStatus" + ch);
    latch_ = bind_optional(seg, slave, "encoderLatchPostion" + ch);
    if (!latch_.bound()) latch_ = bind_optional(seg, slave, "encoderLatchPosition" + ch);
    update(seg, start_position);
}

void EncoderChannel::update(Segment& seg, double position) noexcept {
    int64_t raw = std::llround((position - zero_) * counts_per_unit_);
    // latch C: armed by the rising edge of control bit 0, taken at the next index mark crossed
    bool arm = control_.bit(seg, 0);
    if (arm && !last_arm_) {
        armed_ = true;
        latched_ = false;
    }
    if (!arm) armed_ = latched_ = false;
    last_arm_ = arm;
    if (armed_ && index_every_ > 0 && latch_.bound() && position != last_position_) {
        double lo = std::min(position, last_position_), hi = std::max(position, last_position_);
        double k = std::ceil((lo - index_offset_) / index_every_); // first mark at or above lo
        double mark = index_offset_ + k * index_every_;
        if (mark <= hi && !(mark == last_position_)) {
            int64_t at = std::llround((mark - zero_) * counts_per_unit_) + offset_;
            latch_.set(seg, uint64_t(at));
            armed_ = false;
            latched_ = true;
        }
    }
    last_position_ = position;
    bool set = control_.bit(seg, 2);
    if (set && !last_set_ && setval_.bound()) {
        offset_ = int64_t(setval_.get(seg)) - raw; // the counter continues from the set value
        set_done_ = true;
    }
    if (!set) set_done_ = false;
    last_set_ = set;
    counts_ = raw + offset_;
    value_.set(seg, uint64_t(counts_));
    if (status_.bound()) {
        uint64_t st = status_.get(seg) & ~uint64_t((1u << 2) | 1u);
        status_.set(seg, st | (set_done_ ? 1u << 2 : 0u) | (latched_ ? 1u : 0u));
    }
}

// ---- analog inputs --------------------------------------------------------------------------

AnalogInputChannel::AnalogInputChannel(Segment& seg, int slave, const std::string& entry, double full_scale)
    : value_(bind_io(seg, slave, entry)), digits_per_volt_(32767.0 / full_scale) {
    if (entry.rfind("analogInput", 0) == 0 && entry.find("Array") == std::string::npos)
        status_ = bind_optional(seg, slave, "status" + channel_of(entry));
}

void AnalogInputChannel::set_volts(Segment& seg, double volts, bool new_sample, unsigned k) noexcept {
    double d = volts * digits_per_volt_;
    bool over = d > 32767.0, under = d < -32768.0;
    int64_t digits = std::isfinite(d) ? std::llround(std::clamp(d, -32768.0, 32767.0)) : 0;
    value_.sample(k).set(seg, uint64_t(digits));
    if (!status_.bound()) return;
    if (new_sample) toggle_ = !toggle_;
    uint16_t st = 0;
    if (under) st |= 1u << 0;
    if (over) st |= 1u << 1;
    if (under || over || !std::isfinite(d)) st |= 1u << 6;
    if (toggle_) st |= 1u << 15;
    status_.set(seg, st);
}

// ---- EL1252 ---------------------------------------------------------------------------------

void LatchInput::update(Segment& seg) noexcept {
    bool v = input.get(seg) & 1;
    if (v != last) {
        uint64_t t = seg.slave(std::size_t(input.slave)).system_time();
        // an EL2252 pin switched at its own time, since the last frame
        if (timed && timed->level[timed_channel] == v) t -= std::min(t, seg.time() - std::min(seg.time(), timed->edge_ns[timed_channel]));
        (v ? positive : negative).set(seg, t);
    }
    last = v;
}

// ---- EL2252 ---------------------------------------------------------------------------------

void TimedOutputs::update(Segment& seg) noexcept {
    const uint64_t now = seg.time();
    Esc& esc = seg.slave(std::size_t(activate.slave));
    const uint64_t sys = esc.system_time();
    auto set_pin = [&](int ch, bool v, uint64_t at) {
        if (level[ch] == v) return;
        level[ch] = v;
        edge_ns[ch] = at;
    };
    if (esc.al_state() != kOp) { // safe state: pins off, nothing armed
        for (int ch = 0; ch < 2; ++ch) set_pin(ch, false, now);
        armed_ = false;
        last_activate_ = 0;
        return;
    }
    if (armed_ && event_ <= sys) { // SYNC0 fired since the last frame, with the data it held
        const uint64_t at = now - std::min(now, sys - event_);
        for (int ch = 0; ch < 2; ++ch) set_pin(ch, data_[ch], at);
        armed_ = false;
        ++events;
    }
    const uint8_t act = uint8_t(activate.get(seg));
    if (act == 3 && last_activate_ != 3) {
        event_ = start_time.get(seg);
        armed_ = event_ > sys;
        if (!armed_) ++missed;
    } else if (act != 3) {
        armed_ = false;
    }
    last_activate_ = act;
    for (int ch = 0; ch < 2; ++ch) data_[ch] = outputs[ch].get(seg) & 1;
}

} // namespace beamctl::ethercat::sim
