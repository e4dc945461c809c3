#include "ioc/plcs.hpp"

#include "daq/pcomp.hpp"

#include "module/pv_table.hpp"
#include "ioc/pv_util.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/macros.hpp"
#include "core/paths.hpp"

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
    switch (registry::datatype_float_bits(datatype)) {
    case 32: return plc::EcEntry::Kind::Float32;
    case 64: return plc::EcEntry::Kind::Float64;
    default: return plc::EcEntry::Kind::Integer;
    }
}


// Why a PLC may not name `name` (an entry of bus `owner`, "ec1"): it runs in the cycle of bus
// `own_bus` ("ec2"), or in the IOC's ("").
std::string cycle_refusal(const std::string& name, const std::string& owner, const std::string& own_bus) {
    return SB() << "'" << name << "' is on " << owner << ", which runs in another cycle than this PLC's ("
                << (own_bus.empty() ? std::string("the IOC's") : "that of " + own_bus)
                << "): a PLC reads and writes the buses of its own cycle; plcs[].bus: N runs it in bus N's (buses[].rate_hz)";
}

} // namespace

plc::PlcSource plc_source(const config::PlcEntry& e) {
    plc::PlcSource s;
    s.id = e.id;
    s.file = e.file;
    s.text = read_text(e.file, e.where);
    s.rate_ms = e.rate_ms;
    s.enable = e.enable;
    s.strict = e.strict;
    s.macros = e.macros;
    s.include_path = e.include;
    s.libraries = e.libraries;
    return s;
}

std::optional<plc::PlcSource> axis_plc_source(const motion::AxisConfig& a) {
    if (!a.plc || !a.plc->enable || (a.plc->file.empty() && a.plc->code.empty())) return std::nullopt;
    plc::PlcSource s;
    s.id = a.axis.id.value_or(1);
    s.axis_plc = true;
    std::filesystem::path dir = std::filesystem::path(a.file).parent_path();
    if (!a.plc->file.empty()) {
        s.file = resolve_beside(dir, a.plc->file); // or, as ECMC, the working directory's
        s.text = read_text(s.file, a.file);
    } else {
        s.file = a.file + " (plc.code)";
    }
    for (const auto& line : a.plc->code) s.text += "\n" + line;
    if (!a.plc->macros.empty()) s.macros = parse_macro_defs(a.plc->macros);
    s.include_path.push_back(dir.empty() ? "." : dir.string());
    return s;
}

IocPlcs::IocPlcs(const config::IocConfig& cfg, const std::vector<motion::AxisConfig>& axes, registry::Registry& signals,
                 pv::Database& db)
    : cycle_s_(1.0 / cfg.rate_hz), signals_(signals), db_(db) {
    for (const auto& a : axes) {
        axis_ids_.push_back(a.axis.id.value_or(1));
        axis_names_[a.axis.id.value_or(1)] = a.epics.name;
    }
    for (const auto& st : cfg.storages) storage_ids_.push_back(st.id);
    for (const auto& pc : cfg.pcomp) pcomp_ids_.push_back(pc.id);
    for (const auto& l : cfg.luts) {
        try {
            luts_.emplace_back(l.id, std::make_unique<LookupTable>(LookupTable::load(l.file)));
        } catch (const Error& e) {
            throw Error(SB() << l.file_where << ": " << e.what());
        }
    }
    for (const auto& p : cfg.plugins) {
        try {
            plugins_.push_back(plc::Plugin::load(p.file, p.config));
        } catch (const Error& e) {
            throw Error(SB() << p.where << ": " << e.what());
        }
    }
    std::vector<std::string> group_names;
    for (const auto& a : axes) {
        if (a.axis.group.empty()) continue;
        auto it = std::find(group_names.begin(), group_names.end(), a.axis.group);
        if (it == group_names.end()) {
            group_names.push_back(a.axis.group);
            groups_.emplace_back();
            it = group_names.end() - 1;
        }
        groups_[std::size_t(it - group_names.begin())].push_back(a.axis.id.value_or(1));
    }
    for (const auto& e : cfg.plcs) {
        sources_.push_back(plc_source(e));
        bus_of_.push_back(e.bus);
    }
    // Axis PLCs: the axis file's plc.file (next to the axis file) and plc.code lines.
    for (const auto& a : axes)
        if (auto s = axis_plc_source(a)) sources_.push_back(std::move(*s));
    bus_of_.resize(sources_.size());
    for (auto& s : sources_) // ecmccfg's GRP_<name>_ID environment, as macros
        for (std::size_t g = 0; g < group_names.size(); ++g) s.macros.emplace("GRP_" + group_names[g] + "_ID", std::to_string(g));
    // Check-compile everything now, so `beamctl check` and `run` report every error before
    // anything starts.
    // ... each in its cycle: the buses it may name (plcs[].bus of a bus with rate_hz: that bus;
    // otherwise the buses of the IOC's cycle)
    std::vector<std::string> main_buses;
    for (const auto& bc : cfg.buses)
        if (!bc.rate_hz) main_buses.push_back(SB() << "ec" << bc.id);
    const std::vector<std::string>* allowed = &main_buses;
    std::vector<std::string> own;
    plc::PlcRuntime::Options co = check_options();
    co.ec = [inner = co.ec, reg = &signals, &allowed, &own](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
        auto e = inner(name, why);
        if (!e) return e;
        const registry::Signal* s = reg->find(name);
        if (std::find(allowed->begin(), allowed->end(), s->owner) == allowed->end()) {
            why = cycle_refusal(name, s->owner, allowed == &own ? own.front() : std::string());
            return std::nullopt;
        }
        return e;
    };
    plc::PlcRuntime check(co);
    std::vector<std::string> errors;
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        const auto& s = sources_[i];
        allowed = &main_buses;
        if (bus_of_[i])
            for (const auto& bc : cfg.buses)
                if (bc.id == *bus_of_[i] && bc.rate_hz) {
                    own = {std::string(SB() << "ec" << bc.id)};
                    allowed = &own;
                }
        try {
            check.add(s);
        } catch (const plc::CompileError& e) {
            errors.insert(errors.end(), e.errors().begin(), e.errors().end());
        }
    }
    if (!errors.empty()) throw plc::CompileError(std::move(errors));
    if (cfg.m2m || check.uses_m2m()) {
        config::M2mEntry m = cfg.m2m.value_or(config::M2mEntry{});
        int master = m.master.value_or(cfg.buses.empty() ? -1 : cfg.buses.front().id);
        try {
            m2m_ = std::make_unique<plc::M2m>(m.name, master);
        } catch (const Error& e) {
            throw Error(SB() << (m.where.empty() ? cfg.path : m.where) << ": " << e.what());
        }
    }
    // The registry: each PLC's own variables, and the outputs its code writes (one writer each).
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        const plc::PlcSource& s = sources_[i];
        std::string owner = check.prefix(i);
        owners_.push_back(owner);
        // the PLC code's variables, and the IOC's counts of its scans and faults
        for (const char* v : {"enable", "error", "scantime", "firstscan", "dbg", "scans", "faults"}) {
            registry::Signal sig;
            sig.name = owner + "." + v;
            sig.type = "LREAL";
            std::string_view n = v;
            bool rw = n == "enable" || n == "error" || n == "dbg";
            sig.direction = rw ? registry::Direction::Variable : registry::Direction::Input;
            sig.owner_kind = registry::OwnerKind::Plc;
            sig.owner = owner;
            signals.declare(std::move(sig));
        }
        for (const std::string& entry : check.written_entries(i)) {
            std::string why;
            if (!signals.claim(entry, owner, why)) throw Error(SB() << s.file << ": " << owner << " cannot write: " << why);
        }
    }
    make_pvs(cfg.prefix, signals);
}

IocPlcs::~IocPlcs() {
    if (runtime()) // entered at bind(); the engine has stopped (Ioc's destructor)
        for (auto& p : plugins_) (void)p->rt_exit();
}

std::pair<plc::PlcRuntime*, std::size_t> IocPlcs::at(std::size_t i) const {
    if (i >= where_.size()) return {nullptr, 0};
    return {runtimes_[where_[i].first].get(), where_[i].second};
}

void IocPlcs::request_enable(std::size_t i, bool on) {
    if (auto [rt, k] = at(i); rt) rt->request_enable(k, on);
}

void IocPlcs::set_epics_state(int state) {
    for (auto& rt : runtimes_)
        if (rt) rt->set_epics_state(state);
}

const double* IocPlcs::static_variable(std::size_t i, const std::string& name) const {
    auto [rt, k] = at(i);
    return rt ? rt->static_variable(k, name) : nullptr;
}

plc::PlcRuntime::Options IocPlcs::check_options() const {
    plc::PlcRuntime::Options o;
    o.cycle_s = cycle_s_;
    o.check_only = true;
    o.known_axis_ids = axis_ids_;
    o.known_storage_ids = storage_ids_;
    const registry::Registry* reg = &signals_;
    o.ec = [reg](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
        const registry::Signal* s = reg->find(name);
        if (!s || s->owner_kind != registry::OwnerKind::Bus || s->loop_only) {
            why = SB() << "no process-data entry '" << name << "' on the configured buses";
            return std::nullopt;
        }
        return plc::EcEntry{{}, kind_of(s->type), s->direction == registry::Direction::Output};
    };
    for (const auto& p : plugins_) o.plugins.push_back(p.get());
    // pcomp<n>.* of the IOC's position-compare blocks: stand-in cells
    auto stand_ins = std::make_shared<std::deque<double>>();
    o.cells = [ids = pcomp_ids_, stand_ins](const std::string& name) -> std::optional<plc::Binding> {
        for (int id : ids) {
            std::string p = SB() << "pcomp" << id << ".";
            if (name.rfind(p, 0) != 0) continue;
            for (int i = 0; i < int(std::size(daq::kPcompPlcItems)); ++i)
                if (name.compare(p.size(), std::string::npos, daq::kPcompPlcItems[i]) == 0)
                    return plc::Binding{&stand_ins->emplace_back(0.0), i < daq::kPcompPlcWritable, 1};
        }
        return std::nullopt;
    };
    return o;
}

// A general PLC's PVs, as ecmccfg names them ($(P) = "<prefix>PLCnn"), on its plc<n>.* items.
static const module::PvTable& plc_table() {
    static const module::PvTable t{"plc", {
        {"-EnaCmd", "bo", "enable", {{"DESC", "$(DESC)"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}, {"VAL", "$(ENABLE)"}}, true},
        {"-EnaAct", "bi", "enable", {{"DESC", "PLC running"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}},
        {"-ScanTime", "ai", "scantime", {{"DESC", "Scan period"}, {"EGU", "s"}, {"PREC", "4"}}},
        {"-Err", "longin", "error", {{"DESC", "Run-time fault (0 none)"}, {"HIGH", "1"}, {"HSV", "MAJOR"}}},
        {"-Faults", "longin", "faults", {{"DESC", "Scans that faulted"}}},
        {"-Scans", "longin", "scans", {{"DESC", "Scans run"}}},
    }};
    return t;
}

// An axis PLC's PVs, as ecmccfg's ecmcAxis.db names them ($(P) = "<prefix><axis name>-PLC").
static const module::PvTable& axis_plc_table() {
    static const module::PvTable t{"axis plc", {
        {"-EnaCmd", "bo", "enable", {{"DESC", "$(DESC)"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}, {"VAL", "$(ENABLE)"}}, true},
        {"-EnaCmd-RB", "bi", "enable", {{"DESC", "Plc enable"}, {"ZNAM", "Disabled"}, {"ONAM", "Enabled"}}},
        {"-FirstScan", "bi", "firstscan", {{"DESC", "Plc firstscan"}, {"ZNAM", "No"}, {"ONAM", "Yes"}}},
        {"-ScanTime", "ai", "scantime", {{"DESC", "Scan period"}, {"EGU", "s"}, {"PREC", "4"}}},
        {"-Err", "longin", "error", {{"DESC", "Plc error (run-time fault, 0 none)"}, {"HIGH", "1"}, {"HSV", "MAJOR"}}},
        {"-Faults", "longin", "faults", {{"DESC", "Scans that faulted"}}},
        {"-Scans", "longin", "scans", {{"DESC", "Scans run"}}},
    }};
    return t;
}

void IocPlcs::make_pvs(const std::string& prefix, registry::Registry& signals) {
    pv::DbFile f;
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        const auto& s = sources_[i];
        if (s.axis_plc) { // served under the axis's name, as ecmccfg does
            auto name = axis_names_.find(s.id);
            if (name == axis_names_.end()) continue;
            std::string desc = SB() << "ax" << s.id << " plc " << std::filesystem::path(s.file).filename().string();
            module::PvInstance in{prefix + name->second + "-PLC", owners_[i] + ".",
                          {{"DESC", desc.substr(0, 40)}, {"ENABLE", s.enable ? "1" : "0"}}};
            pv::merge_db(f, make_records(axis_plc_table(), in, signals));
            name_pvs(axis_plc_table(), in, signals);
            continue;
        }
        std::string desc = SB() << "plc" << s.id << " " << std::filesystem::path(s.file).filename().string();
        module::PvInstance in{prefix + "PLC" + two_digits(s.id), owners_[i] + ".",
                      {{"DESC", desc.substr(0, 40)}, {"ENABLE", s.enable ? "1" : "0"}}};
        pv::merge_db(f, make_records(plc_table(), in, signals));
        name_pvs(plc_table(), in, signals);
    }
    db_.load(f);
    seen_faults_.assign(sources_.size(), 0);
    last_fault_.assign(sources_.size(), std::string());
}

namespace {
// Device support "beamctl" on a PLC's items ("@plc0.enable", "@plc0.scans"): reads the runtime's
// status in the IOC loop; a write of plc<n>.enable starts or stops the PLC. IOC loop only.
class PlcItemDevice : public pv::LinkDevice {
public:
    enum class Item { Enable, Error, ScanTime, Scans, Faults, FirstScan };
    PlcItemDevice(IocPlcs& plcs, std::size_t i, Item item, std::string name)
        : plcs_(plcs), i_(i), item_(item), name_(std::move(name)) {}
    bool read(double& v) override {
        if (!value(v)) return false;
        last_ = v;
        return true;
    }
    bool write(double v) override {
        if (item_ != Item::Enable || !plcs_.at(i_).first) return false;
        plcs_.request_enable(i_, v != 0);
        return true;
    }
    bool changed() override {
        double v = NAN;
        value(v);
        bool c = !(v == last_);
        last_ = v;
        // a PLC that ran and stopped again between two looks (enabled, one scan, enable := 0)
        // reads disabled both times: its scan count says it ran
        if (auto [rt, k] = plcs_.at(i_); item_ == Item::Enable && rt) {
            uint64_t scans = rt->status(k).scans;
            if (scans != last_scans_ && v == 0) c = true;
            last_scans_ = scans;
        }
        return c;
    }
    std::string describe() const override { return name_; }

private:
    bool value(double& v) const {
        auto [rt, k] = plcs_.at(i_);
        if (!rt) return false;
        plc::PlcRuntime::Status s = rt->status(k);
        switch (item_) {
        case Item::Enable: v = s.enabled; break;
        case Item::Error: v = s.error; break;
        case Item::ScanTime: v = s.scantime_s; break;
        case Item::Scans: v = double(s.scans); break;
        case Item::Faults: v = double(s.faults); break;
        case Item::FirstScan: v = s.firstscan ? 1 : 0; break;
        }
        return true;
    }
    IocPlcs& plcs_;
    std::size_t i_;
    Item item_;
    std::string name_;
    double last_ = NAN;
    uint64_t last_scans_ = 0;
};
} // namespace

std::unique_ptr<pv::LinkDevice> IocPlcs::make_device(std::string_view name, int bit, bool output, std::string& why) {
    for (std::size_t i = 0; i < owners_.size(); ++i) {
        const std::string& o = owners_[i];
        if (name.size() <= o.size() + 1 || name.compare(0, o.size(), o) != 0 || name[o.size()] != '.') continue;
        std::string_view item = name.substr(o.size() + 1);
        using Item = PlcItemDevice::Item;
        static const std::pair<const char*, Item> items[] = {{"enable", Item::Enable}, {"error", Item::Error},
                                                             {"scantime", Item::ScanTime}, {"scans", Item::Scans},
                                                             {"faults", Item::Faults}, {"firstscan", Item::FirstScan}};
        for (const auto& [n, it] : items) {
            if (item != n) continue;
            if (bit >= 0) {
                why = SB() << "'" << name << "' is a number; it has no bit " << bit;
                return nullptr;
            }
            if (output && it != Item::Enable) {
                why = SB() << "'" << name << "' is a readback of " << o << "; an output link can write " << o << ".enable only";
                return nullptr;
            }
            return std::make_unique<PlcItemDevice>(*this, i, it, std::string(name));
        }
        why = SB() << "'" << name << "' lives in the cycle only (PLC code reads and writes it); records reach " << o
                   << ".enable, .error, .scantime, .firstscan, .scans and .faults";
        return nullptr;
    }
    why = SB() << "no PLC for '" << name << "'";
    return nullptr;
}

void IocPlcs::bind(std::vector<PlcCycle> cycles, motion::AxisGroup* group, std::vector<daq::DataStorage*> storages,
                   std::function<std::optional<plc::Binding>(const std::string&)> cells) {
    if (sources_.empty() && plugins_.empty()) return;
    // Each PLC's cycle: that of its bus, or the IOC's.
    std::vector<std::size_t> cycle_of(sources_.size(), 0);
    for (std::size_t i = 0; i < sources_.size(); ++i)
        if (bus_of_[i])
            for (std::size_t k = 0; k < cycles.size(); ++k)
                if (std::find(cycles[k].buses.begin(), cycles[k].buses.end(), *bus_of_[i]) != cycles[k].buses.end())
                    cycle_of[i] = k;
    runtimes_.resize(cycles.size());
    where_.assign(sources_.size(), {0, 0});
    for (std::size_t k = 0; k < cycles.size(); ++k) {
        PlcCycle& cy = cycles[k];
        const bool main = k == 0;
        std::vector<std::size_t> mine;
        for (std::size_t i = 0; i < sources_.size(); ++i)
            if (cycle_of[i] == k) mine.push_back(i);
        if (mine.empty() && !(main && !plugins_.empty())) continue;
        plc::PlcRuntime::Options o;
        o.memmaps = std::move(cy.memmaps);
        for (const auto& [id, t] : luts_) o.luts.emplace_back(id, t.get());
        o.cycle_s = double(cy.engine->period_ns()) * 1e-9;
        std::vector<std::string> buses;
        for (int b : cy.buses) buses.push_back(SB() << "ec" << b);
        o.ec = [this, buses, main](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
            const registry::Signal* s = signals_.find(name);
            if (!s || s->owner_kind != registry::OwnerKind::Bus || s->loop_only) {
                why = SB() << "no process-data entry '" << name << "' on the configured buses";
                return std::nullopt;
            }
            if (std::find(buses.begin(), buses.end(), s->owner) == buses.end()) {
                why = cycle_refusal(name, s->owner, main ? std::string() : buses.front());
                return std::nullopt;
            }
            registry::BoundSignal b = signals_.bind(name, why);
            if (!b.bound()) return std::nullopt;
            return plc::EcEntry{b, kind_of(s->type), s->direction == registry::Direction::Output};
        };
        o.bus_ok = std::move(cy.bus_ok);
        if (main) { // what lives in the IOC's cycle: axes, storages, plugins, m2m, PCOMP cells
            o.cells = cells;
            o.storages = storages;
            o.groups = groups_;
            o.m2m = m2m_.get();
            if (group)
                for (std::size_t i = 0; i < group->size(); ++i) o.axes.push_back(&group->axis(i));
            for (auto& p : plugins_) o.plugins.push_back(p.get());
        }
        auto rt = std::make_unique<plc::PlcRuntime>(o);
        for (std::size_t i : mine) {
            where_[i] = {k, rt->size()};
            rt->add(sources_[i]); // checked already; what may fail here: a name of another cycle
        }
        if (main)
            for (auto& p : plugins_)
                if (int rc = p->rt_enter()) throw Error(SB() << p->path() << ": rt_enter() failed with " << rc);
        cy.engine->add_stage(rt::StageOrder::GeneralPlcs, *rt);
        if (main && group) group->set_hook(rt.get());
        runtimes_[k] = std::move(rt);
    }
}

void IocPlcs::publish() {
    std::string line;
    for (auto& rt : runtimes_)
        while (rt && rt->pop_output(line)) std::fputs(line.c_str(), stdout);
    std::fflush(stdout);
    // the values are read by the PVs' device support (scan_io_intr)
    // A fault is logged with its place when it differs from the last one logged (a PLC that
    // faults every scan logs once); the place is looked up only when the fault count moved.
    for (std::size_t i = 0; i < sources_.size(); ++i) {
        auto [rt, k] = at(i);
        if (!rt) continue;
        std::uint64_t faults = rt->status(k).faults;
        if (faults == seen_faults_[i]) continue;
        seen_faults_[i] = faults;
        std::string f = rt->fault(k);
        if (f.empty() || f == last_fault_[i]) continue;
        last_fault_[i] = f;
        LOG_ERR(lg, rt->prefix(k) << ": run-time fault at " << f);
    }
}

} // namespace beamctl::ioc
