// The soft PLC inside an IOC, in virtual time (whole IOCs built from YAML, buses simulated):
// cycle order (ECMC acceptance 1), rates and variable scoping (9), mc_* function blocks (3),
// the demo slit's virtual axes (2), plugins (15), axis PLCs, run-time faults, compile errors
// against the IOC's buses and axes.
#include "../temp_dir.hpp"
#include "../alloc_counter.hpp"
#include "virtual_ioc.hpp"
#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "plc/runtime.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sys/mman.h>
#include <unistd.h>

using namespace beamctl;

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;

using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

// A small IOC: two digital terminals wired output 1 -> input 1, and virtual axes.
std::string ioc_yaml(const std::string& axes, const std::string& plcs, const std::string& extra = "") {
    return "ioc: {name: T}\n"
           "engine: {rate_hz: 1000}\n"
           "buses:\n"
           "  - id: 0\n"
           "    link: {type: sim, plant: plant.yaml}\n"
           "    slaves:\n"
           "      - {position: 0, type: EK1100}\n"
           "      - {position: 1, type: EL1008}\n"
           "      - {position: 2, type: EL2008}\n" +
           axes + plcs + extra;
}
const char* kPlant = "wiring:\n  - {from: s2.binaryOutput01, to: s1.binaryInput01}\n";
std::string virtual_axis(int id, const std::string& extra_macros = "") {
    return "  - {file: " + kSource + "/examples/demo/axes/virtual.yaml, macros: {AX_ID: " + std::to_string(id) +
           ", AX_NAME: V" + std::to_string(id) + ", DESC: v, LOW: -100, HIGH: 100" + extra_macros + "}}\n";
}


} // namespace

// Acceptance 1: an input of cycle k is seen by the PLC in k; its output leaves in k; a general
// PLC's extsetpos acts on its axis in k+1. The output written in scan 5 leaves with the frame of
// cycle 5; the input terminal (position 1) sits before the output terminal (position 2) on the
// segment, so that frame samples the input before the output changes and the frame of cycle 6
// brings it back, received at the start of cycle 7 and seen by scan 7. (Had the output left a
// cycle later, or the input been seen a cycle later, this would be 8.)
TEST(IocPlc, CycleOrder) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.n := static.n + 1;
        if (static.n == 1) { ax1.drv.enable := 1; };
        if (static.n == 5) { ec0.s2.binaryOutput01 := 1; };
        if (ec0.s1.binaryInput01 and static.seen == 0) { static.seen := static.n; };
        if (static.n == 10) { ax1.traj.source := 1; ax1.traj.extsetpos := 5; };
        if (ax1.traj.setpos == 5 and static.moved == 0) { static.moved := static.n; };
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n" + virtual_axis(1), "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(20);
    EXPECT_EQ(v.stat(0, "n"), 20);
    EXPECT_EQ(v.stat(0, "seen"), 7);
    EXPECT_EQ(v.stat(0, "moved"), 11); // written after the axes in cycle 10, taken in cycle 11
}

// An axis PLC runs just before its axis: what it writes acts in the same cycle.
TEST(IocPlc, AxisPlcActsInTheSameCycle) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("axis.yaml", R"(
axis: {id: 1, type: virtual, features: {allowSrcChangeWhenEnabled: true}}
epics: {name: Follower}
encoder: {numerator: 1, denominator: 1, type: 1, bits: 32, source: 1}
trajectory: {axis: {velocity: 1, acceleration: 1}}
input: {limit: {forward: ec0.s0.ONE.0, backward: ec0.s0.ONE.0}}
monitoring: {lag: {enable: false, tolerance: 1, time: 10}}
plc:
  enable: true
  code:
    - "if (ax1.plc.firstscan) { ax1.drv.enable := 1; ax1.traj.source := 1; };"
    - "static.k := static.k + 1; ax1.traj.extsetpos := static.k; global.k := static.k;"
)");
    d.write("main.plc", "static.lag := global.k - ax1.traj.setpos;\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n  - {file: axis.yaml}\n", "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(50);
    EXPECT_EQ(*v.plcs().global("k"), 50);
    EXPECT_EQ(v.axis("Follower").status().set_pos, 50);
    EXPECT_EQ(v.stat(0, "lag"), 0); // the general PLC (index 0; axis PLCs follow plcs:) sees this cycle's setpoint
    EXPECT_EQ(v.plcs().prefix(1), "ax1.plc");
}

// Acceptance 9: rate_ms 10 at 1 kHz runs every 10th cycle with scantime 0.01 and one firstscan;
// static is per PLC, global shared, var local to the scan.
TEST(IocPlc, RatesAndScoping) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("slow.plc", R"(
        static.scans := static.scans + 1;
        static.scantime := plc0.scantime;
        if (plc0.firstscan) { static.first := static.first + 1; };
        static.x := static.x + 1;
        global.g := global.g + 1;
        var v := 0;
        v := v + 1;
        static.v := v;
    )");
    d.write("fast.plc", R"(
        static.x := static.x + 10;
        global.g := global.g + 1;
        static.slow := plc0.enable;
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: slow.plc, rate_ms: 10}\n  - {id: 1, file: fast.plc}\n")));
    v.cycles(100);
    EXPECT_EQ(v.stat(0, "scans"), 10);
    EXPECT_DOUBLE_EQ(v.stat(0, "scantime"), 0.01);
    EXPECT_EQ(v.stat(0, "first"), 1);
    EXPECT_EQ(v.stat(0, "x"), 10);
    EXPECT_EQ(v.stat(1, "x"), 1000);
    EXPECT_EQ(*v.plcs().global("g"), 110);
    EXPECT_EQ(v.stat(0, "v"), 1);
    EXPECT_EQ(v.stat(1, "slow"), 1);
    EXPECT_EQ(v.plcs().status(0).scans, 10u);
    // Disabled from outside: it stops; enabled again: it continues, firstscan does not repeat.
    v.plcs().request_enable(0, false);
    v.cycles(100);
    EXPECT_EQ(v.stat(0, "scans"), 10);
    EXPECT_EQ(v.stat(1, "slow"), 0);
    v.plcs().request_enable(0, true);
    v.cycles(100);
    EXPECT_EQ(v.stat(0, "scans"), 20);
    EXPECT_EQ(v.stat(0, "first"), 1);
}

// Acceptance 3: mc_move_abs(1, edge, 10, 5, 10, 10) from 0 is busy for about 2.5 s, then at
// target; execute held high does not start it again.
TEST(IocPlc, McMoveAbsoluteOnTheRisingEdge) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.n := static.n + 1;
        if (plc0.firstscan) { static.p := mc_power(1, 1); };
        static.go := static.n >= 10;
        static.r := mc_move_abs(1, static.go, 10, 5, 10, 10);
        if (mc_get_busy(1)) { static.busy := static.busy + 1; };
        static.pos := mc_get_act_pos(1, 1);
        ax1.enc.extactpos := ax1.traj.setpos;
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n" + virtual_axis(1), "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(3000);
    EXPECT_EQ(v.stat(0, "p"), 0);
    EXPECT_EQ(v.stat(0, "r"), 0);
    EXPECT_NEAR(v.stat(0, "busy"), 2500, 20);
    EXPECT_DOUBLE_EQ(v.axis("V1").status().act_pos, 10);
    EXPECT_TRUE(v.axis("V1").status().at_target);
    EXPECT_DOUBLE_EQ(v.stat(0, "pos"), 10);
    // Moved elsewhere by another client while execute stays high: no second start.
    v.send("V1", motion::AxisCommand{motion::CommandType::MoveAbsolute, 3});
    v.cycles(9000); // 7 mm at the configured 1 mm/s
    EXPECT_FALSE(v.axis("V1").status().busy);
    EXPECT_DOUBLE_EQ(v.axis("V1").status().act_pos, 3);
}

// mc_* refusals return ECMC codes without touching the axis: unknown axis, PLC commands blocked,
// trajectory source not internal.
TEST(IocPlc, McErrorCodes) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.n := static.n + 1;
        static.unknown := mc_move_abs(7, 1, 1, 1, 1, 1);
        if (static.n == 2) { ax1.traj.source := 1; };
        if (static.n == 5) { static.external := mc_move_abs(1, 1, 1, 1, 1, 1); static.err := mc_get_err(); };
        if (static.n == 6) { ax1.traj.source := 0; ax1.allowplccmd := 0; };
        if (static.n == 8) { static.blocked := mc_move_rel(1, 1, 1, 1, 1, 1); };
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n" + virtual_axis(1), "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(10);
    EXPECT_EQ(v.stat(0, "unknown"), 0x20502);
    EXPECT_EQ(v.stat(0, "external"), 0x20052);
    EXPECT_EQ(v.stat(0, "err"), 0x20052);
    EXPECT_EQ(v.stat(0, "blocked"), 0x20053);
    EXPECT_EQ(v.axis("V1").status().error_id, 0u);
}

// The functions and variables ECMC files use that came with issue 13: mc_home_pos (homing
// position, here with sequence 15), mc_move_ext_pos (to traj.extsetpos), mc_set_traj_vel,
// mc_get_prim_enc, mc_get_hw_ready, ax<n>.id / enc.homepos / enc.actpos writes, ec_print_bin/hex.
TEST(IocPlc, EcmcFunctionsOfIssue13) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.n := static.n + 1;
        if (static.n == 1) { mc_power(1, 1); ax1.enc.actpos := 3; };
        if (static.n == 3) { static.act := ax1.enc.actpos; static.id := ax1.id; };
        if (static.n == 4) { static.hp := mc_home_pos(1, 1, 15, 1, 1, 42); };
        if (static.n == 6) { static.homepos := ax1.enc.homepos; static.pe := mc_get_prim_enc(1);
                             static.hw := mc_get_hw_ready(1); };
        if (static.n == 7) { mc_set_traj_vel(1, 2); ax1.traj.extsetpos := 7; };
        if (static.n == 8) { static.mv := mc_move_ext_pos(1, 1, 0, 0, 0); };
        if (static.n == 9) { ec_print_bin(10, 0, 3); ec_print_hex(255, 4, 7); };
        static.set := ax1.traj.setpos;
        if (static.n > 4) { ax1.enc.actpos := ax1.traj.setpos; }; // the kinematics loop closes
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n" + virtual_axis(1), "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(10);
    EXPECT_EQ(v.stat(0, "act"), 3);  // enc.actpos written: the external (PLC) actual position
    EXPECT_EQ(v.stat(0, "id"), 1);
    EXPECT_EQ(v.stat(0, "hp"), 0);
    EXPECT_EQ(v.stat(0, "homepos"), 42);
    EXPECT_EQ(v.stat(0, "pe"), 1);
    EXPECT_EQ(v.stat(0, "hw"), 1);
    EXPECT_EQ(v.stat(0, "mv"), 0);
    std::string out, line;
    while (v.plcs().pop_output(line)) out += line + "|";
    EXPECT_NE(out.find("plc0: 1010"), std::string::npos) << out;
    EXPECT_NE(out.find("plc0: f"), std::string::npos) << out;
    // homing 15 set the position to 42; the move to extsetpos 7 runs at the velocity
    // mc_set_traj_vel set: 2 mm/s
    v.cycles(1000);
    double after_1s = v.stat(0, "set");
    EXPECT_GT(after_1s, 42 - 2.05);
    EXPECT_LT(after_1s, 42 - 1.0);
    v.cycles(18000);
    EXPECT_NEAR(v.stat(0, "set"), 7.0, 1e-6);
}

// ECMC axis groups (axis.group, mc_grp_*): groups numbered in the order the axes name them,
// GRP_<name>_ID macros in every PLC, all/any tests, enable and sources of every member, halt,
// an error raised on the group and reset, the motor-record requests, and bad group ids.
TEST(IocPlc, AxisGroups) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    std::ifstream in(kSource + "/examples/demo/axes/virtual.yaml");
    std::string axis((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    axis.replace(axis.find("  type: virtual\n"), 16, "  type: virtual\n  group: ${GRP}\n");
    d.write("grp_axis.yaml", axis);
    auto ax = [](int id, const char* grp) {
        return "  - {file: grp_axis.yaml, macros: {AX_ID: " + std::to_string(id) + ", AX_NAME: V" + std::to_string(id) +
               ", DESC: v, LOW: -100, HIGH: 100, GRP: " + grp + "}}\n";
    };
    d.write("main.plc", R"(
        static.n += 1;
        if (static.n == 1) {
          static.real := ${GRP_real_ID}; static.virt := ${GRP_virt_ID};
          static.size := mc_grp_size(${GRP_real_ID});
          static.in2 := mc_grp_axis_in_grp(${GRP_real_ID}, 2);
          static.in3 := mc_grp_axis_in_grp(${GRP_real_ID}, 3);
          static.enc := mc_grp_set_enc_src(${GRP_real_ID}, 0);
          static.anyEnable0 := mc_grp_get_any_enable(${GRP_real_ID});
          static.ena := mc_grp_set_enable(${GRP_real_ID}, 1);
        };
        if (static.n == 50) {
          static.allEnabled := mc_grp_get_enabled(${GRP_real_ID});
          static.virtAny := mc_grp_get_any_enabled(${GRP_virt_ID});
          static.src := mc_grp_set_traj_src(${GRP_real_ID}, 1);
        };
        if (static.n == 51) {
          static.srcExt := mc_grp_get_traj_src_ext(${GRP_real_ID});
          mc_grp_set_traj_src(${GRP_real_ID}, 0);
        };
        if (static.n == 52) { static.srcExtAfter := mc_grp_get_any_traj_src_ext(${GRP_real_ID}); mc_move_abs(1, 1, 5, 1, 5, 5); };
        if (static.n == 100) {
          static.anyBusy := mc_grp_get_any_busy(${GRP_real_ID});
          static.allBusy := mc_grp_get_busy(${GRP_real_ID});
          mc_grp_halt(${GRP_real_ID});
        };
        if (static.n == 2000) {
          static.busyAfterHalt := mc_grp_get_any_busy(${GRP_real_ID});
          mc_grp_set_slaved_axis_in_error(${GRP_real_ID});
        };
        if (static.n == 2002) {
          static.err := mc_grp_get_any_error_id(${GRP_real_ID});
          static.enableAfterErr := mc_grp_get_any_enable(${GRP_real_ID});
          mc_grp_reset_error(${GRP_real_ID});
          mc_grp_mr_set_sync(${GRP_real_ID}, 1);
        };
        if (static.n == 2004) {
          static.errAfterReset := mc_grp_get_any_error_id(${GRP_real_ID});
          static.bad := mc_grp_size(7); static.badErr := mc_get_err();
          static.range := mc_grp_get_busy(200); static.rangeErr := mc_get_err();
          static.homedBefore := mc_get_enc_homed(3, 1);
          static.sh := mc_set_enc_homed(3, 1, 1);
          static.shBad := mc_set_enc_homed(3, 4, 1);
          static.ae := mc_set_axis_error(3, 4660);
        };
        if (static.n == 2006) {
          static.homedAfter := mc_get_enc_homed(3, 1);
          static.err3 := mc_get_axis_err(3);
          mc_reset(3);
          mc_set_slaved_axis_in_error(2);
        };
        if (static.n == 2008) { static.err2 := mc_get_axis_err(2); static.err3b := mc_get_axis_err(3); };
        ax1.enc.actpos := ax1.traj.setpos; ax2.enc.actpos := ax2.traj.setpos; ax3.enc.actpos := ax3.traj.setpos;
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("axes:\n" + ax(1, "real") + ax(3, "virt") + ax(2, "real"),
                                              "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(60);
    EXPECT_EQ(v.stat(0, "real"), 0); // named first
    EXPECT_EQ(v.stat(0, "virt"), 1);
    EXPECT_EQ(v.stat(0, "size"), 2);
    EXPECT_EQ(v.stat(0, "in2"), 1);
    EXPECT_EQ(v.stat(0, "in3"), 0);
    EXPECT_EQ(v.stat(0, "enc"), 0);
    EXPECT_EQ(v.stat(0, "anyEnable0"), 0);
    EXPECT_EQ(v.stat(0, "ena"), 0);
    EXPECT_EQ(v.stat(0, "allEnabled"), 1);
    EXPECT_EQ(v.stat(0, "virtAny"), 0); // axis 3 was not in the group enabled
    EXPECT_EQ(v.stat(0, "src"), 0);     // allowSrcChangeWhenEnabled: true
    EXPECT_EQ(v.stat(0, "srcExt"), 1);
    EXPECT_EQ(v.stat(0, "srcExtAfter"), 0);
    v.cycles(60);
    EXPECT_EQ(v.stat(0, "anyBusy"), 1); // axis 1 moves, axis 2 does not
    EXPECT_EQ(v.stat(0, "allBusy"), 0);
    v.cycles(1900);
    EXPECT_EQ(v.stat(0, "busyAfterHalt"), 0);
    EXPECT_LT(v.axis("V1").status().act_pos, 1.0); // halted long before 5
    v.cycles(6);
    EXPECT_EQ(v.stat(0, "err"), 0x1432B);
    EXPECT_EQ(v.stat(0, "enableAfterErr"), 0); // an error disables, as the axis's own
    EXPECT_EQ(v.stat(0, "errAfterReset"), 0);
    EXPECT_EQ(v.axis("V1").status().mr_sync_requests, 1u);
    EXPECT_EQ(v.axis("V3").status().mr_sync_requests, 0u);
    EXPECT_EQ(v.stat(0, "bad"), 0x20508);   // no group 7
    EXPECT_EQ(v.stat(0, "badErr"), 0x20508);
    EXPECT_EQ(v.stat(0, "range"), 0);
    EXPECT_EQ(v.stat(0, "rangeErr"), 0x20502);
    // mc_set_enc_homed, mc_set_axis_error, mc_set_slaved_axis_in_error
    v.cycles(4);
    EXPECT_EQ(v.stat(0, "sh"), 0);
    EXPECT_EQ(v.stat(0, "shBad"), 0x14326);
    EXPECT_EQ(v.stat(0, "ae"), 4660);
    EXPECT_EQ(v.stat(0, "homedAfter"), 1);
    EXPECT_EQ(v.stat(0, "err3"), 4660);
    EXPECT_EQ(v.stat(0, "err3b"), 0); // mc_reset cleared it
    EXPECT_EQ(v.stat(0, "err2"), 0x1432B);
}

// m2m between two IOCs (here two in one process, as two processes would: one shared-memory
// object by name): values written by one PLC are read by the other's; each sees the other
// running and its EtherCAT state; bad indices give ECMC's codes.
TEST(IocPlc, M2mBetweenTwoIocs) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    std::string shm = "beamctl_test_m2m_" + std::to_string(::getpid());
    d.write("a.plc", "static.n += 1;\nm2m_write(3, static.n * 2);\nstatic.bad := m2m_write(120, 1);\n");
    d.write("b.plc", R"(
        static.v := m2m_read(3);
        static.run0 := m2m_ioc_run(0); static.ok0 := m2m_ioc_ec_ok(0);
        static.run5 := m2m_ioc_run(5); static.okSelf := m2m_ioc_ec_ok(-2); static.runSelf := m2m_ioc_run(-2);
        static.range := m2m_ioc_run(16); static.stat := m2m_stat();
        static.r := m2m_read(-1); static.err := m2m_get_err();
    )");
    std::string a_yaml = ioc_yaml("", "plcs:\n  - {id: 0, file: a.plc}\n", "m2m: {name: " + shm + "}\n");
    std::string b_yaml = "ioc: {name: B}\nengine: {rate_hz: 1000}\nplcs:\n  - {id: 0, file: b.plc}\nm2m: {name: " + shm + ", master: -2}\n";
    {
        VirtualIoc a(d.write("a.yaml", a_yaml));
        VirtualIoc b(d.write("b.yaml", b_yaml));
        a.cycles(10);
        b.cycles(1);
        EXPECT_EQ(a.stat(0, "bad"), 0x20059);
        EXPECT_EQ(b.stat(0, "v"), a.stat(0, "n") * 2);
        EXPECT_GT(b.stat(0, "v"), 0);
        EXPECT_EQ(b.stat(0, "run0"), 1);
        EXPECT_EQ(b.stat(0, "ok0"), 1);
        EXPECT_EQ(b.stat(0, "run5"), 0);
        EXPECT_EQ(b.stat(0, "runSelf"), 1);
        EXPECT_EQ(b.stat(0, "okSelf"), 0); // no master: never EtherCAT OK (ECMC)
        EXPECT_EQ(b.stat(0, "range"), -1);
        EXPECT_EQ(b.stat(0, "stat"), 1);
        EXPECT_EQ(b.stat(0, "r"), 0);
        EXPECT_EQ(b.stat(0, "err"), 0x20059);
        a.cycles(5);
        b.cycles(1);
        EXPECT_EQ(b.stat(0, "v"), 30);
    }
    {   // IOC a stopped: b sees it gone
        VirtualIoc b(d.write("b.yaml", b_yaml));
        b.cycles(1);
        EXPECT_EQ(b.stat(0, "run0"), 0);
        EXPECT_EQ(b.stat(0, "v"), 30); // the values stay in the shared memory
    }
    ::shm_unlink(("/" + shm).c_str());
}

// lut_get_value on a table of the IOC file's `luts:` (ECMC's LUT file format).
TEST(IocPlc, LookupTables) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("corr.lut", "# x y\nPREC=5\n-10, -9\n0 1\n10 21 extra\n");
    d.write("main.plc", "static.a := lut_get_value(2, 5);\nstatic.b := lut_get_value(2, -50);\n"
                        "static.c := lut_get_value(2, 10);\nstatic.none := lut_get_value(3, 5);\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: main.plc}\n", "luts:\n  - {id: 2, file: corr.lut}\n")));
    v.cycles(1);
    EXPECT_DOUBLE_EQ(v.stat(0, "a"), 11);  // halfway between (0, 1) and (10, 21)
    EXPECT_DOUBLE_EQ(v.stat(0, "b"), -9);  // clamped below
    EXPECT_DOUBLE_EQ(v.stat(0, "c"), 21);
    EXPECT_DOUBLE_EQ(v.stat(0, "none"), 0); // no table 3
    d.write("bad.lut", "0 1\n1 2\n1 3\n");
    try {
        VirtualIoc bad(d.write("bad.yaml", ioc_yaml("", "", "luts:\n  - {id: 0, file: bad.lut}\n")));
        FAIL() << "loaded";
    } catch (const Error& e) {
        std::string w = e.what();
        EXPECT_NE(w.find("bad.yaml:"), std::string::npos) << w;
        EXPECT_NE(w.find("bad.lut:3: x 1 should be greater"), std::string::npos) << w;
    }
}

// ec_* bit operations and ec_get_time (the cycle's time, ns).
TEST(IocPlc, EcFunctions) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.a := ec_set_bit(0, 3);
        static.b := ec_clr_bit(15, 0);
        static.c := ec_flp_bit(5, 1);
        static.d := ec_chk_bit(4, 2);
        static.e := ec_wrt_bits(0, 5, 4, 7);
        static.f := ec_chk_bits(176, 4, 7);
        static.g := ec_wrt_bit(0, 1, 63) > 0;
        static.bad := ec_set_bit(1, 64);
        static.err := ec_get_err();
        static.t1 := static.t0;
        static.t0 := ec_get_time();
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(3);
    EXPECT_EQ(v.stat(0, "a"), 8);
    EXPECT_EQ(v.stat(0, "b"), 14);
    EXPECT_EQ(v.stat(0, "c"), 7);
    EXPECT_EQ(v.stat(0, "d"), 1);
    EXPECT_EQ(v.stat(0, "e"), 80);
    EXPECT_EQ(v.stat(0, "f"), 11);
    EXPECT_EQ(v.stat(0, "g"), 1);
    EXPECT_EQ(v.stat(0, "bad"), 1);
    EXPECT_EQ(v.stat(0, "err"), 0x20800);
    EXPECT_EQ(v.stat(0, "t0") - v.stat(0, "t1"), 1e6);
}

// A run-time fault latches plc<n>.error and the location; the rest of that scan is skipped, the
// next scans run; enabling again clears it.
TEST(IocPlc, RunTimeFaultLatches) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "static.n := static.n + 1;\nvar v[2] := {1, 2};\nif (static.n == 3) { static.bad := v[static.n]; };\nstatic.after := static.after + 1;\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: main.plc}\n")));
    v.cycles(10);
    EXPECT_EQ(v.stat(0, "n"), 10);
    EXPECT_EQ(v.stat(0, "after"), 9);
    EXPECT_EQ(v.plcs().status(0).error, int(plc::RunStatus::index_out_of_range));
    EXPECT_EQ(v.plcs().status(0).faults, 1u);
    EXPECT_NE(v.plcs().fault(0).find("main.plc:3:"), std::string::npos) << v.plcs().fault(0);
    v.plcs().request_enable(0, false);
    v.cycles(1);
    v.plcs().request_enable(0, true);
    v.cycles(1);
    EXPECT_EQ(v.plcs().status(0).error, 0);
}

// The PLC's PVs are table records on its items (plc0.enable, .scans, ...); EnaCmd follows the PLC
// when its code disables itself, and a .db record reads and writes the same items.
TEST(IocPlc, PvsAndRecordsOnThePlcItems) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "static.n := static.n + 1;\nif (static.n == 50 or ec0.s1.binaryInput01) { plc0.enable := 0; };\n");
    d.write("x.db", "record(longin, \"T:Scans\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@plc0.scans\")\n"
                    "  field(SCAN, \"I/O Intr\")\n}\n"
                    "record(bo, \"T:Run\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@plc0.enable\")\n}\n"
                    "record(bo, \"T:Stop\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@ec0.s2.binaryOutput01\")\n}\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: main.plc}\n", "db:\n  - {file: x.db}\n")));
    pv::Database& db = v.ioc->database();
    auto get = [&](const char* n) {
        pv::Address a;
        EXPECT_TRUE(db.resolve(n, a)) << n;
        double x = 0;
        db.get(a, pv::Prim::Double, &x, 1);
        return x;
    };
    EXPECT_EQ(v.ioc->signals().find("plc0.enable")->pv, "T:PLC00-EnaCmd");
    EXPECT_EQ(v.ioc->signals().find("plc0.scans")->pv, "T:PLC00-Scans");
    v.cycles(20);
    v.ioc->publish();
    EXPECT_EQ(get("T:PLC00-EnaCmd"), 1);
    EXPECT_EQ(get("T:PLC00-EnaAct"), 1);
    EXPECT_EQ(get("T:PLC00-Scans"), 20);
    EXPECT_EQ(get("T:Scans"), 20);
    EXPECT_NEAR(get("T:PLC00-ScanTime"), 0.001, 1e-12);
    v.cycles(40); // scan 50 disables the PLC
    v.ioc->publish();
    EXPECT_EQ(get("T:PLC00-EnaAct"), 0);
    EXPECT_EQ(get("T:PLC00-EnaCmd"), 0); // followed, without enabling it again
    EXPECT_EQ(get("T:Scans"), 50);
    v.cycles(10);
    v.ioc->publish();
    EXPECT_EQ(get("T:Scans"), 50);
    double one = 1;
    pv::Address run;
    ASSERT_TRUE(db.resolve("T:Run", run));
    ASSERT_EQ(db.put(run, pv::Prim::Double, &one, 1), pv::PutStatus::Ok);
    v.cycles(10);
    v.ioc->publish();
    EXPECT_EQ(get("T:PLC00-EnaAct"), 1); // runs on
    EXPECT_EQ(get("T:PLC00-EnaCmd"), 1);
    EXPECT_GT(get("T:Scans"), 51);
    // a PLC that runs one scan and stops itself between two looks: EnaCmd still follows it
    double zero = 0;
    ASSERT_EQ(db.put(run, pv::Prim::Double, &zero, 1), pv::PutStatus::Ok);
    pv::Address stop;
    ASSERT_TRUE(db.resolve("T:Stop", stop));
    ASSERT_EQ(db.put(stop, pv::Prim::Double, &one, 1), pv::PutStatus::Ok); // wired to binaryInput01
    v.cycles(10);
    v.ioc->publish();
    EXPECT_EQ(get("T:PLC00-EnaCmd"), 0);
    double scans = get("T:Scans");
    pv::Address cmd;
    ASSERT_TRUE(db.resolve("T:PLC00-EnaCmd", cmd));
    ASSERT_EQ(db.put(cmd, pv::Prim::Double, &one, 1), pv::PutStatus::Ok);
    v.cycles(10); // one scan: binaryInput01 is on, enable := 0
    v.ioc->publish();
    EXPECT_EQ(get("T:Scans"), scans + 1);
    EXPECT_EQ(get("T:PLC00-EnaAct"), 0);
    EXPECT_EQ(get("T:PLC00-EnaCmd"), 0);
}

// Acceptance 15 (PLC part): a plugin's functions and constants are callable from PLC code, and
// its realtime() runs each cycle.
TEST(IocPlc, PluginFunctions) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "static.s := ex_scale(2);\nstatic.c := ex_clamp(7, 0, 5);\nstatic.pi := ex_pi;\nstatic.n := ex_cycles();\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml("", "plcs:\n  - {id: 0, file: main.plc}\n",
                                              std::string("plugins:\n  - {file: ") + BEAMCTL_TEST_PLUGIN + ", config: \"GAIN=2.5\"}\n")));
    v.cycles(10);
    EXPECT_EQ(v.stat(0, "s"), 5);
    EXPECT_EQ(v.stat(0, "c"), 5);
    EXPECT_NEAR(v.stat(0, "pi"), M_PI, 1e-15);
    EXPECT_GE(v.stat(0, "n"), 8);
}

// Compile errors against the IOC: all of them, each with file:line:col and the reason.
TEST(IocPlc, CompileErrorsNameWhatAndWhere) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "ax1.enc.actvel := 1;\nstatic.a := ax9.enc.actpos;\nec0.s1.binaryInput01 := 1;\nstatic.b := ec0.s1.nothing;\n"
                        "static.c := ec0.s2.binaryOutput01.99;\nstatic.d := ds0.data;\n");
    try {
        rt::VirtualClock clock;
        ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", ioc_yaml("axes:\n" + virtual_axis(1), "plcs:\n  - {id: 0, file: main.plc}\n"))), clock);
        FAIL() << "compiled";
    } catch (const MultiError& e) { // every error of every file of the IOC
        std::string all;
        for (const auto& s : e.errors()) all += s + "\n";
        EXPECT_NE(all.find("main.plc:1:1: 'ax1.enc.actvel' is read-only"), std::string::npos) << all;
        EXPECT_NE(all.find("main.plc:2:13: unknown name 'ax9.enc.actpos': no axis 9 (axes: 1)"), std::string::npos) << all;
        EXPECT_NE(all.find("main.plc:3:1: 'ec0.s1.binaryInput01' is read-only"), std::string::npos) << all;
        EXPECT_NE(all.find("main.plc:4:13: unknown name 'ec0.s1.nothing': no process-data entry 'ec0.s1.nothing'"), std::string::npos) << all;
        EXPECT_NE(all.find("main.plc:5:13: unknown name 'ec0.s2.binaryOutput01.99': bit number out of range"), std::string::npos) << all;
        EXPECT_NE(all.find("main.plc:6:13: unknown name 'ds0.data': no data storage 0 (the IOC has none: `storages:` in the IOC file)"), std::string::npos) << all;
    }
}

// Acceptance 2 on the shipped demo: CEN 0, GAP -> 4 mm puts the blades at -2 and +2, CEN/GAP
// read back from the blades; simultaneous CEN and GAP moves do not drift; a blade on its high
// limit blocks the directions that push it further only.
TEST(IocPlc, DemoSlitVirtualAxes) {
    VirtualIoc v(kSource + "/examples/demo/ioc.yaml");
    v.cycles(100); // the slit PLC enables the blades and virtual axes
    ASSERT_TRUE(v.axis("SlitVGap").status().enabled);
    v.send("SlitVGap", motion::AxisCommand{motion::CommandType::MoveAbsolute, 4});
    v.cycles(5000);
    const auto& top = v.axis("SlitTop").status();
    const auto& bottom = v.axis("SlitBottom").status();
    EXPECT_NEAR(bottom.act_pos, -2, 0.01);
    EXPECT_NEAR(top.act_pos, 2, 0.01);
    EXPECT_NEAR(v.axis("SlitVGap").status().act_pos, 4, 0.01);
    EXPECT_NEAR(v.axis("SlitVCen").status().act_pos, 0, 0.01);
    EXPECT_FALSE(v.axis("SlitVGap").status().busy);
    EXPECT_EQ(v.stat(0, "vstate"), 0); // back in S0: the blades on their own trajectories

    // Both at once: centre to 3 while the gap goes to 6; then both hold exactly.
    v.send("SlitVCen", motion::AxisCommand{motion::CommandType::MoveAbsolute, 3});
    v.send("SlitVGap", motion::AxisCommand{motion::CommandType::MoveAbsolute, 6});
    v.cycles(6000);
    EXPECT_NEAR(bottom.act_pos, 0, 0.01);
    EXPECT_NEAR(top.act_pos, 6, 0.01);
    EXPECT_DOUBLE_EQ(v.axis("SlitVGap").status().set_pos - v.axis("SlitVGap").status().target_pos, 0);
    EXPECT_NEAR(top.set_pos - bottom.set_pos, 6, 1e-12); // no drift of the gap

    // A blade moved directly: CEN and GAP follow it.
    v.send("SlitTop", motion::AxisCommand{motion::CommandType::MoveAbsolute, 7});
    v.cycles(2000);
    EXPECT_NEAR(v.axis("SlitVGap").status().act_pos, 7, 0.01);
    EXPECT_NEAR(v.axis("SlitVCen").status().act_pos, 3.5, 0.01);

    // The top blade onto its forward limit switch (at +12 mm of its axis).
    v.send("SlitTop", motion::AxisCommand{motion::CommandType::MoveAbsolute, 15});
    v.cycles(6000);
    ASSERT_TRUE(top.limit_fwd);
    double cen = v.axis("SlitVCen").status().act_pos, gap = v.axis("SlitVGap").status().act_pos;
    v.send("SlitVCen", motion::AxisCommand{motion::CommandType::MoveRelative, 1});
    v.cycles(2000);
    EXPECT_NEAR(v.axis("SlitVCen").status().act_pos, cen, 0.02) << "CEN forward must be blocked";
    v.send("SlitVGap", motion::AxisCommand{motion::CommandType::MoveRelative, 1});
    v.cycles(2000);
    EXPECT_NEAR(v.axis("SlitVGap").status().act_pos, gap, 0.02) << "GAP forward must be blocked";
    v.send("SlitVCen", motion::AxisCommand{motion::CommandType::MoveRelative, -1});
    v.cycles(3000);
    EXPECT_NEAR(v.axis("SlitVCen").status().act_pos, cen - 1, 0.02) << "CEN backward is allowed";
    EXPECT_FALSE(top.limit_fwd);
    EXPECT_EQ(v.axis("SlitVCen").status().error_id, 0u);
}

// The demo's 5-axis mirror: a pitch move tilts the mirror about its centre (the upstream Y jacks
// rise, the downstream one falls, 800 mm apart), the other four virtual axes stay where they were
// and read back from the jacks; then the jacks are back on their own trajectories.
TEST(IocPlc, DemoMirrorPitch) {
    VirtualIoc v(kSource + "/examples/demo/ioc.yaml");
    v.cycles(100);
    ASSERT_TRUE(v.axis("MirrorPitch").status().enabled);
    v.send("MirrorPitch", motion::AxisCommand{motion::CommandType::MoveAbsolute, 2});
    v.cycles(4000);
    EXPECT_FALSE(v.axis("MirrorPitch").status().busy);
    EXPECT_NEAR(v.axis("MirrorPitch").status().act_pos, 2, 0.002);
    for (const char* other : {"MirrorYaw", "MirrorRoll", "MirrorX", "MirrorY"})
        EXPECT_NEAR(v.axis(other).status().act_pos, 0, 0.005) << other;
    double yui = v.axis("MirrorYUI").status().act_pos, yuo = v.axis("MirrorYUO").status().act_pos;
    double yd = v.axis("MirrorYD").status().act_pos;
    EXPECT_NEAR(yui, yuo, 0.002);
    EXPECT_NEAR(yui - yd, 800 * std::tan(0.002), 0.005);
    EXPECT_NEAR(yui + yd, 0, 0.01); // about the centre, midway between the jacks
    EXPECT_EQ(v.stat(1, "mirror"), 0);
    for (const char* jack : {"MirrorXU", "MirrorXD", "MirrorYUI", "MirrorYUO", "MirrorYD"})
        EXPECT_EQ(v.axis(jack).status().error_id, 0u) << jack;
}

// RT rule 1 with PLCs: the whole demo cycle (bus, axes with their PLC variables, the slit and
// mirror PLCs, virtual moves starting and ending) allocates nothing.
TEST(IocPlc, DemoCycleWithPlcsAllocatesNothing) {
    VirtualIoc v(kSource + "/examples/demo/ioc.yaml");
    v.cycles(200);
    v.send("SlitVGap", motion::AxisCommand{motion::CommandType::MoveAbsolute, 2});
    v.send("MirrorRoll", motion::AxisCommand{motion::CommandType::MoveAbsolute, 1});
    test::count_allocations(true);
    v.cycles(3000);
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_NEAR(v.axis("SlitVGap").status().act_pos, 2, 0.01);
    EXPECT_NEAR(v.axis("MirrorRoll").status().act_pos, 1, 0.002);
    EXPECT_GE(v.plcs().status(0).scans, 3000u);
}

// The shipped log-spiral example: a move of the arc length puts the stage on the spiral
// (seed eqs 21-23, origin at the stage's start) and the readbacks follow.
TEST(IocPlc, SpiralExample) {
    VirtualIoc v(kSource + "/examples/kinematics/ioc.yaml");
    v.cycles(100);
    EXPECT_NEAR(v.axis("SpiralL").status().act_pos, 0, 1e-6);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 5});
    v.cycles(9000);
    EXPECT_FALSE(v.axis("SpiralL").status().busy);
    const double a = 1, b = 0.2, k = a * std::sqrt(1 + b * b) / b;
    const double theta = std::log1p(5 / k) / b, r = a * std::exp(b * theta);
    EXPECT_NEAR(v.axis("StageX").status().act_pos, -1 + r * std::cos(theta), 0.01);
    EXPECT_NEAR(v.axis("StageY").status().act_pos, r * std::sin(theta), 0.01);
    EXPECT_NEAR(v.axis("SpiralL").status().act_pos, 5, 0.01);
    EXPECT_NEAR(v.axis("SpiralR").status().act_pos, r, 0.01);
    EXPECT_NEAR(v.axis("SpiralTheta").status().act_pos, theta, 0.01);
    EXPECT_EQ(v.stat(0, "spiral"), 0);
}
