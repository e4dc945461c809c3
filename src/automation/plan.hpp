// Plans (seed 003's bluesky plans, built into the IOC): step scans over motor records (scan: the
// axes move together through `points`; grid: nested, outer axis first, optionally snaking; list:
// given positions), alignment by a curve fit (align: seed 003's rocking curve: scan around a
// centre, fit a Lorentzian / Gaussian / edge to the signal, move to the fitted centre only if the
// fit is good, repeat finer; else return to the start and latch a state machine), and sequences
// of them with moves and puts (the seed's alignment procedure). Declared in YAML
// (config::PlanEntry), run inside the IOC, so a run goes on with no client attached. PVs under
// $(P)<name>:
//   Start     busy    put 1 (with a callback: it completes when the run ends, failed unless it
//                     ended Done) starts a run with Args; refused while the plan runs
//   Args      waveform CHAR  "name=value ..." for the next run (the plan's `args`; others keep
//                     their defaults)
//   Pause, Resume, Abort  bo  pause after the current point / go on / stop the motors now and end
//   Status    mbbi    Idle, Running, Paused, Done, Aborted, Failed
//   Point, Points longin  the point of the current scan, its points; Progress ai [%] of the run
//   Message   waveform CHAR  what the run does or why it ended; File: the run's HDF5/NeXus file;
//   FilePath  waveform CHAR  the directory of the next run's file ("" none)
//   X, Y, Fit waveform DOUBLE  live: the first motor's readbacks, the signal, the fitted curve
//   Overhead  ai [ms] the run's mean time a point beyond motion, triggers and dwell
//   Center, Width, Amplitude, Background (and ...Err), RedChi2, RSquared ai, FitOk bi (align)
// A point: every axis moves to its position (a move that is refused or ends short fails the run),
// the triggers are put with a callback, the dwell passes, the detectors are read (the signal and
// a fit's sigma computed from them), the row is recorded and the live PVs posted. A run writes
// one file when it ends (daq/plan_file.hpp), whatever the ending.
// Threading: the IOC loop (which owns the database and the CA client); poll() every 10 ms, and
// at once / at a dwell's end through the scheduler the IOC sets.
#pragma once

#include "config/ioc_config.hpp"
#include "pv/database.hpp"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ca {
class Client;
}

namespace beamctl::automation {

class StateMachines;

// Parses a run's arguments, "name=value ..." (spaces, commas or semicolons between them), into the
// values of the plan's declared `args` (defaults where not given): false with why on a name the
// plan does not take or a value that is not a finite number. Text from clients (the Args PV, the
// command line): any bytes are safe.
bool parse_plan_args(const std::vector<std::pair<std::string, double>>& declared, const std::string& text,
                     std::vector<double>& out, std::string& why);

class Plans {
public:
    // Compiles every expression and loads the records into `db` (before init_records). Throws
    // Error naming the configuration entry (file:line:col) that is wrong.
    Plans(const std::vector<config::PlanEntry>& cfg, const std::string& prefix, const std::string& ioc_name, pv::Database& db,
          std::function<double()> clock);
    ~Plans();
    Plans(const Plans&) = delete;
    Plans& operator=(const Plans&) = delete;

    // After init_records: motors, detectors and names found here (others: CA, after connect()).
    void start();
    bool needs_client() const;
    void connect(ca::Client& client);
    // An align plan's `latch:` machine (the IOC's state machines).
    void set_state_machines(StateMachines* fsms) { fsms_ = fsms; }
    // Asks the owner's loop to call poll() after `delay_s` (0: soon): a motion's end, a dwell's.
    // Without one, poll() every 10 ms is all there is (the virtual-time tests).
    void set_scheduler(std::function<void(double delay_s)> wake) { wake_ = std::move(wake); }
    void poll();
    // Aborts every run now (the IOC stops): motors stopped, files written.
    void abort_all(const std::string& why);

    std::size_t size() const;
    // What the PVs say, for tests: "" when there is no such plan.
    std::string status(const std::string& plan) const;

    struct Plan; // internal
    struct Run;
    struct Task;

private:
    friend struct Run;
    pv::Database& db_;
    std::function<double()> clock_;
    std::function<void(double)> wake_;
    StateMachines* fsms_ = nullptr;
    std::string ioc_name_;
    std::vector<std::unique_ptr<Plan>> plans_;
    std::vector<std::unique_ptr<Run>> runs_;
    bool polling_ = false;
    Plan* find(const std::string& name) const;
    pv::PutStatus start_run(Plan& p);
    void finish(Run& r);
    void wake(double delay_s) {
        if (wake_) wake_(delay_s);
    }
};

} // namespace beamctl::automation
