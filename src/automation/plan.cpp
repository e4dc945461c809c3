// Plans: step scans, curve-fit alignment and sequences, run inside the IOC (see plan.hpp).
#include "automation/plan.hpp"

#include "automation/expression_names.hpp"
#include "automation/fit.hpp"
#include "automation/motor_port.hpp"
#include "automation/number_text.hpp"
#include "automation/state_machine.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "daq/plan_file.hpp"
#include "plc/program.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <optional>
#include <sstream>

namespace beamctl::automation {

namespace {

log::Logger lg("plans");

enum Status { kIdle, kRunning, kPaused, kDone, kAborted, kFailed };
constexpr const char* kStatusNames[] = {"Idle", "Running", "Paused", "Done", "Aborted", "Failed"};
constexpr uint32_t kLivePoints = 4096;    // NELM of the live waveforms (a longer scan shows its first points)
constexpr double kMaxPoints = 1000000;    // a scan's points (grid: all of them)

std::string fmt(double v) { return number_text(v, 6); }

// A PV name as a dataset name: "SND:T1:TH1.RBV" -> "SND_T1_TH1_RBV".
std::string label_of(const std::string& pv) {
    std::string s = pv;
    for (char& c : s)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
    return s;
}

// Local time now, strftime's `format` ("%Y-%m-%dT%H:%M:%S%z" for the file's times, "%Y%m%d-%H%M%S"
// for its name).
std::string local_time(const char* format) {
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    localtime_r(&t, &tm);
    char b[40];
    std::strftime(b, sizeof b, format, &tm);
    return b;
}

// Completions of a set of asynchronous operations (moves, puts) the task waits for; shared with
// their callbacks, so that a callback after the task went (an abort) writes into a live object.
struct Pending {
    int outstanding = 0;
    bool failed = false;
    std::string why;
    double t_done = 0; // when the last one completed [clock s]
};

} // namespace

// ---------------------------------------------------------------- a plan
struct Plans::Plan {
    config::PlanEntry cfg;
    std::string p; // "$(P)<name>:"
    ExpressionNames host;
    std::vector<double> args, names, dets; // expression slots (never resized after binding)
    double signal = 0, result = 0;
    std::vector<plc::Program> progs;
    std::vector<std::unique_ptr<PvReader>> name_readers, det_readers;
    std::vector<std::unique_ptr<MotorPort>> motors; // axes' (scan, grid, list), or the aligned one
    std::vector<std::string> motor_pvs;
    std::vector<std::unique_ptr<PvWriter>> triggers;
    // compiled expressions (indices into progs; -1 none)
    int dwell = -1, points = -1, signal_expr = -1, sigma = -1, center = -1;
    std::vector<int> start, stop, axis_points;
    std::vector<std::vector<int>> positions;
    std::vector<int> pass_range, pass_points;
    struct StepX {
        Plan* plan = nullptr;                 // Plan
        std::vector<int> args;                // Plan: index into the child's args, expression here
        std::vector<int> arg_slot;
        std::vector<std::unique_ptr<MotorPort>> motors; // Move
        std::vector<int> moves;
        std::unique_ptr<PvWriter> writer;     // Put
        int value = -1;
    };
    std::vector<StepX> steps;
    std::vector<double> next_args;            // what Args asked for the next run
    Run* run = nullptr;                       // the run using this plan now (its own or a sequence's)
    int runs = 0;
    pv::Record *start_r = nullptr, *args_r = nullptr, *status_r = nullptr, *point_r = nullptr, *points_r = nullptr,
               *progress_r = nullptr, *message_r = nullptr, *file_r = nullptr, *filepath_r = nullptr, *x_r = nullptr,
               *y_r = nullptr, *fit_r = nullptr, *overhead_r = nullptr;
    pv::Record *center_r = nullptr, *center_err_r = nullptr, *width_r = nullptr, *width_err_r = nullptr, *amp_r = nullptr,
               *amp_err_r = nullptr, *bg_r = nullptr, *chi2_r = nullptr, *r2_r = nullptr, *fitok_r = nullptr;
    bool finishing = false; // the plan's own write of Start = 0 (the hook lets it through)

    explicit Plan(const config::PlanEntry& c) : cfg(c), host("plan '" + c.name + "'") {}

    int compile(const std::string& text, const std::string& where, const std::string& what) {
        try {
            progs.push_back(plc::Program::compile("plan_result_ := (" + text + ");", what, host));
        } catch (const plc::CompileError& e) {
            throw Error(where + ": plan '" + cfg.name + "': " + what + " '" + text + "': " + e.what());
        }
        return int(progs.size() - 1);
    }
    // Evaluates a compiled expression with the names read now; false with `why` when a name is
    // not readable or the result is not a number.
    bool eval(int k, double& out, std::string& why) {
        for (std::size_t j = 0; j < name_readers.size(); ++j)
            if (!name_readers[j] || !name_readers[j]->read(names[j])) {
                why = "name '" + cfg.names[j].first + "' (" + cfg.names[j].second + ") is not readable";
                return false;
            }
        result = 0;
        if (progs[std::size_t(k)].run() != 0) {
            why = "the expression failed: " + progs[std::size_t(k)].fault_location();
            return false;
        }
        if (!std::isfinite(result)) {
            why = "an expression gave " + fmt(result);
            return false;
        }
        out = result;
        return true;
    }
    int arg_index(const std::string& n) const {
        for (std::size_t i = 0; i < cfg.args.size(); ++i)
            if (cfg.args[i].first == n) return int(i);
        return -1;
    }
    std::string arg_list() const {
        std::string s;
        for (const auto& [n, v] : cfg.args) s += (s.empty() ? "" : ", ") + n;
        return s.empty() ? "no arguments" : s;
    }
};

// ---------------------------------------------------------------- tasks
struct Plans::Task {
    enum class R { Wait, Done, Failed };
    virtual ~Task() = default;
    // Advances as far as it can now; Failed with `why`.
    virtual R advance(Run& run, double now) = 0;
    virtual void abort() = 0;           // stops the motors it moves, now
    virtual double progress() const = 0; // 0..1
    std::string why;
};

struct Plans::Run {
    Plans& plans;
    Plan& top;
    int number = 0;
    double t0 = 0;
    std::unique_ptr<Task> task;
    bool pause = false, paused = false, abort = false, ended = false;
    std::vector<Plan*> used; // plans marked in use by this run
    daq::PlanRun data;
    double overhead_sum = 0;
    long overhead_n = 0;
    std::string latch;       // a state machine to latch (an align step failed)
    std::string abort_why;   // who aborted: "" (the Abort PV), "the IOC is stopping"
    std::vector<std::string> motors; // the motor records it may move (no other run may move them)
    Run(Plans& p, Plan& t) : plans(p), top(t) {}

    pv::Database& db() { return plans.db_; }
    double now() const { return plans.clock_(); }
    void wake(double delay_s) { plans.wake(delay_s); }
    // For completion callbacks: records when they came, asks for a poll.
    std::function<double()> clock() const { return plans.clock_; }
    std::function<void()> waker() const {
        Plans* pl = &plans;
        return [pl] { pl->wake(0); };
    }

    void use(Plan& p) {
        p.run = this;
        used.push_back(&p);
    }
    void status(Plan& p, int st) { pv::set_value(plans.db_, *p.status_r, st, false); }
    void message(Plan& p, const std::string& m) { pv::set_text(plans.db_, *p.message_r, m); }
    // Moves `motors` to `targets` together; `pending` counts the completions.
    std::shared_ptr<Pending> move(const std::vector<MotorPort*>& motors, const std::vector<double>& targets) {
        auto pend = std::make_shared<Pending>();
        pend->outstanding = int(motors.size());
        std::function<double()> clock = plans.clock_;
        std::function<void()> wk = waker();
        for (std::size_t k = 0; k < motors.size(); ++k)
            motors[k]->move(targets[k], [pend, wk, clock](bool ok, const std::string& why) {
                if (!ok && !pend->failed) pend->failed = true, pend->why = why;
                if (--pend->outstanding == 0) {
                    pend->t_done = clock();
                    wk();
                }
            });
        return pend;
    }
};

namespace {

using Task = Plans::Task;
using Plan = Plans::Plan;
using Run = Plans::Run;

// One scan: points of positions of `motors`, each moved to, triggered, dwelt at and read; then
// (return) back to where the motors were. Its data is a scan of the run's file, filled as it goes.
struct ScanTask final : Task {
    Plan& plan;
    std::vector<MotorPort*> motors;
    std::vector<std::vector<double>> targets; // [point][motor]
    std::vector<double> home;                 // where the motors were
    bool return_after = false;
    double dwell = 0;
    std::size_t scan = 0; // index in the run's data
    std::size_t i = 0;    // the point under way
    enum class Phase { Start, Moving, Trigger, Triggering, Dwell, Returning, End } phase = Phase::Start;
    std::shared_ptr<Pending> pend;
    double t_motion = 0, t_trigger = 0, trigger_s = 0, dwell_end = 0;
    std::vector<double> xs, ys; // live: first motor readbacks, signal
    bool has_signal = false, has_sigma = false;

    ScanTask(Plan& p, std::vector<MotorPort*> m, std::vector<std::vector<double>> t, bool ret, double dw)
        : plan(p), motors(std::move(m)), targets(std::move(t)), return_after(ret), dwell(dw) {}

    void open(Run& run, const std::string& name, const std::string& title) {
        daq::PlanScan s;
        s.name = name, s.title = title;
        std::vector<std::string> labels;
        for (MotorPort* m : motors) {
            const std::string l = label_of(m->name());
            s.columns.push_back({l, units(run, m->name()), m->name() + ".RBV", {}});
            s.columns.push_back({l + "_setpoint", units(run, m->name()), m->name() + ".VAL", {}});
        }
        for (std::size_t k = 0; k < plan.cfg.detectors.size(); ++k)
            s.columns.push_back({plan.cfg.detectors[k].first, {}, plan.cfg.detectors[k].second, {}});
        has_signal = plan.signal_expr >= 0 || plan.cfg.type == config::PlanEntry::Type::Align;
        has_sigma = plan.sigma >= 0;
        if (has_signal) s.columns.push_back({"signal", {}, plan.cfg.signal.empty() ? plan.cfg.detectors[0].second : plan.cfg.signal, {}});
        if (has_sigma) s.columns.push_back({"sigma", {}, plan.cfg.sigma, {}});
        s.columns.push_back({"time", "s", {}, {}});
        s.axis = s.columns[0].name;
        s.signal = has_signal ? "signal" : plan.cfg.detectors[0].first;
        scan = run.data.scans.size();
        run.data.scans.push_back(std::move(s));
        pv::set_value(run.db(), *plan.points_r, double(targets.size()), false);
        pv::set_value(run.db(), *plan.point_r, 0, false);
        pv::set_array(run.db(), *plan.x_r, nullptr, 0);
        pv::set_array(run.db(), *plan.y_r, nullptr, 0);
        pv::set_array(run.db(), *plan.fit_r, nullptr, 0);
    }
    static std::string units(Run& run, const std::string& motor) {
        pv::Address a;
        char s[pv::kStringSize] = {};
        if (!run.db().resolve(motor + ".EGU", a) || !run.db().get(a, pv::Prim::String, s, 1)) return {};
        return s;
    }
    double progress() const override { return targets.empty() ? 1 : double(std::min(i, targets.size())) / double(targets.size()); }
    void abort() override {
        for (MotorPort* m : motors) m->stop();
    }
    R fail(std::string w) {
        why = std::move(w);
        return R::Failed;
    }

    R advance(Run& run, double now) override {
        for (;;) {
            switch (phase) {
            case Phase::Start: {
                if (i >= targets.size()) {
                    if (!return_after) return R::Done;
                    run.message(plan, "returning to the start");
                    pend = run.move(motors, home);
                    phase = Phase::Returning;
                    continue;
                }
                if (run.pause) {
                    if (!run.paused) {
                        run.paused = true;
                        run.status(run.top, kPaused);
                        if (&plan != &run.top) run.status(plan, kPaused);
                        run.message(run.top, "paused before point " + std::to_string(i + 1) + "/" + std::to_string(targets.size()));
                    }
                    return R::Wait;
                }
                for (MotorPort* m : motors)
                    if (!m->state().connected) return fail(m->name() + " is not connected");
                pend = run.move(motors, targets[i]);
                phase = Phase::Moving;
                continue;
            }
            case Phase::Moving:
                if (pend->outstanding > 0) return R::Wait;
                if (pend->failed) return fail("point " + std::to_string(i + 1) + ": " + pend->why);
                t_motion = pend->t_done;
                phase = Phase::Trigger;
                continue;
            case Phase::Trigger: {
                t_trigger = now;
                if (plan.triggers.empty()) { // the dwell counts from the motion's end
                    trigger_s = 0;
                    dwell_end = t_motion + dwell;
                    phase = Phase::Dwell;
                    if (dwell_end > now) run.wake(dwell_end - now);
                    continue;
                }
                pend = std::make_shared<Pending>();
                pend->outstanding = int(plan.triggers.size());
                std::function<double()> clock = run.clock();
                std::function<void()> wk = run.waker();
                for (std::size_t k = 0; k < plan.triggers.size(); ++k) {
                    if (!plan.triggers[k]) return fail("trigger " + plan.cfg.triggers[k].first + " is not reachable");
                    auto pp = pend;
                    plan.triggers[k]->put(plan.cfg.triggers[k].second, true, [pp, wk, clock](bool ok, const std::string& w) {
                        if (!ok && !pp->failed) pp->failed = true, pp->why = w;
                        if (--pp->outstanding == 0) {
                            pp->t_done = clock();
                            wk();
                        }
                    });
                }
                phase = Phase::Triggering;
                continue;
            }
            case Phase::Triggering:
                if (pend->outstanding > 0) return R::Wait;
                if (pend->failed) return fail("point " + std::to_string(i + 1) + ": " + pend->why);
                trigger_s = pend->t_done - t_trigger;
                dwell_end = pend->t_done + dwell; // from the triggers' end
                if (dwell_end > now) run.wake(dwell_end - now);
                phase = Phase::Dwell;
                continue;
            case Phase::Dwell: {
                if (now + 1e-6 < dwell_end) return R::Wait;
                if (std::string w; !read(run, now, w)) return fail("point " + std::to_string(i + 1) + ": " + w);
                // beyond motion, triggers and dwell: from the motion's end to this point's row
                const double t_end = run.now();
                run.overhead_sum += std::max(0.0, t_end - t_motion - trigger_s - dwell);
                ++run.overhead_n;
                ++i;
                phase = Phase::Start;
                continue;
            }
            case Phase::Returning:
                if (pend->outstanding > 0) return R::Wait;
                if (pend->failed) return fail("returning to the start: " + pend->why);
                phase = Phase::End;
                return R::Done;
            case Phase::End:
                return R::Done;
            }
        }
    }

    // Reads the detectors, computes the signal, records the row and posts the live PVs.
    bool read(Run& run, double now, std::string& why) {
        for (std::size_t k = 0; k < plan.det_readers.size(); ++k)
            if (!plan.det_readers[k] || !plan.det_readers[k]->read(plan.dets[k])) {
                why = "detector " + plan.cfg.detectors[k].first + " (" + plan.cfg.detectors[k].second + ") is not readable";
                return false;
            }
        double sig = plan.dets[0], sigma = 0;
        if (plan.signal_expr >= 0 && !plan.eval(plan.signal_expr, sig, why)) return (why = "signal: " + why), false;
        plan.signal = sig;
        if (plan.sigma >= 0 && !plan.eval(plan.sigma, sigma, why)) return (why = "sigma: " + why), false;
        auto& cols = run.data.scans[scan].columns;
        std::size_t c = 0;
        double x0 = 0;
        for (std::size_t k = 0; k < motors.size(); ++k) {
            const MotorPort::State st = motors[k]->state();
            if (k == 0) x0 = st.rbv;
            cols[c++].values.push_back(st.rbv);
            cols[c++].values.push_back(targets[i][k]);
        }
        for (double d : plan.dets) cols[c++].values.push_back(d);
        if (has_signal) cols[c++].values.push_back(sig);
        if (has_sigma) cols[c++].values.push_back(sigma);
        cols[c++].values.push_back(now - run.t0);
        xs.push_back(x0), ys.push_back(sig);
        pv::Database& db = run.db();
        const uint32_t n = uint32_t(std::min<std::size_t>(xs.size(), kLivePoints));
        pv::set_array(db, *plan.x_r, xs.data(), n);
        pv::set_array(db, *plan.y_r, ys.data(), n);
        pv::set_value(db, *plan.point_r, double(i + 1), false);
        return true;
    }
};

// Moves motors together to positions (a sequence's move step; an align's move to the centre).
struct MoveTask final : Task {
    std::vector<MotorPort*> motors;
    std::vector<double> targets;
    std::shared_ptr<Pending> pend;
    MoveTask(std::vector<MotorPort*> m, std::vector<double> t) : motors(std::move(m)), targets(std::move(t)) {}
    double progress() const override { return pend && pend->outstanding == 0 ? 1 : 0; }
    void abort() override {
        for (MotorPort* m : motors) m->stop();
    }
    R advance(Run& run, double) override {
        if (!pend) {
            for (MotorPort* m : motors)
                if (!m->state().connected) return (why = m->name() + " is not connected"), R::Failed;
            pend = run.move(motors, targets);
        }
        if (pend->outstanding > 0) return R::Wait;
        if (pend->failed) return (why = pend->why), R::Failed;
        return R::Done;
    }
};

// A put (a sequence's put step), with or without its callback.
struct PutTask final : Task {
    PvWriter* writer;
    double value;
    bool wait;
    std::shared_ptr<Pending> pend;
    PutTask(PvWriter* w, double v, bool wt) : writer(w), value(v), wait(wt) {}
    double progress() const override { return pend && pend->outstanding == 0 ? 1 : 0; }
    void abort() override {}
    R advance(Run& run, double) override {
        if (!pend) {
            pend = std::make_shared<Pending>();
            pend->outstanding = 1;
            auto pp = pend;
            std::function<void()> wk = run.waker();
            writer->put(value, wait, [pp, wk](bool ok, const std::string& w) {
                if (!ok) pp->failed = true, pp->why = w;
                pp->outstanding = 0;
                wk();
            });
        }
        if (pend->outstanding > 0) return R::Wait;
        if (pend->failed) return (why = pend->why), R::Failed;
        return R::Done;
    }
};

} // namespace

// Scan, grid and list tasks from a plan's expressions (its args set); nullptr with `why`.
static std::unique_ptr<Task> make_task(Plan& plan, Run& run, const std::string& scan_name, std::string& why);

namespace {

// Seed 003's rocking curve: per pass, a scan of `range` around the centre so far, a fit of the
// signal, a check; a good fit moves the motor to its centre (the next pass's centre), a bad one
// (or a failed move) ends the alignment with the motor back where it started.
struct AlignTask final : Task {
    Plan& plan;
    std::string scan_prefix;
    MotorPort* motor;
    double home = 0, center = 0;
    std::size_t pass = 0;
    std::unique_ptr<ScanTask> scan;
    std::unique_ptr<MoveTask> move;
    std::string failure; // set once the alignment failed: the motor is going home
    enum class Phase { Pass, Scanning, Centering, Returning } phase = Phase::Pass;
    FitModel model = FitModel::Lorentzian;

    AlignTask(Plan& p, std::string prefix) : plan(p), scan_prefix(std::move(prefix)), motor(p.motors[0].get()) {
        parse_fit_model(p.cfg.model, model);
    }
    double progress() const override {
        const double n = double(plan.cfg.passes.size());
        return std::min(1.0, (double(pass) + (scan ? scan->progress() : 0)) / n);
    }
    void abort() override { motor->stop(); }
    R advance(Run& run, double now) override {
        for (;;) {
            switch (phase) {
            case Phase::Pass: {
                if (pass == 0) {
                    const MotorPort::State st = motor->state();
                    if (!st.connected) return (why = motor->name() + " is not connected"), R::Failed;
                    home = st.rbv;
                    center = st.rbv;
                    if (plan.center >= 0 && !plan.eval(plan.center, center, why)) return (why = "center: " + why), R::Failed;
                }
                if (pass >= plan.cfg.passes.size()) {
                    run.message(plan, "aligned " + motor->name() + " at " + fmt(center));
                    return R::Done;
                }
                double range = 0, points = 0;
                if (!plan.eval(plan.pass_range[pass], range, why) || !plan.eval(plan.pass_points[pass], points, why))
                    return (why = "pass " + std::to_string(pass + 1) + ": " + why), R::Failed;
                const long n = std::lround(points);
                if (n < 5 || n > long(kMaxPoints) || !(range > 0))
                    return (why = "pass " + std::to_string(pass + 1) + ": needs range > 0 and at least 5 points (range " + fmt(range) +
                                  ", points " + fmt(points) + ")"),
                           R::Failed;
                std::vector<std::vector<double>> t;
                for (long k = 0; k < n; ++k) t.push_back({center - range / 2 + range * double(k) / double(n - 1)});
                double dwell = 0;
                if (plan.dwell >= 0 && !plan.eval(plan.dwell, dwell, why)) return (why = "dwell: " + why), R::Failed;
                scan = std::make_unique<ScanTask>(plan, std::vector<MotorPort*>{motor}, std::move(t), false, std::max(0.0, dwell));
                const std::string tag = std::to_string(pass + 1) + "/" + std::to_string(plan.cfg.passes.size());
                scan->open(run, scan_prefix + "pass" + std::to_string(pass + 1),
                           plan.cfg.name + " pass " + tag + ": " + motor->name() + " " + fmt(center - range / 2) + " .. " +
                               fmt(center + range / 2) + ", " + std::to_string(n) + " points, " + plan.cfg.model + " fit");
                run.message(plan, "pass " + tag + ": scanning " + motor->name() + " around " + fmt(center));
                phase = Phase::Scanning;
                continue;
            }
            case Phase::Scanning: {
                const R r = scan->advance(run, now);
                if (r == R::Wait) return r;
                if (r == R::Failed) return go_home(run, scan->why);
                if (std::string bad = fit(run); !bad.empty()) return go_home(run, "pass " + std::to_string(pass + 1) + ": " + bad);
                move = std::make_unique<MoveTask>(std::vector<MotorPort*>{motor}, std::vector<double>{center});
                run.message(plan, "pass " + std::to_string(pass + 1) + ": moving " + motor->name() + " to the fitted centre " + fmt(center));
                phase = Phase::Centering;
                continue;
            }
            case Phase::Centering: {
                const R r = move->advance(run, now);
                if (r == R::Wait) return r;
                if (r == R::Failed) return go_home(run, "moving to the centre: " + move->why);
                move.reset();
                scan.reset();
                ++pass;
                phase = Phase::Pass;
                continue;
            }
            case Phase::Returning: {
                const R r = move->advance(run, now);
                if (r == R::Wait) return r;
                why = failure + (r == R::Failed ? "; returning to " + fmt(home) + " failed too: " + move->why
                                                : "; " + motor->name() + " is back at " + fmt(home));
                if (!plan.cfg.latch.empty()) run.latch = plan.cfg.latch;
                return R::Failed;
            }
            }
        }
    }
    R go_home(Run& run, const std::string& w) {
        failure = plan.cfg.name + ": " + w;
        LOG_WARN(lg, failure);
        run.message(plan, failure + "; returning " + motor->name() + " to " + fmt(home));
        move = std::make_unique<MoveTask>(std::vector<MotorPort*>{motor}, std::vector<double>{home});
        phase = Phase::Returning;
        return advance(run, run.now());
    }
    // Fits the pass's signal; "" and the new centre when the fit is good, else why not.
    std::string fit(Run& run) {
        daq::PlanScan& s = run.data.scans[scan->scan];
        auto col = [&](const std::string& n) -> const std::vector<double>& {
            for (const auto& c : s.columns)
                if (c.name == n) return c.values;
            return s.columns[0].values;
        };
        const std::vector<double>& x = s.columns[0].values; // the motor's readbacks
        const std::vector<double>& y = col("signal");
        const std::vector<double> sigma = plan.sigma >= 0 ? col("sigma") : std::vector<double>{};
        const FitResult f = fit_curve(model, x, y, sigma);
        FitLimits lim;
        lim.max_reduced_chi2 = plan.cfg.max_reduced_chi2;
        lim.min_r_squared = plan.cfg.min_r_squared;
        lim.max_width = plan.cfg.max_width;
        lim.center_in_range = true;
        const std::string bad = check_fit(f, lim);
        pv::Database& db = run.db();
        auto set = [&](pv::Record* r, double v) { pv::set_value(db, *r, std::isfinite(v) ? v : 0, false); };
        set(plan.center_r, f.center), set(plan.center_err_r, f.center_err), set(plan.width_r, f.width);
        set(plan.width_err_r, f.width_err), set(plan.amp_r, f.amplitude), set(plan.amp_err_r, f.amplitude_err);
        set(plan.bg_r, f.background), set(plan.chi2_r, f.reduced_chi2), set(plan.r2_r, f.r_squared);
        set(plan.fitok_r, bad.empty() ? 1 : 0);
        std::vector<double> curve;
        for (double xi : x) curve.push_back(f.ok ? f(xi) : 0);
        pv::set_array(db, *plan.fit_r, curve.data(), uint32_t(std::min<std::size_t>(curve.size(), kLivePoints)));
        s.columns.push_back({"fit", {}, plan.cfg.model + " fit", curve});
        s.numbers = {{"fit_center", f.center}, {"fit_center_err", f.center_err}, {"fit_width", f.width},
                     {"fit_width_err", f.width_err}, {"fit_amplitude", f.amplitude}, {"fit_amplitude_err", f.amplitude_err},
                     {"fit_background", f.background}, {"fit_background_err", f.background_err}, {"fit_chi2", f.chi2},
                     {"fit_reduced_chi2", f.reduced_chi2}, {"fit_r_squared", f.r_squared}};
        s.texts = {{"fit_model", plan.cfg.model}, {"fit_check", bad.empty() ? "good" : bad}, {"fit_message", f.message}};
        LOG_INFO(lg, plan.cfg.name << ": " << plan.cfg.model << " fit: centre " << fmt(f.center) << " +- " << fmt(f.center_err)
                                   << ", width " << fmt(f.width) << ", reduced chi2 " << fmt(f.reduced_chi2) << ", R2 "
                                   << fmt(f.r_squared) << (bad.empty() ? "" : ": refused: " + bad));
        if (!bad.empty()) return "fit refused: " + bad;
        center = f.center;
        return {};
    }
};

// A sequence: its steps one after the other (another plan with args, a move, a put).
struct SequenceTask final : Task {
    Plan& plan;
    std::size_t k = 0;
    std::unique_ptr<Task> child;
    SequenceTask(Plan& p) : plan(p) {}
    double progress() const override {
        const double n = double(plan.steps.size());
        return n == 0 ? 1 : std::min(1.0, (double(k) + (child ? child->progress() : 0)) / n);
    }
    void abort() override {
        if (child) child->abort();
    }
    R advance(Run& run, double now) override {
        while (k < plan.steps.size()) {
            Plan::StepX& st = plan.steps[k];
            const auto& sc = plan.cfg.steps[k];
            const std::string at = "step " + std::to_string(k + 1) + "/" + std::to_string(plan.steps.size());
            if (!child) {
                using K = config::PlanEntry::Step::Kind;
                std::string w;
                if (sc.kind == K::Plan) {
                    Plan& c = *st.plan;
                    if (c.run && c.run != &run) return (why = at + ": plan " + c.cfg.name + " is running on its own"), R::Failed;
                    for (std::size_t a = 0; a < c.args.size(); ++a) c.args[a] = c.cfg.args[a].second;
                    for (std::size_t a = 0; a < st.args.size(); ++a) {
                        double v = 0;
                        if (!plan.eval(st.args[a], v, w)) return (why = at + ": argument " + sc.args[a].first + ": " + w), R::Failed;
                        c.args[std::size_t(st.arg_slot[a])] = v;
                    }
                    if (!c.run) run.use(c);
                    run.status(c, kRunning);
                    child = make_task(c, run, "s" + std::to_string(k + 1) + "_" + c.cfg.name, w);
                    if (!child) return (why = at + " (" + c.cfg.name + "): " + w), R::Failed;
                    run.message(plan, at + ": " + c.cfg.name);
                } else if (sc.kind == K::Move) {
                    std::vector<MotorPort*> m;
                    std::vector<double> t;
                    std::string text;
                    for (std::size_t j = 0; j < st.motors.size(); ++j) {
                        double v = 0;
                        if (!st.motors[j]) return (why = at + ": " + sc.moves[j].first + " is not reachable"), R::Failed;
                        if (!plan.eval(st.moves[j], v, w)) return (why = at + ": " + sc.moves[j].first + ": " + w), R::Failed;
                        m.push_back(st.motors[j].get()), t.push_back(v);
                        text += (text.empty() ? "" : ", ") + sc.moves[j].first + " to " + fmt(v);
                    }
                    child = std::make_unique<MoveTask>(std::move(m), std::move(t));
                    run.message(plan, at + ": move " + text);
                } else {
                    double v = 0;
                    if (!st.writer) return (why = at + ": " + sc.pv + " is not reachable"), R::Failed;
                    if (!plan.eval(st.value, v, w)) return (why = at + ": " + sc.pv + ": " + w), R::Failed;
                    child = std::make_unique<PutTask>(st.writer.get(), v, sc.wait);
                    run.message(plan, at + ": put " + sc.pv + " = " + fmt(v));
                }
            }
            const R r = child->advance(run, now);
            if (r == R::Wait) return r;
            if (sc.kind == config::PlanEntry::Step::Kind::Plan) run.status(*st.plan, r == R::Done ? kDone : kFailed);
            if (r == R::Failed) return (why = at + ": " + child->why), R::Failed;
            child.reset();
            ++k;
        }
        return R::Done;
    }
};

} // namespace

std::unique_ptr<Task> make_task(Plan& plan, Run& run, const std::string& scan_name, std::string& why) {
    using T = config::PlanEntry::Type;
    const auto& c = plan.cfg;
    if (c.type == T::Align) {
        if (!plan.motors[0]) return (why = c.motor + " is not reachable"), nullptr;
        return std::make_unique<AlignTask>(plan, scan_name + "_");
    }
    if (c.type == T::Sequence) return std::make_unique<SequenceTask>(plan);
    auto number = [&](int k, const std::string& what, double& v) {
        if (plan.eval(k, v, why)) return true;
        why = what + ": " + why;
        return false;
    };
    std::vector<MotorPort*> motors;
    std::vector<double> home;
    for (auto& m : plan.motors) {
        if (!m) return (why = "a motor is not reachable"), nullptr;
        const MotorPort::State st = m->state();
        if (!st.connected) return (why = m->name() + " is not connected"), nullptr;
        motors.push_back(m.get()), home.push_back(st.rbv);
    }
    std::vector<std::vector<double>> t;
    if (c.type == T::List) {
        const std::size_t n = c.axes[0].positions.size();
        t.assign(n, std::vector<double>(motors.size()));
        for (std::size_t a = 0; a < motors.size(); ++a)
            for (std::size_t k = 0; k < n; ++k)
                if (!number(plan.positions[a][k], c.axes[a].motor + " position " + std::to_string(k + 1), t[k][a])) return nullptr;
    } else {
        std::vector<double> s(motors.size()), e(motors.size());
        std::vector<long> n(motors.size());
        for (std::size_t a = 0; a < motors.size(); ++a) {
            double pts = 0;
            if (!number(plan.start[a], c.axes[a].motor + " start", s[a]) || !number(plan.stop[a], c.axes[a].motor + " stop", e[a]) ||
                !number(c.type == T::Grid ? plan.axis_points[a] : plan.points, "points", pts))
                return nullptr;
            n[a] = std::lround(pts);
            if (n[a] < 1 || pts > kMaxPoints) return (why = "points " + fmt(pts) + " should be 1 to " + fmt(kMaxPoints)), nullptr;
        }
        auto at = [&](std::size_t a, long k) { return n[a] == 1 ? s[a] : s[a] + (e[a] - s[a]) * double(k) / double(n[a] - 1); };
        if (c.type == T::Scan) {
            for (long k = 0; k < n[0]; ++k) {
                std::vector<double> row;
                for (std::size_t a = 0; a < motors.size(); ++a) row.push_back(at(a, k));
                t.push_back(std::move(row));
            }
        } else { // grid: the last axis fastest
            double total = 1;
            for (long v : n) total *= double(v);
            if (total > kMaxPoints) return (why = "the grid has " + fmt(total) + " points (at most " + fmt(kMaxPoints) + ")"), nullptr;
            std::vector<long> idx(motors.size(), 0);
            for (long p = 0; p < long(total); ++p) {
                long rest = p;
                for (std::size_t a = motors.size(); a-- > 0;) {
                    idx[a] = rest % n[a];
                    rest /= n[a];
                }
                std::vector<double> row;
                for (std::size_t a = 0; a < motors.size(); ++a) {
                    long k = idx[a];
                    // snake: the inner axis runs backwards on every other line of the one outside it
                    if (c.snake && a + 1 == motors.size() && a > 0 && idx[a - 1] % 2 == 1) k = n[a] - 1 - k;
                    row.push_back(at(a, k));
                }
                t.push_back(std::move(row));
            }
        }
    }
    if (c.relative)
        for (auto& row : t)
            for (std::size_t a = 0; a < row.size(); ++a) row[a] += home[a];
    double dwell = 0;
    if (plan.dwell >= 0 && !number(plan.dwell, "dwell", dwell)) return nullptr;
    const bool ret = c.return_to_start.value_or(c.relative);
    auto task = std::make_unique<ScanTask>(plan, motors, std::move(t), ret, std::max(0.0, dwell));
    task->home = home;
    std::string title = c.name + ": " + (c.type == T::Scan ? "scan" : c.type == T::Grid ? "grid" : "list") + " of";
    for (const auto& a : c.axes) title += " " + a.motor;
    task->open(run, scan_name, title + ", " + std::to_string(task->targets.size()) + " points");
    return task;
}

// ---------------------------------------------------------------- Plans
Plans::Plans(const std::vector<config::PlanEntry>& cfg, const std::string& prefix, const std::string& ioc_name, pv::Database& db,
             std::function<double()> clock)
    : db_(db), clock_(std::move(clock)), ioc_name_(ioc_name) {
    pv::DbFile f;
    for (const auto& c : cfg) {
        auto pp = std::make_unique<Plan>(c);
        Plan& p = *pp;
        p.p = prefix + c.name + ":";
        p.args.resize(c.args.size());
        p.names.resize(c.names.size());
        p.dets.resize(c.detectors.size());
        for (std::size_t i = 0; i < c.args.size(); ++i) p.args[i] = c.args[i].second, p.host.bind(c.args[i].first, &p.args[i], false);
        for (std::size_t i = 0; i < c.names.size(); ++i) p.host.bind(c.names[i].first, &p.names[i], false);
        for (std::size_t i = 0; i < c.detectors.size(); ++i) p.host.bind(c.detectors[i].first, &p.dets[i], false);
        p.host.bind("signal", &p.signal, false);
        p.host.bind("plan_result_", &p.result, true);
        p.next_args = p.args;
        using T = config::PlanEntry::Type;
        if (c.type != T::Sequence) p.dwell = p.compile(c.dwell, c.where, "dwell");
        if (!c.signal.empty()) p.signal_expr = p.compile(c.signal, c.where, "signal");
        if (!c.sigma.empty()) p.sigma = p.compile(c.sigma, c.where, "sigma");
        if (!c.center.empty()) p.center = p.compile(c.center, c.where, "center");
        if (c.type == T::Scan) p.points = p.compile(c.points, c.where, "points");
        for (const auto& a : c.axes) {
            if (c.type == T::List) {
                std::vector<int> pos;
                for (std::size_t k = 0; k < a.positions.size(); ++k)
                    pos.push_back(p.compile(a.positions[k], a.where, a.motor + " position " + std::to_string(k + 1)));
                p.positions.push_back(std::move(pos));
            } else {
                p.start.push_back(p.compile(a.start, a.where, a.motor + " start"));
                p.stop.push_back(p.compile(a.stop, a.where, a.motor + " stop"));
                p.axis_points.push_back(c.type == T::Grid ? p.compile(a.points, a.where, a.motor + " points") : -1);
            }
            p.motor_pvs.push_back(a.motor);
        }
        if (c.type == T::Align) p.motor_pvs.push_back(c.motor);
        for (const auto& ps : c.passes) {
            p.pass_range.push_back(p.compile(ps.range, ps.where, "range"));
            p.pass_points.push_back(p.compile(ps.points, ps.where, "points"));
        }
        for (const auto& st : c.steps) {
            Plan::StepX x;
            using K = config::PlanEntry::Step::Kind;
            if (st.kind == K::Plan) {
                x.plan = find(st.plan);
                if (!x.plan) throw Error(st.where + ": plan '" + c.name + "': '" + st.plan + "' is not a plan defined before it");
                for (const auto& [n, v] : st.args) {
                    x.arg_slot.push_back(x.plan->arg_index(n));
                    x.args.push_back(p.compile(v, st.where, "argument " + n));
                }
            } else if (st.kind == K::Move) {
                for (const auto& [m, v] : st.moves) x.moves.push_back(p.compile(v, st.where, "move of " + m));
            } else {
                x.value = p.compile(st.value, st.where, "value of " + st.pv);
            }
            p.steps.push_back(std::move(x));
        }
        auto rec = [&](const char* type, const char* n, std::vector<std::pair<std::string, std::string>> fields = {}) {
            f.records.push_back(pv::generated_record(type, p.p + n, std::move(fields)));
        };
        rec("busy", "Start", {{"ZNAM", "Done"}, {"ONAM", "Run"}});
        rec("waveform", "Args", {{"FTVL", "CHAR"}, {"NELM", "512"}});
        rec("bo", "Pause", {{"ZNAM", "Run"}, {"ONAM", "Pause"}});
        rec("bo", "Resume", {{"ZNAM", "Done"}, {"ONAM", "Resume"}});
        rec("bo", "Abort", {{"ZNAM", "Done"}, {"ONAM", "Abort"}});
        rec("mbbi", "Status", {{"ZRST", "Idle"}, {"ONST", "Running"}, {"TWST", "Paused"}, {"THST", "Done"}, {"FRST", "Aborted"},
                                {"FVST", "Failed"}, {"FRSV", "MINOR"}, {"FVSV", "MAJOR"}});
        rec("longin", "Point"), rec("longin", "Points"), rec("longin", "Runs");
        rec("ai", "Progress", {{"EGU", "%"}, {"PREC", "1"}});
        rec("ai", "Overhead", {{"EGU", "ms"}, {"PREC", "3"}});
        rec("waveform", "Message", {{"FTVL", "CHAR"}, {"NELM", "512"}});
        rec("waveform", "File", {{"FTVL", "CHAR"}, {"NELM", "512"}});
        rec("waveform", "FilePath", {{"FTVL", "CHAR"}, {"NELM", "512"}});
        for (const char* n : {"X", "Y", "Fit"}) rec("waveform", n, {{"FTVL", "DOUBLE"}, {"NELM", std::to_string(kLivePoints)}});
        if (c.type == T::Align) {
            for (const char* n : {"Center", "CenterErr", "Width", "WidthErr", "Amplitude", "AmplitudeErr", "Background"})
                rec("ai", n, {{"PREC", "6"}});
            rec("ai", "RedChi2", {{"PREC", "4"}}), rec("ai", "RSquared", {{"PREC", "5"}});
            rec("bi", "FitOk", {{"ZNAM", "No"}, {"ONAM", "Yes"}});
        }
        plans_.push_back(std::move(pp));
    }
    db_.load(f);
}

Plans::~Plans() = default;

std::size_t Plans::size() const { return plans_.size(); }

Plans::Plan* Plans::find(const std::string& name) const {
    for (const auto& p : plans_)
        if (p->cfg.name == name) return p.get();
    return nullptr;
}

bool parse_plan_args(const std::vector<std::pair<std::string, double>>& declared, const std::string& text,
                     std::vector<double>& out, std::string& why) {
    std::vector<double> v;
    std::string names;
    for (const auto& [n, d] : declared) v.push_back(d), names += (names.empty() ? "" : ", ") + n;
    std::string t = text;
    for (char& c : t)
        if (c == ',' || c == ';' || c == '\t' || c == '\n' || c == '\r') c = ' ';
    std::istringstream is(t);
    for (std::string item; is >> item;) {
        const std::size_t eq = item.find('=');
        if (eq == std::string::npos) return (why = "argument '" + item + "' should be name=value"), false;
        const std::string name = item.substr(0, eq), num = item.substr(eq + 1);
        int k = -1;
        for (std::size_t i = 0; i < declared.size(); ++i)
            if (declared[i].first == name) k = int(i);
        if (k < 0) return (why = "'" + name + "' is not an argument of the plan (it takes " + (names.empty() ? "none" : names) + ")"), false;
        char* end = nullptr;
        const double x = num.empty() ? NAN : std::strtod(num.c_str(), &end);
        if (num.empty() || *end || !std::isfinite(x)) return (why = "argument " + name + ": '" + num + "' is not a number"), false;
        v[std::size_t(k)] = x;
    }
    out = std::move(v);
    return true;
}

void Plans::start() {
    for (auto& pp : plans_) {
        Plan& p = *pp;
        const auto& c = p.cfg;
        auto local = [&](const std::string& pv) { return db_.find(pv.substr(0, pv.find('.'))) != nullptr; };
        for (const std::string& m : p.motor_pvs) {
            try {
                p.motors.push_back(local(m) ? make_local_motor(db_, m) : nullptr);
            } catch (const Error& e) {
                throw Error(c.where + ": plan '" + c.name + "': " + e.what());
            }
        }
        for (const auto& [n, pv] : c.names) p.name_readers.push_back(make_local_reader(db_, pv));
        for (const auto& [n, pv] : c.detectors) p.det_readers.push_back(make_local_reader(db_, pv));
        for (const auto& [pv, v] : c.triggers) p.triggers.push_back(make_local_writer(db_, pv));
        for (std::size_t k = 0; k < c.steps.size(); ++k) {
            const auto& sc = c.steps[k];
            Plan::StepX& x = p.steps[k];
            for (const auto& [m, v] : sc.moves) {
                try {
                    x.motors.push_back(local(m) ? make_local_motor(db_, m) : nullptr);
                } catch (const Error& e) {
                    throw Error(sc.where + ": plan '" + c.name + "': " + e.what());
                }
            }
            if (sc.kind == config::PlanEntry::Step::Kind::Put) x.writer = make_local_writer(db_, sc.pv);
        }
        auto rec = [&](const char* n) { return db_.find(p.p + n); };
        p.start_r = rec("Start"), p.args_r = rec("Args"), p.status_r = rec("Status"), p.point_r = rec("Point");
        p.points_r = rec("Points"), p.progress_r = rec("Progress"), p.message_r = rec("Message"), p.file_r = rec("File");
        p.filepath_r = rec("FilePath"), p.x_r = rec("X"), p.y_r = rec("Y"), p.fit_r = rec("Fit"), p.overhead_r = rec("Overhead");
        if (c.type == config::PlanEntry::Type::Align) {
            p.center_r = rec("Center"), p.center_err_r = rec("CenterErr"), p.width_r = rec("Width"), p.width_err_r = rec("WidthErr");
            p.amp_r = rec("Amplitude"), p.amp_err_r = rec("AmplitudeErr"), p.bg_r = rec("Background"), p.chi2_r = rec("RedChi2");
            p.r2_r = rec("RSquared"), p.fitok_r = rec("FitOk");
        }
        pv::set_text(db_, *p.filepath_r, c.directory);
        pv::set_value(db_, *p.status_r, kIdle, false);
        Plan* pl = &p;
        p.start_r->put_hook = [this, pl](pv::Record& r, const pv::FieldDesc&) {
            if (pv::get_value(r) == 0) {
                if (pl->finishing || !pl->run) return pv::PutStatus::Ok;
                pv::set_text(db_, *pl->message_r, "running: Abort stops a run (Start = 0 does not)");
                return pv::PutStatus::Failed;
            }
            return start_run(*pl);
        };
        p.args_r->put_hook = [this, pl](pv::Record& r, const pv::FieldDesc&) {
            std::string why;
            if (parse_plan_args(pl->cfg.args, pv::get_text(r), pl->next_args, why)) return pv::PutStatus::Ok;
            pv::set_text(db_, *pl->message_r, "Args: " + why);
            LOG_WARN(lg, pl->cfg.name << ": Args refused: " << why);
            return pv::PutStatus::Failed;
        };
        rec("Pause")->put_hook = [this, pl](pv::Record& r, const pv::FieldDesc&) {
            if (pv::get_value(r) != 0 && pl->run) pl->run->pause = true;
            return pv::PutStatus::Ok;
        };
        rec("Resume")->put_hook = [this, pl](pv::Record& r, const pv::FieldDesc&) {
            if (pv::get_value(r) != 0 && pl->run) {
                Run& run = *pl->run;
                run.pause = false;
                if (run.paused) {
                    run.paused = false;
                    for (Plan* u : run.used) pv::set_value(db_, *u->status_r, kRunning, false);
                    pv::set_text(db_, *run.top.message_r, "resumed");
                }
                wake(0);
            }
            return pv::PutStatus::Ok;
        };
        rec("Abort")->put_hook = [this, pl](pv::Record& r, const pv::FieldDesc&) {
            if (pv::get_value(r) != 0 && pl->run) {
                pl->run->abort = true;
                wake(0);
            }
            return pv::PutStatus::Ok;
        };
        LOG_INFO(lg, c.name << ": " << (c.desc.empty() ? "plan" : c.desc) << ", PVs " << p.p << "*");
    }
}

bool Plans::needs_client() const {
    for (const auto& p : plans_) {
        for (const auto& m : p->motors)
            if (!m) return true;
        for (auto* v : {&p->name_readers, &p->det_readers})
            for (const auto& r : *v)
                if (!r) return true;
        for (const auto& t : p->triggers)
            if (!t) return true;
        for (const auto& s : p->steps) {
            for (const auto& m : s.motors)
                if (!m) return true;
            if (s.value >= 0 && !s.writer) return true;
        }
    }
    return false;
}

void Plans::connect(ca::Client& client) {
    for (auto& pp : plans_) {
        Plan& p = *pp;
        const auto& c = p.cfg;
        for (std::size_t k = 0; k < p.motors.size(); ++k)
            if (!p.motors[k]) p.motors[k] = make_ca_motor(client, p.motor_pvs[k]);
        for (std::size_t k = 0; k < p.name_readers.size(); ++k)
            if (!p.name_readers[k]) p.name_readers[k] = make_ca_reader(client, c.names[k].second);
        for (std::size_t k = 0; k < p.det_readers.size(); ++k)
            if (!p.det_readers[k]) p.det_readers[k] = make_ca_reader(client, c.detectors[k].second);
        for (std::size_t k = 0; k < p.triggers.size(); ++k)
            if (!p.triggers[k]) p.triggers[k] = make_ca_writer(client, c.triggers[k].first);
        for (std::size_t k = 0; k < p.steps.size(); ++k) {
            auto& s = p.steps[k];
            for (std::size_t j = 0; j < s.motors.size(); ++j)
                if (!s.motors[j]) s.motors[j] = make_ca_motor(client, c.steps[k].moves[j].first);
            if (s.value >= 0 && !s.writer) s.writer = make_ca_writer(client, c.steps[k].pv);
        }
    }
}

pv::PutStatus Plans::start_run(Plan& p) {
    auto refuse = [&](const std::string& why) {
        pv::set_text(db_, *p.message_r, why);
        LOG_WARN(lg, p.cfg.name << ": not started: " << why);
        return pv::PutStatus::Failed;
    };
    if (p.run) return refuse(p.run->top.cfg.name == p.cfg.name ? "already running" : "in use by " + p.run->top.cfg.name);
    for (const auto& st : p.steps)
        if (st.plan && st.plan->run) return refuse("its step plan " + st.plan->cfg.name + " is running");
    // the motors this run may move: no two runs drive one motor
    std::vector<std::string> motors;
    auto add = [&](const std::string& pv) { motors.push_back(pv.substr(0, pv.find('.'))); };
    for (const auto& m : p.motor_pvs) add(m);
    for (const auto& st : p.cfg.steps)
        for (const auto& [m, v] : st.moves) add(m);
    for (const auto& st : p.steps)
        if (st.plan)
            for (const auto& m : st.plan->motor_pvs) add(m);
    for (const auto& other : runs_)
        if (!other->ended)
            for (const auto& m : motors)
                if (std::find(other->motors.begin(), other->motors.end(), m) != other->motors.end())
                    return refuse(m + " is in use by the plan " + other->top.cfg.name);
    auto run = std::make_unique<Run>(*this, p);
    Run& r = *run;
    r.motors = std::move(motors);
    r.number = ++p.runs;
    r.t0 = clock_();
    p.args = p.next_args;
    r.use(p);
    for (auto& st : p.steps) // a sequence holds its step plans for the whole run
        if (st.plan && !st.plan->run) r.use(*st.plan);
    std::string args_text;
    for (std::size_t i = 0; i < p.args.size(); ++i) args_text += (i ? " " : "") + p.cfg.args[i].first + "=" + fmt(p.args[i]);
    r.data.title = p.cfg.name + (p.cfg.desc.empty() ? "" : ": " + p.cfg.desc);
    r.data.attributes = {{"plan", p.cfg.name}, {"args", args_text}, {"ioc", ioc_name_}, {"start_time", local_time("%Y-%m-%dT%H:%M:%S%z")},
                         {"run", std::to_string(r.number)}};
    std::string why;
    r.task = make_task(p, r, p.cfg.name, why);
    if (!r.task) {
        for (Plan* u : r.used) u->run = nullptr;
        return refuse(why);
    }
    pv::set_value(db_, *p.status_r, kRunning, false);
    pv::set_value(db_, *p.progress_r, 0, false);
    pv::set_value(db_, *db_.find(p.p + "Runs"), r.number, false);
    pv::set_text(db_, *p.message_r, "run " + std::to_string(r.number) + " started" + (args_text.empty() ? "" : ": " + args_text));
    LOG_INFO(lg, p.cfg.name << ": run " << r.number << " started" << (args_text.empty() ? "" : ": " + args_text));
    runs_.push_back(std::move(run));
    wake(0);
    return pv::PutStatus::Ok;
}

void Plans::finish(Run& r) {
    r.ended = true;
    Plan& p = r.top;
    const int st = r.abort ? kAborted : r.task && r.task->why.empty() ? kDone : kFailed;
    std::string msg = st == kDone ? "done" : st == kAborted ? "aborted" + (r.abort_why.empty() ? std::string() : ": " + r.abort_why) : "failed: " + r.task->why;
    if (st == kAborted && r.task) r.task->abort();
    if (r.overhead_n > 0)
        pv::set_value(db_, *p.overhead_r, 1e3 * r.overhead_sum / double(r.overhead_n), false);
    // the file: whatever the ending
    const std::string dir = pv::get_text(*p.filepath_r);
    if (!dir.empty()) {
        const std::string path = dir + "/" + p.cfg.name + "_" + local_time("%Y%m%d-%H%M%S") + "_" + std::to_string(r.number) + ".h5";
        r.data.attributes.push_back({"end_time", local_time("%Y-%m-%dT%H:%M:%S%z")});
        r.data.attributes.push_back({"status", kStatusNames[st]});
        r.data.attributes.push_back({"message", msg});
        if (r.overhead_n > 0) r.data.attributes.push_back({"overhead_ms", fmt(1e3 * r.overhead_sum / double(r.overhead_n))});
        try {
            daq::write_plan_file(path, r.data);
            pv::set_text(db_, *p.file_r, path);
        } catch (const Error& e) {
            LOG_ERR(lg, p.cfg.name << ": run " << r.number << ": the file was not written: " << e.what());
            msg += "; file not written: " + std::string(e.what());
            pv::set_text(db_, *p.file_r, "");
        }
    }
    for (Plan* u : r.used) {
        u->run = nullptr;
        if (u != &p && int(pv::get_value(*u->status_r)) == kRunning) pv::set_value(db_, *u->status_r, st, false);
    }
    pv::set_value(db_, *p.status_r, st, false);
    if (st == kDone) pv::set_value(db_, *p.progress_r, 100, false);
    pv::set_text(db_, *p.message_r, msg);
    if (st == kDone) LOG_INFO(lg, p.cfg.name << ": run " << r.number << " " << msg);
    else LOG_WARN(lg, p.cfg.name << ": run " << r.number << " " << msg);
    if (st == kFailed && !r.latch.empty()) {
        if (fsms_ && fsms_->latch(r.latch, "plan " + p.cfg.name + " failed: " + r.task->why)) {
            LOG_WARN(lg, p.cfg.name << ": latched state machine " << r.latch);
        } else {
            LOG_ERR(lg, p.cfg.name << ": cannot latch state machine " << r.latch);
        }
    }
    // Start's put-callback completes now: failed unless Done (EPICS: the client's ca_put_callback
    // status), then the busy record goes back to 0.
    if (st != kDone) db_.async_complete(*p.start_r, pv::PutStatus::Failed);
    p.finishing = true;
    pv::set_value(db_, *p.start_r, 0, false);
    p.finishing = false;
}

void Plans::poll() {
    if (polling_ || runs_.empty()) return;
    polling_ = true;
    const double now = clock_();
    for (std::size_t k = 0; k < runs_.size(); ++k) {
        Run& r = *runs_[k];
        if (r.ended) continue;
        if (r.abort) {
            finish(r);
            continue;
        }
        const Task::R res = r.task->advance(r, now);
        pv::set_value(db_, *r.top.progress_r, 100 * r.task->progress(), false);
        if (res != Task::R::Wait) {
            if (res == Task::R::Failed && r.task->why.empty()) r.task->why = "failed";
            finish(r);
        }
    }
    runs_.erase(std::remove_if(runs_.begin(), runs_.end(), [](const auto& r) { return r->ended; }), runs_.end());
    polling_ = false;
}

void Plans::abort_all(const std::string& why) {
    for (auto& r : runs_)
        if (!r->ended) {
            r->abort = true;
            r->abort_why = why;
        }
    poll();
}

std::string Plans::status(const std::string& plan) const {
    const Plan* p = find(plan);
    if (!p || !p->status_r) return {};
    return kStatusNames[std::clamp(int(pv::get_value(*p->status_r)), 0, 5)];
}

} // namespace beamctl::automation
