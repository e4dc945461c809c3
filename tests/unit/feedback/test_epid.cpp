// The EPID step (src/feedback/epid.cpp) and the epid record with soft device support
// (src/feedback/epid_record.cpp): std's devEpidSoft.c term by term, run in virtual time (the
// database clock is set by the test).
#include "feedback/epid.hpp"
#include "feedback/epid_record.hpp"

#include "../pv/db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using namespace beamctl::feedback;

namespace {

EpidInput gains(double kp, double ki, double kd, double drvl = -10, double drvh = 10) {
    EpidInput in;
    in.kp = kp, in.ki = ki, in.kd = kd, in.drvl = drvl, in.drvh = drvh;
    in.fbon = in.fbop = true;
    in.dt = 0.01;
    return in;
}

} // namespace

TEST(EpidStep, PIDTermsAsTheRecordDefinesThem) {
    EpidInput in = gains(2, 0.5, 0.1);
    in.setpoint = 1, in.cval = 0.25;
    EpidTerms t;
    t.err = 0.5; // the previous error
    t.i = 0.3;
    const double out = epid_step(in, t);
    EXPECT_DOUBLE_EQ(t.err, 0.75);
    EXPECT_DOUBLE_EQ(t.p, 2 * 0.75);
    EXPECT_DOUBLE_EQ(t.i, 0.3 + 2 * 0.5 * 0.75 * 0.01);
    EXPECT_DOUBLE_EQ(t.d, 2 * 0.1 * (0.75 - 0.5) / 0.01);
    EXPECT_DOUBLE_EQ(out, t.p + t.i + t.d);
    EXPECT_DOUBLE_EQ(t.cval, 0.25);
}

TEST(EpidStep, TheOutputIsClampedAndKIZeroClearsTheIntegral) {
    EpidInput in = gains(100, 0, 0, -1, 2);
    in.setpoint = 1;
    EpidTerms t;
    t.i = 0.7;
    EXPECT_DOUBLE_EQ(epid_step(in, t), 2);
    EXPECT_EQ(t.i, 0);
    in.setpoint = -1;
    EXPECT_DOUBLE_EQ(epid_step(in, t), -1);
}

TEST(EpidStep, TheIntegralDoesNotWindUpAtTheDriveLimit) {
    // A plant that cannot follow (the output saturates at 1 while the error stays 1): I stops at
    // the limit instead of growing, so the loop leaves the limit as soon as the error turns.
    EpidInput in = gains(1, 10, 0, -1, 1);
    EpidTerms t;
    in.setpoint = 1, in.cval = 0;
    for (int k = 0; k < 1000; ++k) t.oval = epid_step(in, t); // 10 s against the limit
    EXPECT_DOUBLE_EQ(t.oval, 1);
    EXPECT_LE(t.i, 1); // clamped to DRVH, not 1000 * KP*KI*e*dt = 100
    // The error reverses: at the high limit dI < 0 is taken at once.
    in.setpoint = 0, in.cval = 0.5;
    const double before = t.i;
    t.oval = epid_step(in, t);
    EXPECT_LT(t.i, before);
    EXPECT_LT(t.oval, 1);
    // While the output sits at the limit a growing dI is refused.
    EpidTerms u;
    u.oval = 1, u.i = 0.5;
    in.setpoint = 1, in.cval = 0;
    epid_step(in, u);
    EXPECT_DOUBLE_EQ(u.i, 0.5);
}

TEST(EpidStep, FeedbackOnStartsTheIntegralAtTheOutputReadback) {
    EpidInput in = gains(1, 1, 0);
    in.setpoint = 3, in.cval = 3; // no error: the output must not move at all
    in.fbon = true, in.fbop = false;
    in.have_readback = true, in.readback = 4.25;
    EpidTerms t;
    t.i = -7; // what an earlier run left
    EXPECT_DOUBLE_EQ(epid_step(in, t), 4.25);
    EXPECT_DOUBLE_EQ(t.i, 4.25);
    // Feedback off: I is frozen whatever the error.
    in.fbon = false, in.fbop = false, in.cval = 0;
    epid_step(in, t);
    EXPECT_DOUBLE_EQ(t.i, 4.25);
}

TEST(EpidStep, MaxMinStepsTowardsTheMaximum) {
    // cval = -(u - 2)^2: KP > 0 climbs to u = 2 and then dithers around it by KP.
    EpidInput in = gains(0.1, 0, 0, -10, 10);
    in.mode = EpidMode::MaxMin;
    in.fbon = true, in.fbop = false, in.have_readback = true, in.readback = 0;
    EpidTerms t;
    in.cval = -4;
    t.oval = epid_step(in, t);
    in.fbop = true;
    for (int k = 0; k < 60; ++k) {
        in.cval = -(t.oval - 2) * (t.oval - 2);
        t.oval = epid_step(in, t);
    }
    EXPECT_NEAR(t.oval, 2, 0.21);
}

// ---------------------------------------------------------------- the record, soft device support

namespace {

// A first-order plant made of records: the epid's OUTL drives "u"; "y" = GAIN*u + OFFSET.
struct EpidRecordTest : pv::DbTest {
    double now = 0;
    void SetUp() override {
        register_feedback_records(pv::RecordTypes::global());
        db.set_clock([this] { return now; });
    }
    // Advances virtual time by n steps of 0.1 s, letting periodic scanning run.
    void run(int n) {
        for (int k = 0; k < n; ++k) {
            now += 0.1;
            db.scan_periodic(now);
        }
    }
    static constexpr const char* kPlant = R"(
        record(ao, "u") { field(DRVH, "100") field(DRVL, "-100") }
        record(calc, "y") { field(INPA, "u NPP") field(INPB, "2") field(INPC, "0.5") field(CALC, "B*A+C") }
    )";
};

} // namespace

TEST_F(EpidRecordTest, HoldsTheSetpointThroughLinks) {
    load((std::string(kPlant) + R"(
        record(epid, "pid") {
            field(SCAN, ".1 second") field(INP, "y PP") field(OUTL, "u PP")
            field(KP, "0.2") field(KI, "2") field(DRVH, "10") field(DRVL, "-10") field(VAL, "3")
            field(PREC, "3") field(EGU, "mm") field(HOPR, "5") field(LOPR, "-5")
        })").c_str());
    ASSERT_EQ(put("pid.FBON", 1), pv::PutStatus::Ok);
    run(200);
    EXPECT_NEAR(getd("pid.CVAL"), 3, 1e-3);
    EXPECT_NEAR(getd("u"), 1.25, 1e-3); // 2*1.25 + 0.5 = 3
    EXPECT_NEAR(getd("pid.DT"), 0.1, 1e-9);
    EXPECT_EQ(gets("pid.SEVR"), "NO_ALARM");
    // A new setpoint is followed.
    ASSERT_EQ(put("pid", -2), pv::PutStatus::Ok);
    run(200);
    EXPECT_NEAR(getd("y"), -2, 1e-3);
    // Feedback off: the output stays where it was, CVAL still read.
    ASSERT_EQ(put("pid.FBON", 0), pv::PutStatus::Ok);
    const double u = getd("u");
    ASSERT_EQ(put("pid", 4), pv::PutStatus::Ok);
    run(20);
    EXPECT_DOUBLE_EQ(getd("u"), u);
    EXPECT_NEAR(getd("pid.ERR"), 4 - getd("pid.CVAL"), 1e-9);
}

TEST_F(EpidRecordTest, FeedbackOnIsBumpless) {
    load((std::string(kPlant) + R"(
        record(epid, "pid") {
            field(SCAN, ".1 second") field(INP, "y PP") field(OUTL, "u PP")
            field(KP, "0.2") field(KI, "2") field(DRVH, "10") field(DRVL, "-10") field(VAL, "6.5")
        })").c_str());
    ASSERT_EQ(put("u", 3), pv::PutStatus::Ok); // y = 6.5: already at the setpoint
    run(5);
    EXPECT_DOUBLE_EQ(getd("u"), 3);
    ASSERT_EQ(put("pid.FBON", 1), pv::PutStatus::Ok);
    run(1);
    EXPECT_DOUBLE_EQ(getd("pid.I"), 3); // from the output's readback
    EXPECT_DOUBLE_EQ(getd("pid.OVAL"), 3);
    EXPECT_DOUBLE_EQ(getd("u"), 3);
    EXPECT_EQ(getd("pid.FBOP"), 1);
}

TEST_F(EpidRecordTest, MinimumDeltaTAndOutputDeadband) {
    load(R"(
        record(ao, "y") { }
        record(epid, "pid") { field(INP, "y") field(MDT, "0.25") field(ODEL, "0.5")
                              field(KP, "1") field(DRVH, "10") field(DRVL, "-10") field(VAL, "1") })");
    ASSERT_EQ(put("pid.FBON", 1), pv::PutStatus::Ok);
    auto step = [&](double t, double y) {
        now = t;
        ASSERT_EQ(put("y", y), pv::PutStatus::Ok);
        db.process(*db.find("pid"));
    };
    step(1.0, 0); // the first step computes (no dt yet)
    EXPECT_DOUBLE_EQ(getd("pid.OVAL"), 1);
    step(1.1, 0.9); // 0.1 s < MDT: CVAL is read, the step skipped
    EXPECT_DOUBLE_EQ(getd("pid.CVAL"), 0.9);
    EXPECT_DOUBLE_EQ(getd("pid.OVAL"), 1);
    EXPECT_DOUBLE_EQ(getd("pid.DT"), 0);
    step(1.5, 0.9); // 0.5 s: taken; OVAL moves by 0.9 > ODEL
    EXPECT_DOUBLE_EQ(getd("pid.DT"), 0.5);
    EXPECT_NEAR(getd("pid.OVAL"), 0.1, 1e-12);
    step(2.0, 0.6); // P = 0.4: OVAL would move by 0.3 <= ODEL, and stays
    EXPECT_NEAR(getd("pid.P"), 0.4, 1e-12);
    EXPECT_NEAR(getd("pid.OVAL"), 0.1, 1e-12);
}

TEST_F(EpidRecordTest, MetadataFollowsTheRecord) {
    load(R"(record(epid, "pid") { field(HOPR, "5") field(LOPR, "-5") field(DRVH, "2") field(DRVL, "-1")
                                  field(EGU, "um") field(PREC, "4") field(HIHI, "4") })");
    pv::Address a = addr("pid.OVAL");
    pv::Metadata md;
    a.rec->metadata(*a.field, md);
    EXPECT_EQ(md.ctrl_hi, 2);
    EXPECT_EQ(md.ctrl_lo, -1);
    EXPECT_STREQ(md.units, "um");
    EXPECT_EQ(md.precision, 4);
    a = addr("pid");
    a.rec->metadata(*a.field, md);
    EXPECT_EQ(md.disp_hi, 5);
    EXPECT_EQ(md.ctrl_lo, -5);
    EXPECT_EQ(md.alarm_hihi, 4);
}

TEST_F(EpidRecordTest, NoInputIsASoftAlarmAndFastNeedsALoop) {
    load(R"(record(epid, "pid") { field(VAL, "1") field(KP, "1") })");
    db.process(*db.find("pid"));
    EXPECT_EQ(gets("pid.STAT"), "SOFT");
    EXPECT_EQ(gets("pid.SEVR"), "INVALID");
    EXPECT_NE(load_error(R"(record(epid, "f") { field(DTYP, "Fast Epid") field(INP, "5") })").find("needs INP \"@<loop>\""),
              std::string::npos);
    EXPECT_NE(load_error(R"(record(epid, "f") { field(FMOD, "Bang-bang") })").find("FMOD"), std::string::npos);
}

TEST_F(EpidRecordTest, AsyncSoftChannelTriggersTheReadbackFirst) {
    load(R"(
        record(ao, "trig") { field(FLNK, "y") }
        record(calc, "y") { field(INPA, "trig") field(CALC, "A*10") }
        record(epid, "pid") { field(DTYP, "Async Soft Channel") field(TRIG, "trig PP") field(TVAL, "0.7")
                              field(INP, "y") field(VAL, "1") field(KP, "1") }
    )");
    db.process(*db.find("pid"));
    EXPECT_DOUBLE_EQ(getd("pid.CVAL"), 7);
}
