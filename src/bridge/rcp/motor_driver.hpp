// A motor record's driver for an RCP MOTOR object: commands become MOTOR write entries
// ([0] command, [1] target, [2] velocity, [3] acceleration, [4] sequence number), status comes
// from the object's readback entries ([0] position, [1] velocity, [2] status bits, [3] position
// error, [4] error code).
//
// "Done after the command": readbacks carry no sequence number, so a readback with done=1 that
// arrives after a command may have left the RCP before the command arrived there. After a motion
// command (move, jog, home) the driver is Sent and reports done=false, moving=true. It becomes
// Acknowledged on the first readback showing done=0 or moving=1, and Idle (done) on the first
// readback with done=1 after that. If the RCP never shows motion (a null move, a refused command,
// an RCP that only sends on change), the driver falls back to Idle once ack_timeout_s has passed
// since the command and the latest readback says done=1. While Sent, stale problem bits are not
// reported (problem=false) so an old error cannot end a new move. Stop and enable/disable do not
// start a new wait when the motor is idle (so STOP on a motor at rest never drops DMOV).
// Offline (set_comm_error(true): the application timed out): any wait ends, and status() says
// done, not moving, problem and comm_error, so the record ends a motion in progress at once in
// INVALID/COMM with its target set to the readback and no retries. Move, jog, home and
// enable/disable are refused while offline (logged, nothing sent, nothing kept to send later),
// so a move ends like an interrupted one at the record's next poll; only stop is still sent (it
// can only make a machine safer). Nothing is ever re-sent when the application comes back.
// set_position has no command in the protocol: it is refused (logged, nothing sent, the
// readback unchanged).
//
// Threading: used only on the IOC loop thread (like its motor record).
#pragma once

#include "bridge/rcp/protocol.hpp"
#include "pv/motor_record.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <string>

namespace beamctl::bridge::rcp {

class RcpMotorDriver final : public pv::MotorDriver {
public:
    using Command = std::array<double, 5>; // the five float64 of a MOTOR write entry
    // Sends one MOTOR write entry; false if it could not be sent.
    using SendFn = std::function<bool(const Command&)>;
    using Clock = std::function<double()>; // monotonic [s]

    enum class Phase : uint8_t { Idle, Sent, Acknowledged };

    // `name` is used in log messages. ack_timeout_s [s] > 0.
    RcpMotorDriver(std::string name, SendFn send, Clock clock, double ack_timeout_s);

    // pv::MotorDriver (dial EGU, EGU/s, EGU/s^2)
    void move(double dial_target, double velocity, double acceleration) override;
    void move_velocity(double velocity, double acceleration) override;
    void home(bool forward, double velocity, double acceleration) override;
    void stop(double acceleration) override;
    void set_position(double dial_position) override;
    void set_closed_loop(bool on) override;
    Status status() override;

    // Bridge side: a readback entry's five values arrived at now_s [s]. True if the values or
    // the phase changed (the motor record should poll).
    bool on_readback(const double* values, double now_s);
    // The application went offline (true) or came back (false); see the top of this file.
    void set_comm_error(bool on);
    // No more sends (the object is retired); later commands are dropped.
    void detach() { send_ = nullptr; }

    Phase phase() const { return phase_; }
    uint32_t sequence() const { return sequence_; } // of the last command sent
    bool has_readback() const { return has_readback_; }
    double position_error() const { return rb_[3]; } // [EGU]
    double error_code() const { return rb_[4]; }

private:
    bool send(MotorCommand c, double target, double velocity, double acceleration);
    bool refused_offline(MotorCommand c); // true (logged) if c may not be sent now
    void begin_wait();                    // a motion command was sent
    void check_timeout(double now_s);

    std::string name_;
    SendFn send_;
    Clock clock_;
    double ack_timeout_s_;
    Phase phase_ = Phase::Idle;
    double sent_at_s_ = 0;
    uint32_t sequence_ = 0;
    std::array<double, 5> rb_{}; // latest readback
    uint32_t bits_ = motor_status::kDone;
    bool has_readback_ = false;
    bool comm_error_ = false;
    bool last_dir_positive_ = true;
};

} // namespace beamctl::bridge::rcp
