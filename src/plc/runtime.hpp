// The PLCs of an IOC in the RT cycle (ECMC's PLC main). General PLCs run in stage GeneralPlcs
// after the axes, each at its own rate; an axis PLC runs just before its axis (AxisHook). Both
// wait for the first cycle in which every bus is OK, as ECMC's do.
//
// Names in PLC code bind once, at compile time (ARCHITECTURE.md §1, specs/ecmc.md §2):
//   ax<n>.*                    the axis's AxisVariables (ECMC names; writability from the table)
//   ec<m>.s<k>.<entry>[.<bit>] process-data entries, copied in before each scan and out after it
//   ec<m>.masterstatus         when the scan changed them (ECMC's ecmcPLCDataIF); inputs are
//                              read-only
//   static.<name>              per PLC, kept between scans (init 0)
//   global.<name>              shared by all PLCs of the IOC
//   plc<n>.enable|error|scantime|firstscan|dbg   a general PLC's own variables
//   ax<n>.plc.enable|error|scantime|firstscan|dbg  an axis PLC's
//   ds<n>.append|data|index|size|full|clear|error   data storage n (daq::DataStorage), read
//                              before each scan and applied after it when the scan changed them
//   pcomp<n>.enable|start|step|width|pulses|pre_start|relative|dir (rw), .out|active|produced|
//                              health|state (r): position-compare blocks (Options::cells)
//   plugin constants
// Functions: ExprTk's math (the language), ec_* bit operations and ec_get_time, mc_* motion
// function blocks (on the axis command API, acting on the rising edge of `execute`, returning
// ECMC error codes), mc_grp_* on ECMC axis groups, ds_* data storage functions, lut_get_value,
// epics_get_started/state, and plugin functions.
// A run-time fault (index out of range, loop budget) latches the PLC's `error` (cleared when it
// is enabled again) and the scan's remaining code is skipped; the next scan runs normally.
//
// Threading: the constructor and add() on a non-RT thread before the cycle starts; run() and
// before_axis() on the RT thread; request_enable(), status(), fault() and pop_output() on ONE
// non-RT thread (the IOC loop).
#pragma once

#include "core/macros.hpp"
#include "core/lookup_table.hpp"
#include "core/spsc_queue.hpp"
#include "daq/data_storage.hpp"
#include "motion/axis.hpp"
#include "motion/axis_group.hpp"
#include "plc/m2m.hpp"
#include "plc/plugin.hpp"
#include "plc/program.hpp"
#include "registry/memmap.hpp"
#include "registry/signal.hpp"
#include "rt/engine.hpp"

#include <atomic>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace beamctl::plc {

// A process-data entry PLC code may name, as the IOC resolves it.
struct EcEntry {
    registry::BoundSignal signal; // unbound when only checking
    enum class Kind : uint8_t { Integer, Float32, Float64 } kind = Kind::Integer;
    bool writable = false;        // an output entry
};

// One PLC to compile.
struct PlcSource {
    int id = 0;            // general: plc<id>; axis PLC: the axis id (ax<id>.plc)
    bool axis_plc = false;
    std::string file;      // reported in errors; includes are searched next to it
    std::string text;      // the code
    double rate_ms = -1;   // general PLCs: scan period [ms]; -1 (or <= one cycle): every cycle
    bool enable = true;    // plc<n>.enable at start
    MacroMap macros;       // PLC_MACROS; SELF, SELF_ID, M and M_ID are added when absent
    std::vector<std::string> include_path;
    std::vector<std::string> libraries; // files of `function` definitions
    bool strict = false;                // compile errors for what ECMC's ExprTk refuses
};

class PlcRuntime : public rt::Stage, public motion::AxisHook {
public:
    struct Options {
        double cycle_s = 0.001; // engine period [s]
        // Accept every well-formed name of the known namespaces without binding it to anything
        // real (`beamctl plc check` without an IOC): each gets its own cell.
        bool check_only = false;
        // Resolves "ec0.s3.binaryInput01" / "ec0.masterstatus" (no bit); nullopt with `why`
        // set if there is no such entry. Unset: ec names are unknown (unless check_only).
        std::function<std::optional<EcEntry>(const std::string& name, std::string& why)> ec;
        // ec<m>.masterstatus of every bus: PLCs start in the first cycle in which all are 1.
        std::vector<registry::BoundSignal> bus_ok;
        std::vector<motion::Axis*> axes;   // in AxisGroup order (before_axis indexes); ids from params
        // check_only: the axis ids that exist (nullopt: any id)
        std::optional<std::vector<int>> known_axis_ids;
        std::vector<Plugin*> plugins;      // functions and constants by name
        // ECMC axis groups (axis.group): the axis ids of group g, for mc_grp_*(g, ...)
        std::vector<std::vector<int>> groups;
        std::vector<daq::DataStorage*> storages; // ds<id> by DataStorage::id()
        // Cells of other blocks of the cycle the host offers by name (pcomp<n>.enable, ...):
        // asked after the built-in namespaces; nullopt: not one of them.
        std::function<std::optional<Binding>(const std::string& name)> cells;
        std::vector<registry::MemMap*> memmaps;  // ec_*_mm_*(id): ECMC's memory map ids in order (null: not here)
        std::vector<std::pair<int, const LookupTable*>> luts; // lut_get_value(id, x): id 0..15
        M2m* m2m = nullptr; // m2m_* (null: their calls report 0x2005A, shared memory not valid)
        // check_only: the storage ids that exist (nullopt: any id 0..31)
        std::optional<std::vector<int>> known_storage_ids;
        std::uint64_t loop_budget = 1000000; // loop iterations per scan before a fault
    };
    explicit PlcRuntime(Options options);
    ~PlcRuntime() override;
    PlcRuntime(const PlcRuntime&) = delete;
    PlcRuntime& operator=(const PlcRuntime&) = delete;

    // Compiles and adds a PLC (non-RT, before the cycle starts). Throws CompileError with every
    // error (file:line:col and a caret), or Error (a second PLC with the same id, a bad rate).
    void add(const PlcSource& source);

    const char* name() const noexcept override { return "plcs"; }
    // RT: the general PLCs whose turn it is.
    void run(const rt::CycleInfo& c) noexcept override;
    // RT: the axis PLC of the axis at `index` of the group (called by the AxisGroup).
    void before_axis(std::size_t index, const rt::CycleInfo& c) noexcept override;

    // Non-RT (IOC loop) face.
    std::size_t size() const { return plcs_.size(); }
    const PlcSource& source(std::size_t i) const;
    // "plc0" or "ax3.plc": the name of its variables.
    std::string prefix(std::size_t i) const;
    // Sets plc<n>.enable from outside (a PV); applied at the PLC's next cycle.
    void request_enable(std::size_t i, bool on) noexcept;
    struct Status {
        bool enabled = false;
        bool firstscan = true;
        int error = 0;            // latched RunStatus of the last fault (0: none)
        double scantime_s = 0;
        std::uint64_t scans = 0, faults = 0;
    };
    Status status(std::size_t i) const noexcept;
    // Where the latched fault happened ("file:line:col: what"), "" if none.
    std::string fault(std::size_t i) const;
    // println/print output of the PLCs, one chunk at a time ("plc0: text"). Lines that did not
    // fit the queue are counted in output_dropped().
    bool pop_output(std::string& text);
    std::uint64_t output_dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }

    // The process-data entries ("ec0.s3.binaryOutput01", without a bit) that PLC i's code
    // assigns: the PLC is their writer.
    std::vector<std::string> written_entries(std::size_t i) const;

    // Non-RT: the IOC's EPICS state as EPICS's initHookState (16: initHookAfterIocRunning), for
    // epics_get_state() and epics_get_started().
    void set_epics_state(int state) noexcept { epics_state_.store(state, std::memory_order_relaxed); }

    // Some PLC's code calls an m2m_* function (the IOC then opens the shared memory).
    bool uses_m2m() const noexcept { return uses_m2m_; }

    // The cells a name is bound to (tests and diagnostics; nullptr if no PLC uses it).
    const double* global(const std::string& name) const;
    const double* static_variable(std::size_t plc, const std::string& name) const;

    struct Plc; // internal

private:
    friend struct Plc;
    void scan(Plc& p, const rt::CycleInfo& c) noexcept;
    bool buses_ok() noexcept;

    Options opt_;
    // plc<n>.* / ax<n>.plc.* by (id, axis PLC): made when first named (by the PLC itself or by
    // another PLC's code, before or after it is added); stable addresses
    struct PlcVars {
        double enable = 0, error = 0, scantime = 0, firstscan = 1, dbg = 0;
    };
    std::map<std::pair<int, bool>, std::unique_ptr<PlcVars>> plc_vars_;
    PlcVars& plc_vars(int id, bool axis_plc);
    std::vector<std::unique_ptr<Plc>> plcs_;
    std::vector<Plc*> axis_plcs_; // by AxisGroup index
    std::vector<int> axis_by_id_; // axis id (mc_* first argument) -> AxisGroup index, -1 none
    std::vector<std::vector<motion::Axis*>> groups_; // ECMC axis groups' members
    std::deque<double> globals_cells_;
    std::map<std::string, double*> globals_;
    bool started_ = false; // every bus was OK once
    std::uint64_t cycle_ns_ = 0;
    // mc_* function-block memory, per axis (by AxisGroup index): last `execute` per block
    struct McMemory {
        bool abs = false, rel = false, vel = false, home = false, halt = false;
    };
    std::vector<McMemory> mc_;
    double mc_error_ = 0; // last mc_* error (mc_get_err)
    double ec_error_ = 0; // last ec_* error (ec_get_err)
    double ds_error_ = 0; // last ds_* error (ds_get_err)
    daq::DataStorage* storage_by_id_[daq::kMaxStorages] = {};
    static constexpr int kMaxLuts = 16;
    const LookupTable* lut_by_id_[kMaxLuts] = {};
    std::atomic<int> epics_state_{0};
    double m2m_error_ = 0;
    bool uses_m2m_ = false;
    struct Output {
        int plc = 0;
        std::uint16_t len = 0;
        char text[1024];
    };
    SpscQueue<Output> output_;
    std::atomic<std::uint64_t> dropped_{0};

    friend struct Builtins;
};

} // namespace beamctl::plc
