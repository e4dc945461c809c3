// Binding names through the Host, the RT contract of run() (no allocation, faults end the scan
// and leave the program usable, bounded loops), ECMC-style PLCs, and the cost of a scan.
#include "../alloc_counter.hpp"
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

using beamctl::plc::CompileError;
using beamctl::plc::CompileOptions;
using beamctl::plc::Program;
using beamctl::plc::RunStatus;
using beamctl::plc::test::TableHost;

namespace {

const std::filesystem::path kData = std::filesystem::path(__FILE__).parent_path() / "data";

std::string first_error(TableHost& h, const std::string& code) {
    try {
        Program::compile(code, "t.plc", h);
    } catch (const CompileError& e) {
        return e.what();
    }
    return "<no error>";
}

} // namespace

// ---- binding --------------------------------------------------------------------------------

TEST(PlcBinding, UnknownNameIsAnErrorAtItsPosition) {
    TableHost h;
    h.add("ax1.enc.actpos");
    EXPECT_EQ(first_error(h, "ax1.enc.actpos := 1;\n  static.x := ax9.enc.actpos + 1;"),
              "t.plc:2:15: unknown name 'ax9.enc.actpos'\n"
              "  static.x := ax9.enc.actpos + 1;\n"
              "              ^");
    EXPECT_NE(first_error(h, "mc_move_abs(1, 1, 2, 3, 4, 5);").find("unknown name 'mc_move_abs'"),
              std::string::npos);
}

TEST(PlcBinding, WritingAReadOnlyNameIsAnError) {
    TableHost h;
    h.add("ax1.enc.actpos", 0, false);
    h.add("ax1.traj.extsetpos");
    EXPECT_EQ(first_error(h, "ax1.traj.extsetpos := ax1.enc.actpos;\nax1.enc.actpos := 5;"),
              "t.plc:2:1: 'ax1.enc.actpos' is read-only\n"
              "ax1.enc.actpos := 5;\n"
              "^");
    EXPECT_NE(first_error(h, "ax1.enc.actpos += 1;").find("read-only"), std::string::npos);
    EXPECT_NE(first_error(h, "ax1.enc.actpos <=> ax1.traj.extsetpos;").find("read-only"),
              std::string::npos);
    EXPECT_NE(first_error(h, "pi := 3;").find("cannot assign to the constant 'pi'"),
              std::string::npos);
}

TEST(PlcBinding, NamesAreResolvedOnceAtCompileTimeAndReadLive) {
    TableHost h;
    double& in = h.add("ec0.s3.binaryInput01.0", 1);
    double& out = h.add("ec0.s4.binaryOutput02");
    Program p = Program::compile("ec0.s4.binaryOutput02 := not(ec0.s3.binaryInput01.0);\n"
                                 "static.n := ec0.s3.binaryInput01.0 + ec0.s3.binaryInput01.0;",
                                 "t.plc", h);
    EXPECT_EQ(std::count(h.resolved.begin(), h.resolved.end(), "ec0.s3.binaryInput01.0"), 1);
    const std::size_t resolves = h.resolved.size();
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(out, 0);
    in = 0;
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(out, 1);
    EXPECT_EQ(h.resolved.size(), resolves); // nothing resolved while running
}

TEST(PlcBinding, HostFunctions) {
    TableHost h;
    std::vector<double> got;
    h.add_function("ds_append_data", 2, 2, [&](const double* a, int n) {
        got.assign(a, a + n);
        return 0.0;
    });
    h.add_function("ec_get_time", 0, 0, [](const double*, int) { return 123.0; });
    h.add("ax1.enc.actpos", 4.5);
    Program p = Program::compile("static.e := ds_append_data(2, ax1.enc.actpos * 2);\n"
                                 "static.t := ec_get_time() + ec_get_time;",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(got, (std::vector<double>{2, 9}));
    EXPECT_EQ(h["static.t"], 246);
    EXPECT_NE(
        first_error(h, "ds_append_data(1);").find("'ds_append_data' takes 2 arguments, got 1"),
        std::string::npos);
    EXPECT_NE(first_error(h, "ds_append_data('a', 1);").find("string arguments"),
              std::string::npos);
}

// ---- run() ----------------------------------------------------------------------------------

namespace {

// Exercises every kind of instruction: host calls, print, functions (also recursive),
// vectors, loops, short-circuits.
const char* const kBusyProgram = R"(
    function fib(n) { if (n < 2) { n } else { fib(n - 1) + fib(n - 2) } }
    var v[8] := {1, 2, 3};
    var acc := 0;
    for (var i := 0; i < v[]; i += 1) {
        if (i % 2 == 0 & v[i] > 0) continue;
        v[i] := sqrt(i) * static.gain + fib(i);
        acc += v[i];
    };
    var k := 0;
    while ((k += 1) < 5) { acc += sum(v * 2) / 100; };
    static.out := acc + dot(v, v) / 1000 + max(v) + swap_test();
    function swap_test() { var a := 1; var b := 2; a <=> b; a - b }
    static.t := now();
    if (static.t % 100 == 0) { println('t = ', static.t, ' v = ', v); };
    static.gain := static.gain * 0.5 + 1;
)";

} // namespace

TEST(PlcRun, AllocatesNothing) {
    TableHost h;
    h.keep_prints = false;
    double t = 0;
    h.add_function("now", 0, 0, [&](const double*, int) { return t; });
    Program p = Program::compile(kBusyProgram, "t.plc", h);
    ASSERT_EQ(p.run(), 0); // first scan outside the count (nothing is lazily set up, though)
    beamctl::test::count_allocations(true);
    int failures = 0;
    for (int i = 0; i < 20000; ++i) {
        t = i;
        failures += p.run() != 0;
    }
    beamctl::test::count_allocations(false);
    EXPECT_EQ(beamctl::test::allocations(), 0);
    EXPECT_EQ(failures, 0);
    EXPECT_EQ(h.print_calls, 201);
    EXPECT_TRUE(std::isfinite(h["static.out"]));
}

TEST(PlcRun, IndexOutOfRangeEndsTheScanAndTheProgramStaysUsable) {
    TableHost h;
    h.add("i", 5);
    Program p = Program::compile("static.before += 1;\n"
                                 "var v[3] := {10, 20, 30};\n"
                                 "static.got := v[i];\n"
                                 "static.after += 1;\n",
                                 "t.plc", h);
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::index_out_of_range));
    EXPECT_EQ(p.fault_location(), "t.plc:3:15: vector index out of range");
    EXPECT_EQ(h["static.before"], 1); // done before the fault
    EXPECT_EQ(h["static.after"], 0);  // nothing after it
    h["i"] = -0.5;
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::index_out_of_range));
    h["i"] = std::nan("");
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::index_out_of_range));
    h["i"] = 2.9; // truncated
    EXPECT_EQ(p.run(), 0);
    EXPECT_EQ(p.fault_location(), "");
    EXPECT_EQ(h["static.got"], 30);
    EXPECT_EQ(h["static.after"], 1);
    EXPECT_EQ(h["static.before"], 4);
}

TEST(PlcRun, StoreOutOfRangeWritesNothing) {
    TableHost h;
    h.add("i", 3);
    Program p = Program::compile("var v[3]; v[i] := 1; static.x := 1;", "t.plc", h);
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::index_out_of_range));
    EXPECT_EQ(h["static.x"], 0);
}

TEST(PlcRun, LoopBudget) {
    TableHost h;
    CompileOptions o;
    o.max_loop_iterations = 1000;
    Program p =
        Program::compile("static.n := 0;\nwhile (static.go) { static.n += 1; };", "t.plc", h, o);
    h["static.go"] = 1;
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::loop_budget_exceeded));
    EXPECT_EQ(h["static.n"], 1001); // 1000 iterations went back to the condition
    EXPECT_EQ(p.fault_location().rfind("t.plc:2:1: loop iteration budget exceeded", 0), 0u)
        << p.fault_location();
    h["static.go"] = 0;
    EXPECT_EQ(p.run(), 0);
    p.set_loop_budget(10);
    h["static.go"] = 1;
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::loop_budget_exceeded));
    EXPECT_EQ(h["static.n"], 11);
}

TEST(PlcRun, LoopBudgetCoversContinue) {
    TableHost h;
    Program p = Program::compile("for (;;) { continue; };", "t.plc", h);
    p.set_loop_budget(100);
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::loop_budget_exceeded));
}

TEST(PlcRun, CallDepth) {
    TableHost h;
    CompileOptions o;
    o.max_call_depth = 16;
    Program p = Program::compile("function down(n) { if (n > 0) { 1 + down(n - 1) } else { 0 } }\n"
                                 "static.r := down(static.n);",
                                 "t.plc", h, o);
    h["static.n"] = 10;
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.r"], 10);
    h["static.n"] = 100;
    EXPECT_EQ(p.run(), static_cast<int>(RunStatus::call_depth_exceeded));
    h["static.n"] = 15; // usable again, recursion state reset
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.r"], 15);
}

// ---- ECMC-style programs --------------------------------------------------------------------

namespace {

struct SlitAxes {
    TableHost h;
    explicit SlitAxes() {
        for (int ax = 1; ax <= 4; ++ax) {
            const std::string a = "ax" + std::to_string(ax) + ".";
            for (const char* item : {"enc.actpos", "traj.setpos", "traj.extsetpos", "mon.ilockfwd",
                                     "mon.ilockbwd", "mon.lowsoftlim", "mon.highsoftlim"})
                h.add(a + item);
            h.add(a + "mon.highlim", 1, false); // 1: not at the limit switch (ECMC)
            h.add(a + "mon.lowlim", 1, false);
        }
    }
};

CompileOptions slit_macros() {
    CompileOptions o;
    o.macros = {{"LO", "1"}, {"HI", "2"}, {"CEN", "3"}, {"GAP", "4"}};
    return o;
}

} // namespace

TEST(PlcEcmc, SlitKinematics) {
    SlitAxes s;
    TableHost& h = s.h;
    Program p = Program::compile_file((kData / "slit.plc").string(), h, slit_macros());
    // Blades at -1 and 3: centre 1, gap 4.
    h["ax1.enc.actpos"] = -1;
    h["ax2.enc.actpos"] = 3;
    // Centre 0, gap 4 requested: blades to -2 and +2.
    h["ax3.traj.setpos"] = 0;
    h["ax4.traj.setpos"] = 4;
    h["ax1.mon.lowsoftlim"] = -10;
    h["ax1.mon.highsoftlim"] = 5;
    h["ax2.mon.lowsoftlim"] = -5;
    h["ax2.mon.highsoftlim"] = 10;
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ax3.enc.actpos"], 1);
    EXPECT_EQ(h["ax4.enc.actpos"], 4);
    EXPECT_EQ(h["ax1.traj.extsetpos"], -2);
    EXPECT_EQ(h["ax2.traj.extsetpos"], 2);
    EXPECT_EQ(h["ax3.mon.ilockfwd"], 1);
    EXPECT_EQ(h["ax4.mon.ilockbwd"], 1);
    EXPECT_EQ(h["ax4.mon.lowsoftlim"], -10);
    EXPECT_EQ(h["ax4.mon.highsoftlim"], 20);
    EXPECT_EQ(h["ax3.mon.lowsoftlim"], -7);
    EXPECT_EQ(h["ax3.mon.highsoftlim"], 7);

    // One blade at its high limit: the virtual axes may not move forward, backward is fine.
    h["ax2.mon.highlim"] = 0;
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ax3.mon.ilockfwd"], 0);
    EXPECT_EQ(h["ax4.mon.ilockfwd"], 0);
    EXPECT_EQ(h["ax3.mon.ilockbwd"], 1);
    EXPECT_EQ(h["ax4.mon.ilockbwd"], 1);

    // Soft limits frozen: the scan ends before recomputing them.
    h["static.fixedSoftLimits"] = 1;
    h["ax2.mon.highsoftlim"] = 100;
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ax3.mon.highsoftlim"], 7);
}

namespace {

// A toy axis for mc_move_abs: a rising edge of `execute` starts a move at `vel` per scan.
struct ToyAxis {
    double pos = 0, target = 0, vel = 0;
    bool busy = false, last_execute = false;
    int moves = 0;
    void scan(TableHost& h) {
        if (busy) {
            const double step = std::min(std::abs(target - pos), vel);
            pos += target > pos ? step : -step;
            busy = pos != target;
        }
        h["ax1.enc.actpos"] = pos;
        h["ax1.mon.attarget"] = busy ? 0 : 1;
    }
};

} // namespace

TEST(PlcEcmc, BackAndForthSequenceWithEdgeDetection) {
    TableHost h;
    ToyAxis axis;
    for (const char* n : {"ax1.enc.actpos", "ax1.mon.attarget"}) h.add(n);
    h.add("ax1.drv.enabled", 1);
    h.add("ax1.mon.lowlim", 1);
    h.add("ax1.mon.highlim", 1);
    h.add("plc0.firstscan", 1, false);
    h.add("plc0.enable", 1);
    h.add_function("mc_move_abs", 6, 6, [&](const double* a, int) {
        const bool execute = a[1] != 0;
        if (execute && !axis.last_execute) {
            axis.target = a[2];
            axis.vel = a[3];
            axis.busy = true;
            ++axis.moves;
        }
        axis.last_execute = execute;
        return 0.0;
    });
    h.add_function("mc_get_busy", 1, 1, [&](const double*, int) { return axis.busy ? 1.0 : 0.0; });
    h.add_function("mc_power", 2, 2, [&](const double* a, int) {
        h["ax1.drv.enabled"] = a[1];
        return 0.0;
    });
    CompileOptions o;
    o.macros = {{"SELF", "plc0"}, {"AX", "1"}, {"VEL", "2.5"}};
    Program p = Program::compile_file((kData / "sequence.plc").string(), h, o);

    auto scans = [&](int n) {
        for (int i = 0; i < n; ++i) {
            axis.scan(h);
            ASSERT_EQ(p.run(), 0) << p.fault_location();
            h["plc0.firstscan"] = 0;
        }
    };
    h["static.posFrom"] = 0;
    h["static.posTo"] = 10;
    scans(3); // no edge yet: nothing moves
    ASSERT_EQ(h.printed.size(), 1u);
    EXPECT_EQ(h.printed[0], "Starting sequence on axis    1.00000\n");
    EXPECT_EQ(axis.moves, 0);

    h["static.doMotion"] = 1; // rising edge
    scans(1);
    EXPECT_EQ(h["static.seqStep"], 1);
    EXPECT_EQ(axis.moves, 1);
    scans(4); // 10 at 2.5 per scan; in the scan it arrives the move back starts
    EXPECT_EQ(axis.pos, 10);
    EXPECT_EQ(h["static.seqStep"], 2);
    EXPECT_EQ(h["static.cycleCounter"], 1);
    EXPECT_EQ(axis.moves, 2);
    scans(4);
    EXPECT_EQ(axis.pos, 0);
    EXPECT_EQ(h["static.cycleCounter"], 2);
    EXPECT_EQ(h["static.seqStep"], 1); // keeps going while doMotion is held...
    scans(1);
    EXPECT_EQ(axis.moves, 3); // ...with a new rising edge of execute for each move

    // A limit switch stops the sequence and the PLC disables itself.
    h["ax1.mon.highlim"] = 0;
    scans(1);
    EXPECT_EQ(h["ax1.drv.enabled"], 0);
    EXPECT_EQ(h["plc0.enable"], 0);
    EXPECT_EQ(h["static.seqStep"], 0);
    EXPECT_EQ(h.printed.back(), "Sequence stopped, error    0.00000\n");
}


