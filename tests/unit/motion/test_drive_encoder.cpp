// Axis building blocks against the simulated terminals, in virtual time: the stepper drive's
// enable bits and the DS402 enable sequence walked through the simulated CiA402 state machine,
// velocity setpoint scaling seen as stage motion, encoders with counter wrap, absolute offset and
// set position, the PID controller, and the DS402 enable timeout.
#include "sim_axis.hpp"
#include "motion/controller.hpp"
#include "motion/drive.hpp"
#include "motion/encoder.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

using namespace beamctl;
using namespace beamctl::motion;
using beamctl::registry::BoundSignal;
using beamctl::motion::test::SimBus;

namespace {

const char* kStepper = R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7041}
stages:
  - {name: x, drive: s1, start: 0}
)";

} // namespace

TEST(Drive, StepperEnablesAndScalesTheVelocity) {
    SimBus b(kStepper);
    DriveParams p;
    p.type = DriveParams::Type::Stepper;
    p.numerator = 10; // 10 mm/s at raw 32768 (2000 full steps/s, 200 steps/rev, 1 mm/rev)
    p.denominator = 32768;
    p.enable_bit = 0;
    p.enabled_bit = 1;
    p.reset_bit = 1;
    p.error_bits = {3, -1, -1};
    Drive d(p, b.m->bind("ec0.s1.driveControl01"), b.m->bind("ec0.s1.driveStatus01"), b.m->bind("ec0.s1.velocitySetpoint01"));
    EncoderParams ep;
    ep.numerator = 1;
    ep.denominator = 12800; // 200 x 64 counts per mm
    ep.bits = 16;
    Encoder enc(ep, b.m->bind("ec0.s1.positionActual01"));
    for (int i = 0; i < 5; ++i) b.cycle([&] { d.step(false, 2.0, true, 0.001); enc.update(0.001); });
    EXPECT_FALSE(d.enabled());
    EXPECT_EQ(d.raw_setpoint(), 0); // nothing while disabled
    int cycles_to_enable = 0;
    while (!d.enabled() && cycles_to_enable < 10) {
        b.cycle([&] { d.step(true, 0.0, true, 0.001); enc.update(0.001); });
        ++cycles_to_enable;
    }
    EXPECT_TRUE(d.enabled());
    EXPECT_LE(cycles_to_enable, 3); // command out, status back next cycle
    // 2 mm/s for 2 s: the 16-bit counter wraps (51200 counts/s) and the encoder follows it.
    for (int i = 0; i < 2000; ++i) b.cycle([&] { d.step(true, 2.0, false, 0.001); enc.update(0.001); });
    EXPECT_NEAR(d.raw_setpoint(), 2.0 * 32768 / 10, 1);
    EXPECT_NEAR(enc.velocity(), 2.0, 0.01);
    EXPECT_NEAR(enc.position(), b.plant->find_stage("x")->position() - 0.002, 0.002); // 1 cycle behind
    EXPECT_GT(enc.position(), 3.9); // beyond 65536 counts: the wrap was tracked
    // Drive error: latched by the terminal, reported, and cleared by reset.
    b.plant->find_stage("x")->drive()->inject_fault();
    for (int i = 0; i < 3; ++i) b.cycle([&] { d.step(true, 0.0, false, 0.001); });
    EXPECT_TRUE(d.error());
    EXPECT_FALSE(d.enabled());
    d.reset();
    for (int i = 0; i < 5; ++i) b.cycle([&] { d.step(true, 0.0, false, 0.001); });
    EXPECT_FALSE(d.error());
    EXPECT_TRUE(d.enabled());
}

TEST(Drive, Ds402WalksTheStateMachineAndResetsFaults) {
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7211}
stages:
  - {name: r, drive: s1, pitch: 360, quick_stop_decel: 720}
)");
    DriveParams p;
    p.type = DriveParams::Type::Ds402;
    p.numerator = 8000 * 360.0; // deg/s at 2^31 (ecmccfg EL7211 example scaling)
    p.denominator = 2147483648.0;
    Drive d(p, b.m->bind("ec0.s1.driveControl01"), b.m->bind("ec0.s1.driveStatus01"), b.m->bind("ec0.s1.velocitySetpoint01"));
    int n = 0;
    while (!d.enabled() && n < 20) {
        b.cycle([&] { d.step(true, 0.0, false, 0.001); });
        ++n;
    }
    ASSERT_TRUE(d.enabled()) << "control word " << d.control_word();
    EXPECT_EQ(d.control_word(), 0x0F);
    for (int i = 0; i < 1000; ++i) b.cycle([&] { d.step(true, 90.0, false, 0.001); });
    EXPECT_NEAR(b.plant->find_stage("r")->velocity(), 90.0, 1e-3);
    // Fault: reported, disables; reset (bit 7 edge) and the sequence runs again.
    b.plant->find_stage("r")->drive()->inject_fault();
    for (int i = 0; i < 300; ++i) b.cycle([&] { d.step(true, 90.0, false, 0.001); });
    EXPECT_TRUE(d.error());
    EXPECT_FALSE(d.enabled());
    d.reset();
    n = 0;
    while (!d.enabled() && n < 20) {
        b.cycle([&] { d.step(true, 0.0, false, 0.001); });
        ++n;
    }
    EXPECT_TRUE(d.enabled());
    // Disable: shutdown, the drive leaves OPERATION ENABLED.
    for (int i = 0; i < 3; ++i) b.cycle([&] { d.step(false, 0.0, false, 0.001); });
    EXPECT_FALSE(d.enabled());
    EXPECT_EQ(b.m->get(*b.m->find_signal("ec0.s1.driveStatus01")) & 0x6F, 0x21u);
}

TEST(Drive, Ds402EnableTimesOut) {
    // A status word that never reaches OPERATION ENABLED (a plain register, no drive behind it).
    uint8_t image[8] = {};
    BoundSignal cw{image, 0, 16, false, -1}, sw{image, 16, 16, false, -1}, sp{image, 32, 32, true, -1};
    DriveParams p;
    p.type = DriveParams::Type::Ds402;
    p.enable_timeout = 15;
    Drive d(p, cw, sw, sp);
    sw.set(0x40); // switch on disabled, forever
    for (int i = 0; i < 14999; ++i) d.step(true, 0, false, 0.001);
    EXPECT_FALSE(d.timed_out());
    EXPECT_EQ(d.control_word(), 0x06);
    d.step(true, 0, false, 0.001);
    EXPECT_TRUE(d.timed_out());
    d.reset();
    d.step(false, 0, false, 0.001);
    d.step(false, 0, false, 0.001);
    EXPECT_FALSE(d.timed_out());
}

TEST(Encoder, AbsoluteWithOffsetMaskAndSetPosition) {
    uint8_t image[8] = {};
    BoundSignal raw{image, 0, 32, false, -1};
    EncoderParams p;
    p.absolute = true;
    p.bits = 32;
    p.abs_bits = 20; // 20 valid bits: wraps at 2^20
    p.numerator = 360;
    p.denominator = 1 << 20;
    p.abs_offset = -10;
    Encoder e(p, raw);
    raw.set((1 << 20) - 100 + (5 << 24)); // junk above the valid bits
    e.update(0.001);
    EXPECT_NEAR(e.position(), 360.0 * ((1 << 20) - 100) / (1 << 20) - 10, 1e-9);
    EXPECT_TRUE(e.homed()); // absolute encoders are always referenced
    raw.set(100); // crossed the 20-bit wrap forwards: +200 counts
    e.update(0.001);
    EXPECT_NEAR(e.position(), 360.0 * ((1 << 20) + 100) / (1 << 20) - 10, 1e-9);
    e.set_position(0);
    EXPECT_DOUBLE_EQ(e.position(), 0.0);
    raw.set(300);
    e.update(0.001);
    EXPECT_NEAR(e.position(), 360.0 * 200 / (1 << 20), 1e-9);
}

TEST(Encoder, IncrementalWrapsBackwardsAndFiltersVelocity) {
    uint8_t image[2] = {};
    BoundSignal raw{image, 0, 16, false, -1};
    EncoderParams p;
    p.bits = 16;
    p.filter_size = 4;
    Encoder e(p, raw);
    raw.set(10);
    e.update(0.001);
    EXPECT_FALSE(e.homed());
    for (int i = 1; i <= 10; ++i) { // -5 counts per ms, through 0 to 65535...
        raw.set(uint16_t(10 - 5 * i));
        e.update(0.001);
    }
    EXPECT_EQ(e.counts(), 10 - 50);
    EXPECT_NEAR(e.velocity(), -5000, 1e-9);
}

// ECMC's encoder `lookuptable:` correction: scale * table(x) subtracted once homed; with a range,
// x is the position modulo the range (negative positions wrapped into [0, range)).
TEST(Encoder, LookupTableCorrection) {
    uint8_t image[8] = {};
    BoundSignal raw{image, 0, 32, false, -1};
    EncoderParams p;
    p.bits = 32;
    p.numerator = 1;
    p.denominator = 100; // 0.01 per count
    p.correction = std::make_shared<const LookupTable>(LookupTable::parse("0 0\n5 0.5\n10 0\n", "c.lut"));
    p.correction_scale = 2;
    Encoder e(p, raw);
    raw.set(250);
    e.update(0.001);
    EXPECT_DOUBLE_EQ(e.position(), 2.5); // incremental, not homed: no correction yet
    e.set_homed(true);
    e.update(0.001);
    EXPECT_DOUBLE_EQ(e.position(), 2.5 - 2 * 0.25);
    p.correction_range = 10;
    Encoder r(p, raw);
    r.set_homed(true);
    raw.set(0);
    r.update(0.001);
    raw.set(uint32_t(-750)); // -7.5 (the counter wrapped backwards): 2.5 in the table
    r.update(0.001);
    EXPECT_DOUBLE_EQ(r.position(), -7.5 - 2 * 0.25);
    raw.set(1250); // 12.5 -> 2.5
    r.update(0.001);
    EXPECT_DOUBLE_EQ(r.position(), 12.5 - 2 * 0.25);
}

TEST(Controller, PidWithFeedForwardLimitsAndDeadband) {
    ControllerParams p;
    p.kp = 10;
    p.ki = 100;
    p.kff = 1;
    p.max_output = 50;
    p.min_output = -50;
    p.max_integral = 5;
    p.min_integral = -5;
    Controller c(p);
    EXPECT_DOUBLE_EQ(c.step(0.1, 2.0, 0.001), 10 * 0.1 + 100 * 0.1 * 0.001 + 2.0);
    for (int i = 0; i < 10000; ++i) c.step(0.1, 0.0, 0.001); // integral saturates at 5
    EXPECT_DOUBLE_EQ(c.output(), 1.0 + 5.0);
    EXPECT_DOUBLE_EQ(c.step(100, 0, 0.001), 50); // output limit
    ControllerParams q;
    q.kp = 10;
    q.deadband = 0.01;
    q.deadband_cycles = 3;
    Controller db(q);
    for (int i = 0; i < 3; ++i) EXPECT_DOUBLE_EQ(db.step(0.005, 1.0, 0.001), 0.05 + 1.0);
    EXPECT_DOUBLE_EQ(db.step(0.005, 1.0, 0.001), 1.0); // in the band long enough: feed-forward only
    EXPECT_DOUBLE_EQ(db.step(0.02, 1.0, 0.001), 0.2 + 1.0);
}
