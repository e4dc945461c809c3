// ecmccfg's PLC manual (hugo/content/manual/PLC_cfg/: syntax, variables, patterns, functions,
// best_practice, function_libs) as the spec: every example of its pages, written out in
// tests/fixtures/ecmc_manual/ (own values), compiles against a real IOC and runs; each axis
// variable reads what ECMC's ecmcPLCDataIF reads, the writable ones act (enc.homed, ctrl.*), and
// the forms the manual shows (VAR blocks with every address form, a VAR line without ';',
// '#' comments) behave as in ECMC. Whole IOCs in virtual time, the bus simulated.
#include "../ioc/virtual_ioc.hpp"
#include "../temp_dir.hpp"
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sys/mman.h>
#include <unistd.h>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

namespace fs = std::filesystem;
const fs::path kManual = fs::path(BEAMCTL_SOURCE_DIR) / "tests" / "fixtures" / "ecmc_manual";

// The PLCs of the fixture's ioc.yaml, in its `plcs:` order (the runtime's indices; the axis PLC
// of axis.yaml follows them).
enum { kPatterns, kVariables, kSyntax, kVarBlock, kBestPractice, kFunctions, kUseFunctions, kAxisPlc };

// The fixture directory copied to a temporary one, its IOC given its own m2m memory (the
// function library's testm2m() writes m2m index 0).
struct ManualIoc {
    TempDir d;
    std::string shm = "beamctl_test_m2m_manual_" + std::to_string(::getpid());
    std::unique_ptr<VirtualIoc> v;
    ManualIoc() {
        for (const auto& e : fs::directory_iterator(kManual)) fs::copy(e.path(), d.path / e.path().filename());
        std::ofstream(d.path / "ioc.yaml", std::ios::app) << "m2m: {name: " << shm << "}\n";
        v = std::make_unique<VirtualIoc>(d.file("ioc.yaml"));
    }
    ~ManualIoc() {
        v.reset();
        ::shm_unlink(("/" + shm).c_str());
    }
    double stat(int plc, const std::string& name) { return v->stat(std::size_t(plc), name); }
    void set(int plc, const std::string& name, double x) {
        *const_cast<double*>(v->ioc->plcs().static_variable(std::size_t(plc), name)) = x;
    }
    motion::Axis& axis() { return v->axis("M1"); }
    const motion::AxisStatus& st() { return axis().status(); }
    void power() {
        motion::AxisCommand on{motion::CommandType::Power};
        on.on = true;
        v->send("M1", on);
    }
    // cycles until `done` (at most n)
    template <class F> bool until(F done, int n) {
        for (int i = 0; i < n && !done(); ++i) v->cycles(1);
        return done();
    }
};

// An IOC on the fixture's bus, plant and axis with one PLC of `code` (id 0).
struct AxisRig {
    TempDir d;
    std::unique_ptr<VirtualIoc> v;
    explicit AxisRig(const std::string& code) {
        for (const char* f : {"axis.yaml", "plant.yaml"}) fs::copy(kManual / f, d.path / f);
        d.write("main.plc", code);
        d.write("ioc.yaml", "ioc: {name: R}\nengine: {rate_hz: 1000}\nbuses:\n  - id: 0\n"
                            "    link: {type: sim, plant: plant.yaml}\n    slaves:\n"
                            "      - {position: 0, type: EK1100}\n      - {position: 1, type: EL1008}\n"
                            "      - {position: 2, type: EL7041}\n      - {position: 3, type: EL2008}\n"
                            "axes:\n  - {file: axis.yaml}\nplcs:\n  - {id: 0, file: main.plc}\n");
        v = std::make_unique<VirtualIoc>(d.file("ioc.yaml"));
    }
    double stat(const std::string& name) { return v->stat(0, name); }
    void set(const std::string& name, double x) { *const_cast<double*>(v->ioc->plcs().static_variable(0, name)) = x; }
    const motion::AxisStatus& st() { return v->axis("M1").status(); }
    void power() {
        motion::AxisCommand on{motion::CommandType::Power};
        on.on = true;
        v->send("M1", on);
    }
    void move_to(double x) { v->send("M1", motion::AxisCommand{motion::CommandType::MoveAbsolute, x}); }
};

} // namespace

// Every example file compiles against the IOC (its buses, axis, storages, LUT, library) and runs
// without a fault, computing what the manual says.
TEST(PlcManual, EveryExampleCompilesAndRuns) {
    ManualIoc m;
    m.v->cycles(200);
    for (int i = kPatterns; i <= kAxisPlc; ++i) {
        const auto s = m.v->plcs().status(std::size_t(i));
        EXPECT_EQ(s.error, 0) << m.v->plcs().prefix(std::size_t(i)) << ": " << m.v->plcs().fault(std::size_t(i));
        EXPECT_EQ(s.faults, 0u) << m.v->plcs().prefix(std::size_t(i));
        EXPECT_EQ(s.scans, 200u) << m.v->plcs().prefix(std::size_t(i));
    }
    // syntax.md: assignment, if-else with '=', '==', the for loop over static.i
    EXPECT_EQ(m.stat(kSyntax, "branch"), 1);
    EXPECT_EQ(m.stat(kSyntax, "equal"), 1);
    EXPECT_EQ(m.stat(kSyntax, "sum"), 0 + 1 + 2);
    EXPECT_EQ(m.stat(kSyntax, "i"), 3);
    // best_practice.md: SELF_ID and M_ID, the output toggled by the include every scan
    EXPECT_EQ(m.stat(kBestPractice, "plcId"), 4);
    EXPECT_EQ(m.stat(kBestPractice, "master"), 0);
    // the VAR block's aliases: gTest is global.test, sTest static.test, myTraj ax1.traj, ...
    EXPECT_EQ(*m.v->plcs().global("test"), 200);
    EXPECT_EQ(m.stat(kVarBlock, "pini"), 1);
    EXPECT_EQ(m.stat(kVarBlock, "oldTarget"), m.stat(kVariables, "targetpos"));
    // function_libs.md with OFFSET=3: add 15+3, prod 120+3, dot({2,2,2,2,2}^2) 20, one 1+3
    EXPECT_EQ(m.stat(kUseFunctions, "add"), 18);
    EXPECT_EQ(m.stat(kUseFunctions, "prod"), 123);
    EXPECT_EQ(m.stat(kUseFunctions, "dot"), 20);
    EXPECT_EQ(m.stat(kUseFunctions, "one"), 4);
    // patterns.md 1 and 2: nothing requested
    EXPECT_EQ(m.stat(kPatterns, "step"), 0);
    EXPECT_EQ(*m.v->plcs().global("mode"), 0);
    // the axis PLC: firstscan once
    EXPECT_EQ(*m.v->plcs().global("axplcFirst"), 1);
    // functions.md: every function once, then the results
    m.set(kFunctions, "call", 1);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kFunctions, "call"), 0);
    EXPECT_EQ(m.v->plcs().status(kFunctions).error, 0);
    EXPECT_EQ(m.stat(kFunctions, "bit"), 1);
    EXPECT_EQ(m.stat(kFunctions, "bits"), 5);
    EXPECT_EQ(m.stat(kFunctions, "m2m"), 1.5);
    EXPECT_EQ(m.stat(kFunctions, "size"), 100);
    EXPECT_EQ(m.stat(kFunctions, "lut"), 5); // halfway between (0, 0) and (5, 10)
    EXPECT_EQ(m.stat(kFunctions, "prim"), 1);
    EXPECT_EQ(m.stat(kFunctions, "started"), 0); // no PVs served in the test
    EXPECT_GT(m.stat(kFunctions, "t"), 0);
}

// patterns.md 1-6: the step starts on request, the mode is shared, positions are captured
// while the axis is busy, the storage is pushed. Patterns 3 and 4 pulse `execute` for one scan:
// that starts the move (or homing), and, as in ECMC, the next scan's execute 0 stops it again
// (ECMC's mc_move_abs/mc_home call setExecute(0) whenever execute is 0, which raises the
// trajectory's noExecute interlock: a normal stop). The manual's "one-scan pulse" is thus only
// the start; to complete a move, execute is held until the axis is done (IocPlc tests).
TEST(PlcManual, PatternsActAsEcmcDoes) {
    ManualIoc m;
    m.v->cycles(10);
    m.set(kPatterns, "startCmd", 1);
    m.set(kPatterns, "requestAuto", 1);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kPatterns, "step"), 1);
    EXPECT_EQ(*m.v->plcs().global("mode"), 1);
    m.power();
    ASSERT_TRUE(m.until([&] { return m.st().enabled; }, 2000));
    // pattern 3: the request is consumed, one scan of execute starts the move
    m.set(kPatterns, "moveReq", 1);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kPatterns, "moveReq"), 0);
    EXPECT_EQ(m.stat(kPatterns, "execute"), 1);
    EXPECT_TRUE(m.st().busy);
    EXPECT_EQ(m.st().target_pos, 12);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kPatterns, "execute"), 0); // ...and its end stops it
    ASSERT_TRUE(m.until([&] { return !m.st().busy; }, 2000));
    EXPECT_EQ(m.st().error_id, 0u);
    EXPECT_LT(std::fabs(m.st().set_pos), 0.01); // stopped at once (30 mm/s^2 ramps)
    // pattern 5: ds0 got ax1.enc.actpos in each busy scan
    const double n = m.stat(kVariables, "dsindex");
    EXPECT_GE(n, 2);
    EXPECT_LT(n, 100);
    // pattern 6: the push request is consumed
    m.set(kPatterns, "pushNow", 1);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kPatterns, "pushNow"), 0);
    // pattern 4: homing starts on the pulse (not homed, idle), the sequence runs, then stops
    EXPECT_FALSE(m.st().homed);
    m.set(kPatterns, "homeReq", 1);
    m.v->cycles(1);
    EXPECT_EQ(m.stat(kPatterns, "homeReq"), 0);
    EXPECT_EQ(m.stat(kPatterns, "homeExecute"), 1);
    EXPECT_TRUE(m.st().busy);
    ASSERT_TRUE(m.until([&] { return !m.st().busy; }, 5000));
    EXPECT_FALSE(m.st().homed);
    EXPECT_EQ(m.st().error_id, 0u);
    // pattern 3 again, this time the axis is idle again: a new request starts a new move
    m.set(kPatterns, "moveReq", 1);
    m.v->cycles(1);
    EXPECT_TRUE(m.st().busy);
}

// variables.md 1-49 and the PLC items: each static of variables.plc holds what the axis, the bus,
// the storage and the PLCs show in the same cycle, read while the axis moves.
TEST(PlcManual, EveryVariableReadsWhatTheManualSays) {
    ManualIoc m;
    m.power();
    ASSERT_TRUE(m.until([&] { return m.st().enabled; }, 2000));
    m.v->send("M1", motion::AxisCommand{motion::CommandType::MoveAbsolute, 20});
    m.v->cycles(300); // accelerating: a following error
    const motion::AxisStatus& s = m.st();
    ASSERT_TRUE(s.busy);
    auto v = [&](const char* name) { return m.stat(kVariables, name); };
    EXPECT_EQ(v("count"), double(m.v->plcs().status(kVariables).scans)) << "static.* keeps its value between scans";
    EXPECT_EQ(*m.v->plcs().global("count"), v("count"));
    EXPECT_EQ(v("local"), 1);
    EXPECT_EQ(v("input"), 1); // the forward limit switch (normally closed): not reached
    EXPECT_EQ(v("masterOk"), 1);
    EXPECT_EQ(v("id"), 1);
    EXPECT_EQ(v("reset"), 0);
    EXPECT_EQ(v("counter"), double(s.cycle));
    EXPECT_EQ(v("error"), 0);
    EXPECT_EQ(v("allowplccmd"), 1);
    EXPECT_EQ(v("actpos"), s.act_pos);
    EXPECT_EQ(v("actvel"), s.act_vel);
    EXPECT_NEAR(v("rawpos"), s.act_pos * 12800, 1e-6); // counts (from 0 at the start), 12800 per mm
    EXPECT_EQ(v("encsource"), 0);
    EXPECT_EQ(v("homed"), 0);
    EXPECT_EQ(v("homepos"), -30);
    EXPECT_EQ(v("setpos"), s.set_pos);
    EXPECT_EQ(v("setvel"), s.set_vel);
    EXPECT_EQ(v("setvelffraw"), s.set_vel * 1); // Kff 1
    EXPECT_EQ(v("trajsource"), 0);
    EXPECT_EQ(v("busy"), 1);
    EXPECT_EQ(v("dir"), 1);
    // 27, 28: the controller's error (ECMC cntrlError) and the position error, [EGU]
    EXPECT_GT(v("cntrlerror"), 0.001);
    EXPECT_EQ(v("cntrlerror"), s.set_pos - s.act_pos);
    EXPECT_EQ(v("cntrlerror"), s.pos_err);
    EXPECT_EQ(v("poserror"), v("cntrlerror"));
    EXPECT_EQ(v("setvelraw"), s.drive_output);
    EXPECT_EQ(v("enable"), 1);
    EXPECT_EQ(v("enabled"), 1);
    EXPECT_EQ(v("seqstate"), s.sequence_state);
    EXPECT_EQ(v("ilock"), 1);
    EXPECT_EQ(v("ilockbwd"), 1);
    EXPECT_EQ(v("ilockfwd"), 1);
    EXPECT_EQ(v("attarget"), 0);
    EXPECT_EQ(v("lowlim"), 1); // 1: not on the switch
    EXPECT_EQ(v("highlim"), 1);
    EXPECT_EQ(v("homesensor"), 0);
    EXPECT_EQ(v("lowsoftlim"), -45);
    EXPECT_EQ(v("highsoftlim"), 45);
    EXPECT_EQ(v("lowsoftlimenable"), 0);
    EXPECT_EQ(v("highsoftlimenable"), 0);
    EXPECT_EQ(v("blockcom"), 0);
    EXPECT_EQ(v("kp"), 10);
    EXPECT_EQ(v("ki"), 0.5);
    EXPECT_EQ(v("kd"), 0);
    EXPECT_EQ(v("kff"), 1);
    // PLC items: another PLC's (plc0) and the axis PLC's
    EXPECT_EQ(v("plcenable"), 1);
    EXPECT_EQ(v("plcdbg"), 0);
    EXPECT_EQ(v("plcerror"), 0);
    EXPECT_DOUBLE_EQ(v("scantime"), 0.001);
    EXPECT_EQ(v("firstscan"), 0);
    EXPECT_EQ(v("axplcenable"), 1);
    EXPECT_EQ(v("axplcerror"), 0);
    EXPECT_DOUBLE_EQ(v("axplcscantime"), 0.001);
    EXPECT_EQ(v("axplcfirstscan"), 0);
    // data storage: size 100 of the IOC file, filled by patterns.plc while the axis is busy; the
    // appends after that fail with 0x20203 (a normal buffer)
    EXPECT_EQ(v("dssize"), 100);
    EXPECT_EQ(v("dsindex"), 100);
    EXPECT_EQ(v("dsfull"), 1);
    EXPECT_EQ(v("dserror"), 0x20203);
    EXPECT_TRUE(std::isnan(v("dsappend"))); // reads NaN: every assignment appends
    ASSERT_TRUE(m.until([&] { return !m.st().busy; }, 10000));
    m.v->cycles(20);
    EXPECT_EQ(v("attarget"), 1);
    EXPECT_EQ(v("busy"), 0);
    EXPECT_EQ(v("dir"), 0);
    EXPECT_NEAR(v("cntrlerror"), 0, 0.01);
}

// ax<n>.cntrl.error is the error the position controller acts on: with Kp alone (ctrl.ki, kd, kff
// written 0), the controller's output is Kp times it, every cycle of a move; written gains take
// effect in the next cycle (a general PLC writes after the axes) and read back.
TEST(PlcManual, CntrlErrorIsTheControllersPositionErrorAndCtrlGainsAct) {
    AxisRig r(R"(
        if (static.gains) { ax1.ctrl.kp := static.kp; ax1.ctrl.ki := 0; ax1.ctrl.kd := 0; ax1.ctrl.kff := 0; static.gains := 0; };
        static.err := ax1.cntrl.error;
        static.poserr := ax1.cntrl.poserror;
        static.out := ax1.cntrl.output;
        static.kp := ax1.ctrl.kp; static.ki := ax1.ctrl.ki; static.kd := ax1.ctrl.kd; static.kff := ax1.ctrl.kff;
        if (abs(static.out - static.kp * static.err) > 1e-9 * (1 + abs(static.out))) { static.mismatch += 1; };
        if (abs(static.err) > static.maxErr) { static.maxErr := abs(static.err); };
    )");
    r.v->cycles(5);
    r.set("kp", 20);
    r.set("gains", 1);
    r.v->cycles(1);
    EXPECT_EQ(r.stat("kp"), 20);
    EXPECT_EQ(r.stat("ki"), 0);
    EXPECT_EQ(r.stat("kff"), 0);
    r.power();
    for (int i = 0; i < 2000 && !r.st().enabled; ++i) r.v->cycles(1);
    ASSERT_TRUE(r.st().enabled);
    r.set("mismatch", 0);
    r.move_to(5);
    r.v->cycles(200);
    EXPECT_TRUE(r.st().busy);
    EXPECT_EQ(r.stat("err"), r.st().pos_err);
    EXPECT_EQ(r.stat("err"), r.stat("poserr"));
    EXPECT_NE(r.stat("err"), 0);
    EXPECT_EQ(r.stat("out"), r.st().drive_output); // Kff 0: the output is the PID's alone
    for (int i = 0; i < 5000 && r.st().busy; ++i) r.v->cycles(1);
    EXPECT_FALSE(r.st().busy);
    EXPECT_EQ(r.st().error_id, 0u);
    EXPECT_NEAR(r.st().act_pos, 5, 0.1);
    EXPECT_EQ(r.stat("mismatch"), 0);
    EXPECT_GT(r.stat("maxErr"), 0.1); // Kp 20 without feed-forward lags 5/20 mm behind at 5 mm/s
    // Kp 0: no output at all, the setpoint runs away from the actual position
    r.set("kp", 0);
    r.set("gains", 1);
    r.v->cycles(200); // the stage comes to rest
    const double at = r.st().act_pos;
    r.move_to(5.5);
    r.v->cycles(50);
    EXPECT_EQ(r.stat("kp"), 0);
    EXPECT_EQ(r.st().drive_output, 0);
    EXPECT_GT(r.stat("err"), 0);
    EXPECT_NEAR(r.st().act_pos, at, 1e-3);
}

// ax<n>.enc.homed (rw in the manual; ECMC setAxisHomed): a write marks the primary encoder homed
// or not, from a general PLC or the axis PLC; dropped while allowplccmd is 0.
TEST(PlcManual, EncHomedWriteMarksThePrimaryEncoder) {
    AxisRig r(R"(
        if (static.write) { ax1.enc.homed := static.value; static.write := 0; };
        if (static.block) { ax1.allowplccmd := 0; } else { ax1.allowplccmd := 1; };
        static.homed := ax1.enc.homed;
        static.fn := mc_get_homed(1);
    )");
    r.v->cycles(5);
    EXPECT_FALSE(r.st().homed);
    r.set("value", 1);
    r.set("write", 1);
    r.v->cycles(1);
    EXPECT_TRUE(r.st().homed); // applied right after the scan
    r.v->cycles(1);
    EXPECT_EQ(r.stat("homed"), 1);
    EXPECT_EQ(r.stat("fn"), 1);
    r.v->cycles(10);
    EXPECT_TRUE(r.st().homed); // the axis keeps it
    r.set("value", 0);
    r.set("write", 1);
    r.v->cycles(2);
    EXPECT_FALSE(r.st().homed);
    EXPECT_EQ(r.stat("homed"), 0);
    // allowplccmd 0: ignored
    r.set("block", 1);
    r.v->cycles(2);
    r.set("value", 1);
    r.set("write", 1);
    r.v->cycles(2);
    EXPECT_FALSE(r.st().homed);
    // rewriting the value it reads is no write (ECMC writes a boolean back only when it changed)
    r.set("block", 0);
    r.v->cycles(2);
    r.set("value", 0);
    r.set("write", 1);
    r.v->cycles(2);
    EXPECT_FALSE(r.st().homed);
}

// The same from the axis PLC: acts in the cycle it runs in.
TEST(PlcManual, EncHomedFromTheAxisPlc) {
    TempDir d;
    for (const char* f : {"plant.yaml"}) fs::copy(kManual / f, d.path / f);
    std::ifstream in(kManual / "axis.yaml");
    std::string axis((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    axis = axis.substr(0, axis.find("plc:\n")) +
           "plc:\n  enable: true\n  code:\n    - \"static.n += 1; if (static.n == 3) { ax1.enc.homed := 1; };\"\n";
    d.write("axis.yaml", axis);
    VirtualIoc v(d.write("ioc.yaml", "ioc: {name: R}\nengine: {rate_hz: 1000}\nbuses:\n  - id: 0\n"
                                     "    link: {type: sim, plant: plant.yaml}\n    slaves:\n"
                                     "      - {position: 0, type: EK1100}\n      - {position: 1, type: EL1008}\n"
                                     "      - {position: 2, type: EL7041}\naxes:\n  - {file: axis.yaml}\n"));
    v.cycles(2);
    EXPECT_FALSE(v.axis("M1").status().homed);
    v.cycles(1);
    EXPECT_TRUE(v.axis("M1").status().homed);
}

// variables.md's PLC items from any PLC, in any order: plc0 reads and writes plc1 (added after
// it) and reads the axis PLC's items (axis PLCs are added after the general ones); ECMC makes them
// data items shared by name.
TEST(PlcManual, PlcItemsOfLaterPlcsAndOfAxisPlcs) {
    TempDir d;
    for (const char* f : {"axis.yaml", "plant.yaml"}) fs::copy(kManual / f, d.path / f);
    d.write("first.plc", R"(
        static.n += 1;
        static.otherEnable := plc1.enable; static.otherScantime := plc1.scantime;
        static.axEnable := ax1.plc.enable; static.axScantime := ax1.plc.scantime;
        static.axFirst += ax1.plc.firstscan;
        if (static.n == 10) { plc1.enable := 0; };
    )");
    d.write("second.plc", "static.n += 1;\n");
    VirtualIoc v(d.write("ioc.yaml", "ioc: {name: R}\nengine: {rate_hz: 1000}\nbuses:\n  - id: 0\n"
                                     "    link: {type: sim, plant: plant.yaml}\n    slaves:\n"
                                     "      - {position: 0, type: EK1100}\n      - {position: 1, type: EL1008}\n"
                                     "      - {position: 2, type: EL7041}\naxes:\n  - {file: axis.yaml}\n"
                                     "plcs:\n  - {id: 0, file: first.plc}\n  - {id: 1, file: second.plc, rate_ms: 2}\n"));
    v.cycles(40);
    EXPECT_EQ(v.stat(0, "n"), 40);
    EXPECT_EQ(v.stat(1, "n"), 4); // in cycles 2, 4, 6, 8: in cycle 10 plc0 (before it) disabled it
    EXPECT_EQ(v.stat(0, "otherEnable"), 0);
    EXPECT_DOUBLE_EQ(v.stat(0, "otherScantime"), 0.002);
    EXPECT_EQ(v.stat(0, "axEnable"), 1);
    EXPECT_DOUBLE_EQ(v.stat(0, "axScantime"), 0.001);
    EXPECT_EQ(v.stat(0, "axFirst"), 1); // the axis PLC runs before plc0 in each cycle: its first scan, once
    EXPECT_FALSE(v.plcs().status(1).enabled);
}

// ---- compile-level forms ------------------------------------------------------------------------

namespace {

std::string errors(plc::test::TableHost& h, const std::string& code, const plc::CompileOptions& o = {}) {
    try {
        plc::Program::compile(code, "t.plc", h, o);
    } catch (const plc::CompileError& e) {
        return e.what();
    }
    return "<no error>";
}

} // namespace

// best_practice.md's VAR block: every address form of syntax.md's list, `//` comments, macros in
// the addresses, and a last line without ';' (`myPLC : ${SELF}`), which ECMC skips (its
// parseVarBlock reads `name : address;` per line): the file compiles, myPLC is no alias, and a
// use of it says why.
TEST(PlcManual, VarBlockOfTheManual) {
    plc::test::TableHost h;
    h.add("ec0.s2.binaryOutput02", 1);
    h.add("ec0.s3.positionActual01", 40);
    h.add("ec0.s3.driveControl01", 9);
    h.add("ax1.traj.targetpos", 2);
    h.add("ax1.traj.setpos", 0);
    h.add("ax1.enc.actpos", 1.5);
    h.add("ds0.index", 7);
    h.add("plc0.enable", 1);
    plc::CompileOptions o;
    o.macros = {{"M", "ec0"}, {"SELF", "plc0"}, {"DRV_SID", "3"}};
    const std::string block = R"(VAR
  // Globals
  gTest          : global.test;
  // Statics
  sTest          : static.test;
  // EtherCAT I/0
  actPos         : ${M}.s${DRV_SID}.positionActual01;
  mySlave        : ${M}.s${DRV_SID};
  coolingValveBO : ${M}.s${BO_SID=2}.binaryOutput02;
  // Axis data
  targetPos      : ax${AX_ID=1}.traj.targetpos;
  myAxis         : ax1;
  myTraj         : ax${AX_ID=1}.traj;
  // Data storage
  buffer         : ds${DS_ID=0};
  // Constants
  pi             : 3.1415;
  // PLC
  myPLC          : ${SELF}

END_VAR
)";
    plc::Program p = plc::Program::compile(block + R"(
coolingValveBO:=not(coolingValveBO);
static.ctrl := mySlave.driveControl${CH=01};
static.moved := myTraj.targetpos<>static.oldTarget;
static.oldTarget := myTraj.targetpos;
static.sum := gTest + 1 + sTest + mySlave.positionActual01 + actPos;
static.enc := myAxis.enc.actpos+pi;
gTest += 1;
static.index := buffer.index + targetPos;
if(myTraj.setpos>=0) {
    myTraj.setpos+=1;
}
)",
                                           "t.plc", h, o);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ec0.s2.binaryOutput02"], 0);
    EXPECT_EQ(h["static.ctrl"], 9);
    EXPECT_EQ(h["static.moved"], 1);
    EXPECT_EQ(h["static.oldTarget"], 2);
    EXPECT_EQ(h["static.sum"], 0 + 1 + 0 + 40 + 40);
    EXPECT_DOUBLE_EQ(h["static.enc"], 1.5 + 3.1415);
    EXPECT_EQ(h["global.test"], 1);
    EXPECT_EQ(h["static.index"], 9);
    EXPECT_EQ(h["ax1.traj.setpos"], 1);
    // myPLC is no alias (ECMC skipped its line); using it is an error naming the entry
    plc::test::TableHost h2;
    h2.add("plc0.enable", 1);
    const std::string e = errors(h2, "VAR\n  myPLC : plc0\n  en : plc0.enable;\nEND_VAR\nen := 1;\nmyPLC.enable := 0;\n");
    EXPECT_NE(e.find("t.plc:6:1: 'myPLC' is no alias: its VAR entry (t.plc:2:3) has no ';' on its line, and ECMC "
                     "skips such a line"),
              std::string::npos)
        << e;
    // the next line's entry is still read; a skipped name may still be declared with `var`
    plc::test::TableHost h3;
    plc::Program q = plc::Program::compile("VAR\n  a : static.a\n  b : static.b;\nEND_VAR\nb := 4;\nvar a := 2;\nstatic.c := a;\n",
                                           "t.plc", h3);
    ASSERT_EQ(q.run(), 0);
    EXPECT_EQ(h3["static.b"], 4);
    EXPECT_EQ(h3["static.c"], 2);
}

// syntax.md's comment rule: '#' to the end of the line is removed before compiling, also inside
// a string, so the manual's `println('########');` is seen as `println('` (an error, as in ECMC).
TEST(PlcManual, HashEndsTheLineEvenInAString) {
    plc::test::TableHost h;
    const std::string e = errors(h, "println('########');\n");
    EXPECT_NE(e.find("string not terminated (a '#' ends the line, also inside a string)"), std::string::npos) << e;
    plc::Program p = plc::Program::compile("static.a := 1; # static.a := 2;\nstatic.b := static.a; #\n", "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.a"], 1);
    EXPECT_EQ(h["static.b"], 1);
}

// The axis variable table has every name of the manual's motion list (1-49), with the manual's
// access (rw where ECMC's writeAxis acts), cntrl.error on the same value as cntrl.poserror.
TEST(PlcManual, AxisVariableTableIsTheManualsList) {
    const char* rw[] = {"reset", "allowplccmd", "enc.actpos", "enc.source", "enc.homed", "enc.homepos",
                        "traj.setpos", "traj.targetpos", "traj.extsetpos", "traj.targetvel", "traj.targetacc",
                        "traj.targetdec", "traj.command", "traj.cmddata", "traj.source", "traj.execute",
                        "drv.enable", "mon.ilock", "mon.ilockbwd", "mon.ilockfwd", "mon.lowsoftlim",
                        "mon.highsoftlim", "mon.lowsoftlimenable", "mon.highsoftlimenable", "blockcom",
                        "ctrl.kp", "ctrl.ki", "ctrl.kd", "ctrl.kff"};
    const char* ro[] = {"id", "counter", "error", "enc.actvel", "enc.rawpos", "traj.setvel", "traj.setvelffraw",
                        "traj.busy", "traj.dir", "cntrl.error", "cntrl.poserror", "cntrl.output", "drv.setvelraw",
                        "drv.enabled", "seq.state", "mon.attarget"};
    for (const char* n : rw) {
        const auto* v = motion::find_axis_variable(n);
        ASSERT_NE(v, nullptr) << n;
        EXPECT_TRUE(v->writable) << n;
    }
    for (const char* n : ro) {
        const auto* v = motion::find_axis_variable(n);
        ASSERT_NE(v, nullptr) << n;
        EXPECT_FALSE(v->writable) << n;
    }
    // listed read-only by the manual, readable and (beamctl, as ecmccfg's plc_lib uses them)
    // writable: enc.extactpos, mon.lowlim/highlim/homesensor (limits and home sensor with plcOverride)
    for (const char* n : {"enc.extactpos", "mon.lowlim", "mon.highlim", "mon.homesensor"})
        EXPECT_NE(motion::find_axis_variable(n), nullptr) << n;
    EXPECT_EQ(motion::find_axis_variable("cntrl.error")->offset, motion::find_axis_variable("cntrl.poserror")->offset);
    EXPECT_TRUE(motion::is_readback(*motion::find_axis_variable("enc.homed"))); // the axis publishes it
}
