// ECMC axis YAML files as typed structs: the axis files of ecmccfg's loadYamlAxis.cmd and the
// encoder-only files of loadYamlEnc.cmd, so that an existing ecmccfg file loads as it is. Key
// names, types and defaults are those of ecmccfg's schema (scripts/jinja2/ecmcYamlSchema.py) and
// of the templates that render it; fields say where a default comes from when it is not plain.
//
// Macros ($(DRV_SLAVE), ${AX_ID=1}) are expanded in every value after the YAML is read, as ECMC
// expands them in the rendered script: comments are never expanded and a macro cannot change the
// structure of the file. `{{ var.NAME }}` in a value takes NAME from the file's `var:` section.
//
// The files are read with config::YamlReader. Every problem is an error "file:line:col: <key
// path> ...": YAML syntax, unknown keys (with the closest allowed key), duplicate keys, missing required keys, bad values ("trajectory.axis.velocity
// should be > 0, got -1"), malformed signal links, undefined macros. Units: positions in the
// axis unit [EGU]; times in control cycles where ECMC counts cycles (fields named `_cycles`) and
// in seconds where it uses seconds (`_s`).
//
// Pure functions without global state; call them from any non-RT thread (configuration time).
#pragma once

#include "core/error.hpp"
#include "core/macros.hpp"

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::motion {

// A link to a process-image entry, `ec<master>.s<slave>.<entry>[.<bit>]` as in
// `ec0.s3.driveStatus01.3`, checked for syntax only: the signal registry resolves the name later
// and reports a missing one at `where`. `ec0.s<k>.ONE` and `ZERO` are ECMC's constant entries
// (all bits 1 / all bits 0); slave -1 is ECMC's simulation slave.
struct SignalRef {
    std::string text;  // as written, macros expanded
    int bus = 0;       // master index (ec<m>)
    int slave = 0;     // bus position, -1 = simulation slave
    std::string entry; // entry name (alias): positionActual01, ONE, ZERO, ...
    int bit = -1;      // 0..63; -1 = the whole entry
    SourceLoc where;   // of the value in its file

    bool is_constant() const { return entry == "ONE" || entry == "ZERO"; }
    // The same entry with `.bit` (replacing any bit): drive.status + drive.warning bit.
    SignalRef with_bit(int bit) const;
};

// Parses a link; throws Error "where: 'text' is not a signal link (...)".
SignalRef parse_signal_ref(std::string_view text, const SourceLoc& where);

// A limit or home switch input: an entry, or `plcOverride` (the axis PLC writes ax<n>.mon.*).
struct SwitchInput {
    bool plc_override = false;
    SignalRef signal; // when !plc_override
};

enum class AxisType {
    Joint = 1,
    Virtual = 2
}; // ecmccfg: joint|physical|motor|real|j|1,
   // virtual|end_effector|end effector|ee|e|2
enum class DriveMode { CSV, CSP, CSP_PC };
enum class DriveType { Stepper = 0, DS402 = 1 };
enum class EncoderType { Incremental = 0, Absolute = 1 };
enum class EncoderSource { EtherCAT = 0, PLC = 1 };    // PLC: ax<n>.enc.extactpos
enum class TrajectorySource { Internal = 0, PLC = 1 }; // PLC: ax<n>.traj.extsetpos
enum class TrajectoryType { Trapezoid = 0, SCurve = 1 };
enum class ModuloType { Normal = 0, Forward = 1, Backward = 2, Closest = 3 }; // as modulo_target()

constexpr int kMaxAxisId = 127;          // ECMC: 128 axes
constexpr std::size_t kMaxEncoders = 8;  // ECMC: 8 encoders per axis
constexpr std::size_t kMaxErrorBits = 3; // drive.error / encoder.error entries

// `axis:`
struct AxisSection {
    std::optional<int> id; // 0..kMaxAxisId; absent: the previous axis + 1 (ecmccfg numbering)
    AxisType type = AxisType::Joint;
    DriveMode mode = DriveMode::CSV;
    std::string parameters;                 // motor record driver options "powerAutoOnOff=2;"
    std::optional<SignalRef> health_output; // healthOutput: set while the axis is healthy
    std::optional<SignalRef> feed_switches_output; // feedSwitchesOutput: written once at startup
    int64_t feed_switches_value = 1;               // feedSwitchesValue (template default 1)
    std::string group;                             // axis group name ("" = none)
    double tweak_dist = 1.0;                       // tweakDist [EGU]
    struct AutoEnable {
        double enable_timeout_s = -1;  // enableTimeout: try to enable for this long [s]; -1 off
        double disable_timeout_s = -1; // disableTimeout: disable after idle this long [s]; -1 off
        bool at_startup = false;       // atStartup
    };
    std::optional<AutoEnable> auto_enable; // autoEnable (present: motor record auto power off)
    struct AutoMode {                      // switch drive mode for motion / homing (smaract, ...)
        std::optional<SignalRef> mode_set; // modeSet
        std::optional<SignalRef> mode_act; // modeAct
        std::optional<int64_t> mode_cmd_motion; // modeCmdMotion
        std::optional<int64_t> mode_cmd_home;   // modeCmdHome
    };
    std::optional<AutoMode> auto_mode; // autoMode
    struct Features {                  // features (template defaults)
        bool disable_on_reset = false;
        bool alarm_at_hard_limits = false;
        bool block_com = false;
        bool allow_src_change_when_enabled = false;
        bool allow_positioning = true;       // allowedFunctions.positioning
        bool allow_constant_velocity = true; // allowedFunctions.constantVelocity
        bool allow_homing = true;            // allowedFunctions.homing
    } features;
};

// `epics:`
struct EpicsConfig {
    std::string name = "axis"; // axis name in PV names ($(IOC):<name>)
    int precision = 3;         // PREC
    std::string unit = "mm";   // EGU
    std::string description;   // epics.description (in the ecmccfg manual; ecmccfg ignores it)
    struct MotorRecord {
        bool enable = true;
        std::string description;       // DESC
        std::string field_init;        // fieldInit: extra field values "RTRY=0,FOFF=Frozen"
        bool sync_soft_limits = false; // syncSoftLimits
        struct Pvt {
            int64_t npoints = 0;
            int64_t nreadback = 0;
        };
        std::optional<Pvt> pvt; // profile move
    } motor_record;
};

// `drive:` (joint axes only).
struct DriveConfig {
    double numerator = 0;    // [EGU/s] at raw velocity setpoint = denominator (CSV), [EGU] (CSP)
    int64_t denominator = 1; // raw setpoint counts (>= 1)
    DriveType type = DriveType::Stepper;
    SignalRef setpoint;  // velocity (CSV) or position (CSP, CSP_PC) setpoint
    SignalRef control;   // control word
    SignalRef status;    // status word (the schema has it optional; every template needs it)
    int enable_bit = 0;  // enable: stepper enable bit in control (Beckhoff default 0)
    int enabled_bit = 1; // enabled: stepper enabled bit in status (Beckhoff default 1)
    std::optional<int> reset_bit;         // reset: bit in control
    std::optional<int> warning_bit;       // warning: bit in status
    std::optional<int> reduce_torque_bit; // reduceTorque: bit in control
    bool reduce_torque_enable = false;    // reduceTorqueEnable
    std::vector<SignalRef> errors;        // error[]: up to 3; bit numbers as status.<bit>
    struct Brake {
        bool enable = false;
        SignalRef output;
        int64_t open_delay_cycles = 0;  // openDelay: wait after enable before opening [cycles]
        int64_t close_ahead_cycles = 0; // closeAhead: close this early before disable [cycles]
    };
    std::optional<Brake> brake;
};

// `encoder.homing:` (or the legacy top-level `homing:`). Sequence numbers as ecmc.md §5.
struct HomingConfig {
    int type = 0;                        // sequence: 0..12, 14, 15, 21, 22, 25, 26
    std::optional<double> position;      // [EGU] position of the reference
    bool post_move_enable = false;       // postMoveEnable
    double post_move_position = 0;       // postMovePosition [EGU]
    std::optional<int64_t> latch_count;  // latchCount: reference on this latch (>= 0)
    std::optional<double> velocity_to;   // velocity.to: towards the cam [EGU/s]
    std::optional<double> velocity_from; // velocity.from: off the cam [EGU/s]; absent: velocity.to
    std::optional<double> acceleration;  // [EGU/s^2]
    std::optional<double> deceleration;  // [EGU/s^2]
    std::optional<int64_t> timeout_s;    // timeout: abort the sequence after [s]
    int64_t ref_to_enc_id_at_startup = -1; // refToEncIDAtStartup: copy this encoder's position
    int64_t ref_at_home = 0;               // refAtHome: set this encoder when homed (schema 0)
    double tol_to_prim = 0;                // tolToPrim: max difference to the primary [EGU]
    std::optional<SignalRef> trigg;        // seq 26: start drive-internal homing
    std::optional<SignalRef> ready;        // seq 26: drive-internal homing done
};

struct FilterConfig {
    bool enable = false;
    int64_t size = 1; // samples (cycles)
};

// `encoder:` of an axis file, or an encoder-only file.
struct EncoderConfig {
    EncoderSource source = EncoderSource::EtherCAT;
    double numerator = 0;    // [EGU] per `denominator` counts
    int64_t denominator = 1; // counts (>= 1)
    EncoderType type = EncoderType::Incremental;
    std::string mask;      // raw mask as written ("0xFFF00"); the templates do not use it
    int bits = 16;         // raw data bits (0..64)
    int abs_bits = 25;     // absBits: absolute (least significant) bits of an absolute encoder
    double abs_offset = 0; // absOffset [EGU]
    struct LookupTable {
        std::string filename;        // LUT file as written (resolve against the IOC directory)
        std::optional<double> range; // [EGU] modulo of the table
        std::optional<double> scale;
        bool enable = true;
    };
    std::optional<LookupTable> lookuptable;
    std::string unit; // "" = epics.unit
    std::string desc;
    struct DelayComp {
        double time_cycles = 0; // setpoint -> encoder delay [cycles] (fractional)
        bool enable = true;
    };
    std::optional<DelayComp> delay_comp;         // delayComp
    std::optional<bool> allow_over_under_flow;   // allowOverUnderFlow (ECMC default true)
    std::optional<SignalRef> position;           // required when source is EtherCAT
    std::optional<SignalRef> control;            // control word
    std::optional<SignalRef> status;             // status word
    std::optional<int> warning_bit, ready_bit;   // bits in status
    std::optional<int> reset_bit;                // bit in control
    std::vector<SignalRef> errors;               // error[]: up to 3; bit numbers as status.<bit>
    std::optional<FilterConfig> velocity_filter; // filter.velocity (present: enable 1, size 100)
    std::optional<FilterConfig> position_filter; // filter.position / .trajectory (1, 10)
    struct Latch {
        SignalRef position;   // latched position entry
        int control_bit = 0;  // bit in encoder.control that arms the latch
        int status_bit = 0;   // bit in encoder.status: latch triggered
        int64_t arm_cmd = 1;  // armCmd: value written to arm
        int64_t arm_bits = 1; // armBits: width of armCmd
    };
    std::optional<Latch> latch;
    bool primary = false;                  // use for control (last primary wins)
    bool use_as_csp_drive_encoder = false; // useAsCSPDrvEnc: CSP_PC position loop
    std::optional<HomingConfig> homing;
    SourceLoc where;                   // of the encoder mapping
    std::vector<std::string> warnings; // encoder-only file: "file:line:col: ..." (see AxisConfig)
};

// `controller:` (joint axes; used in CSV and CSP_PC).
struct ControllerConfig {
    double kp = 1, ki = 0, kd = 0, kff = 1; // Kp, Ki, Kd, Kff (>= 0)
    struct Inner {                          // gains near the target
        double kp = 1, ki = 0, kd = 0;
        double tol = 0; // [EGU] within this distance of the target
    };
    std::optional<Inner> inner;
    struct Limits { // each pair is active only when max > min (0, 0 = off)
        double min_output = 0, max_output = 0;
        double min_integral = 0, max_integral = 0;
    } limits;
    struct Deadband {
        double tol = 0;          // [EGU]
        int64_t time_cycles = 0; // [cycles]
    };
    std::optional<Deadband> deadband;
};

// `trajectory:`. Defaults that the ecmccfg templates derive are filled in.
struct TrajectoryConfig {
    TrajectorySource source = TrajectorySource::Internal;
    TrajectoryType type = TrajectoryType::Trapezoid;
    struct Axis {
        double velocity = 0;               // [EGU/s] (required, > 0)
        double acceleration = 0;           // [EGU/s^2] (required, > 0)
        double deceleration = 0;           // [EGU/s^2]; default acceleration
        double emergency_deceleration = 0; // [EGU/s^2]; default 10 x max(acceleration,
                                           // deceleration) as the template renders it
        double jerk = 0;                   // [EGU/s^3]; default acceleration (template)
    } axis;
    struct Jog {
        double velocity = 0;     // [EGU/s]; default axis.velocity
        double acceleration = 0; // [EGU/s^2]; default axis.acceleration
    } jog;
    struct Modulo {
        double range = 0; // [EGU]; 0 = off
        ModuloType type = ModuloType::Normal;
    };
    std::optional<Modulo> modulo;
};

// `input:`. Polarity 0: the input is 1 when all is well (normally closed), 1: inverted.
struct InputConfig {
    SwitchInput limit_forward;  // limit.forward -> ax<n>.mon.highlim
    SwitchInput limit_backward; // limit.backward -> ax<n>.mon.lowlim
    int limit_forward_polarity = 0;
    int limit_backward_polarity = 0;
    std::optional<bool> latch_limits; // limit.latchInput
    std::optional<SwitchInput> home;  // -> ax<n>.mon.homesensor
    int home_polarity = 0;
    std::optional<SignalRef> interlock; // -> ax<n>.mon.extinterlock
    int interlock_polarity = 0;
    struct Analog {
        SignalRef interlock;             // analog input (raw)
        std::optional<double> raw_limit; // rawLimit
        int interlock_polarity = 0;      // 0: high value is bad, 1: low value is bad
        bool enable = true;
    };
    std::optional<Analog> analog; // analog.interlock given
};

// `softlimits:`. A limit acts when enable and its own enable are both true.
struct SoftLimitsConfig {
    bool enable = false;
    double forward = 0; // [EGU]
    bool forward_enable = false;
    double backward = 0; // [EGU]
    bool backward_enable = false;
};

// `monitoring:`
struct MonitoringConfig {
    struct Window {
        bool enable = false;
        double tolerance = 0;    // [EGU]
        int64_t time_cycles = 0; // lag: error after [cycles]; target: at target after [cycles]
    };
    Window lag{false, 0, 100}; // schema default when absent
    Window target;             // needed for the motor record's DMOV
    struct Velocity {
        bool enable = false;
        double max = 0;                      // [EGU/s]
        int64_t trajectory_cycles = 0;       // time.trajectory: stop after [cycles]
        std::optional<int64_t> drive_cycles; // time.drive: then disable after [cycles]
    };
    Velocity velocity;
    Velocity velocity_difference; // velocityDifference: setpoint vs actual velocity
    struct Stall {
        bool enable = false;
        std::optional<int64_t> timeout_cycles; // time.timeout [cycles]
        std::optional<double> factor;          // time.factor x last move duration
    };
    std::optional<Stall> stall; // present when stall.enable is given
};

// `plc:` of an axis file (the axis PLC).
struct AxisPlcConfig {
    bool enable = false;                  // required
    bool external_commands = false;       // externalCommands: accept commands from PLCs
    std::string file;                     // PLC file as written (resolve against the IOC directory)
    std::string macros;                   // PLC macros "A=1,B=2" as written
    std::vector<std::string> code;        // lines appended after the file's code
    FilterConfig encoder_velocity_filter; // velocity_filter.encoder (legacy filter.velocity)
    FilterConfig trajectory_velocity_filter; // velocity_filter.trajectory (legacy
                                             // filter.position, filter.trajectory)
};

struct AxisConfig {
    std::string file; // the axis file
    AxisSection axis;
    EpicsConfig epics;
    std::optional<DriveConfig> drive;    // joint axes
    std::vector<EncoderConfig> encoders; // [0] from the axis file; more via add_encoder()
    ControllerConfig controller;         // joint axes
    TrajectoryConfig trajectory;
    InputConfig input;
    SoftLimitsConfig softlimits;
    MonitoringConfig monitoring;
    std::optional<AxisPlcConfig> plc;
    std::map<std::string, std::string> meta; // meta: (author, date, ...) as written
    // Things that load but deserve a look, "file:line:col: ...": keys that ecmccfg ignores
    // (listed in its manual), legacy forms, a missing monitoring section.
    std::vector<std::string> warnings;

    bool is_virtual() const { return axis.type == AxisType::Virtual; }
    // Index in `encoders` of the encoder used for control: the last one marked primary, else 0.
    std::size_t primary_encoder() const;
};

// Reads an axis file (loadYamlAxis.cmd). Every problem of the file is found in one pass and
// thrown as one MultiError (ordered by position; the first line is the first problem).
AxisConfig load_axis_config(const std::string& path, const MacroMap& macros);
AxisConfig parse_axis_config(std::string_view text, const std::string& filename,
                             const MacroMap& macros);
// Same, but every problem is appended to `errors` (ordered by position) instead of thrown, for
// `beamctl check`; the result holds what could be read (defaults elsewhere).
AxisConfig load_axis_config(const std::string& path, const MacroMap& macros,
                            std::vector<Error>& errors);
AxisConfig parse_axis_config(std::string_view text, const std::string& filename,
                             const MacroMap& macros, std::vector<Error>& errors);

// Reads an encoder-only file (loadYamlEnc.cmd: `encoder:` and optional `meta:`, `var:`).
EncoderConfig load_encoder_config(const std::string& path, const MacroMap& macros);
EncoderConfig parse_encoder_config(std::string_view text, const std::string& filename,
                                   const MacroMap& macros);
EncoderConfig load_encoder_config(const std::string& path, const MacroMap& macros,
                                  std::vector<Error>& errors);
EncoderConfig parse_encoder_config(std::string_view text, const std::string& filename,
                                   const MacroMap& macros, std::vector<Error>& errors);

// Appends an encoder from an encoder file to the axis (as loadYamlEnc.cmd after the axis) and
// moves its warnings to the axis. Throws Error (at the encoder) beyond kMaxEncoders. Note that
// loadYamlEnc.cmd does not apply an encoder file's `source` (the axis file's encoder sets it).
void add_encoder(AxisConfig& axis, EncoderConfig encoder);

} // namespace beamctl::motion
