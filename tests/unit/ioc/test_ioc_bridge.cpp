// Two buses in one IOC bridged by a simulated EL6692 (primary on ec0, secondary on ec1, joined by
// the pair name their plants give it): a PLC writes on one bus, another PLC reads the value on the
// other bus and answers; the status word says when the other side is gone.
#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "ethercat/sim/faults.hpp"
#include "ethercat/sim/sim_config.hpp"
#include "virtual_ioc.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

const char* kIoc = R"(ioc: {name: BR}
engine: {rate_hz: 1000}
buses:
  - id: 0
    link: {type: sim, plant: a.yaml}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL6692}
  - id: 1
    link: {type: sim, plant: b.yaml}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL6692-0002}
plcs:
  - {id: 0, file: a.plc}
  - {id: 1, file: b.plc}
)";

struct Bridged {
    TempDir dir;
    std::unique_ptr<VirtualIoc> v;
    explicit Bridged(const std::string& plant_b = "bridges:\n  - {slave: 1, pair: gap_mono}\n") {
        dir.write("a.yaml", "bridges:\n  - {slave: 1, pair: gap_mono}\n");
        dir.write("b.yaml", plant_b);
        // bus 0 counts and sends; bus 1 reads it and answers with the count + 1000
        dir.write("a.plc", "static.n += 1;\nec0.s1.outInt01 := static.n;\nec0.s1.outLreal01 := static.n * 0.25;\n"
                           "static.back := ec0.s1.inInt02;\n");
        dir.write("b.plc", "static.got := ec1.s1.inLreal01;\nec1.s1.outInt02 := ec1.s1.inInt01 + 1000;\n");
        v = std::make_unique<VirtualIoc>(dir.write("ioc.yaml", kIoc));
    }
    double entry(const std::string& name) {
        std::string why;
        registry::BoundSignal s = v->ioc->signals().bind(name, why);
        if (!s.bound()) throw std::runtime_error(why);
        return double(s.get());
    }
};

TEST(IocBridge, APlcOnOneBusReadsWhatTheOtherBusWrote) {
    Bridged b;
    VirtualIoc& v = *b.v;
    v.cycles(200); // both sides in OP
    EXPECT_EQ(b.entry("ec0.s1.externalDeviceNotConnected01"), 0);
    EXPECT_EQ(b.entry("ec1.s1.externalDeviceNotConnected01"), 0);
    std::set<double> lag_there, lag_back;
    double toggles = 0, last_toggle = b.entry("ec1.s1.txPdoToggle01");
    for (int k = 0; k < 500; ++k) {
        v.cycles(1);
        const double n = v.stat(0, "n"), got = v.stat(1, "got"), back = v.stat(0, "back");
        lag_there.insert(n - got / 0.25);
        lag_back.insert(n - (back - 1000));
        const double t = b.entry("ec1.s1.txPdoToggle01");
        toggles += t != last_toggle;
        last_toggle = t;
    }
    // every cycle's value arrives, each after the same number of cycles
    ASSERT_EQ(lag_there.size(), 1u);
    ASSERT_EQ(lag_back.size(), 1u);
    // ec0 -> ec1: written in cycle c, sent with ec0's frame, taken by the secondary after ec1's
    // frame of the same cycle, read with ec1's next frame: the PLC sees it in c + 2, as through a
    // cable on one bus. ec1 -> ec0: ec0's frame of a cycle passes before ec1's, so the answer
    // waits one cycle more there: 3, and 5 for the round trip.
    EXPECT_EQ(*lag_there.begin(), 2);
    EXPECT_EQ(*lag_back.begin(), 5);
    EXPECT_EQ(toggles, 500); // new data every cycle
    // the entries' PVs read the REAL64 values as numbers (IEEE, not integers)
    v.ioc->publish();
    EXPECT_EQ(v.get("BR:m1s001-inLreal01"), v.stat(1, "got"));
    EXPECT_EQ(std::fmod(v.get("BR:m1s001-inLreal01"), 1.0) != 0 || std::fmod(v.get("BR:m0s001-outLreal01"), 1.0) != 0, true);
}

// The primary side loses power: the secondary says so (0x10F4:10, TxPDO state) and holds its
// inputs (the master bringing a powered-up slave back to OP: tests/unit/ethercat/test_self_healing.cpp).
TEST(IocBridge, TheOtherSideGoneIsReportedAndTheInputsHold) {
    Bridged b;
    VirtualIoc& v = *b.v;
    v.cycles(200);
    ethercat::sim::Segment& seg = *v.ioc->segment(0);
    ASSERT_TRUE(seg.post(ethercat::sim::parse_fault("power 1 off", ethercat::Catalog::builtin(), seg.size())));
    v.cycles(20);
    EXPECT_EQ(b.entry("ec1.s1.externalDeviceNotConnected01"), 1);
    EXPECT_EQ(b.entry("ec1.s1.txPdoState01"), 1);
    const double held = v.stat(1, "got");
    EXPECT_GT(held, 0);
    v.cycles(100);
    EXPECT_EQ(v.stat(1, "got"), held);
}

// An EL6692 side whose plant names no pair has no other side: not connected, from the start.
TEST(IocBridge, ASideWithoutAPairIsNotConnected) {
    Bridged b("{}\n");
    b.v->cycles(200);
    EXPECT_EQ(b.entry("ec1.s1.externalDeviceNotConnected01"), 1);
    EXPECT_EQ(b.entry("ec0.s1.externalDeviceNotConnected01"), 1);
    EXPECT_EQ(b.v->stat(1, "got"), 0);
}

TEST(IocBridge, BadBridgesNameWhatAndWhere) {
    TempDir dir;
    const auto& cat = ethercat::Catalog::builtin();
    auto error = [&](const std::string& text) -> std::string {
        try {
            ethercat::sim::SimConfig c = ethercat::sim::SimConfig::parse(text, "plant.yaml", cat);
            ethercat::sim::Segment seg;
            seg.add_configured({{0, "EK1100"}, {1, "EL6692"}, {2, "EL6692"}}, cat);
            c.build(seg, cat);
        } catch (const Error& e) {
            return e.what();
        }
        return "no error";
    };
    EXPECT_NE(error("bridges:\n  - {slave: 0, pair: x}\n").find("plant.yaml:2:5: slave 0 is a EK1100, not an EL6692 side"), std::string::npos)
        << error("bridges:\n  - {slave: 0, pair: x}\n");
    EXPECT_NE(error("bridges:\n  - {slave: 1, pair: x}\n  - {slave: 2, pair: x}\n").find("its primary side is already on another segment"),
              std::string::npos);
    EXPECT_NE(error("bridges:\n  - {slave: 1}\n").find("plant.yaml:2:5"), std::string::npos) << error("bridges:\n  - {slave: 1}\n");
}

} // namespace
