// The synApps motor record (record(motor, "...")) on a MotorDriver, so that pyepics epics.Motor,
// ophyd EpicsMotor and bluesky drive beamctl axes unchanged. Semantics follow motorRecord.cc
// (epics-modules/motor R7): user/dial/raw calibration, SET/FOFF, soft and hard limits, DMOV 1->0->1
// for every drive-field write, put-callback completion when the motion is done, STOP/SPMG,
// HOMF/HOMR, JOGF/JOGR, TWF/TWR, RLV, backlash, retries, DLY, MSTA. See docs in the .cpp header.
// Threading: a motor record, its driver and SimMotorDriver are used only on the owning
// database's thread (the IOC loop), like every record.
#pragma once

#include "pv/record.hpp"

#include <functional>
#include <memory>
#include <string_view>

namespace beamctl::pv {

// What a motor record drives: a beamctl motion axis, a UDP bridge to a remote controller, a sim.
// All positions are DIAL units [EGU] (the record does user<->dial<->raw), velocities [EGU/s],
// accelerations [EGU/s^2]. Commands return at once; progress is seen through status().
// Contract: after move(), move_velocity() or home() returns, status() reports done=false until
// that command has finished (a driver that cannot know yet must report done=false), so the record
// never mistakes the status from before the command for the end of the motion. move() while a
// move is in progress retargets it.
class MotorDriver {
public:
    virtual ~MotorDriver() = default;
    virtual void move(double dial_target, double velocity, double acceleration) = 0;
    virtual void move_velocity(double velocity, double acceleration) = 0; // jog; signed velocity
    virtual void home(bool forward, double velocity, double acceleration) = 0; // forward: dial +
    virtual void stop(double acceleration) = 0;
    virtual void set_position(double dial_position) = 0; // SET/calibration: no motion
    virtual void set_closed_loop(bool on) = 0;           // CNEN
    // DLLM/DHLM (dial) were written: a controller with soft limits of its own takes them (both 0:
    // the record has no limits). Not called at init.
    virtual void set_soft_limits(double dial_low, double dial_high) {
        (void)dial_low;
        (void)dial_high;
    }
    // PCOF (0), ICOF (1), DCOF (2): the controller's gains; false refuses the value.
    virtual bool set_gain(int which, double value) {
        (void)which;
        (void)value;
        return true;
    }
    struct Status {
        double position = 0; // dial readback [EGU]
        double encoder = 0;  // dial encoder readback [EGU], valid when has_encoder
        bool has_encoder = false;
        double velocity = 0; // [EGU/s]
        bool done = true, moving = false, direction_positive = true;
        bool high_limit = false, low_limit = false; // switches at the dial + / dial - end
        bool home_switch = false, homed = false;
        bool problem = false, comm_error = false, enabled = true, slip_stall = false;
        // The readback is known. A driver that has not read its controller yet says false; when
        // it becomes true while the record is idle, VAL/DVAL/RVAL take the readback.
        bool valid = true;
        // The last command was refused or its motion ended short of the target (a limit, an
        // interlock, a fault): the record ends that motion in alarm and fails its put-callback.
        bool failed = false;
        bool limit_violation = false; // ... for a soft limit (its own or, for a virtual axis, a
                                      // real axis's): the record sets LVIO
        // Requests from the controller (ECMC mc_mr_set_sync/stop): when a count changes, the
        // record takes the readback as its target (when idle), or stops as for STOP=1.
        uint32_t sync_requests = 0, stop_requests = 0;
    };
    virtual Status status() = 0; // latest, cheap; called when the record polls
};

// Monotonic time [s]; the default clock of the record and the sim is std::chrono::steady_clock
// (CLOCK_MONOTONIC, the clock of EventLoop::now_s). Tests inject virtual time.
using MotorClock = std::function<double()>;

// An ideal motor without switches: trapezoid moves (velocity, acceleration) from wherever it is,
// jogs, stops, and home() that moves to the home position (default dial 0) and sets `homed`.
// Motion is a function of the clock, evaluated when status() is called.
class SimMotorDriver final : public MotorDriver {
public:
    explicit SimMotorDriver(MotorClock clock = {}, double dial_position = 0);
    ~SimMotorDriver() override;
    void set_clock(MotorClock clock);
    void set_home_position(double dial_position); // where home() ends [EGU]

    void move(double dial_target, double velocity, double acceleration) override;
    void move_velocity(double velocity, double acceleration) override;
    void home(bool forward, double velocity, double acceleration) override;
    void stop(double acceleration) override;
    void set_position(double dial_position) override;
    void set_closed_loop(bool on) override;
    Status status() override;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// A record of type "motor". Created by the database from .db files; whoever builds the IOC gives
// it a driver (set_driver, or attach_motor_drivers by OUT/name) before or after init_records().
// A record that has no driver when it is initialised gets a SimMotorDriver (DTYP "Sim Motor").
// Polling: the record polls its driver whenever it is processed and, whatever its SCAN field
// says, every 0.1 s from Database::scan_periodic (see the .cpp for how).
class MotorRecord : public Record {
public:
    // Attaches the driver. After init, VAL/DVAL/RVAL are set to the new driver's readback and a
    // motion in progress is forgotten (not stopped).
    virtual void set_driver(std::shared_ptr<MotorDriver> driver) = 0;
    virtual const std::shared_ptr<MotorDriver>& driver() const = 0;
    // Time source for DLY and for the built-in SimMotorDriver.
    virtual void set_clock(MotorClock clock) = 0;
    // Reads the driver status, updates RBV DRBV RRBV MSTA HLS LLS MOVN TDIR DMOV ..., advances the
    // motion (backlash, retries, DLY), posts monitors of changed fields and completes a pending
    // put-callback when the motion is done. No-op before init.
    virtual void poll() = 0;
    // The OUT field as written in the .db file (e.g. "@asyn(MCU1,1)"): a driver address.
    virtual std::string_view out() const = 0;

    static MotorRecord* from(Record* r); // nullptr when r is not a motor record

protected:
    using Record::Record;
};

void register_motor_record(RecordTypes& types); // adds the "motor" type

// Offers every motor record of `db` to `factory`; a non-null result becomes its driver.
void attach_motor_drivers(Database& db,
                          const std::function<std::shared_ptr<MotorDriver>(MotorRecord&)>& factory);

} // namespace beamctl::pv
