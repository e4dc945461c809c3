// The RCP MOTOR object: the driver's commands and sequence numbers, "done after the command"
// without a sequence number in the readback (stale done ignored until motion is seen, the
// acknowledge time-out for moves that never show motion), and the motor record on top of it
// through the bridge: DMOV and put-callback completion, HOMF/STOP/JOG/CNEN, time-outs.
#include "rcp_harness.hpp"

#include "bridge/rcp/motor_driver.hpp"
#include "pv/motor_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {

using OT = ObjectType;
using DT = DataType;
constexpr uint32_t kDone = motor_status::kDone, kMoving = motor_status::kMoving,
                   kEnabled = motor_status::kEnabled, kError = motor_status::kError,
                   kHomed = motor_status::kHomed, kHigh = motor_status::kHighLimit;

struct DriverFixture : ::testing::Test {
    double t = 10;
    std::vector<RcpMotorDriver::Command> sent;
    RcpMotorDriver drv{"m",
                       [this](const RcpMotorDriver::Command& c) {
                           sent.push_back(c);
                           return true;
                       },
                       [this] { return t; }, 0.5};
    void readback(double pos, uint32_t bits, double vel = 0, double err = 0) {
        double v[5] = {pos, vel, double(bits), 0, err};
        drv.on_readback(v, t);
    }
};

} // namespace

TEST_F(DriverFixture, CommandsCarryTheirFieldsAndANewSequenceNumber) {
    readback(1.0, kDone | kEnabled);
    drv.move(5, 2, 10);
    ASSERT_EQ(sent.size(), 1u);
    EXPECT_EQ(sent[0], (RcpMotorDriver::Command{1, 5, 2, 10, 1}));
    drv.stop(20);
    EXPECT_EQ(sent[1], (RcpMotorDriver::Command{2, 1.0, 0, 20, 2}))
        << "target: the position readback";
    drv.home(true, 0.5, 5);
    EXPECT_EQ(sent[2][0], 3);
    drv.home(false, -0.5, 5);
    EXPECT_EQ(sent[3][0], 4);
    EXPECT_EQ(sent[3][2], 0.5) << "speeds are magnitudes";
    drv.move_velocity(-3, 7);
    EXPECT_EQ(sent[4], (RcpMotorDriver::Command{6, 1.0, 3, 7, 5}));
    drv.move_velocity(3, 7);
    EXPECT_EQ(sent[5][0], 5);
    drv.move_velocity(0, 7);
    EXPECT_EQ(sent[6][0], 2) << "a jog at speed 0 is a stop";
    drv.set_closed_loop(false);
    EXPECT_EQ(sent[7][0], 8);
    drv.set_closed_loop(true);
    EXPECT_EQ(sent[8][0], 7);
    EXPECT_EQ(sent[8][4], 9);
    EXPECT_EQ(drv.sequence(), 9u);
    drv.set_position(3);
    EXPECT_EQ(sent.size(), 9u) << "the protocol has no command to redefine the position";
    EXPECT_EQ(drv.status().position, 1.0);
}

TEST_F(DriverFixture, DoneOnlyAfterTheRcpShowedTheMotion) {
    readback(0, kDone | kEnabled);
    EXPECT_TRUE(drv.status().done);
    drv.move(5, 1, 1);
    EXPECT_FALSE(drv.status().done) << "reported at once after the command";
    EXPECT_TRUE(drv.status().moving);
    t += 0.01;
    readback(0, kDone | kEnabled); // sent before the RCP saw the command
    EXPECT_FALSE(drv.status().done);
    EXPECT_EQ(drv.phase(), RcpMotorDriver::Phase::Sent);
    t += 0.01;
    readback(1, kMoving | kEnabled, 1);
    EXPECT_EQ(drv.phase(), RcpMotorDriver::Phase::Acknowledged);
    EXPECT_FALSE(drv.status().done);
    t += 1; // longer than the acknowledge time-out: it no longer matters
    readback(4, kMoving | kEnabled, 1);
    EXPECT_FALSE(drv.status().done);
    readback(5, kDone | kEnabled);
    EXPECT_TRUE(drv.status().done);
    EXPECT_EQ(drv.status().position, 5);
    EXPECT_EQ(drv.phase(), RcpMotorDriver::Phase::Idle);
}

TEST_F(DriverFixture, AMoveThatNeverShowsMotionEndsAfterTheAcknowledgeTimeout) {
    readback(0, kDone | kEnabled);
    drv.move(0, 1, 1); // already there
    t += 0.49;
    readback(0, kDone | kEnabled);
    EXPECT_FALSE(drv.status().done);
    t += 0.01;
    EXPECT_TRUE(drv.status().done)
        << "evaluated on status() too (an RCP that sends on change only)";
    // A refused command: the error bit without motion.
    drv.move(100, 1, 1);
    readback(0, kDone | kEnabled | kError, 0, 1);
    EXPECT_FALSE(drv.status().problem) << "problem bits are not trusted until the command is seen";
    t += 0.5;
    readback(0, kDone | kEnabled | kError, 0, 1);
    auto s = drv.status();
    EXPECT_TRUE(s.done);
    EXPECT_TRUE(s.problem);
    EXPECT_EQ(drv.error_code(), 1);
}

TEST_F(DriverFixture, StopOfAMotorAtRestStartsNoWait) {
    readback(2, kDone | kEnabled);
    drv.stop(1);
    EXPECT_TRUE(drv.status().done);
    drv.set_closed_loop(true);
    EXPECT_TRUE(drv.status().done);
    // A stop during a motion keeps waiting for the end of it.
    drv.move(5, 1, 1);
    readback(3, kMoving | kEnabled, 1);
    drv.stop(1);
    EXPECT_FALSE(drv.status().done);
    readback(3.2, kDone | kEnabled);
    EXPECT_TRUE(drv.status().done);
}

TEST_F(DriverFixture, CommErrorEndsAWait) {
    readback(0, kDone | kEnabled);
    drv.move(5, 1, 1);
    readback(1, kMoving | kEnabled, 1);
    drv.set_comm_error(true);
    auto s = drv.status();
    EXPECT_TRUE(s.comm_error);
    EXPECT_TRUE(s.done) << "the record finishes (with an INVALID alarm) instead of waiting forever";
}

TEST_F(DriverFixture, OfflineRefusesEveryCommandButStopAndKeepsNothing) {
    readback(0, kDone | kEnabled);
    drv.move(5, 1, 1);
    readback(1, kMoving | kEnabled, 1);
    drv.set_comm_error(true);
    auto s = drv.status();
    EXPECT_TRUE(s.done);
    EXPECT_TRUE(s.problem) << "the move in progress failed: no retries, targets := readback";
    drv.move(3, 1, 1);
    drv.home(true, 1, 1);
    drv.move_velocity(2, 1);
    drv.set_closed_loop(false);
    EXPECT_EQ(sent.size(), 1u) << "nothing sent while offline";
    EXPECT_TRUE(drv.status().done) << "a refused command starts no wait";
    drv.stop(1);
    ASSERT_EQ(sent.size(), 2u) << "a stop still goes out";
    EXPECT_EQ(sent[1][0], 2);
    drv.set_comm_error(false);
    readback(1, kDone | kEnabled);
    s = drv.status();
    EXPECT_TRUE(s.done);
    EXPECT_FALSE(s.problem);
    EXPECT_FALSE(s.comm_error);
    EXPECT_EQ(sent.size(), 2u) << "nothing refused is sent later";
    drv.move(3, 1, 1);
    ASSERT_EQ(sent.size(), 3u);
    EXPECT_EQ(sent[2], (RcpMotorDriver::Command{1, 3, 1, 1, 3}));
}

TEST_F(DriverFixture, StatusBitsMapToTheRecordsStatus) {
    EXPECT_TRUE(drv.status().comm_error) << "no readback yet";
    readback(-3, kDone | kEnabled | kHomed | kHigh, -0.5);
    auto s = drv.status();
    EXPECT_FALSE(s.comm_error);
    EXPECT_TRUE(s.homed);
    EXPECT_TRUE(s.high_limit);
    EXPECT_FALSE(s.low_limit);
    EXPECT_TRUE(s.enabled);
    EXPECT_EQ(s.velocity, -0.5);
    EXPECT_FALSE(s.direction_positive);
    double bad[5] = {0, 0, NAN, 0, 0};
    drv.on_readback(bad, t);
    EXPECT_TRUE(drv.status().problem) << "status bits that are not a number are an error";
}

// ------------------------------------------------------------------ the motor record
namespace {

struct MotorFixture : ::testing::Test {
    Harness h;
    double pos = 0;
    uint32_t bits = kDone | kEnabled;
    void SetUp() override {
        h.announce("app", {obj(7, OT::Motor, DT::Float64, "Stage")});
        report();
    }
    void report(double p, uint32_t b, double v = 0) {
        pos = p;
        bits = b;
        report(v);
    }
    void report(double v = 0) {
        h.t += 0.01;
        h.feed(data({{7, OT::Motor, DT::Float64, "Stage", {pos, v, double(bits), 0.001, 0}}}));
    }
    RcpMotorDriver::Command last_command() {
        DataPacket d;
        const DataEntry& e = h.sent_entry(h.sent.size() - 1, d);
        EXPECT_EQ(e.type, OT::Motor);
        EXPECT_EQ(e.count, 5);
        RcpMotorDriver::Command c{};
        for (std::size_t i = 0; i < 5 && i < e.values.size(); ++i) c[i] = e.values[i];
        return c;
    }
};

} // namespace

TEST_F(MotorFixture, PutCallbackCompletesWhenTheRcpReportsDoneAfterTheCommand) {
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
    EXPECT_NEAR(h.get("T:app:Stage_PosErr"), 0.001, 1e-12);
    int done = 0;
    pv::PutStatus status = pv::PutStatus::Failed;
    ASSERT_EQ(h.put("T:app:Stage", 5,
                    [&](pv::PutStatus s) {
                        ++done;
                        status = s;
                    }),
              pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    auto c = last_command();
    EXPECT_EQ(c[0], 1);
    EXPECT_EQ(c[1], 5);
    EXPECT_EQ(c[2], 1) << "VELO";
    EXPECT_EQ(c[3], 2) << "VELO / ACCL [EGU/s^2]";
    EXPECT_EQ(c[4], 1) << "sequence";
    EXPECT_EQ(h.sent[0].to, (Endpoint{kRcpIp, 18066}));
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 0);
    report(0, kDone | kEnabled); // stale: left the RCP before the command arrived
    h.advance(0.1);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 0);
    EXPECT_EQ(done, 0);
    report(2, kMoving | kEnabled, 1);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 0);
    EXPECT_EQ(h.get("T:app:Stage.MOVN"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.RBV"), 2, 1e-9);
    EXPECT_EQ(done, 0);
    report(5, kDone | kEnabled);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.RBV"), 5, 1e-9);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(status, pv::PutStatus::Ok);
    // The next move has the next sequence number.
    ASSERT_EQ(h.put("T:app:Stage", 1), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[4], 2);
}

TEST_F(MotorFixture, NullMoveCompletesAfterTheAcknowledgeTimeout) {
    int done = 0;
    ASSERT_EQ(h.put("T:app:Stage", 0.5, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    // The RCP considers itself at the target and never reports motion.
    for (int i = 0; i < 40; ++i) report(0, kDone | kEnabled);
    EXPECT_EQ(done, 0);
    h.advance(0.2); // 0.6 s after the command
    EXPECT_EQ(done, 1);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
}

TEST_F(MotorFixture, HomeJogStopAndEnable) {
    ASSERT_EQ(h.put("T:app:Stage.HOMF", 1), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[0], 3);
    report(0.5, kMoving | kEnabled, -0.2);
    report(0, kDone | kEnabled | kHomed);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_EQ(h.get("T:app:Stage.HOMF"), 0);
    EXPECT_NE(uint32_t(h.get("T:app:Stage.MSTA")) & (1u << 14), 0u) << "MSTA homed";
    ASSERT_EQ(h.put("T:app:Stage.JOGR", 1), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[0], 6);
    report(-0.1, kMoving | kEnabled, -1);
    ASSERT_EQ(h.put("T:app:Stage.JOGR", 0), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[0], 2);
    report(-0.2, kDone | kEnabled);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    ASSERT_EQ(h.put("T:app:Stage", 3), pv::PutStatus::Ok);
    report(1, kMoving | kEnabled, 1);
    ASSERT_EQ(h.put("T:app:Stage.STOP", 1), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[0], 2);
    report(1.1, kDone | kEnabled);
    EXPECT_EQ(h.get("T:app:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:app:Stage.VAL"), 1.1, 1e-9)
        << "a stopped move takes the readback as target";
    ASSERT_EQ(h.put("T:app:Stage.CNEN", 0), pv::PutStatus::Ok);
    EXPECT_EQ(last_command()[0], 8);
    report(1.1, kDone);
    EXPECT_EQ(h.get("T:app:Stage.CNEN"), 0);
}

TEST_F(MotorFixture, ErrorCodeAndSilence) {
    report(0, kDone | kEnabled | kError);
    h.feed(data(
        {{7, OT::Motor, DT::Float64, "Stage", {0, 0, double(kDone | kEnabled | kError), 0, 42}}}));
    EXPECT_EQ(h.get("T:app:Stage_ErrCode"), 42);
    EXPECT_EQ(h.alarm("T:app:Stage"), "MAJOR/STATE") << "the error bit is a problem";
    int done = 0;
    ASSERT_EQ(h.put("T:app:Stage", 4, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    report(1, kMoving | kEnabled, 1);
    h.advance(3.1);
    EXPECT_EQ(h.alarm("T:app:Stage"), "INVALID/COMM");
    EXPECT_EQ(done, 1) << "a silent RCP ends the wait";
    report(4, kDone | kEnabled);
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
}
