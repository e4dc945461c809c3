// The IOC configuration file (`beamctl run ioc.yaml`, ARCHITECTURE.md §4) as typed structs, read
// with config::YamlReader: every error of the file at once, each with file:line:col and the key;
// unknown keys are errors (with a close-match hint); files it references are resolved relative
// to it, and their place in the IOC file is kept (`*_where`) for errors about them.
#pragma once

#include "core/error_list.hpp"
#include "core/macros.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace beamctl::config {

struct SdoConfig {
    uint16_t index = 0;
    uint8_t sub = 0;
    uint64_t value = 0;
    uint8_t size = 4; // bytes: 1, 2, 4 or 8
};

struct SlaveEntry {
    int position = 0;
    std::string type;
    std::string name;       // a scanner's chain: the slave's unique name (seed 002, "OUT0"); "" if none
    uint32_t revision = 0;  // the expected revision (0: the catalog's newest)
    std::vector<SdoConfig> sdo;
    std::string type_where; // file:line:col of the type in the IOC file
    unsigned oversampling = 1;     // samples per cycle (EL3702, EL4732; ecmccfg NELM)
    std::string oversampling_where;
};

struct LinkConfig {
    std::string type = "sim"; // sim | udp | raw | scanner
    std::string plant;        // sim: simulator file (wiring, plants), resolved path; may be empty
    std::string host = "127.0.0.1";
    uint16_t port = 0x88A4;   // udp
    std::string iface;        // raw: network interface of the segment
    bool busy_poll = false;   // raw: spin in receive instead of sleeping (no wake-up latency)
    std::vector<std::string> faults; // sim: fault commands applied before bring-up ("power 3 off")
    std::vector<std::string> faults_where;
    std::string plant_where;  // file:line:col of `plant` in the IOC file
    // scanner: the bus is run by `beamctl scanner`; this IOC attaches to it (docs/scanner.md).
    std::string socket;               // the scanner's socket
    std::vector<std::string> attach;  // link.slaves: the slaves to attach, names or positions
    std::string attach_where;
    // claims: the outputs this IOC writes: all of its slaves' (default), none (it only looks), or
    // a list of "SLAVE:entry" / "SLAVE:*" (SLAVE a name or position).
    bool claim_all = true;
    std::vector<std::pair<std::string, std::string>> claims;
    double tick_timeout_s = 0.1;     // no tick for this long: the cycle runs on its own, without bus data
    double resolve_timeout_s = 30;   // link.slaves: how long the IOC waits at start for the scanner to name them
    std::string where;                // file:line:col of the link
};

struct BusConfig {
    int id = 0;
    bool strict = false; // refuse to start with a slave missing, wrong or failing
    // Its own cycle (own RT thread) at this rate [Hz]; unset: the IOC's cycle (engine.rate_hz).
    std::optional<double> rate_hz;
    std::string rate_where; // file:line:col of rate_hz
    // The position of an EL6692 side on this bus whose other side's DC time base this bus's
    // distributed clock follows (its 0x1A02 time stamps steer the reference clock).
    std::optional<int> dc_follow;
    std::string dc_follow_where;
    LinkConfig link;
    std::vector<SlaveEntry> slaves;
};

// Reads a `buses:` list (the IOC file's, or a scanner's chain with `scanner_file`: slave names
// required and unique, no scanner links). Errors go to the node's reader.
class YamlNode;
std::vector<BusConfig> read_bus_list(const YamlNode& buses, const std::string& dir, bool scanner_file);

struct DbConfig {
    std::string file; // resolved path
    MacroMap macros;
    std::string file_where; // file:line:col of the file name in the IOC file
};

// An ECMC axis file with its macros (ecmccfg loadYamlAxis.cmd), and extra encoder files
// (loadYamlEnc.cmd).
struct AxisEntry {
    std::string file; // resolved path
    MacroMap macros;
    struct Encoder {
        std::string file;
        MacroMap macros;
        std::string file_where;
    };
    std::vector<Encoder> encoders;
    std::string where;      // file:line:col of the entry in the IOC file
    std::string file_where; // file:line:col of the file name in the IOC file
};

// "ioc.yaml:12:5: axes[1] (jack.yaml with AX_ID=2, AX_NAME=J2, DRV_SLAVE=5)": what an error in an
// axis's files is prefixed with, so that it names the entry and the macros that led to it.
std::string axis_entry_context(const AxisEntry& e, std::size_t index);

// A PLC file (ecmccfg loadPLCFile.cmd): `plcs: [{id, file, rate_ms, enable, macros, include,
// libraries, strict}]`.
struct PlcEntry {
    int id = 0;              // plc<id>, PV PLC<id as 2 digits>-...
    std::string file;        // resolved path
    double rate_ms = -1;     // scan period [ms]; -1 = every cycle
    bool enable = true;
    bool strict = false;     // refuse what ECMC's ExprTk would refuse (plc::CompileOptions::strict)
    std::optional<int> bus;  // runs in the cycle of this bus (one with its own rate_hz); unset: the IOC's
    std::string bus_where;
    MacroMap macros;
    std::vector<std::string> include;   // resolved directories searched by `include`
    std::vector<std::string> libraries; // resolved files of `function` definitions
    std::string where;       // file:line:col of the entry
    std::string file_where;  // file:line:col of the file name
};

// A kinematics group (docs/motion.md, motion/kinematics.hpp): virtual axes whose moves drive real
// axes; its inverse transform, in the PLC language, is what the engine checks virtual moves with.
// `kinematics: [{name, virtual: [ids], real: [ids], inverse: CODE | file: F, macros, include}]`.
// In the code, `ax<n>` is the position of axis n: read it for a virtual axis, assign it for a real.
struct KinematicsEntry {
    std::string name;
    std::vector<int> virt, real;        // axis ids
    std::string code;                   // inline inverse (at code_at; code_block: a `|` block), or
    SourceLoc code_at;
    bool code_block = false;
    std::string file;                   // resolved path of a file with it
    MacroMap macros;
    std::vector<std::string> include;   // resolved directories searched by `include`
    std::string where;                  // file:line:col of the entry
    std::string file_where;             // file:line:col of `file`, if given
};

// A plugin (include/beamctl/plugin.h): `plugins: [{file, config}]`.
struct PluginEntry {
    std::string file; // resolved path
    std::string config;
    std::string where;
    std::string file_where;
};

// The UDP bridge to rapid-control-prototyping machines (`bridges: rcp:`; docs/rcp.md).
struct RcpBridgeEntry {
    std::string listen;             // IPv4 address the sockets bind to; "": chosen (BridgeConfig)
    uint16_t port = 18065;          // beacon port (data is accepted on it too)
    std::string prefix;             // PV prefix; default: the IOC prefix + "RCP:"
    double timeout_s = 3;           // [s] silence before an application's PVs go INVALID/COMM
    std::string db_out;             // resolved path of the generated .db file; empty: none
    std::string pv_pattern;         // object PV names; empty: "<prefix><application>:<name>"
    // Fields of every generated motor record, added to (or replacing) the bridge's defaults,
    // e.g. {DHLM: 45, DLLM: -45}: the protocol does not carry limits.
    std::vector<std::pair<std::string, std::string>> motor_fields;
    // Who may talk to the bridge and how much (docs/rcp.md, "Who may talk to the bridge").
    std::vector<std::pair<std::string, std::string>> machines; // {application name, address or network}
    std::vector<std::string> allow;                            // networks
    std::size_t max_applications = 32, max_applications_per_address = 8, max_objects = 255, max_model_changes_per_minute = 30;
    std::string where;
};

// A data storage (ECMC's ecmccfg addDataStorage.cmd; docs/plc.md): `storages: [{id, size, type,
// capacity, sample_rate_ms, desc}]`. PLC code fills it (ds<id>.*, ds_*); PVs DSnn-*.
struct StorageEntry {
    int id = 0;                 // ds<id>, 0..31
    std::size_t size = 1000;    // values (ECMC DS_SIZE)
    int type = 0;               // 0 normal, 1 ring, 2 fifo (ECMC DS_TYPE)
    std::size_t capacity = 0;   // the most ds<id>.size may grow to (0: size)
    double sample_rate_ms = 100; // [ms] a changed buffer reaches its PVs at most this often
    std::string desc;           // DSnn-Desc (default "ds<id>")
    std::string where;          // file:line:col of the entry
};

// A lookup table for PLC code (ecmccfg loadLUTFile.cmd): `luts: [{id, file}]`; lut_get_value(id, x).
struct LutEntry {
    int id = 0;             // 0..15
    std::string file;       // resolved path
    std::string where, file_where;
};

// ECMC's m2m shared memory (plc/m2m.hpp): `m2m: {name, master}`. Opened when given, or when a
// PLC calls an m2m_* function (then with the defaults).
struct M2mEntry {
    std::string name = "beamctl_m2m"; // /dev/shm/<name>: IOCs with the same name share values
    std::optional<int> master;        // this IOC's index (-15..15); default: its first bus id, -1 without buses
    std::string where;
};

// Autosave of the records' info(autosaveFields[_pass0], "...") fields (docs/autosave.md):
// `autosave: {dir: DIR, period_s: 5}`.
struct AutosaveEntry {
    std::string dir;     // resolved path of the .sav files
    double period_s = 5; // [s] at most one save of a changed file per period
    std::string where;   // file:line:col of the entry
};

// PVT profile moves (docs/motion.md): `pvt: {trigger: ec0.s2.binaryOutput01, trigger_duration_s: 0.1}`,
// ecmccfg's pvtControllerConfig.cmd TRG_EC_ENTRY and TRG_DUR_S.
struct PvtEntry {
    std::string trigger;             // an output bit pulsed at each profile trigger ("": none)
    double trigger_duration_s = 0.1; // [s] high time of a pulse
    std::string where;
};

// A position-compare block (docs/flyscan.md; PandA's PCOMP): `pcomp: [{id, input, start, step,
// width, pulses, pre_start, relative, dir, enable, output, egu, desc}]`; PVs $(P)PCOMP<id>:*.
struct PcompEntry {
    int id = 1;                 // pcomp<id>, 1..32
    std::string input;          // INP: an engine signal ("ax1.enc.actpos", "ec0.s3.positionActual01") or
                                // "time": the engine clock [s] (a time-based pulse train)
    std::string output;         // an output bit driven with OUT in the same cycle ("": none), an
                                // EL2252 channel (timestamped) or an analog output (EL4732 samples)
    int64_t analog_high = 16384, analog_low = 0; // an analog output's raw values for OUT 1 / 0 (5 V / 0 V on +-10 V)
    double start = 0, step = 0, width = 0, pre_start = 0;
    uint32_t pulses = 0;        // 0: unlimited
    bool relative = false;
    int dir = 0;                // 0 positive, 1 negative, 2 either
    bool enable = false;        // ENABLE at start
    std::string egu;            // units of INP (default: "s" for time, else none)
    std::string desc;
    std::string where, input_where, output_where;
};

// A captured value (docs/flyscan.md; PandA's PCAP fields): `{signal, name, units, modes}`.
struct CaptureField {
    std::string signal;            // an engine signal, "time" or "pcomp<n>.out"
    std::string name;              // column name (default: the signal with '.' -> '_')
    std::string units;
    std::vector<std::string> modes = {"value"}; // value, diff, sum, min, max
    std::string where;
};

// The capture (PandA's PCAP): `capture: {trigger, gate, fields, ring_rows, last_rows, file_path,
// file_name, flush_s}`; PVs $(P)PCAP:*.
struct CaptureEntry {
    // What captures a row: "pcomp<n>" (its OUT rising edge), "cycle" (every cycle), or a signal
    // (rising to nonzero); a list captures a row when any of them does.
    std::vector<std::string> triggers = {"cycle"};
    std::string gate;              // a signal: accumulate while nonzero ("": always)
    std::vector<CaptureField> fields;
    // Data storages (ids of `storages:`) whose appended values the file gets, as they come: an
    // NXlog /entry/ds<id> each; ring_rows values of room between the cycle and the writer.
    std::vector<int> storages;
    std::size_t ring_rows = 1 << 16; // rows between the cycle and the writer thread
    std::size_t last_rows = 1000;    // rows served as live waveforms
    std::string file_path = "/tmp";  // FILE_PATH at start
    std::string file_name = "capture_%04d.h5"; // FILE_NAME at start; %d (%0Nd): the capture number
    double flush_s = 1.0;            // [s] SWMR flush period
    std::string where, trigger_where, gate_where;
};

// A fast feedback loop (docs/feedback.md): synApps' EPID in the cycle, `feedback: [{name, input,
// output, ...}]`; its interface is the epid record $(P)<name> (DTYP "Fast Epid").
struct FeedbackEntry {
    std::string name;           // the record $(P)<name>, and INP "@<name>"
    std::string input;          // an engine value: a bus entry, an axis variable (ax1.enc.actpos)
    double input_scale = 1, input_offset = 0;   // CVAL = raw * scale + offset
    std::string output;         // a bus output entry the loop writes (its one writer)
    double output_scale = 1, output_offset = 0; // raw = (OVAL - offset) / scale, rounded, clamped to the entry
    double dt = 0;              // DT [s]: time per step (0: every cycle); averages the samples in it
    double kp = 0, ki = 0, kd = 0, val = 0;
    double drvh = 0, drvl = 0;  // output limits [output units]
    bool fbon = false;          // FBON at start
    std::string scan = ".1 second"; // how often the record exchanges with the loop
    double hopr = 0, lopr = 0;
    int prec = 3;
    std::string egu, desc;
    std::string where, input_where, output_where;
};

// A simulated energy-dispersive detector behind synApps' mca record (docs/detectors.md):
// `detectors: {mca: [{name, channels, offset, slope, lines, background, dead_time, elements,
// noise_fwhm, preamp_gains, dxp: {...}}]}`.
struct McaEntry {
    struct Line {
        std::string name;
        double energy = 0, rate = 0, fwhm = 0.15; // keV, counts/s, keV
    };
    // The pulse processor's settings at start (dxp's PVs; 0: the default of SimMca)
    struct Dxp {
        double peaking_time = 2.0, gap_time = 0.15;   // us
        double trigger_threshold = 0, energy_threshold = 0; // keV
        double preamp_gain = 2.0;                     // mV/keV
        double max_energy = 0, adc_percent_rule = 0;  // keV, %
        double calibration_energy = 5.9;              // keV
    };
    std::string name;            // the record $(P)<name> and mca.db's $(P)<name>Start, ...; with
                                 // elements > 1, the first: <stem><k> .. <stem><k + elements - 1>
    int elements = 1;            // detector elements (> 1: also $(P)<stem>Sum and dxpMED's PVs)
    uint32_t channels = 2048;
    double offset = 0, slope = 0.01; // keV = offset + slope * channel (CALO, CALS)
    std::vector<Line> lines;
    double background = 50;      // counts/s over the spectrum
    double dead_time = 2e-6;     // s per event
    int bus = -1;                // the simulated bus whose beam's transmission scales the rates
                                 // (-1: the first with a beam:, if any)
    double noise_fwhm = 0.1;     // keV: the electronic part of the FWHMs at dxp.peaking_time
    std::vector<double> preamp_gains; // mV/keV each element really has (empty: dxp.preamp_gain)
    Dxp dxp;
    std::string where;

    // The element's records: mca record name, and the DXP prefix after $(P) ("dxp<n>:" for a name
    // that ends in its number n, else "dxp_<name>:").
    std::string element_name(int i) const;
    std::string dxp_prefix(int i) const;
    std::string sum_name() const; // <stem>Sum
};

// A quad electrometer (quadEM) over four engine values (docs/detectors.md):
// `detectors: {quadem: [{name, currents: [4 values], geometry, averaging_time, current_scale,
// current_offset, position_scale, position_offset, egu, prec}]}`.
struct QuadEmEntry {
    std::string name;                   // $(P)<name>: quadEM's PVs, e.g. QE1 -> DEMO:QE1:PosY:MeanValue_RBV
    std::vector<std::string> currents;  // four engine values (bus entries, axis variables)
    std::string geometry = "Square";    // Diamond, Square, SquareCC
    double averaging_time = 0.1;        // [s] AveragingTime
    double current_scale[4] = {1, 1, 1, 1}, current_offset[4] = {0, 0, 0, 0};
    double position_scale[2] = {1e6, 1e6}, position_offset[2] = {0, 0};
    std::string egu;                    // of the positions
    int prec = 4;
    int ts_points = 1000;               // the time series' length (quadEM's TSPOINTS)
    struct Range {
        std::string name;       // the Range PV's state string ("+-120 uA")
        double full_scale = 0;  // [current units] a current beyond +-full_scale reads +-full_scale (0: no limit)
    };
    std::vector<Range> ranges;          // Range's choices (none: one, "Full", without a limit)
    int range = 0;                      // the one at start
    std::string where, currents_where;
};

// `smart_control:` (docs/goniometer.md): the goniometer controller of smartControl (seed 004) over a
// line protocol on TCP and a pseudo-terminal, so that an external control program drives up to
// four of this IOC's motors, a shutter, a detector trigger and a scaler.
struct SmartControlEntry {
    struct Axis {
        std::string name;          // the protocol's: TWOTHETA, OMEGA, PHI, KAPPA
        std::string motor;         // a motor record of this IOC (PV name)
        double offset = 0;         // motor = sign x smart + offset (then into the cut window)
        int sign = 1;              // +1 / -1
        double low_cut = 0, high_cut = 0; // [motor units] the window a rotation is wrapped into (by 360); equal: none
        std::string where;
    };
    std::string name = "smart";   // $(P)smart: (the setup table's PVs)
    std::string bind = "127.0.0.1";
    int port = 0;                 // TCP (0: none)
    std::string pty;              // a symlink to a pseudo-terminal's slave ("": none)
    std::vector<Axis> axes;       // in the protocol's order
    std::string shutter;          // PV written 1 (open) / 0 (closed)
    std::string trigger;          // PV written 1 when a frame starts, 0 when it ends
    std::string scaler;           // PV whose value is integrated over a count [value x s]
    std::string where;
};

// `compound_motors:` (docs/automation.md): motors whose position is a function of other motors
// (motor records of this IOC or, through Channel Access, of other IOCs), served as motor records.
// A group drives a set of real motors and serves one or more virtual motors: `forward` gives each
// virtual from the reals' readbacks (and the read-only `inputs`), `inverse` each driven real from
// the virtuals; both in the PLC's expression language.
struct CompoundMotorEntry {
    struct Virtual {
        std::string name;     // the motor record $(P)<name>, and the name in the expressions
        std::string forward;  // expression in reals and inputs
        std::string egu, desc;
        int prec = 3;
        double velocity = 1; // VELO (the record's; the reals move at their own speeds)
        double mres = 0;     // 0: 10^-prec
        std::string where;
    };
    struct Name {
        std::string name; // in the expressions
        std::string pv;   // a motor record (reals) or any PV (inputs)
        std::string where;
    };
    std::string name;                // the group's, for messages
    std::vector<Name> reals, inputs;
    std::vector<Virtual> virtuals;
    std::vector<std::pair<std::string, std::string>> inverse; // real name -> expression, in file order
    std::vector<std::string> inverse_where;
    std::string where;
};

// `state_machines:` (docs/automation.md): finite state machines served as PVs under
// $(P)<name>: (State, Request, Busy, Transition, Step, Allowed, Error, Latched, Ack, AckBy, AckTime).
// A transition runs its steps (the from-state's exit steps, its own, the to-state's entry steps);
// any failure, a time-out, a false guard or a state's invariant turning false moves the machine to
// its error latch, which refuses every request until Ack is written.
struct StateMachineEntry {
    struct Step {
        enum class Kind { Put, WaitFor, Delay } kind = Kind::Put;
        std::string pv;        // Put: the PV written
        double value = 0;      // Put: the value
        bool wait = true;      // Put: with a put-callback; the step ends when it completes
        std::string expr;      // WaitFor: the condition
        double seconds = 0;    // Delay: how long; Put/WaitFor: time-out (0: the transition's)
        std::string where;
    };
    struct State {
        std::string name, parent; // a sub-state names its parent
        std::string invariant;    // must hold while in the state (and its sub-states); "" none
        std::vector<Step> entry, exit;
        std::string where;
    };
    struct Transition {
        std::string name, from, to; // from: a state or a parent of states
        std::string guard;          // must hold when requested; "" none
        std::vector<Step> steps;
        double timeout = 300;       // [s] the whole transition
        std::string where;
    };
    std::string name;
    std::vector<State> states;                                // in mbbi order (at most 16)
    std::string initial, latch, after_ack;                    // after_ack: default initial
    std::vector<std::pair<std::string, std::string>> names;   // expression name -> PV
    std::vector<std::string> names_where;
    std::vector<Transition> transitions;
    std::string where;
};

// `notify:` (docs/automation.md): email (SMTP) and webhooks (HTTP POST of JSON) when a state
// machine latches or a PV of this IOC reaches an alarm severity.
struct NotifyEntry {
    struct Rule {
        std::string state_machine; // "name" or "*": when it latches
        std::string pv;            // a record of this IOC: when its SEVR reaches `severity`
        int severity = 2;          // 1 MINOR, 2 MAJOR, 3 INVALID
        std::string where;
    };
    struct Webhook {
        std::string url, host, path; // http://host[:port]/path
        int port = 80;
    };
    std::string smtp_host;         // "" no email
    int smtp_port = 25;
    std::string from = "beamctl";
    std::vector<std::string> to;
    std::vector<Webhook> webhooks;
    std::vector<Rule> rules;
    double min_interval_s = 60;    // per rule: at most one message per interval
    double dedup_s = 600;          // the same text within this is sent once
    int retries = 3;
    double retry_interval_s = 10;
    double timeout_s = 5;          // each connection's
    std::string where;
};

// `collision_zones:` (docs/automation.md): forbidden regions of the joint positions of several
// motor records of this IOC; a move that would enter one is refused, a moving axis about to enter
// is stopped.
struct CollisionZoneEntry {
    std::string name;                                      // PVs $(P)<name>:...
    std::vector<std::pair<std::string, std::string>> axes; // expression name -> motor record
    std::string forbidden;                                 // true inside the forbidden region
    double lookahead_s = 0.2;                              // how far ahead a moving axis is judged
    std::string where;
};

// `plans:` (docs/automation.md): step scans (scan, grid, list), alignment by a curve fit (align:
// seed 003's rocking curve) and sequences of them, run inside the IOC from PVs $(P)<name>:...
// Numbers marked "expr" are a number or an expression (the PLC's language) over the plan's `args`
// and `names`, evaluated when the run (or its step) starts.
struct PlanEntry {
    enum class Type { Scan, Grid, List, Align, Sequence };
    struct Axis {                 // scan/grid: start..stop; list: positions
        std::string motor;        // a motor record (here or another IOC's)
        std::string start, stop;  // expr
        std::string points;       // expr (grid: this axis's; scan: the plan's)
        std::vector<std::string> positions; // list: expr each
        std::string where;
    };
    struct Pass {                 // align: one scan of `range` (full width) centred on the centre so far
        std::string range, points; // expr
        std::string where;
    };
    struct Step {                 // sequence
        enum class Kind { Plan, Move, Put } kind = Kind::Plan;
        std::string plan;                                      // Plan: another plan (not a sequence)
        std::vector<std::pair<std::string, std::string>> args; // Plan: its arg -> expr
        std::vector<std::pair<std::string, std::string>> moves; // Move: motor -> expr (moved together)
        std::string pv, value;                                  // Put: PV, expr
        bool wait = true;                                       // Put: with a put-callback
        std::string where;
    };
    Type type = Type::Scan;
    std::string name;                                         // PVs $(P)<name>:...
    std::string desc;
    std::vector<std::pair<std::string, double>> args;         // run-time parameters and their defaults
    std::vector<std::pair<std::string, std::string>> names;   // expression name -> PV (read when used)
    std::vector<Axis> axes;                                   // scan, grid, list
    std::string points;                                       // scan: expr
    bool snake = false;                                       // grid: inner axis alternates direction
    bool relative = false;                                    // positions relative to where the motors are
    std::optional<bool> return_to_start;                      // default: relative
    std::string dwell = "0";                                  // [s] expr: after the move, before reading
    std::vector<std::pair<std::string, std::string>> detectors; // name -> PV read at each point
    std::vector<std::pair<std::string, double>> triggers;     // PV -> value put (callback) before the dwell
    std::string signal;                                       // expr over detectors; "": the first detector
    // align
    std::string motor;                                        // the motor aligned
    std::string center;                                       // expr; "": where the motor is
    std::vector<Pass> passes;
    std::string model = "lorentzian";                         // lorentzian, gaussian, edge
    std::string sigma;                                        // expr over detectors and signal: a point's standard deviation
    double max_reduced_chi2 = 0, min_r_squared = 0, max_width = 0; // 0: not checked
    std::string latch;                                        // a state machine latched when the alignment fails
    // sequence
    std::vector<Step> steps;
    std::string directory = "/tmp";                           // one HDF5/NeXus file a run ("": none)
    std::string where;
};

// `detectors: {area_detector: [{cam, image, hdf, stats, bus, size, pixel_size, centre, ...}]}`: a
// simulated camera of the beam behind areaDetector's PV sets (docs/detectors.md).
struct AreaDetectorEntry {
    std::string cam = "cam1", image = "image1", hdf = "HDF1", stats = "Stats1"; // $(P)<part>: each
    int bus = -1;                  // the simulated bus whose plant's beam it sees (-1: the first with one)
    int size_x = 640, size_y = 480; // sensor pixels
    double pixel_size = 0.005;     // [mm] at the beam plane
    double centre_x = 0, centre_y = 0; // [mm] the beam-plane point at the sensor's centre
    double photons_per_flux = 1e10; // electrons per second per flux unit
    double dark = 10, read_noise = 2; // counts a pixel per frame; electrons rms
    std::string data_type = "UInt16"; // DataType's initial choice (the image's FTVL follows it)
    double acquire_time = 0.01, acquire_period = 0.1, gain = 1;
    std::string file_path;          // HDF1:FilePath's initial value
    std::string where;
};

struct IocConfig {
    std::string path; // the file itself
    std::string name = "IOC";
    std::string prefix; // "NAME:" unless given
    std::string stats;  // $(IOC) of the IOC health PVs (devIocStats's $(IOC):HEARTBEAT, ...); "" none
    double rate_hz = 1000;
    int cpu = -1;
    int priority = 80;
    std::vector<BusConfig> buses;
    std::vector<AxisEntry> axes;
    std::vector<PluginEntry> plugins;
    std::vector<PlcEntry> plcs;
    std::vector<KinematicsEntry> kinematics;
    std::vector<StorageEntry> storages;
    std::vector<LutEntry> luts;
    std::optional<M2mEntry> m2m;
    std::vector<DbConfig> db;
    std::optional<RcpBridgeEntry> rcp;
    std::optional<uint16_t> ca_port; // default: EPICS_CAS_SERVER_PORT / 5064
    std::string acf;                 // resolved path
    std::string acf_where;           // file:line:col of `acf`
    std::optional<AutosaveEntry> autosave;
    std::optional<PvtEntry> pvt;
    std::vector<PcompEntry> pcomp;
    std::optional<CaptureEntry> capture;
    std::vector<FeedbackEntry> feedback;
    std::vector<McaEntry> mca; // detectors.mca
    std::vector<QuadEmEntry> quadem; // detectors.quadem
    std::vector<AreaDetectorEntry> area_detector; // detectors.area_detector
    std::optional<SmartControlEntry> smart_control;
    std::vector<CompoundMotorEntry> compound_motors;
    std::vector<StateMachineEntry> state_machines;
    std::optional<NotifyEntry> notify;
    std::vector<CollisionZoneEntry> collision_zones;
    std::vector<PlanEntry> plans;

    // Reads the file, expanding its macro references first (expand_ioc_macros) with `macros`
    // (`beamctl run -m`).
    // Throws one MultiError with every error of the file (its first line: the first error).
    static IocConfig load(const std::string& path, const MacroMap& macros = {});
    static IocConfig parse(const std::string& text, const std::string& path);
    // The same, recording every error in `errors` and returning what could be read (defaults
    // where values were bad), for `beamctl check`.
    static IocConfig load(const std::string& path, ErrorList& errors, const MacroMap& macros = {});
    static IocConfig parse(const std::string& text, const std::string& path, ErrorList& errors);
};

// The slaves of a bus as {position, catalog type}.
std::vector<std::pair<int, std::string>> positions_and_types(const BusConfig& bc);

// The IOC file's text with its macro references expanded, as `beamctl run -m NAME=VALUE` asks:
// $(NAME) and ${NAME} take the value given in `macros`, $(NAME=default) that value or else the
// default (core/macros.hpp syntax). A reference to a name with neither is left as it is, for the
// file or code it is handed to (axis, PLC and kinematics macros). Values are inserted as text
// before the YAML is read. Errors (an unterminated reference, a recursive value) name path:line:col.
std::string expand_ioc_macros(const std::string& text, const MacroMap& macros, const std::string& path);

} // namespace beamctl::config
