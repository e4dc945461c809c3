#include "ioc/axes.hpp"

#include "motion/axis_variables.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
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
} // namespace

IocAxes::IocAxes(const std::vector<config::AxisEntry>& entries, const std::string& prefix,
                 registry::Registry& signals, pv::Database& db)
    : db_(db), prefix_(prefix) {
    std::set<int> ids;
    std::set<std::string> names;
    for (const auto& e : entries) {
        Axis a;
        a.cfg = motion::load_axis_config(e.file, e.macros);
        for (const auto& enc : e.encoders) motion::add_encoder(a.cfg, motion::load_encoder_config(enc.file, enc.macros));
        for (const auto& w : a.cfg.warnings) LOG_WARN(lg, w);
        // ECMC numbering: an axis without an id is the previous one + 1
        int id = a.cfg.axis.id.value_or(axes_.empty() ? 1 : axes_.back().params.id + 1);
        a.cfg.axis.id = id;
        if (!ids.insert(id).second) throw Error(SB() << e.where << ": axis id " << id << " is used twice (" << e.file << ")");
        if (!names.insert(a.cfg.epics.name).second)
            throw Error(SB() << e.where << ": axis name '" << a.cfg.epics.name << "' is used twice (" << e.file << ")");
        a.params = motion::make_axis_params(a.cfg);
        a.params.id = id;
        a.pv = prefix + a.cfg.epics.name;
        std::string owner = SB() << "axis " << id << " (" << a.cfg.epics.name << ")";
        for (const auto& r : motion::axis_signal_refs(a.cfg)) {
            if (r.slave < 0) throw Error(SB() << at(r.where) << ": '" << r.text << "': the simulation slave (s-1) is not supported");
            const registry::Signal* sig = signals.find(signal_name(r));
            if (!sig)
                throw Error(SB() << at(r.where) << ": no signal '" << signal_name(r) << "' on the configured buses (from '" << r.text << "')");
            std::string why;
            if (sig->direction == registry::Direction::Output && !signals.claim(sig->name, owner, why))
                throw Error(SB() << at(r.where) << ": " << owner << " cannot drive it: " << why);
        }
        // The axis as PLC code and records see it: ax<n>.enc.actpos, ax<n>.traj.extsetpos, ...
        for (const motion::AxisVariableInfo& v : motion::axis_variables()) {
            registry::Signal s;
            s.name = SB() << "ax" << id << "." << v.name;
            s.type = "LREAL";
            s.direction = v.writable ? registry::Direction::Variable : registry::Direction::Input;
            s.owner_kind = registry::OwnerKind::Axis;
            s.owner = owner;
            std::string_view n = v.name;
            if (n == "enc.actpos") s.pv = a.pv + "-PosAct";
            else if (n == "enc.actvel") s.pv = a.pv + "-VelAct";
            else if (n == "traj.setpos") s.pv = a.pv + "-PosSet";
            else if (n == "traj.targetpos") s.pv = a.pv + "-TgtPosCmd";
            else if (n == "traj.targetvel") s.pv = a.pv + "-TgtVelCmd";
            else if (n == "traj.busy") s.pv = a.pv + "-Busy";
            else if (n == "drv.enabled") s.pv = a.pv + "-EnaAct";
            else if (n == "mon.attarget") s.pv = a.pv + "-AtTarget";
            else if (n == "mon.lowlim") s.pv = a.pv + "-LimBwd";
            else if (n == "mon.highlim") s.pv = a.pv + "-LimFwd";
            else if (n == "error") s.pv = a.pv + "-ErrId";
            signals.declare(std::move(s));
        }
        axes_.push_back(std::move(a));
    }
    for (std::size_t i = 0; i < axes_.size(); ++i) make_pvs(axes_[i], i);
}

std::string IocAxes::owner(std::size_t i) const {
    return SB() << "axis " << axes_.at(i).params.id << " (" << axes_.at(i).cfg.epics.name << ")";
}

int IocAxes::find(const std::string& name) const {
    for (std::size_t i = 0; i < axes_.size(); ++i)
        if (axes_[i].cfg.epics.name == name) return int(i);
    return -1;
}

void IocAxes::make_pvs(Axis& a, std::size_t index) {
    pv::DbFile f;
    const std::string& p = a.pv;
    std::string prec = std::to_string(a.cfg.epics.precision), egu = a.cfg.epics.unit;
    auto ai = [&](const char* s, const char* desc, const std::string& unit) {
        f.records.push_back(record("ai", p + s, {{"DESC", desc}, {"PREC", prec}, {"EGU", unit}}));
    };
    auto li = [&](const char* s, const char* desc) { f.records.push_back(record("longin", p + s, {{"DESC", desc}})); };
    auto bi = [&](const char* s, const char* desc, const char* z, const char* o) {
        f.records.push_back(record("bi", p + s, {{"DESC", desc}, {"ZNAM", z}, {"ONAM", o}}));
    };
    auto bo = [&](const char* s, const char* desc, const char* z, const char* o) {
        f.records.push_back(record("bo", p + s, {{"DESC", desc}, {"ZNAM", z}, {"ONAM", o}}));
    };
    ai("-PosAct", "Actual position", egu);
    ai("-VelAct", "Actual velocity", egu + "/s");
    ai("-PosSet", "Setpoint position", egu);
    ai("-PosErr", "Following error", egu);
    li("-Stat", "Status word");
    f.records.push_back(record("longin", p + "-ErrId", {{"DESC", "Error id"}, {"HIHI", "1"}, {"HHSV", "MAJOR"}}));
    f.records.push_back(record("longin", p + "-WrnId", {{"DESC", "Warning id"}, {"HIHI", "1"}, {"HHSV", "MINOR"}}));
    li("-SeqState", "Homing sequence state");
    li("-LastIlock", "Last interlock");
    bi("-EnaAct", "Enabled", "Disabled", "Enabled");
    bi("-Busy", "Busy", "Idle", "Busy");
    bi("-AtTarget", "At target", "Not at target", "At target");
    bi("-Moving", "Moving", "Stopped", "Moving");
    f.records.push_back(record("bi", p + "-LimFwd", {{"DESC", "Forward limit switch"}, {"ZNAM", "Limit activated"}, {"ONAM", "Limit OK"}, {"ZSV", "MINOR"}}));
    f.records.push_back(record("bi", p + "-LimBwd", {{"DESC", "Backward limit switch"}, {"ZNAM", "Limit activated"}, {"ONAM", "Limit OK"}, {"ZSV", "MINOR"}}));
    bi("-HomeSwitch", "Home switch", "Off", "On");
    bi("-Homed", "Homed", "Not homed", "Homed");
    f.records.push_back(record("bi", p + "-Err", {{"DESC", "Error"}, {"ZNAM", "No error"}, {"ONAM", "Error"}, {"OSV", "MAJOR"}}));
    bo("-EnaCmd", "Enable", "Disable", "Enable");
    bo("-ExeCmd", "Execute MtnCmd (rising edge)", "Stop", "Execute");
    bo("-StpCmd", "Stop", "0", "Stop");
    bo("-RstCmd", "Reset errors", "0", "Reset");
    f.records.push_back(record("ao", p + "-TgtPosCmd", {{"DESC", "Target position"}, {"PREC", prec}, {"EGU", egu}}));
    f.records.push_back(record("ao", p + "-TgtVelCmd", {{"DESC", "Target velocity"}, {"PREC", prec}, {"EGU", egu + "/s"},
                                                          {"VAL", std::to_string(a.params.trajectory.velocity)}}));
    f.records.push_back(record("longout", p + "-MtnCmd", {{"DESC", "1 VEL 2 REL 3 ABS 10 HOME"}, {"VAL", "3"}}));
    f.records.push_back(record("longout", p + "-MtnCmdData", {{"DESC", "Homing sequence; 14 = configured"}, {"VAL", "14"}}));
    f.records.push_back(record("stringin", p + "-MsgTxt", {{"DESC", "Error message"}}));
    for (std::size_t k = 0; k < a.cfg.encoders.size() && k < motion::AxisStatus::kMaxEncoders; ++k) {
        char n[24];
        std::snprintf(n, sizeof n, "-Enc%02zu-PosAct", k + 1);
        f.records.push_back(record("ai", p + n, {{"DESC", (SB() << "Encoder " << k + 1 << " position").str()}, {"PREC", prec}, {"EGU", egu}}));
    }
    if (a.cfg.epics.motor_record.enable) make_motor_record(a, f);
    db_.load(f);
    for (std::size_t k = 0; k < a.cfg.encoders.size() && k < motion::AxisStatus::kMaxEncoders; ++k) {
        char n[24];
        std::snprintf(n, sizeof n, "-Enc%02zu-PosAct", k + 1);
        a.enc.push_back(db_.find(p + n));
        a.enc.back()->val_read_only = true;
    }
    if (a.cfg.epics.motor_record.enable)
        if (pv::MotorRecord* m = pv::MotorRecord::from(db_.find(p))) m->set_driver(std::make_shared<AxisMotorDriver>(*this, index));
    auto rec = [&](const char* s) { return db_.find(p + s); };
    a.pos_act = rec("-PosAct");
    a.vel_act = rec("-VelAct");
    a.pos_set = rec("-PosSet");
    a.pos_err = rec("-PosErr");
    a.stat = rec("-Stat");
    a.err_id = rec("-ErrId");
    a.wrn_id = rec("-WrnId");
    a.seq_state = rec("-SeqState");
    a.last_ilock = rec("-LastIlock");
    a.ena_act = rec("-EnaAct");
    a.busy = rec("-Busy");
    a.at_target = rec("-AtTarget");
    a.moving = rec("-Moving");
    a.lim_fwd = rec("-LimFwd");
    a.lim_bwd = rec("-LimBwd");
    a.home_switch = rec("-HomeSwitch");
    a.homed = rec("-Homed");
    a.err = rec("-Err");
    a.ena_cmd = rec("-EnaCmd");
    a.exe_cmd = rec("-ExeCmd");
    a.tgt_pos = rec("-TgtPosCmd");
    a.tgt_vel = rec("-TgtVelCmd");
    a.mtn_cmd = rec("-MtnCmd");
    a.mtn_data = rec("-MtnCmdData");
    a.msg = rec("-MsgTxt");
    for (pv::Record* r : {a.pos_act, a.vel_act, a.pos_set, a.pos_err, a.stat, a.err_id, a.wrn_id, a.seq_state, a.last_ilock,
                          a.ena_act, a.busy, a.at_target, a.moving, a.lim_fwd, a.lim_bwd, a.home_switch, a.homed, a.err, a.msg})
        r->val_read_only = true;
    hook(index);
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

// PV writes become axis commands (ECMC control-word semantics).
void IocAxes::hook(std::size_t i) {
    Axis& a = axes_[i];
    auto on_val = [](auto fn) {
        return [fn](pv::Record& r, const pv::FieldDesc& f) {
            if (std::string_view(f.name) != "VAL") return pv::PutStatus::Ok;
            return fn(get_value(r)) ? pv::PutStatus::Ok : pv::PutStatus::Failed;
        };
    };
    a.ena_cmd->put_hook = on_val([this, i](double v) {
        motion::AxisCommand c{motion::CommandType::Power};
        c.on = v != 0;
        return send(i, c) != 0;
    });
    a.exe_cmd->put_hook = [this, i](pv::Record& r, const pv::FieldDesc& f) {
        if (std::string_view(f.name) != "VAL") return pv::PutStatus::Ok;
        Axis& ax = axes_[i];
        double v = get_value(r);
        motion::AxisCommand c;
        if (v == 0) { // falling edge: stop with the normal deceleration
            c.type = motion::CommandType::Halt;
        } else {
            c.type = command_of(int(get_value(*ax.mtn_cmd)));
            if (c.type == motion::CommandType::None) return pv::PutStatus::Failed;
            c.position = get_value(*ax.tgt_pos);
            c.velocity = get_value(*ax.tgt_vel);
            if (c.type == motion::CommandType::MoveVelocity && c.position < 0) c.velocity = -std::fabs(c.velocity);
            c.homing_sequence = int(get_value(*ax.mtn_data));
        }
        return send(i, c) ? pv::PutStatus::Ok : pv::PutStatus::Failed;
    };
    db_.find(a.pv + "-StpCmd")->put_hook = on_val([this, i](double v) {
        if (v == 0) return true;
        motion::AxisCommand c{motion::CommandType::Halt};
        return send(i, c) != 0;
    });
    db_.find(a.pv + "-RstCmd")->put_hook = on_val([this, i](double v) {
        if (v == 0) return true;
        motion::AxisCommand c{motion::CommandType::Reset};
        return send(i, c) != 0;
    });
}

void IocAxes::bind(const Resolver& resolve, rt::Engine& engine) {
    if (axes_.empty()) return;
    std::vector<std::unique_ptr<motion::Axis>> rt_axes;
    for (auto& a : axes_) rt_axes.push_back(std::make_unique<motion::Axis>(a.params, motion::bind_axis_io(a.cfg, resolve)));
    group_ = std::make_unique<motion::AxisGroup>(std::move(rt_axes));
    engine.add_stage(rt::StageOrder::Axes, *group_);
}

void IocAxes::publish_one(Axis& a, const motion::AxisStatus& s) {
    const double values[] = {s.act_pos, s.act_vel, s.set_pos, s.pos_err, double(s.stat_word()), double(s.error_id),
                             double(s.warning_id), double(s.sequence_state), double(uint8_t(s.last_interlock)),
                             double(s.enabled), double(s.busy), double(s.at_target), double(s.moving),
                             double(!s.limit_fwd), double(!s.limit_bwd), double(s.home_sensor), double(s.homed),
                             double(s.error_id != 0)};
    pv::Record* recs[] = {a.pos_act, a.vel_act, a.pos_set, a.pos_err, a.stat, a.err_id, a.wrn_id, a.seq_state,
                          a.last_ilock, a.ena_act, a.busy, a.at_target, a.moving, a.lim_fwd, a.lim_bwd,
                          a.home_switch, a.homed, a.err};
    constexpr std::size_t n = sizeof recs / sizeof recs[0];
    if (a.last.size() != n) a.last.assign(n, NAN);
    for (std::size_t k = 0; k < n; ++k) {
        if (values[k] == a.last[k] && !recs[k]->udf) continue;
        a.last[k] = values[k];
        set_value(db_, *recs[k], values[k], false);
    }
    if (a.enc_last.size() != a.enc.size()) a.enc_last.assign(a.enc.size(), NAN);
    for (std::size_t k = 0; k < a.enc.size() && int(k) < s.enc_count; ++k) {
        double v = s.enc_pos[k];
        if (v == a.enc_last[k] && !a.enc[k]->udf) continue;
        a.enc_last[k] = v;
        set_value(db_, *a.enc[k], v, false);
    }
    // EnaCmd follows changes the axis makes itself (an error that disables clears it); a
    // processed record does not call its put hook, so this sends no command.
    if (s.enable_cmd != a.last_enable_cmd) {
        a.last_enable_cmd = s.enable_cmd;
        if (get_value(*a.ena_cmd) != double(s.enable_cmd)) set_value(db_, *a.ena_cmd, double(s.enable_cmd), false);
    }
    if (s.error_id != a.last_error) {
        a.last_error = s.error_id;
        char text[64] = "";
        if (s.error_id) std::snprintf(text, sizeof text, "E: %.24s (0x%" PRIx32 ")", motion::error_id::text(s.error_id), s.error_id);
        text[pv::kStringSize - 1] = 0; // a DBR_STRING holds 39 characters
        const pv::FieldDesc* f = a.msg->type().find("VAL");
        pv::Elements e = a.msg->elements(*f);
        pv::put_element(*a.msg, *f, e, 0, pv::Prim::String, text);
        a.msg->udf = 0;
        db_.process(*a.msg);
    }
}

void IocAxes::set_derived_limits(std::size_t i, double lo, double hi) {
    pv::Record* m = db_.find(axes_.at(i).pv);
    if (!pv::MotorRecord::from(m)) return;
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

void IocAxes::publish() {
    if (!group_) return;
    const auto& st = group_->snapshot();
    for (std::size_t i = 0; i < axes_.size() && i < st.size(); ++i) publish_one(axes_[i], st[i]);
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
        for (std::size_t v : r.tag ? std::vector<std::size_t>{r.axis} : k.spec().virt) {
            Axis& a = axes_[v];
            const pv::FieldDesc* f = a.msg->type().find("VAL");
            pv::Elements e = a.msg->elements(*f);
            pv::put_element(*a.msg, *f, e, 0, pv::Prim::String, text);
            a.msg->udf = 0;
            db_.process(*a.msg);
        }
    }
}

} // namespace beamctl::ioc
