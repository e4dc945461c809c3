// Terminal behaviour and plant models behind the master, in virtual time (1 ms cycles): stepper
// and CiA402 drives moving stages, hard stops, limit and home switches, encoders, analog signal
// sources and sensors, EL3702 counters, EL1252 latches, configuration errors, and a plant that
// allocates nothing per cycle.
#include "../alloc_counter.hpp"
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/link.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/sim_config.hpp"

#include "sim_bus.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

using namespace beamctl;
using namespace beamctl::ethercat;

namespace {

using simbus::PlantBus;

const char* kStepper = R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL1008}
  - {position: 2, type: EL7041}
stages:
  - name: x
    drive: s2
    travel: [-10, 10]
    pitch: 1.0
    limits:
      forward: {input: s1.binaryInput01, at: 8}
      backward: {input: s1.binaryInput02, at: -8}
    home: {input: s1.binaryInput03, at: 0, width: 1}
)";

} // namespace

TEST(Plant, StepperMovesAtTheCommandedVelocity) {
    PlantBus b(kStepper);
    sim::Stage* x = b.plant->find_stage("x");
    ASSERT_NE(x, nullptr);
    b.cycles(5);
    EXPECT_EQ(b.get("ec0.s2.driveStatus01") & 0x3, 0x1u); // ready to enable, not enabled
    // Disabled: a setpoint does nothing.
    b.set("ec0.s2.velocitySetpoint01", 8192);
    b.cycles(100);
    EXPECT_EQ(x->position(), 0.0);
    // Enabled: 8192/32767 of 2000 full steps/s = 500 steps/s = 2.5 rev/s = 2.5 mm/s.
    b.set("ec0.s2.driveControl01", 1);
    b.cycles(1000);
    uint64_t st = b.get("ec0.s2.driveStatus01");
    EXPECT_TRUE(st & 0x2) << std::hex << st;   // ready (power stage on)
    EXPECT_TRUE(st & 0x10) << std::hex << st;  // moving positive
    EXPECT_FALSE(st & 0x80) << std::hex << st; // no stall
    double v = 8192.0 / 32767 * 2000 / 200;
    EXPECT_NEAR(x->velocity(), v, 1e-3);
    EXPECT_NEAR(x->position(), v * 1.0, 0.02); // 1 s, less the loop's start-up lag
    // The drive's own encoder: 200 steps x 64 microsteps per mm, 16-bit counter.
    EXPECT_NEAR(double(b.get("ec0.s2.positionActual01")), x->position() * 12800, 200);
}

TEST(Plant, StepperSpeedRangeComesFromTheStartupSdo) {
    // 0x8012:05 = 3: 8000 full steps/s at full scale (four times the default).
    PlantBus b(kStepper, {{0x8012, 0x05, 3, 1}});
    b.set("ec0.s2.driveControl01", 1);
    b.set("ec0.s2.velocitySetpoint01", 8192);
    b.cycles(500);
    EXPECT_NEAR(b.plant->find_stage("x")->velocity(), 4 * 8192.0 / 32767 * 2000 / 200, 1e-3);
}

TEST(Plant, LimitSwitchesHomeCamAndHardStopStall) {
    PlantBus b(kStepper);
    sim::Stage* x = b.plant->find_stage("x");
    b.cycles(3);
    // Normally closed limits read 1 away from the limit; the home cam (normally open) reads 1 on it.
    EXPECT_EQ(b.get("ec0.s1.binaryInput01"), 1u);
    EXPECT_EQ(b.get("ec0.s1.binaryInput02"), 1u);
    EXPECT_EQ(b.get("ec0.s1.binaryInput03"), 1u);
    b.set("ec0.s2.driveControl01", 1);
    b.set("ec0.s2.velocitySetpoint01", 32767); // 10 mm/s
    b.cycles(100);
    EXPECT_EQ(b.get("ec0.s1.binaryInput03"), 0u); // left the cam (0.5 mm)
    b.cycles(750);                                 // 8.5 mm: past the forward limit
    EXPECT_EQ(b.get("ec0.s1.binaryInput01"), 0u);
    EXPECT_EQ(b.get("ec0.s1.binaryInput02"), 1u);
    b.cycles(500); // into the hard stop at 10 mm: the motor stalls
    EXPECT_DOUBLE_EQ(x->position(), 10.0);
    uint64_t st = b.get("ec0.s2.driveStatus01");
    EXPECT_TRUE(st & 0x80) << std::hex << st; // motor stall
    EXPECT_TRUE(st & 0x04) << std::hex << st; // warning
    // Backwards: the stall clears and the stage leaves the stop.
    b.set("ec0.s2.velocitySetpoint01", uint64_t(int64_t(-32767)));
    b.cycles(300);
    EXPECT_LT(x->position(), 8.0);
    st = b.get("ec0.s2.driveStatus01");
    EXPECT_FALSE(st & 0x80) << std::hex << st;
    EXPECT_TRUE(st & 0x20) << std::hex << st; // moving negative
    EXPECT_EQ(b.get("ec0.s1.binaryInput01"), 1u);
}

TEST(Plant, StepperErrorLatchesUntilReset) {
    PlantBus b(kStepper);
    b.set("ec0.s2.driveControl01", 1);
    b.set("ec0.s2.velocitySetpoint01", 8192);
    b.cycles(50);
    b.plant->find_stage("x")->drive()->inject_fault();
    b.cycles(100);
    uint64_t st = b.get("ec0.s2.driveStatus01");
    EXPECT_TRUE(st & 0x08) << std::hex << st; // error
    EXPECT_FALSE(st & 0x02);                  // power stage off
    EXPECT_NEAR(b.plant->find_stage("x")->velocity(), 0.0, 1e-9); // friction stopped it
    b.set("ec0.s2.driveControl01", 1 | 2); // enable + reset (rising edge)
    b.cycles(3);
    b.set("ec0.s2.driveControl01", 1);
    b.cycles(3);
    st = b.get("ec0.s2.driveStatus01");
    EXPECT_FALSE(st & 0x08) << std::hex << st;
    EXPECT_TRUE(st & 0x02) << std::hex << st;
}

namespace {
const char* kServo = R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7211}
stages:
  - {name: rot, drive: s1, pitch: 360, travel: [-720, 720], max_force: 50, quick_stop_decel: 720}
)";
uint16_t state_bits(uint64_t sw) { return uint16_t(sw & 0x6F); }
} // namespace

TEST(Plant, Cia402StateMachineAndVelocityMode) {
    using S = sim::Cia402Terminal;
    PlantBus b(kServo);
    auto* drv = static_cast<S*>(b.plant->find_stage("rot")->drive());
    b.cycles(3);
    EXPECT_EQ(drv->state(), S::State::SwitchOnDisabled);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x40);
    EXPECT_TRUE(b.get("ec0.s1.driveStatus01") & 0x200); // remote
    // Enable operation before shutdown/switch on is not a valid command sequence: no change.
    b.set("ec0.s1.driveControl01", 0x0F);
    b.cycles(3);
    EXPECT_EQ(drv->state(), S::State::SwitchOnDisabled);
    b.set("ec0.s1.driveControl01", 0x06); // shutdown
    b.cycles(3);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x21);
    b.set("ec0.s1.driveControl01", 0x07); // switch on
    b.cycles(3);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x23);
    EXPECT_TRUE(b.get("ec0.s1.driveStatus01") & 0x10); // voltage enabled
    // Enable operation with 0.25 rev/s = 90 deg/s (2^31 digits = 8000 rev/s).
    b.set("ec0.s1.velocitySetpoint01", uint64_t(int64_t(std::llround(0.25 * 268435.456))));
    b.set("ec0.s1.driveControl01", 0x0F);
    b.cycles(1000);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x27);
    sim::Stage* rot = b.plant->find_stage("rot");
    EXPECT_NEAR(rot->velocity(), 90.0, 1e-3);
    EXPECT_NEAR(double(b.get_signed("ec0.s1.velocityActual01")), 0.25 * 268435.456, 2);
    // Resolver feedback: 2^20 counts per revolution, absolute.
    // (inputs are sampled after a frame and read by the next: one cycle, 0.09 deg, behind)
    EXPECT_NEAR(double(b.get_signed("ec0.s1.positionActual01")), (rot->position() - 0.09) / 360 * 1048576, 2);
    // Quick stop: ramps down at 720 deg/s^2 (125 ms from 90 deg/s), then SWITCH ON DISABLED.
    b.set("ec0.s1.driveControl01", 0x0B);
    b.cycles(2);
    EXPECT_EQ(drv->state(), S::State::QuickStopActive);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x07);
    b.cycles(200);
    EXPECT_EQ(drv->state(), S::State::SwitchOnDisabled);
    EXPECT_NEAR(rot->velocity(), 0.0, 1e-6);
    // Fault and fault reset (rising edge of bit 7).
    b.set("ec0.s1.driveControl01", 0x06);
    b.cycles(2);
    drv->inject_fault();
    b.cycles(2);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x08);
    b.set("ec0.s1.driveControl01", 0x86);
    b.cycles(2);
    b.set("ec0.s1.driveControl01", 0x06);
    b.cycles(2);
    EXPECT_EQ(state_bits(b.get("ec0.s1.driveStatus01")), 0x21); // reset -> disabled -> shutdown -> ready
}

TEST(Plant, ServoBlockedAtTheHardStopFaultsOnOverload) {
    PlantBus b(kServo);
    auto* drv = static_cast<sim::Cia402Terminal*>(b.plant->find_stage("rot")->drive());
    for (uint16_t cw : {0x06, 0x07, 0x0F}) {
        b.set("ec0.s1.driveControl01", cw);
        b.cycles(2);
    }
    b.set("ec0.s1.velocitySetpoint01", uint64_t(int64_t(std::llround(2.0 * 268435.456)))); // 720 deg/s
    b.cycles(1500); // reaches +720 after ~1 s, then pushes against the stop
    EXPECT_EQ(drv->state(), sim::Cia402Terminal::State::OperationEnabled);
    b.cycles(1200); // saturated for more than overload_time (1 s)
    EXPECT_EQ(drv->state(), sim::Cia402Terminal::State::Fault);
    EXPECT_DOUBLE_EQ(b.plant->find_stage("rot")->position(), 720.0);
}

TEST(Plant, EncoderTerminalWithSetCounter) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7041}
  - {position: 2, type: EL5101}
  - {position: 3, type: EL5042}
stages:
  - name: y
    drive: s1
    start: 2
    encoders:
      - {entry: s2.positionActual01, counts_per_unit: 1000}
      - {entry: s3.positionActual01, counts_per_unit: 100000, absolute: true, zero: -1}
)");
    b.cycles(3);
    EXPECT_EQ(b.get("ec0.s2.positionActual01"), 0u);                  // incremental: 0 at power-up
    EXPECT_EQ(b.get("ec0.s3.positionActual01"), uint64_t(3 * 100000)); // absolute: (2 - -1) x 1e5
    b.set("ec0.s1.driveControl01", 1);
    b.set("ec0.s1.velocitySetpoint01", 32767); // 10 mm/s
    b.cycles(500);
    double x = b.plant->find_stage("y")->position();
    EXPECT_NEAR(double(b.get("ec0.s2.positionActual01")), (x - 0.01 - 2) * 1000, 2); // one cycle behind
    // Set counter: value 1000, control bit 2; status bit 2 reports it done.
    b.set("ec0.s1.velocitySetpoint01", 0);
    b.cycles(300);
    b.set("ec0.s2.encoderValue01", 1000);
    b.set("ec0.s2.encoderControl01", 4);
    b.cycles(3);
    EXPECT_EQ(b.get("ec0.s2.positionActual01"), 1000u);
    EXPECT_TRUE(b.get("ec0.s2.encoderStatus01") & 4);
    b.set("ec0.s2.encoderControl01", 0);
    b.cycles(2);
    EXPECT_FALSE(b.get("ec0.s2.encoderStatus01") & 4);
}

TEST(Plant, SignalGeneratorsAndStageSensor) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL3104}
  - {position: 2, type: EL7041}
  - {position: 3, type: EL3702}
stages:
  - {name: z, drive: s2, start: 3}
signals:
  - {to: s1.analogInput01, shape: sine, amplitude: 5, frequency: 1}
  - {to: s1.analogInput02, shape: constant, offset: 12}
  - {to: s1.analogInput03, stage: z, gain: 0.5, offset: -1}
  - {to: s1.analogInput04, shape: ramp, amplitude: 2, frequency: 10}
  - {to: s3.analogInputArray01_1, shape: square, amplitude: 1}
)");
    b.cycles(250); // t = 250 ms after the first frame: sin(pi/2) = 1
    EXPECT_NEAR(double(b.get_signed("ec0.s1.analogInput01")), 5 * 3276.7, 2);
    EXPECT_EQ(b.get_signed("ec0.s1.analogInput02"), 32767); // 12 V clips at 10 V
    uint64_t st = b.get("ec0.s1.status02");
    EXPECT_TRUE(st & 0x2) << std::hex << st;  // overrange
    EXPECT_TRUE(st & 0x40) << std::hex << st; // error
    EXPECT_FALSE(b.get("ec0.s1.status01") & 0x43);
    EXPECT_NEAR(double(b.get_signed("ec0.s1.analogInput03")), (0.5 * 3 - 1) * 3276.7, 1);
    // The status toggle bit flips with every new sample.
    uint64_t t1 = b.get("ec0.s1.status01") & 0x8000;
    b.cycles(1);
    EXPECT_NE(b.get("ec0.s1.status01") & 0x8000, t1);
    EXPECT_EQ(std::llabs(b.get_signed("ec0.s3.analogInputArray01_1")), 3277);
    // EL3702 counts its samples: one per cycle.
    uint64_t c0 = b.get("ec0.s3.cycleCounter01");
    b.cycles(10);
    EXPECT_EQ(b.get("ec0.s3.cycleCounter01"), (c0 + 10) & 0xFFFF);
}

TEST(Plant, El1252TimestampsEdgesOfAWiredOutput) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL2008}
  - {position: 2, type: EL1252}
wiring:
  - {from: s1.binaryOutput01, to: s2.binaryInput01}
)");
    b.cycles(3);
    EXPECT_EQ(b.get("ec0.s2.timestampLatchPositive01"), 0u);
    b.set("ec0.s1.binaryOutput01", 1);
    b.cycles(2);
    uint64_t tp = b.get("ec0.s2.timestampLatchPositive01");
    EXPECT_GT(tp, 1'000'000'000u);
    b.cycles(5);
    b.set("ec0.s1.binaryOutput01", 0);
    b.cycles(2);
    uint64_t tn = b.get("ec0.s2.timestampLatchNegative01");
    EXPECT_GE(tn, tp + 5'000'000u); // at least the 5 ms the output stayed on
}

// EL2252: the pins switch at startTime (armed by activate 0 -> 3, ecmccfg's sequence), between
// frames; a cabled EL1252 latches that time, on the same time base (both get the bus's system
// time). A start time already past when armed never fires; activate 0 cancels an armed event.
TEST(Plant, El2252SwitchesAtItsStartTime) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL2252}
  - {position: 2, type: EL1252}
wiring:
  - {from: s1.binaryOutput01, to: s2.binaryInput01}
)");
    b.cycles(3);
    const uint64_t now = b.m->dc_reference_time(); // the frame of the last cycle
    ASSERT_GT(now, 0u);
    const uint64_t at = now + 2'345'678; // 2.35 ms ahead: between frames
    b.set("ec0.s1.startTime", at);
    b.set("ec0.s1.binaryOutput01", 1);
    b.set("ec0.s1.activate", 0);
    b.cycles(1);
    b.set("ec0.s1.activate", 3);
    b.cycles(1);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->level[0], false); // not yet
    b.cycles(3);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->level[0], true);
    EXPECT_EQ(b.get("ec0.s2.timestampLatchPositive01"), at);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->events, 1u);
    // a start time in the past: never fires, counted
    b.set("ec0.s1.binaryOutput01", 0);
    b.set("ec0.s1.startTime", b.m->dc_reference_time() - 1000);
    b.set("ec0.s1.activate", 0);
    b.cycles(1);
    b.set("ec0.s1.activate", 3);
    b.cycles(5);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->level[0], true);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->missed, 1u);
    // armed, then cancelled by activate 0 before its time
    b.set("ec0.s1.startTime", b.m->dc_reference_time() + 10'000'000);
    b.set("ec0.s1.activate", 0);
    b.cycles(1);
    b.set("ec0.s1.activate", 3);
    b.cycles(2);
    b.set("ec0.s1.activate", 0);
    b.cycles(20);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->level[0], true);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->events, 1u);
    // the falling edge at its time
    const uint64_t off = b.m->dc_reference_time() + 3'500'001;
    b.set("ec0.s1.startTime", off);
    b.cycles(1);
    b.set("ec0.s1.activate", 3);
    b.cycles(5);
    EXPECT_EQ(b.plant->timed_outputs.at(0)->level[0], false);
    EXPECT_EQ(b.get("ec0.s2.timestampLatchNegative01"), off);
}

TEST(Plant, DrivesWithoutAPlantMoveDefaultStages) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL7041}
  - {position: 2, type: EL7211}
)");
    ASSERT_EQ(b.plant->stages().size(), 2u);
    ASSERT_NE(b.plant->find_stage("s1"), nullptr);
    ASSERT_NE(b.plant->find_stage("s2"), nullptr);
    b.set("ec0.s1.driveControl01", 1);
    b.set("ec0.s1.velocitySetpoint01", 3277); // 1 mm/s
    b.cycles(500);
    EXPECT_GT(b.get("ec0.s1.positionActual01"), 0u);
    EXPECT_NEAR(b.plant->find_stage("s1")->velocity(), 1.0, 1e-3);
}

TEST(Plant, StepsAllocateNothingPerCycle) {
    PlantBus b(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL1008}
  - {position: 2, type: EL2008}
  - {position: 3, type: EL3104}
  - {position: 4, type: EL7041}
  - {position: 5, type: EL7211}
  - {position: 6, type: EL5101}
  - {position: 7, type: EL3702}
  - {position: 8, type: EL1252}
wiring:
  - {from: s2.binaryOutput01, to: s8.binaryInput01}
stages:
  - name: x
    drive: s4
    travel: [-5, 5]
    limits: {forward: {input: s1.binaryInput01, at: 4}, backward: {input: s1.binaryInput02, at: -4}}
    encoders: [{entry: s6.positionActual01, counts_per_unit: 1000}]
signals:
  - {to: s3.analogInput01, shape: noise, amplitude: 1}
  - {to: s3.analogInput02, stage: x, gain: 1, noise: 0.01}
)");
    b.set("ec0.s4.driveControl01", 1);
    b.set("ec0.s4.velocitySetpoint01", 32767);
    b.cycles(10); // first frames in OP read CoE parameters
    const SignalInfo& out = b.sig("ec0.s2.binaryOutput01");
    test::count_allocations(true);
    for (int i = 0; i < 10000; ++i) {
        if (i % 100 == 0) b.m->set(out, (i / 100) & 1);
        b.cycles(1);
    }
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_GE(b.plant->steps, 10000u);
}

namespace {
std::string config_error(const std::string& yaml) {
    try {
        sim::SimConfig::parse(yaml, "plant.yaml", Catalog::builtin());
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}
const char* kSlaves = "slaves:\n  - {position: 0, type: EL1008}\n  - {position: 1, type: EL7041}\n  - {position: 2, type: EL3104}\n";
} // namespace

TEST(Plant, ConfigurationErrorsNameTheirPlace) {
    auto has = [](const std::string& e, const std::string& part) { return e.find(part) != std::string::npos; };
    std::string e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s1, weight: 3}\n");
    EXPECT_TRUE(has(e, "plant.yaml:6:") && has(e, "unknown key 'weight'")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s0}\n");
    EXPECT_TRUE(has(e, "plant.yaml:6:") && has(e, "EL1008, not a drive")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s1, travel: [5, -5]}\n");
    EXPECT_TRUE(has(e, "plant.yaml:6:") && has(e, "should be below max")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s1, travel: [-5, 5], start: 9}\n");
    EXPECT_TRUE(has(e, "outside travel")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s1, mass: -1}\n");
    EXPECT_TRUE(has(e, "mass should be > 0")) << e;
    e = config_error(std::string(kSlaves) +
                     "stages:\n  - name: x\n    drive: s1\n    limits:\n      forward: {input: s0.binaryInput01, at: 1}\n"
                     "      backward: {input: s0.binaryInput01, at: -1}\n");
    EXPECT_TRUE(has(e, "plant.yaml:10:") && has(e, "already driven (by plant.yaml:9:")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - name: x\n    drive: s1\n    home: {input: s0.binaryInput09, at: 0}\n");
    EXPECT_TRUE(has(e, "plant.yaml:8:") && has(e, "no process-data entry 'binaryInput09'")) << e;
    e = config_error(std::string(kSlaves) + "signals:\n  - {to: s0.binaryInput01, shape: sine}\n");
    EXPECT_TRUE(has(e, "has 1 bits; a signal drives a 16-bit analog input")) << e;
    e = config_error(std::string(kSlaves) + "signals:\n  - {to: s2.analogInput01, shape: triangle}\n");
    EXPECT_TRUE(has(e, "plant.yaml:6:") && has(e, "unknown shape 'triangle'")) << e;
    e = config_error(std::string(kSlaves) + "signals:\n  - {to: s2.analogInput01, stage: nope}\n");
    EXPECT_TRUE(has(e, "no stage named 'nope'")) << e;
    e = config_error(std::string(kSlaves) + "signals:\n  - {to: s1.positionActual01, shape: sine}\n");
    EXPECT_TRUE(has(e, "already driven (by the default stage of s1)")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: s1}\n  - {name: x, drive: s1}\n");
    EXPECT_TRUE(has(e, "plant.yaml:7:") && has(e, "defined twice")) << e;
    e = config_error(std::string(kSlaves) + "stages:\n  - {name: x, drive: 11}\n");
    EXPECT_TRUE(has(e, "should look like s<position>")) << e;
}
