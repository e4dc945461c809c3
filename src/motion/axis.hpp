// A motion axis as ECMC runs it, once per RT cycle between bus receive and bus send:
//   inputs    limit switches, home sensor, external interlock (polarity applied), bus status
//   encoder   raw counter -> actual position and velocity
//   sequencer the command being executed: positioning, velocity, homing, stopping
//   trajectory setpoint (trapezoid or S-curve) from the sequencer's target
//   monitor   hard and soft limits, lag, at-target, max velocity, interlocks; faults latch an
//             ECMC error id, stop the axis with the emergency deceleration and, for some, disable it
//   control   CSV: velocity = Kff * trajectory velocity + PID(setpoint - actual)
//   drive     enable sequence, control word, velocity setpoint
// Commands (AxisCommand) come through Axis::command(), called on the RT thread (the axis group
// drains a queue filled by non-RT code). Everything is noexcept and allocation-free once built.
#pragma once

#include "motion/axis_variables.hpp"
#include "motion/controller.hpp"
#include "motion/drive.hpp"
#include "motion/encoder.hpp"
#include "motion/homing.hpp"
#include "motion/pvt.hpp"
#include "motion/trajectory.hpp"
#include "registry/signal.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::motion {

// ECMC error and warning ids the axis raises (ecmc main/ecmcErrorsList.h; specs/ecmc.md §5).
// Errors (0x1xxxx) latch and stop the axis; warnings (0x11xxxx) refuse or stop a move only.
namespace error_id {
constexpr uint32_t kNone = 0;
constexpr uint32_t kBusNotOk = 0x14315;        // ERROR_AXIS_HARDWARE_STATUS_NOT_OK: disabled
constexpr uint32_t kNotEnabled = 0x14316;      // ERROR_AXIS_NOT_ENABLED: motion command refused
constexpr uint32_t kNotAllowedWhenEnabled = 0x14319; // ERROR_AXIS_COMMAND_NOT_ALLOWED_WHEN_ENABLED
constexpr uint32_t kBusy = 0x1431C;            // ERROR_AXIS_BUSY: homing while busy
constexpr uint32_t kSlavedAxisInError = 0x1432B; // ERROR_AXIS_SLAVED_AXIS_IN_ERROR (mc_grp_set_slaved_axis_in_error)
constexpr uint32_t kSlavedAxisInterlock = 0x1432E; // ERROR_AXIS_SLAVED_AXIS_INTERLOCK (mc_grp_set_slaved_axis_ilocked)
constexpr uint32_t kAutoEnableTimeout = 0x1432F; // ERROR_AXIS_AUTO_ENABLE_TIMEOUT: not enabled in time
constexpr uint32_t kDriveAlarm0 = 0x1460E;     // ERROR_DRV_HW_ALARM_0..2: drive error input n
constexpr uint32_t kDriveTimeout = 0x14613;    // ERROR_DRV_STATE_MACHINE_TIME_OUT (stepper)
constexpr uint32_t kDs402Timeout = 0x14652;    // ERROR_DRV_DS402_STATE_MACHINE_TIME_OUT
constexpr uint32_t kDs402Fault = 0x14655;      // ERROR_DRV_DS402_FAULT_STATE
constexpr uint32_t kMaxVelocity = 0x14C07;     // ERROR_MON_MAX_VELOCITY_EXCEEDED
constexpr uint32_t kLag = 0x14C08;             // ERROR_MON_MAX_POSITION_LAG_EXCEEDED
constexpr uint32_t kExternalInterlock = 0x14C09; // ERROR_MON_EXTERNAL_HARDWARE_INTERLOCK
constexpr uint32_t kBothLimits = 0x14C10;      // ERROR_MON_BOTH_LIMIT_INTERLOCK
constexpr uint32_t kStall = 0x14C19;           // ERROR_MON_STALL
constexpr uint32_t kSeqFailed = 0x14D04;       // ERROR_SEQ_SEQ_FAILED: unexpected limit while homing
constexpr uint32_t kSeqCmdData = 0x14D0A;      // ERROR_SEQ_CMD_DATA_UNDEFINED: unknown homing sequence
constexpr uint32_t kNoHomeFlank = 0x14D0C;     // ERROR_SEQ_NO_HOME_SWITCH_FLANK
constexpr uint32_t kNoSecondHomeFlank = 0x14D0D; // ERROR_SEQ_NO_SECOND_HOME_SWITCH_FLANK
constexpr uint32_t kLatchCount = 0x14D14;     // ERROR_SEQ_LATCH_COUNT_OUT_OF_RANGE (or no latch)
constexpr uint32_t kVelocityZero = 0x14D12;    // ERROR_SEQ_VELOCITY_ZERO (also bad parameters)
constexpr uint32_t kHomeNotAllowed = 0x14D1A;  // ERROR_SEQ_HOME_NOT_ALLOWED (sequence 0)
constexpr uint32_t kAbsBitsOutOfRange = 0x14D0E; // ERROR_SEQ_ERROR_ABS_BIT_OUT_OF_RANGE (homing 21/22)
constexpr uint32_t kHomeSeqNotSupported = 0x14D19; // ERROR_SEQ_HOME_SEQ_NOT_SUPPORTED (26 without trigg/ready)
constexpr uint32_t kPrimaryEncoderOutOfRange = 0x14327; // ERROR_AXIS_PRIMARY_ENC_ID_OUT_OF_RANGE
constexpr uint32_t kPrimaryEncoderWhileBusy = 0x14328;  // ERROR_AXIS_SWITCH_PRIMARY_ENC_NOT_ALLOWED_WHEN_BUSY
constexpr uint32_t kMotionNotAllowed = 0x14D16; // ERROR_SEQ_MOTION_CMD_NOT_ENABLED (allowedFunctions)
// refusals that do not latch an axis error (ECMC returns them to the caller only)
constexpr uint32_t kTrajSourceNotInternal = 0x20052; // ERROR_MAIN_TRAJ_SOURCE_NOT_INTERNAL
constexpr uint32_t kCommandsBlocked = 0x20053;       // ERROR_MAIN_AXIS_COM_BLOCKED (allowplccmd 0)
constexpr uint32_t kBlockCom = 0x20039; // ERROR_MAIN_AXIS_BLOCK_COM: ax<n>.blockcom / features.blockCom
// warnings
constexpr uint32_t kEnableLost = 0x114601;     // WARNING_DRV_ENABLED_LOST
constexpr uint32_t kHardLimitFwd = 0x114C02;   // WARNING_MON_HARD_LIMIT_FWD_INTERLOCK
constexpr uint32_t kHardLimitBwd = 0x114C03;   // WARNING_MON_HARD_LIMIT_BWD_INTERLOCK
constexpr uint32_t kSoftLimitFwd = 0x114D00;   // WARNING_SEQ_SETPOINT_SOFTLIM_FWD_VILOATION
constexpr uint32_t kSoftLimitBwd = 0x114D01;   // ..._BWD_...
const char* text(uint32_t id) noexcept;
inline bool is_warning(uint32_t id) noexcept { return id >= 0x100000; }
} // namespace error_id

// ECMC's last-interlock codes (status bits 27-31).
enum class Interlock : uint8_t {
    None = 0, SoftBwd = 1, SoftFwd = 2, HardBwd = 3, HardFwd = 4, NoExecute = 5, Lag = 6,
    BothLimits = 7, External = 8, MaxSpeed = 10, AxisError = 13, UnexpectedLimit = 14,
    BusNotOk = 16, Plc = 17, PlcBwd = 18, PlcFwd = 19, Stall = 23,
};

struct AxisParams {
    int id = 1;
    std::string name;
    bool virtual_axis = false; // no drive, no encoder: actual = setpoint
    bool csp = false;          // cyclic synchronous position: the drive gets the setpoint position
                               // (in the primary encoder's frame), no axis position loop
    // CSP_PC: CSP with the axis's PID on top: the drive gets setpoint + a position correction from
    // the primary encoder's error (while busy or outside the deadband), in the frame of encoder
    // `csp_drive_encoder` (encoder.useAsCSPDrvEnc: the drive's own)
    bool csp_pc = false;
    int csp_drive_encoder = -1;
    EncoderParams encoder;
    DriveParams drive;
    ControllerParams controller;
    TrajectoryLimits trajectory;      // velocity, acceleration, deceleration, jerk (0 = trapezoid)
    double emergency_deceleration = 0; // [units/s^2]; 0 = 3 x deceleration (as ECMC)
    double jog_velocity = 0;          // [units/s]; 0 = trajectory velocity
    double modulo_range = 0;          // [units]; 0 = linear axis
    int modulo_type = 0;
    // limits and inputs: polarity 0 = the signal reads 1 while OK (normally closed), 1 = inverted
    int limit_fwd_polarity = 0, limit_bwd_polarity = 0, home_polarity = 0, interlock_polarity = 0;
    bool soft_fwd_enable = false, soft_bwd_enable = false;
    double soft_fwd = 0, soft_bwd = 0; // [units]
    // monitoring; times in cycles, as ECMC
    bool lag_enable = false;
    double lag_tolerance = 0;
    int lag_time_cycles = 0;
    bool target_enable = false;
    double target_tolerance = 0;
    int target_time_cycles = 0;
    bool velocity_enable = false;
    double velocity_max = 0;
    int velocity_time_traj_cycles = 200, velocity_time_drive_cycles = 400;
    bool stall_enable = true; // needs target monitoring
    // motor brake (drive.brake): opened this many cycles after the drive is enabled; closed this
    // many cycles before the drive is disabled (ECMC openDelay / closeAhead)
    int brake_open_delay_cycles = 0, brake_close_ahead_cycles = 0;
    bool enable_at_startup = false; // re-enable after a bus outage (ECMC autoEnable.atStartup)
    // ECMC autoEnable (axis.autoEnable): a motion command to a disabled axis enables it and runs
    // once it is enabled, error kAutoEnableTimeout (and disabled) if it is not within
    // `auto_enable_timeout_s`; an enabled axis idle (not busy, at target when target monitoring
    // is on) for `auto_disable_timeout_s` is disabled. <= 0: off (ECMC: active when > 0).
    double auto_enable_timeout_s = -1, auto_disable_timeout_s = -1;
    // PLC connection (ECMC): initial sources (0 internal/encoder, 1 PLC: traj.extsetpos /
    // enc.extactpos), commands from PLC variables, switches written by PLC code (plcOverride)
    int trajectory_source = 0, encoder_source = 0;
    bool external_commands = false;  // plc.externalCommands: traj.* commands from PLC code
    bool block_com = false; // features.blockCom at start (ax<n>.blockcom): motion and enable refused
    bool allow_source_change = true; // features.allowSrcChangeWhenEnabled (else only when disabled)
    // features.allowedFunctions: positioning (absolute/relative moves), constantVelocity (velocity
    // moves, jogs), homing; a command of a function not allowed is refused with kMotionNotAllowed
    bool allow_positioning = true, allow_constant_velocity = true, allow_homing = true;
    bool limit_fwd_plc = false, limit_bwd_plc = false, home_plc = false;
    // homing defaults (ECMC encoder.homing)
    int homing_sequence = 0;
    double homing_position = 0;
    double homing_velocity_to = 0, homing_velocity_from = 0; // [units/s]; 0 = velocity/10
    double homing_acceleration = 0;                           // 0 = trajectory acceleration
    int homing_latch_count = 1; // sequences 11/12: reference on this index latch
    // All encoders of the axis in file order (ECMC Enc01..); `encoder` above is the primary one,
    // at index `primary_encoder` here. The others are read for their PVs only.
    std::vector<EncoderParams> encoders;
    int primary_encoder = 0;
    bool homing_post_move_enable = false;
    double homing_post_move_position = 0;
    // axis.autoMode: the drive mode for motion (modeCmdMotion) and homing (modeCmdHome); -1 none
    int auto_mode_motion = -1, auto_mode_home = -1;
};

// Where the axis reads and writes (bound signals; unbound ones are not used).
struct AxisIo {
    registry::BoundSignal encoder;                            // raw position
    registry::BoundSignal drive_control, drive_status, drive_setpoint;
    registry::BoundSignal limit_fwd, limit_bwd, home, interlock;
    registry::BoundSignal bus_status; // ec<m>.masterstatus: 1 while the bus's cycle is consistent
    // ec<m>.s<k>.valid of every slave the axis reads or writes: 1 while its data takes part, in OP
    std::vector<registry::BoundSignal> slave_valid;
    registry::BoundSignal brake;      // output: 1 = brake open (released); unbound: no brake
    // encoder latch (index homing 11/12): latched counter, arm bit (encoder control), valid bit
    registry::BoundSignal latch_position, latch_arm, latch_valid;
    // drive-internal homing (sequence 26): start output, done input (encoder homing.trigg/ready)
    registry::BoundSignal homing_trigg, homing_ready;
    // axis.autoMode: the drive's mode of operation, written and read back
    registry::BoundSignal mode_set, mode_act;
    std::vector<registry::BoundSignal> encoders; // raw counters of AxisParams::encoders
};

enum class CommandType : uint8_t {
    None = 0, MoveVelocity = 1, MoveRelative = 2, MoveAbsolute = 3, Home = 10,
    MovePvt = 9,     // a PVT path (Axis::start_pvt; ECMC_CMD_MOVEPVTABS), never sent as a command
    Halt = 20,       // ramp down with the command's (or configured) deceleration
    Stop = 21,       // ramp down with the emergency deceleration
    Power = 22,      // enable (on) or disable
    Reset = 23,      // clear errors whose cause is gone; reset the drive
    SetPosition = 24, // the actual position reads `position` (no motion)
    SetGain = 25,     // controller gain `gain` (0 Kp, 1 Ki, 2 Kd) := `position` (motor record PCOF..)
    SetSoftLimits = 26, // the soft limits and their enables (motor record DHLM/DLLM, ecmccfg CfgDHLM...)
};

struct AxisCommand {
    CommandType type = CommandType::None;
    double position = 0;     // target [units] (absolute), distance (relative), new position
    double velocity = 0;     // [units/s]; 0 = configured (MoveVelocity: signed, required)
    double acceleration = 0, deceleration = 0; // [units/s^2]; 0 = configured
    int homing_sequence = -1; // Home: -1 or 14 = the configured sequence (ECMC: 14 = encoder's)
    bool on = false;         // Power
    bool set_home_position = false; // Home: `position` is the new homing position (mc_home_pos)
    int gain = 0;            // SetGain: 0 Kp, 1 Ki, 2 Kd
    // SetSoftLimits: each that is not NaN (a limit [units]) or -1 (an enable) replaces the axis's
    double soft_fwd = std::nan(""), soft_bwd = std::nan("");
    int8_t soft_fwd_on = -1, soft_bwd_on = -1;
    uint64_t tag = 0;        // echoed as AxisStatus::done_tag when this command has finished
};

struct AxisStatus {
    double act_pos = 0, act_vel = 0;       // [units], [units/s]
    double set_pos = 0, set_vel = 0;       // trajectory setpoint
    double pos_err = 0;                    // setpoint - actual
    double target_pos = 0;                 // of the current/last move
    double drive_output = 0;               // velocity sent to the drive [units/s]
    bool enable_cmd = false, enabled = false;
    bool busy = false, at_target = false, moving = false;
    bool limit_fwd = false, limit_bwd = false; // switch ACTIVE (at the limit)
    bool home_sensor = false, homed = false;
    bool soft_limit_fwd = false, soft_limit_bwd = false; // at/beyond an enabled soft limit
    bool soft_fwd_enabled = false, soft_bwd_enabled = false;
    double soft_fwd = 0, soft_bwd = 0; // the soft limits now [units] (PLC code may move them)
    bool brake_open = false;
    static constexpr int kMaxEncoders = 8;
    std::array<double, kMaxEncoders> enc_pos{}; // every encoder's position (Enc01..) [units]
    int enc_count = 0;
    bool ilock_fwd = false, ilock_bwd = false;           // motion in that direction blocked
    uint32_t error_id = 0, warning_id = 0;
    Interlock last_interlock = Interlock::None;
    int sequence_state = 0;
    CommandType command = CommandType::None;
    uint64_t done_tag = 0;  // tag of the last command that finished (or was refused)
    uint64_t refused_tag = 0; // tag of the last command refused
    // The last motion command was refused or ended short (a limit, an interlock, a fault, a stop
    // of its kinematics group): a move that did not get where it was sent never reads as success.
    // Cleared when the next motion command is accepted.
    bool move_failed = false;
    bool following = false;      // the setpoint comes from the PLC (traj.source 1)
    bool ext_moving = false;     // ... and moved this cycle: something else moves the axis
    bool ext_limited = false;    // the PLC's setpoint was held at a limit this cycle
    bool position_valid = false; // act_pos has been read from a working bus (and, for a PLC-fed
                                 // actual position, after the PLC's first scan)
    // Requests to the motor record (PLC mc_mr_set_sync/stop, mc_grp_mr_set_*): the record
    // syncs VAL to the readback / stops when the count changes.
    uint32_t mr_sync_requests = 0, mr_stop_requests = 0;
    uint64_t cycle = 0;
    // ECMC `Stat` bits: 0 enable, 1 enabled, 2 execute, 3 busy, 4 attarget, 5 moving, 6 limit fwd
    // OK (1 = not on the switch), 7 limit bwd OK, 8 home switch, 9 homed, 14/15 soft limit fwd/bwd
    // enabled, 17/18 motion fwd/bwd interlocked, 19/20 soft-limit interlock fwd/bwd, 21 busy,
    // 24-26 sequence state, 27-31 last interlock
    uint32_t stat_word() const noexcept;
};

class Axis {
public:
    Axis(const AxisParams& p, const AxisIo& io);
    Axis(const Axis&) = delete; // its Homing refers to it
    Axis& operator=(const Axis&) = delete;

    // RT: one cycle of `dt` seconds. Reads inputs from the image, writes drive outputs.
    void run(double dt) noexcept;
    // RT: starts a command. Returns 0 when accepted, else the error/warning id why not (the
    // command is then finished at once: done_tag = its tag). A motion command for an axis whose
    // trajectory source is the PLC (traj.source 1) takes the axis back to its own trajectory,
    // starting from the PLC's setpoint, when features.allowSrcChangeWhenEnabled is set (how a
    // virtual axis that follows its physical axes is commanded); otherwise it is refused with
    // kTrajSourceNotInternal.
    [[nodiscard]] uint32_t command(const AxisCommand& c) noexcept;
    // RT: refuses `c` with `id` without running it (a check above the axis, e.g. its kinematics
    // group, said no): it finishes at once, the warning or error is raised and move_failed set.
    uint32_t refuse(const AxisCommand& c, uint32_t id) noexcept;
    // RT: ends the running motion short with the emergency deceleration and the warning `id`
    // (move_failed), e.g. when a real axis of its kinematics group reached a limit.
    void abort_motion(uint32_t id, Interlock why) noexcept;
    // RT: while on, a PLC-fed setpoint (traj.source 1) is held where it is: the real axes of a
    // kinematics group stop together, at once, when one of them reaches a limit (the geometry
    // holds: a slit's centre does not shift). Released when the group is at rest.
    void hold_external(bool on) noexcept { ext_hold_ = on; }
    // RT: follows `path` (plus `offset`) from its time 0, one cycle at a time, from where the
    // setpoint is (the caller moved the axis to path->start_position() + offset first). Refused
    // (the id returned, nothing latched) unless enabled, idle, without error, on its own
    // trajectory. The path must stay valid until in_pvt() is false. Limits, lag, errors, Halt and
    // Stop end it with a ramp from where it is and move_failed set; disabling ends it at once.
    [[nodiscard]] uint32_t start_pvt(const PvtPath* path, double offset) noexcept;
    bool in_pvt() const noexcept { return seq_ == Seq::Pvt; }
    // RT: the trajectory's velocity, acceleration, deceleration, jerk for the next moves (ECMC
    // mc_set_traj_*); a value <= 0 or not finite leaves that one as it is.
    void set_trajectory_limits(double v, double a, double d, double j) noexcept;

    // RT, ECMC axis-group operations (mc_grp_*):
    // The trajectory (0 internal, 1 PLC) or encoder (0 encoder, 1 PLC) source; refused with
    // kNotAllowedWhenEnabled while enabled unless features.allowSrcChangeWhenEnabled.
    uint32_t set_traj_source(int source) noexcept;
    uint32_t set_enc_source(int source) noexcept;
    void set_allow_source_change(bool on) noexcept { p_.allow_source_change = on; }
    // The control (primary) encoder, by index from 0 (ECMC mc_set_prim_enc, from 1 there):
    // refused while busy; the setpoint takes the new encoder's position.
    uint32_t select_primary_encoder(int index) noexcept;
    // Encoder `index` (from 0) is referenced (homed, or absolute); false if there is none.
    bool encoder_homed(int index) const noexcept;
    // Marks encoder `index` (from 0) referenced or not (ECMC mc_set_enc_homed); false if none.
    bool set_encoder_homed(int index, bool homed) noexcept;
    // features.allowedFunctions at run time (ECMC mc_set_enable_motion_funcs).
    void set_allowed_functions(bool positioning, bool constant_velocity, bool homing) noexcept {
        p_.allow_positioning = positioning;
        p_.allow_constant_velocity = constant_velocity;
        p_.allow_homing = homing;
    }
    // An error raised from outside (mc_grp_set_error, a slaved axis in error): the motion stops
    // and the axis is disabled, as for its own errors.
    void raise_error(uint32_t id) noexcept { fault(id, true); }
    // autoEnable/autoDisable switched on or off at run time (the configured times are kept).
    void set_auto_enable(bool on) noexcept { auto_enable_on_ = on; }
    void set_auto_disable(bool on) noexcept {
        auto_disable_on_ = on;
        idle_time_ = 0;
    }
    // ECMC ctrlWithinDeadband: the controller's error within its deadband (internal trajectory),
    // or what PLC code says (mc_grp_set_ctrl_within_db) while the setpoint comes from the PLC.
    bool within_controller_deadband() const noexcept { return traj_source_ ? ext_within_deadband_ : ctrl_.in_deadband(); }
    void set_within_deadband_external(bool on) noexcept { ext_within_deadband_ = on; }
    // Requests to the axis's motor record (ECMC mc_mr_set_sync/stop): counted in the status.
    void request_mr_sync() noexcept { ++st_.mr_sync_requests; }
    void request_mr_stop() noexcept { ++st_.mr_stop_requests; }

    const AxisStatus& status() const noexcept { return st_; }
    // ECMC's ax<n>.* variables: PLC code reads and writes them between the axis's cycles.
    AxisVariables& variables() noexcept { return vars_; }
    const AxisParams& params() const noexcept { return p_; }
    Encoder& encoder() noexcept { return enc_; }
    Trajectory& trajectory() noexcept { return traj_; }

private:
    enum class Seq : uint8_t { Idle, Moving, Stopping, Homing, Pvt };
    void read_inputs() noexcept;
    void take_variables() noexcept;    // PLC writes -> commands, sources, interlocks
    void publish_variables() noexcept; // status -> ax<n>.* variables
    void monitor(double dt) noexcept;
    void rereference_others() noexcept; // homing: encoders with refAtHome follow
    void fault(uint32_t id, bool disable) noexcept;
    void finish(uint64_t tag) noexcept;
    void start_stop(double decel) noexcept;
    void interlock_stop() noexcept;
    double hold_at_limits(double x) noexcept;
    uint32_t check_target(double target) const noexcept;
    double decel() const noexcept;
    double emergency_decel() const noexcept;

    AxisParams p_;
    AxisIo io_;
    Encoder enc_;
    std::vector<Encoder> others_; // the non-primary encoders (PV readout)
    Drive drive_;
    Controller ctrl_;
    Trajectory traj_;
    AxisStatus st_;
    AxisVariables vars_, seen_; // seen_: the values as the axis last published or took them
    int traj_source_ = 0, enc_source_ = 0;
    double last_ext_set_ = NAN, last_ext_act_ = NAN;
    static constexpr int kExtSettleCycles = 20; // a PLC setpoint unchanged this long: at rest
    int ext_still_cycles_ = kExtSettleCycles;
    bool ext_hold_ = false;
    bool plc_ilock_fwd_ = false, plc_ilock_bwd_ = false; // motion blocked by PLC interlocks

    Seq seq_ = Seq::Idle;
    const PvtPath* pvt_ = nullptr; // Seq::Pvt: the path, its time [s], segment cursor, offset
    double pvt_t_ = 0, pvt_offset_ = 0;
    std::size_t pvt_seg_ = 0;
    uint64_t tag_ = 0;       // of the running command
    bool enable_req_ = false;
    bool was_enabled_ = false;
    int lag_cycles_ = 0, target_cycles_ = 0, overspeed_cycles_ = 0, overspeed_drive_cycles_ = 0;
    double move_time_ = 0;     // duration of the current/last busy period [s]
    double stall_wait_ = -1;   // after a move: time left to reach the target [s] (< 0: not armed)
    bool bus_was_ok_ = true;
    int ok_cycles_ = 0; // cycles in a row with the bus OK (position_valid after 2)
    // A motion command that arrived while the drive was being enabled runs once it is (ECMC's
    // auto-enable path: the axis reports busy meanwhile).
    int brake_cycles_ = 0, close_ahead_left_ = 0;
    AxisCommand pending_{};
    bool has_pending_ = false;
    bool auto_enabling_ = false; // pending_ waits for an auto-enable (times out)
    double auto_enable_time_ = 0, idle_time_ = 0; // [s] enabling, idle while enabled
    bool auto_enable_on_ = true, auto_disable_on_ = true; // run-time switches (mc_*_autoenable_enable)
    bool ext_within_deadband_ = false;
    double csp_correction_ = 0; // CSP_PC: the PID's position correction [units]
    double csp_drive_frame_offset() const noexcept; // the drive encoder's frame offset
    // homing (motion/homing.hpp): the running sequence, and the inputs of the last cycle
    friend class Homing;
    Homing homing_{*this};
    bool last_home_ = false, last_lim_fwd_ = false, last_lim_bwd_ = false;
    std::array<int, AxisStatus::kMaxEncoders> other_index_{}; // encoder index of others_[i]
};

} // namespace beamctl::motion
