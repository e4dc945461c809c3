// The IOC's soft PLCs: `plcs:` of the IOC file (general PLCs) and the `plc:` code of axis files
// (axis PLCs), with `plugins:`. Every PLC is compiled when the IOC is built, against the
// configured buses and axes (errors with file:line:col, all at once), and again at bring-up
// against the real addresses; then run by a plc::PlcRuntime in the RT cycle.
//
// PVs ($(P) = the IOC prefix, nn = the PLC id as two digits, as ecmccfg), from one table
// (plcs.cpp, plc_table) on the PLC's items plc<n>.enable, .error, .scantime, .scans, .faults:
//   $(P)PLCnn-EnaCmd (bo, writes plc<n>.enable; follows it), -EnaAct (bi), -ScanTime (ai, s),
//   -Err (longin: the latched run-time fault, 0 none), -Faults (longin), -Scans (longin)
// Axis groups: each `axis.group` name of the axis files is a group, numbered from 0 in the order
// the axes name them (ECMC AddAxisToGroupByName); every PLC gets the macro GRP_<name>_ID with its
// number, as ecmccfg sets the environment variable, for mc_grp_*(group, ...).
// An axis PLC's PVs, as ecmccfg's ecmcAxis.db: $(P)<axis name>-PLC-EnaCmd (bo), -EnaCmd-RB (bi),
// -FirstScan (bi), -ScanTime (ai), -Err, -Faults, -Scans (longin).
// println/print output goes to the IOC's standard output ("plc0: text"); faults are logged with
// their location.
// Threading: everything here on the IOC loop thread, except the runtime's RT side.
#pragma once

#include "config/ioc_config.hpp"
#include "motion/axis_config.hpp"
#include "motion/axis_group.hpp"
#include "plc/plugin.hpp"
#include "plc/runtime.hpp"
#include "pv/database.hpp"
#include "pv/link.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace beamctl::ioc {

// The axis PLC of an axis file (`plc:` with enable, and file or code): plc.file read next to the
// axis file, then the plc.code lines; nullopt when the axis has none. Throws Error when the file
// cannot be read.
std::optional<plc::PlcSource> axis_plc_source(const motion::AxisConfig& axis);

// One cycle's share of the PLCs (IocPlcs::bind): the engine it runs on, the buses it runs (ids),
// their masterstatus signals, and the memory maps by ECMC id (null: a bus of another cycle).
struct PlcCycle {
    rt::Engine* engine = nullptr;
    std::vector<int> buses;
    std::vector<registry::BoundSignal> bus_ok;
    std::vector<registry::MemMap*> memmaps;
};

class IocPlcs {
public:
    // Loads the plugins, reads every PLC and compiles it against the bus signals of `signals`
    // and the axes' ids; declares each PLC's plc<n>.* variables there and makes each PLC the one
    // writer of the outputs its code assigns (a second writer is an error naming the first).
    // Throws plc::CompileError (every error) or Error.
    IocPlcs(const config::IocConfig& cfg, const std::vector<motion::AxisConfig>& axes,
            registry::Registry& signals, pv::Database& db);
    ~IocPlcs();

    // Bring-up: compiles for real (ec names bound through the registry, after the buses are up;
    // ax names to the axes), adds the general PLCs' stage and the axis PLCs' hook. `cycles[0]` is
    // the IOC's cycle: axis PLCs, and general PLCs without `bus:`, with the axes, the data
    // storages (ds<n>), the plugins and the other blocks' `cells`; a PLC with `bus: N` runs in
    // the cycle of bus N, on that cycle's buses and memory maps only (one runtime per cycle).
    // Throws plc::CompileError (a PLC naming a bus of another cycle) or Error.
    void bind(std::vector<PlcCycle> cycles, motion::AxisGroup* group, std::vector<daq::DataStorage*> storages = {},
              std::function<std::optional<plc::Binding>(const std::string&)> cells = {});
    // IOC loop: statuses into PVs, output lines to stdout, faults to the log.
    void publish();

    // Options that check PLC code against this IOC without binding anything
    // (`beamctl plc check --ioc`).
    plc::PlcRuntime::Options check_options() const;
    std::size_t size() const { return sources_.size(); }
    // The IOC cycle's runtime (axis PLCs, general PLCs without bus:); null before bind or if none.
    plc::PlcRuntime* runtime() { return runtimes_.empty() ? nullptr : runtimes_[0].get(); }
    // PLC i (sources() order) in its cycle's runtime: the runtime (null before bind) and its index there.
    std::pair<plc::PlcRuntime*, std::size_t> at(std::size_t i) const;
    void request_enable(std::size_t i, bool on); // plc<n>.enable, in whichever cycle it runs
    void set_epics_state(int state);             // every runtime's (PlcRuntime::set_epics_state)
    const double* static_variable(std::size_t i, const std::string& name) const;
    const std::vector<plc::PlcSource>& sources() const { return sources_; }
    // Device support "beamctl" on a PLC item ("plc0.enable", "plc0.scans", ...): reads the
    // runtime's status; a write of <plc>.enable starts or stops it. Null with `why` otherwise.
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view name, int bit, bool output, std::string& why);

private:
    void make_pvs(const std::string& prefix, registry::Registry& signals);

    double cycle_s_;
    const registry::Registry& signals_;
    std::vector<int> axis_ids_;
    std::map<int, std::string> axis_names_; // axis id -> epics.name (axis PLC PVs)
    std::vector<int> storage_ids_; // `storages:` of the IOC file
    std::vector<int> pcomp_ids_;   // `pcomp:` of the IOC file
    std::vector<std::vector<int>> groups_; // ECMC axis groups (axis.group), in order of appearance: axis ids
    std::vector<std::pair<int, std::unique_ptr<LookupTable>>> luts_; // `luts:` of the IOC file
    std::unique_ptr<plc::M2m> m2m_; // `m2m:`, or a PLC calls m2m_*
    std::vector<std::unique_ptr<plc::Plugin>> plugins_;
    std::vector<plc::PlcSource> sources_;
    std::vector<std::optional<int>> bus_of_; // per source: plcs[].bus (axis PLCs: none)
    std::vector<std::unique_ptr<plc::PlcRuntime>> runtimes_; // per cycle (null: no PLC there)
    std::vector<std::pair<std::size_t, std::size_t>> where_; // per source: (cycle, index in its runtime)
    std::vector<std::string> owners_; // "plc0", "ax1.plc": the prefix of each PLC's items
    pv::Database& db_;
    std::vector<std::uint64_t> seen_faults_; // fault counts already looked at, per PLC
    std::vector<std::string> last_fault_;    // the last fault logged, per PLC
};

// Reads a general PLC entry or an axis file's `plc:` into a source (file text + code lines,
// macros, include path: the file's directory first). Throws Error if a file cannot be read.
plc::PlcSource plc_source(const config::PlcEntry& e);

} // namespace beamctl::ioc
