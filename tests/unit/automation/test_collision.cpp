// Collision zones (automation/collision.hpp) in virtual time on simulated motor records: a move
// whose path crosses the forbidden region is refused before the motor starts (also one computed
// with the other axis at its moving target), a move around it is accepted, a jog towards it is
// stopped before the axes are inside, and the expression is checked at start-up.
#include "automation/collision.hpp"

#include "db_rig.hpp"

#include "core/error.hpp"
#include "pv/db_file.hpp"
#include "pv/motor_record.hpp"
#include "pv/publish.hpp"

#include <gtest/gtest.h>

#include <optional>

using namespace beamctl;
using namespace beamctl::automation;

namespace {

const char* kMotors = R"(
record(motor, "T:l") { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "50") field(ACCL, "0.2") field(JVEL, "50") field(DHLM, "700") field(DLLM, "0") }
record(motor, "T:x") { field(MRES, "0.001") field(RDBD, "0.001") field(VELO, "20") field(ACCL, "0.2") field(DHLM, "100") field(DLLM, "-100") }
)";

config::CollisionZoneEntry zone() {
    config::CollisionZoneEntry z;
    z.name = "table", z.where = "t.yaml:1:1";
    z.axes = {{"l", "T:l"}, {"x", "T:x"}};
    z.forbidden = "l > 500 and x > 40";
    z.lookahead_s = 0.2;
    return z;
}

struct Rig : test::DbRig {
    std::unique_ptr<CollisionZones> cz;
    Rig() {
        db.load(pv::parse_db(kMotors, "m.db", {}));
        cz = std::make_unique<CollisionZones>(std::vector<config::CollisionZoneEntry>{zone()}, "Z:", db, [this] { return now; });
        for (const char* m : {"T:l", "T:x"}) pv::MotorRecord::from(db.find(m))->set_clock([this] { return now; });
        db.init_records();
        cz->start();
        poll = [this] { cz->poll(); };
        run(0.2);
    }
    void move(const std::string& m, double x, double seconds = 30) {
        ASSERT_EQ(put(m, x), pv::PutStatus::Ok) << m;
        run(seconds);
    }
};

} // namespace

TEST(CollisionZone, AMoveIntoTheRegionIsRefusedBeforeTheMotorStarts) {
    Rig r;
    r.move("T:x", 60, 5); // arm in: fine while l = 0
    ASSERT_NEAR(r.get("T:x.RBV"), 60, 1e-3);
    EXPECT_EQ(r.put("T:l", 600), pv::PutStatus::Failed);
    r.run(1.0);
    EXPECT_EQ(r.get("T:l.RBV"), 0);
    EXPECT_EQ(r.get("T:l.VAL"), 0); // the refused value is not kept
    EXPECT_EQ(r.get("Z:table:Refused"), 1);
    EXPECT_EQ(pv::get_text(*r.db.find("Z:table:Message")),
              "move of T:l to 600 refused: it would enter collision zone 'table' (l > 500 and x > 40) at l 501, x 60");
    r.move("T:l", 450, 15); // short of it: fine
    EXPECT_NEAR(r.get("T:l.RBV"), 450, 1e-3);
    EXPECT_EQ(r.put("T:l.RLV", 100), pv::PutStatus::Failed); // relative, into it
    EXPECT_EQ(r.get("Z:table:Refused"), 2);
}

TEST(CollisionZone, APathAroundTheRegionIsAcceptedAndOneThroughItIsNot) {
    Rig r;
    r.move("T:l", 600, 20); // far out with the arm out: fine
    ASSERT_NEAR(r.get("T:l.RBV"), 600, 1e-3);
    EXPECT_EQ(r.put("T:x", 60), pv::PutStatus::Failed); // the arm in there: inside
    EXPECT_EQ(r.get("T:x.RBV"), 0);
    r.move("T:x", 40, 5); // up to the edge (x > 40 is forbidden)
    EXPECT_NEAR(r.get("T:x.RBV"), 40, 1e-3);
    EXPECT_EQ(r.get("Z:table:Inside"), 0);
}

TEST(CollisionZone, AMoveIsJudgedWithTheOtherAxisAtItsTarget) {
    Rig r;
    ASSERT_EQ(r.put("T:x", 60), pv::PutStatus::Ok); // moving in (3 s)
    r.run(0.5);
    EXPECT_EQ(r.put("T:l", 600), pv::PutStatus::Failed); // where x is going, l may not go
    r.run(5);
    EXPECT_EQ(r.get("T:l.RBV"), 0);
}

TEST(CollisionZone, AJogTowardsTheRegionIsStoppedBeforeTheAxesAreInside) {
    Rig r;
    r.move("T:x", 60, 5);
    r.move("T:l", 400, 15);
    ASSERT_EQ(r.put("T:l.JOGF", 1), pv::PutStatus::Ok); // not a target: only the motion tells
    r.run(5);
    r.put("T:l.JOGF", 0);
    r.run(1);
    EXPECT_LT(r.get("T:l.RBV"), 500);
    EXPECT_GT(r.get("T:l.RBV"), 450); // it went most of the way
    EXPECT_EQ(r.get("T:l.DMOV"), 1);
    EXPECT_EQ(r.get("Z:table:Stopped"), 1);
    EXPECT_EQ(r.get("Z:table:Inside"), 0);
    EXPECT_EQ(r.cz->stopped(), 1u);
}

TEST(CollisionZone, BadConfigurationIsRefusedNamingWhere) {
    pv::Database db;
    db.load(pv::parse_db(kMotors + std::string("record(ao, \"T:y\") {}\n"), "m.db", {}));
    auto bad = zone();
    bad.forbidden = "l > 500 and z > 40";
    try {
        CollisionZones cz({bad}, "Z:", db, [] { return 0.0; });
        FAIL() << "accepted an unknown name";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("t.yaml:1:1: collision zone 'table':"), std::string::npos) << e.what();
    }
    auto not_motor = zone();
    not_motor.axes[1].second = "T:y";
    CollisionZones cz({not_motor}, "Z:", db, [] { return 0.0; });
    db.init_records();
    try {
        cz.start();
        FAIL() << "accepted an ao";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("axis 'x': 'T:y' is not a motor record of this IOC"), std::string::npos) << e.what();
    }
}
