#include "ioc/pvt.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ioc/pv_util.hpp"
#include "motion/axis.hpp"
#include "motion/axis_group.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace beamctl::ioc {

namespace {
log::Logger lg("pvt");

using Ctl = motion::PvtController;

std::string hex(uint32_t id) {
    char b[16];
    std::snprintf(b, sizeof b, "0x%x", id);
    return b;
}
} // namespace

IocPvt::IocPvt(const config::IocConfig& cfg, IocAxes& axes, pv::Database& db) : cfg_(cfg), iaxes_(axes), db_(db) {
    uint32_t npoints = 0, nreadback = 0;
    for (std::size_t i = 0; i < axes.size(); ++i) {
        const auto& mr = axes.config(i).epics.motor_record;
        if (!mr.pvt) continue;
        AxisPvt& a = axes_.emplace_back();
        a.index = i;
        a.name = axes.name(i);
        a.npoints = uint32_t(std::clamp<int64_t>(mr.pvt->npoints, 2, 1000000));
        a.nreadback = uint32_t(std::clamp<int64_t>(mr.pvt->nreadback, 1, 1000000));
        npoints = std::max(npoints, a.npoints);
        nreadback = std::max(nreadback, a.nreadback);
    }
    if (axes_.empty()) return;
    if (axes_.size() > Ctl::kMaxAxes)
        throw Error(SB() << axes_.size() << " axes have epics.motorRecord.pvt: at most " << Ctl::kMaxAxes << " take part in profiles");
    max_size_ = std::max(npoints, nreadback); // ecmccfg pvtControllerConfig.cmd: NPULSES = NPOINTS
    const std::string p = cfg.prefix + "PVT-";
    const std::string n = std::to_string(npoints), mx = std::to_string(max_size_);
    auto mbbi = [](const std::string& name, std::vector<std::pair<std::string, std::string>> states) {
        static const char* st[] = {"ZRST", "ONST", "TWST", "THST", "FRST"};
        static const char* sv[] = {"ZRSV", "ONSV", "TWSV", "THSV", "FRSV"};
        std::vector<std::pair<std::string, std::string>> f;
        for (std::size_t k = 0; k < states.size(); ++k) {
            f.emplace_back(st[k], states[k].first);
            f.emplace_back(sv[k], states[k].second);
        }
        return record("mbbi", name, f);
    };
    auto text = [](const std::string& name) { return record("waveform", name, {{"FTVL", "CHAR"}, {"NELM", "256"}}); };
    pv::DbFile f;
    f.records = {
        record("longout", p + "NumAxes", {{"VAL", std::to_string(axes_.size())}}),
        record("longout", p + "NumPoints", {{"VAL", n}, {"DRVL", "1"}, {"DRVH", mx}}),
        record("longin", p + "MaxSize", {{"VAL", mx}}),
        record("longin", p + "CurrentPoint", {}),
        record("longout", p + "NumPulses", {{"VAL", n}, {"DRVL", "0"}, {"DRVH", mx}}),
        record("longin", p + "NumActualPulses", {}),
        record("longout", p + "StartPulses", {{"VAL", "1"}, {"DRVL", "0"}, {"DRVH", mx}}),
        record("longout", p + "EndPulses", {{"VAL", n}, {"DRVL", "0"}, {"DRVH", mx}}),
        record("bo", p + "TimeMode", {{"ZNAM", "Fixed"}, {"ONAM", "Array"}}),
        record("ao", p + "FixedTime", {{"VAL", "1.0"}, {"PREC", "3"}, {"EGU", "s"}}),
        record("waveform", p + "Times", {{"FTVL", "DOUBLE"}, {"NELM", n}, {"PREC", "3"}}),
        record("ao", p + "Acceleration", {{"VAL", "0.5"}, {"PREC", "3"}, {"EGU", "s"}}),
        record("bo", p + "MoveMode", {{"ZNAM", "Absolute"}, {"ONAM", "Relative"}}),
        record("bo", p + "Build", {{"ZNAM", "Done"}, {"ONAM", "Build"}}),
        mbbi(p + "BuildState", {{"Done", "NO_ALARM"}, {"Busy", "MINOR"}}),
        mbbi(p + "BuildStatus", {{"Undefined", "INVALID"}, {"Success", "NO_ALARM"}, {"Failure", "MAJOR"}}),
        text(p + "BuildMessage"),
        record("bo", p + "Execute", {{"ZNAM", "Done"}, {"ONAM", "Execute"}}),
        mbbi(p + "ExecuteState", {{"Done", "NO_ALARM"}, {"Move start", "MINOR"}, {"Executing", "MINOR"}, {"Flyback", "MINOR"}}),
        mbbi(p + "ExecuteStatus",
             {{"Undefined", "INVALID"}, {"Success", "NO_ALARM"}, {"Failure", "MAJOR"}, {"Abort", "MAJOR"}, {"Timeout", "MAJOR"}}),
        text(p + "ExecuteMessage"),
        record("bo", p + "Abort", {{"ZNAM", "Done"}, {"ONAM", "Abort"}}),
        record("bo", p + "Readback", {{"ZNAM", "Done"}, {"ONAM", "Readback"}}),
        mbbi(p + "ReadbackState", {{"Done", "NO_ALARM"}, {"Busy", "MINOR"}}),
        mbbi(p + "ReadbackStatus", {{"Undefined", "INVALID"}, {"Success", "NO_ALARM"}, {"Failure", "MAJOR"}}),
        text(p + "ReadbackMessage"),
        record("longin", p + "SftTrg", {}),
    };
    for (AxisPvt& a : axes_) {
        std::string ap = cfg.prefix + a.name + "-PVT-";
        std::string prec = std::to_string(axes.config(a.index).epics.precision);
        f.records.push_back(record("bo", ap + "UseAxis", {{"ZNAM", "No"}, {"ONAM", "Yes"}}));
        f.records.push_back(record("waveform", ap + "Positions", {{"FTVL", "DOUBLE"}, {"NELM", std::to_string(a.npoints)}, {"PREC", prec}}));
        f.records.push_back(record("waveform", ap + "Readbacks", {{"FTVL", "DOUBLE"}, {"NELM", std::to_string(a.nreadback)}, {"PREC", prec}}));
        f.records.push_back(record("waveform", ap + "FollowingErrors", {{"FTVL", "DOUBLE"}, {"NELM", std::to_string(a.nreadback)}, {"PREC", prec}}));
    }
    db_.load(f);
    auto find = [&](const std::string& name) {
        pv::Record* r = db_.find(name);
        if (!r) throw Error(SB() << "pvt: no record " << name);
        return r;
    };
    num_points_ = find(p + "NumPoints");
    num_pulses_ = find(p + "NumPulses");
    start_pulses_ = find(p + "StartPulses");
    end_pulses_ = find(p + "EndPulses");
    time_mode_ = find(p + "TimeMode");
    fixed_time_ = find(p + "FixedTime");
    times_ = find(p + "Times");
    accel_ = find(p + "Acceleration");
    move_mode_ = find(p + "MoveMode");
    build_state_ = find(p + "BuildState");
    build_status_ = find(p + "BuildStatus");
    build_msg_ = find(p + "BuildMessage");
    exec_state_ = find(p + "ExecuteState");
    exec_status_ = find(p + "ExecuteStatus");
    exec_msg_ = find(p + "ExecuteMessage");
    rb_state_ = find(p + "ReadbackState");
    rb_status_ = find(p + "ReadbackStatus");
    rb_msg_ = find(p + "ReadbackMessage");
    current_point_ = find(p + "CurrentPoint");
    actual_pulses_ = find(p + "NumActualPulses");
    soft_trigger_ = find(p + "SftTrg");
    for (pv::Record* r : {find(p + "MaxSize"), current_point_, actual_pulses_, soft_trigger_, build_state_, build_status_,
                          build_msg_, exec_state_, exec_status_, exec_msg_, rb_state_, rb_status_, rb_msg_})
        r->val_read_only = true;
    // A change of what the profile is made of asks for a new build (ECMC's messages).
    auto changed = [this](const char* what) {
        return [this, what](pv::Record&, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) == "VAL") invalidate(SB() << what << " changed, rebuild required...");
            return pv::PutStatus::Ok;
        };
    };
    num_points_->put_hook = changed("Num points");
    num_pulses_->put_hook = changed("Pulse count");
    start_pulses_->put_hook = changed("Start pulses point");
    end_pulses_->put_hook = changed("End pulses point");
    time_mode_->put_hook = changed("Time mode");
    fixed_time_->put_hook = changed("Fixed time");
    times_->put_hook = changed("Time array");
    accel_->put_hook = changed("Acceleration time");
    move_mode_->put_hook = changed("Move mode");
    auto action = [this](void (IocPvt::*fn)()) {
        return [this, fn](pv::Record&, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) == "VAL") (this->*fn)();
            return pv::PutStatus::Ok;
        };
    };
    find(p + "Build")->put_hook = action(&IocPvt::build);
    find(p + "Execute")->put_hook = action(&IocPvt::execute);
    find(p + "Abort")->put_hook = action(&IocPvt::abort);
    find(p + "Readback")->put_hook = action(&IocPvt::readback);
    for (AxisPvt& a : axes_) {
        std::string ap = cfg.prefix + a.name + "-PVT-";
        a.use = find(ap + "UseAxis");
        a.positions = find(ap + "Positions");
        a.readbacks = find(ap + "Readbacks");
        a.ferrors = find(ap + "FollowingErrors");
        a.readbacks->val_read_only = a.ferrors->val_read_only = true;
        a.use->put_hook = changed("Axis selection");
        a.positions->put_hook = [this, &a](pv::Record&, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) == "VAL") invalidate(a.name + ": positions changed, rebuild required...");
            return pv::PutStatus::Ok;
        };
        a.rb.assign(max_size_, 0.0);
        a.fe.assign(max_size_, 0.0);
    }
}

void IocPvt::bind(rt::Engine& engine, registry::Registry& reg) {
    if (axes_.empty()) return;
    ctrl_ = std::make_unique<motion::PvtController>(1.0 / double(cfg_.rate_hz));
    if (cfg_.pvt && !cfg_.pvt->trigger.empty()) {
        std::string why;
        registry::BoundSignal s = reg.bind(cfg_.pvt->trigger, why);
        if (!s.bound()) throw Error(SB() << cfg_.pvt->where << ": pvt.trigger: " << why);
        ctrl_->set_trigger(s);
    }
    engine.add_stage(rt::StageOrder::Axes, *ctrl_); // after the axes (IocAxes added theirs first)
}

double IocPvt::num(pv::Record* r) const { return get_value(*r); }

void IocPvt::set_num(pv::Record* r, double v) {
    if (r->udf == 0 && get_value(*r) == v) return;
    set_value(db_, *r, v, false);
}

void IocPvt::set_text(pv::Record* r, const std::string& text) {
    std::vector<double> c(text.begin(), text.begin() + std::min<std::size_t>(text.size(), 255));
    c.push_back(0);
    set_array(db_, *r, c.data(), uint32_t(c.size()));
}

std::vector<double> IocPvt::array(pv::Record* r) const {
    const pv::FieldDesc* f = r->type().find("VAL");
    pv::Elements e = r->elements(*f);
    std::vector<double> v(e.count);
    for (uint32_t i = 0; i < e.count; ++i) pv::get_element(*r, *f, e, i, pv::Prim::Double, &v[i]);
    return v;
}

std::string IocPvt::axis_name(int index) const {
    return index >= 0 && std::size_t(index) < iaxes_.size() ? iaxes_.name(std::size_t(index)) : std::string("?");
}

void IocPvt::invalidate(const std::string& why) {
    built_ = false;
    set_num(build_status_, 0);
    set_text(build_msg_, why);
}

void IocPvt::build() {
    if (ctrl_ && ctrl_->busy()) {
        set_text(build_msg_, "Profile busy, command ignored..");
        return;
    }
    built_ = false;
    set_num(build_state_, 1);
    set_num(build_status_, 0);
    set_text(build_msg_, "Build in progress.");
    auto failed = [&](const std::string& why) {
        LOG_WARN(lg, "PVT build refused: " << why);
        set_num(build_state_, 0);
        set_num(build_status_, 2);
        set_text(build_msg_, "Error: " + why);
    };
    int npoints = int(num(num_points_));
    int npulses = int(num(num_pulses_));
    int start_p = int(num(start_pulses_)), end_p = int(num(end_pulses_));
    double ta = num(accel_);
    bool array_mode = num(time_mode_) != 0;
    if (npoints < 2) return failed(SB() << "NumPoints is " << npoints << ": a profile needs at least 2 points.");
    if (!(ta > 0)) return failed(SB() << "Acceleration time " << ta << " s: it should be > 0 seconds.");
    // segment times
    std::vector<double> dt;
    if (array_mode) {
        std::vector<double> t = array(times_);
        if (t.size() + 1 < std::size_t(npoints))
            return failed(SB() << "Time array has " << t.size() << " values, NumPoints " << npoints << " needs " << npoints - 1 << ".");
        for (int i = 0; i + 1 < npoints; ++i)
            if (!(t[std::size_t(i)] > 0)) return failed(SB() << "Invalid time in time array (time " << i + 1 << " is " << t[std::size_t(i)] << "). Time values must be > 0 seconds.");
        dt.assign(t.begin(), t.begin() + (npoints - 1));
    } else {
        double ft = num(fixed_time_);
        if (!(ft > 0)) return failed("Time invalid, must be > 0 seconds.");
        dt.assign(std::size_t(npoints - 1), ft);
    }
    // pulses: 1-based points StartPulses..EndPulses
    double start_t = 0, between = 0;
    if (npulses > 0) {
        if (std::size_t(npulses) > max_size_) return failed(SB() << "Output pulse count cannot be higher than " << max_size_ << ".");
        if (start_p < 1 || start_p > npoints) return failed(SB() << "Start pulse id " << start_p << " outside points 1.." << npoints << ".");
        if (end_p < start_p || end_p > npoints) return failed(SB() << "End pulse id " << end_p << " outside points " << start_p << ".." << npoints << ".");
        auto time_of = [&](int id) {
            double t = ta;
            for (int k = 0; k + 1 < id; ++k) t += dt[std::size_t(k)];
            return t;
        };
        start_t = time_of(start_p);
        between = npulses > 1 ? (time_of(end_p) - start_t) / double(npulses - 1) : 0;
    }
    bool relative = num(move_mode_) != 0;
    motion::PvtController::Job job;
    job.relative = relative;
    job.pulses = uint32_t(std::max(npulses, 0));
    job.start_t = start_t;
    job.between = between;
    if (cfg_.pvt) job.duration_s = cfg_.pvt->trigger_duration_s;
    for (AxisPvt& a : axes_) {
        a.has_built = false;
        if (num(a.use) == 0) continue;
        std::vector<double> pos = array(a.positions);
        if (pos.size() < std::size_t(npoints))
            return failed(SB() << a.name << ": " << pos.size() << " positions written, NumPoints is " << npoints << ".");
        pos.resize(std::size_t(npoints));
        try {
            a.built = motion::PvtPath::build(pos, dt, ta);
        } catch (const Error& e) {
            return failed(SB() << a.name << ": " << e.what() << ".");
        }
        // What the axis allows: its soft limits (absolute profiles; relative ones at execute)
        // and its maximum velocity.
        const motion::AxisParams& ap = iaxes_.params(a.index);
        double pmin = 0, pmax = 0, vmax = 0;
        a.built.extremes(1.0 / double(cfg_.rate_hz), pmin, pmax, vmax);
        if (!relative && ap.soft_fwd_enable && pmax > ap.soft_fwd)
            return failed(SB() << a.name << ": the path reaches " << pmax << ", beyond the high soft limit " << ap.soft_fwd << ".");
        if (!relative && ap.soft_bwd_enable && pmin < ap.soft_bwd)
            return failed(SB() << a.name << ": the path reaches " << pmin << ", beyond the low soft limit " << ap.soft_bwd << ".");
        if (ap.velocity_enable && ap.velocity_max > 0 && vmax > ap.velocity_max)
            return failed(SB() << a.name << ": the path needs " << vmax << " units/s, above the axis's maximum " << ap.velocity_max << ".");
        a.has_built = true;
        if (job.n >= Ctl::kMaxAxes) return failed("too many axes.");
        auto& j = job.axes[job.n++];
        j.index = int(a.index);
        j.capacity = max_size_;
        j.count = &a.count;
    }
    if (job.n == 0) return failed("no axis selected (set <Axis>-PVT-UseAxis).");
    built_job_ = job;
    build_relative_ = relative;
    built_ = true;
    set_num(build_state_, 0);
    set_num(build_status_, 1);
    set_text(build_msg_, "Build profile succeeded");
}

void IocPvt::execute() {
    auto refused = [&](const std::string& why) {
        LOG_WARN(lg, "PVT execute refused: " << why);
        set_num(exec_status_, 2);
        set_text(exec_msg_, why);
    };
    if (!ctrl_) return refused("Profile not initialized, command ignored.");
    if (ctrl_->busy()) return refused("Profile busy, command ignored.");
    if (!built_) return refused("Profile not built: Build it first.");
    motion::PvtController::Job job = built_job_;
    motion::AxisGroup& group = *iaxes_.group();
    for (std::size_t k = 0; k < job.n; ++k) {
        auto& j = job.axes[k];
        AxisPvt* a = nullptr;
        for (AxisPvt& x : axes_)
            if (int(x.index) == j.index) a = &x;
        a->running = a->built; // the RT thread reads `running` until the controller is idle again
        j.axis = &group.axis(a->index);
        j.path = &a->running;
        j.readback = a->rb.data();
        j.ferror = a->fe.data();
        if (build_relative_) { // soft limits against where the axis is now
            const motion::AxisParams& ap = iaxes_.params(a->index);
            double pmin = 0, pmax = 0, vmax = 0, at = iaxes_.looked(a->index).set_pos;
            a->running.extremes(1.0 / double(cfg_.rate_hz), pmin, pmax, vmax);
            if (ap.soft_fwd_enable && pmax + at > ap.soft_fwd)
                return refused(SB() << a->name << ": the path would reach " << pmax + at << ", beyond the high soft limit " << ap.soft_fwd << ".");
            if (ap.soft_bwd_enable && pmin + at < ap.soft_bwd)
                return refused(SB() << a->name << ": the path would reach " << pmin + at << ", beyond the low soft limit " << ap.soft_bwd << ".");
        }
    }
    if (!ctrl_->execute(job)) return refused("Profile busy, command ignored.");
    running_ = true;
    runs_seen_ = ctrl_->status().runs;
    set_num(exec_state_, 1);
    set_num(exec_status_, 0);
    set_num(current_point_, 0);
    set_num(actual_pulses_, 0);
    set_text(exec_msg_, "Profile started");
}

void IocPvt::abort() {
    if (!ctrl_ || !ctrl_->busy()) return;
    (void)ctrl_->abort();
}

void IocPvt::readback() {
    set_num(rb_state_, 0);
    if (!ctrl_ || ctrl_->busy() || !running_) {
        set_num(rb_status_, 2);
        set_text(rb_msg_, ctrl_ && ctrl_->busy() ? "Readback failed: the profile is running" : "Readback failed: no profile has run");
        return;
    }
    for (AxisPvt& a : axes_) {
        if (num(a.use) == 0) continue;
        uint32_t n = std::min(a.count.load(std::memory_order_acquire), a.nreadback);
        set_array(db_, *a.readbacks, a.rb.data(), n);
        set_array(db_, *a.ferrors, a.fe.data(), n);
    }
    set_num(rb_status_, 1);
    set_text(rb_msg_, "Readback done");
}

void IocPvt::publish() {
    if (!ctrl_) return;
    if (!started_) { // after the records' initialisation
        started_ = true;
        if (build_msg_->udf) set_text(build_msg_, "Build not executed.");
        for (pv::Record* r : {build_status_, exec_status_, rb_status_, build_state_, exec_state_, rb_state_})
            if (r->udf) set_num(r, 0);
    }
    if (!running_) return;
    Ctl::Status s = ctrl_->status();
    set_num(current_point_, s.current_point);
    set_num(actual_pulses_, s.pulses);
    set_num(soft_trigger_, s.pulses);
    if (s.runs == runs_seen_) {
        if (s.state == Ctl::State::Idle) return; // ended and reported, or not taken yet
        set_num(exec_state_, s.state == Ctl::State::Executing ? 2 : 1);
        if (s.state == Ctl::State::Executing) set_text(exec_msg_, "Profile executing...");
        else if (s.state == Ctl::State::MoveToStart || s.state == Ctl::State::WaitAtStart) set_text(exec_msg_, "Profile moving to start...");
        return;
    }
    runs_seen_ = s.runs; // the profile ended: its result, once
    set_num(exec_state_, 0);
    switch (s.result) {
    case Ctl::Result::Success:
        set_num(exec_status_, 1);
        set_text(exec_msg_, "Profile done");
        break;
    case Ctl::Result::Abort:
        set_num(exec_status_, 3);
        set_text(exec_msg_, "Profile aborted.");
        break;
    default: {
        std::string who = axis_name(s.axis);
        std::string id = s.id ? " (" + hex(s.id) + ")" : "";
        std::string why;
        switch (s.why) {
        case Ctl::Why::AxisError: why = who + " is in error" + id; break;
        case Ctl::Why::EnableTimeout: why = who + " did not enable"; break;
        case Ctl::Why::StartRefused: why = who + " refused the move to the start" + id; break;
        case Ctl::Why::StartMissed: why = who + " did not reach the start" + id; break;
        case Ctl::Why::PathRefused: why = who + " refused the path" + id; break;
        case Ctl::Why::EndedShort: why = who + " stopped before the end of its path" + id; break;
        case Ctl::Why::None: why = "unknown"; break;
        }
        set_num(exec_status_, 2);
        set_text(exec_msg_, "Profile failed: " + why);
        LOG_WARN(lg, "PVT profile failed: " << why);
        break;
    }
    }
}

} // namespace beamctl::ioc
