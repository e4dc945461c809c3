// Compound motors (automation/compound_motor.hpp) in virtual time, on motor records of one
// database with simulated motors: seed 003's delay-branch energy E (Si(220) Bragg angle for the
// crystal, twice it for the arm, the diagnostic following L sin 2theta with L an input) and a slit's
// gap and centre over two blades. Forward of inverse gives the target back; the virtual's limits
// follow the reals'; a move beyond them is refused before anything moves; a stopped or
// interrupted move fails its put-callback; bad expressions are refused naming where.
#include "automation/compound_motor.hpp"

#include "db_rig.hpp"

#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "pv/db_file.hpp"
#include "pv/motor_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>

using namespace beamctl;
using namespace beamctl::automation;

namespace {

constexpr double kHc = 12.398419843320026; // keV Angstrom
constexpr double kD = 1.920155716;         // Si(220) d-spacing [Angstrom]

double bragg_deg(double kev) { return std::asin(kHc / (2 * kD * kev)) * 180 / M_PI; }

const char* kMotors = R"(
record(motor, "T:th")  { field(MRES, "0.0001") field(RDBD, "0.0001") field(VELO, "5") field(ACCL, "0.1") field(DHLM, "80") field(DLLM, "5") }
record(motor, "T:tth") { field(MRES, "0.0001") field(RDBD, "0.0001") field(VELO, "10") field(ACCL, "0.1") field(DHLM, "170") field(DLLM, "10") }
record(motor, "T:dd")  { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "50") field(ACCL, "0.1") field(DHLM, "300") field(DLLM, "-300") }
record(motor, "S:top") { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "1") field(ACCL, "0.1") field(DHLM, "5") field(DLLM, "-5") }
record(motor, "S:bot") { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "1") field(ACCL, "0.1") field(DHLM, "5") field(DLLM, "-5") }
record(ao, "T:L") { field(VAL, "250") }
)";

config::CompoundMotorEntry energy_group() {
    config::CompoundMotorEntry e;
    e.name = "energy", e.where = "test.yaml:1:1";
    e.reals = {{"th", "T:th", "test.yaml:2:1"}, {"tth", "T:tth", "test.yaml:3:1"}, {"dd", "T:dd", "test.yaml:4:1"}};
    e.inputs = {{"L", "T:L", "test.yaml:5:1"}};
    config::CompoundMotorEntry::Virtual v;
    v.name = "E", v.egu = "keV", v.prec = 5, v.where = "test.yaml:6:1";
    v.forward = "12.398419843320026 / (2 * 1.920155716 * sin(th * pi / 180))";
    e.virtuals = {v};
    const std::string theta = "asin(12.398419843320026 / (2 * 1.920155716 * E))";
    e.inverse = {{"th", theta + " * 180 / pi"}, {"tth", "2 * " + theta + " * 180 / pi"}, {"dd", "L * sin(2 * " + theta + ")"}};
    e.inverse_where = {"test.yaml:7:1", "test.yaml:8:1", "test.yaml:9:1"};
    return e;
}

config::CompoundMotorEntry slit_group() {
    config::CompoundMotorEntry e;
    e.name = "slit", e.where = "test.yaml:20:1";
    e.reals = {{"top", "S:top", ""}, {"bot", "S:bot", ""}};
    config::CompoundMotorEntry::Virtual gap, centre;
    gap.name = "gap", gap.forward = "top - bot";
    centre.name = "centre", centre.forward = "(top + bot) / 2";
    e.virtuals = {gap, centre};
    e.inverse = {{"top", "centre + gap / 2"}, {"bot", "centre - gap / 2"}};
    e.inverse_where = {"", ""};
    return e;
}

struct Rig : test::DbRig {
    std::unique_ptr<CompoundMotors> cm;

    explicit Rig(std::vector<config::CompoundMotorEntry> groups = {energy_group(), slit_group()}) {
        now = 10;
        db.load(pv::parse_db(kMotors, "motors.db", {}));
        cm = std::make_unique<CompoundMotors>(groups, "V:", db);
        for (const char* m : {"T:th", "T:tth", "T:dd", "S:top", "S:bot", "V:E", "V:gap", "V:centre"})
            if (pv::MotorRecord* r = pv::MotorRecord::from(db.find(m))) r->set_clock([this] { return now; });
        db.init_records();
        cm->start();
        poll = [this] { cm->poll(); };
        // the simulated motors start at dial 0: put the reals where the tests begin
        for (auto [m, x] : {std::pair{"T:th", 20.0}, {"T:tth", 40.0}, {"T:dd", 0.0}, {"S:top", 1.0}, {"S:bot", -1.0}}) put(m, x);
        run(10);
    }
    // A put-callback on n; runs until it completes (at most `seconds`): its status, or nullopt.
    std::optional<pv::PutStatus> move(const std::string& n, double x, double seconds = 60) {
        pv::Address a;
        if (!db.resolve(n, a)) throw std::runtime_error("no " + n);
        std::optional<pv::PutStatus> got;
        const pv::PutStatus st = db.put(a, pv::Prim::Double, &x, 1, [&](pv::PutStatus s) { got = s; });
        if (st != pv::PutStatus::Ok) return st;
        for (double t = 0; t < seconds && !got; t += 0.1) run(0.1);
        return got;
    }
};

} // namespace

TEST(CompoundMotor, StartsAtTheForwardOfTheReadbacksAndMovesEveryRealToTheInverse) {
    Rig r;
    EXPECT_EQ(r.cm->groups(), 2u);
    EXPECT_EQ(r.cm->virtual_count(), 3u);
    // th starts at 20 degrees: E = hc / (2 d sin 20)
    const double e0 = kHc / (2 * kD * std::sin(20 * M_PI / 180));
    EXPECT_NEAR(r.get("V:E.RBV"), e0, 1e-4);
    EXPECT_NEAR(r.get("V:E.VAL"), e0, 1e-4); // VAL follows the readback while idle
    EXPECT_NEAR(r.get("V:gap.RBV"), 2, 1e-9);
    EXPECT_NEAR(r.get("V:centre.RBV"), 0, 1e-9);

    const auto st = r.move("V:E", 8.0);
    ASSERT_TRUE(st.has_value());
    EXPECT_EQ(*st, pv::PutStatus::Ok);
    EXPECT_EQ(r.get("V:E.DMOV"), 1);
    EXPECT_NEAR(r.get("T:th.RBV"), bragg_deg(8.0), 1e-4);
    EXPECT_NEAR(r.get("T:tth.RBV"), 2 * bragg_deg(8.0), 1e-4);
    EXPECT_NEAR(r.get("T:dd.RBV"), 250 * std::sin(2 * bragg_deg(8.0) * M_PI / 180), 1e-3);
    EXPECT_NEAR(r.get("V:E.RBV"), 8.0, 1e-4); // forward of inverse: the target
}

TEST(CompoundMotor, LimitsFollowTheRealsAndAMoveBeyondThemMovesNothing) {
    Rig r;
    // th within [5, 80] degrees -> E within [hc/(2d sin 80), hc/(2d sin 5)]
    const double e_lo = kHc / (2 * kD * std::sin(80 * M_PI / 180)), e_hi = kHc / (2 * kD * std::sin(5 * M_PI / 180));
    EXPECT_NEAR(r.get("V:E.LLM"), e_lo, 1e-4);
    EXPECT_NEAR(r.get("V:E.HLM"), e_hi, 1e-3);
    // Narrow a real's limits: the virtual's follow (th <= 30 -> E >= hc/(2d sin 30)).
    r.put("T:th.HLM", 30);
    r.run(0.05); // at once, not at the next periodic search
    EXPECT_NEAR(r.get("V:E.LLM"), kHc / (2 * kD * std::sin(30 * M_PI / 180)), 1e-4);
    const double th = r.get("T:th.RBV"), tth = r.get("T:tth.RBV");
    const auto st = r.move("V:E", 5.0); // needs th = 40
    ASSERT_TRUE(st.has_value());
    EXPECT_NE(*st, pv::PutStatus::Ok);
    EXPECT_EQ(r.get("V:E.LVIO"), 1);
    EXPECT_DOUBLE_EQ(r.get("T:th.RBV"), th);
    EXPECT_DOUBLE_EQ(r.get("T:tth.RBV"), tth);
    // and a move within them still works
    EXPECT_EQ(r.move("V:E", 7.0).value_or(pv::PutStatus::NoAccess), pv::PutStatus::Ok);
}

TEST(CompoundMotor, TheGroupRefusesATargetOutsideARealsLimitsEvenWhenTheRecordWouldNot) {
    // Only the group knows tth's limit when th's allows more: tth <= 60 means th <= 30.
    Rig r;
    r.put("T:tth.HLM", 60);
    r.put("V:E.LLM", 1); // a client widened the virtual's own limit: the group still checks
    const double th = r.get("T:th.RBV");
    const auto st = r.move("V:E", 5.0);
    ASSERT_TRUE(st.has_value());
    EXPECT_NE(*st, pv::PutStatus::Ok);
    EXPECT_DOUBLE_EQ(r.get("T:th.RBV"), th);
}

TEST(CompoundMotor, SeveralVirtualsOverOneSetOfRealsKeepEachOther) {
    Rig r;
    ASSERT_EQ(r.move("V:gap", 3.0).value_or(pv::PutStatus::NoAccess), pv::PutStatus::Ok);
    EXPECT_NEAR(r.get("S:top.RBV"), 1.5, 1e-3);
    EXPECT_NEAR(r.get("S:bot.RBV"), -1.5, 1e-3);
    EXPECT_NEAR(r.get("V:centre.RBV"), 0, 1e-3);
    ASSERT_EQ(r.move("V:centre", 0.5).value_or(pv::PutStatus::NoAccess), pv::PutStatus::Ok);
    EXPECT_NEAR(r.get("S:top.RBV"), 2.0, 1e-3);
    EXPECT_NEAR(r.get("S:bot.RBV"), -1.0, 1e-3);
    EXPECT_NEAR(r.get("V:gap.RBV"), 3.0, 2e-3);
    // the gap's limits: the blades within [-5, 5] around centre 0.5 -> gap <= 9
    EXPECT_NEAR(r.get("V:gap.HLM"), 9.0, 1e-3);
}

TEST(CompoundMotor, AStoppedMoveFailsItsPutCallbackAndStopsTheReals) {
    Rig r;
    pv::Address a;
    ASSERT_TRUE(r.db.resolve("V:E", a));
    double x = 4.0; // th from 20 to ~53.6 degrees at 5 deg/s: about 7 s
    std::optional<pv::PutStatus> got;
    ASSERT_EQ(r.db.put(a, pv::Prim::Double, &x, 1, [&](pv::PutStatus s) { got = s; }), pv::PutStatus::Ok);
    r.run(2.0);
    EXPECT_FALSE(got.has_value());
    EXPECT_EQ(r.get("V:E.DMOV"), 0);
    r.put("V:E.STOP", 1);
    for (int k = 0; k < 100 && !got; ++k) r.run(0.1);
    ASSERT_TRUE(got.has_value());
    EXPECT_NE(*got, pv::PutStatus::Ok);
    EXPECT_EQ(r.get("V:E.DMOV"), 1);
    const double th = r.get("T:th.RBV");
    EXPECT_GT(th, 25);
    EXPECT_LT(th, bragg_deg(4.0) - 1);
    r.run(2.0);
    EXPECT_DOUBLE_EQ(r.get("T:th.RBV"), th); // stopped, not still going
}

TEST(CompoundMotor, ARealStoppedOnItsOwnFailsTheVirtualsMove) {
    Rig r;
    pv::Address a;
    ASSERT_TRUE(r.db.resolve("V:E", a));
    double x = 4.0;
    std::optional<pv::PutStatus> got;
    ASSERT_EQ(r.db.put(a, pv::Prim::Double, &x, 1, [&](pv::PutStatus s) { got = s; }), pv::PutStatus::Ok);
    r.run(1.0);
    r.put("T:th.STOP", 1); // someone stops one real: its put-callback completes, short of its target
    for (int k = 0; k < 200 && !got; ++k) r.run(0.1);
    ASSERT_TRUE(got.has_value());
    EXPECT_NE(*got, pv::PutStatus::Ok);
    EXPECT_GT(std::fabs(r.get("V:E.RBV") - 4.0), 0.1);
}

TEST(CompoundMotor, JoggingAndHomingAreRefused) {
    Rig r;
    const double th = r.get("T:th.RBV");
    r.put("V:E.JOGF", 1);
    r.run(1.0);
    r.put("V:E.JOGF", 0);
    r.run(1.0);
    EXPECT_DOUBLE_EQ(r.get("T:th.RBV"), th);
    EXPECT_EQ(r.get("V:E.DMOV"), 1);
}

TEST(CompoundMotor, BadExpressionsAreRefusedNamingWhere) {
    pv::Database db;
    db.load(pv::parse_db(kMotors, "motors.db", {}));
    auto bad_forward = energy_group();
    bad_forward.virtuals[0].forward = "12.4 / sin(theta)";
    try {
        CompoundMotors cm({bad_forward}, "V:", db);
        FAIL() << "accepted an unknown name";
    } catch (const Error& e) {
        const std::string w = e.what();
        EXPECT_NE(w.find("test.yaml:6:1: forward of E"), std::string::npos) << w;
        EXPECT_NE(w.find("theta"), std::string::npos) << w;
        EXPECT_NE(w.find("compound motor group 'energy' knows th, tth, dd, L"), std::string::npos) << w;
    }
    auto bad_inverse = energy_group();
    bad_inverse.inverse[1].second = "2 * (E";
    try {
        CompoundMotors cm({bad_inverse}, "V:", db);
        FAIL() << "accepted a syntax error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("test.yaml:8:1: inverse of tth"), std::string::npos) << e.what();
    }
}

TEST(CompoundMotor, ARealThatIsNotAMotorRecordIsAnError) {
    auto g = energy_group();
    g.reals[2].pv = "T:L"; // an ao
    pv::Database db;
    db.load(pv::parse_db(kMotors, "motors.db", {}));
    CompoundMotors cm({g}, "V:", db);
    db.init_records();
    try {
        cm.start();
        FAIL() << "accepted an ao as a motor";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("test.yaml:4:1: compound motor group 'energy': real 'dd': 'T:L' is not a motor record"),
                  std::string::npos)
            << e.what();
    }
}
