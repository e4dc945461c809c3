// The rcp-sim model in virtual time: MODEL.yaml errors with file:line:col, the example file,
// signal shapes, the first-order plant, the tolerance status, the wrapping counter, setpoints,
// the motor (trapezoid, limits, homing, jog, enable, duplicates), packets and determinism.
#include "bridge/rcp/model.hpp"

#include "core/error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::bridge::rcp;

namespace {

const std::filesystem::path kExample = std::filesystem::path(__FILE__).parent_path() / ".." / ".." /
                                       ".." / "examples" / "rcp" / "model.yaml";

Model model(const std::string& yaml) {
    return Model(ModelConfig::parse(yaml, "m.yaml"));
}

std::string error_of(const std::string& yaml) {
    try {
        ModelConfig::parse(yaml, "m.yaml");
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

DataEntry write(const Model& m, const std::string& name, const std::vector<double>& v) {
    for (const ObjectSpec& o : m.config().objects)
        if (o.name == name)
            return DataEntry{
                o.id, o.type, o.data_type, uint16_t(v.size()), o.name, std::span<const double>(v)};
    ADD_FAILURE() << "no object " << name;
    return {};
}

// A MOTOR command entry; `cmd` values (command, target, velocity, acceleration, sequence).
Malformed command(Model& m, const std::string& name, std::vector<double> cmd) {
    DataEntry e = write(m, name, cmd);
    return m.apply_write(e);
}

void run(Model& m, double seconds, double dt = 0.001) {
    for (int i = 0, n = int(std::lround(seconds / dt)); i < n; ++i) m.step(dt);
}

const char* kPlant = R"(
application: test
rate_hz: 1000
objects:
  - {id: 1, name: Set, type: AO, setpoint: {initial: 0, min: -5, max: 5}}
  - {id: 2, name: Enable, type: BO, setpoint: {initial: 1}}
  - {id: 3, name: Out, type: AI, plant: {input: Set, time_constant_s: 0.5, gain: 2, enable: Enable}}
  - {id: 4, name: Settled, type: BI, within: {value: Out, target: Set, tolerance: 0.01}}
  - {id: 5, name: Count, type: LI, data_type: int8, counter: {step: 100}}
)";

const char* kMotor = R"(
application: test
objects:
  - id: 1
    name: M
    type: MOTOR
    motor: {position: 0, velocity: 2, max_velocity: 4, acceleration: 10, max_acceleration: 20,
            soft_limits: [-8, 8], hard_limits: [-10, 10], home_position: 1, home_velocity: 1}
  - {id: 2, name: Free, type: MOTOR, motor: {hard_limits: [-3, 3], velocity: 2, acceleration: 10}}
)";

} // namespace

TEST(RcpModel, ExampleModelLoads) {
    ModelConfig c = ModelConfig::load(kExample.string());
    Model m(c);
    EXPECT_EQ(c.application, "sgDemo");
    EXPECT_EQ(c.objects.size(), 17u);
    int motors = 0;
    for (const auto& o : c.objects) motors += o.type == ObjectType::Motor;
    EXPECT_EQ(motors, 1);
    auto beacons = m.beacon_packets();
    EXPECT_EQ(beacons.size(), 1u);
    std::vector<Packet> data;
    m.data_packets(data);
    EXPECT_GE(data.size(), 1u);
    DataPacket d;
    std::size_t entries = 0;
    for (const Packet& p : data) {
        ASSERT_TRUE(parse_data(std::span<const uint8_t>(p), d).ok());
        entries += d.entry_count;
    }
    EXPECT_EQ(entries, 17u) << "every object in every step";
}

TEST(RcpModel, ConfigurationErrorsSayWhereAndWhat) {
    EXPECT_EQ(
        error_of(
            "application: a\nobjects:\n  - {id: 1, name: X, type: AI, signal: {shap: sine}}\n"),
        "m.yaml:3:41: unknown key 'shap' in objects[0].signal (did you mean 'shape'?)");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: XY}\n"),
              "m.yaml:3:28: objects[0].type: unknown type 'XY' (expected AI AO BI BO LI LO MOTOR)");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 0, name: X, type: AI, signal: {}}\n"),
              "m.yaml:3:10: objects[0].id should be from 1 to 255, got 0");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: AO}\n  - {id: 1, "
                       "name: Y, type: AO}\n"),
              "m.yaml:4:5: objects[1]: object id 1 is used twice");
    EXPECT_EQ(
        error_of(
            "application: a\nobjects:\n  - {id: 1, name: X, type: AI, plant: {input: Nope}}\n"),
        "m.yaml:3:5: objects[0]: plant input: no object named 'Nope'");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: AI, signal: {}}\n"
                       "  - {id: 2, name: Y, type: AI, plant: {input: X}}\n"),
              "m.yaml:4:5: objects[1]: plant input: 'X' is a AI object");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: LI, data_type: "
                       "float64, counter: {}}\n"),
              "m.yaml:3:5: objects[0]: counter: needs an integer data_type (got float64)");
    EXPECT_EQ(
        error_of(
            "application: a\nobjects:\n  - {id: 1, name: X, type: AI, count: 120, signal: {}}\n"),
        "m.yaml:3:39: objects[0].count: 120 of float64 does not fit one data packet (at most "
        "118)");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: AI}\n"),
              "m.yaml:3:5: objects[0]: a AI object needs a behaviour (signal:, plant:, within: or "
              "counter:)");
    EXPECT_EQ(error_of("application: a b\nobjects: []\n"),
              "m.yaml:1:14: application: 'a b' should be 1..39 characters of [A-Za-z0-9_:.-]\n"
              "m.yaml:2:10: objects: should be a non-empty list")
        << "every error of the file";
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: X, type: LO, data_type: int8, "
                       "setpoint: {initial: 300}}\n"),
              "m.yaml:3:69: objects[0].setpoint.initial: 300 is not a int8 value");
    EXPECT_EQ(error_of("application: a\nrate_hz: -1\nobjects:\n  - {id: 1, name: X, type: AO}\n"),
              "m.yaml:2:10: rate_hz should be > 0 and <= 100000, got -1");
    EXPECT_EQ(error_of("application: a\nobjects:\n  - {id: 1, name: M, type: MOTOR, motor: "
                       "{hard_limits: [1, 0]}}\n"),
              "m.yaml:3:56: objects[0].motor.hard_limits: low 1 should be below high 0");
    EXPECT_EQ(error_of("application: [a\n"),
              "m.yaml:2:1: YAML syntax error: end of sequence flow not found");
    EXPECT_NE(error_of("bogus: 1\n").find("m.yaml:1:1: unknown key 'bogus' in the model"),
              std::string::npos);
}

TEST(RcpModel, SignalShapes) {
    Model m = model(R"(
application: s
objects:
  - {id: 1, name: Sin, type: AI, signal: {shape: sine, amplitude: 2, frequency_hz: 1, offset: 1}}
  - {id: 2, name: Sq, type: AI, signal: {shape: square, amplitude: 3, frequency_hz: 1}}
  - {id: 3, name: Ramp, type: AI, signal: {shape: ramp, amplitude: 10, frequency_hz: 1}}
  - {id: 4, name: Bit, type: BI, signal: {shape: square, frequency_hz: 1}}
  - {id: 5, name: Int, type: LI, data_type: int16, signal: {shape: sine, amplitude: 100.4, frequency_hz: 1}}
  - {id: 6, name: Wave, type: AI, count: 4, signal: {shape: ramp, amplitude: 1, frequency_hz: 1}}
)");
    EXPECT_NEAR(m.value("Sin"), 1, 1e-12);
    m.step(0.25);
    EXPECT_NEAR(m.value("Sin"), 3, 1e-12);
    EXPECT_EQ(m.value("Sq"), 3);
    EXPECT_NEAR(m.value("Ramp"), 2.5, 1e-12);
    EXPECT_EQ(m.value("Bit"), 1);
    EXPECT_EQ(m.value("Int"), 100) << "rounded to the integer type";
    auto w = m.values("Wave");
    ASSERT_EQ(w.size(), 4u);
    EXPECT_NEAR(w[0], 0.25, 1e-12);
    EXPECT_NEAR(w[1], 0.5, 1e-12);
    EXPECT_NEAR(w[3], 0.0, 1e-12) << "1.0 wraps";
    m.step(0.5);
    EXPECT_EQ(m.value("Sq"), -3);
    EXPECT_EQ(m.value("Bit"), 0);
    EXPECT_EQ(m.value("Int"), -100);
}

TEST(RcpModel, PlantFollowsItsSetpointWithAFirstOrderResponse) {
    Model m = model(kPlant);
    EXPECT_EQ(m.value("Out"), 0);
    ASSERT_EQ(m.apply_write(write(m, "Set", {1.5})), Malformed::None);
    // y(t) = gain * u * (1 - exp(-t / tau)), exactly at every step
    for (int i = 1; i <= 500; ++i) {
        m.step(0.001);
        ASSERT_NEAR(m.value("Out"), 3.0 * (1 - std::exp(-i * 0.001 / 0.5)), 1e-12) << "step " << i;
    }
    EXPECT_NEAR(m.value("Out"), 3.0 * (1 - std::exp(-1.0)), 1e-12);
    EXPECT_EQ(m.value("Settled"), 0);
    // The same time in larger steps gives the same value (exact discretisation).
    Model coarse = model(kPlant);
    coarse.apply_write(write(coarse, "Set", {1.5}));
    coarse.step(0.25);
    coarse.step(0.25);
    EXPECT_NEAR(coarse.value("Out"), m.value("Out"), 1e-12);
    // Gain 2 never settles on the setpoint; a setpoint of 0 does.
    m.apply_write(write(m, "Set", {0}));
    run(m, 5);
    EXPECT_NEAR(m.value("Out"), 0, 1e-4);
    EXPECT_EQ(m.value("Settled"), 1);
    // Disabled: the output holds.
    m.apply_write(write(m, "Set", {2}));
    m.apply_write(write(m, "Enable", {0}));
    run(m, 1);
    EXPECT_NEAR(m.value("Out"), 0, 1e-4);
    // Setpoints are clamped to their limits.
    m.apply_write(write(m, "Set", {99}));
    EXPECT_EQ(m.value("Set"), 5);
}

TEST(RcpModel, CounterWrapsInItsDataType) {
    Model m = model(kPlant);
    std::vector<double> seen;
    for (int i = 0; i < 4; ++i) {
        m.step(0.001);
        seen.push_back(m.value("Count"));
    }
    EXPECT_EQ(seen, (std::vector<double>{100, -56, 44, -112}));
    Model big = model(
        "application: c\nobjects:\n  - {id: 1, name: C, type: LI, counter: {step: 2147483647}}\n");
    big.step(0.001);
    big.step(0.001);
    EXPECT_EQ(big.value("C"), -2);
}

TEST(RcpModel, WritesAreCheckedAgainstTheModel) {
    Model m = model(kPlant);
    std::vector<double> one{1};
    EXPECT_EQ(m.apply_write(write(m, "Out", {1})), Malformed::NotWritable);
    DataEntry e = write(m, "Set", {1});
    e.type = ObjectType::LO;
    EXPECT_EQ(m.apply_write(e), Malformed::TypeMismatch);
    e = write(m, "Set", {1});
    e.data_type = DataType::Float32;
    EXPECT_EQ(m.apply_write(e), Malformed::TypeMismatch);
    e = write(m, "Set", {1});
    e.name = "Sett";
    EXPECT_EQ(m.apply_write(e), Malformed::NameMismatch);
    EXPECT_EQ(m.apply_write(write(m, "Set", {1, 2})), Malformed::CountMismatch);
    e = write(m, "Set", {1});
    e.id = 99;
    EXPECT_EQ(m.apply_write(e), Malformed::UnknownObject);
    EXPECT_EQ(m.value("Set"), 0) << "nothing applied";
}

TEST(RcpModel, MotorMovesWithinItsVelocityAndAcceleration) {
    Model m = model(kMotor);
    const MotorState* s = m.motor("M");
    ASSERT_NE(s, nullptr);
    EXPECT_EQ(m.values("M")[2], double(motor_status::kDone | motor_status::kEnabled));
    ASSERT_EQ(command(m, "M", {1, 5, 3, 10, 1}), Malformed::None);
    EXPECT_EQ(uint32_t(m.values("M")[2]) & motor_status::kDone, 0u) << "busy at once";
    double vmax = 0, prev_v = 0, amax = 0;
    int steps = 0;
    while (s->mode != MotorState::Mode::Idle && steps < 10000) {
        m.step(0.001);
        ++steps;
        if (s->mode == MotorState::Mode::Idle) break; // the arrival step stops on the target
        vmax = std::max(vmax, std::fabs(s->velocity));
        amax = std::max(amax, std::fabs(s->velocity - prev_v) / 0.001);
        prev_v = s->velocity;
        EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kMoving, 0u);
    }
    EXPECT_EQ(s->position, 5);
    EXPECT_LE(vmax, 3 + 1e-9);
    EXPECT_GT(vmax, 2.9);
    EXPECT_LE(amax, 10 + 1e-6);
    // trapezoid: distance / velocity + velocity / acceleration
    EXPECT_NEAR(steps * 0.001, 5.0 / 3 + 3.0 / 10, 0.02);
    EXPECT_EQ(uint32_t(m.values("M")[2]), motor_status::kDone | motor_status::kEnabled);
    // Velocity and acceleration beyond the maxima are clamped; <= 0 takes the defaults.
    command(m, "M", {1, 0, 100, 100, 2});
    EXPECT_EQ(s->v_max, 4);
    EXPECT_EQ(s->accel, 20);
    command(m, "M", {1, 0, 0, -1, 3});
    EXPECT_EQ(s->v_max, 2);
    EXPECT_EQ(s->accel, 10);
}

TEST(RcpModel, MotorRefusesTargetsOutsideItsSoftLimitsAndWhenDisabled) {
    Model m = model(kMotor);
    const MotorState* s = m.motor("M");
    command(m, "M", {1, 9, 1, 1, 1});
    EXPECT_EQ(s->mode, MotorState::Mode::Idle);
    EXPECT_EQ(m.values("M")[4], 1);
    EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kError, 0u);
    EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kDone, 0u);
    command(m, "M", {8, 0, 0, 0, 2}); // disable
    EXPECT_EQ(uint32_t(m.values("M")[2]) & motor_status::kEnabled, 0u);
    command(m, "M", {1, 2, 1, 1, 3});
    EXPECT_EQ(m.values("M")[4], 2);
    command(m, "M", {7, 0, 0, 0, 4}); // enable clears the error
    EXPECT_EQ(m.values("M")[4], 0);
    command(m, "M", {42, 0, 0, 0, 5});
    EXPECT_EQ(m.values("M")[4], 3);
    command(m, "M", {1, NAN, 1, 1, 6});
    EXPECT_EQ(m.values("M")[4], 4);
}

TEST(RcpModel, RepeatedDatagramsAreIgnored) {
    Model m = model(kMotor);
    const MotorState* s = m.motor("M");
    auto done = [&] { return (uint32_t(m.values("M")[2]) & motor_status::kDone) != 0; };
    command(m, "M", {1, 2, 1, 1, 7});
    run(m, 5);
    EXPECT_EQ(s->position, 2);
    EXPECT_TRUE(done());
    command(m, "M", {1, 2, 1, 1, 7}); // the same datagram again
    EXPECT_TRUE(done()) << "not taken as a new command";
    command(m, "M", {1, 2, 1, 1, 8}); // the same move as a new command
    EXPECT_FALSE(done());
    run(m, 1);
    command(m, "M", {1, 4, 1, 1, 8}); // a new command with a reused number (an IOC restarted)
    run(m, 5);
    EXPECT_EQ(s->position, 4);
}

TEST(RcpModel, HardLimitStopsAJogOnTheSwitch) {
    Model m = model(kMotor);
    const MotorState* s = m.motor("Free");
    command(m, "Free", {5, 0, 2, 10, 1}); // jog forward, no soft limits
    run(m, 3);
    EXPECT_EQ(s->position, 3);
    EXPECT_EQ(s->mode, MotorState::Mode::Idle);
    uint32_t b = uint32_t(m.values("Free")[2]);
    EXPECT_NE(b & motor_status::kHighLimit, 0u);
    EXPECT_NE(b & motor_status::kDone, 0u);
    command(m, "Free", {1, 0, 2, 10, 2}); // away from the switch
    run(m, 3);
    EXPECT_EQ(s->position, 0);
    EXPECT_EQ(uint32_t(m.values("Free")[2]) & motor_status::kHighLimit, 0u);
    // With soft limits a jog ends on the soft limit.
    const MotorState* t = m.motor("M");
    command(m, "M", {6, 0, 4, 20, 1});
    run(m, 5);
    EXPECT_EQ(t->position, -8);
    EXPECT_EQ(t->mode, MotorState::Mode::Idle);
}

TEST(RcpModel, HomingSearchesReversesAtTheLimitAndStopsOnHome) {
    Model m = model(kMotor);
    const MotorState* s = m.motor("M");
    command(m, "M", {1, 5, 4, 20, 1});
    run(m, 5);
    ASSERT_EQ(s->position, 5);
    command(m, "M", {3, 0, 0, 0, 2}); // home forward: away from home (1) first
    EXPECT_FALSE(s->homed);
    bool hit_limit = false;
    for (int i = 0; i < 40000 && s->mode != MotorState::Mode::Idle; ++i) {
        m.step(0.001);
        hit_limit = hit_limit || s->high_limit;
    }
    EXPECT_TRUE(hit_limit) << "searched forward to the switch";
    EXPECT_EQ(s->mode, MotorState::Mode::Idle);
    EXPECT_EQ(s->position, 1);
    EXPECT_TRUE(s->homed);
    EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kHomed, 0u);
    // Home reverse from below home: crosses it while searching, comes back onto it.
    command(m, "M", {1, -2, 4, 20, 3});
    run(m, 5);
    command(m, "M", {4, 0, 0, 0, 4});
    run(m, 30);
    EXPECT_EQ(s->position, 1);
    EXPECT_TRUE(s->homed);
}

TEST(RcpModel, CommandsShowNotDoneInTheNextStep) {
    Model m = model(kMotor);
    command(m, "M", {1, 0, 1, 1, 1}); // a null move
    m.step(0.001);
    EXPECT_EQ(uint32_t(m.values("M")[2]) & motor_status::kDone, 0u);
    m.step(0.001);
    EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kDone, 0u);
    command(m, "M", {2, 0, 0, 0, 2}); // stop at rest: nothing to show
    EXPECT_NE(uint32_t(m.values("M")[2]) & motor_status::kDone, 0u);
}

TEST(RcpModel, BeaconsContinueAfter17Objects) {
    std::string yaml = "application: many\nlisten: {host: 10.1.2.3, port: 7000}\nioc: {host: "
                       "10.1.2.4, port: 18065, data_port: 18070}\nobjects:\n";
    for (int i = 1; i <= 20; ++i)
        yaml += "  - {id: " + std::to_string(i) + ", name: s" + std::to_string(i) +
                ", type: AI, signal: {}}\n";
    Model m = model(yaml);
    auto b = m.beacon_packets();
    ASSERT_EQ(b.size(), 2u);
    Beacon first, second;
    ASSERT_TRUE(parse_beacon(std::span<const uint8_t>(b[0]), first).ok());
    ASSERT_TRUE(parse_beacon(std::span<const uint8_t>(b[1]), second).ok());
    EXPECT_FALSE(first.continuation);
    EXPECT_TRUE(second.continuation);
    EXPECT_EQ(first.objects.size(), 17u);
    EXPECT_EQ(second.objects.size(), 3u);
    EXPECT_EQ(second.objects[2].name, "s20");
    EXPECT_EQ(first.objects[0].ip_rcp, 0x0A010203u);
    EXPECT_EQ(first.objects[0].port_rcp, 7000);
    EXPECT_EQ(first.objects[0].ip_ioc, 0x0A010204u);
    EXPECT_EQ(first.objects[0].port_ioc, 18070);
    m.set_listen_port(7001);
    ASSERT_TRUE(parse_beacon(std::span<const uint8_t>(m.beacon_packets()[0]), first).ok());
    EXPECT_EQ(first.objects[0].port_rcp, 7001);
    std::vector<Packet> d;
    m.data_packets(d);
    EXPECT_EQ(d.size(), 2u) << "20 float64 entries of 53 bytes need two packets";
}

TEST(RcpModel, SameWritesAndStepsGiveTheSamePackets) {
    ModelConfig c = ModelConfig::load(kExample.string());
    Model a(c), b(c);
    std::vector<Packet> pa, pb;
    for (int i = 0; i < 3000; ++i) {
        if (i == 100) {
            for (Model* m : {&a, &b}) {
                m->apply_write(write(*m, "Setpoint", {2.5}));
                command(*m, "Stage", {1, 10, 5, 50, 1});
            }
        }
        a.step(0.01);
        b.step(0.01);
        a.data_packets(pa);
        b.data_packets(pb);
        ASSERT_EQ(pa, pb) << "step " << i;
    }
    EXPECT_NEAR(a.value("PlantOut"), 2.5, 1e-6);
    EXPECT_EQ(a.value("InTolerance"), 1);
    EXPECT_EQ(a.motor("Stage")->position, 10);
    EXPECT_EQ(a.value("Counter"), 3000);
}
