// PVT profile moves (ECMC's profile-move PVs) in virtual time: the path ECMC builds (ramps, mean
// velocities, cubic Hermite), build checks and their messages, execution on two axes started in
// the same cycle, pulses with readbacks, relative mode, and every way a profile ends short
// (stop, abort, an interlock) reported as Failure or Abort, never as Success.
#include "../temp_dir.hpp"
#include "ethercat/sim/io_point.hpp"
#include "ethercat/sim/segment.hpp"
#include "motion/pvt.hpp"
#include "pv/convert.hpp"
#include "virtual_ioc.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

// A virtual axis with its own encoder (actual = setpoint), soft limits -50..50, max 100 units/s.
std::string axis_yaml(int id, const std::string& name) {
    return "axis: {id: " + std::to_string(id) + ", type: virtual}\n"
           "epics: {name: " + name + ", motorRecord: {pvt: {npoints: 20, nreadback: 20}}}\n"
           "encoder: {numerator: 1, denominator: 1, type: 1, bits: 32, position: ec0.s0.ZERO}\n"
           "trajectory: {axis: {velocity: 20, acceleration: 200}}\n"
           "input: {limit: {forward: ec0.s0.ONE.0, backward: ec0.s0.ONE.0}}\n"
           "softlimits: {enable: true, forward: 50, forwardEnable: true, backward: -50, backwardEnable: true}\n"
           "monitoring: {lag: {enable: false, tolerance: 1, time: 10}, \n"
           "             velocity: {enable: true, max: 100, time: {trajectory: 100, drive: 200}}}\n";
}

struct PvtIoc : VirtualIoc {
    explicit PvtIoc(const std::string& path) : VirtualIoc(path) {}
    void put(const std::string& name, double v) { put_array(name, {v}); }
    void put_array(const std::string& name, const std::vector<double>& v) {
        pv::Address a;
        ASSERT_TRUE(ioc->database().resolve(name, a)) << name;
        ASSERT_EQ(ioc->database().put(a, pv::Prim::Double, v.data(), uint32_t(v.size())), pv::PutStatus::Ok) << name;
    }
};

std::string ioc_file(TempDir& d, const std::string& extra = "") {
    d.write("x.yaml", axis_yaml(1, "X"));
    d.write("y.yaml", axis_yaml(2, "Y"));
    return d.write("ioc.yaml", "ioc: {name: T, prefix: 'T:'}\n"
                               "engine: {rate_hz: 1000}\n"
                               "buses:\n  - id: 0\n    link: {type: sim}\n    slaves:\n      - {position: 0, type: EK1100}\n"
                               "      - {position: 1, type: EL2008}\n"
                               "axes:\n  - {file: x.yaml}\n  - {file: y.yaml}\n" + extra);
}

} // namespace

// ECMC's construction: pre-point Ta before P0 at P0 - v0 Ta/2, interior velocities the mean of
// the neighbouring segments', post-point Ta after the last; the path passes every point with
// that velocity, continuously.
TEST(Pvt, PathAsEcmcBuildsIt) {
    motion::PvtPath p = motion::PvtPath::build({0, 1, 3, 3}, {1, 1, 2}, 0.5);
    ASSERT_EQ(p.points().size(), 6u);
    EXPECT_DOUBLE_EQ(p.points()[0].p, 0 - 1 * 0.5 / 2);
    EXPECT_DOUBLE_EQ(p.points()[2].v, (1 + 2) / 2.0);
    EXPECT_DOUBLE_EQ(p.points()[3].v, (2 + 0) / 2.0);
    EXPECT_DOUBLE_EQ(p.end_time(), 0.5 + 4 + 0.5);
    std::size_t seg = 0;
    double x, v, a;
    const double want[] = {0, 1, 3, 3};
    for (std::size_t i = 0; i < p.real_points(); ++i) {
        p.eval(p.point_time(i), seg, x, v, a);
        EXPECT_NEAR(x, want[i], 1e-12) << i;
    }
    p.eval(0, seg = 0, x, v, a);
    EXPECT_NEAR(v, 0, 1e-12);
    p.eval(p.end_time(), seg, x, v, a);
    EXPECT_NEAR(v, 0, 1e-12);
    EXPECT_NEAR(x, 3, 1e-12);
    // continuous position and velocity across a point
    double x1, v1, x2, v2;
    p.eval(1.5 - 1e-9, seg = 0, x1, v1, a);
    p.eval(1.5 + 1e-9, seg, x2, v2, a);
    EXPECT_NEAR(x1, x2, 1e-6);
    EXPECT_NEAR(v1, v2, 1e-6);
    EXPECT_THROW(motion::PvtPath::build({0}, {}, 0.5), Error);
    EXPECT_THROW(motion::PvtPath::build({0, 1}, {1}, 0), Error);
    EXPECT_THROW(motion::PvtPath::build({0, 1}, {-1}, 0.5), Error);
}

TEST(Pvt, TwoAxesRunTheirPathsWithPulsesAndReadbacks) {
    TempDir d;
    PvtIoc v(ioc_file(d, "pvt: {trigger: ec0.s1.binaryOutput01, trigger_duration_s: 0.01}\n"));
    v.ioc->publish();
    EXPECT_EQ(v.text("T:PVT-BuildMessage"), "Build not executed.");
    v.put("T:PVT-NumPoints", 5);
    v.put("T:PVT-NumPulses", 5);
    v.put("T:PVT-EndPulses", 5);
    v.put("T:PVT-FixedTime", 0.1);
    v.put("T:PVT-Acceleration", 0.05);
    v.put("T:X-PVT-UseAxis", 1);
    v.put("T:Y-PVT-UseAxis", 1);
    v.put_array("T:X-PVT-Positions", {0, 1, 2, 3, 2});
    v.put_array("T:Y-PVT-Positions", {5, 5, 4, 3, 3});
    v.put("T:PVT-Build", 1);
    EXPECT_EQ(v.get("T:PVT-BuildStatus"), 1) << v.text("T:PVT-BuildMessage");
    EXPECT_EQ(v.text("T:PVT-BuildMessage"), "Build profile succeeded");
    v.put("T:PVT-Execute", 1);
    EXPECT_EQ(v.get("T:PVT-ExecuteState"), 1); // Move start
    // the axes go to their starts (Ta before P0), then run the paths in step
    motion::Axis& x = v.axis("X");
    motion::Axis& y = v.axis("Y");
    // the trigger output as the terminal sees it (pvt.trigger: EL2008 output 1)
    ethercat::sim::Segment& seg = *v.ioc->segment(0);
    ethercat::sim::IoPoint out = ethercat::sim::bind_io(seg, 1, "binaryOutput01");
    bool saw_executing = false, in_step = true, last = false;
    int edges = 0, high_cycles = 0;
    for (int k = 0; k < 3000 && v.get("T:PVT-ExecuteState") != 0; ++k) {
        v.cycles(1);
        if (k % 10 == 0) v.ioc->publish();
        if (x.in_pvt() != y.in_pvt()) in_step = false;
        if (x.in_pvt()) saw_executing = true;
        bool high = out.get(seg) != 0;
        edges += high && !last;
        high_cycles += high;
        last = high;
    }
    v.ioc->publish();
    EXPECT_TRUE(saw_executing);
    EXPECT_TRUE(in_step); // started and ended in the same cycles
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 1) << v.text("T:PVT-ExecuteMessage");
    EXPECT_EQ(v.text("T:PVT-ExecuteMessage"), "Profile done");
    EXPECT_EQ(v.get("T:PVT-NumActualPulses"), 5);
    EXPECT_EQ(v.get("T:PVT-SftTrg"), 5);
    EXPECT_EQ(v.get("T:PVT-CurrentPoint"), 5);
    // ends Ta/2 * v_last past the last point: 2 - 1 * 0.05/2
    EXPECT_EQ(edges, 5);           // five pulses on the wire
    EXPECT_NEAR(high_cycles, 5 * 10, 5); // each 10 ms (trigger_duration_s)
    EXPECT_NEAR(x.status().set_pos, 2 - 10 * 0.05 / 2, 1e-9); // v_last = -10 units/s: Ta/2 * v_last past the end
    EXPECT_NEAR(y.status().set_pos, 3, 1e-9);
    EXPECT_FALSE(x.status().busy);
    // readbacks at the pulses (one per point here): the points themselves
    v.put("T:PVT-Readback", 1);
    EXPECT_EQ(v.get("T:PVT-ReadbackStatus"), 1);
    std::vector<double> want{0, 1, 2, 3, 2};
    for (uint32_t i = 0; i < 5; ++i) {
        EXPECT_NEAR(v.get("T:X-PVT-Readbacks", i), want[i], 1e-9) << i;
        EXPECT_NEAR(v.get("T:X-PVT-FollowingErrors", i), 0, 1e-9) << i;
    }
    EXPECT_NEAR(v.get("T:Y-PVT-Readbacks", 2), 4, 1e-9);
    // a second run from where it stands works too (absolute: it goes back to the start)
    v.put("T:PVT-Execute", 1);
    v.run(2000);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 1) << v.text("T:PVT-ExecuteMessage");
}

TEST(Pvt, BuildChecksAndMessages) {
    TempDir d;
    PvtIoc v(ioc_file(d));
    v.put("T:PVT-NumPoints", 4);
    v.put("T:PVT-NumPulses", 0);
    v.put("T:PVT-Build", 1);
    EXPECT_EQ(v.get("T:PVT-BuildStatus"), 2);
    EXPECT_EQ(v.text("T:PVT-BuildMessage"), "Error: no axis selected (set <Axis>-PVT-UseAxis).");
    v.put("T:X-PVT-UseAxis", 1);
    v.put_array("T:X-PVT-Positions", {0, 1, 2});
    v.put("T:PVT-Build", 1);
    EXPECT_EQ(v.text("T:PVT-BuildMessage"), "Error: X: 3 positions written, NumPoints is 4.");
    v.put_array("T:X-PVT-Positions", {0, 10, 60, 0}); // beyond the soft limit at 50
    v.put("T:PVT-Build", 1);
    EXPECT_NE(v.text("T:PVT-BuildMessage").find("beyond the high soft limit 50"), std::string::npos) << v.text("T:PVT-BuildMessage");
    v.put_array("T:X-PVT-Positions", {0, 1, 2, 3});
    v.put("T:PVT-Acceleration", 0.001);
    v.put("T:PVT-FixedTime", 0.001); // 1000 units/s
    v.put("T:PVT-Build", 1);
    EXPECT_NE(v.text("T:PVT-BuildMessage").find("above the axis's maximum 100"), std::string::npos) << v.text("T:PVT-BuildMessage");
    v.put("T:PVT-FixedTime", 1);
    EXPECT_EQ(v.text("T:PVT-BuildMessage"), "Fixed time changed, rebuild required...");
    v.put("T:PVT-Acceleration", 0);
    v.put("T:PVT-Build", 1);
    EXPECT_NE(v.text("T:PVT-BuildMessage").find("Acceleration time 0 s"), std::string::npos);
    v.put("T:PVT-Acceleration", 0.2);
    v.put("T:PVT-TimeMode", 1);
    v.put_array("T:PVT-Times", {1, 0, 1});
    v.put("T:PVT-Build", 1);
    EXPECT_NE(v.text("T:PVT-BuildMessage").find("time 2 is 0"), std::string::npos) << v.text("T:PVT-BuildMessage");
    v.put("T:PVT-NumPulses", 3);
    v.put("T:PVT-StartPulses", 5);
    v.put_array("T:PVT-Times", {1, 1, 1});
    v.put("T:PVT-Build", 1);
    EXPECT_NE(v.text("T:PVT-BuildMessage").find("Start pulse id 5 outside points 1..4"), std::string::npos);
    // execute without a valid build: Failure with the reason (ECMC leaves the status alone)
    v.put("T:PVT-Execute", 1);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 2);
    EXPECT_EQ(v.text("T:PVT-ExecuteMessage"), "Profile not built: Build it first.");
}

// A profile that ends short never says Success: a motor-record STOP (Halt) in the middle is a
// Failure naming the axis; Abort says Abort; both axes stand still afterwards.
TEST(Pvt, StoppedOrAbortedProfilesAreNotSuccess) {
    TempDir d;
    PvtIoc v(ioc_file(d));
    v.put("T:PVT-NumPoints", 3);
    v.put("T:PVT-NumPulses", 0);
    v.put("T:PVT-FixedTime", 0.5);
    v.put("T:X-PVT-UseAxis", 1);
    v.put("T:Y-PVT-UseAxis", 1);
    v.put_array("T:X-PVT-Positions", {0, 5, 10});
    v.put_array("T:Y-PVT-Positions", {0, -5, -10});
    v.put("T:PVT-Build", 1);
    ASSERT_EQ(v.get("T:PVT-BuildStatus"), 1) << v.text("T:PVT-BuildMessage");
    v.put("T:PVT-Execute", 1);
    motion::Axis& y = v.axis("Y");
    for (int k = 0; k < 5000 && !y.in_pvt(); ++k) v.cycles(1);
    ASSERT_TRUE(y.in_pvt());
    v.run(300);
    v.send("Y", motion::AxisCommand{motion::CommandType::Halt});
    v.run(2000);
    EXPECT_EQ(v.get("T:PVT-ExecuteState"), 0);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 2);
    EXPECT_EQ(v.text("T:PVT-ExecuteMessage"), "Profile failed: Y stopped before the end of its path");
    EXPECT_FALSE(v.axis("X").status().busy);
    EXPECT_LT(v.axis("X").status().set_pos, 9); // halted too, short of its end
    // Abort
    v.put("T:PVT-Execute", 1);
    for (int k = 0; k < 5000 && !y.in_pvt(); ++k) v.cycles(1);
    v.run(200);
    v.put("T:PVT-Abort", 1);
    v.run(2000);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 3);
    EXPECT_EQ(v.text("T:PVT-ExecuteMessage"), "Profile aborted.");
    // a motion command to an axis running a profile is refused (busy)
    v.put("T:PVT-Execute", 1);
    for (int k = 0; k < 5000 && !y.in_pvt(); ++k) v.cycles(1);
    motion::AxisCommand mv{motion::CommandType::MoveAbsolute, 3};
    EXPECT_EQ(y.command(mv), motion::error_id::kBusy);
    v.run(3000);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 1) << v.text("T:PVT-ExecuteMessage");
}

// Relative mode: the positions are offsets from where each axis stands at execute.
TEST(Pvt, RelativeModeOffsetsFromTheSetpoint) {
    TempDir d;
    PvtIoc v(ioc_file(d));
    v.send("X", motion::AxisCommand{motion::CommandType::Power, 0, 0, 0, 0, -1, true});
    v.cycles(5);
    v.send("X", motion::AxisCommand{motion::CommandType::MoveAbsolute, 10});
    v.run(3000);
    ASSERT_NEAR(v.axis("X").status().set_pos, 10, 1e-9);
    v.put("T:PVT-NumPoints", 3);
    v.put("T:PVT-NumPulses", 0);
    v.put("T:PVT-FixedTime", 0.2);
    v.put("T:PVT-MoveMode", 1);
    v.put("T:X-PVT-UseAxis", 1);
    v.put_array("T:X-PVT-Positions", {0, 1, 1});
    v.put("T:PVT-Build", 1);
    v.put("T:PVT-Execute", 1);
    v.run(3000);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 1) << v.text("T:PVT-ExecuteMessage");
    EXPECT_NEAR(v.axis("X").status().set_pos, 11, 1e-9);
    v.put("T:PVT-Readback", 1);
    EXPECT_NEAR(v.get("T:X-PVT-Readbacks", 1), 11, 1e-9); // absolute readbacks
    // relative profile that would cross the soft limit from here: refused at execute
    v.put("T:PVT-FixedTime", 1);
    v.put_array("T:X-PVT-Positions", {0, 20, 45});
    v.put("T:PVT-Build", 1);
    ASSERT_EQ(v.get("T:PVT-BuildStatus"), 1);
    v.put("T:PVT-Execute", 1);
    EXPECT_EQ(v.get("T:PVT-ExecuteStatus"), 2);
    EXPECT_NE(v.text("T:PVT-ExecuteMessage").find("beyond the high soft limit 50"), std::string::npos) << v.text("T:PVT-ExecuteMessage");
}
