#include "automation/smart_control.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/convert.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

namespace beamctl::automation {
namespace {

log::Logger lg("smartcontrol");

constexpr const char* kParts[] = {"TwoTheta", "Omega", "Phi", "Kappa"};

pv::DbRecord record(const std::string& type, const std::string& name, const std::vector<std::pair<std::string, std::string>>& fields) {
    return pv::generated_record(type, name, fields);
}

std::string fmt(double v) {
    char b[48];
    std::snprintf(b, sizeof b, "%.3f", v);
    return b;
}

std::string num(double v) {
    char b[48];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

// The owner's writes by record name (pv/publish.hpp); nothing when there is no such record.
void set_record(pv::Database& db, const std::string& name, double v) {
    if (pv::Record* r = db.find(name)) pv::set_value(db, *r, v, false);
}

void set_text(pv::Database& db, const std::string& name, const std::string& text) {
    if (pv::Record* r = db.find(name)) pv::set_string(db, *r, text);
}

} // namespace

SmartControl::SmartControl(const config::SmartControlEntry& cfg, const std::string& prefix, pv::Database& db, std::function<double()> clock)
    : cfg_(cfg), p_(prefix + cfg.name + ":"), db_(db), clock_(std::move(clock)) {
    pv::DbFile f;
    for (int i = 0; i < 4; ++i) {
        const config::SmartControlEntry::Axis* c = nullptr;
        for (const auto& a : cfg_.axes)
            if (a.name == kSmartAxes[i]) c = &a;
        const std::string x = p_ + kParts[i];
        f.records.push_back(record("bi", x + "Exists", {{"ZNAM", "No"}, {"ONAM", "Yes"}, {"VAL", c ? "1" : "0"}, {"PINI", "YES"}}));
        f.records.push_back(record("ao", x + "Offset", {{"PREC", "3"}, {"VAL", num(c ? c->offset : 0)}}));
        f.records.push_back(record("bo", x + "Sign", {{"ZNAM", "Positive"}, {"ONAM", "Negative"}, {"VAL", c && c->sign < 0 ? "1" : "0"}}));
        f.records.push_back(record("ao", x + "LowCut", {{"PREC", "3"}, {"VAL", num(c ? c->low_cut : 0)}}));
        f.records.push_back(record("ao", x + "HighCut", {{"PREC", "3"}, {"VAL", num(c ? c->high_cut : 0)}}));
        for (const char* r : {"Position", "Velocity", "LowLimit", "HighLimit"}) f.records.push_back(record("ai", x + r, {{"PREC", "3"}}));
        if (c) {
            Axis a;
            a.cfg = *c;
            a.part = kParts[i];
            axes_.push_back(std::move(a));
        }
    }
    f.records.push_back(record("bi", p_ + "Shutter", {{"ZNAM", "Closed"}, {"ONAM", "Open"}}));
    f.records.push_back(record("bi", p_ + "Trigger", {{"ZNAM", "Off"}, {"ONAM", "On"}}));
    f.records.push_back(record("mbbi", p_ + "State", {{"ZRST", "Idle"}, {"ONST", "Moving"}, {"TWST", "Scanning"}, {"THST", "Counting"}}));
    for (const char* r : {"Clients", "Commands", "Errors"}) f.records.push_back(record("longin", p_ + r, {}));
    f.records.push_back(record("stringin", p_ + "LastCommand", {}));
    f.records.push_back(record("stringin", p_ + "LastReply", {}));
    db_.load(f);
}

void SmartControl::start() {
    auto need = [&](const std::string& pv, const std::string& where, const std::string& what, pv::Address& out) {
        if (!db_.resolve(pv, out))
            throw Error(SB() << where << ": smart_control: " << what << " '" << pv << "' is not a PV of this IOC");
    };
    for (Axis& a : axes_) {
        pv::Record* r = db_.find(a.cfg.motor);
        if (!r || std::string_view(r->type().name()) != "motor")
            throw Error(SB() << a.cfg.where << ": smart_control: " << a.cfg.name << ": '" << a.cfg.motor
                             << "' is not a motor record of this IOC");
        need(a.cfg.motor + ".VAL", a.cfg.where, "motor", a.val);
        need(a.cfg.motor + ".RBV", a.cfg.where, "motor", a.rbv);
        need(a.cfg.motor + ".VELO", a.cfg.where, "motor", a.velo);
        need(a.cfg.motor + ".HLM", a.cfg.where, "motor", a.hlm);
        need(a.cfg.motor + ".LLM", a.cfg.where, "motor", a.llm);
        need(a.cfg.motor + ".STOP", a.cfg.where, "motor", a.stop);
        need(a.cfg.motor + ".DMOV", a.cfg.where, "motor", a.dmov);
        need(a.cfg.motor + ".VMAX", a.cfg.where, "motor", a.vmax);
        need(a.cfg.motor + ".CNEN", a.cfg.where, "motor", a.cnen);
        need(a.cfg.motor + ".LVIO", a.cfg.where, "motor", a.lvio);
        need(a.cfg.motor + ".RDBD", a.cfg.where, "motor", a.rdbd);
        need(a.cfg.motor + ".MRES", a.cfg.where, "motor", a.mres);
    }
    if ((has_shutter_ = !cfg_.shutter.empty())) need(cfg_.shutter, cfg_.where, "shutter", shutter_);
    if ((has_trigger_ = !cfg_.trigger.empty())) need(cfg_.trigger, cfg_.where, "trigger", trigger_);
    if ((has_scaler_ = !cfg_.scaler.empty())) need(cfg_.scaler, cfg_.where, "scaler", scaler_);
    started_ = true;
    publish_table();
}

double SmartControl::get(const pv::Address& a) const {
    double v = 0;
    db_.get(a, pv::Prim::Double, &v, 1);
    return v;
}

bool SmartControl::put(const pv::Address& a, double v, pv::PutCallback cb) {
    if (!cb) return db_.put(a, pv::Prim::Double, &v, 1) == pv::PutStatus::Ok;
    // A refused put calls back and returns the refusal; the callers act on the refusal, so the
    // callback answers only a put that was taken (at once or later).
    struct Pending {
        bool in_put = true, early = false;
        pv::PutStatus status = pv::PutStatus::Ok;
        pv::PutCallback cb;
    };
    auto p = std::make_shared<Pending>();
    p->cb = std::move(cb);
    const pv::PutStatus st = db_.put(a, pv::Prim::Double, &v, 1, [p](pv::PutStatus s) {
        if (p->in_put) {
            p->early = true;
            p->status = s;
        } else {
            p->cb(s);
        }
    });
    p->in_put = false;
    if (st != pv::PutStatus::Ok) return false;
    if (p->early) p->cb(p->status);
    return true;
}

double SmartControl::pv_value(const std::string& rec) const {
    pv::Address a;
    return db_.resolve(rec, a) ? get(a) : 0;
}

SmartAxisSetup SmartControl::setup(const Axis& a) const {
    const std::string x = p_ + a.part;
    SmartAxisSetup s;
    s.offset = pv_value(x + "Offset");
    s.sign = pv_value(x + "Sign") != 0 ? -1 : 1;
    s.low_cut = pv_value(x + "LowCut");
    s.high_cut = pv_value(x + "HighCut");
    return s;
}

int SmartControl::find_axis(const std::string& name) const {
    for (std::size_t i = 0; i < axes_.size(); ++i)
        if (axes_[i].cfg.name == name) return int(i);
    return -1;
}

void SmartControl::set_output(const pv::Address* a, double v) {
    if (a) put(*a, v);
}

void SmartControl::fail(const Reply& reply, const std::string& keyword, const std::string& why) {
    ++errors_;
    const std::string line = keyword.empty() ? "ERR " + why : keyword + " ERR " + why;
    LOG_WARN(lg, p_ << " " << line);
    set_record(db_, p_ + "Errors", double(std::min<uint64_t>(errors_, 0x7FFFFFFF)));
    set_text(db_, p_ + "LastReply", line);
    reply(line);
}

std::string SmartControl::positions(const std::vector<int>& axes) const {
    std::string s;
    for (int i : axes) s += " " + axes_[std::size_t(i)].cfg.name + "=" + fmt(motor_to_smart(setup(axes_[std::size_t(i)]), get(axes_[std::size_t(i)].rbv)));
    return s;
}

// The target's place in the cut window and within the motor's soft limits (HLM/LLM in user units).
bool SmartControl::check_motor_target(const Axis& a, double motor, std::string& why) const {
    const double hlm = get(a.hlm), llm = get(a.llm);
    if (hlm > llm && (motor > hlm || motor < llm)) {
        why = a.cfg.name + ": " + fmt(motor) + " (motor) is beyond the motor's soft limits " + fmt(llm) + " .. " + fmt(hlm);
        return false;
    }
    return true;
}

void SmartControl::command(std::string_view line, const Reply& reply) {
    ++commands_;
    set_record(db_, p_ + "Commands", double(std::min<uint64_t>(commands_, 0x7FFFFFFF)));
    set_text(db_, p_ + "LastCommand", std::string(line.substr(0, 39)));
    SmartCommand c;
    std::string why;
    if (!parse_smart_command(line, c, why)) return fail(reply, c.keyword, why); // no keyword (not ASCII): "ERR <why>"
    const std::string& k = c.keyword;
    auto ok = [&](const std::string& rest) {
        const std::string l = k + " OK" + rest;
        set_text(db_, p_ + "LastReply", l);
        reply(l);
    };
    if (!started_) return fail(reply, k, "not started");
    int axis = -1;
    if (!c.axis.empty() && (axis = find_axis(c.axis)) < 0) return fail(reply, k, c.axis + " is not configured (smart_control.axes)");
    using K = SmartCommand::Kind;
    switch (c.kind) {
    case K::Id: {
        std::string names;
        for (const Axis& a : axes_) names += " " + a.cfg.name;
        return ok(" beamctl smartControl" + names);
    }
    case K::Help: return ok(" ID HELP STATUS POS LIMITS VELO MOVE STOP SHUTTER COUNT SCAN (docs/goniometer.md)");
    case K::Status: {
        static const char* states[] = {"IDLE", "MOVING", "COUNTING", "SCANNING", "SCANNING"};
        std::string s = std::string(" ") + states[op_.kind];
        if (has_shutter_) s += get(shutter_) != 0 ? " SHUTTER=OPEN" : " SHUTTER=CLOSED";
        for (const Axis& a : axes_) s += " " + a.cfg.name + (get(a.dmov) != 0 ? "=DONE" : "=MOVING");
        return ok(s);
    }
    case K::Pos: {
        std::vector<int> which;
        for (std::size_t i = 0; i < axes_.size(); ++i)
            if (axis < 0 || int(i) == axis) which.push_back(int(i));
        return ok(positions(which));
    }
    case K::Limits: {
        std::string s;
        for (std::size_t i = 0; i < axes_.size(); ++i) {
            if (axis >= 0 && int(i) != axis) continue;
            const Axis& a = axes_[i];
            const SmartAxisSetup su = setup(a);
            double lo = get(a.llm), hi = get(a.hlm);
            if (su.high_cut > su.low_cut) lo = std::max(lo, su.low_cut), hi = std::min(hi, su.high_cut);
            double l = (lo - su.offset) * su.sign, h = (hi - su.offset) * su.sign; // not wrapped: the motor's range
            if (l > h) std::swap(l, h);
            s += " " + a.cfg.name + "=" + fmt(l) + ".." + fmt(h);
        }
        return ok(s);
    }
    case K::Velo: {
        const Axis& a = axes_[std::size_t(axis)];
        if (c.has_value) {
            if (op_.kind == Op::ScanExposing && op_.axis == axis) return fail(reply, k, "the scan sets " + a.cfg.name + "'s velocity");
            const double vmax = get(a.vmax);
            if (vmax > 0 && c.value > vmax) return fail(reply, k, a.cfg.name + ": " + fmt(c.value) + " is above the motor's VMAX " + fmt(vmax));
            if (!put(a.velo, c.value)) return fail(reply, k, a.cfg.name + ": the motor refused the velocity");
        }
        return ok(" " + a.cfg.name + "=" + fmt(get(a.velo)));
    }
    case K::Shutter: {
        if (!has_shutter_) return fail(reply, k, "no shutter (smart_control.shutter)");
        if (c.has_value) {
            if (op_.kind == Op::ScanExposing) return fail(reply, k, "the scan holds the shutter");
            if (!put(shutter_, c.open ? 1 : 0)) return fail(reply, k, "the shutter refused");
        }
        return ok(get(shutter_) != 0 ? " OPEN" : " CLOSED");
    }
    case K::Stop: {
        for (const Axis& a : axes_) put(a.stop, 1);
        if (op_.kind == Op::Count) {
            Reply r = op_.reply;
            const std::string kw = op_.keyword;
            op_ = Op{};
            fail(r, kw, "stopped");
        } else if (op_.kind == Op::ScanToStart || op_.kind == Op::ScanExposing) {
            end_scan(false, "stopped");
        } // a MOVE answers when its motors report the stop (ERR: ended short)
        return ok("");
    }
    case K::Move:
    case K::Count:
    case K::Scan: break;
    }
    if (op_.kind != Op::None) return fail(reply, k, "busy: " + op_.keyword + " is under way (STOP ends it)");
    if (c.kind == K::Count) {
        if (!has_scaler_) return fail(reply, k, "no scaler (smart_control.scaler)");
        op_ = Op{};
        op_.kind = Op::Count;
        op_.reply = reply;
        op_.keyword = k;
        op_.id = next_id_++;
        op_.t_start = op_.t_last = clock_();
        op_.t_end = op_.t_start + c.value;
        return;
    }
    // MOVE and SCAN: every target checked before anything moves
    Op next;
    std::vector<std::pair<int, double>> motor_targets;
    if (c.kind == K::Move) {
        for (const auto& [name, pos] : c.targets) {
            const int i = find_axis(name);
            if (i < 0) return fail(reply, k, name + " is not configured (smart_control.axes)");
            double m = 0;
            if (!smart_to_motor(setup(axes_[std::size_t(i)]), pos, m, why)) return fail(reply, k, name + " " + fmt(pos) + " " + why);
            if (!check_motor_target(axes_[std::size_t(i)], m, why)) return fail(reply, k, why);
            motor_targets.emplace_back(i, m);
            next.targets.emplace_back(i, pos);
        }
    } else {
        const Axis& a = axes_[std::size_t(axis)];
        const SmartAxisSetup su = setup(a);
        double m0 = 0;
        if (!smart_to_motor(su, c.start, m0, why)) return fail(reply, k, a.cfg.name + " " + fmt(c.start) + " " + why);
        const double m1 = m0 + su.sign * (c.end - c.start); // the same turn: no wrap within a scan
        if (su.high_cut > su.low_cut && (m1 < su.low_cut || m1 > su.high_cut))
            return fail(reply, k, a.cfg.name + ": the scan to " + fmt(c.end) + " leaves the cut window");
        if (!check_motor_target(a, m0, why) || !check_motor_target(a, m1, why)) return fail(reply, k, why);
        const double velo = std::fabs(m1 - m0) / c.seconds, vmax = get(a.vmax);
        if (vmax > 0 && velo > vmax)
            return fail(reply, k, a.cfg.name + ": " + fmt(velo) + "/s for the exposure is above the motor's VMAX " + fmt(vmax));
        motor_targets.emplace_back(axis, m0);
        next.axis = axis;
        next.motor_end = m1;
        next.end = c.end;
        next.saved_velo = velo; // the exposure's, until the start is reached
    }
    next.kind = c.kind == K::Move ? Op::Move : Op::ScanToStart;
    next.reply = reply;
    next.keyword = k;
    next.id = next_id_++;
    op_ = std::move(next);
    start_moves(motor_targets, op_.id);
}

void SmartControl::start_moves(const std::vector<std::pair<int, double>>& motor_targets, uint64_t id) {
    op_.outstanding = int(motor_targets.size()) + 1; // +1: no completion before every move is sent
    op_.failures.clear();
    op_.motor_target.assign(axes_.size(), NAN);
    for (const auto& [i, m] : motor_targets) op_.motor_target[std::size_t(i)] = m;
    for (const auto& [i, m] : motor_targets) {
        const Axis& a = axes_[std::size_t(i)];
        const int ax = i;
        if (!put(a.val, m, [this, id, ax](pv::PutStatus s) { on_move_done(id, ax, s); })) {
            op_.failures.push_back(a.cfg.name + " refused by the motor");
            --op_.outstanding;
        }
    }
    on_move_done(id, -1, pv::PutStatus::Ok); // the +1
}

void SmartControl::on_move_done(uint64_t id, int axis, pv::PutStatus s) {
    if (op_.id != id || (op_.kind != Op::Move && op_.kind != Op::ScanToStart && op_.kind != Op::ScanExposing)) return; // stale
    // success is the motor's word and the position: a move stopped on the way completes its
    // put-callback normally (the motor record takes the stop position as its target)
    const Axis* ax = axis >= 0 ? &axes_[std::size_t(axis)] : nullptr;
    const double target = ax && std::size_t(axis) < op_.motor_target.size() ? op_.motor_target[std::size_t(axis)] : NAN;
    if (ax && s == pv::PutStatus::Ok && std::isfinite(target) &&
        std::fabs(get(ax->rbv) - target) > std::max(get(ax->rdbd), std::fabs(get(ax->mres))) + 1e-9) {
        const SmartAxisSetup su = setup(*ax);
        op_.failures.push_back(ax->cfg.name + " ended short at " + fmt(motor_to_smart(su, get(ax->rbv))) + " (target " +
                               fmt(motor_to_smart(su, target)) + ")");
    }
    if (axis >= 0 && s != pv::PutStatus::Ok) {
        const Axis& a = axes_[std::size_t(axis)];
        std::string f = a.cfg.name + " ended at " + fmt(motor_to_smart(setup(a), get(a.rbv)));
        if (get(a.cnen) == 0)
            f += " (the motor's drive is disabled: CNEN 0)";
        else if (get(a.lvio) != 0)
            f += " (refused by the motor's soft limits: LVIO)";
        else
            f += " (the motor reports failure: stopped, limit, fault or ended short)";
        op_.failures.push_back(f);
    }
    if (--op_.outstanding > 0) return;
    std::string why;
    for (const std::string& f : op_.failures) why += (why.empty() ? "" : "; ") + f;
    if (op_.kind == Op::Move) {
        Reply r = op_.reply;
        const std::string kw = op_.keyword;
        std::vector<int> which;
        for (const auto& t : op_.targets) which.push_back(t.first);
        op_ = Op{};
        if (!why.empty()) return fail(r, kw, why);
        const std::string l = kw + " OK" + positions(which);
        set_text(db_, p_ + "LastReply", l);
        r(l);
    } else if (op_.kind == Op::ScanToStart) {
        if (!why.empty()) return end_scan(false, why);
        begin_exposure();
    } else {
        end_scan(why.empty(), why);
    }
}

// At the scan's start: the exposure's velocity, the shutter open, the trigger, counting, the move.
void SmartControl::begin_exposure() {
    Axis& a = axes_[std::size_t(op_.axis)];
    const double velo = op_.saved_velo;
    op_.saved_velo = get(a.velo);
    op_.kind = Op::ScanExposing;
    if (!put(a.velo, velo)) return end_scan(false, a.cfg.name + ": the motor refused the exposure's velocity " + fmt(velo));
    if (has_shutter_) put(shutter_, 1);
    if (has_trigger_) put(trigger_, 1);
    op_.counts = 0;
    op_.t_start = op_.t_last = clock_();
    const uint64_t id = op_.id;
    const int ax = op_.axis;
    op_.outstanding = 1;
    op_.failures.clear();
    op_.motor_target.assign(axes_.size(), NAN);
    op_.motor_target[std::size_t(op_.axis)] = op_.motor_end;
    if (!put(a.val, op_.motor_end, [this, id, ax](pv::PutStatus s) { on_move_done(id, ax, s); }))
        end_scan(false, a.cfg.name + " refused the move to the scan's end");
}

void SmartControl::end_scan(bool ok, const std::string& why) {
    const bool exposing = op_.kind == Op::ScanExposing;
    if (has_shutter_) put(shutter_, 0);
    if (has_trigger_) put(trigger_, 0);
    if (exposing && op_.axis >= 0) put(axes_[std::size_t(op_.axis)].velo, op_.saved_velo);
    Reply r = op_.reply;
    const std::string kw = op_.keyword;
    const double counts = op_.counts, seconds = clock_() - op_.t_start;
    const int axis = op_.axis;
    op_ = Op{};
    if (!ok) return fail(r, kw, why);
    std::string l = kw + " OK" + positions({axis}) + " SECONDS=" + fmt(seconds);
    if (has_scaler_) l += " COUNTS=" + fmt(counts);
    set_text(db_, p_ + "LastReply", l);
    r(l);
}

void SmartControl::poll() {
    if (!started_) return;
    const double now = clock_();
    if ((op_.kind == Op::Count || op_.kind == Op::ScanExposing) && has_scaler_) {
        const double until = op_.kind == Op::Count ? std::min(now, op_.t_end) : now;
        if (until > op_.t_last) op_.counts += get(scaler_) * (until - op_.t_last), op_.t_last = until;
    }
    if (op_.kind == Op::Count && now >= op_.t_end) {
        Reply r = op_.reply;
        const std::string l = op_.keyword + " OK " + fmt(op_.counts);
        op_ = Op{};
        set_text(db_, p_ + "LastReply", l);
        r(l);
    }
    if (now - last_table_ >= 0.1) publish_table();
}

void SmartControl::set_clients(int n) { set_record(db_, p_ + "Clients", n); }

void SmartControl::count_error(const std::string& why) {
    ++errors_;
    LOG_WARN(lg, p_ << " " << why);
    set_record(db_, p_ + "Errors", double(std::min<uint64_t>(errors_, 0x7FFFFFFF)));
}

// The client's view of each axis, as smartControl's screen shows it, and the state.
void SmartControl::publish_table() {
    last_table_ = clock_();
    for (const Axis& a : axes_) {
        const SmartAxisSetup su = setup(a);
        const std::string x = p_ + a.part;
        set_record(db_, x + "Position", motor_to_smart(su, get(a.rbv)));
        set_record(db_, x + "Velocity", get(a.velo));
        double l = (get(a.llm) - su.offset) * su.sign, h = (get(a.hlm) - su.offset) * su.sign;
        if (l > h) std::swap(l, h);
        set_record(db_, x + "LowLimit", l);
        set_record(db_, x + "HighLimit", h);
    }
    if (has_shutter_) set_record(db_, p_ + "Shutter", get(shutter_) != 0);
    if (has_trigger_) set_record(db_, p_ + "Trigger", get(trigger_) != 0);
    static const int state[] = {0, 1, 3, 2, 2};
    set_record(db_, p_ + "State", state[op_.kind]);
}

} // namespace beamctl::automation
