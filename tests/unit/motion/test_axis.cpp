// The axis against a simulated stepper stage (EL7041 + EL1008 switches), in virtual time: the
// ECMC acceptance behaviours of specs/ecmc.md — move timing (3), lag error then disable (4), hard
// limits (5), soft limits (6), homing on the low limit and home switch with post-move (7), set
// position (8), bus loss (12) — plus command refusal and retargeting.
// GCC 12 reports a false -Wrestrict inside std::string assignment at -O2 (GCC bug 105329).
#pragma GCC diagnostic ignored "-Wrestrict"
#include "motion/axis.hpp"

#include "sim_axis.hpp"

#include <gtest/gtest.h>

#include <functional>

#include <cmath>

using namespace beamctl;
using namespace beamctl::motion;
using beamctl::motion::test::SimBus;

namespace {

// Stage: travel [-60, 60] mm, limit switches at +-50 (normally closed), home cam at -30 +- 0.5.
const char* kPlant = R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL1008}
  - {position: 2, type: EL7041}
stages:
  - name: x
    drive: s2
    travel: [-60, 60]
    start: 0
    max_force: 500
    limits:
      forward: {input: s1.binaryInput01, at: 50}
      backward: {input: s1.binaryInput02, at: -50}
    home: {input: s1.binaryInput03, at: -30, width: 1}
)";

AxisParams stepper_params() {
    AxisParams p;
    p.id = 1;
    p.name = "X";
    p.encoder.numerator = 1;
    p.encoder.denominator = 12800; // 200 steps x 64 per mm
    p.encoder.bits = 16;
    p.drive.type = DriveParams::Type::Stepper;
    p.drive.numerator = 10; // 10 mm/s at 32768 (2000 full steps/s, 1 mm/rev)
    p.drive.denominator = 32768;
    p.drive.enable_bit = 0;
    p.drive.enabled_bit = 1;
    p.drive.reset_bit = 1;
    p.drive.error_bits = {3, -1, -1};
    p.controller.kp = 10;
    p.controller.kff = 1;
    p.trajectory = {5, 10, 10, 0}; // 5 mm/s, 10 mm/s^2, trapezoid
    p.emergency_deceleration = 100;
    p.target_enable = true;
    p.target_tolerance = 0.01;
    p.target_time_cycles = 10;
    p.lag_enable = true;
    p.lag_tolerance = 0.5;
    p.lag_time_cycles = 10;
    p.homing_velocity_to = 8;
    p.homing_velocity_from = 2;
    return p;
}

// The signals of a stepper/servo axis on drive slave `drv` (its own encoder input), plus the
// bus status; switches and interlock are set by the caller.
AxisIo drive_io(SimBus& b, int drv) {
    std::string s = "ec0.s" + std::to_string(drv) + ".";
    AxisIo io;
    io.encoder = b.m->bind(s + "positionActual01");
    io.drive_control = b.m->bind(s + "driveControl01");
    io.drive_status = b.m->bind(s + "driveStatus01");
    io.drive_setpoint = b.m->bind(s + "velocitySetpoint01");
    io.bus_status = b.m->bind("ec0.masterstatus");
    io.slave_valid.push_back(b.m->bind(s + "valid"));
    return io;
}

AxisIo switch_io(SimBus& b) {
    AxisIo io = drive_io(b, 2);
    io.limit_fwd = b.m->bind("ec0.s1.binaryInput01");
    io.limit_bwd = b.m->bind("ec0.s1.binaryInput02");
    io.home = b.m->bind("ec0.s1.binaryInput03");
    io.slave_valid.push_back(b.m->bind("ec0.s1.valid"));
    return io;
}

struct AxisBus {
    SimBus b{kPlant};
    Axis ax;
    double dt = 0.001;
    explicit AxisBus(AxisParams p = stepper_params())
        : ax(p, switch_io(b)) {
        cycles(3);
    }
    // With signals added to the usual ones (signals the test itself plays the other end of).
    AxisBus(AxisParams p, const std::function<void(AxisIo&)>& more)
        : ax(p, [&] {
              AxisIo io = switch_io(b);
              more(io);
              return io;
          }()) {
        cycles(3);
    }
    void cycles(int n) {
        for (int i = 0; i < n; ++i) b.cycle([&] { ax.run(dt); });
    }
    // Runs until `done` or `max` cycles; returns the cycles it took.
    template <class F>
    int until(F&& done, int max = 100000) {
        int n = 0;
        while (!done() && n < max) {
            cycles(1);
            ++n;
        }
        return n;
    }
    uint32_t cmd(CommandType t, double pos = 0, double vel = 0, uint64_t tag = 0) {
        AxisCommand c;
        c.type = t;
        c.position = pos;
        c.velocity = vel;
        c.tag = tag;
        return ax.command(c);
    }
    void enable() {
        AxisCommand c;
        c.type = CommandType::Power;
        c.on = true;
        (void)ax.command(c);
        until([&] { return ax.status().enabled; }, 100);
    }
    double stage() { return b.plant->find_stage("x")->position(); }
};

} // namespace

TEST(Axis, MoveAbsoluteTakesTheTrapezoidTimeAndEndsAtTarget) {
    AxisBus a;
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, 10, 0, 7), error_id::kNotEnabled);
    EXPECT_EQ(a.ax.status().done_tag, 7u); // a refused command is finished at once
    EXPECT_EQ(a.ax.status().error_id, error_id::kNotEnabled); // and latched (enabling resets it)
    a.enable();
    ASSERT_TRUE(a.ax.status().enabled);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 10, 0, 8), 0u);
    EXPECT_TRUE(a.ax.status().busy);
    int n = a.until([&] { return !a.ax.status().busy; });
    EXPECT_NEAR(n * 0.001, 2.5, 0.003); // 10 mm at 5 mm/s with 10 mm/s^2: 2.5 s (acceptance 3)
    EXPECT_EQ(a.ax.status().done_tag, 8u);
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 10.0);
    n = a.until([&] { return a.ax.status().at_target; }, 2000);
    EXPECT_LT(n, 2000);
    EXPECT_NEAR(a.ax.status().act_pos, 10.0, 0.01);
    EXPECT_NEAR(a.stage(), 10.0, 0.01);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    uint32_t stat = a.ax.status().stat_word();
    EXPECT_EQ(stat & 0x3, 0x3u);       // enable, enabled
    EXPECT_EQ(stat & (1u << 4), 1u << 4); // at target
    EXPECT_EQ(stat & 0xC0, 0xC0u);     // both limits OK
}

TEST(Axis, RelativeMovesAndRetargetingMidMove) {
    AxisBus a;
    a.enable();
    ASSERT_EQ(a.cmd(CommandType::MoveRelative, 5, 0, 1), 0u);
    a.cycles(500);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, -5, 0, 2), 0u); // reverse while moving
    EXPECT_EQ(a.ax.status().done_tag, 1u);                      // the first one was superseded
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_EQ(a.ax.status().done_tag, 2u);
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, -5.0);
    a.until([&] { return a.ax.status().at_target; }, 2000);
    EXPECT_NEAR(a.stage(), -5.0, 0.01);
}

TEST(Axis, LagErrorAfterTimeThenDisableAtTwiceTheTime) {
    // Acceptance 4: tolerance 0.5, time 10 cycles. The drive is limited to a small force and a
    // big friction makes it stall; the setpoint moves on.
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7041}
stages:
  - {name: x, drive: s1, friction: 400, max_force: 100}
)");
    Axis ax(stepper_params(), drive_io(b, 1));
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    for (int i = 0; i < 10; ++i) b.cycle([&] { ax.run(0.001); });
    ASSERT_TRUE(ax.status().enabled);
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 20}), 0u);
    int first_error = -1, disabled = -1, lag_start = -1;
    for (int i = 0; i < 3000 && disabled < 0; ++i) {
        b.cycle([&] { ax.run(0.001); });
        if (lag_start < 0 && std::fabs(ax.status().pos_err) > 0.5) lag_start = i;
        if (first_error < 0 && ax.status().error_id == error_id::kLag) first_error = i;
        if (first_error >= 0 && !ax.status().enable_cmd) disabled = i;
    }
    ASSERT_GE(lag_start, 0);
    ASSERT_GE(first_error, 0);
    EXPECT_EQ(first_error - lag_start, 10); // error and stop on the 11th cycle over tolerance
    EXPECT_EQ(disabled - lag_start, 19);    // drive disabled on the 20th (2 x time)
}

TEST(Axis, HardLimitsBlockOnlyTheirDirection) {
    AxisBus a;
    a.enable();
    ASSERT_EQ(a.cmd(CommandType::MoveVelocity, 0, 8), 0u);
    a.until([&] { return !a.ax.status().busy; }, 10000);
    EXPECT_TRUE(a.ax.status().limit_fwd); // stopped on the forward switch (acceptance 5)
    EXPECT_EQ(a.ax.status().warning_id, error_id::kHardLimitFwd);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_GT(a.stage(), 50.0);
    EXPECT_LT(a.stage(), 60.0); // stopped before the hard stop
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, 55), error_id::kHardLimitFwd);
    EXPECT_EQ(a.cmd(CommandType::MoveVelocity, 0, 1), error_id::kHardLimitFwd);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 40), 0u); // away from the switch: allowed
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_FALSE(a.ax.status().limit_fwd);
    EXPECT_NEAR(a.ax.status().act_pos, 40, 0.05);
}

TEST(Axis, BothLimitsIsAnError) {
    AxisBus a;
    a.enable();
    // Wire both switches active: move the stage to the forward limit and force the backward
    // input low through its entry (the plant drives it; write after the plant, before the read).
    a.b.plant->find_stage("x")->set_position(55);
    a.cycles(3);
    ASSERT_TRUE(a.ax.status().limit_fwd);
    registry::BoundSignal bwd = a.b.m->bind("ec0.s1.binaryInput02");
    a.b.cycle([&] {
        bwd.set(0);
        a.ax.run(0.001);
    });
    EXPECT_EQ(a.ax.status().error_id, error_id::kBothLimits);
    EXPECT_FALSE(a.ax.status().enable_cmd); // both limits disable the drive at once
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, 0), error_id::kBothLimits); // refused while latched
    a.cycles(2);
    EXPECT_EQ(a.cmd(CommandType::Reset), 0u);
    EXPECT_EQ(a.ax.status().error_id, 0u);
}

TEST(Axis, SoftLimitsRefuseTargetsAndStopVelocityMovesAtTheLimit) {
    AxisParams p = stepper_params();
    p.soft_fwd_enable = true;
    p.soft_fwd = 20;
    p.soft_bwd_enable = true;
    p.soft_bwd = -20;
    AxisBus a(p);
    a.enable();
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, 25), error_id::kSoftLimitFwd); // acceptance 6
    EXPECT_EQ(a.ax.status().warning_id, error_id::kSoftLimitFwd);
    EXPECT_FALSE(a.ax.status().busy);
    ASSERT_EQ(a.cmd(CommandType::MoveVelocity, 0, 5), 0u); // jog: decelerates to stop at 20
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 20.0);
    EXPECT_EQ(a.cmd(CommandType::MoveVelocity, 0, 5), error_id::kSoftLimitFwd);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, -10), 0u); // backward allowed
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, -10.0);
}

TEST(Axis, HomingOnLowLimitAndHomeSwitchWithPostMove) {
    // Acceptance 7: sequence 3, homing position -30: to the low limit, reverse, the home switch's
    // rising edge is -30; post-move to -25 keeps the axis busy until done.
    AxisParams p = stepper_params();
    p.homing_sequence = 3;
    p.homing_position = -30;
    p.homing_post_move_enable = true;
    p.homing_post_move_position = -25;
    AxisBus a(p);
    a.enable();
    // Make the encoder wrong first (as after power-up): position reads 7 where the stage is at 0.
    ASSERT_EQ(a.cmd(CommandType::SetPosition, 7), 0u);
    ASSERT_EQ(a.cmd(CommandType::Home, 0, 0, 42), 0u);
    EXPECT_FALSE(a.ax.status().homed);
    bool saw_limit = false;
    int n = a.until([&] {
        saw_limit = saw_limit || a.ax.status().limit_bwd;
        return !a.ax.status().busy;
    }, 60000);
    EXPECT_LT(n, 60000);
    EXPECT_TRUE(saw_limit);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_TRUE(a.ax.status().homed);
    EXPECT_EQ(a.ax.status().done_tag, 42u);
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, -25.0); // post-move done before busy fell
    a.until([&] { return a.ax.status().at_target; }, 2000);
    // The home cam's edge (stage at -30.5 going forward) now reads -30: the encoder agrees with
    // the stage to within the edge detection (one cycle at 2 mm/s) and the cam half-width.
    EXPECT_NEAR(a.ax.status().act_pos - a.stage(), -30 - (-30.5), 0.01);
}

TEST(Axis, SetPositionAndHomingSequence15MoveNothing) {
    AxisParams p = stepper_params();
    p.homing_sequence = 15;
    p.homing_position = 100;
    AxisBus a(p);
    a.enable();
    double before = a.stage();
    ASSERT_EQ(a.cmd(CommandType::Home), 0u);
    a.cycles(5);
    EXPECT_TRUE(a.ax.status().homed);
    EXPECT_NEAR(a.ax.status().act_pos, 100, 1e-6);
    EXPECT_NEAR(a.ax.status().set_pos, 100, 1e-6);
    EXPECT_DOUBLE_EQ(a.stage(), before);
    EXPECT_FALSE(a.ax.status().busy);
    EXPECT_EQ(a.ax.status().error_id, 0u);
}

TEST(Axis, BusLossDisablesAndDoesNotReEnable) {
    AxisBus a;
    a.enable();
    ASSERT_EQ(a.cmd(CommandType::MoveVelocity, 0, 2), 0u);
    a.cycles(100);
    a.b.seg.unplug(2); // the drive's slave drops off the bus: WKC incomplete
    a.cycles(3);
    EXPECT_EQ(a.ax.status().error_id, error_id::kBusNotOk); // acceptance 12
    EXPECT_FALSE(a.ax.status().enable_cmd);
    EXPECT_FALSE(a.ax.status().busy);
    a.b.seg.replug(2);
    a.b.m->check_and_recover();
    a.cycles(50);
    EXPECT_FALSE(a.ax.status().enabled); // not re-enabled automatically
    EXPECT_EQ(a.ax.status().error_id, error_id::kBusNotOk);
    EXPECT_EQ(a.cmd(CommandType::Reset), 0u);
    a.cycles(5);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    a.enable();
    EXPECT_TRUE(a.ax.status().enabled);
}

TEST(Axis, VirtualAxisFollowsItsTrajectory) {
    AxisParams p;
    p.virtual_axis = true;
    p.trajectory = {2, 4, 4, 40}; // S-curve
    Axis ax(p, AxisIo{});
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    ax.run(0.001);
    ASSERT_TRUE(ax.status().enabled);
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 3}), 0u);
    int n = 0;
    while (ax.status().busy || n == 0) {
        ax.run(0.001);
        ++n;
        ASSERT_LT(n, 10000);
    }
    EXPECT_DOUBLE_EQ(ax.status().act_pos, 3.0);
    EXPECT_DOUBLE_EQ(ax.status().pos_err, 0.0);
}

// Homing 5/6 (ECMC): to the low/high limit, then through the home cam and back into it: the
// reference is the cam's centre (-30), whichever side the sequence comes from.
TEST(Axis, HomingSequences5And6FindTheCamCentreAfterTheLimit) {
    for (int seq : {5, 6}) {
        AxisParams p = stepper_params();
        p.homing_sequence = seq;
        p.homing_position = 7;
        p.homing_velocity_from = 4;
        AxisBus a(p);
        a.enable();
        ASSERT_EQ(a.cmd(CommandType::Home), 0u) << seq;
        bool reached_limit = false;
        a.until([&] {
            reached_limit = reached_limit || (seq == 5 ? a.ax.status().limit_bwd : a.ax.status().limit_fwd);
            return !a.ax.status().busy;
        }, 120000);
        EXPECT_TRUE(reached_limit) << seq;
        EXPECT_EQ(a.ax.status().error_id, 0u) << seq;
        EXPECT_TRUE(a.ax.status().homed) << seq;
        EXPECT_NEAR(a.ax.status().act_pos - a.stage(), 7 - (-30.0), 0.02) << seq; // one cycle at 4 mm/s
    }
}

// Homing 21/22 (ECMC, resolvers and single-turn absolute encoders): off the limit, the
// latchCount-th overflow of the encoder's absolute bits (here 12 of the 16-bit counter: every
// 4096 counts, 0.32 mm) beyond where the axis stopped is the homing position. Checked by moving on
// slowly and reading the position where the absolute bits overflow.
TEST(Axis, HomingSequences21And22ReferenceTheAbsoluteBitsOverflow) {
    for (int seq : {21, 22}) {
        for (int count : {1, 2}) {
            AxisParams p = stepper_params();
            p.encoder.abs_bits = 12;
            p.homing_sequence = seq;
            p.homing_position = 3;
            p.homing_latch_count = count;
            AxisBus a(p);
            a.enable();
            ASSERT_EQ(a.cmd(CommandType::Home), 0u);
            a.until([&] { return !a.ax.status().busy; }, 60000);
            ASSERT_EQ(a.ax.status().error_id, 0u) << seq;
            ASSERT_TRUE(a.ax.status().homed);
            // on in the sequence's direction off the switch, at 0.2 mm/s, to the count-th overflow
            double v = seq == 21 ? 0.2 : -0.2;
            ASSERT_EQ(a.cmd(CommandType::MoveVelocity, 0, v), 0u);
            uint64_t last = a.ax.encoder().last_raw() & 4095;
            int overflows = 0;
            double at = NAN;
            a.until([&] {
                uint64_t r = a.ax.encoder().last_raw() & 4095;
                bool wrapped = seq == 21 ? r < last : r > last;
                last = r;
                if (wrapped && ++overflows == count) at = a.ax.status().act_pos;
                return overflows == count;
            }, 20000);
            ASSERT_EQ(overflows, count) << seq << " " << count;
            // the position where the counter reads 0 in its absolute bits, within one cycle's travel
            EXPECT_NEAR(at, 3.0, 0.0003 + 1.0 / 12800) << seq << " latchCount " << count;
        }
    }
    AxisParams p = stepper_params();
    p.encoder.abs_bits = 20; // more than the counter's 16 bits
    p.homing_sequence = 21;
    AxisBus a(p);
    a.enable();
    (void)a.cmd(CommandType::Home);
    a.cycles(2);
    EXPECT_EQ(a.ax.status().error_id, error_id::kAbsBitsOutOfRange);
}

// Homing 26 (ECMC): the drive homes itself. With axis.autoMode the drive is put in its homing
// mode first (the sequence waits until it reports it), `trigg` starts it, `ready` rising ends it:
// the position there becomes the homing position; the drive goes back to its motion mode before
// the command ends. Without trigg/ready the sequence is refused (0x14D19).
TEST(Axis, HomingSequence26IsTheDrivesOwnWithAutoMode) {
    uint8_t img[4] = {}; // [0] trigg, [1] ready, [2] mode set, [3] mode act
    auto at = [&](uint32_t byte) { return registry::BoundSignal{img, byte * 8, 8, false, -1}; };
    AxisParams p = stepper_params();
    p.homing_sequence = 26;
    p.homing_position = 12.5;
    p.auto_mode_motion = 8; // CSP
    p.auto_mode_home = 6;   // homing mode
    AxisBus a(p, [&](AxisIo& io) {
        io.homing_trigg = at(0);
        io.homing_ready = at(1);
        io.mode_set = at(2);
        io.mode_act = at(3);
    });
    a.enable();
    // the test is the drive: its mode follows the request 5 cycles later; homing takes 40 cycles
    int mode_delay = 0, homing = 0, trigg_cycles = 0;
    uint8_t requested = 0;
    auto drive = [&] {
        if (img[2] != requested) {
            requested = img[2];
            mode_delay = 5;
        }
        if (mode_delay > 0 && --mode_delay == 0) img[3] = requested;
        if (img[0]) {
            ++trigg_cycles;
            if (img[3] != 6) ADD_FAILURE() << "triggered before the drive was in its homing mode";
            if (++homing == 40) img[1] = 1;
        } else {
            homing = 0;
            img[1] = 0;
        }
    };
    ASSERT_EQ(a.cmd(CommandType::MoveRelative, 1), 0u);
    EXPECT_EQ(img[2], 8); // a motion command writes the motion mode
    a.until([&] { drive(); return !a.ax.status().busy; }, 5000);
    ASSERT_EQ(a.cmd(CommandType::Home), 0u);
    EXPECT_EQ(img[2], 6);
    int n = a.until([&] { drive(); return !a.ax.status().busy; }, 5000);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_TRUE(a.ax.status().homed);
    EXPECT_NEAR(a.ax.status().act_pos, 12.5, 1e-9);
    EXPECT_EQ(img[0], 0);     // trigg cleared
    EXPECT_EQ(img[2], 8);     // back in the motion mode ...
    EXPECT_EQ(img[3], 8);     // ... reported before the command ended
    EXPECT_GE(trigg_cycles, 40);
    EXPECT_GE(n, 5 + 40 + 5); // homing mode reported, the drive homing, motion mode reported
    AxisParams q = stepper_params();
    q.homing_sequence = 26;
    AxisBus b(q);
    b.enable();
    (void)b.cmd(CommandType::Home);
    b.cycles(2);
    EXPECT_EQ(b.ax.status().error_id, error_id::kHomeSeqNotSupported);
}

// A second encoder with homing.refAtHome takes the primary's position when the axis homes, and
// can be made the control encoder while the axis is not busy (ECMC SelectAxisEncPrimary /
// mc_set_prim_enc): the axis then reads and closes its loop on it.
TEST(Axis, SecondEncoderReferencedAtHomingAndSelectable) {
    AxisParams p = stepper_params();
    p.homing_sequence = 7;
    p.homing_position = 0;
    p.homing_velocity_from = 4;
    EncoderParams second = p.encoder;
    second.numerator = 2; // twice the primary's scale (a different gearing)
    second.ref_at_home = true;
    p.encoders = {p.encoder, second};
    p.primary_encoder = 0;
    AxisBus a(p, [&](AxisIo& io) { io.encoders = {io.encoder, io.encoder}; });
    a.enable();
    EXPECT_FALSE(a.ax.encoder_homed(1));
    ASSERT_EQ(a.cmd(CommandType::Home), 0u);
    a.until([&] { return !a.ax.status().busy; }, 60000);
    ASSERT_TRUE(a.ax.status().homed);
    EXPECT_TRUE(a.ax.encoder_homed(1));
    a.cycles(1);
    EXPECT_NEAR(a.ax.status().enc_pos[1], a.ax.status().enc_pos[0], 1e-9); // set with the primary
    ASSERT_EQ(a.cmd(CommandType::MoveRelative, 1), 0u);
    EXPECT_EQ(a.ax.select_primary_encoder(1), error_id::kPrimaryEncoderWhileBusy);
    a.until([&] { return !a.ax.status().busy; }, 5000);
    double e0 = a.ax.status().enc_pos[0], e1 = a.ax.status().enc_pos[1];
    EXPECT_NEAR(e1 - e0, 1.0, 0.02); // 1 mm of stage is 2 mm on the second encoder
    EXPECT_EQ(a.ax.select_primary_encoder(5), error_id::kPrimaryEncoderOutOfRange);
    ASSERT_EQ(a.ax.select_primary_encoder(1), 0u);
    EXPECT_EQ(a.ax.params().primary_encoder, 1);
    a.cycles(1);
    EXPECT_NEAR(a.ax.status().act_pos, e1, 0.01);
    double stage = a.stage();
    ASSERT_EQ(a.cmd(CommandType::MoveRelative, 1), 0u); // 1 mm on the second encoder: 0.5 of stage
    a.until([&] { return !a.ax.status().busy; }, 5000);
    EXPECT_NEAR(a.stage() - stage, 0.5, 0.02);
    EXPECT_NEAR(a.ax.status().enc_pos[0], e0 + 0.5, 0.02); // the first goes on reading
}

// features.allowedFunctions (ECMC): a command of a function not allowed is refused with
// 0x14D16, latched as the axis error; the others run; mc_set_enable_motion_funcs changes them.
TEST(Axis, AllowedFunctions) {
    AxisParams p;
    p.virtual_axis = true;
    p.trajectory = {2, 4, 4, 0};
    p.allow_positioning = false;
    p.allow_homing = false;
    Axis ax(p, AxisIo{});
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    ax.run(0.001);
    EXPECT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 3}), error_id::kMotionNotAllowed);
    EXPECT_EQ(ax.status().error_id, error_id::kMotionNotAllowed);
    EXPECT_TRUE(ax.status().move_failed);
    (void)ax.command(AxisCommand{CommandType::Reset});
    AxisCommand home{CommandType::Home};
    home.homing_sequence = 15;
    EXPECT_EQ(ax.command(home), error_id::kMotionNotAllowed);
    (void)ax.command(AxisCommand{CommandType::Reset});
    AxisCommand vel{CommandType::MoveVelocity, 0, 1};
    EXPECT_EQ(ax.command(vel), 0u); // constantVelocity still allowed
    ax.run(0.001);
    EXPECT_TRUE(ax.status().busy);
    (void)ax.command(AxisCommand{CommandType::Halt});
    for (int i = 0; i < 1000 && ax.status().busy; ++i) ax.run(0.001);
    ax.set_allowed_functions(true, false, true);
    EXPECT_EQ(ax.command(vel), error_id::kMotionNotAllowed);
    (void)ax.command(AxisCommand{CommandType::Reset});
    EXPECT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 3}), 0u);
}

TEST(Axis, HomingSequencesOnTheHomeCam) {
    // 7: backward at "from" to the cam's rising edge (the cam spans -30.5..-29.5, so the edge
    // going backward is at -29.5); 9: through the cam and back, the middle of both edges (-30).
    for (int seq : {7, 9}) {
        AxisParams p = stepper_params();
        p.homing_sequence = seq;
        p.homing_position = 0;
        p.homing_velocity_from = 4;
        AxisBus a(p);
        a.enable();
        ASSERT_EQ(a.cmd(CommandType::Home), 0u) << seq;
        a.until([&] { return !a.ax.status().busy; }, 60000);
        EXPECT_EQ(a.ax.status().error_id, 0u) << seq;
        EXPECT_TRUE(a.ax.status().homed) << seq;
        a.until([&] { return a.ax.status().at_target; }, 2000);
        double edge = seq == 7 ? -29.5 : -30.0;
        EXPECT_NEAR(a.ax.status().act_pos - a.stage(), 0 - edge, 0.02) << seq; // one cycle at 4 mm/s
    }
}

TEST(Axis, HomingFailsOnAnUnexpectedLimitAndIsRefusedWhileBusy) {
    AxisParams p = stepper_params();
    p.homing_sequence = 8; // forward to the cam, but the stage is beyond it: runs into the fwd limit
    AxisBus a(p);
    a.b.plant->find_stage("x")->set_position(0);
    a.enable();
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 5), 0u);
    a.cycles(100);
    EXPECT_EQ(a.cmd(CommandType::Home), error_id::kBusy);
    EXPECT_EQ(a.ax.status().error_id, error_id::kBusy); // an error: it latches and stops the move
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_LT(a.ax.status().set_pos, 4.0);
    EXPECT_EQ(a.cmd(CommandType::Reset), 0u);
    ASSERT_EQ(a.cmd(CommandType::Home), 0u);
    a.until([&] { return !a.ax.status().busy; }, 60000);
    EXPECT_EQ(a.ax.status().error_id, error_id::kSeqFailed);
    EXPECT_FALSE(a.ax.status().homed);
    EXPECT_EQ(a.cmd(CommandType::Home, 0, 0, 0), error_id::kSeqFailed); // latched until reset
    AxisCommand zero{CommandType::Home};
    zero.homing_sequence = 0;
    EXPECT_EQ(a.ax.command(zero), error_id::kSeqFailed);
    EXPECT_EQ(a.cmd(CommandType::Reset), 0u);
    AxisCommand bad{CommandType::Home};
    bad.homing_sequence = 13;
    EXPECT_EQ(a.ax.command(bad), error_id::kSeqCmdData);
    EXPECT_EQ(a.ax.status().error_id, error_id::kSeqCmdData);
}

TEST(Axis, EnablingResetsErrorsAndExternalInterlockDisables) {
    AxisParams p = stepper_params();
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL2008}
  - {position: 2, type: EL1008}
  - {position: 3, type: EL7041}
wiring:
  - {from: s1.binaryOutput01, to: s2.binaryInput01}
)");
    AxisIo io = drive_io(b, 3);
    io.interlock = b.m->bind("ec0.s2.binaryInput01");
    Axis ax(p, io);
    registry::BoundSignal ok = b.m->bind("ec0.s1.binaryOutput01");
    auto cycles = [&](int n) {
        for (int i = 0; i < n; ++i) b.cycle([&] { ax.run(0.001); });
    };
    auto power = [&] {
        AxisCommand on{CommandType::Power};
        on.on = true;
        (void)ax.command(on);
    };
    ok.set(1); // interlock input OK (normally closed)
    cycles(5);
    power();
    cycles(5);
    ASSERT_TRUE(ax.status().enabled);
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveVelocity, 0, 2}), 0u);
    cycles(100);
    ok.set(0); // the interlock opens
    cycles(5);
    EXPECT_EQ(ax.status().error_id, error_id::kExternalInterlock);
    EXPECT_FALSE(ax.status().enabled);
    EXPECT_FALSE(ax.status().busy);
    ok.set(1);
    cycles(5);
    power(); // enabling resets the error (ECMC enableAutoResetError)
    cycles(5);
    EXPECT_EQ(ax.status().error_id, 0u);
    EXPECT_TRUE(ax.status().enabled);
}

TEST(Axis, StallWhenTheTargetIsNotReachedAfterTheMove) {
    // A stage that sticks (friction above the motor's force) and no lag monitoring: the move's
    // setpoint arrives, the actual position never does. After max(15 s, 10 x 1 s) -> stall.
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7041}
stages:
  - {name: x, drive: s1, friction: 400, max_force: 100}
)");
    AxisParams p = stepper_params();
    p.lag_enable = false;
    Axis ax(p, drive_io(b, 1));
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    for (int i = 0; i < 10; ++i) b.cycle([&] { ax.run(0.001); });
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 2}), 0u); // 0.9 s move
    int n = 0;
    while (ax.status().error_id == 0 && n < 30000) {
        b.cycle([&] { ax.run(0.001); });
        ++n;
    }
    EXPECT_EQ(ax.status().error_id, error_id::kStall);
    EXPECT_NEAR(n * 0.001, 0.9 + 15.0, 0.01); // the move's time, then 15 s not at target
    EXPECT_FALSE(ax.status().enable_cmd);
}

TEST(Axis, ServoAxisThroughDs402) {
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7211}
stages:
  - {name: r, drive: s1, pitch: 360, mass: 0.2, friction: 0.2}
)");
    AxisParams p;
    p.encoder.numerator = 360;
    p.encoder.denominator = 1048576;
    p.encoder.bits = 32;
    p.encoder.absolute = true;
    p.drive.type = DriveParams::Type::Ds402;
    p.drive.numerator = 8000 * 360.0;
    p.drive.denominator = 2147483648.0;
    p.controller.kp = 20;
    p.trajectory = {90, 360, 360, 3600}; // S-curve
    p.target_enable = true;
    p.target_tolerance = 0.05;
    p.target_time_cycles = 10;
    p.lag_enable = true;
    p.lag_tolerance = 1;
    p.lag_time_cycles = 20;
    Axis ax(p, drive_io(b, 1));
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    int n = 0;
    while (!ax.status().enabled && n < 50) {
        b.cycle([&] { ax.run(0.001); });
        ++n;
    }
    ASSERT_TRUE(ax.status().enabled);
    EXPECT_LE(n, 10); // 0x06 -> 0x07 -> 0x0F, one cycle each way
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 180}), 0u);
    n = 0;
    while ((ax.status().busy || !ax.status().at_target) && n < 10000) {
        b.cycle([&] { ax.run(0.001); });
        ++n;
    }
    EXPECT_EQ(ax.status().error_id, 0u);
    EXPECT_TRUE(ax.status().at_target);
    EXPECT_NEAR(b.plant->find_stage("r")->position(), 180, 0.05);
}

TEST(Axis, AMoveRightAfterEnableWaitsForTheDrive) {
    AxisBus a;
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)a.ax.command(on);
    ASSERT_FALSE(a.ax.status().enabled);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 2, 0, 5), 0u); // taken, runs once enabled
    EXPECT_TRUE(a.ax.status().busy);
    EXPECT_NE(a.ax.status().done_tag, 5u);
    a.until([&] { return !a.ax.status().busy; }, 5000);
    EXPECT_EQ(a.ax.status().done_tag, 5u);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 2.0);
}

TEST(Axis, BrakeOpensAfterEnableAndClosesAheadOfDisable) {
    // ECMC drive.brake: open openDelay cycles after the drive is enabled (the axis is enabled only
    // then); on disable the brake closes at once and the drive stays enabled closeAhead cycles.
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL2008}
  - {position: 2, type: EL7041}
)");
    AxisParams p = stepper_params();
    p.brake_open_delay_cycles = 20;
    p.brake_close_ahead_cycles = 15;
    AxisIo io = drive_io(b, 2);
    io.brake = b.m->bind("ec0.s1.binaryOutput01");
    Axis ax(p, io);
    registry::BoundSignal control = b.m->bind("ec0.s2.driveControl01");
    auto brake_out = [&] { return b.m->get(*b.m->find_signal("ec0.s1.binaryOutput01")); };
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    int drive_on = -1, brake_on = -1, axis_on = -1;
    for (int i = 0; i < 60; ++i) {
        b.cycle([&] { ax.run(0.001); });
        if (drive_on < 0 && ax.status().enable_cmd && (b.m->get(*b.m->find_signal("ec0.s2.driveStatus01")) & 2)) drive_on = i;
        if (brake_on < 0 && brake_out()) brake_on = i;
        if (axis_on < 0 && ax.status().enabled) axis_on = i;
    }
    ASSERT_GE(drive_on, 0);
    EXPECT_GE(brake_on - drive_on, 19);
    EXPECT_LE(brake_on - drive_on, 22);
    EXPECT_GE(axis_on, brake_on - 1);
    // disable: brake closes now, the drive's enable bit stays 15 more cycles
    AxisCommand off{CommandType::Power};
    (void)ax.command(off);
    int brake_off = -1, enable_off = -1;
    for (int i = 0; i < 40; ++i) {
        b.cycle([&] { ax.run(0.001); });
        if (brake_off < 0 && !brake_out()) brake_off = i;
        if (enable_off < 0 && !(control.get() & 1)) enable_off = i;
    }
    EXPECT_LE(brake_off, 1);
    EXPECT_GE(enable_off - brake_off, 14);
    EXPECT_LE(enable_off - brake_off, 16);
    EXPECT_FALSE(ax.status().enabled);
}

TEST(Axis, NegativeSoftLimitRangeIsValid) {
    // ECMC acceptance 6: limits (-227, -192) are a valid range
    AxisParams p = stepper_params();
    p.soft_fwd_enable = p.soft_bwd_enable = true;
    p.soft_fwd = -192;
    p.soft_bwd = -227;
    AxisBus a(p);
    a.enable();
    ASSERT_EQ(a.cmd(CommandType::SetPosition, -200), 0u);
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, -190), error_id::kSoftLimitFwd);
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, -230), error_id::kSoftLimitBwd);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, -195), 0u);
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, -195.0);
}

TEST(Axis, Ds402NotEnabledInTimeIsError14652) {
    // ECMC acceptance 13: a DS402 drive that never reaches OPERATION ENABLED (a status word that
    // stays SWITCH ON DISABLED) -> 0x14652 after 15 s, enable withdrawn.
    uint8_t image[16] = {};
    AxisParams p;
    p.drive.type = DriveParams::Type::Ds402;
    p.trajectory = {1, 1, 1, 0};
    AxisIo io;
    io.drive_control = registry::BoundSignal{image, 0, 16, false, -1};
    io.drive_status = registry::BoundSignal{image, 16, 16, false, -1};
    io.drive_setpoint = registry::BoundSignal{image, 32, 32, true, -1};
    io.encoder = registry::BoundSignal{image, 64, 32, false, -1};
    io.drive_status.set(0x40);
    Axis ax(p, io);
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    int n = 0;
    while (ax.status().error_id == 0 && n < 20000) {
        ax.run(0.001);
        ++n;
    }
    EXPECT_EQ(ax.status().error_id, error_id::kDs402Timeout);
    EXPECT_NEAR(n, 15000, 2);
    EXPECT_FALSE(ax.status().enable_cmd);
}

TEST(Axis, IndexHomingUsesTheLatchCountthMark) {
    // ECMC acceptance 8 (sequence 11, latchCount 2): to the low limit, back off it, and the second
    // index mark latched by the EL5101 (marks every 1 mm at x.25) is the reference.
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL1008}
  - {position: 2, type: EL7041}
  - {position: 3, type: EL5101}
stages:
  - name: x
    drive: s2
    travel: [-60, 60]
    start: -40
    limits:
      forward: {input: s1.binaryInput01, at: 50}
      backward: {input: s1.binaryInput02, at: -50}
    encoders:
      - {entry: s3.positionActual01, counts_per_unit: 1000, index_every: 1, index_offset: 0.25}
)");
    AxisParams p = stepper_params();
    p.encoder.numerator = 1;
    p.encoder.denominator = 1000;
    p.encoder.bits = 16;
    p.homing_sequence = 11;
    p.homing_latch_count = 2;
    p.homing_position = 0;
    p.homing_velocity_from = 1;
    AxisIo io = drive_io(b, 2);
    io.encoder = b.m->bind("ec0.s3.positionActual01");
    io.limit_fwd = b.m->bind("ec0.s1.binaryInput01");
    io.limit_bwd = b.m->bind("ec0.s1.binaryInput02");
    io.latch_position = b.m->bind("ec0.s3.encoderLatchPostion01");
    io.latch_arm = b.m->bind("ec0.s3.encoderControl01", 0);
    io.latch_valid = b.m->bind("ec0.s3.encoderStatus01", 0);
    Axis ax(p, io);
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    for (int i = 0; i < 10; ++i) b.cycle([&] { ax.run(0.001); });
    ASSERT_TRUE(ax.status().enabled);
    ASSERT_EQ(ax.command(AxisCommand{CommandType::Home}), 0u);
    int n = 0;
    while (ax.status().busy && n < 60000) {
        b.cycle([&] { ax.run(0.001); });
        ++n;
    }
    ASSERT_EQ(ax.status().error_id, 0u) << std::hex << ax.status().error_id;
    EXPECT_TRUE(ax.status().homed);
    // the second mark after leaving the switch (at -50) is -48.75: it now reads 0
    double stage = b.plant->find_stage("x")->position();
    EXPECT_NEAR(ax.status().act_pos - stage, 0 - (-48.75), 0.002);
    // without a latch the sequence is refused
    Axis plain(p, drive_io(b, 2));
    (void)plain.command(on);
    for (int i = 0; i < 10; ++i) b.cycle([&] { plain.run(0.001); });
    EXPECT_EQ(plain.command(AxisCommand{CommandType::Home}), error_id::kLatchCount);
}

TEST(Axis, ServoAxisInCyclicSynchronousPosition) {
    // EL7211-0010_CSP: the axis sends the trajectory's position (in the resolver's frame, after a
    // set position too) and the drive's own loop follows it; no axis PID.
    SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7211-0010_CSP}
stages:
  - {name: r, drive: s1, pitch: 360, mass: 0.2, friction: 0.2, start: 30}
)");
    AxisParams p;
    p.csp = true;
    p.encoder.numerator = 360;
    p.encoder.denominator = 1048576;
    p.encoder.bits = 32;
    p.encoder.absolute = true;
    p.encoder.abs_bits = 32;
    p.drive.type = DriveParams::Type::Ds402;
    p.drive.position_mode = true;
    p.drive.numerator = 360; // [deg] per 2^20 counts
    p.drive.denominator = 1048576;
    p.trajectory = {90, 360, 360, 3600};
    p.target_enable = true;
    p.target_tolerance = 0.05;
    p.target_time_cycles = 10;
    p.lag_enable = true;
    p.lag_tolerance = 1;
    p.lag_time_cycles = 20;
    AxisIo io = drive_io(b, 1);
    io.drive_setpoint = b.m->bind("ec0.s1.positionSetpoint01");
    ASSERT_TRUE(io.drive_setpoint.bound());
    Axis ax(p, io);
    AxisCommand on{CommandType::Power};
    on.on = true;
    (void)ax.command(on);
    for (int i = 0; i < 20; ++i) b.cycle([&] { ax.run(0.001); });
    ASSERT_TRUE(ax.status().enabled);
    EXPECT_NEAR(b.plant->find_stage("r")->position(), 30, 0.01); // enabling does not jump
    EXPECT_NEAR(ax.status().act_pos, 30, 0.01);
    ASSERT_EQ(ax.command(AxisCommand{CommandType::SetPosition, 100}), 0u); // another frame
    ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 190}), 0u);
    int n = 0;
    while ((ax.status().busy || !ax.status().at_target) && n < 10000) {
        b.cycle([&] { ax.run(0.001); });
        ++n;
    }
    EXPECT_EQ(ax.status().error_id, 0u);
    EXPECT_TRUE(ax.status().at_target);
    EXPECT_NEAR(b.plant->find_stage("r")->position(), 120, 0.05); // 90 deg further
    EXPECT_NEAR(n * 0.001, 1.0 + 0.35, 0.2); // S-curve 90 deg at 90 deg/s, 360 deg/s^2
}

// CSP_PC (ECMC): CSP with the axis PID on top. The drive closes its loop on its own encoder
// (useAsCSPDrvEnc), whose scale is 2 % off the primary (an external scale, the truth); the PID on
// the primary's error corrects the drive's setpoint so the axis ends at target on the primary.
// Plain CSP on the same setup ends 2 % short.
TEST(Axis, CspWithPositionControllerOnTheExternalEncoder) {
    for (bool pc : {false, true}) {
        SimBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7211-0010_CSP}
stages:
  - {name: r, drive: s1, pitch: 360, mass: 0.2, friction: 0.2, start: 0}
)");
        AxisParams p;
        p.csp = true;
        p.csp_pc = pc;
        EncoderParams drive_enc;
        drive_enc.numerator = 360;
        drive_enc.denominator = 1048576;
        drive_enc.bits = 32;
        drive_enc.absolute = true;
        drive_enc.abs_bits = 32;
        EncoderParams external = drive_enc;
        external.numerator = 360 * 1.02; // reads 2 % more than the drive's encoder
        p.encoder = external;
        p.encoders = {external, drive_enc};
        p.primary_encoder = 0;
        p.csp_drive_encoder = 1;
        p.drive.type = DriveParams::Type::Ds402;
        p.drive.position_mode = true;
        p.drive.numerator = 360;
        p.drive.denominator = 1048576;
        p.controller.kp = 0.5; // a correction of the position: a loop gain below 1
        p.controller.ki = 2;
        p.trajectory = {90, 360, 360, 3600};
        p.target_enable = true;
        p.target_tolerance = 0.05;
        p.target_time_cycles = 10;
        AxisIo io = drive_io(b, 1);
        io.drive_setpoint = b.m->bind("ec0.s1.positionSetpoint01");
        io.encoders = {io.encoder, io.encoder};
        Axis ax(p, io);
        AxisCommand on{CommandType::Power};
        on.on = true;
        (void)ax.command(on);
        for (int i = 0; i < 20; ++i) b.cycle([&] { ax.run(0.001); });
        ASSERT_TRUE(ax.status().enabled);
        ASSERT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 90}), 0u);
        for (int n = 0; n < 4000; ++n) b.cycle([&] { ax.run(0.001); });
        if (pc) {
            EXPECT_NEAR(ax.status().act_pos, 90, 0.05) << "CSP_PC";
            EXPECT_TRUE(ax.status().at_target);
            EXPECT_NEAR(b.plant->find_stage("r")->position(), 90 / 1.02, 0.05);
        } else {
            EXPECT_NEAR(ax.status().act_pos, 90 * 1.02, 0.1) << "plain CSP: the drive's frame"; // 1.8 off
        }
    }
}

TEST(AxisVariables, NamesAndWritability) {
    const AxisVariableInfo* v = find_axis_variable("traj.extsetpos");
    ASSERT_NE(v, nullptr);
    EXPECT_TRUE(v->writable);
    EXPECT_FALSE(find_axis_variable("enc.actvel")->writable);
    EXPECT_TRUE(find_axis_variable("enc.actpos")->writable); // ECMC: stores the external position
    EXPECT_EQ(find_axis_variable("enc.nope"), nullptr);
    EXPECT_EQ(find_axis_variable("enc.actvelo"), nullptr); // not ECMC's either
    EXPECT_NE(find_axis_variable("cntrl.error"), nullptr);  // ECMC defines it (11.0.8 never parses it); the manual lists it
    for (const char* name : {"id", "counter", "blockcom", "enc.rawpos", "enc.homepos", "traj.targetdec", "traj.setvel",
                             "traj.setvelffraw", "traj.dir", "drv.setvelraw", "cntrl.poserror", "cntrl.output", "seq.state"})
        EXPECT_NE(find_axis_variable(name), nullptr) << name;
    AxisVariables vars;
    *axis_variable(vars, *v) = 4.5;
    EXPECT_EQ(vars.traj.extsetpos, 4.5);
    EXPECT_GE(axis_variables().size(), 30u);
}

TEST(AxisVariables, PhysicalAxisFollowsExtsetposFromThePlc) {
    // What a kinematics PLC does for a slit blade: traj.source 1, extsetpos every cycle.
    AxisBus a;
    a.enable();
    AxisVariables& v = a.ax.variables();
    v.traj.source = 1;
    for (int i = 0; i < 2000; ++i) { // a 2 mm ramp over 1 s, then hold
        v.traj.extsetpos = std::min(2.0, i * 0.002);
        a.cycles(1);
    }
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 2.0);
    EXPECT_NEAR(a.stage(), 2.0, 0.01);
    EXPECT_EQ(a.ax.status().error_id, 0u); // followed within the lag tolerance
    // back to the internal trajectory: bumpless, and commands work again
    v.traj.source = 0;
    a.cycles(2);
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 2.0);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 3), 0u);
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 3.0);
}

TEST(AxisVariables, PlcCommandsInterlocksAndEnable) {
    AxisParams p = stepper_params();
    p.external_commands = true;
    AxisBus a(p);
    AxisVariables& v = a.ax.variables();
    v.drv.enable = 1; // mc_power from a PLC
    a.until([&] { return a.ax.status().enabled; }, 100);
    ASSERT_TRUE(a.ax.status().enabled);
    EXPECT_EQ(v.drv.enabled, 1.0);
    v.traj.command = 3;
    v.traj.targetpos = 4;
    v.traj.targetvel = 2;
    v.traj.execute = 1; // rising edge
    a.cycles(2);
    EXPECT_EQ(v.traj.busy, 1.0);
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 4.0);
    EXPECT_EQ(v.traj.setpos, 4.0);
    // PLC interlock forward: a forward move is stopped, backward allowed
    v.traj.execute = 0;
    a.cycles(1);
    v.mon.ilockfwd = 0;
    v.traj.targetpos = 8;
    v.traj.execute = 1;
    a.cycles(200);
    EXPECT_NEAR(a.ax.status().set_pos, 4.0, 0.05);
    EXPECT_EQ(a.ax.status().last_interlock, Interlock::PlcFwd);
    v.traj.execute = 0;
    a.cycles(1);
    v.traj.targetpos = 1;
    v.traj.execute = 1;
    a.cycles(1); // the axis takes PLC writes at the start of its next cycle
    a.until([&] { return !a.ax.status().busy; });
    EXPECT_DOUBLE_EQ(a.ax.status().set_pos, 1.0);
    // an error that disables shows in drv.enable
    v.traj.execute = 0;
    v.mon.ilockfwd = 1;
    a.b.plant->find_stage("x")->drive()->inject_fault();
    a.cycles(5);
    EXPECT_EQ(v.drv.enable, 0.0);
    EXPECT_NE(v.error, 0.0);
}

TEST(AxisVariables, VirtualAxisActualFromThePlcAndPlcLimitSwitches) {
    AxisParams p;
    p.virtual_axis = true;
    p.encoder_source = 1;
    p.limit_fwd_plc = true;
    p.trajectory = {2, 4, 4, 0};
    Axis ax(p, AxisIo{});
    AxisVariables& v = ax.variables();
    v.drv.enable = 1;
    v.enc.extactpos = 7.5; // e.g. the slit centre (LO + HI) / 2
    ax.run(0.001);
    ax.run(0.001);
    EXPECT_TRUE(ax.status().enabled);
    EXPECT_DOUBLE_EQ(ax.status().act_pos, 7.5);
    EXPECT_EQ(v.enc.actpos, 7.5);
    v.mon.highlim = 0; // a blade at its high limit blocks the virtual axis forward
    ax.run(0.001);
    EXPECT_TRUE(ax.status().limit_fwd);
    EXPECT_EQ(ax.command(AxisCommand{CommandType::MoveAbsolute, 9}), error_id::kHardLimitFwd);
}

// ECMC axis.autoEnable (ecmcAxisBase autoEnableSM/autoDisableSM): a motion command to a disabled
// axis enables it, runs once the drive is enabled and the axis is busy meanwhile; an idle enabled
// axis is disabled after disableTimeout.
TEST(Axis, AutoEnableRunsTheMoveAndAutoDisablesAfterTheIdleTime) {
    AxisParams p = stepper_params();
    p.auto_enable_timeout_s = 1.0;
    p.auto_disable_timeout_s = 2.0;
    AxisBus a(p);
    ASSERT_FALSE(a.ax.status().enable_cmd);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 3, 0, 7), 0u); // taken: no 0x14316
    EXPECT_TRUE(a.ax.status().busy);
    EXPECT_TRUE(a.ax.status().enable_cmd);
    int to_idle = a.until([&] { return !a.ax.status().busy; }, 10000);
    EXPECT_EQ(a.ax.status().done_tag, 7u);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_FALSE(a.ax.status().move_failed);
    EXPECT_NEAR(a.ax.status().act_pos, 3.0, 0.01);
    EXPECT_GT(to_idle, 1000); // the trapezoid: 3 mm at 5 mm/s, 10 mm/s^2 (1.1 s) after enabling
    ASSERT_TRUE(a.ax.status().enabled);
    // disabled once idle and at target for 2 s (at target comes 10 cycles after the setpoint)
    int to_disabled = a.until([&] { return !a.ax.status().enabled; }, 10000);
    EXPECT_GE(to_disabled, 2000);
    EXPECT_LE(to_disabled, 2100);
    EXPECT_FALSE(a.ax.status().enable_cmd);
    EXPECT_EQ(a.ax.status().error_id, 0u);
    EXPECT_NEAR(a.ax.status().act_pos, 3.0, 0.01); // stays where it went
    // a second move enables it again
    ASSERT_EQ(a.cmd(CommandType::MoveRelative, -1, 0, 8), 0u);
    a.until([&] { return !a.ax.status().busy; }, 10000);
    EXPECT_EQ(a.ax.status().done_tag, 8u);
    EXPECT_NEAR(a.ax.status().act_pos, 2.0, 0.01);
    EXPECT_TRUE(a.ax.status().enabled);
}

TEST(Axis, AutoEnableTimeoutIsError1432FAndTheMoveFails) {
    AxisParams p = stepper_params();
    p.auto_enable_timeout_s = 0.5;
    p.drive.enabled_bit = 7; // a status bit the drive never sets: it never reports enabled
    AxisBus a(p);
    ASSERT_EQ(a.cmd(CommandType::MoveAbsolute, 3, 0, 9), 0u);
    int n = a.until([&] { return !a.ax.status().busy; }, 5000);
    EXPECT_GE(n, 499);
    EXPECT_LE(n, 503);
    EXPECT_EQ(a.ax.status().error_id, error_id::kAutoEnableTimeout);
    EXPECT_FALSE(a.ax.status().enable_cmd); // ECMC: setEnable(false)
    EXPECT_EQ(a.ax.status().done_tag, 9u);
    EXPECT_EQ(a.ax.status().refused_tag, 9u);
    EXPECT_TRUE(a.ax.status().move_failed);
    EXPECT_NEAR(a.stage(), 0.0, 1e-9);
}

TEST(Axis, WithoutAutoEnableAMoveOfADisabledAxisIsRefused) {
    AxisBus a; // autoEnable absent: ECMC refuses with 0x14316
    EXPECT_EQ(a.cmd(CommandType::MoveAbsolute, 3, 0, 4), error_id::kNotEnabled);
    EXPECT_FALSE(a.ax.status().enable_cmd);
    EXPECT_TRUE(a.ax.status().move_failed);
    // homing 15 (set position) needs no enable, and does not auto-enable either
    AxisParams p = stepper_params();
    p.auto_enable_timeout_s = 1.0;
    p.homing_sequence = 15;
    p.homing_position = 5;
    AxisBus b(p);
    EXPECT_EQ(b.cmd(CommandType::Home), 0u);
    EXPECT_FALSE(b.ax.status().enable_cmd);
    b.cycles(2);
    EXPECT_NEAR(b.ax.status().act_pos, 5.0, 1e-9);
}

// ECMC's rules for the variables that PLC code (ecmccfg's plc_lib/master_slave) writes: enc.actpos
// stores the external actual position (the actual position while enc.source is 1), traj.setpos
// the external setpoint; blockcom refuses motion and enabling (0x20039); id, counter, traj.dir read.
TEST(AxisVariables, EcmcWriteRulesBlockcomAndReadOnlyState) {
    AxisParams p = stepper_params();
    p.virtual_axis = true;
    p.encoder_source = 1;
    p.id = 7;
    AxisBus a(p);
    AxisVariables& v = a.ax.variables();
    EXPECT_EQ(v.id, 7);
    v.enc.actpos = 12.5; // the kinematics PLC writes the virtual axis's actual position
    a.cycles(1);
    EXPECT_DOUBLE_EQ(v.enc.extactpos, 12.5);
    EXPECT_DOUBLE_EQ(a.ax.status().act_pos, 12.5);
    EXPECT_DOUBLE_EQ(v.enc.actpos, 12.5);
    double c0 = v.counter;
    a.cycles(3);
    EXPECT_EQ(v.counter, c0 + 3);
    // allowplccmd 0: the write is dropped, as ECMC
    v.allowplccmd = 0;
    v.enc.actpos = 1;
    a.cycles(1);
    EXPECT_DOUBLE_EQ(a.ax.status().act_pos, 12.5);
    v.allowplccmd = 1;

    AxisBus b; // a physical stepper
    AxisVariables& w = b.ax.variables();
    w.blockcom = 1;
    b.cycles(1);
    AxisCommand on{CommandType::Power};
    on.on = true;
    EXPECT_EQ(b.ax.command(on), error_id::kBlockCom);
    EXPECT_EQ(b.ax.status().error_id, error_id::kBlockCom);
    EXPECT_FALSE(b.ax.status().enable_cmd);
    w.blockcom = 0;
    (void)b.ax.command(AxisCommand{CommandType::Reset});
    b.enable();
    ASSERT_EQ(b.cmd(CommandType::MoveVelocity, 0, -2), 0u);
    b.cycles(300);
    EXPECT_EQ(w.traj.dir, -1);
    EXPECT_LT(w.traj.setvel, 0);
    w.blockcom = 1;
    b.cycles(1);
    EXPECT_EQ(b.cmd(CommandType::MoveAbsolute, 5), error_id::kBlockCom);
    (void)b.ax.command(AxisCommand{CommandType::Halt}); // stopping is never blocked
    b.until([&] { return !b.ax.status().busy; }, 5000);
    EXPECT_EQ(w.traj.dir, 0);
}
