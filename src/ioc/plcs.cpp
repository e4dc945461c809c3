#include "ioc/plcs.hpp"

#include "ioc/pv_util.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/macros.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace beamctl::ioc {
namespace {
log::Logger lg("plc");

std::string read_text(const std::string& path, const std::string& where) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw Error(SB() << where << ": cannot open PLC file '" << path << "': " << std::strerror(errno));
    std::ostringstream ss;
    ss << f.rdbuf();
    return ss.str();
}

plc::EcEntry::Kind kind_of(const std::string& datatype) {
    if (datatype == "REAL") return plc::EcEntry::Kind::Float32;
    if (datatype == "LREAL") return plc::EcEntry::Kind::Float64;
    return plc::EcEntry::Kind::Integer;
}

std::string two_digits(int id) {
    char b[16];
    std::snprintf(b, sizeof b, "%02d", id);
    return b;
}

} // namespace

plc::PlcSource plc_source(const config::PlcEntry& e) {
    plc::PlcSource s;
    s.id = e.id;
    s.file = e.file;
    s.text = read_text(e.file, e.where);
    s.rate_ms = e.rate_ms;
    s.enable = e.enable;
    s.macros = e.macros;
    s.include_path = e.include;
    s.libraries = e.libraries;
    return s;
}

IocPlcs::IocPlcs(const config::IocConfig& cfg, const std::vector<motion::AxisConfig>& axes, registry::Registry& signals,
                 pv::Database& db)
    : cycle_s_(1.0 / cfg.rate_hz), signals_(signals), db_(db) {
    for (const auto& a : axes) axis_ids_.push_back(a.axis.id.value_or(1));
    for (const auto& p : cfg.plugins) {
        try {
            plugins_.push_back(plc::Plugin::load(p.file, p.config));
        } catch (const Error& e) {
            throw Error(SB() << p.where << ": " << e.what());
        }
    }
    for (const auto& e : cfg.plcs) sources_.push_back(plc_source(e));
    // Axis PLCs: the axis file's plc.file (next to the axis file) and plc.code lines.
    for (const auto& a : axes) {
        if (!a.plc || !a.plc->enable || (a.plc->file.empty() && a.plc->code.empty())) continue;
        plc::PlcSource s;
        s.id = a.axis.id.value_or(1);
        s.axis_plc = true;
        std::filesystem::path dir = std::filesystem::path(a.file).parent_path();
        if (!a.plc->file.empty()) {
            std::filesystem::path f = a.plc->file;
            if (f.is_relative()) f = dir / f;
            s.file = f.string();
            s.text = read_text(s.file, a.file);
        } else {
            s.file = a.file + " (plc.code)";
        }
        for (const auto& line : a.plc->code) s.text += "\n" + line;
        if (!a.plc->macros.empty()) s.macros = parse_macro_defs(a.plc->macros);
        s.include_path.push_back(dir.empty() ? "." : dir.string());
        sources_.push_back(std::move(s));
    }
    // Check-compile everything now, so `beamctl check` and `run` report every error before
    // anything starts.
    plc::PlcRuntime check(check_options());
    std::vector<std::string> errors;
    for (const auto& s : sources_) {
        try {
            check.add(s);
        } catch (const plc::CompileError& e) {
            errors.insert(errors.end(), e.errors().begin(), e.errors().end());
        }
    }
    if (!errors.empty()) throw plc::CompileError(std::move(errors));
    // The registry: each PLC's own variables, and the outputs its code writes (one writer each).
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        const plc::PlcSource& s = sources_[i];
        std::string owner = check.prefix(i);
        std::string pv = s.axis_plc ? std::string() : cfg.prefix + "PLC" + two_digits(s.id);
        for (const char* v : {"enable", "error", "scantime", "firstscan", "dbg"}) {
            registry::Signal sig;
            sig.name = owner + "." + v;
            sig.type = "LREAL";
            bool rw = std::string_view(v) != "scantime" && std::string_view(v) != "firstscan";
            sig.direction = rw ? registry::Direction::Variable : registry::Direction::Input;
            sig.owner_kind = registry::OwnerKind::Plc;
            sig.owner = owner;
            if (!pv.empty() && std::string_view(v) == "enable") sig.pv = pv + "-EnaCmd";
            if (!pv.empty() && std::string_view(v) == "scantime") sig.pv = pv + "-ScanTime";
            if (!pv.empty() && std::string_view(v) == "error") sig.pv = pv + "-Err";
            signals.declare(std::move(sig));
        }
        for (const std::string& entry : check.written_entries(i)) {
            std::string why;
            if (!signals.claim(entry, owner, why)) throw Error(SB() << s.file << ": " << owner << " cannot write: " << why);
        }
    }
    make_pvs(cfg.prefix, db);
}

IocPlcs::~IocPlcs() {
    if (runtime_) // entered at bind(); the engine has stopped (Ioc's destructor)
        for (auto& p : plugins_) (void)p->rt_exit();
}

plc::PlcRuntime::Options IocPlcs::check_options() const {
    plc::PlcRuntime::Options o;
    o.cycle_s = cycle_s_;
    o.check_only = true;
    o.known_axis_ids = axis_ids_;
    const registry::Registry* reg = &signals_;
    o.ec = [reg](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
        const registry::Signal* s = reg->find(name);
        if (!s || s->owner_kind != registry::OwnerKind::Bus) {
            why = SB() << "no process-data entry '" << name << "' on the configured buses";
            return std::nullopt;
        }
        return plc::EcEntry{{}, kind_of(s->type), s->direction == registry::Direction::Output};
    };
    for (const auto& p : plugins_) o.plugins.push_back(p.get());
    return o;
}

void IocPlcs::make_pvs(const std::string& prefix, pv::Database& db) {
    pv::DbFile f;
    std::vector<std::pair<std::size_t, std::string>> names;
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        const auto& s = sources_[i];
        if (s.axis_plc) continue;
        std::string p = prefix + "PLC" + two_digits(s.id);
        std::string desc = SB() << "plc" << s.id << " " << std::filesystem::path(s.file).filename().string();
        desc = desc.substr(0, 40);
        f.records.push_back(record("bo", p + "-EnaCmd", {{"DESC", desc}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}, {"VAL", s.enable ? "1" : "0"}}));
        f.records.push_back(record("bi", p + "-EnaAct", {{"DESC", "PLC running"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}));
        f.records.push_back(record("ai", p + "-ScanTime", {{"DESC", "Scan period"}, {"EGU", "s"}, {"PREC", "4"}}));
        f.records.push_back(record("longin", p + "-Err", {{"DESC", "Run-time fault (0 none)"}, {"HIGH", "1"}, {"HSV", "MAJOR"}}));
        f.records.push_back(record("longin", p + "-Faults", {{"DESC", "Scans that faulted"}}));
        f.records.push_back(record("longin", p + "-Scans", {{"DESC", "Scans run"}}));
        names.emplace_back(i, p);
    }
    db.load(f);
    for (auto& [i, p] : names) {
        Pvs v;
        v.index = i;
        v.ena_cmd = db.find(p + "-EnaCmd");
        v.ena_act = db.find(p + "-EnaAct");
        v.scan_time = db.find(p + "-ScanTime");
        v.err = db.find(p + "-Err");
        v.faults = db.find(p + "-Faults");
        v.scans = db.find(p + "-Scans");
        std::size_t index = i;
        v.ena_cmd->put_hook = [this, index](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            if (!runtime_) return pv::PutStatus::Failed;
            runtime_->request_enable(index, get_value(r) != 0);
            return pv::PutStatus::Ok;
        };
        pvs_.push_back(v);
    }
    seen_faults_.assign(sources_.size(), 0);
    last_fault_.assign(sources_.size(), std::string());
}

void IocPlcs::bind(rt::Engine& engine, motion::AxisGroup* group, std::vector<registry::BoundSignal> bus_ok) {
    if (sources_.empty() && plugins_.empty()) return;
    plc::PlcRuntime::Options o;
    o.cycle_s = cycle_s_;
    o.ec = [this](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
        const registry::Signal* s = signals_.find(name);
        if (!s || s->owner_kind != registry::OwnerKind::Bus) {
            why = SB() << "no process-data entry '" << name << "' on the configured buses";
            return std::nullopt;
        }
        registry::BoundSignal b = signals_.bind(name, why);
        if (!b.bound()) return std::nullopt;
        return plc::EcEntry{b, kind_of(s->type), s->direction == registry::Direction::Output};
    };
    o.bus_ok = std::move(bus_ok);
    if (group)
        for (std::size_t i = 0; i < group->size(); ++i) o.axes.push_back(&group->axis(i));
    for (auto& p : plugins_) o.plugins.push_back(p.get());
    runtime_ = std::make_unique<plc::PlcRuntime>(o);
    for (const auto& s : sources_) runtime_->add(s); // checked already: errors here are bugs
    for (auto& p : plugins_)
        if (int rc = p->rt_enter()) throw Error(SB() << p->path() << ": rt_enter() failed with " << rc);
    engine.add_stage(rt::StageOrder::GeneralPlcs, *runtime_);
    if (group) group->set_hook(runtime_.get());
    for (const auto& v : pvs_) set_value(db_, *v.scan_time, runtime_->status(v.index).scantime_s, false);
}

void IocPlcs::publish() {
    if (!runtime_) return;
    std::string line;
    while (runtime_->pop_output(line)) std::fputs(line.c_str(), stdout);
    std::fflush(stdout);
    auto upd = [&](pv::Record* r, double v) {
        if (get_value(*r) != v || r->udf) set_value(db_, *r, v, false);
    };
    for (auto& v : pvs_) {
        plc::PlcRuntime::Status s = runtime_->status(v.index);
        upd(v.ena_act, s.enabled);
        upd(v.err, s.error);
        upd(v.faults, double(s.faults));
        upd(v.scans, double(s.scans));
        if (int(s.enabled) != v.last_enabled) { // follows what the PLC itself does (enable := 0)
            v.last_enabled = s.enabled;
            if (get_value(*v.ena_cmd) != double(s.enabled)) set_value(db_, *v.ena_cmd, s.enabled, false);
        }
    }
    // A fault is logged with its place when it differs from the last one logged (a PLC that
    // faults every scan logs once); the place is looked up only when the fault count moved.
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        std::uint64_t faults = runtime_->status(i).faults;
        if (faults == seen_faults_[i]) continue;
        seen_faults_[i] = faults;
        std::string f = runtime_->fault(i);
        if (f.empty() || f == last_fault_[i]) continue;
        last_fault_[i] = f;
        LOG_ERR(lg, runtime_->prefix(i) << ": run-time fault at " << f);
    }
}

} // namespace beamctl::ioc
