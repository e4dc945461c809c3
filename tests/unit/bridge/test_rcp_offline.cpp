// Machine safety of the RCP bridge in virtual time (issue 11): while an application is offline
// puts to its outputs fail and change nothing, motor commands are refused (never queued, never
// replayed when the machine comes back), a move in progress ends in alarm with its target
// dropped; back online the setpoints take the machine's values once, without sending them; data
// that arrives before a machine's first beacon is counted apart and not logged as malformed.
#include "rcp_harness.hpp"

#include "bridge/rcp/motor_driver.hpp"
#include "core/log.hpp"
#include "pv/motor_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {

using OT = ObjectType;
using DT = DataType;
constexpr uint32_t kDone = motor_status::kDone, kMoving = motor_status::kMoving,
                   kEnabled = motor_status::kEnabled;
constexpr uint32_t kMstaProblem = 1u << 9, kMstaCommErr = 1u << 12; // motor record MSTA bits

std::vector<BeaconObject> outputs() {
    return {obj(1, OT::AI, DT::Float64, "Temp"), obj(2, OT::AO, DT::Float64, "Set"),
            obj(4, OT::BO, DT::Bool, "Valve"), obj(6, OT::LO, DT::Int16, "Mode"),
            obj(9, OT::AO, DT::Float64, "Gains")};
}

// The machine's readbacks of every output of outputs().
Packet readbacks(double set, double valve, double mode, std::vector<double> gains) {
    return data({{1, OT::AI, DT::Float64, "Temp", {20}},
                 {2, OT::AO, DT::Float64, "Set", {set}},
                 {4, OT::BO, DT::Bool, "Valve", {valve}},
                 {6, OT::LO, DT::Int16, "Mode", {mode}},
                 {9, OT::AO, DT::Float64, "Gains", std::move(gains)}});
}

struct Status {
    int calls = 0;
    pv::PutStatus last = pv::PutStatus::Ok;
    pv::PutCallback cb() {
        return [this](pv::PutStatus s) {
            ++calls;
            last = s;
        };
    }
};

} // namespace

TEST(RcpOffline, PutsToOutputsFailAndChangeNothingWhileOffline) {
    Harness h;
    h.announce("app", outputs());
    h.feed(readbacks(2, 1, 3, {1, 2, 3, 4}));
    ASSERT_EQ(h.get("T:app:Set"), 2);
    h.advance(3.1); // silent for longer than timeout_s
    ASSERT_FALSE(h.core->applications()[0].online);
    ASSERT_EQ(h.alarm("T:app:Set"), "INVALID/COMM");

    Status st;
    EXPECT_EQ(h.put("T:app:Set", 5, st.cb()), pv::PutStatus::Failed);
    EXPECT_EQ(st.calls, 1) << "a put-callback completes, with a failure";
    EXPECT_EQ(st.last, pv::PutStatus::Failed);
    EXPECT_EQ(h.get("T:app:Set"), 2) << "the value is unchanged";
    EXPECT_EQ(h.alarm("T:app:Set"), "INVALID/COMM");
    EXPECT_EQ(h.put("T:app:Valve", 0), pv::PutStatus::Failed);
    EXPECT_EQ(h.get("T:app:Valve"), 1);
    EXPECT_EQ(h.put("T:app:Mode", 1), pv::PutStatus::Failed);
    EXPECT_EQ(h.get("T:app:Mode"), 3);
    double gains[4] = {9, 9, 9, 9};
    EXPECT_EQ(h.db.put(h.addr("T:app:Gains"), pv::Prim::Double, gains, 2), pv::PutStatus::Failed);
    EXPECT_EQ(h.get_array("T:app:Gains"), (std::vector<double>{1, 2, 3, 4}))
        << "a refused waveform put changes neither values nor count";
    EXPECT_EQ(h.alarm("T:app:Gains"), "INVALID/COMM");
    EXPECT_TRUE(h.sent.empty()) << "nothing is sent while offline";
    EXPECT_EQ(h.put("T:app:Set.DRVH", 10), pv::PutStatus::Ok) << "only the value is refused";

    // Nothing refused is sent later: the machine comes back, nothing goes out until a new put.
    h.advance(1);
    h.feed(readbacks(2, 1, 3, {1, 2, 3, 4}));
    h.advance(1);
    EXPECT_TRUE(h.sent.empty());
    EXPECT_EQ(h.alarm("T:app:Set"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.put("T:app:Set", 5, st.cb()), pv::PutStatus::Ok);
    EXPECT_EQ(st.last, pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    DataPacket d;
    EXPECT_EQ(h.sent_entry(0, d).values[0], 5);
}

TEST(RcpOffline, SetpointsTakeTheMachinesValuesOnceWhenItComesBack) {
    Harness h;
    h.announce("app", outputs());
    h.feed(readbacks(0, 0, 0, {1, 1, 1, 1}));
    ASSERT_EQ(h.put("T:app:Set", 3), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:app:Valve", 1), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:app:Mode", 2), pv::PutStatus::Ok);
    double gains[4] = {5, 6, 7, 8};
    ASSERT_EQ(h.db.put(h.addr("T:app:Gains"), pv::Prim::Double, gains, 4), pv::PutStatus::Ok);
    h.feed(readbacks(3, 1, 2, {5, 6, 7, 8}));
    std::size_t sent = h.sent.size();
    ASSERT_EQ(sent, 4u);

    // The machine restarts: offline, then back with its initial values.
    h.advance(3.1);
    h.feed(beacon("app", outputs()));
    EXPECT_EQ(h.get("T:app:Set"), 3) << "a beacon carries no values: nothing to take yet";
    h.feed(readbacks(0, 0, 0, {1, 1, 1, 1}));
    EXPECT_EQ(h.get("T:app:Set"), 0);
    EXPECT_EQ(h.get("T:app:Set_RBV"), 0);
    EXPECT_EQ(h.get("T:app:Valve"), 0);
    EXPECT_EQ(h.get("T:app:Mode"), 0);
    EXPECT_EQ(h.get_array("T:app:Gains"), (std::vector<double>{1, 1, 1, 1}));
    EXPECT_EQ(h.alarm("T:app:Set"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.sent.size(), sent) << "taking the readback sends nothing";

    // Once only: after that the setpoint is the operator's again.
    h.feed(readbacks(0.5, 0, 0, {1, 1, 1, 1}));
    EXPECT_EQ(h.get("T:app:Set"), 0);
    EXPECT_EQ(h.get("T:app:Set_RBV"), 0.5);

    // A put after the machine came back, before its first readback, wins over that readback
    // (which may have left the machine before the put arrived).
    h.advance(3.1);
    h.feed(beacon("app", outputs()));
    ASSERT_EQ(h.put("T:app:Set", 4), pv::PutStatus::Ok);
    h.feed(readbacks(0, 0, 3, {1, 1, 1, 1}));
    EXPECT_EQ(h.get("T:app:Set"), 4);
    EXPECT_EQ(h.get("T:app:Mode"), 3) << "the others still take the machine's values";
}

// ------------------------------------------------------------------ motors
namespace {

struct OfflineMotor : ::testing::Test {
    Harness h;
    Status st;
    void SetUp() override {
        h.announce("app", {obj(7, OT::Motor, DT::Float64, "Stage")});
        report(0, kDone | kEnabled);
        // Retries would re-send the move; they must not.
        ASSERT_EQ(h.put("T:app:Stage.RTRY", 3), pv::PutStatus::Ok);
    }
    void report(double pos, uint32_t bits, double vel = 0) {
        h.t += 0.01;
        h.feed(data({{7, OT::Motor, DT::Float64, "Stage", {pos, vel, double(bits), 0, 0}}}));
    }
    uint32_t msta() { return uint32_t(h.get("T:app:Stage.MSTA")); }
    std::vector<double> commands() { // command ([0]) of every packet sent
        std::vector<double> c;
        for (std::size_t i = 0; i < h.sent.size(); ++i) {
            DataPacket d;
            c.push_back(h.sent_entry(i, d).values[0]);
        }
        return c;
    }
};

} // namespace

TEST_F(OfflineMotor, AMoveInProgressEndsInAlarmWithItsTargetDropped) {
    ASSERT_EQ(h.put("T:app:Stage", 5, st.cb()), pv::PutStatus::Ok);
    report(0, kMoving | kEnabled, 1);
    report(2, kMoving | kEnabled, 1);
    ASSERT_EQ(h.get("T:app:Stage.DMOV"), 0);
    h.advance(3.1); // the machine falls silent mid-move
    EXPECT_EQ(st.calls, 1) << "the put-callback completes";
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_EQ(h.alarm("T:app:Stage"), "INVALID/COMM");
    EXPECT_NE(msta() & kMstaProblem, 0u) << "ended as a failure, not a success";
    EXPECT_NE(msta() & kMstaCommErr, 0u);
    EXPECT_NEAR(h.get("T:app:Stage.VAL"), 2, 1e-9) << "the target is dropped: VAL = RBV";
    EXPECT_EQ(commands(), (std::vector<double>{1})) << "no retry was sent";

    // Back, the axis where it stopped: nothing is sent, nothing resumes.
    for (int i = 0; i < 20; ++i) report(2, kDone | kEnabled);
    h.advance(1);
    EXPECT_EQ(commands(), (std::vector<double>{1}));
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.VAL"), 2, 1e-9);
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(msta() & kMstaProblem, 0u);
}

TEST_F(OfflineMotor, CommandsWhileOfflineAreRefusedAndNeverReplayed) {
    h.advance(3.1);
    ASSERT_EQ(h.alarm("T:app:Stage"), "INVALID/COMM");
    ASSERT_EQ(h.put("T:app:Stage", 5, st.cb()), pv::PutStatus::Ok);
    h.advance(0.05);
    EXPECT_EQ(st.calls, 1) << "the move ends at once";
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.VAL"), 0, 1e-9) << "the target is not kept";
    EXPECT_EQ(h.alarm("T:app:Stage"), "INVALID/COMM");
    EXPECT_NE(msta() & kMstaProblem, 0u);
    ASSERT_EQ(h.put("T:app:Stage.HOMF", 1), pv::PutStatus::Ok);
    h.advance(0.05);
    EXPECT_EQ(h.get("T:app:Stage.HOMF"), 0);
    ASSERT_EQ(h.put("T:app:Stage.JOGF", 1), pv::PutStatus::Ok);
    h.advance(0.05);
    ASSERT_EQ(h.put("T:app:Stage.JOGF", 0), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:app:Stage.CNEN", 0), pv::PutStatus::Ok);
    h.advance(0.05);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_TRUE(h.sent.empty()) << "no move, home, jog or enable is sent while offline";
    ASSERT_EQ(h.put("T:app:Stage.STOP", 1), pv::PutStatus::Ok);
    EXPECT_EQ(commands(), (std::vector<double>{2})) << "a stop still goes out";
    std::size_t sent = h.sent.size();

    // The machine comes back: none of it is sent.
    for (int i = 0; i < 20; ++i) report(0, kDone | kEnabled);
    h.advance(2);
    EXPECT_EQ(h.sent.size(), sent);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.RBV"), 0, 1e-9);
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
    // And moves work again.
    ASSERT_EQ(h.put("T:app:Stage", 1), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), sent + 1);
    EXPECT_EQ(commands().back(), 1);
}

TEST_F(OfflineMotor, BackAtAnotherPositionTheTargetFollowsTheReadback) {
    ASSERT_EQ(h.put("T:app:Stage", 5), pv::PutStatus::Ok);
    report(1, kMoving | kEnabled, 1);
    report(5, kDone | kEnabled);
    ASSERT_EQ(h.get("T:app:Stage.DMOV"), 1);
    ASSERT_NEAR(h.get("T:app:Stage.VAL"), 5, 1e-9);
    std::size_t sent = h.sent.size();
    h.advance(3.1);
    report(0, kDone | kEnabled); // restarted at its initial position
    EXPECT_NEAR(h.get("T:app:Stage.RBV"), 0, 1e-9);
    EXPECT_NEAR(h.get("T:app:Stage.VAL"), 0, 1e-9) << "VAL = RBV once back";
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    h.advance(1);
    EXPECT_EQ(h.sent.size(), sent) << "nothing sent";
}

// ------------------------------------------------------------------ data before a beacon
TEST(RcpBridge, DataBeforeTheFirstBeaconIsCountedApartAndLoggedAtDebug) {
    Harness h;
    Packet d = data({{1, OT::AI, DT::Float64, "Temp", {5}}});
    beamctl::log::configure("rcp=warn");
    testing::internal::CaptureStderr();
    for (int i = 0; i < 10; ++i) {
        h.feed(d);
        h.advance(0.1);
    }
    std::string warn_text = testing::internal::GetCapturedStderr();
    EXPECT_EQ(h.core->totals().before_beacon, 10u);
    for (uint64_t n : h.core->totals().malformed) EXPECT_EQ(n, 0u) << "not malformed";
    EXPECT_EQ(warn_text.find("rcp"), std::string::npos) << "nothing at warn: " << warn_text;
    h.advance(1);
    EXPECT_EQ(h.get("T:DataBeforeBeacon"), 10);
    EXPECT_EQ(h.get("T:Malformed-UnknownApplication"), 0);

    beamctl::log::configure("rcp=debug");
    testing::internal::CaptureStderr();
    h.t += 5; // a new episode
    h.feed(d);
    std::string debug_text = testing::internal::GetCapturedStderr();
    EXPECT_NE(debug_text.find("debug rcp: data from 10.0.0.2:5000 before any beacon"),
              std::string::npos)
        << debug_text;

    // Going on for timeout_s without a beacon: at warn (its beacons may go elsewhere).
    beamctl::log::configure("rcp=warn");
    testing::internal::CaptureStderr();
    for (int i = 0; i < 50; ++i) {
        h.t += 0.1;
        h.feed(d);
    }
    warn_text = testing::internal::GetCapturedStderr();
    beamctl::log::configure(); // back to BEAMCTL_LOG
    EXPECT_NE(warn_text.find("warn  rcp: data from 10.0.0.2:5000 before any beacon"),
              std::string::npos)
        << warn_text;
    EXPECT_NE(warn_text.find("are its beacons sent to udp port 18065?"), std::string::npos)
        << warn_text;

    // The beacon arrives: the same data is accepted.
    h.announce("app", {obj(1, OT::AI, DT::Float64, "Temp")});
    h.feed(d);
    EXPECT_EQ(h.get("T:app:Temp"), 5);
    EXPECT_EQ(h.core->totals().before_beacon, 61u);
}
