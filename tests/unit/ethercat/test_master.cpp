// The master against the simulator over the in-process link: bring-up to OP, identity and count
// errors, signals with ecmccfg names, a DO->DI wiring loop, frame loss, an unplugged slave, and
// a cyclic path that allocates nothing.
#include "../alloc_counter.hpp"
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/inprocess_link.hpp"
#include "ethercat/sim/segment.hpp"

#include "sim_bus.hpp"

#include <gtest/gtest.h>

using namespace beamctl;
using namespace beamctl::ethercat;
using beamctl::ethercat::simbus::Bus;
using beamctl::ethercat::simbus::demo;
using beamctl::ethercat::simbus::kDemo;

TEST(Master, BringsFourteenTerminalsToOp) {
    Bus b(demo());
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    for (std::size_t i = 0; i < b.seg.size(); ++i) EXPECT_EQ(b.seg.slave(i).al_state(), 8) << kDemo[i];
    EXPECT_EQ(m.send_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.wkc(), m.expected_wkc());
    EXPECT_GT(m.expected_wkc(), 10);
    EXPECT_NE(m.find_signal("ec0.s1.binaryInput01"), nullptr);
    EXPECT_NE(m.find_signal("ec0.s3.binaryOutput08"), nullptr);
    EXPECT_EQ(m.find_signal("ec0.s0.binaryInput01"), nullptr); // EK1100 has no process data
}

TEST(Master, DigitalOutputWiredToInputIsSeenNextCycle) {
    Bus b({"EK1100", "EL2008", "EL1008"});
    // Wiring: EL2008 output n drives EL1008 input n (copied after every frame, like a cable).
    b.seg.on_frame = [](sim::Segment& s) {
        uint8_t out = s.slave(1).outputs_valid() ? *s.slave(1).sm_buffer(0) : 0;
        *s.slave(2).sm_buffer(0) = out;
    };
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    const SignalInfo* o3 = m.find_signal("ec0.s1.binaryOutput03");
    const SignalInfo* i3 = m.find_signal("ec0.s2.binaryInput03");
    const SignalInfo* i4 = m.find_signal("ec0.s2.binaryInput04");
    ASSERT_TRUE(o3 && i3 && i4);
    m.set(*o3, 1);
    m.send_process_data();
    m.receive_process_data();
    // Same frame: the output reached the slave, the input was read before the wire copied it.
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.get(*i3), 1u);
    EXPECT_EQ(m.get(*i4), 0u);
    m.set(*o3, 0);
    for (int i = 0; i < 2; ++i) {
        m.send_process_data();
        m.receive_process_data();
    }
    EXPECT_EQ(m.get(*i3), 0u);
}

TEST(Master, StrictIdentityMismatchNamesPositionExpectedAndFound) {
    Bus b({"EK1100", "EL1008", "EL2008"});
    b.cfg[2].type = "EL2808";
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.set_strict(true);
    try {
        m.bring_up();
        FAIL() << "bring-up should fail";
    } catch (const Error& e) {
        std::string w = e.what();
        EXPECT_NE(w.find("ec0 position 2"), std::string::npos) << w;
        EXPECT_NE(w.find("expected EL2808"), std::string::npos) << w;
        EXPECT_NE(w.find("found EL2008"), std::string::npos) << w;
    }
}

TEST(Master, StrictMissingSlavesAreAClearError) {
    Bus b({"EK1100", "EL1008"});
    b.cfg.push_back({5, "EL2008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.set_strict(true);
    try {
        m.bring_up();
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("2 slave(s) on the bus"), std::string::npos) << e.what();
    }
}

TEST(Master, UnknownTypeIsRejectedAtConfiguration) {
    sim::Segment seg;
    sim::InProcessLink link(seg);
    EXPECT_THROW(Master(link, 0, {{0, "EL9999"}}, Catalog::builtin()), Error);
}

TEST(Master, LostFramesAreCountedAndInputsKeepTheirLastValue) {
    Bus b({"EK1100", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    *b.seg.slave(1).sm_buffer(0) = 0x81;
    m.send_process_data();
    m.receive_process_data();
    const SignalInfo* i1 = m.find_signal("ec0.s1.binaryInput01");
    EXPECT_EQ(m.get(*i1), 1u);
    b.seg.set_frame_loss(0.5, 42);
    int lost = 0;
    for (int i = 0; i < 200; ++i) {
        *b.seg.slave(1).sm_buffer(0) = 0x00;
        m.send_process_data();
        if (m.receive_process_data(0) == CycleStatus::FrameLost) {
            ++lost;
            EXPECT_EQ(m.get(*i1), i == 0 ? 1u : m.get(*i1));
        }
    }
    EXPECT_GT(lost, 60);
    EXPECT_LT(lost, 140);
    EXPECT_EQ(m.frames_lost(), uint64_t(lost));
    EXPECT_EQ(b.seg.frames_lost, uint64_t(lost));
}

TEST(Master, UnpluggedSlaveDropsTheWorkingCounterOthersKeepCycling) {
    Bus b({"EK1100", "EL2008", "EL1008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    b.seg.unplug(2);
    *b.seg.slave(3).sm_buffer(0) = 0x02;
    m.send_process_data();
    // Its status byte did not come back: the cycle is consistent without it, its data invalid in
    // this very cycle, the others' valid.
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.wkc(), m.expected_wkc() - 1);
    EXPECT_EQ(m.get(*m.find_signal("ec0.s3.binaryInput02")), 1u); // the others still exchange data
    EXPECT_FALSE(m.slave_valid(2));
    EXPECT_FALSE(m.slave_online(2));
    EXPECT_TRUE(m.slave_valid(1));
    EXPECT_TRUE(m.slave_valid(3));
    EXPECT_EQ(m.get(*m.find_signal("ec0.s2.valid")), 0u);
    EXPECT_EQ(m.get(*m.find_signal("ec0.s3.valid")), 1u);
    EXPECT_EQ(m.wkc_errors(), 0u);
}

TEST(Master, CyclicExchangeAllocatesNothing) {
    Bus b(demo());
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    test::count_allocations(true);
    for (int i = 0; i < 10000; ++i) {
        m.send_process_data();
        m.receive_process_data();
    }
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_EQ(m.wkc(), m.expected_wkc());
}

#include "ethercat/sim/sim_config.hpp"

#include <thread>

TEST(Master, OverUdpToASimulatorWithWiring) {
    const Catalog& cat = Catalog::builtin();
    sim::SimConfig cfg = sim::SimConfig::parse(R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL2008}
  - {position: 2, type: EL1008}
wiring:
  - {from: s1.binaryOutput02, to: s2.binaryInput05}
)", "dio.yaml", cat);
    sim::Segment seg;
    cfg.build(seg, cat);
    sim::UdpServer server(seg, "127.0.0.1", 0);
    volatile bool stop = false;
    std::thread t([&] { server.run(stop, 20); });
    {
        UdpLink link("127.0.0.1", server.port());
        Master m(link, 0, {{0, "EK1100"}, {1, "EL2008"}, {2, "EL1008"}}, cat);
        m.bring_up();
        m.set(*m.find_signal("ec0.s1.binaryOutput02"), 1);
        for (int i = 0; i < 3; ++i) {
            m.send_process_data();
            m.receive_process_data(200000);
        }
        EXPECT_EQ(m.wkc(), m.expected_wkc());
        EXPECT_EQ(m.get(*m.find_signal("ec0.s2.binaryInput05")), 1u);
        EXPECT_EQ(m.get(*m.find_signal("ec0.s2.binaryInput02")), 0u);
    }
    stop = true;
    t.join();
    EXPECT_GT(server.frames, 10u);
}

TEST(SimConfig, ErrorsNameFileLineAndColumn) {
    const Catalog& cat = Catalog::builtin();
    try {
        sim::SimConfig::parse("slaves:\n  - {position: 0, type: EL9999}\n", "bad.yaml", cat);
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("bad.yaml:2:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("EL9999"), std::string::npos);
    }
    try {
        sim::SimConfig::parse("slaves:\n  - {position: 0, type: EL1008}\nwiring:\n  - {from: s0.binaryInput01, to: s0.binaryOutput01}\n",
                              "bad.yaml", cat);
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("bad.yaml:4:"), std::string::npos) << e.what();
    }
    EXPECT_THROW(sim::SimConfig::parse("slave: []\n", "typo.yaml", cat), Error);
}

TEST(Master, RotatingStatusPollSeesEverySlaveAndALostOne) {
    Bus b({"EK1100", "EL2008", "EL1008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    for (int i = 0; i < 8; ++i) {
        m.send_process_data();
        EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok); // the poll does not count in the WKC
    }
    for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_TRUE(m.slave_online(i));
        EXPECT_EQ(m.slave_al_status(i), 8);
    }
    b.seg.unplug(2);
    for (int i = 0; i < 4; ++i) { // one full round of the poll
        m.send_process_data();
        m.receive_process_data();
    }
    EXPECT_FALSE(m.slave_online(2));
    EXPECT_TRUE(m.slave_online(1));
    EXPECT_TRUE(m.slave_online(3));
    // A slave that drops to SAFEOP with an error shows it in its status byte.
    b.seg.slave(3).memory()[0x0130] = 0x14;
    for (int i = 0; i < 4; ++i) {
        m.send_process_data();
        m.receive_process_data();
    }
    EXPECT_EQ(m.slave_al_status(3), 0x14);
}

TEST(Master, DistributedClocksDelaysOffsetsSync0AndReferenceTime) {
    Bus b({"EK1100", "EL1008", "EL7211", "EL2008", "EL5042"});
    b.seg.set_time(5'000'000'000ull);
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.set_cycle_time_ns(500'000);
    m.bring_up();
    ASSERT_EQ(m.dc_reference(), 2); // the first slave with DC: EL7211
    auto reg32 = [&](int pos, uint16_t a) { return le32(b.seg.slave(pos).memory() + a); };
    // Delays from the reference: 2 hops further for EL5042 (positions 2 -> 4).
    EXPECT_EQ(reg32(2, 0x0928), 0u);
    EXPECT_EQ(reg32(4, 0x0928), 2 * sim::Segment::kHopDelayNs);
    // SYNC0 configured: cycle time and AssignActivate (EL7211 0x0700, EL5042 0x0300).
    EXPECT_EQ(reg32(2, 0x09A0), 500'000u);
    EXPECT_EQ(b.seg.slave(2).memory()[0x0981], 0x07);
    EXPECT_EQ(b.seg.slave(4).memory()[0x0981], 0x03);
    EXPECT_EQ(b.seg.slave(1).memory()[0x0981], 0x00); // EL1008 has no DC
    // All DC slaves share one system time; every cycle the reference time travels to the others.
    EXPECT_EQ(b.seg.slave(2).system_time(), b.seg.slave(4).system_time());
    b.seg.set_time(5'000'500'000ull);
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    // The reference's time as the frame passed it (2 hops from the master).
    EXPECT_EQ(m.dc_reference_time(), b.seg.slave(2).system_time() + 2 * sim::Segment::kHopDelayNs);
    // EL5042 compares it, plus its delay, with its own time as the frame passes: no difference.
    EXPECT_EQ(reg32(4, 0x092C), 0u);
}

namespace {
// Holds back one returning frame (it "arrives" after the cycle's time-out) and delivers it
// first in the next cycle, as a slow wire would.
struct LateLink : Link {
    Link& inner;
    bool hold_next = false;
    std::vector<uint8_t> held;
    explicit LateLink(Link& l) : inner(l) {}
    bool send(const uint8_t* f, std::size_t n) noexcept override { return inner.send(f, n); }
    std::size_t receive(uint8_t* buf, std::size_t cap, int t) noexcept override {
        if (!held.empty() && !hold_next) {
            std::size_t n = held.size();
            std::memcpy(buf, held.data(), n);
            held.clear();
            return n;
        }
        std::size_t n = inner.receive(buf, cap, t);
        if (n && hold_next) {
            held.assign(buf, buf + n);
            hold_next = false;
            return 0;
        }
        return n;
    }
    const char* kind() const noexcept override { return "late"; }
};
} // namespace

TEST(Master, AFrameThatComesBackLateIsDroppedNotUsedByTheNextCycle) {
    Bus b({"EK1100", "EL1008"});
    LateLink late(b.link);
    Master m(late, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    const SignalInfo* i1 = m.find_signal("ec0.s1.binaryInput01");
    *b.seg.slave(1).sm_buffer(0) = 0x01; // this value travels in the late frame
    late.hold_next = true;
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::FrameLost);
    EXPECT_EQ(m.get(*i1), 0u);
    *b.seg.slave(1).sm_buffer(0) = 0x00; // the next cycle reads the new value
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.get(*i1), 0u);
    EXPECT_EQ(m.frames_late(), 1u);
    EXPECT_EQ(m.frames_lost(), 1u);
}

TEST(Master, SmWatchdogTakesASlaveWithoutOutputDataToSafeop) {
    Bus b({"EK1100", "EL2008", "EL1008"});
    b.seg.set_time(1'000'000'000ull);
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    // Cycling every 1 ms for 300 ms keeps the outputs alive.
    for (int i = 1; i <= 300; ++i) {
        b.seg.set_time(1'000'000'000ull + i * 1'000'000ull);
        m.send_process_data();
        m.receive_process_data();
    }
    EXPECT_EQ(b.seg.slave(1).al_state(), 8);
    // 150 ms without process data (default watchdog 100 ms), then any frame passes.
    b.seg.set_time(1'450'000'000ull);
    uint16_t v = 0;
    m.transact(kBrd, 0, 0x0130, &v, 2);
    EXPECT_EQ(b.seg.slave(1).al_state(), 4);                 // EL2008 has a watched output SM
    EXPECT_EQ(b.seg.slave(1).al_status_code(), 0x001B);
    EXPECT_TRUE(b.seg.slave(1).al_error());
    EXPECT_EQ(b.seg.slave(2).al_state(), 8);                 // EL1008 has no outputs
}

TEST(Master, MasterStatusAndConstantEntriesAreSignals) {
    Bus b({"EK1100", "EL2008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    const SignalInfo* ms = m.find_signal("ec0.masterstatus");
    const SignalInfo* one = m.find_signal("ec0.s2.ONE");
    const SignalInfo* zero = m.find_signal("ec0.s1.ZERO");
    ASSERT_TRUE(ms && one && zero);
    EXPECT_GE(ms->bit_offset, m.bus_bytes() * 8); // the master's memory, not on the bus
    EXPECT_EQ(m.get(*one), 0xFFFFFFFFu);
    EXPECT_EQ(m.get(*zero), 0u);
    m.send_process_data();
    ASSERT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.get(*ms), 1u);
    b.seg.unplug(2); // WKC drops with its status byte: consistent, that slave's data invalid
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.get(*ms), 1u);
    EXPECT_EQ(m.get(*m.find_signal("ec0.s2.valid")), 0u);
    // A working counter the slaves taking part do not explain (an FMMU lost): not OK.
    b.seg.slave(1).memory()[0x0600 + 12] = 0; // EL2008's output FMMU off
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::WkcMismatch);
    EXPECT_EQ(m.get(*ms), 0u);
    EXPECT_EQ(m.get(*m.find_signal("ec0.s1.valid")), 0u);
    EXPECT_EQ(m.wkc_errors(), 1u);
    EXPECT_EQ(m.get(*one), 0xFFFFFFFFu); // never touched by the bus
}
