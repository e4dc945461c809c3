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

// kIoc with bus 1 on its own cycle at `rate_hz`, PLC 1 in it.
std::string own_cycle(const std::string& rate_hz, const std::string& plc1 = "{id: 1, file: b.plc, bus: 1}") {
    std::string y = kIoc;
    y.replace(y.find("  - id: 1\n"), 10, "  - id: 1\n    rate_hz: " + rate_hz + "\n");
    y.replace(y.find("{id: 1, file: b.plc}"), 20, plc1);
    return y;
}

// Both EL6692 sides of `y` with 0x1A02 (the DC time stamps) assigned, as ecmccfg writes it.
std::string with_time_stamps(std::string y) {
    const std::string ts = "sdo: [{index: 0x1C13, sub: 0, value: 0, size: 1}, {index: 0x1C13, sub: 1, value: 0x1A00, size: 2}, "
                           "{index: 0x1C13, sub: 2, value: 0x1A02, size: 2}, {index: 0x1C13, sub: 0, value: 2, size: 1}]";
    y.replace(y.find("{position: 1, type: EL6692}"), 27, "{position: 1, type: EL6692, " + ts + "}");
    y.replace(y.find("{position: 1, type: EL6692-0002}"), 32, "{position: 1, type: EL6692-0002, " + ts + "}");
    return y;
}

struct Bridged {
    TempDir dir;
    std::unique_ptr<VirtualIoc> v;
    explicit Bridged(const std::string& plant_b = "bridges:\n  - {slave: 1, pair: gap_mono}\n", const std::string& ioc = kIoc) {
        dir.write("a.yaml", "bridges:\n  - {slave: 1, pair: gap_mono}\n");
        dir.write("b.yaml", plant_b);
        // bus 0 counts and sends; bus 1 reads it and answers with the count + 1000
        dir.write("a.plc", "static.n += 1;\nec0.s1.outInt01 := static.n;\nec0.s1.outLreal01 := static.n * 0.25;\n"
                           "static.back := ec0.s1.inInt02;\n");
        dir.write("b.plc", "static.got := ec1.s1.inLreal01;\nec1.s1.outInt02 := ec1.s1.inInt01 + 1000;\n");
        v = std::make_unique<VirtualIoc>(dir.write("ioc.yaml", ioc));
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

// Bus 1 on its own cycle (its own engine, here at 400 Hz against the IOC's 1 kHz), its PLC with
// it: the two cycles are not in step, the bridge still carries every value the slower side can
// take, and each PLC scans at its own cycle's rate.
TEST(IocBridge, EachBusRunsItsOwnCycle) {
    Bridged b("bridges:\n  - {slave: 1, pair: gap_mono}\n", own_cycle("400"));
    VirtualIoc& v = *b.v;
    ASSERT_EQ(v.ioc->cycle_count(), 2u);
    EXPECT_EQ(v.ioc->cycle_of_bus(0), 0u);
    EXPECT_EQ(v.ioc->cycle_of_bus(1), 1u);
    EXPECT_EQ(v.ioc->cycle(1).period_ns(), 2'500'000u);
    v.cycles(500);
    const uint64_t c0 = v.ioc->cycle(0).stats().cycles, c1 = v.ioc->cycle(1).stats().cycles;
    EXPECT_EQ(c0, 500u);
    EXPECT_NEAR(double(c1), 200.0, 1.0); // 400 Hz over the same 0.5 s
    // each bus's thread PVs show its own cycle's statistics
    v.ioc->publish();
    EXPECT_EQ(v.get("BR:m0-ThdCycles"), double(v.ioc->cycle(0).stats().latency_samples));
    EXPECT_EQ(v.get("BR:m1-ThdCycles"), double(v.ioc->cycle(1).stats().latency_samples));
    EXPECT_NEAR(v.get("BR:m1-ThdCycles") / v.get("BR:m0-ThdCycles"), 0.4, 0.01);
    auto [rt1, k1] = v.ioc->plcs().at(1);
    ASSERT_NE(rt1, nullptr);
    EXPECT_NE(rt1, v.ioc->plcs().runtime()); // PLC 1 runs in bus 1's cycle, PLC 0 in the IOC's
    EXPECT_DOUBLE_EQ(rt1->status(k1).scantime_s, 0.0025);
    const uint64_t scans0 = v.ioc->plcs().at(0).first->status(0).scans, scans1 = rt1->status(k1).scans;
    EXPECT_NEAR(double(scans0) / double(scans1), 2.5, 0.1);
    // bus 1 takes the newest count each of its cycles: a few IOC cycles old, never older than
    // one bus-1 cycle plus the bridge's frames; it only goes up
    double last_got = 0;
    std::set<double> lags;
    for (int k = 0; k < 400; ++k) {
        v.cycles(1);
        const double n = v.stat(0, "n"), got = v.stat(1, "got") / 0.25;
        EXPECT_GE(got, last_got);
        last_got = got;
        lags.insert(n - got);
    }
    EXPECT_GE(*lags.begin(), 1);
    EXPECT_LE(*lags.rbegin(), 2 + 2 * 3); // the bridge's two frames, in the slower cycle's steps
    EXPECT_GT(lags.size(), 1u); // not in step: the lag moves
    // the answer comes back through the same bridge
    EXPECT_GT(v.stat(0, "back"), 1000);
}

// A PLC of the IOC's cycle cannot touch a bus of another cycle (two threads on one process
// image): refused at bring-up, naming the entry and what to do.
TEST(IocBridge, APlcNamingABusOfAnotherCycleIsRefused) {
    std::string what = "no error";
    try {
        Bridged b("bridges:\n  - {slave: 1, pair: gap_mono}\n", own_cycle("500", "{id: 1, file: b.plc}"));
    } catch (const std::exception& e) {
        what = e.what();
    }
    EXPECT_NE(what.find("b.plc:1:"), std::string::npos) << what;
    EXPECT_NE(what.find("'ec1.s1.inLreal01' is on ec1, which runs in another cycle than this PLC's"), std::string::npos) << what;
    EXPECT_NE(what.find("plcs[].bus: N"), std::string::npos) << what;
}

TEST(IocBridge, OwnCycleKeysAreChecked) {
    TempDir dir;
    auto error = [&](const std::string& y) -> std::string {
        try {
            config::IocConfig::load(dir.write("ioc.yaml", y));
        } catch (const Error& e) {
            return e.what();
        }
        return "no error";
    };
    EXPECT_NE(error(own_cycle("0")).find("ioc.yaml:10:14: buses[1].rate_hz should be from 1 to 20000, got 0"), std::string::npos) << error(own_cycle("0"));
    std::string bad_bus = own_cycle("500", "{id: 1, file: b.plc, bus: 7}");
    EXPECT_NE(error(bad_bus).find("no bus 7 in buses:"), std::string::npos) << error(bad_bus);
}

// Axes run in the IOC's cycle: a drive on a bus of its own cycle is refused, naming the entry.
TEST(IocBridge, AnAxisOnABusOfAnotherCycleIsRefused) {
    TempDir dir;
    std::string y = R"(ioc: {name: BR}
buses:
  - id: 0
    rate_hz: 500
    link: {type: sim}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL7041}
axes:
  - {file: )" + std::string(BEAMCTL_SOURCE_DIR) + R"(/examples/demo/axes/jack.yaml, macros: {AX_ID: 1, AX_NAME: Gap, DRV_SLAVE: 1}}
)";
    std::string what = "no error";
    try {
        VirtualIoc v(dir.write("ioc.yaml", y));
    } catch (const std::exception& e) {
        what = e.what();
    }
    EXPECT_NE(what.find("jack.yaml:"), std::string::npos) << what;
    EXPECT_NE(what.find("is on bus 0, which runs its own cycle (buses[].rate_hz)"), std::string::npos) << what;
}

// Distributed clocks across the bridge: both sides assign 0x1A02 (startup SDOs, as ecmccfg writes
// them), the monochromator's segment runs its own clock 40 ppm fast; each side latches both
// segments' DC times together, and the IOC serves their difference and its rate.
TEST(IocBridge, TheSkewBetweenTheTwoTimeBasesIsMeasuredAndServed) {
    std::string y = with_time_stamps(own_cycle("500"));
    Bridged b("bridges:\n  - {slave: 1, pair: gap_mono}\nclock: {offset_us: 250, drift_ppm: 40}\n", y);
    VirtualIoc& v = *b.v;
    v.run(200);
    EXPECT_EQ(b.entry("ec1.s1.externalDeviceNotConnected01"), 0);
    const double t0 = b.entry("ec0.s1.internalTimestamp01"); // bus 0's DC time
    const double skew0 = b.entry("ec0.s1.externalTimestamp01") - t0;
    // bus 1's time base is bus 1's: ~250 us ahead from the start (the masters configured their
    // offsets from the same host clock), its own view the other way round
    EXPECT_NEAR(b.entry("ec1.s1.externalTimestamp01") - b.entry("ec1.s1.internalTimestamp01"), -skew0, 1e3);
    double toggles = 0, last = b.entry("ec0.s1.timestampToggle01");
    for (int k = 0; k < 100; ++k) {
        v.cycles(1);
        toggles += b.entry("ec0.s1.timestampToggle01") != last;
        last = b.entry("ec0.s1.timestampToggle01");
    }
    EXPECT_EQ(toggles, 100); // a new pair of time stamps every frame
    v.run(2000); // 2 s more
    const double t1 = b.entry("ec0.s1.internalTimestamp01");
    const double skew1 = b.entry("ec0.s1.externalTimestamp01") - t1;
    EXPECT_NEAR((skew1 - skew0) / (t1 - t0) * 1e6, 40.0, 0.5); // 40 ppm: 80 us over 2 s
    // served: the skew [ns] and its rate [ppm] on both sides
    v.ioc->publish();
    EXPECT_NEAR(v.get("BR:m0s001-DcSkew"), skew1, 50e3); // within the 10 ms between looks at 40 ppm
    EXPECT_NEAR(v.get("BR:m0s001-DcDrift"), 40.0, 0.5);
    EXPECT_NEAR(v.get("BR:m1s001-DcDrift"), -40.0, 0.5);
    EXPECT_NEAR(v.get("BR:m1s001-DcSkew"), -v.get("BR:m0s001-DcSkew"), 2e3);
}

// The mono bus's distributed clock follows the undulator's (dc_follow: its EL6692 side): its
// master writes each cycle into its reference clock the time it will have plus an eighth of the
// measured skew, the reference's drift control pulls its clock along, and the two time bases come
// together, the 40 ppm drift taken out.
TEST(IocBridge, ADcFollowingBusAlignsItsClockToTheOther) {
    std::string y = with_time_stamps(own_cycle("500"));
    y.replace(y.find("    rate_hz: 500\n"), 17, "    rate_hz: 500\n    dc_follow: 1\n");
    Bridged b("bridges:\n  - {slave: 1, pair: gap_mono}\nclock: {offset_us: 250, drift_ppm: 40}\n", y);
    VirtualIoc& v = *b.v;
    auto skew = [&] { return b.entry("ec0.s1.externalTimestamp01") - b.entry("ec0.s1.internalTimestamp01"); };
    for (int k = 0; k < 1000 && b.entry("ec0.s1.internalTimestamp01") == 0; ++k) v.cycles(1); // both sides in OP
    const double first = skew(), t_first = b.entry("ec0.s1.internalTimestamp01");
    const double pulled_first = double(v.ioc->segment(1)->steered_ns());
    // the two masters set their clocks from the host's clock at bring-up, a wall-clock moment
    // apart (more under a sanitizer): 1 us per write at most, 500 writes a second, then 2 s more
    v.run(int(std::fabs(first) / 1000.0 * 2 * 1.2) + 2000);
    double worst = 0;
    for (int k = 0; k < 1000; ++k) {
        v.cycles(1);
        worst = std::max(worst, std::fabs(skew()));
    }
    EXPECT_LT(worst, 1000) << "from " << first; // within 1 us for the last second, drift and all
    EXPECT_GT(std::fabs(first), 5 * worst);     // and it was not so from the start
    v.ioc->publish();
    EXPECT_NEAR(v.get("BR:m0s001-DcDrift"), 0.0, 0.5);
    EXPECT_LT(std::fabs(v.get("BR:m1s001-DcSkew")), 1000);
    // what the mono segment's clock was pulled by since: the skew there was, and 40 ppm of the time
    const double t_end = b.entry("ec0.s1.internalTimestamp01");
    const double pulled = double(v.ioc->segment(1)->steered_ns()) - pulled_first;
    EXPECT_NEAR(pulled, -(first - skew()) - 40e-6 * (t_end - t_first), 2000) << pulled;
}

TEST(IocBridge, DcFollowNamesAnEl6692SideWithTimeStamps) {
    std::string what = "no error";
    std::string y = own_cycle("500");
    y.replace(y.find("    rate_hz: 500\n"), 17, "    rate_hz: 500\n    dc_follow: 0\n");
    try {
        Bridged b("{}\n", y);
    } catch (const std::exception& e) {
        what = e.what();
    }
    EXPECT_NE(what.find("ioc.yaml:11:16: dc_follow: 0 should be the position of an EL6692 side on bus 1 (it is a EK1100)"), std::string::npos)
        << what;
    y = own_cycle("500");
    y.replace(y.find("    rate_hz: 500\n"), 17, "    rate_hz: 500\n    dc_follow: 1\n");
    try {
        Bridged b("{}\n", y);
    } catch (const std::exception& e) {
        what = e.what();
    }
    EXPECT_NE(what.find("ec1.s1: dc_follow needs the EL6692's time stamps: assign 0x1A02"), std::string::npos) << what;
}

// Without 0x1A02 the sides latch no time stamps; the skew PVs stay undefined (INVALID).
TEST(IocBridge, WithoutTheTimeStampPdoThereIsNoSkew) {
    Bridged b;
    b.v->run(300);
    pv::Record* r = b.v->ioc->database().find("BR:m0s001-DcSkew");
    ASSERT_NE(r, nullptr);
    EXPECT_EQ(r->sevr, pv::kInvalid);
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
