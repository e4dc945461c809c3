// Every reader on the one YAML reader: a file holding several errors reports each of them, with
// file:line:col and the key path, in one pass (the plant file, a catalog device file and a
// catalog directory, the rcp-sim model, an ECMC axis file).
#include "../temp_dir.hpp"
#include "bridge/rcp/model.hpp"
#include "core/error_list.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/sim_config.hpp"
#include "motion/axis_config.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

using namespace beamctl;

namespace {

std::string joined(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += x + "\n";
    return s;
}

// The errors of the MultiError `f` throws (fails the test when it throws none).
template <typename F> std::vector<std::string> errors_of(F&& f) {
    try {
        f();
    } catch (const MultiError& e) {
        return e.errors();
    } catch (const Error& e) {
        ADD_FAILURE() << "an Error, not a MultiError: " << e.what();
        return {e.what()};
    }
    ADD_FAILURE() << "no error";
    return {};
}

using beamctl::test::TempDir;

} // namespace

TEST(ConfigFiles, PlantFileReportsEveryError) {
    const char* text = "slaves:\n"                                                   // 1
                       "  - {position: 0, type: EL1008}\n"                           // 2
                       "  - {position: 1, type: EL7041}\n"                           // 3
                       "stages:\n"                                                   // 4
                       "  - {name: x, drive: s1, mass: -1, travel: [5, -5]}\n"       // 5
                       "  - {name: y, drive: 11, weight: 3}\n"                       // 6
                       "signals:\n"                                                  // 7
                       "  - {to: s0.binaryInput01, shape: triangle, frequency: -1}\n" // 8
                       "wirng: []\n";                                                // 9
    const auto e = errors_of([&] {
        ethercat::sim::SimConfig::parse(text, "plant.yaml", ethercat::Catalog::builtin());
    });
    const std::vector<std::string> want = {
        "plant.yaml:5:32: stages[0].mass should be > 0, got -1",
        "plant.yaml:5:44: stages[0].travel: min 5 should be below max -5",
        "plant.yaml:6:22: stages[1].drive: '11' should look like s<position>, e.g. s11",
        "plant.yaml:6:26: unknown key 'weight' in stages[1] (expected one of: name, drive, mass, "
        "friction, damping, travel, start, pitch, steps_per_rev, max_force, velocity_scale, "
        "quick_stop_decel, overload_time, feedback_counts_per_rev, encoders, limits, home)",
        "plant.yaml:8:35: signals[0].shape: unknown shape 'triangle' (expected constant, sine, "
        "square, ramp, noise)",
        "plant.yaml:8:56: signals[0].frequency should be >= 0, got -1",
        "plant.yaml:9:1: unknown key 'wirng' in the simulator configuration (did you mean "
        "'wiring'?)",
    };
    EXPECT_EQ(e, want) << joined(e);
}

TEST(ConfigFiles, PlantWiringErrorsAreAllReportedOnceTheFileIsRight) {
    const char* text = "slaves:\n"
                       "  - {position: 0, type: EL1008}\n"
                       "  - {position: 1, type: EL7041}\n"
                       "  - {position: 2, type: EL3104}\n"
                       "stages:\n"
                       "  - {name: x, drive: s2}\n"                              // 6: not a drive
                       "signals:\n"
                       "  - {to: s0.binaryInput01, shape: sine}\n"              // 8: 1 bit
                       "  - {to: s2.analogInput01, stage: nope}\n"              // 9: no stage
                       "  - {to: s1.positionActual01, shape: sine}\n";          // 10: driven
    const auto e = errors_of([&] {
        ethercat::sim::SimConfig::parse(text, "plant.yaml", ethercat::Catalog::builtin());
    });
    ASSERT_EQ(e.size(), 4u) << joined(e);
    EXPECT_EQ(e[0].rfind("plant.yaml:6:", 0), 0u) << e[0];
    EXPECT_NE(e[0].find("EL3104, not a drive"), std::string::npos) << e[0];
    EXPECT_EQ(e[1].rfind("plant.yaml:8:", 0), 0u) << e[1];
    EXPECT_NE(e[1].find("a signal drives a 16-bit analog input"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("no stage named 'nope'"), std::string::npos) << e[2];
    EXPECT_EQ(e[3].rfind("plant.yaml:10:", 0), 0u) << e[3];
    EXPECT_NE(e[3].find("already driven (by the default stage of s1)"), std::string::npos) << e[3];
}

TEST(ConfigFiles, CatalogDeviceFileReportsEveryErrorAndChangesNothing) {
    TempDir dir;
    const std::string file = dir.write("bad.yaml", R"(type: XT0002
nmae: "XT0002 test terminal"
vendor: 2
product: 0x0001G052
sync_managers:
  - {index: 0, start: 0x1000, control: 0x00, type: Input}
tx_pdos:
  - index: 0x1600
    entries:
      - {index: 0x6000, sub: 1, bits: 2, name: binaryInput01, datatype: BOOL}
      - {index: 0, bits: 7, name: gap}
)");
    ethercat::Catalog cat;
    const auto e = errors_of([&] { cat.load_yaml(file); });
    const std::vector<std::string> want = {
        file + ":1:1: the device: missing required key 'revision'",
        file + ":2:1: unknown key 'nmae' in the device (did you mean 'name'?)",
        file + ":4:10: product should be an unsigned integer, got '0x0001G052'",
        file + ":6:52: sync_managers[0].type: 'Input' should be one of MBoxOut, MBoxIn, Outputs, "
               "Inputs, Unused",
        file + ":8:12: tx_pdos[0].index: 0x1600 should be in 0x1A00-0x1BFF (TxPDO, inputs)",
        file + ":10:39: tx_pdos[0].entries[0].bits: 2 should be 1 for datatype BOOL",
        file + ":11:35: tx_pdos[0].entries[1].name: padding (index 0) has no name",
    };
    EXPECT_EQ(e, want) << joined(e);
    EXPECT_EQ(cat.size(), 0u) << "a bad file changes nothing";
}

TEST(ConfigFiles, CatalogDirectoryReportsEveryBadFileAndLoadsTheGoodOnes) {
    TempDir dir;
    dir.write("a.yaml", "type: A\nname: a\nvendor: 2\nproduct: 1\nrevision: x\n");
    dir.write("b.yaml", "type: B\nname: b\nvendor: 2\nproduct: 2\nrevision: 1\n");
    dir.write("c.yaml", "type: C\nname: c\nvendor: -2\nproduct: 3\nrevision: 1\nfoo: 1\n");
    ethercat::Catalog cat;
    const auto e = errors_of([&] { cat.load_dir(dir.path.string()); });
    const std::string d = dir.path.string();
    const std::vector<std::string> want = {
        d + "/a.yaml:5:11: revision should be an unsigned integer, got 'x'",
        d + "/c.yaml:3:9: vendor should be an unsigned integer, got '-2'",
        d + "/c.yaml:6:1: unknown key 'foo' in the device (expected one of: type, variant_of, "
            "name, vendor, product, revision, coe, dc_assign_activate, ebus_current_ma, "
            "sync_managers, rx_pdos, tx_pdos, oversampling)",
    };
    EXPECT_EQ(e, want) << joined(e);
    EXPECT_EQ(cat.types(), std::vector<std::string>{"B"});
}

TEST(ConfigFiles, RcpModelReportsEveryError) {
    const char* text = "application: demo\n"                                            // 1
                       "rate_hz: 0\n"                                                   // 2
                       "ioc: {host: localhost, port: 70000}\n"                          // 3
                       "objects:\n"                                                     // 4
                       "  - {id: 1, name: A, type: AO}\n"                               // 5
                       "  - {id: 1, name: B, type: AI, plant: {input: Nope}}\n"         // 6
                       "  - {id: 300, name: C, type: BI, within: {value: A}}\n"         // 7
                       "  - {id: 4, name: D, type: MOTOR, motor: {velocity: 5, max_velocity: 2}}\n"; // 8
    const auto e = errors_of([&] { bridge::rcp::ModelConfig::parse(text, "m.yaml"); });
    const std::vector<std::string> want = {
        "m.yaml:2:10: rate_hz should be > 0 and <= 100000, got 0",
        "m.yaml:3:13: ioc.host: 'localhost' should be an IPv4 address such as 127.0.0.1",
        "m.yaml:3:30: ioc.port should be from 1 to 65535, got 70000",
        "m.yaml:6:5: objects[1]: object id 1 is used twice",
        "m.yaml:6:5: objects[1]: plant input: no object named 'Nope'",
        "m.yaml:7:10: objects[2].id should be from 1 to 255, got 300",
        "m.yaml:7:34: objects[2].within: missing required key 'target' (an object name)",
        "m.yaml:8:53: objects[3].motor.velocity: 5 exceeds max_velocity 2",
    };
    EXPECT_EQ(e, want) << joined(e);
}

TEST(ConfigFiles, AxisFileReportsEveryErrorThrownOrCollected) {
    const char* text = "axis:\n"                                            // 1
                       "  id: 1\n"                                          // 2
                       "  typ: joint\n"                                     // 3
                       "drive:\n"                                           // 4
                       "  numerator: 0\n"                                   // 5
                       "  setpoint: ec0.s2.velocitySetpoint01\n"            // 6
                       "  control: ec0.s2.driveControl01\n"                 // 7
                       "  status: ec0.s2.driveStatus01\n"                   // 8
                       "encoder:\n"                                         // 9
                       "  numerator: 1\n"                                   // 10
                       "  position: ec0.s2.positionActual01\n"              // 11
                       "  bits: 99\n"                                       // 12
                       "trajectory:\n"                                      // 13
                       "  axis:\n"                                          // 14
                       "    velocty: 5\n"                                   // 15
                       "    acceleration: -1\n"                             // 16
                       "input:\n"                                           // 17
                       "  limit:\n"                                         // 18
                       "    forward: ec0.s1.binaryInput01\n"                // 19
                       "    backward: ec0.s1.binaryInput02\n"               // 20
                       "monitoring: {}\n";                                  // 21
    // Unknown keys are warnings (ECMC's loader drops them); a misspelt required key is the
    // missing key's error.
    const std::vector<std::string> want = {
        "axis.yaml:5:14: drive.numerator should not be 0 (it scales the setpoint)",
        "axis.yaml:12:9: encoder.bits should be from 0 to 64, got 99",
        "axis.yaml:14:3: trajectory.axis: missing required key 'velocity' ('velocty' is not it)",
        "axis.yaml:16:19: trajectory.axis.acceleration should be > 0, got -1",
    };
    EXPECT_EQ(errors_of([&] { motion::parse_axis_config(text, "axis.yaml", {}); }), want);
    std::vector<Error> collected;
    motion::parse_axis_config(text, "axis.yaml", {}, collected);
    std::vector<std::string> got;
    for (const auto& e : collected) got.push_back(e.what());
    EXPECT_EQ(got, want) << joined(got);
}
