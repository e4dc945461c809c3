#include "ioc/axes.hpp"

#include "motion/axis_variables.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "module/pv_table.hpp"
#include "ioc/pv_util.hpp"
#include "motion/axis_setup.hpp"
#include "pv/motor_record.hpp"

#include <cinttypes>
#include <cmath>
#include <cstdio>

namespace beamctl::ioc {
namespace {
log::Logger lg("ioc.axes");

std::string at(const SourceLoc& w) { return SB() << w.file << ":" << w.line << ":" << w.col; }

// "ec0.s3.driveStatus01" of a link (without its bit).
std::string signal_name(const motion::SignalRef& r) {
    if (r.entry == "masterstatus") return SB() << "ec" << r.bus << ".masterstatus";
    return SB() << "ec" << r.bus << ".s" << r.slave << "." << r.entry;
}

// ECMC MtnCmd codes.
motion::CommandType command_of(int code) {
    switch (code) {
    case 1: return motion::CommandType::MoveVelocity;
    case 2: return motion::CommandType::MoveRelative;
    case 3: return motion::CommandType::MoveAbsolute;
    case 10: return motion::CommandType::Home;
    default: return motion::CommandType::None;
    }
}
// The motor record's driver for one axis (ECMC's ecmcMotorRecordAxis): commands become axis
// commands; status comes from the axis group's latest snapshot. Done follows ECMC: the command
// was taken and finished (tags), the axis is not busy, and it is at target (or target monitoring
// is off, the axis is disabled or in error, or the command was refused).
class AxisMotorDriver : public pv::MotorDriver {
public:
    AxisMotorDriver(IocAxes& axes, std::size_t index) : axes_(axes), i_(index) {}
    void move(double target, double velocity, double acceleration) override {
        motion::AxisCommand c{motion::CommandType::MoveAbsolute, target, velocity};
        c.acceleration = c.deceleration = acceleration;
        sent(axes_.send(i_, c));
    }
    void move_velocity(double velocity, double acceleration) override {
        motion::AxisCommand c{motion::CommandType::MoveVelocity, 0, velocity};
        c.acceleration = c.deceleration = acceleration;
        sent(axes_.send(i_, c));
    }
    void home(bool, double, double) override { // ECMC: the configured sequence; direction and HVEL unused
        motion::AxisCommand c{motion::CommandType::Home};
        sent(axes_.send(i_, c));
    }
    void stop(double acceleration) override {
        motion::AxisCommand c{motion::CommandType::Halt};
        c.deceleration = acceleration;
        axes_.send(i_, c);
    }
    void set_position(double position) override {
        sent(axes_.send(i_, motion::AxisCommand{motion::CommandType::SetPosition, position}));
    }
    void set_closed_loop(bool on) override {
        motion::AxisCommand c{motion::CommandType::Power};
        c.on = on;
        axes_.send(i_, c);
    }
    void set_soft_limits(double dial_low, double dial_high) override { axes_.set_record_limits(i_, dial_low, dial_high); }
    // ECMC's motor driver: PCOF/ICOF/DCOF in 0..0.99 are the controller's Kp/Ki/Kd / 100.
    bool set_gain(int which, double value) override {
        if (!(value >= 0 && value <= 0.99)) return false;
        motion::AxisCommand c{motion::CommandType::SetGain, value * 100};
        c.gain = which;
        return axes_.send(i_, c) != 0;
    }
    Status status() override {
        const motion::AxisStatus& s = axes_.status(i_);
        const motion::AxisParams& p = axes_.params(i_);
        Status r;
        r.position = s.act_pos;
        r.encoder = s.act_pos;
        r.has_encoder = !p.virtual_axis;
        r.velocity = s.act_vel;
        bool taken = s.done_tag >= last_tag_ && !s.busy;
        // The outcome belongs to this driver's last command only once the cycle has taken it
        // (a stale failure must not end the next move before it starts).
        bool failed = s.done_tag >= last_tag_ && s.move_failed;
        bool settled = s.at_target || !p.target_enable || s.error_id != 0 || !s.enabled || s.refused_tag == last_tag_ || failed;
        // Something else moves the axis (the PLC's setpoint, e.g. a virtual axis's kinematics):
        // DMOV/MOVN follow it, as the motor record does for a move it did not start.
        bool external = s.following && s.ext_moving && s.enabled;
        r.done = (last_tag_ == 0 ? !s.busy : taken && settled) && !external;
        r.moving = !r.done;
        r.direction_positive = s.act_vel > 0 || (s.act_vel == 0 && last_dir_);
        if (s.act_vel != 0) last_dir_ = s.act_vel > 0;
        r.high_limit = s.limit_fwd;
        r.low_limit = s.limit_bwd;
        r.home_switch = s.home_sensor;
        r.homed = s.homed;
        // ECMC: PROBLEM on an axis error or a soft-limit interlock; beamctl also on a refused
        // command or a motion that ended short
        bool soft = s.warning_id == motion::error_id::kSoftLimitFwd || s.warning_id == motion::error_id::kSoftLimitBwd;
        r.failed = failed;
        r.limit_violation = failed && soft;
        r.problem = s.error_id != 0 || failed || (soft && s.done_tag >= last_tag_);
        r.valid = s.position_valid;
        r.enabled = s.enabled;
        r.slip_stall = s.error_id == motion::error_id::kStall;
        r.sync_requests = s.mr_sync_requests;
        r.stop_requests = s.mr_stop_requests;
        return r;
    }

private:
    void sent(uint64_t tag) {
        if (tag) last_tag_ = tag;
    }
    IocAxes& axes_;
    std::size_t i_;
    uint64_t last_tag_ = 0;
    bool last_dir_ = true;
};

// fieldInit "RTRY=0,FOFF=Frozen" -> {RTRY, 0}, {FOFF, Frozen}
std::vector<std::pair<std::string, std::string>> field_init(const std::string& s) {
    std::vector<std::pair<std::string, std::string>> v;
    std::size_t at = 0;
    while (at < s.size()) {
        std::size_t end = s.find(',', at);
        std::string item = s.substr(at, end == std::string::npos ? std::string::npos : end - at);
        std::size_t eq = item.find('=');
        if (eq != std::string::npos) {
            auto trim = [](std::string x) {
                x.erase(0, x.find_first_not_of(" \t"));
                x.erase(x.find_last_not_of(" \t") + 1);
                return x;
            };
            v.emplace_back(trim(item.substr(0, eq)), trim(item.substr(eq + 1)));
        }
        if (end == std::string::npos) break;
        at = end + 1;
    }
    return v;
}
// The axis PVs as ecmccfg's ecmcAxis.db names them, on the axis's data items (ECMC's asyn names
// where ECMC has them: ax<n>.actpos, .status, .control, ...). The commands are writes: EnaCmd,
// ExeCmd, StpCmd and RstCmd are bits 0-3 of ax<n>.control, as ecmccfg's asynMask records.
const module::PvTable& axis_table() {
    static const module::PvTable t{"axis", {
        {"-PosAct", "ai", "actpos", {{"DESC", "Actual position"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-VelAct", "ai", "actvel", {{"DESC", "Actual velocity"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)/s"}}},
        {"-PosSet", "ai", "setpos", {{"DESC", "Setpoint position"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-PosErr", "ai", "poserr", {{"DESC", "Following error"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-Stat", "longin", "status", {{"DESC", "Status word"}}},
        {"-ErrId", "longin", "errorid", {{"DESC", "Error id"}, {"HIHI", "1"}, {"HHSV", "MAJOR"}}},
        {"-WrnId", "longin", "warningid", {{"DESC", "Warning id"}, {"HIHI", "1"}, {"HHSV", "MINOR"}}},
        {"-SeqState", "longin", "seqstate", {{"DESC", "Homing sequence state"}}},
        {"-LastIlock", "longin", "lastilock", {{"DESC", "Last interlock"}}},
        {"-EnaAct", "bi", "status.1", {{"DESC", "Enabled"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}},
        {"-Busy", "bi", "status.3", {{"DESC", "Busy"}, {"ZNAM", "Idle"}, {"ONAM", "Busy"}}},
        {"-AtTarget", "bi", "status.4", {{"DESC", "At target"}, {"ZNAM", "Not at target"}, {"ONAM", "At target"}}},
        {"-Moving", "bi", "status.5", {{"DESC", "Moving"}, {"ZNAM", "Stopped"}, {"ONAM", "Moving"}}},
        {"-LimFwd", "bi", "status.6", {{"DESC", "Forward limit switch"}, {"ZNAM", "Limit activated"}, {"ONAM", "Limit OK"}, {"ZSV", "MINOR"}}},
        {"-LimBwd", "bi", "status.7", {{"DESC", "Backward limit switch"}, {"ZNAM", "Limit activated"}, {"ONAM", "Limit OK"}, {"ZSV", "MINOR"}}},
        {"-HomeSwitch", "bi", "status.8", {{"DESC", "Home switch"}, {"ZNAM", "Off"}, {"ONAM", "On"}}},
        {"-Homed", "bi", "status.9", {{"DESC", "Homed"}, {"ZNAM", "Not homed"}, {"ONAM", "Homed"}}},
        {"-Err", "bi", "errorid", {{"DESC", "Error"}, {"ZNAM", "No error"}, {"ONAM", "Error"}, {"OSV", "MAJOR"}}},
        // EnaCmd follows the axis when it disables itself (an error): asyn's read-back
        {"-EnaCmd", "bo", "control.0", {{"DESC", "Enable"}, {"ZNAM", "Disable"}, {"ONAM", "Enable"}}, true},
        {"-ExeCmd", "bo", "control.1", {{"DESC", "Execute MtnCmd (rising edge)"}, {"ZNAM", "Stop"}, {"ONAM", "Execute"}}},
        {"-StpCmd", "bo", "control.2", {{"DESC", "Stop"}, {"ZNAM", "0"}, {"ONAM", "Stop"}}},
        {"-RstCmd", "bo", "control.3", {{"DESC", "Reset errors"}, {"ZNAM", "0"}, {"ONAM", "Reset"}}},
        {"-TgtPosCmd", "ao", "targpos", {{"DESC", "Target position"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-TgtVelCmd", "ao", "targvelo", {{"DESC", "Target velocity"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)/s"}, {"VAL", "$(VELO)"}}},
        {"-MtnCmd", "longout", "command", {{"DESC", "1 VEL 2 REL 3 ABS 10 HOME"}, {"VAL", "3"}}},
        {"-MtnCmdData", "longout", "cmddata", {{"DESC", "Homing sequence; 14 = configured"}, {"VAL", "14"}}},
        {"-MsgTxt", "stringin", "", {{"DESC", "Error message"}}}, // text: set by the axes on an error
        // the soft limits as ecmccfg's ecmcMotorRecord.template and ecmcAxis.db name them: one value
        // with the motor record's DHLM/DLLM (a put to either moves both)
        {"-CfgDHLM", "ao", "softlimfwd", {{"DESC", "EC High Soft Limit"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}, true},
        {"-CfgDLLM", "ao", "softlimbwd", {{"DESC", "EC Low Soft Limit"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}, true},
        {"-CfgDHLM-En", "longout", "softlimfwden", {{"DESC", "EC High Soft Limit enable"}}, true},
        {"-CfgDLLM-En", "longout", "softlimbwden", {{"DESC", "EC Low Soft Limit enable"}}, true},
        {"-CfgDHLM-RB", "ai", "softlimfwd", {{"DESC", "EC High Soft Limit RB"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-CfgDLLM-RB", "ai", "softlimbwd", {{"DESC", "EC Low Soft Limit RB"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
        {"-CfgDHLM-En-RB", "longin", "softlimfwden", {{"DESC", "EC High Soft Limit enable RB"}}},
        {"-CfgDLLM-En-RB", "longin", "softlimbwden", {{"DESC", "EC Low Soft Limit enable RB"}}},
        {"-SftLimFwdEna-RB", "bi", "status.14", {{"DESC", "Softlim Fwd Enabled"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}},
        {"-SftLimBwdEna-RB", "bi", "status.15", {{"DESC", "Softlim Bwd Enabled"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}},
    }};
    return t;
}

// One row per encoder: $(P) = "<axis PV>-Enc01", signals "ax<n>.enc01.*".
const module::PvTable& encoder_table() {
    static const module::PvTable t{"axis encoder", {
        {"-PosAct", "ai", "actpos", {{"DESC", "Encoder $(N) position"}, {"PREC", "$(PREC)"}, {"EGU", "$(EGU)"}}},
    }};
    return t;
}

std::string encoder_key(std::size_t k) { // "enc01"
    char n[16];
    std::snprintf(n, sizeof n, "enc%02zu", k + 1);
    return n;
}

// The axis's data items as the IOC loop sees them (ECMC's asyn names where ECMC has them), with
// the PLC variable of the same value: what records read and write through device support.
// Readbacks come from the axis group's latest snapshot; the command items are the IOC's own
// (ExeCmd runs `command` with targpos, targvelo and cmddata, as ECMC's control word does).
enum class Write : uint8_t { None, TargPos, TargVelo, Command, CmdData, Control, SoftFwd, SoftBwd, SoftFwdOn, SoftBwdOn };
struct AxisItem {
    const char* name; // after "ax<n>."
    const char* plc;  // the PLC variable with this value ("" none); a record may use either name
    Write write;
    int control_bit;  // a PLC name that is one bit of `control` (drv.enable = bit 0), else -1
    double (*get)(const motion::AxisStatus& s, const AxisCommandState& c);
};
constexpr AxisItem kAxisItems[] = {
    {"actpos", "enc.actpos", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.act_pos; }},
    {"actvel", "enc.actvel", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.act_vel; }},
    {"setpos", "traj.setpos", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.set_pos; }},
    {"poserr", "", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.pos_err; }},
    {"status", "", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.stat_word()); }},
    {"errorid", "error", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.error_id); }},
    {"warningid", "", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.warning_id); }},
    {"seqstate", "", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.sequence_state); }},
    {"lastilock", "", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(uint8_t(s.last_interlock)); }},
    {"targpos", "traj.targetpos", Write::TargPos, -1, [](const motion::AxisStatus&, const AxisCommandState& c) { return c.targpos; }},
    {"targvelo", "traj.targetvel", Write::TargVelo, -1, [](const motion::AxisStatus&, const AxisCommandState& c) { return c.targvelo; }},
    {"command", "traj.command", Write::Command, -1, [](const motion::AxisStatus&, const AxisCommandState& c) { return double(c.command); }},
    {"cmddata", "traj.cmddata", Write::CmdData, -1, [](const motion::AxisStatus&, const AxisCommandState& c) { return double(c.cmddata); }},
    // the soft limits and their enables (ECMC's motor driver parameters CfgDHLM, CfgDLLM, CfgDHLM-En, CfgDLLM-En)
    {"softlimfwd", "", Write::SoftFwd, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.soft_fwd; }},
    {"softlimbwd", "", Write::SoftBwd, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return s.soft_bwd; }},
    {"softlimfwden", "", Write::SoftFwdOn, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.soft_fwd_enabled); }},
    {"softlimbwden", "", Write::SoftBwdOn, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.soft_bwd_enabled); }},
    // bit 0 enable (the axis's enable command), 1 execute, 2 stop, 3 reset
    {"control", "", Write::Control, -1, [](const motion::AxisStatus& s, const AxisCommandState& c) {
         return double((c.control & ~1u) | (s.enable_cmd ? 1u : 0u)); }},
    // PLC names of bits and flags
    {"", "drv.enable", Write::Control, 0, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.enable_cmd); }},
    {"", "traj.execute", Write::Control, 1, [](const motion::AxisStatus&, const AxisCommandState& c) { return double(c.control >> 1 & 1); }},
    {"", "reset", Write::Control, 3, [](const motion::AxisStatus&, const AxisCommandState& c) { return double(c.control >> 3 & 1); }},
    {"", "drv.enabled", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.enabled); }},
    {"", "traj.busy", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.busy); }},
    {"", "mon.attarget", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.at_target); }},
    {"", "mon.lowlim", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(!s.limit_bwd); }},
    {"", "mon.highlim", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(!s.limit_fwd); }},
    {"", "mon.homesensor", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.home_sensor); }},
    {"", "enc.homed", Write::None, -1, [](const motion::AxisStatus& s, const AxisCommandState&) { return double(s.homed); }},
};

const AxisItem* find_item(std::string_view name) {
    for (const AxisItem& it : kAxisItems)
        if ((*it.name && name == it.name) || (*it.plc && name == it.plc)) return &it;
    return nullptr;
}

// Device support "beamctl" on an axis data item: "@ax1.actpos", "@ax1.status.1" (a bit),
// "@ax1.control.0" (EnaCmd), "@ax1.enc01.actpos", or a PLC name ("@ax1.enc.actpos"). Reads the
// axis group's latest snapshot (the IOC loop's 10 ms look: SCAN "I/O Intr" records are processed
// when the value differs from the last one read); writes are the axis's commands. IOC loop only.
class AxisItemDevice : public pv::LinkDevice {
public:
    AxisItemDevice(IocAxes& axes, std::size_t i, const AxisItem* item, int enc, int bit, bool binary, std::string name)
        : axes_(axes), i_(i), item_(item), enc_(enc), bit_(bit), binary_(binary), name_(std::move(name)) {}
    bool read(double& v) override {
        v = value();
        last_ = v;
        return true;
    }
    bool write(double v) override {
        if (!item_ || item_->write == Write::None || !std::isfinite(v)) return false;
        return axes_.write_item(i_, int(item_->write), item_->control_bit >= 0 ? item_->control_bit : bit_, v);
    }
    bool changed() override {
        double v = value();
        bool c = !(v == last_);
        last_ = v;
        return c;
    }
    std::string describe() const override { return name_; }

private:
    double value() const {
        const motion::AxisStatus& s = axes_.looked(i_);
        double v = item_ ? item_->get(s, axes_.command_state(i_)) : (enc_ < s.enc_count ? s.enc_pos[std::size_t(enc_)] : 0.0);
        if (bit_ >= 0) return double(uint64_t(int64_t(v)) >> bit_ & 1);
        return binary_ ? double(v != 0) : v;
    }
    IocAxes& axes_;
    std::size_t i_;
    const AxisItem* item_; // null: encoder enc_'s position
    int enc_, bit_;
    bool binary_;
    std::string name_;
    double last_ = NAN;
};
} // namespace

IocAxes::IocAxes(const std::vector<config::AxisEntry>& entries, const std::string& prefix,
                 registry::Registry& signals, pv::Database& db, ErrorList& errors)
    : db_(db), prefix_(prefix) {
    std::set<int> ids;
    std::set<std::string> names;
    for (std::size_t n = 0; n < entries.size(); ++n) {
        const config::AxisEntry& e = entries[n];
        // every error of the entry, each with the chain that led to it (ioc.yaml's entry, its macros)
        const std::string chain = config::axis_entry_context(e, n);
        auto fail = [&](const std::string& m) { errors.add(chain + ": " + m); };
        Axis a;
        std::vector<Error> file_errors;
        a.cfg = motion::load_axis_config(e.file, e.macros, file_errors);
        for (const auto& enc : e.encoders) {
            motion::EncoderConfig ec = motion::load_encoder_config(enc.file, enc.macros, file_errors);
            if (file_errors.empty()) {
                try {
                    motion::add_encoder(a.cfg, std::move(ec));
                } catch (const Error& x) {
                    file_errors.push_back(x);
                }
            }
        }
        for (const auto& x : file_errors) fail(x.what());
        if (!file_errors.empty()) continue; // nothing more of this axis can be known
        for (const auto& w : a.cfg.warnings) LOG_WARN(lg, w);
        // ECMC numbering: an axis without an id is the previous one + 1
        int id = a.cfg.axis.id.value_or(axes_.empty() ? 1 : axes_.back().params.id + 1);
        a.cfg.axis.id = id;
        if (!ids.insert(id).second) {
            errors.add(SB() << e.where << ": axis id " << id << " is used twice (" << e.file << ")");
            continue;
        }
        if (!names.insert(a.cfg.epics.name).second) {
            errors.add(SB() << e.where << ": axis name '" << a.cfg.epics.name << "' is used twice (" << e.file << ")");
            continue;
        }
        try {
            a.params = motion::make_axis_params(a.cfg);
        } catch (const Error& x) {
            fail(x.what());
            continue;
        }
        a.params.id = id;
        a.pv = prefix + a.cfg.epics.name;
        std::string owner = SB() << "axis " << id << " (" << a.cfg.epics.name << ")";
        for (const auto& r : motion::axis_signal_refs(a.cfg)) { // every bad reference, not the first
            if (r.slave < 0) {
                fail(SB() << at(r.where) << ": '" << r.text << "': the simulation slave (s-1) is not supported");
                continue;
            }
            const registry::Signal* sig = signals.find(signal_name(r));
            if (!sig || sig->loop_only) {
                fail(SB() << at(r.where) << ": no signal '" << signal_name(r) << "' on the configured buses (from '" << r.text << "')");
                continue;
            }
            std::string why;
            if (sig->direction == registry::Direction::Output && !signals.claim(sig->name, owner, why))
                fail(SB() << at(r.where) << ": " << owner << " cannot drive it: " << why);
        }
        // The axis as PLC code and records see it: ax<n>.enc.actpos, ax<n>.traj.extsetpos, ...
        for (const motion::AxisVariableInfo& v : motion::axis_variables()) {
            registry::Signal s;
            s.name = SB() << "ax" << id << "." << v.name;
            s.type = "LREAL";
            s.direction = motion::is_readback(v) ? registry::Direction::Input : registry::Direction::Variable;
            s.owner_kind = registry::OwnerKind::Axis;
            s.owner = owner;
            signals.declare(std::move(s));
        }
        // ... and as its PVs and other records do: ax<n>.actpos, .status, .control, ...
        auto item = [&](std::string name, bool writable) {
            registry::Signal s;
            s.name = SB() << "ax" << id << "." << name;
            s.type = "LREAL";
            s.direction = writable ? registry::Direction::Variable : registry::Direction::Input;
            s.owner_kind = registry::OwnerKind::Axis;
            s.owner = owner;
            signals.declare(std::move(s));
        };
        for (const AxisItem& it : kAxisItems)
            if (*it.name) item(it.name, it.write != Write::None);
        for (std::size_t k = 0; k < a.cfg.encoders.size() && k < motion::AxisStatus::kMaxEncoders; ++k)
            item(encoder_key(k) + ".actpos", false);
        a.cmd.targvelo = a.params.trajectory.velocity;
        axes_.push_back(std::move(a));
    }
    for (Axis& a : axes_) {
        make_pvs(a, signals);
        // the PLC name of an item is served by the item's PV
        for (const AxisItem& it : kAxisItems) {
            if (!*it.name || !*it.plc) continue;
            std::string p = SB() << "ax" << a.params.id << ".";
            if (const registry::Signal* s = signals.find(p + it.name); s && !s->pv.empty()) signals.set_pv(p + it.plc, s->pv);
        }
    }
    attach_motor_drivers();
}

std::string IocAxes::owner(std::size_t i) const {
    return SB() << "axis " << axes_.at(i).params.id << " (" << axes_.at(i).cfg.epics.name << ")";
}

int IocAxes::find(const std::string& name) const {
    for (std::size_t i = 0; i < axes_.size(); ++i)
        if (axes_[i].cfg.epics.name == name) return int(i);
    return -1;
}

void IocAxes::make_pvs(Axis& a, registry::Registry& signals) {
    char velo[40];
    std::snprintf(velo, sizeof velo, "%.12g", a.params.trajectory.velocity);
    std::string sp = SB() << "ax" << a.params.id << ".";
    module::PvInstance in{a.pv, sp, {{"PREC", std::to_string(a.cfg.epics.precision)}, {"EGU", a.cfg.epics.unit}, {"VELO", velo}}};
    pv::DbFile f = make_records(axis_table(), in, signals);
    name_pvs(axis_table(), in, signals);
    for (std::size_t k = 0; k < a.cfg.encoders.size() && k < motion::AxisStatus::kMaxEncoders; ++k) {
        char dash[16];
        std::snprintf(dash, sizeof dash, "-Enc%02zu", k + 1);
        module::PvInstance e{a.pv + dash, sp + encoder_key(k) + ".", in.macros};
        e.macros["N"] = std::to_string(k + 1);
        pv::merge_db(f, make_records(encoder_table(), e, signals));
        name_pvs(encoder_table(), e, signals);
    }
    if (a.cfg.epics.motor_record.enable) make_motor_record(a, f);
    db_.load(f);
    a.msg = db_.find(a.pv + "-MsgTxt");
    a.msg->val_read_only = true;
}

void IocAxes::attach_motor_drivers() {
    for (std::size_t i = 0; i < axes_.size(); ++i)
        if (axes_[i].cfg.epics.motor_record.enable)
            if (pv::MotorRecord* m = pv::MotorRecord::from(db_.find(axes_[i].pv))) m->set_driver(std::make_shared<AxisMotorDriver>(*this, i));
}

void IocAxes::attach_asyn_motors() {
    for (pv::Record* r : db_.records()) {
        pv::MotorRecord* m = pv::MotorRecord::from(r);
        if (!m || r->dtyp != 1 || std::dynamic_pointer_cast<AxisMotorDriver>(m->driver())) continue; // ours already
        std::string out(m->out());
        if (!out.empty() && out[0] == '@') out.erase(0, 1);
        // asyn(PORT,ADDR[,TIMEOUT])
        std::size_t comma = out.find(','), close = out.find(')');
        if (out.rfind("asyn(", 0) != 0 || comma == std::string::npos || close == std::string::npos || comma > close)
            throw Error(SB() << "record " << r->name() << ": OUT '" << m->out() << "' should be @asyn(PORT,ADDR) for DTYP asynMotor");
        std::string addr = out.substr(comma + 1, close - comma - 1);
        addr = addr.substr(0, addr.find(','));
        char* end = nullptr;
        long id = std::strtol(addr.c_str(), &end, 10);
        int found = -1;
        std::string ids;
        for (std::size_t i = 0; i < axes_.size(); ++i) {
            if (params(i).id == id && end && *end == '\0') found = int(i);
            ids += (ids.empty() ? "" : ", ") + std::to_string(params(i).id);
        }
        if (found < 0)
            throw Error(SB() << "record " << r->name() << ": OUT '" << m->out() << "': no axis " << addr
                             << (ids.empty() ? std::string(" (the IOC has no axes)") : " (axes: " + ids + ")"));
        m->set_driver(std::make_shared<AxisMotorDriver>(*this, std::size_t(found)));
    }
}

uint64_t IocAxes::send(std::size_t i, motion::AxisCommand c) {
    if (!group_) return 0;
    c.tag = next_tag_++;
    return group_->send(i, c) ? c.tag : 0;
}

const motion::AxisStatus& IocAxes::status(std::size_t i) {
    if (!group_) return idle_;
    const auto& st = group_->snapshot();
    return i < st.size() ? st[i] : idle_;
}


void IocAxes::make_motor_record(Axis& a, pv::DbFile& f) {
    const motion::AxisParams& p = a.params;
    auto num = [](double v) {
        char b[40];
        std::snprintf(b, sizeof b, "%.12g", v);
        return std::string(b);
    };
    // one step = one encoder count (the readback resolution); virtual axes: 10^-PREC
    double mres = p.virtual_axis ? std::pow(10.0, -a.cfg.epics.precision) : std::fabs(p.encoder.numerator / p.encoder.denominator);
    std::vector<std::pair<std::string, std::string>> fields = {
        {"DTYP", "asynMotor"},
        {"OUT", SB() << "@asyn(MCU1," << p.id << ")"},
        {"DESC", a.cfg.epics.motor_record.description.substr(0, 40)},
        {"EGU", a.cfg.epics.unit},
        {"PREC", std::to_string(a.cfg.epics.precision)},
        {"MRES", num(mres)},
        {"VELO", num(p.trajectory.velocity)},
        {"ACCL", num(p.trajectory.acceleration > 0 ? p.trajectory.velocity / p.trajectory.acceleration : 0.2)},
        {"JVEL", num(p.jog_velocity > 0 ? p.jog_velocity : p.trajectory.velocity)},
        {"HVEL", num(p.homing_velocity_to > 0 ? p.homing_velocity_to : p.trajectory.velocity / 10)},
        {"TWV", num(a.cfg.axis.tweak_dist)},
        {"RDBD", num(p.target_enable && p.target_tolerance > 0 ? p.target_tolerance : mres)},
        {"RTRY", "0"},
    };
    if (p.velocity_enable && p.velocity_max > 0) fields.push_back({"VMAX", num(p.velocity_max)});
    if (p.soft_fwd_enable && p.soft_bwd_enable) {
        fields.push_back({"DHLM", num(p.soft_fwd)});
        fields.push_back({"DLLM", num(p.soft_bwd)});
    }
    for (auto& kv : field_init(a.cfg.epics.motor_record.field_init)) {
        bool replaced = false;
        for (auto& f2 : fields)
            if (f2.first == kv.first) f2.second = kv.second, replaced = true;
        if (!replaced) fields.push_back(kv);
    }
    f.records.push_back(record("motor", a.pv, fields));
}

std::unique_ptr<pv::LinkDevice> IocAxes::make_device(std::string_view name, int bit, bool output, bool binary, std::string& why) {
    // "ax<id>.<item>"
    std::size_t dot = name.find('.');
    int id = dot != std::string_view::npos && name.size() > 2 ? std::atoi(std::string(name.substr(2, dot - 2)).c_str()) : -1;
    std::size_t i = 0;
    while (i < axes_.size() && axes_[i].params.id != id) ++i;
    if (i == axes_.size()) {
        why = SB() << "no axis " << id << " for '" << name << "'";
        return nullptr;
    }
    std::string_view rest = name.substr(dot + 1);
    const AxisItem* item = find_item(rest);
    int enc = -1;
    if (!item) {
        for (std::size_t k = 0; k < axes_[i].cfg.encoders.size() && k < motion::AxisStatus::kMaxEncoders; ++k)
            if (rest == encoder_key(k) + ".actpos") enc = int(k);
        if (enc < 0) {
            why = SB() << "'" << name << "' lives in the cycle only (PLC code reads and writes it); records reach "
                       << "ax" << id << ".actpos, .actvel, .setpos, .poserr, .status, .errorid, .warningid, "
                       << ".targpos, .targvelo, .command, .cmddata, .control and the encoders' .encNN.actpos";
            return nullptr;
        }
    }
    if (output && (!item || item->write == Write::None)) {
        why = SB() << "'" << name << "' is a readback of " << owner(i) << "; an output link cannot write it";
        return nullptr;
    }
    if (output && bit >= 0 && item->write != Write::Control) {
        why = SB() << "'" << name << "." << bit << "': only the bits of ax" << id << ".control are commands";
        return nullptr;
    }
    std::string full = bit >= 0 ? std::string(SB() << name << "." << bit) : std::string(name);
    return std::make_unique<AxisItemDevice>(*this, i, item, enc, bit, binary, full);
}

bool IocAxes::write_item(std::size_t i, int w, int bit, double v) {
    AxisCommandState& c = axes_.at(i).cmd;
    switch (Write(w)) {
    case Write::None: return false;
    case Write::TargPos: c.targpos = v; return true;
    case Write::TargVelo: c.targvelo = v; return true;
    case Write::Command: c.command = int(v); return true;
    case Write::CmdData: c.cmddata = int(v); return true;
    case Write::SoftFwd:
    case Write::SoftBwd:
    case Write::SoftFwdOn:
    case Write::SoftBwdOn: { // the motor record's DHLM/DLLM follow (publish), as ECMC's
        if (!std::isfinite(v)) return false;
        motion::AxisCommand l{motion::CommandType::SetSoftLimits};
        if (Write(w) == Write::SoftFwd) l.soft_fwd = v;
        if (Write(w) == Write::SoftBwd) l.soft_bwd = v;
        if (Write(w) == Write::SoftFwdOn) l.soft_fwd_on = v != 0 ? 1 : 0;
        if (Write(w) == Write::SoftBwdOn) l.soft_bwd_on = v != 0 ? 1 : 0;
        return send(i, l) != 0;
    }
    case Write::Control: break;
    }
    // the control word (ECMC): bit 0 enable, 1 execute (1 runs `command`, 0 halts), 2 stop, 3 reset
    uint32_t old = c.control | (status(i).enable_cmd ? 1u : 0u);
    uint32_t word = bit >= 0 ? (v != 0 ? old | 1u << bit : old & ~(1u << bit)) : uint32_t(int64_t(v));
    uint32_t touched = bit >= 0 ? 1u << bit : (old ^ word) | (word & 0xCu); // stop/reset: every write of 1
    c.control = word & ~1u;
    bool ok = true;
    if (touched & 1u) {
        motion::AxisCommand p{motion::CommandType::Power};
        p.on = word & 1u;
        ok = send(i, p) != 0 && ok;
    }
    if (touched & 2u) {
        motion::AxisCommand m;
        if (!(word & 2u)) { // execute low: stop with the normal deceleration
            m.type = motion::CommandType::Halt;
        } else {
            m.type = command_of(c.command);
            if (m.type == motion::CommandType::None) return false;
            m.position = c.targpos;
            m.velocity = c.targvelo;
            if (m.type == motion::CommandType::MoveVelocity && c.targpos < 0) m.velocity = -std::fabs(m.velocity);
            m.homing_sequence = c.cmddata;
        }
        ok = send(i, m) != 0 && ok;
    }
    if ((touched & 4u) && (word & 4u)) ok = send(i, motion::AxisCommand{motion::CommandType::Halt}) != 0 && ok;
    if ((touched & 8u) && (word & 8u)) ok = send(i, motion::AxisCommand{motion::CommandType::Reset}) != 0 && ok;
    return ok;
}

void IocAxes::bind(const Resolver& resolve, rt::Engine& engine) {
    if (axes_.empty()) return;
    std::vector<std::unique_ptr<motion::Axis>> rt_axes;
    for (auto& a : axes_) rt_axes.push_back(std::make_unique<motion::Axis>(a.params, motion::bind_axis_io(a.cfg, resolve)));
    group_ = std::make_unique<motion::AxisGroup>(std::move(rt_axes));
    engine.add_stage(rt::StageOrder::Axes, *group_);
}

void IocAxes::set_message(Axis& a, const char* text) {
    char t[pv::kStringSize] = "";
    std::snprintf(t, sizeof t, "%s", text); // a DBR_STRING holds 39 characters
    const pv::FieldDesc* f = a.msg->type().find("VAL");
    pv::Elements e = a.msg->elements(*f);
    pv::put_element(*a.msg, *f, e, 0, pv::Prim::String, t);
    a.msg->udf = 0;
    db_.process(*a.msg);
}

void IocAxes::set_derived_limits(std::size_t i, double lo, double hi) {
    axes_.at(i).derived = true;
    put_dial_limits(i, lo, hi);
}

void IocAxes::put_dial_limits(std::size_t i, double lo, double hi) {
    pv::Record* m = db_.find(axes_.at(i).pv);
    if (!pv::MotorRecord::from(m)) return;
    // the record follows the axis: its puts (DLLM, then DHLM) must not go back to the axis, where
    // the half-done pair would narrow the limits for a cycle
    axes_.at(i).following_axis = true;
    struct Done {
        Axis& a;
        ~Done() { a.following_axis = false; }
    } done{axes_.at(i)};
    auto put = [&](const char* field, double v) {
        pv::Address a;
        a.rec = m;
        a.field = m->type().find(field);
        double cur = 0;
        db_.get(a, pv::Prim::Double, &cur, 1);
        if (std::fabs(cur - v) > 1e-12 * std::max(1.0, std::fabs(v))) db_.put(a, pv::Prim::Double, &v, 1);
    };
    // widen first, so that DLLM <= DHLM holds after each put
    double cur_hi = 0;
    pv::Address a;
    a.rec = m;
    a.field = m->type().find("DHLM");
    db_.get(a, pv::Prim::Double, &cur_hi, 1);
    if (lo > cur_hi) {
        put("DHLM", hi);
        put("DLLM", lo);
    } else {
        put("DLLM", lo);
        put("DHLM", hi);
    }
}

void IocAxes::set_record_limits(std::size_t i, double lo, double hi) {
    Axis& a = axes_.at(i);
    if (a.derived || a.following_axis || !group_) return;
    const motion::AxisStatus& s = status(i);
    bool on = !(lo == 0 && hi == 0);
    bool same = on ? s.soft_fwd_enabled && s.soft_bwd_enabled && s.soft_fwd == hi && s.soft_bwd == lo
                   : !s.soft_fwd_enabled && !s.soft_bwd_enabled;
    if (same) return; // the axis's own change coming back through the record
    motion::AxisCommand c{motion::CommandType::SetSoftLimits};
    if (on) {
        c.soft_fwd = hi;
        c.soft_bwd = lo;
    }
    c.soft_fwd_on = c.soft_bwd_on = on ? 1 : 0;
    uint64_t tag = send(i, c);
    if (!tag) {
        LOG_ERR(lg, owner(i) << ": the soft limits " << lo << " .. " << hi << " of its motor record did not reach the axis (command queue full)");
        return;
    }
    a.limits_pending = true;
    a.limits_tag = tag;
    if (on) {
        a.soft_fwd = hi;
        a.soft_bwd = lo;
    }
}

void IocAxes::publish() {
    if (!group_) return;
    const auto& st = group_->snapshot();
    look_ = st; // the records' device support reads this look (scan_io_intr); MsgTxt is text
    for (std::size_t i = 0; i < axes_.size() && i < st.size(); ++i) {
        // soft limits moved by PLC code: the motor record's DHLM/DLLM follow, as ECMC's driver
        Axis& a = axes_[i];
        const motion::AxisStatus& s = st[i];
        if (std::isnan(a.soft_fwd)) { // what the record was configured with
            a.soft_fwd = a.params.soft_fwd;
            a.soft_bwd = a.params.soft_bwd;
        }
        if (a.limits_pending) { // the record's own put: wait until the axis has taken it
            if (s.done_tag < a.limits_tag) continue;
            a.limits_pending = false;
        }
        if (!a.derived && s.soft_fwd_enabled && s.soft_bwd_enabled && (s.soft_fwd != a.soft_fwd || s.soft_bwd != a.soft_bwd)) {
            a.soft_fwd = s.soft_fwd;
            a.soft_bwd = s.soft_bwd;
            if (s.soft_bwd <= s.soft_fwd) put_dial_limits(i, s.soft_bwd, s.soft_fwd);
        }
    }
    for (std::size_t i = 0; i < axes_.size() && i < st.size(); ++i) {
        Axis& a = axes_[i];
        if (st[i].error_id == a.last_error) continue;
        a.last_error = st[i].error_id;
        char text[64] = "";
        if (a.last_error) std::snprintf(text, sizeof text, "E: %.24s (0x%" PRIx32 ")", motion::error_id::text(a.last_error), a.last_error);
        set_message(a, text);
    }
    motion::AxisGroup::Result r;
    while (group_->pop_result(r)) {
        if (!r.code) continue;
        std::string who = r.axis < axes_.size() ? axes_[r.axis].cfg.epics.name : std::string("?");
        if (r.kinematics < 0) {
            LOG_INFO(lg, who << ": command " << r.tag << " refused: " << motion::error_id::text(r.code) << " (0x" << std::hex << r.code << ")");
            continue;
        }
        // A kinematics group refused or stopped a virtual move: say which real axis and why.
        const motion::Kinematics& k = group_->kinematics(std::size_t(r.kinematics));
        if (!r.tag) who = k.spec().name;
        std::string real = r.verdict.real >= 0 ? axes_[k.spec().real[std::size_t(r.verdict.real)]].cfg.epics.name : std::string();
        SB what;
        if (r.tag) what << who << ": move refused by kinematics '" << k.spec().name << "': ";
        else what << "kinematics '" << who << "': coupled move stopped: ";
        if (real.empty()) what << "the inverse transform failed";
        else if (motion::error_id::is_warning(r.code) && r.code != motion::error_id::kHardLimitFwd && r.code != motion::error_id::kHardLimitBwd && r.tag)
            what << real << " would go to " << r.verdict.position << ", beyond its soft limit " << r.verdict.limit;
        else
            what << real << ": " << motion::error_id::text(r.code) << " (0x" << std::hex << r.code << std::dec << ")";
        LOG_WARN(lg, what.str());
        // MsgTxt (39 characters) of the refused virtual axis, or of every virtual axis of a
        // stopped group: "W: <real> would pass a limit" / "W: <real> at a limit: stopped"
        char text[64];
        std::snprintf(text, sizeof text, "W: %s %s", real.empty() ? "inverse failed" : real.c_str(),
                      r.tag ? "would pass a limit" : "at a limit: stopped");
        text[pv::kStringSize - 1] = 0;
        for (std::size_t v : r.tag ? std::vector<std::size_t>{r.axis} : k.spec().virt) set_message(axes_[v], text);
    }
}

} // namespace beamctl::ioc
