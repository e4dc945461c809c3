// Terminal behaviour models: what the firmware of a Beckhoff terminal does with its process data.
//   drives    EL70x1 stepper (velocity mode, enable/reset/reduce-torque bits, stall flag) and
//             EL72x1 servo (CiA402 state machine, cyclic synchronous velocity) turn control words
//             and setpoints into a DriveCommand for the plant and report status back;
//   encoders  turn a plant position into counter values (incremental or absolute, set counter);
//   analog    inputs turn volts into digits with under/overrange status;
//   EL3702    cycle counters, n samples per cycle (oversampling); EL1252 time stamps of input edges.
// The plant (plant.hpp) calls these after every frame on the segment's thread; none allocates
// once built (CoE parameters are read only when a slave enters OP).
#pragma once

#include "ethercat/sim/io_point.hpp"

#include <cmath>
#include <cstdint>
#include <string>

namespace beamctl::ethercat::sim {

class Segment;

// What a drive asks of the mechanics this step.
struct DriveCommand {
    bool powered = false;   // the power stage drives the motor (else the motor is free)
    double velocity = 0;    // commanded velocity [units/s]
    double force_limit = 0; // largest force the motor can exert now [N]
};

// What the mechanics did, for the drive's status word.
struct DriveFeedback {
    double velocity = 0;     // actual velocity [units/s]
    bool saturated = false;  // the motor force was at its limit (blocked, overloaded)
    double dt = 0;           // time this step covered [s]
};

// Motor and transmission behind a drive terminal.
struct MotorParams {
    double units_per_rev = 1;            // stage travel per motor revolution [units/rev] (lead-screw pitch)
    double steps_per_rev = 200;          // stepper: full steps per revolution
    double max_force = 100;              // force at full current [N]
    double velocity_scale = 268435.456;  // servo: setpoint digits per rev/s (2^31 = 8000 rev/s)
    double quick_stop_decel = 100;       // servo: quick-stop ramp [units/s^2]
    double overload_time = 1.0;          // servo: force saturated this long -> fault [s]
    double position_scale = 1048576;     // servo CSP: target position counts per rev (2^20)
    double position_start = 0;           // servo CSP: stage position where the counts are 0
};

class DriveTerminal {
public:
    DriveTerminal(int slave, const MotorParams& p) : slave_(slave), p_(p) {}
    virtual ~DriveTerminal() = default;
    // Reads the outputs (control word, setpoint) and steps the drive's own state; `position` is
    // where the stage is [units] (position-mode drives close their loop on it).
    virtual DriveCommand command(Segment& seg, double dt, double position) noexcept = 0;
    // Writes the status inputs once the plant has moved.
    virtual void report(Segment& seg, const DriveFeedback& fb) noexcept = 0;
    // Latches a drive fault, as a real terminal does on over-temperature or under-voltage;
    // it clears only through the terminal's reset (stepper reset bit, CiA402 fault reset).
    virtual void inject_fault() noexcept = 0;
    virtual bool fault() const noexcept = 0;
    // The slave has just entered OP: read what the master configured over CoE.
    virtual void entered_op(Segment&) {}
    int slave() const { return slave_; }
    const MotorParams& params() const { return p_; }

protected:
    int slave_;
    MotorParams p_;
};

// EL7031/EL7041/EL7047 in velocity mode. Control 0x7010: bit 0 enable, 1 reset, 2 reduce torque;
// status 0x6010: bit 0 ready to enable, 1 ready, 2 warning, 3 error, 4/5 moving +/-, 6 torque
// reduced, 7 motor stall, 15 TxPDO toggle. Setpoint +-32767 = the speed range of 0x8012:05
// (0..5 = 1000..32000 full steps/s, default 2000).
class StepperTerminal : public DriveTerminal {
public:
    StepperTerminal(Segment& seg, int slave, const MotorParams& p);
    DriveCommand command(Segment& seg, double dt, double position) noexcept override;
    void report(Segment& seg, const DriveFeedback& fb) noexcept override;
    void inject_fault() noexcept override { error_ = true; }
    bool fault() const noexcept override { return error_; }
    void entered_op(Segment& seg) override;
    bool stalled() const { return stalled_; }
    double speed_range() const { return speed_range_; } // full steps/s at setpoint 32767

private:
    IoPoint control_, status_, setpoint_;
    double speed_range_ = 2000;
    bool enabled_ = false, reduced_ = false, error_ = false, stalled_ = false, last_reset_ = false;
    bool toggle_ = false;
    double saturated_s_ = 0;
};

// EL7201/EL7211/EL7221 with the CiA402 state machine (controlword 0x7010:01, statusword
// 0x6010:01, actual velocity 0x6010:07) in cyclic synchronous velocity mode (target velocity
// 0x7010:06) or, where the terminal has positionSetpoint01 (0x7010:05, the _CSP variant), cyclic
// synchronous position mode: its own position loop follows the target with feed-forward.
// Quick stop ramps down at quick_stop_decel, then goes to SWITCH ON DISABLED (option code 2).
class Cia402Terminal : public DriveTerminal {
public:
    enum class State : uint8_t {
        NotReadyToSwitchOn, SwitchOnDisabled, ReadyToSwitchOn, SwitchedOn, OperationEnabled,
        QuickStopActive, FaultReactionActive, Fault,
    };
    Cia402Terminal(Segment& seg, int slave, const MotorParams& p);
    DriveCommand command(Segment& seg, double dt, double position) noexcept override;
    void report(Segment& seg, const DriveFeedback& fb) noexcept override;
    void inject_fault() noexcept override;
    bool fault() const noexcept override { return state_ == State::Fault || state_ == State::FaultReactionActive; }
    State state() const { return state_; }
    static uint16_t statusword(State s) noexcept; // the state bits (0-3, 5, 6)
    static const char* name(State s) noexcept;

private:
    IoPoint control_, status_, setpoint_, actual_, target_;
    State state_ = State::NotReadyToSwitchOn;
    double last_target_ = NAN; // CSP: previous target [units]
    bool last_reset_ = false, voltage_ = false, target_reached_ = false;
    double ramp_velocity_ = 0; // during quick stop / fault reaction [units/s]
    double last_velocity_ = 0; // actual velocity of the last step [units/s]
    double overload_s_ = 0;
};

// A position counter: positionActualNN of an encoder terminal (EL5101, EL5042) or of a drive's
// feedback (EL7041 encoder input, EL72x1 resolver). Incremental counters read 0 at power-up
// (counts from where the stage stood); absolute ones read (position - zero) * counts_per_unit.
// Where the terminal has encoderControlNN/encoderValueNN/encoderStatusNN, control bit 2 (set
// counter) loads encoderValueNN and status bit 2 reports it done.
// Index marks (reference pulses, the "C" track) every `index_every` units from `index_offset`:
// where the terminal has encoderLatchPostionNN (EL5101; the spelling is ecmccfg's), control bit 0
// arms latch C on its rising edge; the next index mark crossed latches the counter there, sets
// status bit 0 (latch C valid) until the bit is cleared.
class EncoderChannel {
public:
    EncoderChannel(Segment& seg, int slave, const std::string& entry, double counts_per_unit,
                   bool absolute, double zero, double start_position, double index_every = 0,
                   double index_offset = 0);
    void update(Segment& seg, double position) noexcept;
    int64_t counts() const { return counts_; }
    int slave() const { return slave_; }
    // Fault injection: the counter jumps by `counts` (lost or extra pulses) and keeps counting.
    void glitch(int64_t counts) noexcept { offset_ += counts; }

private:
    int slave_;
    IoPoint value_, control_, setval_, status_, latch_;
    double counts_per_unit_, zero_;
    double index_every_, index_offset_;
    double last_position_;
    int64_t offset_ = 0, counts_ = 0;
    bool last_set_ = false, set_done_ = false;
    bool last_arm_ = false, armed_ = false, latched_ = false;
};

// An analog input channel: analogInputNN (and its statusNN word where the terminal has one:
// bit 0 underrange, 1 overrange, 6 error, 15 toggle on every new sample). +-full_scale volts
// map to +-32767 and clip there.
class AnalogInputChannel {
public:
    AnalogInputChannel(Segment& seg, int slave, const std::string& entry, double full_scale = 10);
    // Sample `k` (0-based; > 0 only for an oversampling channel, see samples()).
    void set_volts(Segment& seg, double volts, bool new_sample, unsigned k = 0) noexcept;
    unsigned samples(Segment& seg) const noexcept { return value_.samples(seg); }

private:
    IoPoint value_, status_;
    double digits_per_volt_;
    bool toggle_ = false;
};

// EL3702 cycleCounterNN: counts the samples the terminal took (one per cycle).
struct CycleCounter {
    IoPoint counter;
    uint64_t count = 0;
    void update(Segment& seg) noexcept { counter.set(seg, ++count); }
};

// EL2252 binaryOutput01/02 switched by distributed clocks (SYNC0 single shot): the terminal takes
// startTime (the DC system time of the next switching) when `activate` becomes 3 and sets its pins
// to binaryOutputNN at that time; the outputs hold between events. ecmccfg's sequence
// (examples/test/el1252Toel2252): startTime, the outputs and activate 0 in one frame, activate 3 in
// the next. A start time that is already past when activated never fires (counted in `missed`), as
// an ESC's SYNC0 start time in the past does not; activate 0 cancels an event not yet fired.
// Pins are off while the slave is not in OP.
struct TimedOutputs {
    IoPoint activate, start_time, outputs[2];
    bool level[2] = {};       // the pins
    uint64_t edge_ns[2] = {}; // segment time [ns] of each pin's last change
    uint64_t events = 0, missed = 0;
    void update(Segment& seg) noexcept;

private:
    bool armed_ = false;
    uint8_t last_activate_ = 0;
    uint64_t event_ = 0;        // DC system time of the armed event
    bool data_[2] = {};         // binaryOutputNN of the last frame (what SYNC0 latches)
};

// EL1252 binaryInputNN with timestampLatchPositiveNN/NegativeNN: the slave's DC system time of
// the last rising/falling edge (edges are seen once per frame).
// An input wired to an EL2252 pin (`timed`) latches the pin's edge time, between frames.
struct LatchInput {
    IoPoint input, positive, negative;
    const TimedOutputs* timed = nullptr;
    int timed_channel = 0;
    bool last = false;
    void update(Segment& seg) noexcept;
};

} // namespace beamctl::ethercat::sim
