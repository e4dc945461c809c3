// The IOC file through the one reader: every section read with its defaults, the places of the
// files it names, and a file with many errors reporting each with file:line:col in one pass.
#include "config/ioc_config.hpp"

#include "core/error_list.hpp"

#include <gtest/gtest.h>

using namespace beamctl;
using namespace beamctl::config;

namespace {

std::string joined(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += x + "\n";
    return s;
}

std::vector<std::string> errors_of(const std::string& text) {
    ErrorList e;
    IocConfig::parse(text, "/cfg/ioc.yaml", e);
    return e.messages();
}

} // namespace

TEST(IocConfig, ReadsEverySectionWithPlacesOfTheFilesItNames) {
    const char* text = R"(ioc: {name: DEMO}
engine: {rate_hz: 2000, cpu: 1, priority: 70}
buses:
  - id: 0
    link: {type: sim, plant: plant.yaml}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 2, type: EL7041, sdo: [{index: 0x8010, sub: 1, value: 1000, size: 2}]}
axes:
  - {file: axes/x.yaml, macros: {AX_ID: 1, DRV_SLAVE: 2}, encoders: [{file: enc.yaml}]}
plcs:
  - {file: main.plc, rate_ms: 10, enable: false, include: [lib], macros: {A: 1}}
kinematics:
  - {name: slit, virtual: [11, 12], real: [1, 2], inverse: "ax1 := ax11;"}
  - {virtual: [13], real: [3], file: /abs/k.plc_inc}
db:
  - {file: extra.db, macros: {P: "X:"}}
bridges:
  rcp: {port: 18066, timeout_s: 2, motor_fields: {DHLM: 45}}
ca: {port: 5070, acf: access.acf}
)";
    IocConfig c = IocConfig::parse(text, "/cfg/ioc.yaml");
    EXPECT_EQ(c.name, "DEMO");
    EXPECT_EQ(c.prefix, "DEMO:");
    EXPECT_EQ(c.rate_hz, 2000);
    EXPECT_EQ(c.cpu, 1);
    EXPECT_EQ(c.priority, 70);
    ASSERT_EQ(c.buses.size(), 1u);
    EXPECT_EQ(c.buses[0].link.plant, "/cfg/plant.yaml");
    EXPECT_EQ(c.buses[0].link.plant_where, "/cfg/ioc.yaml:5:30");
    ASSERT_EQ(c.buses[0].slaves.size(), 2u);
    EXPECT_EQ(c.buses[0].slaves[1].type, "EL7041");
    EXPECT_EQ(c.buses[0].slaves[1].type_where, "/cfg/ioc.yaml:8:29");
    ASSERT_EQ(c.buses[0].slaves[1].sdo.size(), 1u);
    EXPECT_EQ(c.buses[0].slaves[1].sdo[0].index, 0x8010);
    EXPECT_EQ(c.buses[0].slaves[1].sdo[0].size, 2);
    EXPECT_EQ(c.buses[0].slaves[1].sdo[0].value, 1000u);
    ASSERT_EQ(c.axes.size(), 1u);
    EXPECT_EQ(c.axes[0].file, "/cfg/axes/x.yaml");
    EXPECT_EQ(c.axes[0].file_where, "/cfg/ioc.yaml:10:12");
    EXPECT_EQ(c.axes[0].where, "/cfg/ioc.yaml:10:5");
    EXPECT_EQ(c.axes[0].macros.at("DRV_SLAVE"), "2");
    ASSERT_EQ(c.axes[0].encoders.size(), 1u);
    EXPECT_EQ(c.axes[0].encoders[0].file, "/cfg/enc.yaml");
    ASSERT_EQ(c.plcs.size(), 1u);
    EXPECT_EQ(c.plcs[0].id, 0);
    EXPECT_EQ(c.plcs[0].rate_ms, 10);
    EXPECT_FALSE(c.plcs[0].enable);
    EXPECT_EQ(c.plcs[0].include, std::vector<std::string>{"/cfg/lib"});
    ASSERT_EQ(c.kinematics.size(), 2u);
    EXPECT_EQ(c.kinematics[0].name, "slit");
    EXPECT_EQ(c.kinematics[0].virt, (std::vector<int>{11, 12}));
    EXPECT_EQ(c.kinematics[0].code, "ax1 := ax11;");
    EXPECT_EQ(c.kinematics[1].name, "kinematics[1]");
    EXPECT_EQ(c.kinematics[1].file, "/abs/k.plc_inc");
    ASSERT_EQ(c.db.size(), 1u);
    EXPECT_EQ(c.db[0].macros.at("P"), "X:");
    ASSERT_TRUE(c.rcp);
    EXPECT_EQ(c.rcp->prefix, "DEMO:RCP:");
    EXPECT_EQ(c.rcp->port, 18066);
    EXPECT_EQ(c.rcp->timeout_s, 2);
    EXPECT_EQ(c.rcp->motor_fields.size(), 1u);
    EXPECT_EQ(c.ca_port, 5070);
    EXPECT_EQ(c.acf, "/cfg/access.acf");
}

TEST(IocConfig, DefaultsForAMinimalFile) {
    IocConfig c = IocConfig::parse("ioc: {name: T, prefix: \"P:\"}\n", "ioc.yaml");
    EXPECT_EQ(c.prefix, "P:");
    EXPECT_EQ(c.rate_hz, 1000);
    EXPECT_EQ(c.cpu, -1);
    EXPECT_EQ(c.priority, 80);
    EXPECT_TRUE(c.buses.empty());
    EXPECT_FALSE(c.rcp);
    EXPECT_FALSE(c.ca_port);
}

TEST(IocConfig, EveryErrorOfTheFileInOnePass) {
    const char* text = "ioc: {name: \"A B\"}\n"                                      // 1
                       "engine: {rate_hz: 0, cpus: 1}\n"                             // 2
                       "buses:\n"                                                    // 3
                       "  - id: 0\n"                                                 // 4
                       "    link: {type: simm}\n"                                    // 5
                       "    slaves:\n"                                               // 6
                       "      - {position: 1, type: EL1008}\n"                       // 7
                       "      - {position: 1, type: EL2008}\n"                       // 8
                       "      - {position: 2, type: EL7041, sdo: [{index: 0x8010, value: 70000, size: 2}]}\n" // 9
                       "axes:\n"                                                     // 10
                       "  - {macros: {A: 1}}\n"                                      // 11
                       "plcs:\n"                                                     // 12
                       "  - {file: a.plc, rate_ms: 0}\n"                             // 13
                       "  - {id: 0, file: b.plc}\n"                                  // 14
                       "kinematics:\n"                                               // 15
                       "  - {virtual: [], real: [1], inverse: x, file: y}\n"         // 16
                       "web: {port: 8080}\n";                                        // 17
    const auto e = errors_of(text);
    const std::vector<std::string> want = {
        "/cfg/ioc.yaml:1:14: ioc.name: 'A B' should be a plain PV name part",
        "/cfg/ioc.yaml:2:19: engine.rate_hz should be from 1 to 20000, got 0",
        "/cfg/ioc.yaml:2:22: unknown key 'cpus' in engine (did you mean 'cpu'?)",
        "/cfg/ioc.yaml:5:18: buses[0].link.type should be sim, udp, raw or scanner, got 'simm' (did you "
        "mean 'sim'?)",
        "/cfg/ioc.yaml:8:20: buses[0].slaves[1].position: 1 is used twice",
        "/cfg/ioc.yaml:9:66: buses[0].slaves[2].sdo[0].value should be from 0 to 65535, got 70000",
        "/cfg/ioc.yaml:11:5: axes[0]: missing required key 'file' (an ECMC axis YAML file)",
        "/cfg/ioc.yaml:13:28: plcs[0].rate_ms: 0 should be > 0, or -1 (every cycle)",
        "/cfg/ioc.yaml:14:5: plcs[1]: PLC id 0 used twice",
        "/cfg/ioc.yaml:16:5: kinematics[0]: give the inverse transform as 'inverse' (PLC code) or "
        "'file', one of them",
        "/cfg/ioc.yaml:16:15: kinematics[0].virtual: should be a list of axis ids",
        "/cfg/ioc.yaml:17:1: unknown key 'web' in the IOC file: it is not supported by this "
        "version of beamctl yet",
    };
    EXPECT_EQ(e, want) << joined(e);
    try {
        IocConfig::parse(text, "/cfg/ioc.yaml");
        FAIL() << "no error";
    } catch (const MultiError& m) {
        EXPECT_EQ(m.errors(), want);
    }
}

TEST(IocConfig, StructuralErrors) {
    EXPECT_EQ(errors_of(""), std::vector<std::string>{"/cfg/ioc.yaml:1:1: empty configuration "
                                                      "(needs at least ioc:)"});
    EXPECT_EQ(errors_of("- a\n"), std::vector<std::string>{"/cfg/ioc.yaml:1:1: the IOC file should "
                                                           "be a mapping (key: value lines), got a "
                                                           "list"});
    EXPECT_EQ(errors_of("engine: {}\n"),
              std::vector<std::string>{"/cfg/ioc.yaml:1:1: the IOC file: missing required key "
                                       "'ioc' ({name: ..., prefix: ...})"});
    auto e = errors_of("ioc: {name: T}\nbuses: [{id: 0, link: {type: raw}}]\n");
    EXPECT_EQ(e, (std::vector<std::string>{
                     "/cfg/ioc.yaml:2:9: buses[0]: missing required key 'slaves' (a list of "
                     "{position, type})",
                     "/cfg/ioc.yaml:2:23: buses[0].link: a raw link needs 'iface' (the network "
                     "interface of the segment)"}))
        << joined(e);
    e = errors_of("ioc: {name: T}\nbuses: [{slaves: [{position: 0}]}]\nca: {port: 70000}\n");
    EXPECT_EQ(e, (std::vector<std::string>{
                     "/cfg/ioc.yaml:2:19: buses[0].slaves[0]: missing required key 'type' (a "
                     "device of the catalog, e.g. EL1008)",
                     "/cfg/ioc.yaml:3:12: ca.port should be from 0 to 65535, got 70000"}))
        << joined(e);
    e = errors_of("ioc: {name: T}\nbridges: {rcp: {timeout_s: 0}}\n");
    EXPECT_EQ(e, (std::vector<std::string>{
                     "/cfg/ioc.yaml:2:28: bridges.rcp.timeout_s should be > 0 and <= 3600, got 0"}))
        << joined(e);
    e = errors_of("ioc: {name: T}\nioc: {name: U}\n");
    EXPECT_EQ(e, (std::vector<std::string>{
                     "/cfg/ioc.yaml:2:1: duplicate key 'ioc' in the IOC file (also at line 1)"}))
        << joined(e);
}

TEST(IocConfig, AMissingFileAndMacroErrorsAreErrorsToo) {
    ErrorList e;
    IocConfig::load("/nonexistent/ioc.yaml", e);
    EXPECT_EQ(e.messages(), std::vector<std::string>{"/nonexistent/ioc.yaml: cannot open: No such "
                                                     "file or directory"});
    EXPECT_THROW(IocConfig::load("/nonexistent/ioc.yaml"), Error);
}

TEST(IocConfig, FeedbackAndDetectorSections) {
    const std::string ok = "ioc: {name: T}\n"
                           "feedback:\n"
                           "  - {name: f1, input: ax1.enc.actpos, output: ec0.s2.analogOutput01, kp: 1, drvh: 2, drvl: -2, dt: 0.01}\n"
                           "detectors:\n"
                           "  mca:\n"
                           "    - {name: mca1, channels: 1024, slope: 0.02, lines: [{name: Fe Ka, energy: 6.4, rate: 100}]}\n";
    config::IocConfig c = config::IocConfig::parse(ok, "/cfg/ioc.yaml");
    ASSERT_EQ(c.feedback.size(), 1u);
    EXPECT_EQ(c.feedback[0].output, "ec0.s2.analogOutput01");
    EXPECT_EQ(c.feedback[0].dt, 0.01);
    ASSERT_EQ(c.mca.size(), 1u);
    EXPECT_EQ(c.mca[0].channels, 1024u);
    ASSERT_EQ(c.mca[0].lines.size(), 1u);
    EXPECT_EQ(c.mca[0].lines[0].fwhm, 0.15);
    const auto e = errors_of("ioc: {name: T}\n"
                             "feedback:\n"
                             "  - {name: f1, input: x, output: y, drvh: 1, drvl: 2}\n"
                             "  - {name: f1, input: x, output: y}\n"
                             "detectors:\n"
                             "  mca:\n"
                             "    - {name: m, slope: 0, lines: [{energy: 1}]}\n");
    ASSERT_EQ(e.size(), 5u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("ioc.yaml:3:"), std::string::npos);
    EXPECT_NE(e[0].find("drvl 2 is above drvh 1"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("ioc.yaml:4:"), std::string::npos);
    EXPECT_NE(e[1].find("needs drvh and drvl"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("defined twice"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("should not be 0"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("rate"), std::string::npos) << e[4];
}

TEST(IocConfig, AreaDetectorSection) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "detectors:\n"
                                                   "  area_detector:\n"
                                                   "    - {size: [320, 240], pixel_size: 0.01, data_type: UInt8, acquire_time: 0.5, file_path: /data}\n"
                                                   "    - {cam: cam2, image: image2, hdf: HDF2, stats: Stats2, bus: 1, centre: [1, -2]}\n"
                                                   "  mca:\n"
                                                   "    - {name: mca1, bus: 2}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.area_detector.size(), 2u);
    EXPECT_EQ(c.area_detector[0].cam, "cam1");
    EXPECT_EQ(c.area_detector[0].size_x, 320);
    EXPECT_EQ(c.area_detector[0].data_type, "UInt8");
    EXPECT_EQ(c.area_detector[0].acquire_time, 0.5);
    EXPECT_EQ(c.area_detector[0].file_path, "/data");
    EXPECT_EQ(c.area_detector[0].bus, -1);
    EXPECT_EQ(c.area_detector[1].stats, "Stats2");
    EXPECT_EQ(c.area_detector[1].bus, 1);
    EXPECT_EQ(c.area_detector[1].centre_y, -2);
    ASSERT_EQ(c.mca.size(), 1u);
    EXPECT_EQ(c.mca[0].bus, 2);
    const auto e = errors_of("ioc: {name: T}\n"
                             "detectors:\n"
                             "  area_detector:\n"
                             "    - {size: [320], data_type: RGB, pixel_size: 0}\n"
                             "    - {hdf: HDF2, stats: Stats2, image: \"im 1\"}\n");
    ASSERT_EQ(e.size(), 5u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("ioc.yaml:4:"), std::string::npos) << e[0];
    EXPECT_NE(e[0].find("should be [x, y] pixels"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("'RGB' is not a data type"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("pixel_size should be from 1e-06 to 100, got 0"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("area_detector cam 'cam1' is defined twice"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("'im 1' should be a plain PV name part"), std::string::npos) << e[4];
}

TEST(IocConfig, QuadEmSection) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "detectors:\n"
                                                   "  quadem:\n"
                                                   "    - {name: QE1, currents: [a, b, c, d], geometry: Diamond, averaging_time: 0.5,\n"
                                                   "       current_scale: [1, 2, 3, 4], position_scale: [10, 20], egu: um}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.quadem.size(), 1u);
    EXPECT_EQ(c.quadem[0].currents, (std::vector<std::string>{"a", "b", "c", "d"}));
    EXPECT_EQ(c.quadem[0].geometry, "Diamond");
    EXPECT_EQ(c.quadem[0].averaging_time, 0.5);
    EXPECT_EQ(c.quadem[0].current_scale[3], 4);
    EXPECT_EQ(c.quadem[0].position_scale[1], 20);
    EXPECT_EQ(c.quadem[0].position_offset[0], 0);
    const auto e = errors_of("ioc: {name: T}\n"
                             "detectors:\n"
                             "  quadem:\n"
                             "    - {name: QE1, currents: [a, b, c], geometry: Round}\n"
                             "    - {name: QE1, currents: [a, b, c, d], position_scale: [1], averaging_time: -1}\n"
                             "    - {name: QE2}\n");
    ASSERT_EQ(e.size(), 6u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("ioc.yaml:4:"), std::string::npos) << e[0];
    EXPECT_NE(e[0].find("should name four values, got 3"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("'Round' is not a geometry"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("defined twice"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("position_scale: should be 2 numbers"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("averaging_time should be from 0 to 3600, got -1"), std::string::npos) << e[4];
    EXPECT_NE(e[5].find("ioc.yaml:6:"), std::string::npos) << e[5];
    EXPECT_NE(e[5].find("currents"), std::string::npos) << e[5];
}

TEST(IocConfig, McaElementsAndDxpSettings) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "detectors:\n"
                                                   "  mca:\n"
                                                   "    - {name: mca1, elements: 4, preamp_gains: [2, 2.1, 1.9, 2], noise_fwhm: 0.05,\n"
                                                   "       dxp: {peaking_time: 4, energy_threshold: 0.5, max_energy: 30}}\n"
                                                   "    - {name: fluo}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.mca.size(), 2u);
    const config::McaEntry& m = c.mca[0];
    EXPECT_EQ(m.elements, 4);
    EXPECT_EQ(m.element_name(3), "mca4");
    EXPECT_EQ(m.dxp_prefix(2), "dxp3:");
    EXPECT_EQ(m.sum_name(), "mcaSum");
    EXPECT_EQ(m.preamp_gains[1], 2.1);
    EXPECT_EQ(m.noise_fwhm, 0.05);
    EXPECT_EQ(m.dxp.peaking_time, 4);
    EXPECT_EQ(m.dxp.gap_time, 0.15);
    EXPECT_EQ(m.dxp.energy_threshold, 0.5);
    EXPECT_EQ(m.dxp.max_energy, 30);
    EXPECT_EQ(c.mca[1].dxp_prefix(0), "dxp_fluo:");
    const auto e = errors_of("ioc: {name: T}\n"
                             "detectors:\n"
                             "  mca:\n"
                             "    - {name: det, elements: 2}\n"
                             "    - {name: mca1, elements: 3, preamp_gains: [2, 2]}\n"
                             "    - {name: mca3}\n"
                             "    - {name: m7, elements: 2}\n"
                             "    - {name: mca9, dxp: {peaking_time: 0, max_energy: 0.001}, offset: 1}\n");
    ASSERT_EQ(e.size(), 6u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("should end in the first element's number"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("one gain [mV/keV] per element (3), not 2"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("mca 'mca3' is defined twice"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("only one multi-element detector"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("peaking_time"), std::string::npos) << e[4];
    EXPECT_NE(e[5].find("above the spectrum's offset"), std::string::npos) << e[5];
}

TEST(IocConfig, QuadEmRanges) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "detectors:\n"
                                                   "  quadem:\n"
                                                   "    - {name: QE1, currents: [a, b, c, d], range: 1,\n"
                                                   "       ranges: [{name: \"+-2 uA\", full_scale: 2}, {name: \"+-200 nA\", full_scale: 0.2}]}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.quadem.size(), 1u);
    ASSERT_EQ(c.quadem[0].ranges.size(), 2u);
    EXPECT_EQ(c.quadem[0].ranges[1].name, "+-200 nA");
    EXPECT_EQ(c.quadem[0].ranges[1].full_scale, 0.2);
    EXPECT_EQ(c.quadem[0].range, 1);
    const auto e = errors_of("ioc: {name: T}\n"
                             "detectors:\n"
                             "  quadem:\n"
                             "    - {name: QE1, currents: [a, b, c, d], range: 2, ranges: [{name: a, full_scale: -1}]}\n");
    ASSERT_EQ(e.size(), 2u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("range 2 is not one of the 1 ranges"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("full_scale should be >= 0, got -1"), std::string::npos) << e[1];
}

TEST(IocConfig, CompoundMotors) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "compound_motors:\n"
                                                   "  - name: slit\n"
                                                   "    reals: {top: \"S:top\", bot: \"S:bot\"}\n"
                                                   "    inputs: {g: \"S:gain.VAL\"}\n"
                                                   "    virtuals:\n"
                                                   "      gap: {forward: \"top - bot\", egu: mm, prec: 4, velocity: 2}\n"
                                                   "      centre: {forward: \"(top + bot) / 2\"}\n"
                                                   "    inverse: {top: \"centre + gap / 2\", bot: \"centre - gap / 2\"}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.compound_motors.size(), 1u);
    const auto& g = c.compound_motors[0];
    EXPECT_EQ(g.name, "slit");
    ASSERT_EQ(g.reals.size(), 2u);
    EXPECT_EQ(g.reals[1].name, "bot");
    EXPECT_EQ(g.reals[1].pv, "S:bot");
    ASSERT_EQ(g.inputs.size(), 1u);
    EXPECT_EQ(g.inputs[0].pv, "S:gain.VAL");
    ASSERT_EQ(g.virtuals.size(), 2u);
    EXPECT_EQ(g.virtuals[0].name, "gap");
    EXPECT_EQ(g.virtuals[0].egu, "mm");
    EXPECT_EQ(g.virtuals[0].prec, 4);
    EXPECT_EQ(g.virtuals[0].velocity, 2);
    EXPECT_EQ(g.virtuals[1].forward, "(top + bot) / 2");
    ASSERT_EQ(g.inverse.size(), 2u);
    EXPECT_EQ(g.inverse[0], std::make_pair(std::string("top"), std::string("centre + gap / 2")));
    const auto e = errors_of("ioc: {name: T}\n"
                             "compound_motors:\n"
                             "  - name: a\n"
                             "    reals: {x: \"M:x\", 2y: \"M:y\"}\n"
                             "    virtuals: {x: {forward: \"x\"}, v: {egu: mm}}\n"
                             "    inverse: {z: \"v\"}\n"
                             "  - name: b\n"
                             "    reals: {r: \"M:r\"}\n"
                             "    virtuals: {v: {forward: \"r\"}}\n"
                             "    inverse: {r: \"v\"}\n");
    ASSERT_EQ(e.size(), 5u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("'2y' is not a name the expressions can use"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("'x' is used twice in compound motor group 'a'"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("forward"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("'z' is not one of the group's reals"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("compound motor 'v' is defined twice"), std::string::npos) << e[4];
}

TEST(IocConfig, StateMachines) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "state_machines:\n"
                                                   "  - name: m\n"
                                                   "    states: {a: {}, b: {parent: a, invariant: \"x > 1\", entry: [{delay: 0.5}]}, l: {}}\n"
                                                   "    initial: a\n"
                                                   "    latch: l\n"
                                                   "    names: {x: \"P:x\"}\n"
                                                   "    transitions:\n"
                                                   "      - {from: a, to: b, guard: \"x > 0\", timeout: 20,\n"
                                                   "         steps: [{put: \"P:y\", value: 2, wait: false, timeout: 3}, {wait_for: \"x > 1\", timeout: 4}]}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.state_machines.size(), 1u);
    const auto& m = c.state_machines[0];
    ASSERT_EQ(m.states.size(), 3u);
    EXPECT_EQ(m.states[1].parent, "a");
    EXPECT_EQ(m.states[1].invariant, "x > 1");
    ASSERT_EQ(m.states[1].entry.size(), 1u);
    EXPECT_EQ(m.states[1].entry[0].kind, config::StateMachineEntry::Step::Kind::Delay);
    EXPECT_EQ(m.initial, "a");
    EXPECT_EQ(m.latch, "l");
    EXPECT_EQ(m.after_ack, "a"); // the initial state by default
    ASSERT_EQ(m.transitions.size(), 1u);
    const auto& t = m.transitions[0];
    EXPECT_EQ(t.name, "a->b");
    EXPECT_EQ(t.timeout, 20);
    ASSERT_EQ(t.steps.size(), 2u);
    EXPECT_EQ(t.steps[0].pv, "P:y");
    EXPECT_EQ(t.steps[0].value, 2);
    EXPECT_FALSE(t.steps[0].wait);
    EXPECT_EQ(t.steps[0].seconds, 3);
    EXPECT_EQ(t.steps[1].expr, "x > 1");
    const auto e = errors_of("ioc: {name: T}\n"
                             "state_machines:\n"
                             "  - name: m\n"
                             "    states: {a: {parent: z}, b: {}}\n"
                             "    initial: c\n"
                             "    transitions:\n"
                             "      - {from: a, to: q}\n"
                             "      - {from: a, to: b, steps: [{put: \"P:y\"}, {delay: 1, wait_for: \"1\"}]}\n");
    ASSERT_EQ(e.size(), 5u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("'z' is not another state of 'm'"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("'c' is not a state of 'm'"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("'q' is not a state of 'm'"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("value"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("a step is one of put"), std::string::npos) << e[4];
}

TEST(IocConfig, Notify) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "state_machines:\n"
                                                   "  - {name: m, states: {a: {}}, initial: a}\n"
                                                   "notify:\n"
                                                   "  smtp: {host: mail.lab, port: 2525, from: ioc@lab, to: [a@lab, b@lab]}\n"
                                                   "  webhooks: [\"http://hooks.lab:8080/x/y\", \"http://h2/\"]\n"
                                                   "  rules: [{state_machine: m}, {pv: \"P:t\", severity: MINOR}]\n"
                                                   "  min_interval: 30\n"
                                                   "  retries: 1\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_TRUE(c.notify);
    const auto& n = *c.notify;
    EXPECT_EQ(n.smtp_host, "mail.lab");
    EXPECT_EQ(n.smtp_port, 2525);
    EXPECT_EQ(n.to, (std::vector<std::string>{"a@lab", "b@lab"}));
    ASSERT_EQ(n.webhooks.size(), 2u);
    EXPECT_EQ(n.webhooks[0].host, "hooks.lab");
    EXPECT_EQ(n.webhooks[0].port, 8080);
    EXPECT_EQ(n.webhooks[0].path, "/x/y");
    EXPECT_EQ(n.webhooks[1].port, 80);
    ASSERT_EQ(n.rules.size(), 2u);
    EXPECT_EQ(n.rules[1].pv, "P:t");
    EXPECT_EQ(n.rules[1].severity, 1);
    EXPECT_EQ(n.min_interval_s, 30);
    EXPECT_EQ(n.retries, 1);
    const auto e = errors_of("ioc: {name: T}\n"
                             "notify:\n"
                             "  webhooks: [\"https://secure/\"]\n"
                             "  rules: [{state_machine: nope}, {pv: a, state_machine: b}, {pv: x, severity: LOUD}]\n");
    ASSERT_EQ(e.size(), 5u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("needs smtp: or webhooks:"), std::string::npos) << e[0]; // errors in file order
    EXPECT_NE(e[1].find("https is not supported"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("'nope' is not one of state_machines:"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("a rule names one of state_machine: or pv:"), std::string::npos) << e[3];
    EXPECT_NE(e[4].find("LOUD"), std::string::npos) << e[4];
}

TEST(IocConfig, CollisionZones) {
    config::IocConfig c = config::IocConfig::parse("ioc: {name: T}\n"
                                                   "collision_zones:\n"
                                                   "  - {name: z, axes: {l: \"M:l\", x: \"M:x\"}, forbidden: \"l > 5 and x > 4\", lookahead: 0.5}\n",
                                                   "/cfg/ioc.yaml");
    ASSERT_EQ(c.collision_zones.size(), 1u);
    EXPECT_EQ(c.collision_zones[0].axes[1], std::make_pair(std::string("x"), std::string("M:x")));
    EXPECT_EQ(c.collision_zones[0].forbidden, "l > 5 and x > 4");
    EXPECT_EQ(c.collision_zones[0].lookahead_s, 0.5);
    const auto e = errors_of("ioc: {name: T}\n"
                             "collision_zones:\n"
                             "  - {name: z, axes: {}, lookahead: 20}\n"
                             "  - {name: z, axes: {a: \"M:a\"}, forbidden: \"a > 1\"}\n");
    ASSERT_EQ(e.size(), 4u) << ::testing::PrintToString(e);
    EXPECT_NE(e[0].find("missing required key 'forbidden'"), std::string::npos) << e[0];
    EXPECT_NE(e[1].find("needs at least one axis"), std::string::npos) << e[1];
    EXPECT_NE(e[2].find("lookahead"), std::string::npos) << e[2];
    EXPECT_NE(e[3].find("collision zone 'z' is defined twice"), std::string::npos) << e[3];
}
