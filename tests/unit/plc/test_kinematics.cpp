// The kinematics examples (examples/plc_lib/*.plc_inc, examples/kinematics/*.plc) run as PLC
// code against axes bound like the IOC binds them: forward(inverse(v)) == v, the exact mirror
// against an independent model built from rotation matrices, the linear mirror against the exact
// one, the virtual-axis state machine and the interlocks. Seeded random poses, no timing.
#include "motion/axis_variables.hpp"
#include "plc/program.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numbers>
#include <random>
#include <string>
#include <vector>

using beamctl::motion::AxisVariables;
using beamctl::plc::Binding;
using beamctl::plc::CompileOptions;
using beamctl::plc::Host;
using beamctl::plc::Program;

namespace {

namespace fs = std::filesystem;

#ifdef BEAMCTL_SOURCE_DIR
const fs::path kRoot = BEAMCTL_SOURCE_DIR;
#else
// tests/<dir>/plc/test_kinematics.cpp -> the repository.
const fs::path kRoot = fs::path(__FILE__).parent_path().parent_path().parent_path().parent_path();
#endif
const fs::path kLib = kRoot / "examples" / "plc_lib";
const fs::path kMains = kRoot / "examples" / "kinematics";

constexpr double kTol = 1e-9; // forward(inverse(v)) == v [mm, mrad]
constexpr int kPoses = 1000;

// Axes as the IOC binds them (ax<n>.<variable> from motion's table, read-only where ECMC's are),
// static.*, and plc0.firstscan.
class AxisHost : public Host {
public:
    AxisVariables& ax(int n) { return axes_[n]; }
    double& stat(const std::string& name) { return statics_["static." + name]; }
    double firstscan = 1;

    std::optional<Binding> resolve(std::string_view name) override {
        const std::string n(name);
        if (n == "plc0.firstscan") return Binding{&firstscan, false, 1};
        if (n.rfind("static.", 0) == 0) return Binding{&statics_[n], true, 1};
        if (n.rfind("ax", 0) != 0) return std::nullopt;
        std::size_t p = 2;
        while (p < n.size() && std::isdigit(static_cast<unsigned char>(n[p]))) ++p;
        if (p == 2 || p >= n.size() || n[p] != '.') return std::nullopt;
        const auto* info = beamctl::motion::find_axis_variable(std::string_view(n).substr(p + 1));
        if (!info) return std::nullopt;
        return Binding{beamctl::motion::axis_variable(axes_[std::stoi(n.substr(2, p - 2))], *info),
                       info->writable, 1};
    }

private:
    std::map<int, AxisVariables> axes_;
    std::map<std::string, double> statics_;
};

CompileOptions options() {
    CompileOptions o;
    o.macros = {{"SELF", "plc0"}, {"SELF_ID", "0"}};
    o.include_path = {kLib.string()};
    return o;
}

// A main file that substitutes `macros` and includes `inc` (as the shipped mains do).
Program compile_include(AxisHost& h, const std::string& inc, const std::string& macros) {
    const std::string text = "substitute \"" + macros + "\"\ninclude \"" + inc + "\"\n";
    return Program::compile(text, "main.plc", h, options());
}

void run(Program& p, AxisHost& h) {
    ASSERT_EQ(p.run(), 0) << p.fault_location();
    h.firstscan = 0;
}

// ---- the mirror: an independent model ---------------------------------------------------------

struct Geometry { // [mm], the macros of mirror_trig.plc_inc
    double dz = 800, dzx = 800, dx = 300, xyd = 0, zc = 0, hy = 50, hx = 25, wx = 60, xoff = 0,
           yoff = 0;
    std::string macros() const {
        char buf[512];
        std::snprintf(buf, sizeof buf,
                      "DZ=%.17g,DZX=%.17g,DX=%.17g,XYD=%.17g,ZC=%.17g,HY=%.17g,HX=%.17g,WX=%.17g,"
                      "XOFF=%.17g,YOFF=%.17g",
                      dz, dzx, dx, xyd, zc, hy, hx, wx, xoff, yoff);
        return buf;
    }
};
// A mirror that is not symmetric in any way: inboard at -x, YD off axis, centre off the middle.
const Geometry kOddGeometry{650, 900, -280, 35, -60, 42, 30, 55, 12.5, -3};

// Axis numbers of the shipped mains: jacks 1-5, virtual 6-10.
enum { XU = 1, XD, YUI, YUO, YD, PITCH, YAW, ROLL, CX, CY };
const char* const kMirrorAxes = "XU=1,XD=2,YUI=3,YUO=4,YD=5,PITCH=6,YAW=7,ROLL=8,CX=9,CY=10,SM=mirror";

using Pose = std::array<double, 5>;  // pitch, yaw, roll [mrad], CX, CY [mm]
using Jacks = std::array<double, 5>; // XU, XD, YUI, YUO, YD [mm]
using Vec3 = std::array<double, 3>;
using Mat3 = std::array<Vec3, 3>;

Mat3 mul(const Mat3& a, const Mat3& b) {
    Mat3 c{};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
    return c;
}
double dot3(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Jack readings for a pose: the mirror body is rotated by Ry(yaw) Rx(pitch) Rz(roll) and placed
// so that its stripe surface and stripe mid-plane pass through (CX, CY, ZC); each jack's ball
// centre moves on its own lab line and touches its contact plane (offset from those planes by
// HY + YOFF along the normal, WX + XOFF along the transverse axis).
Jacks model_inverse(const Geometry& g, const Pose& v) {
    const double th = v[0] / 1000, ps = v[1] / 1000, ph = v[2] / 1000;
    const Mat3 rx{{{1, 0, 0}, {0, std::cos(th), -std::sin(th)}, {0, std::sin(th), std::cos(th)}}};
    const Mat3 ry{{{std::cos(ps), 0, std::sin(ps)}, {0, 1, 0}, {-std::sin(ps), 0, std::cos(ps)}}};
    const Mat3 rz{{{std::cos(ph), -std::sin(ph), 0}, {std::sin(ph), std::cos(ph), 0}, {0, 0, 1}}};
    const Mat3 r = mul(ry, mul(rx, rz));
    const Vec3 n{r[0][1], r[1][1], r[2][1]}; // R ey
    const Vec3 m{r[0][0], r[1][0], r[2][0]}; // R ex
    const Vec3 c{v[3], v[4], g.zc};
    // Point p = base + t * dir on the plane u·p = u·c - d.
    auto meet = [&](const Vec3& u, double d, Vec3 base, int axis) {
        base[axis] = 0;
        Vec3 dir{0, 0, 0};
        dir[axis] = 1;
        return (dot3(u, c) - d - dot3(u, base)) / dot3(u, dir);
    };
    const double dy = g.hy + g.yoff, dxo = g.wx + g.xoff;
    return {meet(m, dxo, {0, -g.hx, -g.dzx / 2}, 0) + g.wx, meet(m, dxo, {0, -g.hx, g.dzx / 2}, 0) + g.wx,
            meet(n, dy, {g.dx / 2, 0, -g.dz / 2}, 1) + g.hy,
            meet(n, dy, {-g.dx / 2, 0, -g.dz / 2}, 1) + g.hy,
            meet(n, dy, {g.xyd, 0, g.dz / 2}, 1) + g.hy};
}

// The linear model of mirror_matrix.plc_inc: the Jacobian of model_inverse at v = 0 (central
// differences) plus its value there.
Jacks model_linear(const Geometry& g, const Pose& v) {
    const Jacks p0 = model_inverse(g, {});
    Jacks p = p0;
    for (int k = 0; k < 5; ++k) {
        Pose a{}, b{};
        const double h = 1e-3;
        a[k] = h;
        b[k] = -h;
        const Jacks pa = model_inverse(g, a), pb = model_inverse(g, b);
        for (int j = 0; j < 5; ++j) p[j] += (pa[j] - pb[j]) / (2 * h) * v[k];
    }
    return p;
}

Pose random_pose(std::mt19937_64& rng, double scale = 1) {
    std::uniform_real_distribution<double> u(-20 * scale, 20 * scale); // mrad, mm
    return {u(rng), u(rng), u(rng), u(rng), u(rng)};
}

// One mirror PLC: sets virtual setpoints and reads the jacks' extsetpos (state 1), sets the jacks'
// actual positions and reads the virtual readbacks.
class MirrorRig {
public:
    MirrorRig(const std::string& inc, const Geometry& g)
        : program_(compile_include(host_, inc, std::string(kMirrorAxes) + "," + g.macros())) {}
    explicit MirrorRig(const std::string& main_file)
        : program_(Program::compile_file((kMains / main_file).string(), host_, options())) {}

    AxisHost& host() { return host_; }
    void scan() { run(program_, host_); }

    Jacks inverse(const Pose& v) {
        host_.ax(PITCH).traj.busy = 1;
        for (int k = 0; k < 5; ++k) host_.ax(PITCH + k).traj.setpos = v[k];
        scan();
        EXPECT_EQ(host_.stat("mirror"), 1);
        Jacks p;
        for (int j = 0; j < 5; ++j) p[j] = host_.ax(XU + j).traj.extsetpos;
        return p;
    }
    Pose forward(const Jacks& p) {
        for (int j = 0; j < 5; ++j) host_.ax(XU + j).enc.actpos = p[j];
        scan();
        Pose v;
        for (int k = 0; k < 5; ++k) v[k] = host_.ax(PITCH + k).enc.extactpos;
        return v;
    }

private:
    AxisHost host_;
    Program program_;
};

void expect_near(const std::array<double, 5>& a, const std::array<double, 5>& b, double tol,
                 const std::string& what) {
    for (int k = 0; k < 5; ++k) ASSERT_NEAR(a[k], b[k], tol) << what << ", component " << k;
}

} // namespace

// ---- compiling the shipped files --------------------------------------------------------------

TEST(KinematicsExamples, EveryShippedMainCompilesAndRuns) {
    std::vector<fs::path> mains;
    for (const auto& e : fs::directory_iterator(kMains))
        if (e.path().extension() == ".plc") mains.push_back(e.path());
    ASSERT_GE(mains.size(), 4u);
    for (const fs::path& f : mains) {
        AxisHost h;
        Program p = Program::compile_file(f.string(), h, options());
        EXPECT_EQ(p.run(), 0) << f << ": " << p.fault_location();
        EXPECT_EQ(h.ax(1).drv.enable, 1) << f << ": the first scan enables the axes";
    }
}

TEST(KinematicsExamples, EveryLibraryFileCompilesWithItsDefaults) {
    const std::map<std::string, std::string> axes = {
        {"slit_plane.plc_inc", "LO=1,HI=2,CEN=3,GAP=4,SM=slit"},
        {"mirror_trig.plc_inc", kMirrorAxes},
        {"mirror_matrix.plc_inc", kMirrorAxes},
        {"spiral.plc_inc", "X=1,Y=2,L=3,SM=spiral"}};
    int n = 0;
    for (const auto& e : fs::directory_iterator(kLib)) {
        if (e.path().extension() != ".plc_inc") continue;
        const std::string name = e.path().filename().string();
        ASSERT_TRUE(axes.count(name)) << name << " is new: add it to this test";
        AxisHost h;
        Program p = compile_include(h, name, axes.at(name));
        EXPECT_EQ(p.run(), 0) << name;
        ++n;
    }
    EXPECT_EQ(n, 4);
}

TEST(KinematicsExamples, IncludedTwiceWithDifferentMacrosGivesTwoIndependentSystems) {
    AxisHost h;
    const std::string text = std::string("substitute \"") + kMirrorAxes + "\"\n" +
                             "include \"mirror_trig.plc_inc\"\n"
                             "substitute \"XU=11,XD=12,YUI=13,YUO=14,YD=15,PITCH=16,YAW=17,"
                             "ROLL=18,CX=19,CY=20,SM=mirror2," +
                             kOddGeometry.macros() + "\"\ninclude \"mirror_trig.plc_inc\"\n";
    Program p = Program::compile(text, "main.plc", h, options());
    const Pose v{3, -4, 5, 6, -7};
    const Jacks a = model_inverse(Geometry{}, v), b = model_inverse(kOddGeometry, v);
    for (int j = 0; j < 5; ++j) {
        h.ax(XU + j).enc.actpos = a[j];
        h.ax(XU + 10 + j).enc.actpos = b[j];
    }
    run(p, h);
    for (int k = 0; k < 5; ++k) {
        EXPECT_NEAR(h.ax(PITCH + k).enc.extactpos, v[k], kTol) << k;
        EXPECT_NEAR(h.ax(PITCH + 10 + k).enc.extactpos, v[k], kTol) << k;
    }
    // Each has its own state machine.
    h.ax(YAW + 10).traj.busy = 1;
    run(p, h);
    EXPECT_EQ(h.stat("mirror"), 0);
    EXPECT_EQ(h.stat("mirror2"), 1);
    EXPECT_EQ(h.ax(XU).traj.source, 0);
    EXPECT_EQ(h.ax(XU + 10).traj.source, 1);
}

TEST(KinematicsExamples, SlitPlanesAreIndependent) {
    AxisHost h;
    Program p = Program::compile_file((kMains / "slit.plc").string(), h, options());
    h.ax(1).enc.actpos = -2; // horizontal blades
    h.ax(2).enc.actpos = 3;
    h.ax(3).enc.actpos = 1; // vertical blades
    h.ax(4).enc.actpos = 1.5;
    h.ax(7).traj.busy = 1; // vertical centre moves
    h.ax(7).traj.setpos = 4;
    h.ax(8).traj.setpos = 0.5;
    run(p, h);
    EXPECT_EQ(h.ax(5).enc.extactpos, 0.5);
    EXPECT_EQ(h.ax(6).enc.extactpos, 5);
    EXPECT_EQ(h.ax(7).enc.extactpos, 1.25);
    EXPECT_EQ(h.ax(8).enc.extactpos, 0.5);
    EXPECT_EQ(h.stat("slitx"), 0);
    EXPECT_EQ(h.stat("slity"), 1);
    EXPECT_EQ(h.ax(1).traj.source, 0);
    EXPECT_EQ(h.ax(3).traj.source, 1);
    EXPECT_EQ(h.ax(3).traj.extsetpos, 3.75);
    EXPECT_EQ(h.ax(4).traj.extsetpos, 4.25);
}

// ---- the exact mirror -------------------------------------------------------------------------

TEST(MirrorTrig, InverseMatchesTheRotationMatrixModel) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_trig.plc_inc", g);
        std::mt19937_64 rng(1);
        for (int i = 0; i < kPoses; ++i) {
            const Pose v = random_pose(rng);
            expect_near(rig.inverse(v), model_inverse(g, v), kTol, "pose " + std::to_string(i));
        }
    }
}

TEST(MirrorTrig, ForwardRecoversThePoseOfTheModelsJacks) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_trig.plc_inc", g);
        std::mt19937_64 rng(2);
        for (int i = 0; i < kPoses; ++i) {
            const Pose v = random_pose(rng);
            expect_near(rig.forward(model_inverse(g, v)), v, kTol, "pose " + std::to_string(i));
        }
    }
}

TEST(MirrorTrig, ForwardOfAnyJackPositionsIsAPoseThatGivesThemBack) {
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(-20, 20);
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_trig.plc_inc", g);
        for (int i = 0; i < kPoses; ++i) {
            const Jacks p{u(rng), u(rng), u(rng), u(rng), u(rng)};
            expect_near(model_inverse(g, rig.forward(p)), p, kTol, "jacks " + std::to_string(i));
        }
    }
}

TEST(MirrorTrig, ForwardOfInverseIsIdentityThroughThePlc) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_trig.plc_inc", g);
        std::mt19937_64 rng(4);
        for (int i = 0; i < kPoses; ++i) {
            const Pose v = random_pose(rng);
            expect_near(rig.forward(rig.inverse(v)), v, kTol, "pose " + std::to_string(i));
        }
    }
}

TEST(MirrorTrig, ShippedMainUsesTheDefaultGeometry) {
    MirrorRig rig("mirror.plc");
    std::mt19937_64 rng(5);
    for (int i = 0; i < 100; ++i) {
        const Pose v = random_pose(rng);
        expect_near(rig.inverse(v), model_inverse(Geometry{}, v), kTol, "pose");
    }
}

TEST(MirrorTrig, SignConventions) {
    MirrorRig rig("mirror_trig.plc_inc", Geometry{});
    const Jacks pitch = rig.inverse({1, 0, 0, 0, 0});
    EXPECT_GT(pitch[2], pitch[4]); // pitch > 0 lifts the upstream end
    EXPECT_EQ(pitch[2], pitch[3]);
    const Jacks yaw = rig.inverse({0, 1, 0, 0, 0});
    EXPECT_GT(yaw[1], yaw[0]); // yaw > 0 moves the downstream end to +x
    const Jacks roll = rig.inverse({0, 0, 1, 0, 0});
    EXPECT_GT(roll[2], roll[3]); // roll > 0 lifts the +x (YUI) side
    const Jacks c = rig.inverse({0, 0, 0, 2, 3});
    expect_near(c, {2, 2, 3, 3, 3}, 1e-12, "translation");
}

// ---- the linear mirror ------------------------------------------------------------------------

TEST(MirrorMatrix, ForwardOfInverseIsIdentityThroughThePlc) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_matrix.plc_inc", g);
        std::mt19937_64 rng(6);
        for (int i = 0; i < kPoses; ++i) {
            const Pose v = random_pose(rng);
            expect_near(rig.forward(rig.inverse(v)), v, kTol, "pose " + std::to_string(i));
        }
    }
}

TEST(MirrorMatrix, IsTheJacobianOfTheExactModelAtTheNominalPose) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig("mirror_matrix.plc_inc", g);
        std::mt19937_64 rng(7);
        for (int i = 0; i < 100; ++i) {
            const Pose v = random_pose(rng);
            expect_near(rig.inverse(v), model_linear(g, v), 1e-7, "pose"); // (numeric Jacobian)
        }
    }
}

TEST(MirrorMatrix, AgreesWithTheTrigonometricFormToSecondOrder) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig trig("mirror_trig.plc_inc", g), lin("mirror_matrix.plc_inc", g);
        std::mt19937_64 rng(8);
        for (int i = 0; i < 200; ++i) {
            const Pose u = random_pose(rng);
            // Jack difference d(s) for the pose s*u: halving s quarters it (no first-order term).
            double d[4];
            double vd[4]; // and the readbacks of the same jacks
            for (int k = 0; k < 4; ++k) {
                const double s = std::ldexp(1.0, -k);
                Pose v;
                for (int j = 0; j < 5; ++j) v[j] = s * u[j];
                const Jacks pt = trig.inverse(v), pl = lin.inverse(v);
                const Pose vt = trig.forward(pt), vl = lin.forward(pt);
                d[k] = vd[k] = 0;
                for (int j = 0; j < 5; ++j) {
                    d[k] = std::max(d[k], std::abs(pt[j] - pl[j]));
                    vd[k] = std::max(vd[k], std::abs(vt[j] - vl[j]));
                }
            }
            // Bound at full scale (20 mrad, 20 mm): DZ/2 * 0.02^2 + 2 * 20 mm * 0.02.
            EXPECT_LT(d[0], 1.0);
            for (int k = 1; k < 4; ++k) {
                if (d[k - 1] > 1e-6) {
                    EXPECT_NEAR(d[k - 1] / d[k], 4, 0.5) << "pose " << i << ", scale " << k;
                }
                if (vd[k - 1] > 1e-6) {
                    EXPECT_NEAR(vd[k - 1] / vd[k], 4, 0.5) << "pose " << i << ", scale " << k;
                }
            }
        }
    }
}

// ---- the mirror's state machine and interlocks ------------------------------------------------

class MirrorStates : public ::testing::TestWithParam<const char*> {};

TEST_P(MirrorStates, FollowTakeOverAndGiveBack) {
    const bool exact = std::string(GetParam()) == "mirror_trig.plc_inc";
    MirrorRig rig(GetParam(), Geometry{});
    AxisHost& h = rig.host();
    auto model = [&](const Pose& v) { return exact ? model_inverse({}, v) : model_linear({}, v); };
    const double tol = exact ? kTol : 1e-7;

    rig.scan(); // first scan: everything enabled, state 0
    for (int a = XU; a <= CY; ++a) EXPECT_EQ(h.ax(a).drv.enable, 1) << a;
    EXPECT_EQ(h.stat("mirror"), 0);

    // S0: the virtual axes follow the forward kinematics of the jacks' setpoints.
    const Pose v1{2, -3, 4, 5, -6};
    const Jacks p1 = model(v1);
    for (int j = 0; j < 5; ++j) h.ax(XU + j).traj.setpos = p1[j];
    rig.scan();
    for (int k = 0; k < 5; ++k) {
        EXPECT_EQ(h.ax(PITCH + k).traj.source, 1);
        EXPECT_NEAR(h.ax(PITCH + k).traj.extsetpos, v1[k], tol) << k;
        EXPECT_EQ(h.ax(XU + k).traj.source, 0);
    }

    // One virtual axis busy: S1, the jacks follow the inverse of all five setpoints (those not
    // moving keep their value, so nothing drifts), already in this scan.
    Pose v2 = v1;
    v2[1] = 7;
    for (int k = 0; k < 5; ++k) h.ax(PITCH + k).traj.setpos = v2[k];
    h.ax(YAW).traj.busy = 1;
    rig.scan();
    EXPECT_EQ(h.stat("mirror"), 1);
    Jacks p2 = model(v2);
    for (int j = 0; j < 5; ++j) {
        EXPECT_EQ(h.ax(XU + j).traj.source, 1);
        EXPECT_NEAR(h.ax(XU + j).traj.extsetpos, p2[j], tol) << j;
    }
    v2[1] = 9; // still moving
    h.ax(YAW).traj.setpos = 9;
    rig.scan();
    p2 = model(v2);
    for (int j = 0; j < 5; ++j) EXPECT_NEAR(h.ax(XU + j).traj.extsetpos, p2[j], tol) << j;

    // Not busy: S0, the jacks take their own trajectories back.
    h.ax(YAW).traj.busy = 0;
    rig.scan();
    EXPECT_EQ(h.stat("mirror"), 0);
    for (int j = 0; j < 5; ++j) EXPECT_EQ(h.ax(XU + j).traj.source, 0) << j;
    const Pose v3{-1, 1, -1, 1, -1};
    const Jacks p3 = model(v3);
    for (int j = 0; j < 5; ++j) h.ax(XU + j).traj.setpos = p3[j];
    rig.scan();
    for (int k = 0; k < 5; ++k) EXPECT_NEAR(h.ax(PITCH + k).traj.extsetpos, v3[k], tol) << k;
}

TEST_P(MirrorStates, InStateZeroTheVirtualSetpointsFollowTheJacks) {
    const bool exact = std::string(GetParam()) == "mirror_trig.plc_inc";
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig(GetParam(), g);
        AxisHost& h = rig.host();
        std::mt19937_64 rng(11);
        for (int i = 0; i < kPoses; ++i) {
            const Pose v = random_pose(rng);
            const Jacks p = exact ? model_inverse(g, v) : model_linear(g, v);
            for (int j = 0; j < 5; ++j) h.ax(XU + j).traj.setpos = p[j];
            rig.scan();
            ASSERT_EQ(h.stat("mirror"), 0);
            for (int k = 0; k < 5; ++k)
                ASSERT_NEAR(h.ax(PITCH + k).traj.extsetpos, v[k], exact ? kTol : 1e-7) << i;
        }
    }
}

// Every limit switch of every jack blocks exactly the virtual directions that move that jack
// towards it, per the sign of the model's Jacobian at the present pose (angles 0, centre at
// `at`). Centres outside the jacks make the roll move YUI and YUO the same way.
TEST_P(MirrorStates, LimitSwitchesBlockTheVirtualDirectionsThatPushFurther) {
    for (const Geometry& g : {Geometry{}, kOddGeometry}) {
        MirrorRig rig(GetParam(), g);
        AxisHost& h = rig.host();
        const bool exact = std::string(GetParam()) == "mirror_trig.plc_inc";
        const std::array<std::array<double, 2>, 3> centres{{{0, 0}, {200, -40}, {-220, 30}}};
        for (const auto& at : centres) {
            if (!exact && (at[0] != 0 || at[1] != 0)) continue; // linear: J at v = 0 only
            const Pose v0{0, 0, 0, at[0], at[1]};
            const Jacks p0 = model_inverse(g, v0);
            for (int j = 0; j < 5; ++j) h.ax(XU + j).enc.actpos = p0[j];
            for (int j = 0; j < 5; ++j) {
                for (int high = 0; high < 2; ++high) {
                    for (int i = 0; i < 5; ++i) h.ax(XU + i).mon.lowlim = h.ax(XU + i).mon.highlim = 1;
                    (high ? h.ax(XU + j).mon.highlim : h.ax(XU + j).mon.lowlim) = 0;
                    rig.scan();
                    for (int k = 0; k < 5; ++k) {
                        Pose a = v0, b = v0;
                        a[k] += 1e-3;
                        b[k] -= 1e-3;
                        const double dpdv = (model_inverse(g, a)[j] - model_inverse(g, b)[j]) / 2e-3;
                        const bool moves = std::abs(dpdv) > 1e-6;
                        const bool fwd_blocked = moves && ((dpdv > 0) == bool(high));
                        const bool bwd_blocked = moves && ((dpdv < 0) == bool(high));
                        const auto& mon = h.ax(PITCH + k).mon;
                        EXPECT_EQ(mon.ilockfwd, fwd_blocked ? 0 : 1)
                            << "jack " << j << (high ? " high" : " low") << " limit, virtual " << k
                            << " at CX " << at[0];
                        EXPECT_EQ(mon.ilockbwd, bwd_blocked ? 0 : 1)
                            << "jack " << j << (high ? " high" : " low") << " limit, virtual " << k
                            << " at CX " << at[0];
                    }
                }
            }
        }
    }
}

INSTANTIATE_TEST_SUITE_P(BothForms, MirrorStates,
                         ::testing::Values("mirror_trig.plc_inc", "mirror_matrix.plc_inc"));

// ---- the spiral -------------------------------------------------------------------------------

namespace {

struct Spiral {
    double a = 1, b = 0.2, x0 = 0, y0 = 0;
    double k() const { return a * std::sqrt(1 + b * b) / b; }
    // Seed eqs 22-23 at the θ whose arc length from (x0 + a, y0) is L (eq 21 minus L(0)).
    std::array<double, 2> point(double l) const {
        const double th = std::log(b * (l + k()) / (a * std::sqrt(1 + b * b))) / b;
        return {x0 + a * std::cos(th) * std::exp(b * th), y0 + a * std::sin(th) * std::exp(b * th)};
    }
    double theta(double l) const { return std::log1p(l / k()) / b; }
    std::string macros() const {
        char buf[160];
        std::snprintf(buf, sizeof buf, "X=1,Y=2,L=3,SM=spiral,A=%.17g,B=%.17g,X0=%.17g,Y0=%.17g",
                      a, b, x0, y0);
        return buf;
    }
};

class SpiralRig {
public:
    explicit SpiralRig(const Spiral& s)
        : program_(compile_include(host_, "spiral.plc_inc", s.macros())) {}
    AxisHost& host() { return host_; }
    void scan() { run(program_, host_); }
    std::array<double, 2> inverse(double l) {
        host_.ax(3).traj.busy = 1;
        host_.ax(3).traj.setpos = l;
        scan();
        return {host_.ax(1).traj.extsetpos, host_.ax(2).traj.extsetpos};
    }
    double forward(const std::array<double, 2>& xy) {
        host_.ax(1).enc.actpos = xy[0];
        host_.ax(2).enc.actpos = xy[1];
        scan();
        return host_.ax(3).enc.extactpos;
    }

private:
    AxisHost host_;
    Program program_;
};

} // namespace

TEST(Spiral, ArcLengthStartsAtTheSpiralOrigin) {
    SpiralRig rig(Spiral{});
    const auto p = rig.inverse(0);
    EXPECT_NEAR(p[0], 1, 1e-15);
    EXPECT_NEAR(p[1], 0, 1e-15);
    EXPECT_NEAR(rig.forward({1, 0}), 0, 1e-15);
    // A quarter turn: L = K (e^(0.2 π/2) - 1) (arc length by quadrature would agree).
    const double l = Spiral{}.k() * std::expm1(0.2 * std::numbers::pi / 2);
    const auto q = rig.inverse(l);
    EXPECT_NEAR(q[0], 0, 1e-12);
    EXPECT_NEAR(q[1], std::exp(0.2 * std::numbers::pi / 2), 1e-12);
}

TEST(Spiral, InverseFollowsSeedEquations) {
    for (const Spiral& s : {Spiral{}, Spiral{2.5, -0.15, 3, -4}}) {
        SpiralRig rig(s);
        std::mt19937_64 rng(9);
        std::uniform_real_distribution<double> u(-0.95, 12);
        for (int i = 0; i < kPoses; ++i) {
            const double l = u(rng) * s.k(); // (L < |K| when B < 0)
            const auto p = rig.inverse(l), q = s.point(l);
            ASSERT_NEAR(p[0], q[0], kTol) << l;
            ASSERT_NEAR(p[1], q[1], kTol) << l;
        }
    }
}

TEST(Spiral, ForwardOfInverseIsIdentityAfterARestart) {
    // Random jumps: each forward is a first scan (θ's branch from the radius).
    for (const Spiral& s : {Spiral{}, Spiral{2.5, -0.15, 3, -4}}) {
        SpiralRig rig(s);
        std::mt19937_64 rng(10);
        std::uniform_real_distribution<double> u(-0.95, 12);
        for (int i = 0; i < kPoses; ++i) {
            const double l = u(rng) * s.k(); // (L < |K| when B < 0)
            const auto p = rig.inverse(l);
            rig.host().firstscan = 1;
            ASSERT_NEAR(rig.forward(p), l, kTol) << l;
            EXPECT_NEAR(rig.host().stat("spiral_theta"), s.theta(l), 1e-12);
            EXPECT_NEAR(rig.host().stat("spiral_r"), std::hypot(p[0] - s.x0, p[1] - s.y0), 1e-12);
        }
    }
}

TEST(Spiral, ThetaStaysContinuousOverManyTurns) {
    // Along the spiral in small steps, 5 turns out and back, with the radius-based branch only at
    // the first scan: θ crosses ±π ten times and must never jump by 2π.
    const Spiral s;
    SpiralRig rig(s);
    const double l_end = s.k() * std::expm1(s.b * 10 * std::numbers::pi);
    std::vector<double> ls;
    for (int i = 0; i <= 20000; ++i) ls.push_back(-0.9 * s.k() + (l_end + 0.9 * s.k()) * i / 20000);
    for (int i = 20000; i >= 0; --i) ls.push_back(ls[i]);
    for (double l : ls) {
        const auto p = s.point(l);
        ASSERT_NEAR(rig.forward(p), l, kTol);
        ASSERT_NEAR(rig.host().stat("spiral_theta"), s.theta(l), 1e-9);
    }
    // Off the spiral, the winding is the one the axes came from (not the radius's): out to two
    // turns again, then a step away from the spiral.
    for (int i = 0; i <= 1000; ++i) {
        const double th0 = s.theta(ls.back()); // to two turns out
        const double th = th0 + (4 * std::numbers::pi - th0) * i / 1000;
        rig.forward(s.point(s.k() * std::expm1(s.b * th)));
    }
    // Far outside on the +y axis, where the radius alone would say two turns further out.
    rig.forward({0.001, 300});
    EXPECT_NEAR(rig.host().stat("spiral_theta"), std::atan2(300, 0.001) + 4 * std::numbers::pi,
                1e-12);
}

TEST(Spiral, StateMachineAndSetpointFollowing) {
    const Spiral s;
    SpiralRig rig(s);
    AxisHost& h = rig.host();
    rig.scan();
    EXPECT_EQ(h.ax(1).drv.enable + h.ax(2).drv.enable + h.ax(3).drv.enable, 3);
    // S0: L follows the setpoints of X and Y.
    const double l1 = 3; // θ < π: a jump from (0, 0) within half a turn
    const auto p1 = s.point(l1);
    h.ax(1).traj.setpos = p1[0];
    h.ax(2).traj.setpos = p1[1];
    rig.scan();
    EXPECT_EQ(h.stat("spiral"), 0);
    EXPECT_EQ(h.ax(3).traj.source, 1);
    EXPECT_NEAR(h.ax(3).traj.extsetpos, l1, kTol);
    EXPECT_EQ(h.ax(1).traj.source, 0);
    // L busy: X and Y follow L.
    const auto p2 = rig.inverse(20);
    EXPECT_EQ(h.stat("spiral"), 1);
    EXPECT_EQ(h.ax(1).traj.source, 1);
    EXPECT_EQ(h.ax(2).traj.source, 1);
    EXPECT_NEAR(p2[0], s.point(20)[0], kTol);
    // Not busy: back to S0; the setpoint θ continues from where L left it.
    h.ax(3).traj.busy = 0;
    h.ax(1).traj.setpos = p2[0];
    h.ax(2).traj.setpos = p2[1];
    rig.scan();
    EXPECT_EQ(h.stat("spiral"), 0);
    EXPECT_EQ(h.ax(1).traj.source, 0);
    rig.scan();
    EXPECT_NEAR(h.ax(3).traj.extsetpos, 20, kTol);
}

TEST(Spiral, LimitSwitchesBlockTheDirectionsAlongTheTangent) {
    const Spiral s;
    SpiralRig rig(s);
    AxisHost& h = rig.host();
    for (int i = 0; i < 64; ++i) {
        const double l = -0.5 * s.k() + i * 0.37;
        const auto p = s.point(l);
        const auto pa = s.point(l + 1e-4), pb = s.point(l - 1e-4);
        const double d[2] = {pa[0] - pb[0], pa[1] - pb[1]};
        for (int axis = 0; axis < 2; ++axis) {
            for (int high = 0; high < 2; ++high) {
                for (int a = 1; a <= 2; ++a) h.ax(a).mon.lowlim = h.ax(a).mon.highlim = 1;
                (high ? h.ax(1 + axis).mon.highlim : h.ax(1 + axis).mon.lowlim) = 0;
                rig.forward(p);
                const bool fwd_blocked = high ? d[axis] > 0 : d[axis] < 0;
                const bool bwd_blocked = high ? d[axis] < 0 : d[axis] > 0;
                EXPECT_EQ(h.ax(3).mon.ilockfwd, fwd_blocked ? 0 : 1) << l << " " << axis;
                EXPECT_EQ(h.ax(3).mon.ilockbwd, bwd_blocked ? 0 : 1) << l << " " << axis;
            }
        }
    }
}
