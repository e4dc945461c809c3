// Kinematics groups in whole IOCs, in virtual time (issue 11, machine safety): a virtual move whose
// path would take a real axis past its soft limit or further into an active limit switch is refused
// before it starts; a real axis that reaches a limit during a coupled move stops the whole group,
// which ends short (move_failed); a real axis never follows a PLC setpoint past its soft limit; the
// virtual axes' limits follow from the real axes'; the demo mirror's inverse transform agrees with
// its PLC; configuration errors name what and where.
#include "../temp_dir.hpp"
#include "../alloc_counter.hpp"
#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "plc/program.hpp"
#include "pv/motor_record.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

using namespace beamctl;

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;
const std::string kDemo = kSource + "/examples/demo/ioc.yaml";

struct Demo {
    rt::VirtualClock clock;
    std::unique_ptr<ioc::Ioc> ioc;
    explicit Demo(const std::string& path = kDemo) {
        ioc = std::make_unique<ioc::Ioc>(config::IocConfig::load(path), clock);
        ioc->bring_up();
        cycles(100); // the PLCs enable the axes
    }
    void cycles(int n) { ioc->engine().run_cycles(uint64_t(n)); }
    motion::Axis& axis(const std::string& name) {
        int i = ioc->axes().find(name);
        if (i < 0) throw std::runtime_error("no axis " + name);
        return ioc->axes().group()->axis(std::size_t(i));
    }
    const motion::AxisStatus& st(const std::string& name) { return axis(name).status(); }
    void move(const std::string& name, double to, motion::CommandType t = motion::CommandType::MoveAbsolute) {
        ASSERT_NE(ioc->axes().send(std::size_t(ioc->axes().find(name)), motion::AxisCommand{t, to}), 0u);
    }
    // Runs n cycles and returns the largest setpoint `name` had meanwhile.
    double peak(const std::string& name, int n) {
        double m = -1e300;
        for (int i = 0; i < n; ++i) {
            cycles(1);
            m = std::max(m, st(name).set_pos);
        }
        return m;
    }
    double field(const std::string& rec, const char* f) {
        pv::Record* r = ioc->database().find(rec);
        pv::Address a;
        a.rec = r;
        a.field = r->type().find(f);
        double v = 0;
        ioc->database().get(a, pv::Prim::Double, &v, 1);
        return v;
    }
};

TEST(IocKinematics, VirtualMovePastABladeSoftLimitIsRefusedBeforeItStarts) {
    Demo d;
    d.move("SlitVCen", 2.5);
    d.cycles(3000);
    ASSERT_NEAR(d.st("SlitTop").set_pos, 2.5, 1e-9);
    // GAP 30 around 2.5 needs SlitTop at 17.5, past its soft limit of 17
    d.move("SlitVGap", 30);
    double top = d.peak("SlitTop", 3000);
    EXPECT_LE(top, 17.0);
    EXPECT_NEAR(d.st("SlitTop").set_pos, 2.5, 1e-9); // nothing moved
    EXPECT_EQ(d.st("SlitVGap").warning_id, motion::error_id::kSoftLimitFwd);
    EXPECT_TRUE(d.st("SlitVGap").move_failed);
    EXPECT_FALSE(d.st("SlitVGap").busy);
    EXPECT_EQ(d.st("SlitVGap").error_id, 0u); // a warning: the next good move runs
    d.move("SlitVGap", 6);
    d.cycles(4000);
    EXPECT_NEAR(d.st("SlitTop").set_pos, 5.5, 1e-9);
    EXPECT_FALSE(d.st("SlitVGap").move_failed);
    EXPECT_EQ(d.st("SlitVGap").warning_id, 0u);
    // relative moves are checked at their target too
    d.move("SlitVGap", 30, motion::CommandType::MoveRelative);
    EXPECT_LE(d.peak("SlitTop", 2000), 17.0);
    EXPECT_TRUE(d.st("SlitVGap").move_failed);
}

TEST(IocKinematics, MirrorMovePastAJackLimitIsRefused) {
    Demo d;
    // pitch 40 mrad moves the Y jacks by 800/2 * tan(0.04) = 16 mm > their 15 mm soft limit;
    // the virtual soft limit (10 mrad) would refuse it first, so go via roll instead: roll moves
    // YUI/YUO by +-150 * tan(roll): 10 mrad is 1.5 mm, allowed.
    d.move("MirrorRoll", 9);
    d.cycles(12000);
    EXPECT_FALSE(d.st("MirrorRoll").move_failed);
    EXPECT_NEAR(d.st("MirrorRoll").act_pos, 9, 0.002);
    // Centre Y 10 mm (allowed by its own limit) with the jacks already at up to +1.35 mm takes
    // YUI to about 11.35 mm: allowed. Then the X jacks: centre X beyond their reach is not (their
    // soft limits are +-15, the virtual's +-10): Y 10 and pitch 8 mrad puts YUI past 15.
    d.move("MirrorY", 10);
    d.cycles(14000);
    EXPECT_FALSE(d.st("MirrorY").move_failed);
    d.move("MirrorPitch", 8); // YUI: 10 + 1.35 + 400 * tan(8 mrad) = 14.55 -> allowed
    d.cycles(12000);
    EXPECT_FALSE(d.st("MirrorPitch").move_failed) << d.st("MirrorPitch").warning_id;
    d.move("MirrorPitch", 10); // + 400 * tan(2 mrad) = 0.8 more: YUI 15.35 > 15: refused
    double peak = d.peak("MirrorYUI", 3000);
    EXPECT_LE(peak, 15.0);
    EXPECT_TRUE(d.st("MirrorPitch").move_failed);
    EXPECT_EQ(d.st("MirrorPitch").warning_id, motion::error_id::kSoftLimitFwd);
    EXPECT_NEAR(d.st("MirrorPitch").act_pos, 8, 0.002);
}

TEST(IocKinematics, ABladeOnItsLimitSwitchStopsTheWholeCoupledMove) {
    Demo d;
    d.move("SlitVCen", 2.5);
    d.cycles(3000);
    // SlitTop's forward switch is at 12 mm of its axis: GAP 20 around 2.5 reaches it at 12.
    d.move("SlitVGap", 20);
    d.cycles(14000);
    const auto& top = d.st("SlitTop");
    const auto& bottom = d.st("SlitBottom");
    EXPECT_TRUE(d.st("SlitVGap").move_failed);
    EXPECT_FALSE(d.st("SlitVGap").busy);
    EXPECT_EQ(d.st("SlitVGap").warning_id, motion::error_id::kHardLimitFwd);
    EXPECT_LT(top.act_pos, 12.6);
    EXPECT_GT(top.act_pos, 11.5);
    // the other blade stopped with it, in the same cycle: the centre held (to one cycle of the
    // blades' motion, 1 mm/s x 1 ms)
    EXPECT_NEAR((top.set_pos + bottom.set_pos) / 2, 2.5, 1e-3);
    EXPECT_NEAR(d.st("SlitVCen").set_pos, 2.5, 1e-3);
    // further out is refused, back in is allowed
    d.move("SlitVGap", 1, motion::CommandType::MoveRelative);
    d.cycles(1000);
    EXPECT_TRUE(d.st("SlitVGap").move_failed);
    d.move("SlitVGap", 8);
    d.cycles(10000);
    EXPECT_FALSE(d.st("SlitVGap").move_failed);
    EXPECT_NEAR(d.st("SlitTop").set_pos - d.st("SlitBottom").set_pos, 8, 1e-5);
    EXPECT_NEAR(d.st("SlitTop").set_pos, 6.5, 2e-3);
}

TEST(IocKinematics, ARealAxisNeverFollowsAPlcSetpointPastItsSoftLimit) {
    Demo d;
    motion::Axis& jack = d.axis("MirrorXU"); // soft limits +-15, no limit switches
    // What a faulty PLC could do: take the jack and ramp its setpoint to 20 mm.
    jack.variables().traj.source = 1;
    double x = 0;
    double peak = -1e300;
    for (int i = 0; i < 12000; ++i) {
        x = std::min(x + 0.002, 20.0);
        jack.variables().traj.extsetpos = x;
        d.cycles(1);
        peak = std::max(peak, jack.status().set_pos);
    }
    EXPECT_LE(peak, 15.0);
    EXPECT_NEAR(jack.status().set_pos, 15.0, 1e-9);
    EXPECT_EQ(jack.status().warning_id, motion::error_id::kSoftLimitFwd);
    EXPECT_TRUE(jack.status().ext_limited);
    jack.variables().traj.extsetpos = 14.999; // back inside is followed
    d.cycles(2);
    EXPECT_NEAR(jack.status().set_pos, 14.999, 1e-9);
    EXPECT_FALSE(jack.status().ext_limited);
    // a blade on its limit switch: held where it is (SlitTop's switch is at 12 mm of its axis)
    motion::Axis& top = d.axis("SlitTop");
    top.variables().traj.source = 1;
    x = 0;
    for (int i = 0; i < 8000; ++i) {
        x = std::min(x + 0.002, 16.0);
        top.variables().traj.extsetpos = x;
        d.cycles(1);
    }
    EXPECT_LT(top.status().set_pos, 15.0); // held short of where the PLC wanted it (16)
    EXPECT_EQ(top.status().warning_id, motion::error_id::kHardLimitFwd);
    EXPECT_EQ(top.status().last_interlock, motion::Interlock::HardFwd);
}

TEST(IocKinematics, VirtualLimitsFollowTheRealAxes) {
    Demo d;
    d.move("SlitVCen", 2.5);
    d.cycles(3000);
    d.ioc->publish();
    // GAP: both blades within +-17 around 2.5 -> gap up to 2 * (17 - 2.5) = 29; the gap's own
    // limits are -2 .. 30
    EXPECT_NEAR(d.field("DEMO:SlitVGap", "DHLM"), 29.0, 1e-4);
    EXPECT_NEAR(d.field("DEMO:SlitVGap", "DLLM"), -2.0, 1e-9);
    EXPECT_NEAR(d.field("DEMO:SlitVGap", "HLM"), 29.0, 1e-4);
    // CEN with a gap of 0: the blades allow +-17, the centre's own limits +-15
    EXPECT_NEAR(d.field("DEMO:SlitVCen", "DHLM"), 15.0, 1e-9);
    d.move("SlitVGap", 10);
    d.cycles(6000);
    d.ioc->publish();
    EXPECT_NEAR(d.field("DEMO:SlitVCen", "DHLM"), 12.0, 1e-4); // 17 - 10/2
    EXPECT_NEAR(d.field("DEMO:SlitVCen", "DLLM"), -12.0, 1e-4);
    EXPECT_NEAR(d.field("DEMO:SlitVGap", "DHLM"), 29.0, 1e-4);
}

// The demo's mirror kinematics group uses examples/plc_lib/inverse/mirror_trig.plc_inc; the
// mirror PLC drives the jacks with mirror_trig.plc_inc. At any pose the two give the same jacks.
TEST(IocKinematics, MirrorInverseFileAgreesWithTheMirrorPlc) {
    Demo d;
    const char* virt[] = {"MirrorPitch", "MirrorYaw", "MirrorRoll", "MirrorX", "MirrorY"};
    const char* jacks[] = {"MirrorXU", "MirrorXD", "MirrorYUI", "MirrorYUO", "MirrorYD"};
    const double pose[] = {1.7, -2.3, 3.1, 1.2, -0.8};
    for (int i = 0; i < 5; ++i) d.move(virt[i], pose[i]);
    d.cycles(8000);
    const config::KinematicsEntry* mirror = nullptr;
    for (const auto& e : d.ioc->config().kinematics)
        if (e.name == "mirror") mirror = &e;
    ASSERT_NE(mirror, nullptr);
    auto inv = ioc::compile_inverse(*mirror, kDemo);
    double v[5], r[5];
    for (int i = 0; i < 5; ++i) v[i] = d.st(virt[i]).set_pos;
    for (int i = 0; i < 5; ++i) EXPECT_NEAR(v[i], pose[i], 1e-9) << virt[i];
    ASSERT_TRUE(inv->evaluate(v, r));
    for (int k = 0; k < 5; ++k) EXPECT_NEAR(r[k], d.st(jacks[k]).set_pos, 1e-9) << jacks[k];
}

TEST(IocKinematics, TheCycleWithKinematicsChecksAllocatesNothing) {
    Demo d;
    test::count_allocations(true);
    d.move("SlitVGap", 4);
    d.move("MirrorRoll", 2);
    d.cycles(3000);
    d.move("SlitVGap", 40); // refused
    d.cycles(100);
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_TRUE(d.st("SlitVGap").move_failed);
}

using beamctl::test::TempDir;

std::string config_error(const std::string& kinematics) {
    TempDir t;
    std::string axes;
    for (int id : {1, 2, 11, 12})
        axes += "  - {file: " + kSource + "/examples/demo/axes/virtual.yaml, macros: {AX_ID: " + std::to_string(id) +
                ", AX_NAME: V" + std::to_string(id) + ", DESC: v}}\n";
    std::string path = t.write("ioc.yaml", "ioc: {name: T}\nbuses:\n  - id: 0\n    link: {type: sim}\n    slaves:\n"
                                           "      - {position: 0, type: EK1100}\naxes:\n" + axes + "kinematics:\n" + kinematics);
    try {
        rt::VirtualClock clock;
        ioc::Ioc ioc(config::IocConfig::load(path), clock);
    } catch (const std::exception& e) {
        return e.what();
    }
    return "";
}

TEST(IocKinematics, ConfigurationErrorsNameWhatAndWhere) {
    const std::string ok = "  - {name: s, virtual: [11, 12], real: [1, 2], inverse: \"ax1 := ax11 - ax12/2; ax2 := ax11 + ax12/2;\"}\n";
    EXPECT_EQ(config_error(ok), "");
    std::string e = config_error("  - {name: s, virtual: [11, 13], real: [1, 2], inverse: \"ax1 := ax11; ax2 := ax11;\"}\n");
    EXPECT_NE(e.find("ioc.yaml:"), std::string::npos) << e;
    EXPECT_NE(e.find("no axis 13"), std::string::npos) << e;
    e = config_error("  - {name: s, virtual: [11, 12], real: [1, 2], inverse: \"ax1 := ax11;\"}\n");
    EXPECT_NE(e.find("does not assign ax2"), std::string::npos) << e;
    const std::string bad = "  - {name: s, virtual: [11, 12], real: [1, 2], inverse: \"ax1 := ax11 +; ax2 := ax7;\"}\n";
    e = config_error(bad);
    // the place in ioc.yaml (line 13, the entry): the ';' is the 14th character of the code
    const std::string at = "ioc.yaml:13:" + std::to_string(bad.find('"') + 1 + 14) + ": kinematics 's' inverse: ";
    EXPECT_NE(e.find(at + "expected a value"), std::string::npos) << at << "\n" << e;
    EXPECT_NE(e.find("ax7"), std::string::npos) << e;                      // and the second error too
    e = config_error(ok + "  - {name: t, virtual: [12], real: [2], inverse: \"ax2 := ax12;\"}\n");
    EXPECT_NE(e.find("axis 12 is a virtual axis of another group"), std::string::npos) << e;
    e = config_error("  - {name: s, virtual: [11], real: [1], inverse: \"ax1 := ax11;\", file: x.plc}\n");
    EXPECT_NE(e.find("one of them"), std::string::npos) << e;
    e = config_error("  - {name: s, virtual: [11], real: [1], file: nothere.plc_inc}\n");
    EXPECT_NE(e.find("nothere.plc_inc"), std::string::npos) << e;
}

} // namespace
