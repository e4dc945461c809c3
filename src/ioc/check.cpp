#include "ioc/check.hpp"

#include "ca/access_security.hpp"
#include "config/ioc_config.hpp"
#include "config/yaml_reader.hpp"
#include "core/error_list.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/local_bus.hpp"
#include "ethercat/sim/segment.hpp"
#include "scanner/scanner.hpp"
#include "ethercat/sim/sim_config.hpp"
#include "ioc/ioc.hpp"
#include "ioc/plcs.hpp"
#include "motion/axis_config.hpp"
#include "motion/axis_setup.hpp"
#include "plc/plugin.hpp"
#include "plc/program.hpp"
#include "plc/runtime.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"
#include "pv/substitutions.hpp"
#include "rt/engine.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <memory>
#include <set>

namespace beamctl::ioc {
namespace {

class Checker {
public:
    explicit Checker(ErrorList& errors)
        : errors_(errors) {}

    // True when `file` can be read; else an error at `where` (its place in the IOC file).
    bool readable(const std::string& where, const std::string& key, const std::string& file) {
        if (file.empty()) return false; // not given: the IOC file's own error
        std::ifstream f(file, std::ios::binary);
        if (f) return true;
        const int e = errno;
        errors_.add(SB() << (where.empty() ? std::string() : where + ": ") << key << ": " << file
                         << ": " << std::strerror(e));
        return false;
    }

    // Every error of running f(): a CompileError's each, a MultiError's each, an Error.
    template <typename F> void collect(F&& f, const std::string& context = {}) {
        try {
            f();
        } catch (const plc::CompileError& e) {
            for (const auto& m : e.errors()) errors_.add(in(context, m));
        } catch (const MultiError& e) {
            for (const auto& m : e.errors()) errors_.add(in(context, m));
        } catch (const Error& e) {
            errors_.add(in(context, e.what()));
        }
    }

    void buses(const config::IocConfig& cfg, const ethercat::Catalog& catalog) {
        std::set<int> beamed; // the buses whose plant has a beam (what a camera sees)
        for (std::size_t b = 0; b < cfg.buses.size(); ++b) {
            const config::BusConfig& bc = cfg.buses[b];
            bool types_ok = true;
            for (const auto& s : bc.slaves) {
                if (const ethercat::DeviceDesc* d = catalog.find(s.type)) {
                    if (s.oversampling != 1) {
                        try {
                            (void)d->with_oversampling(s.oversampling);
                        } catch (const Error& e) {
                            errors_.add(SB() << s.oversampling_where << ": buses[" << b << "] position " << s.position
                                             << ": " << e.what());
                        }
                    }
                    continue;
                }
                types_ok = false;
                errors_.add(SB() << s.type_where << ": buses[" << b << "] position " << s.position
                                 << ": " << catalog.unknown_type_error(s.type));
            }
            if (bc.link.type != "sim" || bc.link.plant.empty()) continue;
            const std::string key = SB() << "buses[" << b << "].link.plant";
            if (!readable(bc.link.plant_where, key, bc.link.plant)) continue;
            ErrorList plant_errors;
            ethercat::sim::SimConfig sim =
                ethercat::sim::SimConfig::load(bc.link.plant, catalog, plant_errors);
            if (plant_errors.empty() && !sim.slaves.empty())
                plant_errors.add(SB() << bc.link.plant
                                      << ": a plant file used by an IOC takes its slaves from the "
                                         "IOC file; remove 'slaves:'");
            if (plant_errors.empty() && types_ok) {
                // The plant against the bus as the IOC builds it: its slaves in position order,
                // an EK1100 in every gap.
                ethercat::sim::Segment seg;
                seg.add_configured(config::positions_and_types(bc), catalog);
                sim.build(seg, catalog, plant_errors);
            }
            errors_.append(plant_errors);
            if (plant_errors.empty() && sim.beam) beamed.insert(bc.id);
        }
        auto beam_needed = [&](const std::string& where, const std::string& what, int bus) {
            if (bus >= 0 && !beamed.count(bus))
                errors_.add(SB() << where << ": " << what << ": bus " << bus
                                 << " has no simulated beam in this IOC (a sim link whose plant has a beam: section)");
        };
        for (const config::AreaDetectorEntry& a : cfg.area_detector) beam_needed(a.where, "area_detector " + a.cam, a.bus);
        for (const config::McaEntry& m : cfg.mca) beam_needed(m.where, "mca " + m.name, m.bus);
    }

    void axes(const config::IocConfig& cfg) {
        for (std::size_t i = 0; i < cfg.axes.size(); ++i) {
            const config::AxisEntry& a = cfg.axes[i];
            const std::string chain = config::axis_entry_context(a, i); // as the IOC build names them
            if (readable(a.file_where, SB() << "axes[" << i << "].file", a.file)) {
                std::vector<Error> errors;
                motion::AxisConfig c = motion::load_axis_config(a.file, a.macros, errors);
                for (const auto& e : errors) errors_.add(chain + ": " + e.what());
                if (!errors.empty()) failed_axes_.push_back(SB() << "axes[" << i << "] (" << a.file << ")");
                warnings_.insert(warnings_.end(), c.warnings.begin(), c.warnings.end());
            } else {
                unreadable_axes_.push_back(chain + ": "); // the IOC build says it again: once is enough
                failed_axes_.push_back(SB() << "axes[" << i << "] (" << a.file << ")");
            }
            for (std::size_t k = 0; k < a.encoders.size(); ++k) {
                const auto& enc = a.encoders[k];
                if (!readable(enc.file_where, SB() << "axes[" << i << "].encoders[" << k << "].file",
                              enc.file))
                    continue;
                std::vector<Error> errors;
                motion::EncoderConfig c = motion::load_encoder_config(enc.file, enc.macros, errors);
                for (const auto& e : errors) errors_.add(chain + ": " + e.what());
                warnings_.insert(warnings_.end(), c.warnings.begin(), c.warnings.end());
            }
        }
    }

    // Plugins are loaded (PLC code may call their functions); general PLCs compiled with every
    // well-formed name of the known namespaces accepted (the names are bound in the second pass).
    void plcs(const config::IocConfig& cfg) {
        std::vector<std::unique_ptr<plc::Plugin>> plugins;
        for (std::size_t i = 0; i < cfg.plugins.size(); ++i) {
            const config::PluginEntry& p = cfg.plugins[i];
            if (!readable(p.file_where, SB() << "plugins[" << i << "].file", p.file)) continue;
            collect([&] { plugins.push_back(plc::Plugin::load(p.file, p.config)); }, p.where);
        }
        plc::PlcRuntime::Options opt;
        opt.check_only = true;
        opt.cycle_s = 1.0 / cfg.rate_hz;
        for (const auto& p : plugins) opt.plugins.push_back(p.get());
        plc::PlcRuntime check(opt);
        for (std::size_t i = 0; i < cfg.plcs.size(); ++i) {
            const config::PlcEntry& p = cfg.plcs[i];
            if (!readable(p.file_where, SB() << "plcs[" << i << "].file", p.file)) continue;
            collect([&] { check.add(plc_source(p)); });
        }
        for (std::size_t i = 0; i < cfg.kinematics.size(); ++i) {
            const config::KinematicsEntry& k = cfg.kinematics[i];
            if (!k.file.empty())
                readable(k.file_where, SB() << "kinematics[" << i << "].file", k.file);
        }
    }

    // The IOC build's errors without the follow-ons of what the first pass found: an unreadable
    // axis file again, and "no axis n" of PLC code or kinematics said with the axis that did not load.
    void second_pass(const ErrorList& build) {
        for (const std::string& m : build.messages()) {
            bool repeat = false;
            for (const std::string& chain : unreadable_axes_)
                repeat = repeat || m.rfind(chain, 0) == 0;
            if (repeat) continue;
            std::size_t at = m.find("no axis ");
            if (at == std::string::npos || failed_axes_.empty()) {
                errors_.add(m);
                continue;
            }
            std::string note = " [";
            for (std::size_t k = 0; k < failed_axes_.size(); ++k) note += (k ? ", " : "") + failed_axes_[k];
            note += failed_axes_.size() == 1 ? " did not load: see its errors]" : " did not load: see their errors]";
            std::size_t eol = m.find('\n');
            errors_.add(eol == std::string::npos ? m + note : m.substr(0, eol) + note + m.substr(eol));
        }
    }

    void databases(const config::IocConfig& cfg) {
        pv::Database db;
        for (std::size_t i = 0; i < cfg.db.size(); ++i) {
            const config::DbConfig& d = cfg.db[i];
            if (!readable(d.file_where, SB() << "db[" << i << "].file", d.file)) continue;
            collect([&] {
                for (const pv::DbFile& f : pv::load_records_file(d.file, d.macros)) db.load(f);
            });
        }
        if (!cfg.acf.empty() && readable(cfg.acf_where, "ca.acf", cfg.acf))
            collect([&] { ca::AccessSecurity::load_file(cfg.acf); });
    }

private:
    static std::string in(const std::string& context, const std::string& m) {
        return context.empty() ? m : context + ": " + m;
    }

    ErrorList& errors_;
    std::vector<std::string> unreadable_axes_; // the chains of axis entries whose file cannot be read
    std::vector<std::string> failed_axes_;     // "axes[i] (file)" of every entry whose file has errors

public:
    std::vector<std::string> warnings_; // of the axis and encoder files
};

} // namespace

CheckReport check_ioc(const std::string& path, const MacroMap& macros) {
    CheckReport report;
    ErrorList errors;
    config::IocConfig cfg = config::IocConfig::load(path, errors, macros);
    std::ifstream probe(path);
    bool bus_errors = false; // the IOC cannot be built without its buses: the second pass waits
    Checker checker(errors);
    if (probe) { // the files it names, each with all its errors
        Checker& c = checker;
        const ethercat::Catalog* catalog = nullptr;
        errors.capture([&] { catalog = &ethercat::Catalog::builtin(); });
        std::size_t before = errors.size();
        if (catalog) c.buses(cfg, *catalog);
        bus_errors = errors.size() > before;
        c.axes(cfg);
        c.plcs(cfg);
        c.databases(cfg);
        report.warnings = c.warnings_;
    }
    if (probe && !bus_errors) { // the errors between the files: the IOC as `run` builds it (repeats dropped)
        for (auto& bc : cfg.buses) bc.link.resolve_timeout_s = 1; // a check does not wait for a scanner
        rt::MonotonicClock clock;
        ErrorList build;
        Checker(build).collect([&] {
            Ioc ioc(cfg, clock);
            report.pvs = ioc.database().size();
            report.buses = ioc.bus_count();
        });
        checker.second_pass(build);
    }
    report.errors = errors.messages();
    return report;
}

// A scanner's file (a top-level `scanner:` key): its keys, its buses built as the scanner builds them
// (catalog types, plant, faults), without bringing anything up.
CheckReport check_scanner(const std::string& path) {
    CheckReport report;
    ErrorList errors;
    errors.capture([&] {
        scanner::ScannerConfig cfg = scanner::ScannerConfig::load(path);
        const ethercat::Catalog& catalog = ethercat::Catalog::builtin();
        for (const auto& bc : cfg.buses) {
            ethercat::sim::LocalBus b = ethercat::sim::make_local_bus(bc, catalog, path);
            report.buses++;
        }
    });
    report.errors = errors.messages();
    return report;
}

bool is_scanner_file(const std::string& path) {
    std::ifstream f(path);
    std::string line;
    while (std::getline(f, line))
        if (line.rfind("scanner:", 0) == 0) return true;
    return false;
}

int run_check(const std::string& path, const MacroMap& macros, std::FILE* out, std::FILE* err) {
    if (is_scanner_file(path)) {
        CheckReport r = check_scanner(path);
        for (const auto& e : r.errors) std::fprintf(err, "%s\n", e.c_str());
        if (!r.ok()) {
            std::fprintf(err, "%s: %zu error%s\n", path.c_str(), r.errors.size(), r.errors.size() == 1 ? "" : "s");
            return 1;
        }
        std::fprintf(out, "%s: OK (a scanner file, %zu bus(es))\n", path.c_str(), r.buses);
        return 0;
    }
    CheckReport r = check_ioc(path, macros);
    for (const auto& w : r.warnings) std::fprintf(err, "warning: %s\n", w.c_str());
    for (const auto& e : r.errors) std::fprintf(err, "%s\n", e.c_str());
    if (!r.ok()) {
        std::fprintf(err, "%s: %zu error%s\n", path.c_str(), r.errors.size(),
                     r.errors.size() == 1 ? "" : "s");
        return 1;
    }
    std::fprintf(out, "%s: OK (%zu PVs, %zu bus(es))\n", path.c_str(), r.pvs, r.buses);
    return 0;
}

int run_axis_check(const std::string& file, const std::vector<std::string>& encoder_files,
                   const MacroMap& macros, std::FILE* out, std::FILE* err) {
    ErrorList errors;
    std::vector<Error> file_errors;
    motion::AxisConfig axis = motion::load_axis_config(file, macros, file_errors);
    for (const auto& enc_file : encoder_files) {
        motion::EncoderConfig enc = motion::load_encoder_config(enc_file, macros, file_errors);
        if (file_errors.empty()) errors.capture([&] { motion::add_encoder(axis, std::move(enc)); });
    }
    for (const auto& e : file_errors) errors.add(e);
    if (errors.empty()) {
        errors.capture([&] { motion::make_axis_params(axis); });
        errors.capture([&] {
            std::optional<plc::PlcSource> src = axis_plc_source(axis);
            if (!src) return;
            plc::PlcRuntime::Options opt;
            opt.check_only = true;
            plc::PlcRuntime check(opt);
            try {
                check.add(*src);
            } catch (const plc::CompileError& e) {
                for (const auto& m : e.errors()) errors.add(m);
            }
        });
    }
    for (const auto& w : axis.warnings) std::fprintf(out, "warning: %s\n", w.c_str());
    for (const auto& m : errors.messages()) std::fprintf(err, "%s\n", m.c_str());
    if (!errors.empty()) {
        std::fprintf(err, "%s: %zu error%s\n", file.c_str(), errors.size(), errors.size() == 1 ? "" : "s");
        return 1;
    }
    std::fprintf(out, "%s: OK\n", file.c_str());
    return 0;
}

} // namespace beamctl::ioc
