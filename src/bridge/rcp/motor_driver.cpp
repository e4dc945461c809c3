#include "bridge/rcp/motor_driver.hpp"

#include "core/log.hpp"

#include <cmath>
#include <cstring>
#include <utility>

namespace beamctl::bridge::rcp {
namespace {
log::Logger lg("rcp.motor");

const char* command_name(MotorCommand c) {
    switch (c) {
    case MotorCommand::None:
        return "none";
    case MotorCommand::MoveAbsolute:
        return "move";
    case MotorCommand::Stop:
        return "stop";
    case MotorCommand::HomeForward:
        return "home forward";
    case MotorCommand::HomeReverse:
        return "home reverse";
    case MotorCommand::JogForward:
        return "jog forward";
    case MotorCommand::JogReverse:
        return "jog reverse";
    case MotorCommand::Enable:
        return "enable";
    case MotorCommand::Disable:
        return "disable";
    }
    return "?";
}

} // namespace

RcpMotorDriver::RcpMotorDriver(std::string name, SendFn send, Clock clock, double ack_timeout_s)
    : name_(std::move(name))
    , send_(std::move(send))
    , clock_(std::move(clock))
    , ack_timeout_s_(ack_timeout_s) {}

bool RcpMotorDriver::refused_offline(MotorCommand c) {
    if (!comm_error_ || c == MotorCommand::Stop) return false;
    LOG_WARN(lg, "motor " << name_ << ": " << command_name(c)
                          << " refused: the application is offline (nothing sent)");
    return true;
}

void RcpMotorDriver::set_comm_error(bool on) {
    comm_error_ = on;
    if (on) phase_ = Phase::Idle; // nothing more to wait for
}

bool RcpMotorDriver::send(MotorCommand c, double target, double velocity, double acceleration) {
    if (!send_) {
        LOG_WARN(lg, "motor " << name_ << ": object retired, command " << int(c) << " dropped");
        return false;
    }
    ++sequence_;
    Command cmd{double(uint8_t(c)), target, velocity, acceleration, double(sequence_)};
    return send_(cmd);
}

void RcpMotorDriver::begin_wait() {
    phase_ = Phase::Sent;
    sent_at_s_ = clock_ ? clock_() : 0;
}

void RcpMotorDriver::move(double target, double velocity, double acceleration) {
    if (refused_offline(MotorCommand::MoveAbsolute)) return;
    last_dir_positive_ = target >= rb_[0];
    send(MotorCommand::MoveAbsolute, target, velocity, acceleration);
    begin_wait();
}

void RcpMotorDriver::move_velocity(double velocity, double acceleration) {
    if (velocity == 0) return stop(acceleration);
    MotorCommand c = velocity > 0 ? MotorCommand::JogForward : MotorCommand::JogReverse;
    if (refused_offline(c)) return;
    last_dir_positive_ = velocity > 0;
    send(c, rb_[0], std::fabs(velocity), acceleration);
    begin_wait();
}

void RcpMotorDriver::home(bool forward, double velocity, double acceleration) {
    MotorCommand c = forward ? MotorCommand::HomeForward : MotorCommand::HomeReverse;
    if (refused_offline(c)) return;
    last_dir_positive_ = forward;
    send(c, rb_[0], std::fabs(velocity), acceleration);
    begin_wait();
}

void RcpMotorDriver::stop(double acceleration) {
    send(MotorCommand::Stop, rb_[0], 0, acceleration);
    // A stop ends whatever is in progress; it starts no wait of its own when nothing is.
    if (phase_ == Phase::Sent) sent_at_s_ = clock_ ? clock_() : 0;
}

void RcpMotorDriver::set_position(double dial_position) {
    LOG_WARN(lg, "motor " << name_ << ": set position " << dial_position
                          << " refused: the RCP protocol has no command to redefine the position");
}

void RcpMotorDriver::set_closed_loop(bool on) {
    if (refused_offline(on ? MotorCommand::Enable : MotorCommand::Disable)) return;
    send(on ? MotorCommand::Enable : MotorCommand::Disable, rb_[0], 0, 0);
}

bool RcpMotorDriver::on_readback(const double* v, double now_s) {
    bool changed = !has_readback_;
    for (int i = 0; i < 5; ++i) {
        // bitwise: NaN readbacks compare equal to themselves
        changed = changed || std::memcmp(&rb_[i], &v[i], sizeof(double)) != 0;
        rb_[i] = v[i];
    }
    Phase before = phase_;
    double b = v[2];
    bits_ = b >= 0 && b < 4294967296.0 ? uint32_t(b) : motor_status::kError;
    has_readback_ = true;
    bool done = bits_ & motor_status::kDone, moving = bits_ & motor_status::kMoving;
    if (phase_ == Phase::Sent && (!done || moving))
        phase_ = Phase::Acknowledged;
    else if (phase_ == Phase::Acknowledged && done && !moving)
        phase_ = Phase::Idle;
    check_timeout(now_s);
    return changed || phase_ != before;
}

void RcpMotorDriver::check_timeout(double now_s) {
    if (phase_ != Phase::Sent || now_s - sent_at_s_ < ack_timeout_s_) return;
    bool done = bits_ & motor_status::kDone, moving = bits_ & motor_status::kMoving;
    if (!has_readback_ || comm_error_ || (done && !moving)) phase_ = Phase::Idle;
}

pv::MotorDriver::Status RcpMotorDriver::status() {
    if (clock_) check_timeout(clock_());
    Status s;
    s.position = rb_[0];
    s.encoder = rb_[0];
    s.has_encoder = false;
    s.velocity = rb_[1];
    bool done = bits_ & motor_status::kDone, moving = bits_ & motor_status::kMoving;
    bool error = bits_ & motor_status::kError;
    if (phase_ == Phase::Idle) {
        s.done = done;
        s.moving = moving;
        s.problem = error;
        if (rb_[1] != 0) last_dir_positive_ = rb_[1] > 0;
    } else {
        s.done = false;
        s.moving = true;
        s.problem = phase_ == Phase::Acknowledged && error;
    }
    s.direction_positive = last_dir_positive_;
    s.high_limit = bits_ & motor_status::kHighLimit;
    s.low_limit = bits_ & motor_status::kLowLimit;
    s.homed = bits_ & motor_status::kHomed;
    s.enabled = bits_ & motor_status::kEnabled;
    s.home_switch = false;
    s.comm_error = comm_error_ || !has_readback_;
    if (comm_error_) { // nothing is known: stopped, and a motion in progress failed
        s.done = true;
        s.moving = false;
        s.problem = true;
    }
    return s;
}

} // namespace beamctl::bridge::rcp
