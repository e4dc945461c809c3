#include "motion/axis_config.hpp"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

using beamctl::Error;
using beamctl::MacroMap;
using beamctl::SourceLoc;
using namespace beamctl::motion;

namespace {

const std::filesystem::path kData = std::filesystem::path(__FILE__).parent_path() / "data";

std::string data(const char* name) {
    return (kData / name).string();
}

std::string read(const std::string& path) {
    std::ifstream f(path);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
}

template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "<no error>";
}

// All problems of `text` as one string per problem.
std::vector<std::string> errors_of(const std::string& text, const MacroMap& macros = {}) {
    std::vector<Error> errors;
    parse_axis_config(text, "axis.yaml", macros, errors);
    std::vector<std::string> out;
    for (const auto& e : errors) out.push_back(e.what());
    return out;
}

std::string joined(const std::vector<std::string>& v) {
    std::string out;
    for (const auto& s : v) out += s + "\n";
    return out;
}

// The warnings of `text` (which must load).
std::vector<std::string> warnings_of(const std::string& text, const MacroMap& macros = {}) {
    std::vector<Error> errors;
    AxisConfig c = parse_axis_config(text, "axis.yaml", macros, errors);
    return c.warnings;
}

bool contains(const std::vector<std::string>& v, const std::string& part) {
    for (const auto& s : v)
        if (s.find(part) != std::string::npos) return true;
    return false;
}

// 1-based line and column of the first `needle` in `text`, as "line:col".
std::string where_in(const std::string& text, const std::string& needle) {
    const std::size_t at = text.find(needle);
    if (at == std::string::npos) return "<not found>";
    const std::size_t line_start = text.rfind('\n', at);
    const std::size_t col = line_start == std::string::npos ? at + 1 : at - line_start;
    const auto line = 1 + std::count(text.begin(), text.begin() + std::ptrdiff_t(at), '\n');
    return std::to_string(line) + ":" + std::to_string(col);
}

const MacroMap kStepperMacros = {{"DRV_SLAVE", "3"}, {"ENC_SLAVE", "4"}};

// A small valid joint axis.
const char* kMinimal = R"(axis:
  id: 1
drive:
  numerator: 10
  denominator: 32768
  setpoint: ec0.s3.velocitySetpoint01
  control: ec0.s3.driveControl01
  status: ec0.s3.driveStatus01
encoder:
  numerator: 1
  denominator: 12800
  position: ec0.s3.positionActual01
trajectory:
  axis:
    velocity: 1
    acceleration: 2
input:
  limit:
    forward: ec0.s3.driveStatus01.12
    backward: ec0.s3.driveStatus01.11
monitoring:
  target:
    enable: true
    tolerance: 0.01
    time: 10
)";

// kMinimal with `value` at the dotted `path` (intermediate mappings created), re-emitted.
std::string with_value(const std::string& path, const YAML::Node& value,
                       const char* base = kMinimal) {
    YAML::Node root = YAML::Load(base);
    YAML::Node n = root;
    std::stringstream parts(path);
    std::string part, last;
    std::vector<std::string> keys;
    while (std::getline(parts, part, '.')) keys.push_back(part);
    for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
        YAML::Node next = n[keys[i]];
        if (!next.IsMap()) n[keys[i]] = YAML::Node(YAML::NodeType::Map);
        n.reset(n[keys[i]]);
    }
    n[keys.back()] = value;
    YAML::Emitter out;
    out << root;
    return std::string(out.c_str()) + "\n";
}

std::string without(const std::string& path, const char* base = kMinimal) {
    YAML::Node root = YAML::Load(base);
    YAML::Node n = root;
    std::stringstream parts(path);
    std::vector<std::string> keys;
    std::string part;
    while (std::getline(parts, part, '.')) keys.push_back(part);
    for (std::size_t i = 0; i + 1 < keys.size(); ++i) n.reset(n[keys[i]]);
    n.remove(keys.back());
    YAML::Emitter out;
    out << root;
    return std::string(out.c_str()) + "\n";
}

} // namespace

// ---- fixtures ---------------------------------------------------------------------------------

TEST(AxisConfigFixtures, StepperLoadsWithValuesAndDefaults) {
    const AxisConfig c = load_axis_config(data("stepper_axis.yaml"), kStepperMacros);
    EXPECT_EQ(c.file, data("stepper_axis.yaml"));
    ASSERT_TRUE(c.axis.id.has_value());
    EXPECT_EQ(*c.axis.id, 1); // ${AX_ID=1}
    EXPECT_EQ(c.axis.type, AxisType::Joint);
    EXPECT_EQ(c.axis.mode, DriveMode::CSV);
    EXPECT_DOUBLE_EQ(c.axis.tweak_dist, 0.5);
    ASSERT_TRUE(c.axis.auto_enable.has_value());
    EXPECT_DOUBLE_EQ(c.axis.auto_enable->enable_timeout_s, 5.0);
    EXPECT_DOUBLE_EQ(c.axis.auto_enable->disable_timeout_s, 3.0);
    EXPECT_FALSE(c.axis.auto_enable->at_startup);
    EXPECT_TRUE(c.axis.features.allow_src_change_when_enabled);
    EXPECT_TRUE(c.axis.features.allow_homing);
    EXPECT_FALSE(c.axis.health_output.has_value());

    EXPECT_EQ(c.epics.name, "M1");
    EXPECT_EQ(c.epics.precision, 4);
    EXPECT_EQ(c.epics.motor_record.description, "Slit blade");
    EXPECT_EQ(c.epics.motor_record.field_init, "RTRY=0,FOFF=Frozen");
    EXPECT_TRUE(c.epics.motor_record.enable);

    ASSERT_TRUE(c.drive.has_value());
    const DriveConfig& d = *c.drive;
    EXPECT_EQ(d.type, DriveType::Stepper);
    EXPECT_DOUBLE_EQ(d.numerator, 10);
    EXPECT_EQ(d.denominator, 32768);
    EXPECT_EQ(d.setpoint.text, "ec0.s3.velocitySetpoint01");
    EXPECT_EQ(d.setpoint.slave, 3);
    EXPECT_EQ(d.setpoint.entry, "velocitySetpoint01");
    EXPECT_EQ(d.setpoint.bit, -1);
    EXPECT_EQ(d.control.entry, "driveControl01");
    EXPECT_EQ(d.status.entry, "driveStatus01");
    EXPECT_EQ(d.enable_bit, 0);
    EXPECT_EQ(d.enabled_bit, 1);
    EXPECT_EQ(d.reset_bit, 1);
    EXPECT_EQ(d.warning_bit, 2);
    EXPECT_EQ(d.reduce_torque_bit, 2);
    EXPECT_TRUE(d.reduce_torque_enable);
    ASSERT_EQ(d.errors.size(), 3u);
    EXPECT_EQ(d.errors[0].text, "ec0.s3.driveStatus01.3"); // a bit of drive.status
    EXPECT_EQ(d.errors[1].bit, 7);
    EXPECT_EQ(d.errors[2].text, "ec0.s3.driveStatus01.14"); // a link
    EXPECT_FALSE(d.brake.has_value());

    ASSERT_EQ(c.encoders.size(), 1u);
    const EncoderConfig& e = c.encoders[0];
    EXPECT_EQ(e.source, EncoderSource::EtherCAT);
    EXPECT_EQ(e.type, EncoderType::Absolute);
    EXPECT_EQ(e.bits, 32);
    EXPECT_EQ(e.abs_bits, 26);
    EXPECT_DOUBLE_EQ(e.abs_offset, -1408.794);
    ASSERT_TRUE(e.position.has_value());
    EXPECT_EQ(e.position->text, "ec0.s4.positionActual01"); // ${ENC_CHANNEL=01}
    EXPECT_EQ(e.ready_bit, 2);
    EXPECT_EQ(e.warning_bit, 0);
    ASSERT_EQ(e.errors.size(), 1u);
    EXPECT_EQ(e.errors[0].text, "ec0.s4.encoderStatus01.1");
    ASSERT_TRUE(e.homing.has_value());
    EXPECT_EQ(e.homing->type, 3);
    EXPECT_EQ(e.homing->position, -30);
    EXPECT_EQ(e.homing->velocity_to, 2);
    EXPECT_EQ(e.homing->velocity_from, 0.5);
    EXPECT_TRUE(e.homing->post_move_enable);
    EXPECT_DOUBLE_EQ(e.homing->post_move_position, 5);
    EXPECT_EQ(e.homing->ref_to_enc_id_at_startup, -1); // schema default
    EXPECT_EQ(c.primary_encoder(), 0u);

    EXPECT_DOUBLE_EQ(c.controller.kp, 5);
    EXPECT_DOUBLE_EQ(c.controller.ki, 0.01);
    EXPECT_DOUBLE_EQ(c.controller.kff, 1); // schema default

    EXPECT_EQ(c.trajectory.type, TrajectoryType::Trapezoid);
    EXPECT_EQ(c.trajectory.source, TrajectorySource::Internal);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.velocity, 2);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.acceleration, 4);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.deceleration, 4);            // = acceleration
    EXPECT_DOUBLE_EQ(c.trajectory.axis.jerk, 4);                    // = acceleration
    EXPECT_DOUBLE_EQ(c.trajectory.axis.emergency_deceleration, 40); // 10 x acceleration
    EXPECT_DOUBLE_EQ(c.trajectory.jog.velocity, 1);
    EXPECT_DOUBLE_EQ(c.trajectory.jog.acceleration, 4);
    EXPECT_FALSE(c.trajectory.modulo.has_value());

    EXPECT_FALSE(c.input.limit_forward.plc_override);
    EXPECT_EQ(c.input.limit_forward.signal.text, "ec0.s3.driveStatus01.12");
    EXPECT_EQ(c.input.limit_backward.signal.bit, 11);
    ASSERT_TRUE(c.input.home.has_value());
    EXPECT_TRUE(c.input.home->signal.is_constant());
    ASSERT_TRUE(c.input.interlock.has_value());
    EXPECT_EQ(c.input.interlock->entry, "ONE");

    EXPECT_TRUE(c.softlimits.enable);
    EXPECT_DOUBLE_EQ(c.softlimits.forward, -5);
    EXPECT_DOUBLE_EQ(c.softlimits.backward, -15);

    EXPECT_TRUE(c.monitoring.lag.enable);
    EXPECT_DOUBLE_EQ(c.monitoring.lag.tolerance, 0.1);
    EXPECT_EQ(c.monitoring.lag.time_cycles, 10);
    EXPECT_TRUE(c.monitoring.target.enable);
    EXPECT_FALSE(c.monitoring.velocity.enable);
    EXPECT_EQ(c.monitoring.velocity.trajectory_cycles, 100);
    EXPECT_EQ(c.monitoring.velocity.drive_cycles, 200);
    EXPECT_FALSE(c.monitoring.stall.has_value());
    EXPECT_FALSE(c.plc.has_value());
    EXPECT_TRUE(c.warnings.empty()) << joined(c.warnings);
}

TEST(AxisConfigFixtures, ServoDs402Loads) {
    const AxisConfig c =
        load_axis_config(data("servo_axis.yaml"), {{"AX_ID", "2"}, {"DRV_SLAVE", "5"}});
    EXPECT_EQ(c.axis.id, 2);
    EXPECT_EQ(c.axis.mode, DriveMode::CSP); // "csp" as ecmccfg upper-cases it
    EXPECT_EQ(c.axis.group, "rotations");
    ASSERT_TRUE(c.axis.health_output.has_value());
    EXPECT_EQ(c.axis.health_output->text, "ec0.s2.binaryOutput01"); // $(IO_SLAVE=2)
    EXPECT_EQ(c.epics.unit, "deg");
    EXPECT_EQ(c.epics.precision, 3); // default
    EXPECT_TRUE(c.epics.motor_record.sync_soft_limits);
    ASSERT_TRUE(c.epics.motor_record.pvt.has_value());
    EXPECT_EQ(c.epics.motor_record.pvt->npoints, 100);
    EXPECT_EQ(c.epics.motor_record.pvt->nreadback, 0);

    ASSERT_TRUE(c.drive.has_value());
    EXPECT_EQ(c.drive->type, DriveType::DS402);
    EXPECT_EQ(c.drive->setpoint.entry, "positionSetpoint01");
    EXPECT_EQ(c.drive->denominator, 1048576);
    EXPECT_EQ(c.drive->reset_bit, 7);
    ASSERT_EQ(c.drive->errors.size(), 1u);
    EXPECT_EQ(c.drive->errors[0].text, "ec0.s5.driveStatus01.3");
    ASSERT_TRUE(c.drive->brake.has_value());
    EXPECT_TRUE(c.drive->brake->enable);
    EXPECT_EQ(c.drive->brake->output.text, "ec0.s2.binaryOutput02");
    EXPECT_EQ(c.drive->brake->open_delay_cycles, 10);
    EXPECT_EQ(c.drive->brake->close_ahead_cycles, 5);

    const EncoderConfig& e = c.encoders.at(0);
    EXPECT_DOUBLE_EQ(e.abs_offset, 0); // $(OFFSET=0)
    ASSERT_TRUE(e.delay_comp.has_value());
    EXPECT_DOUBLE_EQ(e.delay_comp->time_cycles, 1.5);
    EXPECT_TRUE(e.delay_comp->enable);
    ASSERT_TRUE(e.velocity_filter.has_value());
    EXPECT_TRUE(e.velocity_filter->enable); // present without enable: on (template)
    EXPECT_EQ(e.velocity_filter->size, 20);
    EXPECT_FALSE(e.position_filter.has_value());

    ASSERT_TRUE(c.controller.deadband.has_value());
    EXPECT_EQ(c.controller.deadband->time_cycles, 100);
    EXPECT_DOUBLE_EQ(c.controller.limits.max_output, 100);
    EXPECT_DOUBLE_EQ(c.controller.limits.min_integral, 0);
    ASSERT_TRUE(c.controller.inner.has_value());
    EXPECT_DOUBLE_EQ(c.controller.inner->kp, 2);
    EXPECT_DOUBLE_EQ(c.controller.inner->ki, 0);
    EXPECT_DOUBLE_EQ(c.controller.inner->tol, 0.05);

    EXPECT_EQ(c.trajectory.type, TrajectoryType::SCurve);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.jerk, 1000);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.emergency_deceleration, 3600); // 10 x dec (> acc)
    EXPECT_DOUBLE_EQ(c.trajectory.jog.velocity, 90);                  // = axis.velocity
    ASSERT_TRUE(c.trajectory.modulo.has_value());
    EXPECT_DOUBLE_EQ(c.trajectory.modulo->range, 360);
    EXPECT_EQ(c.trajectory.modulo->type, ModuloType::Closest);

    EXPECT_TRUE(c.input.limit_forward.plc_override);
    EXPECT_TRUE(c.input.limit_backward.plc_override);

    EXPECT_EQ(c.monitoring.target.time_cycles, 50);
    EXPECT_TRUE(c.monitoring.velocity.enable);
    EXPECT_DOUBLE_EQ(c.monitoring.velocity.max, 120);
    ASSERT_TRUE(c.monitoring.stall.has_value());
    EXPECT_TRUE(c.monitoring.stall->enable);
    EXPECT_EQ(c.monitoring.stall->timeout_cycles, 10000);
    EXPECT_EQ(c.monitoring.stall->factor, 5.0);

    ASSERT_TRUE(c.plc.has_value());
    EXPECT_TRUE(c.plc->enable);
    EXPECT_FALSE(c.plc->external_commands);
    ASSERT_EQ(c.plc->code.size(), 2u);
    EXPECT_EQ(c.plc->code[0], "ax2.mon.highlim:=ec_chk_bit(ec0.s2.binaryInputs01,0);");
    EXPECT_TRUE(c.plc->encoder_velocity_filter.enable);
    EXPECT_EQ(c.plc->encoder_velocity_filter.size, 50);
    EXPECT_FALSE(c.plc->trajectory_velocity_filter.enable); // template default
    EXPECT_EQ(c.plc->trajectory_velocity_filter.size, 1);
    EXPECT_TRUE(c.warnings.empty()) << joined(c.warnings);
}

TEST(AxisConfigFixtures, VirtualAxisHasNoDriveAndAPlcEncoder) {
    const AxisConfig c = load_axis_config(data("virtual_axis.yaml"), {{"AX_ID", "10"}});
    EXPECT_TRUE(c.is_virtual());
    EXPECT_EQ(c.axis.type, AxisType::Virtual); // "end effector"
    EXPECT_EQ(c.axis.id, 10);
    EXPECT_FALSE(c.drive.has_value());
    ASSERT_EQ(c.encoders.size(), 1u);
    EXPECT_EQ(c.encoders[0].source, EncoderSource::PLC);
    EXPECT_FALSE(c.encoders[0].position.has_value());
    EXPECT_EQ(c.input.limit_forward.signal.slave, -1); // simulation slave
    EXPECT_TRUE(c.input.limit_forward.signal.is_constant());
    EXPECT_FALSE(c.softlimits.enable);
    EXPECT_DOUBLE_EQ(c.softlimits.forward, 52);
    ASSERT_TRUE(c.plc.has_value());
    EXPECT_TRUE(c.plc->external_commands);
    EXPECT_TRUE(c.monitoring.lag.enable); // yes
}

TEST(AxisConfigFixtures, EncoderFileAddsASecondEncoder) {
    AxisConfig c = load_axis_config(data("stepper_axis.yaml"), kStepperMacros);
    EncoderConfig e = load_encoder_config(data("encoder_openloop.yaml"), {{"DRV_SLAVE", "3"}});
    EXPECT_EQ(e.type, EncoderType::Incremental);
    EXPECT_EQ(e.denominator, 12800);
    EXPECT_EQ(e.unit, "mm");
    EXPECT_EQ(e.position->text, "ec0.s3.positionActual01");
    ASSERT_TRUE(e.homing.has_value());
    EXPECT_EQ(e.homing->ref_to_enc_id_at_startup, 1);
    EXPECT_EQ(e.homing->ref_at_home, 1);
    EXPECT_EQ(e.homing->velocity_to, 0.5);
    EXPECT_FALSE(e.homing->velocity_from.has_value()); // runtime uses velocity.to
    EXPECT_EQ(e.where.file, data("encoder_openloop.yaml"));
    EXPECT_EQ(e.where.line, 3);

    add_encoder(c, e);
    ASSERT_EQ(c.encoders.size(), 2u);
    EXPECT_EQ(c.encoders[1].desc, "Open loop");
    EXPECT_EQ(c.primary_encoder(), 0u);
    c.encoders[1].primary = true;
    EXPECT_EQ(c.primary_encoder(), 1u);
}

TEST(AxisConfigFixtures, EncoderFileWithPrimaryFlag) {
    const EncoderConfig e = parse_encoder_config(
        "encoder:\n  numerator: 1\n  position: ec0.s3.positionActual01\n  primary: 1\n", "enc.yaml",
        {});
    EXPECT_TRUE(e.primary);
    AxisConfig c = parse_axis_config(kMinimal, "axis.yaml", {});
    add_encoder(c, e);
    EXPECT_EQ(c.primary_encoder(), 1u);
}

TEST(AxisConfigFixtures, AtMostEightEncoders) {
    AxisConfig c = parse_axis_config(kMinimal, "axis.yaml", {});
    const EncoderConfig e = parse_encoder_config(
        "encoder:\n  numerator: 1\n  position: ec0.s3.positionActual01\n", "enc.yaml", {});
    for (int i = 1; i < 8; ++i) add_encoder(c, e);
    EXPECT_EQ(c.encoders.size(), 8u);
    EXPECT_EQ(error_of([&] { add_encoder(c, e); }),
              "enc.yaml:1:1: axis 1 already has 8 encoders (ECMC's limit)");
}

TEST(AxisConfigFixtures, BadEncoderFile) {
    // ECMC loads it (its loader drops the key): a warning, as ecmccfg ignores it.
    EncoderConfig e = load_encoder_config(data("bad_encoder.yaml"), {{"DRV_SLAVE", "3"}});
    ASSERT_EQ(e.warnings.size(), 1u);
    EXPECT_EQ(e.warnings[0], data("bad_encoder.yaml") +
                                 ":5:1: unknown key 'homing' in the file: ecmccfg ignores it here; use "
                                 "encoder.homing (ignored)");
}

TEST(AxisConfigFixtures, BadAxisFileReportsEveryProblemInOrder) {
    const std::string path = data("bad_axis.yaml");
    std::vector<Error> errors;
    load_axis_config(path, {}, errors);
    ASSERT_EQ(errors.size(), 4u);
    EXPECT_EQ(std::string(errors[0].what()),
              path + ":3:9: axis.mode should be CSV, CSP or CSP_PC, got 'CSX'");
    EXPECT_EQ(std::string(errors[1].what()),
              path + ":11:11: drive.status: 'ec0.s3.driveStatus01.64' is not a signal link: bit "
                     "64 should be 0..63; the form is ec<master>.s<slave>.<entry>[.<bit>], e.g. "
                     "ec0.s3.driveStatus01.3");
    EXPECT_EQ(std::string(errors[2].what()),
              path + ":18:3: trajectory.axis: missing required key 'acceleration'");
    EXPECT_EQ(std::string(errors[3].what()),
              path + ":19:15: trajectory.axis.velocity should be > 0, got -1");
    // the misspelt key is a warning (ECMC drops unknown keys)
    std::vector<Error> again;
    AxisConfig c = load_axis_config(path, {}, again);
    EXPECT_TRUE(contains(c.warnings, path + ":16:3: unknown key 'bitz' in encoder (did you mean 'bits'?): "
                                            "ignored, as ECMC does"))
        << joined(c.warnings);
    // Without the out-parameter every problem is thrown at once, the first one first.
    std::string all;
    for (const auto& e : errors) all += (all.empty() ? "" : "\n") + std::string(e.what());
    EXPECT_EQ(error_of([&] { load_axis_config(path, {}); }), all);
}

TEST(AxisConfigFixtures, MissingFile) {
    EXPECT_EQ(error_of([] { load_axis_config("/nonexistent/ax.yaml", {}); }),
              "/nonexistent/ax.yaml: cannot open: No such file or directory");
    std::vector<Error> errors;
    load_encoder_config("/nonexistent/enc.yaml", {}, errors);
    EXPECT_EQ(errors.size(), 1u);
}

// ---- macros -----------------------------------------------------------------------------------

TEST(AxisConfigMacros, GivenValuesOverrideDefaults) {
    const AxisConfig c = load_axis_config(data("stepper_axis.yaml"), {{"DRV_SLAVE", "7"},
                                                                      {"ENC_SLAVE", "8"},
                                                                      {"AX_ID", "12"},
                                                                      {"ENC_CHANNEL", "02"},
                                                                      {"AX_NAME", "BLADE_LO"}});
    EXPECT_EQ(c.axis.id, 12);
    EXPECT_EQ(c.epics.name, "BLADE_LO");
    EXPECT_EQ(c.drive->control.text, "ec0.s7.driveControl01");
    EXPECT_EQ(c.encoders[0].position->text, "ec0.s8.positionActual02");
    EXPECT_EQ(c.encoders[0].position->slave, 8);
}

TEST(AxisConfigMacros, UndefinedMacroNamesTheReference) {
    const std::string path = data("stepper_axis.yaml");
    const std::string text = read(path);
    // drive.setpoint is the first value that uses DRV_SLAVE; the error points at its '$'.
    const std::string at = where_in(text, "$(DRV_SLAVE)");
    const std::string setpoint = where_in(text, "  setpoint: ");
    EXPECT_EQ(at, setpoint.substr(0, setpoint.find(':')) + ":18"); // "  setpoint: ec0.s" + 1
    const std::string e = error_of([&] { load_axis_config(path, {{"ENC_SLAVE", "4"}}); });
    EXPECT_EQ(e.substr(0, e.find('\n')),
              path + ":" + at + ": drive.setpoint: undefined macro 'DRV_SLAVE'");
    // and every other use of it, each at its own place, without follow-on errors
    std::istringstream lines(e);
    std::size_t n = 0;
    for (std::string line; std::getline(lines, line); ++n)
        EXPECT_NE(line.find(": undefined macro 'DRV_SLAVE'"), std::string::npos) << line;
    EXPECT_EQ(n, 8u) << e;
}

TEST(AxisConfigMacros, EveryUndefinedMacroIsReported) {
    const std::vector<std::string> errors =
        errors_of(read(data("stepper_axis.yaml")), {{"ENC_SLAVE", "4"}});
    std::size_t drv = 0;
    for (const auto& e : errors)
        if (e.find("undefined macro 'DRV_SLAVE'") != std::string::npos) ++drv;
    EXPECT_EQ(drv, 8u) << joined(errors); // every value that uses it, once
}

TEST(AxisConfigMacros, CommentsAreNotExpandedAndDefaultsApply) {
    const std::string text = std::string(kMinimal) +
                             "# $(NOT_DEFINED) in a comment\n"
                             "epics:\n  name: ${NAME=X1}  # $(ALSO_NOT)\n  precision: $(PREC=5)\n";
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    EXPECT_EQ(c.epics.name, "X1");
    EXPECT_EQ(c.epics.precision, 5);
}

TEST(AxisConfigMacros, MacroValueCannotChangeTheStructure) {
    const std::string text = with_value("epics.motorRecord.description", YAML::Node("$(N)"));
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {{"N", "A\n  precision: 9"}});
    EXPECT_EQ(c.epics.motor_record.description, "A\n  precision: 9");
    EXPECT_EQ(c.epics.precision, 3);
    const std::string name = with_value("epics.name", YAML::Node("$(N)"));
    const auto errors = errors_of(name, {{"N", "A: B"}});
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_TRUE(contains(errors, "epics.name should be a PV name part without spaces or quotes, "
                                 "got 'A: B'"));
}

TEST(AxisConfigMacros, VarSectionValues) {
    const std::string text = std::string(kMinimal) + "var:\n  slave: 9\n"
                                                     "epics:\n  name: 'M{{ var.slave }}'\n";
    EXPECT_EQ(parse_axis_config(text, "axis.yaml", {}).epics.name, "M9");
    EXPECT_TRUE(contains(errors_of(std::string(kMinimal) + "epics:\n  name: 'M{{ var.nope }}'\n"),
                         "axis.yaml:27:10: epics.name: 'nope' is not a value in var:"));
    EXPECT_TRUE(contains(errors_of(std::string(kMinimal) + "epics:\n  name: 'M{% if x %}'\n"),
                         "jinja2 statements"));
}

// ---- signal links -----------------------------------------------------------------------------

TEST(SignalRef, ParsesEntriesBitsAndConstants) {
    const SourceLoc at{"f.yaml", 3, 7};
    SignalRef r = parse_signal_ref("ec0.s3.driveStatus01.3", at);
    EXPECT_EQ(r.bus, 0);
    EXPECT_EQ(r.slave, 3);
    EXPECT_EQ(r.entry, "driveStatus01");
    EXPECT_EQ(r.bit, 3);
    EXPECT_EQ(r.text, "ec0.s3.driveStatus01.3");
    EXPECT_EQ(r.where.str(), "f.yaml:3:7");
    EXPECT_FALSE(r.is_constant());

    r = parse_signal_ref("ec1.s12.positionActual01", at);
    EXPECT_EQ(r.bus, 1);
    EXPECT_EQ(r.slave, 12);
    EXPECT_EQ(r.bit, -1);

    r = parse_signal_ref("ec0.s-1.ONE.2", at);
    EXPECT_EQ(r.slave, -1);
    EXPECT_TRUE(r.is_constant());
    EXPECT_EQ(r.bit, 2);
    EXPECT_TRUE(parse_signal_ref("ec0.s5.ZERO", at).is_constant());
    EXPECT_EQ(parse_signal_ref("ec0.s1.BI_2.63", at).bit, 63);

    const SignalRef w = parse_signal_ref("ec0.s-1.driveStatus01", at).with_bit(12);
    EXPECT_EQ(w.text, "ec0.s-1.driveStatus01.12");
    EXPECT_EQ(w.bit, 12);
}

TEST(SignalRef, RejectsMalformedLinksWithLocation) {
    const SourceLoc at{"f.yaml", 4, 12};
    const std::pair<const char*, const char*> cases[] = {
        {"", "it should start with ec<master>"},
        {"s3.binaryInput01", "it should start with ec<master>"},
        {"ecx.s3.a", "expected the master number after 'ec'"},
        {"ec0s3.a", "expected '.' after 'ec0'"},
        {"ec0.3.driveControl01", "expected s<slave> after 'ec0.'"},
        {"ec0.s.x", "expected the slave number after 'ec0.s'"},
        {"ec0.s-2.ONE", "the slave should be >= -1"},
        {"ec0.s3", "expected '.<entry>' after 'ec0.s3'"},
        {"ec0.s3.", "expected an entry name after 'ec0.s3.'"},
        {"ec0.s3.1entry", "expected an entry name after 'ec0.s3.'"},
        {"ec0.s3.entry.", "expected a bit number after 'ec0.s3.entry.'"},
        {"ec0.s3.entry.x", "expected a bit number after 'ec0.s3.entry.'"},
        {"ec0.s3.entry.64", "bit 64 should be 0..63"},
        {"ec0.s3.entry.1.2", "unexpected '.2' after 'ec0.s3.entry.1'"},
        {"ec0.s3.entry 1", "unexpected ' 1' after 'ec0.s3.entry'"},
        {"ec0.s1234567.x", "expected the slave number after 'ec0.s'"},
    };
    for (const auto& [text, why] : cases) {
        const std::string msg = error_of([&] { parse_signal_ref(text, at); });
        EXPECT_EQ(
            msg.rfind(std::string("f.yaml:4:12: '") + text + "' is not a signal link: " + why, 0),
            0u)
            << text << " -> " << msg;
    }
}

TEST(SignalRef, PlcOverrideOnlyForLimitsAndHome) {
    const std::string ok = with_value("input.home", YAML::Node("plcOverride"));
    const AxisConfig c = parse_axis_config(ok, "axis.yaml", {});
    ASSERT_TRUE(c.input.home.has_value());
    EXPECT_TRUE(c.input.home->plc_override);

    const std::string bad = with_value("drive.control", YAML::Node("plcOverride"));
    EXPECT_EQ(error_of([&] { parse_axis_config(bad, "axis.yaml", {}); }),
              "axis.yaml:" + where_in(bad, "plcOverride") +
                  ": drive.control: plcOverride is only possible for input.limit.forward, "
                  "input.limit.backward and input.home");
}

TEST(SignalRef, BadLinkInAFileNamesKeyAndPlace) {
    const std::string text = with_value("input.interlock", YAML::Node("ec0.s3.binaryInput01.1x"));
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:" + where_in(text, "ec0.s3.binaryInput01.1x") +
                  ": input.interlock: 'ec0.s3.binaryInput01.1x' is not a signal link: unexpected "
                  "'x' after 'ec0.s3.binaryInput01.1'; the form is "
                  "ec<master>.s<slave>.<entry>[.<bit>], e.g. ec0.s3.driveStatus01.3");
    // A quoted value is located at its first character, not at the quote.
    const std::string quoted =
        std::string(kMinimal) + "axis:\n  healthOutput: 'ec0.s3'\n"; // duplicate axis too
    EXPECT_TRUE(contains(errors_of(quoted), "axis.yaml:27:18: axis.healthOutput: 'ec0.s3'"))
        << joined(errors_of(quoted));
}

TEST(SignalRef, EmptyLinkIsUnlinkedWhereOptionalAndAnErrorWhereRequired) {
    const AxisConfig c =
        parse_axis_config(with_value("axis.healthOutput", YAML::Node("")), "axis.yaml", {});
    EXPECT_FALSE(c.axis.health_output.has_value());
    EXPECT_TRUE(contains(errors_of(with_value("drive.setpoint", YAML::Node(""))),
                         "drive.setpoint should be a signal link, got ''"));
    EXPECT_TRUE(contains(errors_of(with_value("input.limit.forward", YAML::Node(""))),
                         "input.limit.forward should be a signal link or plcOverride, got ''"));
}

// ---- validation -------------------------------------------------------------------------------

TEST(AxisConfigErrors, MessageNamesFileLineColumnKeyAndValue) {
    const std::string text = R"(axis:
  id: 1
drive:
  numerator: 10
  setpoint: ec0.s3.velocitySetpoint01
  control: ec0.s3.driveControl01
  status: ec0.s3.driveStatus01
encoder:
  numerator: 1
  position: ec0.s3.positionActual01
trajectory:
  axis:
    velocity: -1
    acceleration: 2
input:
  limit:
    forward: ec0.s3.ONE.0
    backward: ec0.s3.ONE.0
)";
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:13:15: trajectory.axis.velocity should be > 0, got -1");
}

// Every mapping of the schema rejects a key it does not know, at the key, with the allowed keys.
TEST(AxisConfigWarnings, EverySectionCatchesUnknownKeys) {
    const char* sections[] = {"",
                              "axis",
                              "axis.autoEnable",
                              "axis.autoMode",
                              "axis.features",
                              "axis.features.allowedFunctions",
                              "epics",
                              "epics.motorRecord",
                              "epics.motorRecord.pvt",
                              "drive",
                              "drive.brake",
                              "encoder",
                              "encoder.lookuptable",
                              "encoder.delayComp",
                              "encoder.filter",
                              "encoder.filter.velocity",
                              "encoder.filter.trajectory",
                              "encoder.filter.position",
                              "encoder.latch",
                              "encoder.homing",
                              "encoder.homing.velocity",
                              "controller",
                              "controller.inner",
                              "controller.limits",
                              "controller.deadband",
                              "trajectory",
                              "trajectory.axis",
                              "trajectory.jog",
                              "trajectory.modulo",
                              "input",
                              "input.limit",
                              "input.analog",
                              "softlimits",
                              "monitoring",
                              "monitoring.lag",
                              "monitoring.target",
                              "monitoring.velocity",
                              "monitoring.velocity.time",
                              "monitoring.velocityDifference",
                              "monitoring.velocityDifference.time",
                              "monitoring.stall",
                              "monitoring.stall.time",
                              "plc",
                              "plc.filter",
                              "plc.filter.velocity",
                              "plc.filter.trajectory",
                              "plc.filter.position",
                              "plc.velocity_filter",
                              "plc.velocity_filter.encoder",
                              "plc.velocity_filter.trajectory",
                              "homing",
                              "homing.velocity",
                              "meta"};
    for (const char* section : sections) {
        const std::string path =
            std::string(section).empty() ? "bogusKey" : std::string(section) + ".bogusKey";
        const std::string text = with_value(path, YAML::Node(1));
        const std::string in = std::string(section).empty() ? "the file" : section;
        const std::string expected = "axis.yaml:" + where_in(text, "bogusKey") +
                                     ": unknown key 'bogusKey' in " + in + " (expected one of: ";
        EXPECT_TRUE(contains(warnings_of(text), expected)) << section << "\n"
                                                           << text << joined(warnings_of(text));
    }
    // The encoder-only file too.
    std::vector<Error> errors;
    EncoderConfig enc = parse_encoder_config("encoder:\n  numerator: 1\n  position: ec0.s1.x\nextra: 1\n",
                                             "enc.yaml", {}, errors);
    EXPECT_TRUE(errors.empty());
    ASSERT_EQ(enc.warnings.size(), 1u);
    EXPECT_EQ(enc.warnings[0], "enc.yaml:4:1: unknown key 'extra' in the file (expected one of: encoder, meta, "
                               "var): ignored, as ECMC does");
}

TEST(AxisConfigErrors, CollectedErrorsFollowTheFileNotTheReadingOrder) {
    // axis: is read first, but trajectory: comes first in the file.
    const std::string text = R"(trajectory:
  axis:
    velocity: 0
    acceleration: 1
axis:
  mode: CSX
drive:
  numerator: 10
  setpoint: ec0.s3.velocitySetpoint01
  control: ec0.s3.driveControl01
  status: ec0.s3.driveStatus01
encoder:
  numerator: 1
  position: ec0.s3.positionActual01
input:
  limit:
    forward: ec0.s3.ONE.0
    backward: ec0.s3.ONE.0
monitoring:
)";
    EXPECT_EQ(errors_of(text),
              (std::vector<std::string>{
                  "axis.yaml:3:15: trajectory.axis.velocity should be > 0, got 0",
                  "axis.yaml:6:9: axis.mode should be CSV, CSP or CSP_PC, got 'CSX'"}));
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:3:15: trajectory.axis.velocity should be > 0, got 0\n"
              "axis.yaml:6:9: axis.mode should be CSV, CSP or CSP_PC, got 'CSX'")
        << "thrown: every error, in file order";
}

TEST(AxisConfigErrors, UnknownKeySuggestsTheNearestKey) {
    const std::string text = with_value("trajectory.axis.decceleration", YAML::Node(1));
    EXPECT_TRUE(errors_of(text).empty()) << joined(errors_of(text));
    EXPECT_TRUE(contains(warnings_of(text),
                         "unknown key 'decceleration' in trajectory.axis (did you mean "
                         "'deceleration'?): ignored, as ECMC does"));
}

TEST(AxisConfigErrors, MissingRequiredKeys) {
    const std::pair<const char*, const char*> cases[] = {
        {"axis", "axis.yaml:1:1: the file: missing required key 'axis'"},
        {"drive", "axis.yaml:1:1: the file: missing required key 'drive'"},
        {"encoder", "axis.yaml:1:1: the file: missing required key 'encoder'"},
        {"trajectory", "axis.yaml:1:1: the file: missing required key 'trajectory'"},
        {"input", "axis.yaml:1:1: the file: missing required key 'input'"},
        {"trajectory.axis.velocity", "trajectory.axis: missing required key 'velocity'"},
        {"trajectory.axis.acceleration", "trajectory.axis: missing required key 'acceleration'"},
        {"trajectory.axis", "trajectory: missing required key 'axis'"},
        {"drive.setpoint", "drive: missing required key 'setpoint'"},
        {"drive.control", "drive: missing required key 'control'"},
        {"drive.status", "drive: missing required key 'status'"},
        {"drive.numerator", "drive: missing required key 'numerator'"},
        {"input.limit", "input: missing required key 'limit'"},
        {"input.limit.forward", "input.limit: missing required key 'forward'"},
        {"input.limit.backward", "input.limit: missing required key 'backward'"},
        {"monitoring.target.enable", "monitoring.target: missing required key 'enable'"},
        {"encoder.position",
         "encoder: an encoder read from EtherCAT (source 0) needs "
         "encoder.position; for a value written by a PLC set encoder.source: 1"},
        {"encoder.numerator",
         "encoder.numerator should not be 0 for an encoder read from EtherCAT"},
    };
    for (const auto& [path, expected] : cases) {
        const std::string text = without(path);
        EXPECT_TRUE(contains(errors_of(text), expected)) << path << "\n" << joined(errors_of(text));
    }
    // Sub-sections with required keys of their own.
    const std::pair<const char*, const char*> nested[] = {
        {"drive.brake.openDelay", "drive.brake: missing required key 'enable'"},
        {"drive.brake.openDelay", "drive.brake: missing required key 'output'"},
        {"encoder.latch.control", "encoder.latch: missing required key 'position'"},
        {"encoder.delayComp.enable", "encoder.delayComp: missing required key 'time'"},
        {"encoder.lookuptable.scale", "encoder.lookuptable: missing required key 'filename'"},
        {"plc.externalCommands", "plc: missing required key 'enable'"},
        {"monitoring.velocity.time.drive", "monitoring.velocity.time: missing required key "
                                           "'trajectory'"},
        {"controller.deadband.tol", "controller.deadband: missing required key 'time'"},
    };
    for (const auto& [path, expected] : nested) {
        const std::string text = with_value(path, YAML::Node(1));
        EXPECT_TRUE(contains(errors_of(text), expected)) << path << "\n" << joined(errors_of(text));
    }
}

TEST(AxisConfigErrors, MissingKeyIsReportedAtItsSection) {
    const std::string text = R"(axis:
  id: 1
drive:
  numerator: 10
  setpoint: ec0.s3.velocitySetpoint01
  control: ec0.s3.driveControl01
  status: ec0.s3.driveStatus01
encoder:
  numerator: 1
  position: ec0.s3.positionActual01
trajectory:
  axis:
    velocity: 1
input:
  limit:
    forward: ec0.s3.ONE.0
    backward: ec0.s3.ONE.0
monitoring:
)";
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:12:3: trajectory.axis: missing required key 'acceleration'");
}

TEST(AxisConfigErrors, BadValuesSayWhatShouldBeWhat) {
    struct Case {
        const char* path;
        const char* value;
        const char* expected;
    };
    const Case cases[] = {
        {"trajectory.axis.velocity", "-1", "trajectory.axis.velocity should be > 0, got -1"},
        {"trajectory.axis.acceleration", "0", "trajectory.axis.acceleration should be > 0, got 0"},
        {"trajectory.axis.acceleration", "fast",
         "trajectory.axis.acceleration should be a number, got 'fast'"},
        {"trajectory.axis.jerk", "1e999", "trajectory.axis.jerk should be a number, got '1e999'"},
        {"trajectory.axis.velocity", ".nan",
         "trajectory.axis.velocity should be a number, got '.nan'"},
        {"trajectory.type", "2", "trajectory.type should be 0 (trapezoid) or 1 (S-curve), got 2"},
        {"trajectory.modulo.type", "4",
         "trajectory.modulo.type should be 0 (normal), 1 (forward), 2 (backward) or 3 (closest), "
         "got 4"},
        {"drive.type", "2", "drive.type should be 0 (stepper) or 1 (DS402), got 2"},
        {"drive.denominator", "0", "drive.denominator should be >= 1, got 0"},
        {"drive.denominator", "2.5", "drive.denominator should be an integer, got '2.5'"},
        {"drive.numerator", "0", "drive.numerator should not be 0"},
        {"drive.warning", "64", "drive.warning should be from 0 to 63, got 64"},
        {"encoder.bits", "65", "encoder.bits should be from 0 to 64, got 65"},
        {"encoder.source", "2", "encoder.source should be 0 (EtherCAT) or 1 (PLC), got 2"},
        {"encoder.homing.type", "13",
         "encoder.homing.type should be a homing sequence: 0..12, 14, 15, 21, 22, 25 or 26, got "
         "13"},
        {"encoder.homing.latchCount", "-1", "encoder.homing.latchCount should be >= 0, got -1"},
        {"axis.mode", "CSX", "axis.mode should be CSV, CSP or CSP_PC, got 'CSX'"},
        {"axis.type", "banana", "axis.type should be joint (1) or virtual (2), got 'banana'"},
        {"axis.type", "debug", "axis.type debug (0) is not supported"},
        {"axis.id", "128", "axis.id should be from 0 to 127, got 128"},
        {"axis.autoEnable.atStartup", "maybe",
         "axis.autoEnable.atStartup should be true or false, got 'maybe'"},
        {"epics.precision", "-1", "epics.precision should be from 0 to 17, got -1"},
        {"epics.name", "two words", "epics.name should be a PV name part without spaces"},
        {"input.limit.forwardPolarity", "2", "input.limit.forwardPolarity should be 0 or 1, got 2"},
        {"monitoring.target.time", "1.5", "monitoring.target.time should be an integer, got '1.5'"},
        {"monitoring.target.tolerance", "-0.1",
         "monitoring.target.tolerance should be >= 0, got -0.1"},
        {"controller.Kp", "-1", "controller.Kp should be >= 0, got -1"},
        {"encoder.filter.velocity.size", "0", "encoder.filter.velocity.size should be >= 1, got 0"},
    };
    for (const Case& c : cases) {
        const std::string text = with_value(c.path, YAML::Node(c.value));
        const auto errors = errors_of(text);
        EXPECT_TRUE(contains(errors, std::string(": ") + c.expected))
            << c.path << " = " << c.value << "\n"
            << joined(errors);
    }
}

TEST(AxisConfigErrors, ListsAndSectionsOfTheWrongShape) {
    YAML::Node four;
    for (int b : {1, 2, 3, 4}) four.push_back(b);
    EXPECT_TRUE(contains(errors_of(with_value("drive.error", four)),
                         "drive.error should have at most 3 entries, got 4"));
    EXPECT_TRUE(
        contains(errors_of(with_value("drive.error", YAML::Node(3))),
                 "drive.error should be a list of status bits or links, got a single value"));
    EXPECT_TRUE(contains(errors_of(with_value("trajectory.axis", YAML::Node(1))),
                         "trajectory.axis should be a mapping (key: value lines), got a single "
                         "value"));
    EXPECT_TRUE(contains(errors_of(with_value("epics.name", four)),
                         "epics.name should be a name, got a list"));
    YAML::Node bits;
    bits.push_back(1);
    EXPECT_TRUE(contains(errors_of(with_value("encoder.error", bits)),
                         "encoder.error[0] is a bit of encoder.status, which is not given"));
}

TEST(AxisConfigErrors, SchemaDependencies) {
    EXPECT_TRUE(contains(errors_of(with_value("drive.reduceTorque", YAML::Node(2))),
                         "drive.reduceTorque needs drive.reduceTorqueEnable as well"));
    EXPECT_TRUE(contains(errors_of(with_value("softlimits.forward", YAML::Node(5))),
                         "softlimits.forward needs softlimits.forwardEnable as well"));
    EXPECT_TRUE(contains(errors_of(with_value("monitoring.lag.enable", YAML::Node(true))),
                         "monitoring.lag.enable needs monitoring.lag.tolerance as well"));
    EXPECT_TRUE(contains(errors_of(with_value("encoder.homing.postMoveEnable", YAML::Node(true))),
                         "encoder.homing.postMoveEnable needs encoder.homing.postMovePosition"));
    EXPECT_TRUE(
        contains(errors_of(with_value("encoder.homing.type", YAML::Node(26))),
                 "encoder.homing.type 26 (drive-internal homing) needs encoder.homing.trigg "
                 "and encoder.homing.ready"));
}

TEST(AxisConfigErrors, SoftLimitsMustBeOrdered) {
    const std::string text = std::string(kMinimal) +
                             "softlimits:\n  enable: true\n  forwardEnable: true\n  forward: 10\n"
                             "  backwardEnable: true\n  backward: 10\n";
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:31:3: softlimits.backward (10) should be below softlimits.forward (10)");
    // Negative limits are fine (ecmc#63).
    const std::string neg = std::string(kMinimal) +
                            "softlimits:\n  enable: true\n  forwardEnable: true\n  forward: -192\n"
                            "  backwardEnable: true\n  backward: -227\n";
    EXPECT_DOUBLE_EQ(parse_axis_config(neg, "axis.yaml", {}).softlimits.backward, -227);
}

TEST(AxisConfigErrors, DuplicateKeysAreErrors) {
    const std::string text = std::string(kMinimal) + "trajectory:\n  axis:\n    velocity: 1\n";
    EXPECT_TRUE(
        contains(errors_of(text),
                 "axis.yaml:26:1: duplicate key 'trajectory' in the file (also at line 13)"))
        << joined(errors_of(text));
}

TEST(AxisConfigErrors, VirtualAxisHasNoDrive) {
    const std::string text = with_value("axis.type", YAML::Node("virtual"));
    EXPECT_EQ(error_of([&] { parse_axis_config(text, "axis.yaml", {}); }),
              "axis.yaml:" + where_in(text, "drive:") +
                  ": a virtual axis (axis.type virtual) has no drive; remove it or make the axis "
                  "a joint");
}

TEST(AxisConfigErrors, AxisTypeSpellings) {
    for (const char* t : {"1", "joint", "J", "physical", "Motor", "real"})
        EXPECT_EQ(parse_axis_config(with_value("axis.type", YAML::Node(t)), "a.yaml", {}).axis.type,
                  AxisType::Joint)
            << t;
    const std::string virt = without("drive");
    for (const char* t : {"2", "virtual", "end effector", "End_Effector", "ee", "e"}) {
        const std::string text = with_value("axis.type", YAML::Node(t), virt.c_str());
        EXPECT_TRUE(parse_axis_config(text, "a.yaml", {}).is_virtual()) << t;
    }
}

// ---- legacy forms and warnings ----------------------------------------------------------------

TEST(AxisConfigWarnings, KeysEcmccfgIgnoresLoadWithAWarning) {
    std::string text = with_value("encoder.velocityFilterSize", YAML::Node(100));
    text = with_value("epics.description", YAML::Node("main axis"), text.c_str());
    text = with_value("output.health", YAML::Node("ec0.s1.binaryOutput01"), text.c_str());
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    EXPECT_EQ(c.epics.description, "main axis"); // documented in the ecmccfg manual
    ASSERT_EQ(c.warnings.size(), 2u) << joined(c.warnings);
    EXPECT_TRUE(contains(c.warnings, "axis.yaml:" + where_in(text, "velocityFilterSize") +
                                         ": 'encoder.velocityFilterSize' is ignored by ecmccfg "
                                         "(use encoder.filter.velocity.size)"));
    EXPECT_TRUE(contains(c.warnings, "'output' is ignored by ecmccfg"));
}

TEST(AxisConfigWarnings, MisplacedKeysAreWarningsWithAHint) {
    // ECMC loads these files and ignores the keys: so does beamctl, saying where they belong.
    EXPECT_TRUE(contains(warnings_of(with_value("epics.fieldInit", YAML::Node("RTRY=0"))),
                         "unknown key 'fieldInit' in epics: ecmccfg ignores it here; use "
                         "epics.motorRecord.fieldInit (ignored)"));
    EXPECT_TRUE(contains(warnings_of(with_value("motorRecord.name", YAML::Node("M1"))),
                         "unknown key 'motorRecord' in the file: ecmccfg ignores it here"));
    EXPECT_TRUE(errors_of(with_value("epics.fieldInit", YAML::Node("RTRY=0"))).empty());
}

TEST(AxisConfigWarnings, LegacyTopLevelHomingMovesToTheEncoder) {
    const std::string text = std::string(kMinimal) + "homing:\n  type: 3\n  position: -30\n";
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    ASSERT_TRUE(c.encoders.at(0).homing.has_value());
    EXPECT_EQ(c.encoders[0].homing->type, 3);
    EXPECT_TRUE(contains(c.warnings, "axis.yaml:26:1: top-level homing is the legacy form"));

    const std::string both = with_value("encoder.homing.type", YAML::Node(1), text.c_str());
    EXPECT_TRUE(contains(errors_of(both), "homing and encoder.homing are both given"));
}

TEST(AxisConfigWarnings, LegacyPlcFilterIsUsedWhenTheNewOneIsMissing) {
    const std::string text = with_value("plc.filter.position.size", YAML::Node(20),
                                        with_value("plc.enable", YAML::Node(true)).c_str());
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    EXPECT_EQ(c.plc->trajectory_velocity_filter.size, 20);
    EXPECT_FALSE(c.plc->trajectory_velocity_filter.enable);
    EXPECT_TRUE(contains(c.warnings, "plc.filter is the legacy form of plc.velocity_filter"));
}

TEST(AxisConfigWarnings, MissingMonitoringAndDs402StepperBits) {
    std::string text = without("monitoring");
    text = with_value("drive.type", YAML::Node(1), text.c_str());
    text = with_value("drive.enabled", YAML::Node(1), text.c_str());
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    EXPECT_EQ(c.warnings.size(), 2u) << joined(c.warnings);
    EXPECT_TRUE(contains(c.warnings, "drive.enabled is not used by a DS402 drive"));
    EXPECT_TRUE(contains(c.warnings, "axis.yaml:1:1: no monitoring section"));
    EXPECT_FALSE(c.monitoring.lag.enable);
    EXPECT_EQ(c.monitoring.lag.time_cycles, 100); // schema default
}

TEST(AxisConfigDefaults, EmergencyDecelerationAndDefaultsOfAMinimalAxis) {
    const AxisConfig c = parse_axis_config(kMinimal, "axis.yaml", {});
    EXPECT_EQ(c.axis.mode, DriveMode::CSV);
    EXPECT_DOUBLE_EQ(c.axis.tweak_dist, 1.0);
    EXPECT_EQ(c.epics.name, "axis");
    EXPECT_EQ(c.epics.unit, "mm");
    EXPECT_EQ(c.encoders[0].bits, 16);
    EXPECT_EQ(c.encoders[0].abs_bits, 25);
    EXPECT_EQ(c.drive->type, DriveType::Stepper);
    EXPECT_DOUBLE_EQ(c.controller.kp, 1);
    EXPECT_DOUBLE_EQ(c.trajectory.axis.emergency_deceleration, 20); // 10 x acceleration 2
    const std::string slower = with_value("trajectory.axis.deceleration", YAML::Node(1));
    EXPECT_DOUBLE_EQ(parse_axis_config(slower, "a.yaml", {}).trajectory.axis.emergency_deceleration,
                     20); // deceleration below acceleration: still 10 x acceleration
    const std::string given = with_value("trajectory.axis.emergencyDeceleration", YAML::Node(7));
    EXPECT_DOUBLE_EQ(parse_axis_config(given, "a.yaml", {}).trajectory.axis.emergency_deceleration,
                     7);
    EXPECT_TRUE(c.warnings.empty()) << joined(c.warnings);
}

TEST(AxisConfigDefaults, NumbersAndBooleansInYaml11Forms) {
    std::string text = with_value("drive.denominator", YAML::Node("0x8000"));
    text = with_value("softlimits.enable", YAML::Node("on"), text.c_str());
    text = with_value("softlimits.forwardEnable", YAML::Node("Yes"), text.c_str());
    text = with_value("softlimits.forward", YAML::Node("+1.5e2"), text.c_str());
    text = with_value("softlimits.backwardEnable", YAML::Node("0"), text.c_str());
    text = with_value("softlimits.backward", YAML::Node(".5"), text.c_str());
    const AxisConfig c = parse_axis_config(text, "axis.yaml", {});
    EXPECT_EQ(c.drive->denominator, 32768);
    EXPECT_TRUE(c.softlimits.enable);
    EXPECT_TRUE(c.softlimits.forward_enable);
    EXPECT_DOUBLE_EQ(c.softlimits.forward, 150);
    EXPECT_FALSE(c.softlimits.backward_enable);
    EXPECT_DOUBLE_EQ(c.softlimits.backward, 0.5);
}

// ---- never crash ------------------------------------------------------------------------------

TEST(AxisConfigGarbage, EveryInputGivesAnErrorNotACrash) {
    const std::string cases[] = {
        "",
        "   \n\n",
        "# only a comment\n",
        "- axis\n- encoder\n",
        "just some text",
        "axis: [1, 2",
        "axis:\n\tid: 1\n",
        "{a: 1, a: 2}",
        std::string("axis:\n  id: \0\x01\x02", 15),
        "\xff\xfe\x00\x00garbage",
        std::string(20000, '['),
        "axis: &a\n  id: *a\n",
        "? [complex, key]\n: 1\n",
        "axis: 1\n---\naxis: 2\n",
        "axis: !!binary aGVsbG8=\n",
        "axis:\n  id: 1\ntrajectory: {axis: {velocity: 1, acceleration: 1}}\ninput: 3\n",
    };
    for (const std::string& text : cases) {
        EXPECT_THROW(parse_axis_config(text, "junk.yaml", {}), Error) << text.substr(0, 40);
        std::vector<Error> errors;
        EXPECT_NO_THROW(parse_axis_config(text, "junk.yaml", {}, errors)) << text.substr(0, 40);
        EXPECT_FALSE(errors.empty()) << text.substr(0, 40);
        errors.clear();
        EXPECT_NO_THROW(parse_encoder_config(text, "junk.yaml", {}, errors)) << text.substr(0, 40);
        EXPECT_FALSE(errors.empty()) << text.substr(0, 40);
    }
    EXPECT_EQ(
        error_of([] { parse_axis_config("", "e.yaml", {}); }),
        "e.yaml:1:1: the file is empty; it needs axis:, encoder:, trajectory:, input: and, for "
        "a joint axis, drive:");
    EXPECT_EQ(error_of([] { parse_axis_config("- a\n", "e.yaml", {}); }),
              "e.yaml:1:1: the file should be a mapping of sections (axis:, encoder:, trajectory:, "
              "input: and, for a joint axis, drive:), got a list");
    // The place is yaml-cpp's: here the key that breaks the indentation.
    EXPECT_EQ(error_of([] { parse_axis_config("axis:\n  id: 1\n mode: CSV\n", "e.yaml", {}); }),
              "e.yaml:3:2: YAML syntax error: end of map not found");
}

// Seeded random edits of a valid file (and random bytes) either load or give beamctl::Errors.
TEST(AxisConfigGarbage, RandomEditsNeverCrash) {
    const std::string base =
        beamctl::expand_macros(read(data("servo_axis.yaml")), {{"AX_ID", "1"}, {"DRV_SLAVE", "3"}});
    std::mt19937 rng(20240611);
    const std::string alphabet = ":-[]{}'\"#&*!|>%@`,.$()\n \t0123456789abcxyzONE";
    int loaded = 0, rejected = 0;
    for (int i = 0; i < 400; ++i) {
        std::string text = base;
        const int edits = 1 + int(rng() % 4);
        for (int k = 0; k < edits && !text.empty(); ++k) {
            const std::size_t at = rng() % text.size();
            switch (rng() % 4) {
            case 0:
                text.erase(at, 1 + rng() % 8);
                break;
            case 1:
                text.insert(at, 1, alphabet[rng() % alphabet.size()]);
                break;
            case 2:
                text[at] = char(rng() % 256);
                break;
            default:
                text.insert(at, text.substr(rng() % text.size(), rng() % 40));
                break;
            }
        }
        if (i % 10 == 0) {
            text.resize(rng() % 200);
            for (char& ch : text) ch = char(rng() % 256);
        }
        std::vector<Error> errors;
        try {
            parse_axis_config(text, "fuzz.yaml", {}, errors);
            parse_encoder_config(text, "fuzz.yaml", {}, errors);
            parse_axis_config(text, "fuzz.yaml", {});
            ++loaded;
        } catch (const Error& e) {
            EXPECT_EQ(std::string(e.what()).rfind("fuzz.yaml:", 0), 0u) << e.what();
            ++rejected;
        } catch (const std::exception& e) {
            ADD_FAILURE() << "not a beamctl::Error: " << e.what() << "\n" << text;
        }
    }
    EXPECT_GT(loaded, 0);
    EXPECT_GT(rejected, 100);
}
