// Plans (automation/plan.hpp) in virtual time, on simulated motor records and calc "detectors" of
// one database: a scan visits every point, reads after the dwell and writes its file; a relative
// scan returns; a grid snakes; a list goes where it is told; pause holds before the next point,
// resume goes on, abort stops the motor and fails Start's put-callback; a refused move fails the
// run; an alignment finds a Lorentzian's and an edge's centre and moves there, and without a peak
// puts the motor back and latches its state machine; a sequence runs its steps with arguments and
// names; bad Args and a second Start are refused with a reason; bad configuration names where.
#include "automation/plan.hpp"

#include "automation/state_machine.hpp"
#include "db_rig.hpp"

#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "pv/db_file.hpp"
#include "pv/motor_record.hpp"
#include "pv/publish.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <optional>

using namespace beamctl;
using namespace beamctl::automation;

namespace {

// x, y: simulated motors; D:lin = 2 x; D:peak: a Lorentzian of x (centre 1.234, FWHM 0.1, on
// 0.02); D:edge: a falling logistic edge of x at 0.7 (scale 0.05); D:up: a constant upstream 1000.
const char* kDb = R"db(
record(motor, "M:x") { field(MRES, "0.0001") field(RDBD, "0.0001") field(VELO, "2") field(ACCL, "0.05") field(DHLM, "10") field(DLLM, "-10") }
record(motor, "M:y") { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "5") field(ACCL, "0.05") field(DHLM, "10") field(DLLM, "-10") }
record(calc, "D:lin") { field(INPA, "M:x.RBV CP") field(CALC, "2*A") }
record(ao, "D:center") { field(VAL, "1.234") }
record(calc, "D:peak") { field(INPA, "M:x.RBV CP") field(INPB, "D:center CP") field(CALC, "1000*(0.02+1/(1+((A-B)*2/0.1)^2))") }
record(calc, "D:edge") { field(INPA, "M:x.RBV CP") field(CALC, "1000/(1+EXP((A-0.7)/0.05))") }
record(ao, "D:up") { field(VAL, "1000") }
record(ao, "D:out") { }
record(bo, "D:n2") { }
)db";

const char* kFsm = R"(state_machines:
  - name: main
    states: {ok: {}, error_latch: {}}
    initial: ok
    latch: error_latch
)";

std::string temp_dir() {
    char t[] = "/tmp/beamctl-plan-XXXXXX";
    const char* d = ::mkdtemp(t);
    return d ? d : "/tmp";
}

struct Rig : test::DbRig {
    std::string dir = temp_dir();
    config::IocConfig cfg;
    std::unique_ptr<StateMachines> fsms;
    std::unique_ptr<Plans> plans;

    explicit Rig(const std::string& plans_yaml) {
        now = 10;
        db.load(pv::parse_db(kDb, "plan.db", {}));
        std::string text = "ioc: {name: T}\n" + std::string(kFsm) + "plans:\n" + plans_yaml;
        for (std::size_t at = 0; (at = text.find("DIR", at)) != std::string::npos;) text.replace(at, 3, dir);
        cfg = config::IocConfig::parse(text, "/cfg/ioc.yaml");
        fsms = std::make_unique<StateMachines>(cfg.state_machines, "P:", db, [this] { return now; });
        plans = std::make_unique<Plans>(cfg.plans, "P:", "T", db, [this] { return now; });
        plans->set_state_machines(fsms.get());
        for (const char* m : {"M:x", "M:y"}) pv::MotorRecord::from(db.find(m))->set_clock([this] { return now; });
        db.init_records();
        fsms->start();
        plans->start();
        poll = [this] {
            fsms->poll();
            plans->poll();
        };
        run(1);
    }
    ~Rig() { std::filesystem::remove_all(dir); }

    void set_text(const std::string& n, const std::string& t) {
        std::vector<char> c(t.begin(), t.end());
        c.push_back(0);
        const pv::PutStatus st = db.put(addr(n), pv::Prim::Char, c.data(), uint32_t(c.size()));
        last_put = st;
    }
    std::string text(const std::string& n) const { return pv::get_text(*db.find(n)); }
    std::vector<double> array(const std::string& n) const {
        std::vector<double> v(4096);
        v.resize(db.get(addr(n), pv::Prim::Double, v.data(), uint32_t(v.size())));
        return v;
    }
    // Start = 1 with a put-callback; `done` holds its status once the run ended.
    pv::PutStatus start(const std::string& plan) {
        done.reset();
        return put("P:" + plan + ":Start", 1, [this](pv::PutStatus s) { done = s; });
    }
    // Runs until Start's callback came (at most `seconds`).
    bool finish(double seconds = 120) {
        for (double t = 0; t < seconds && !done; t += 0.1) run(0.1);
        return done.has_value();
    }
    std::string status(const std::string& plan) const { return plans->status(plan); }
    double moveto(const std::string& m, double x) {
        put(m, x);
        run(5);
        return get(m + ".RBV");
    }
    pv::PutStatus last_put = pv::PutStatus::Ok;
    std::optional<pv::PutStatus> done;
};

// A 1-D float64 dataset of a plan file.
std::vector<double> read_dataset(const std::string& file, const std::string& path) {
    std::vector<double> v;
    const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0) return v;
    const hid_t d = H5Dopen2(f, path.c_str(), H5P_DEFAULT);
    if (d >= 0) {
        const hid_t s = H5Dget_space(d);
        v.resize(std::size_t(H5Sget_simple_extent_npoints(s)));
        if (!v.empty()) H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
        H5Sclose(s);
        H5Dclose(d);
    }
    H5Fclose(f);
    return v;
}

} // namespace

TEST(Plan, AScanVisitsEveryPointReadsAfterTheDwellAndWritesItsFile) {
    Rig r("  - {name: s, type: scan, axes: [{motor: M:x, start: 0, stop: 1}], points: 5, dwell: 0.2,\n"
          "     detectors: {y: D:lin}, directory: DIR}\n");
    EXPECT_EQ(r.status("s"), "Idle");
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    r.run(0.05);
    EXPECT_EQ(r.status("s"), "Running");
    EXPECT_FALSE(r.done.has_value()); // Start's put-callback waits for the run
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok);
    EXPECT_EQ(r.status("s"), "Done");
    EXPECT_EQ(r.get("P:s:Start"), 0);
    EXPECT_EQ(r.get("P:s:Points"), 5);
    EXPECT_EQ(r.get("P:s:Point"), 5);
    EXPECT_EQ(r.get("P:s:Progress"), 100);
    const auto x = r.array("P:s:X"), y = r.array("P:s:Y");
    ASSERT_EQ(x.size(), 5u);
    ASSERT_EQ(y.size(), 5u);
    for (std::size_t k = 0; k < 5; ++k) {
        EXPECT_NEAR(x[k], 0.25 * double(k), 1e-4) << k;
        EXPECT_NEAR(y[k], 2 * x[k], 1e-9) << k; // read after the motor arrived
    }
    EXPECT_NEAR(r.get("M:x.RBV"), 1, 1e-4); // absolute: stays at the last point
    const std::string file = r.text("P:s:File");
    ASSERT_TRUE(std::filesystem::exists(file)) << file;
    EXPECT_NE(file.find(r.dir + "/s_"), std::string::npos) << file;
    EXPECT_EQ(read_dataset(file, "/entry/s/y"), y);
    const auto sp = read_dataset(file, "/entry/s/M_x_setpoint");
    ASSERT_EQ(sp.size(), 5u);
    EXPECT_EQ(sp[2], 0.5);
    const auto t = read_dataset(file, "/entry/s/time");
    ASSERT_EQ(t.size(), 5u);
    for (std::size_t k = 1; k < 5; ++k) EXPECT_GT(t[k] - t[k - 1], 0.2) << "the dwell passes before each read";
    EXPECT_GE(r.get("P:s:Runs"), 1);
}

TEST(Plan, ARelativeScanGoesAroundWhereTheMotorIsAndReturns) {
    Rig r("  - {name: s, type: scan, axes: [{motor: M:x, start: -w, stop: w}], points: 3, relative: true,\n"
          "     args: {w: 0.5}, detectors: {y: D:lin}, signal: \"y / 2\", directory: \"\"}\n");
    EXPECT_NEAR(r.moveto("M:x", 2), 2, 1e-4);
    r.set_text("P:s:Args", "w=0.25");
    EXPECT_EQ(r.last_put, pv::PutStatus::Ok);
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok);
    const auto x = r.array("P:s:X"), y = r.array("P:s:Y");
    ASSERT_EQ(x.size(), 3u);
    EXPECT_NEAR(x[0], 1.75, 1e-4);
    EXPECT_NEAR(x[2], 2.25, 1e-4);
    EXPECT_NEAR(y[2], 2.25, 1e-4); // the signal expression: y / 2 = x
    EXPECT_NEAR(r.get("M:x.RBV"), 2, 1e-4) << "relative: back to the start";
    EXPECT_EQ(r.text("P:s:File"), ""); // directory "": no file
}

TEST(Plan, AGridSnakesItsInnerAxisAndAListGoesWhereItIsTold) {
    Rig r("  - {name: g, type: grid, axes: [{motor: M:x, start: 0, stop: 1, points: 2}, {motor: M:y, start: 0, stop: 2, points: 3}],\n"
          "     snake: true, detectors: {y: D:lin}, directory: DIR}\n"
          "  - {name: l, type: list, axes: [{motor: M:x, positions: [3, 1, 2]}], detectors: {y: D:lin}, directory: DIR}\n");
    ASSERT_EQ(r.start("g"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(r.status("g"), "Done");
    const std::string file = r.text("P:g:File");
    EXPECT_EQ(read_dataset(file, "/entry/g/M_x_setpoint"), (std::vector<double>{0, 0, 0, 1, 1, 1}));
    EXPECT_EQ(read_dataset(file, "/entry/g/M_y_setpoint"), (std::vector<double>{0, 1, 2, 2, 1, 0}));
    ASSERT_EQ(r.start("l"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    const auto x = r.array("P:l:X");
    ASSERT_EQ(x.size(), 3u);
    EXPECT_NEAR(x[0], 3, 1e-4);
    EXPECT_NEAR(x[1], 1, 1e-4);
    EXPECT_NEAR(x[2], 2, 1e-4);
}

TEST(Plan, PauseHoldsBeforeTheNextPointResumeGoesOnAbortStopsAndFails) {
    Rig r("  - {name: s, type: scan, axes: [{motor: M:x, start: 0, stop: 4}], points: 5, dwell: 0.5, detectors: {y: D:lin}, directory: DIR}\n");
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    r.run(0.3);
    r.put("P:s:Pause", 1);
    r.run(10);
    EXPECT_EQ(r.status("s"), "Paused");
    const double held = r.get("P:s:Point");
    EXPECT_LT(held, 5);
    r.run(10);
    EXPECT_EQ(r.get("P:s:Point"), held) << "paused: no new point";
    r.put("P:s:Resume", 1);
    r.run(0.05);
    EXPECT_EQ(r.status("s"), "Running");
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok);
    EXPECT_EQ(r.get("P:s:Point"), 5);

    // abort: in the middle of a move
    r.moveto("M:x", 0);
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    for (double t = 0; t < 5 && r.get("M:x.DMOV") != 0; t += 0.05) r.run(0.05);
    r.run(0.1);
    ASSERT_EQ(r.get("M:x.DMOV"), 0) << "moving when aborted";
    r.put("P:s:Abort", 1);
    ASSERT_TRUE(r.finish(5));
    EXPECT_EQ(*r.done, pv::PutStatus::Failed) << "an aborted run is not a success";
    EXPECT_EQ(r.status("s"), "Aborted");
    r.run(2);
    EXPECT_EQ(r.get("M:x.DMOV"), 1);
    EXPECT_LT(r.get("M:x.RBV"), 3.9) << "stopped where it was, not at the end";
    EXPECT_TRUE(std::filesystem::exists(r.text("P:s:File"))) << "an aborted run's data is written too";
}

TEST(Plan, StartIsRefusedWhileRunningBadArgsAreRefusedAndARefusedMoveFailsTheRun) {
    Rig r("  - {name: s, type: scan, args: {stop: 1}, axes: [{motor: M:x, start: 0, stop: stop}], points: 3, detectors: {y: D:lin}, directory: DIR}\n");
    r.set_text("P:s:Args", "nope=1");
    EXPECT_EQ(r.last_put, pv::PutStatus::Failed);
    EXPECT_NE(r.text("P:s:Message").find("'nope' is not an argument of the plan (it takes stop)"), std::string::npos) << r.text("P:s:Message");
    r.set_text("P:s:Args", "stop=abc");
    EXPECT_EQ(r.last_put, pv::PutStatus::Failed);
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    r.run(0.05);
    EXPECT_EQ(r.put("P:s:Start", 1), pv::PutStatus::Failed);
    EXPECT_EQ(r.text("P:s:Message"), "already running");
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok);

    // a point beyond the motor's soft limit (DHLM 10): the motor refuses, the run fails
    r.set_text("P:s:Args", "stop=20");
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Failed);
    EXPECT_EQ(r.status("s"), "Failed");
    EXPECT_NE(r.text("P:s:Message").find("point 3: M:x refused or failed the move (at 10, target 20)"), std::string::npos) << r.text("P:s:Message");
}

TEST(Plan, AnAlignmentFindsTheLorentzianCentreAndMovesThere) {
    Rig r("  - {name: a, type: align, motor: M:x, detectors: {down: D:peak, up: D:up}, signal: \"down / up\",\n"
          "     passes: [{range: 0.6, points: 41}, {range: 0.2, points: 21}], min_r_squared: 0.9, latch: main, directory: DIR}\n"
          "  - {name: e, type: align, model: edge, motor: M:x, detectors: {i: D:edge}, passes: [{range: 1, points: 31}], directory: \"\"}\n");
    r.moveto("M:x", 1.1);
    ASSERT_EQ(r.start("a"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok) << r.text("P:a:Message");
    EXPECT_NEAR(r.get("P:a:Center"), 1.234, 0.001) << "within 1 % of the width (0.1)";
    EXPECT_NEAR(r.get("P:a:Width"), 0.1, 0.002);
    EXPECT_EQ(r.get("P:a:FitOk"), 1);
    EXPECT_NEAR(r.get("M:x.RBV"), 1.234, 2e-4) << "moved to the fitted centre";
    EXPECT_EQ(r.array("P:a:Fit").size(), 21u); // the last pass's curve
    const std::string file = r.text("P:a:File");
    EXPECT_EQ(read_dataset(file, "/entry/a_pass1/signal").size(), 41u);
    EXPECT_EQ(read_dataset(file, "/entry/a_pass2/fit").size(), 21u);
    EXPECT_EQ(r.fsms->state_name("main"), "ok");

    r.moveto("M:x", 0.5);
    ASSERT_EQ(r.start("e"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok) << r.text("P:e:Message");
    EXPECT_NEAR(r.get("M:x.RBV"), 0.7, 0.002) << "the edge's 50 % point";
}

TEST(Plan, AnAlignmentWithoutAPeakPutsTheMotorBackAndLatches) {
    Rig r("  - {name: a, type: align, motor: M:x, detectors: {down: D:peak, up: D:up}, signal: \"down / up\",\n"
          "     passes: [{range: 0.6, points: 41}], min_r_squared: 0.9, latch: main, directory: DIR}\n");
    r.put("D:center", 6); // far outside the scan
    r.moveto("M:x", 1.1);
    ASSERT_EQ(r.start("a"), pv::PutStatus::Ok);
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Failed);
    EXPECT_EQ(r.status("a"), "Failed");
    EXPECT_EQ(r.get("P:a:FitOk"), 0);
    EXPECT_NEAR(r.get("M:x.RBV"), 1.1, 1e-4) << "back where it started";
    EXPECT_EQ(r.fsms->state_name("main"), "error_latch");
    EXPECT_TRUE(r.fsms->latched("main"));
    EXPECT_NE(r.fsms->error("main").find("fit refused"), std::string::npos) << r.fsms->error("main");
    EXPECT_TRUE(std::filesystem::exists(r.text("P:a:File")));
}

TEST(Plan, ASequenceRunsItsStepsWithArgumentsAndNames) {
    Rig r("  - {name: s, type: scan, args: {n: 3}, axes: [{motor: M:x, start: 0, stop: 1}], points: n, detectors: {y: D:lin}, directory: \"\"}\n"
          "  - name: q\n"
          "    type: sequence\n"
          "    args: {where: 2, n: 4}\n"
          "    names: {lin: D:lin}\n"
          "    directory: DIR\n"
          "    steps:\n"
          "      - {move: {M:x: where, M:y: -1}}\n"
          "      - {put: D:out, value: \"lin + 1\"}\n"
          "      - {plan: s, args: {n: \"n + 1\"}}\n");
    r.set_text("P:q:Args", "where=3");
    ASSERT_EQ(r.start("q"), pv::PutStatus::Ok);
    r.run(0.05);
    EXPECT_EQ(r.put("P:s:Start", 1), pv::PutStatus::Failed) << "its step plan is in use";
    ASSERT_TRUE(r.finish());
    EXPECT_EQ(*r.done, pv::PutStatus::Ok) << r.text("P:q:Message");
    EXPECT_NEAR(r.get("M:y.RBV"), -1, 1e-3);
    EXPECT_NEAR(r.get("D:out"), 7, 1e-3); // lin = 2 * 3 when the put ran, + 1
    EXPECT_EQ(r.get("P:s:Points"), 5);    // n + 1
    EXPECT_EQ(r.status("s"), "Done");
    const std::string file = r.text("P:q:File");
    EXPECT_EQ(read_dataset(file, "/entry/s3_s/y").size(), 5u) << "the step's scan in the sequence's file";
}

TEST(Plan, BadConfigurationIsRefusedNamingWhere) {
    ErrorList e;
    config::IocConfig::parse("ioc: {name: T}\nplans:\n"
                             "  - {name: a, type: align, motor: M:x, detectors: {d: D:peak}, passes: [{range: 1, points: 9}], max_reduced_chi2: 2}\n"
                             "  - {name: s, type: scan, axes: [{motor: M:x, start: 0, stop: 1}], points: 3, detectors: {d: D:lin}, model: edge}\n"
                             "  - {name: q, type: sequence, steps: [{plan: nope}, {plan: s, args: {z: 1}}, {move: {}}]}\n"
                             "  - {name: l, type: list, axes: [{motor: M:x, positions: [1, 2]}, {motor: M:y, positions: [1]}], detectors: {d: D:lin}}\n",
                             "/cfg/ioc.yaml", e);
    const auto m = e.messages();
    ASSERT_EQ(m.size(), 6u) << ::testing::PrintToString(m);
    EXPECT_NE(m[0].find("needs sigma:"), std::string::npos) << m[0];
    EXPECT_NE(m[1].find("model: is for an align plan"), std::string::npos) << m[1];
    EXPECT_NE(m[2].find("'nope' is not a plan defined above this one"), std::string::npos) << m[2];
    EXPECT_NE(m[3].find("'s' has no argument 'z'"), std::string::npos) << m[3];
    EXPECT_NE(m[4].find("needs at least one MOTOR: POSITION"), std::string::npos) << m[4];
    EXPECT_NE(m[5].find("the same (nonzero) number of positions"), std::string::npos) << m[5];
    EXPECT_NE(m[0].find("/cfg/ioc.yaml:3:"), std::string::npos) << m[0];

    // an expression that does not compile: named with its place
    pv::Database db;
    const auto c = config::IocConfig::parse(
        "ioc: {name: T}\nplans:\n  - {name: s, type: scan, axes: [{motor: M:x, start: \"0 +\", stop: 1}], points: 3, detectors: {d: D:lin}}\n",
        "/cfg/ioc.yaml");
    try {
        Plans p(c.plans, "P:", "T", db, [] { return 0.0; });
        FAIL() << "a bad expression was accepted";
    } catch (const Error& x) {
        EXPECT_NE(std::string(x.what()).find("/cfg/ioc.yaml:3:"), std::string::npos) << x.what();
        EXPECT_NE(std::string(x.what()).find("M:x start"), std::string::npos) << x.what();
    }
}

TEST(Plan, TwoRunsNeverDriveOneMotor) {
    Rig r("  - {name: s, type: scan, axes: [{motor: M:x, start: 0, stop: 1}], points: 3, dwell: 0.5, detectors: {y: D:lin}, directory: \"\"}\n"
          "  - {name: t, type: list, axes: [{motor: M:x, positions: [2]}], detectors: {y: D:lin}, directory: \"\"}\n"
          "  - {name: u, type: list, axes: [{motor: M:y, positions: [2]}], detectors: {y: D:lin}, directory: \"\"}\n"
          "  - {name: q, type: sequence, steps: [{move: {M:x: 3}}], directory: \"\"}\n");
    ASSERT_EQ(r.start("s"), pv::PutStatus::Ok);
    r.run(0.05);
    EXPECT_EQ(r.put("P:t:Start", 1), pv::PutStatus::Failed);
    EXPECT_EQ(r.text("P:t:Message"), "M:x is in use by the plan s");
    EXPECT_EQ(r.put("P:q:Start", 1), pv::PutStatus::Failed) << "a sequence's move step counts too";
    EXPECT_EQ(r.put("P:u:Start", 1), pv::PutStatus::Ok) << "another motor: runs alongside";
    ASSERT_TRUE(r.finish());
    r.run(5);
    EXPECT_EQ(r.status("u"), "Done");
    EXPECT_EQ(r.put("P:t:Start", 1), pv::PutStatus::Ok) << "free again once the run ended";
    r.run(5);
    EXPECT_EQ(r.status("t"), "Done");
}
