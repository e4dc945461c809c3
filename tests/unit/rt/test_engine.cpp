// The RT engine in virtual time: stage order, cycle timing statistics, missed cycles, and a full
// cycle (bus receive, send, publish over a simulated 14-terminal segment) that allocates nothing.
#include "../alloc_counter.hpp"
#include "ethercat/bus.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/segment.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

using namespace beamctl;

namespace {

struct Recorder : rt::Stage {
    const char* n;
    std::vector<std::string>* log;
    rt::VirtualClock* clock;
    uint64_t work_ns;
    Recorder(const char* name, std::vector<std::string>* l, rt::VirtualClock* c, uint64_t w)
        : n(name), log(l), clock(c), work_ns(w) {}
    const char* name() const noexcept override { return n; }
    void run(const rt::CycleInfo&) noexcept override {
        if (log) log->push_back(n);
        clock->advance(work_ns);
    }
};

} // namespace

TEST(Engine, StagesRunInArchitectureOrder) {
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    std::vector<std::string> log;
    Recorder send("send", &log, &clock, 0), recv("recv", &log, &clock, 0), plc("plc", &log, &clock, 0),
        axes("axes", &log, &clock, 0), pub("publish", &log, &clock, 0);
    e.add_stage(rt::StageOrder::Publish, pub);
    e.add_stage(rt::StageOrder::BusSend, send);
    e.add_stage(rt::StageOrder::GeneralPlcs, plc);
    e.add_stage(rt::StageOrder::BusReceive, recv);
    e.add_stage(rt::StageOrder::Axes, axes);
    e.run_cycles(1);
    EXPECT_EQ(log, (std::vector<std::string>{"recv", "axes", "plc", "send", "publish"}));
}

TEST(Engine, TimingStatisticsInVirtualTime) {
    rt::VirtualClock clock;
    rt::Engine e({2000}, clock); // 500 us period
    Recorder a("a", nullptr, &clock, 30'000), b("b", nullptr, &clock, 70'000);
    e.add_stage(rt::StageOrder::Axes, a);
    e.add_stage(rt::StageOrder::GeneralPlcs, b);
    uint64_t t0 = clock.now_ns();
    e.run_cycles(100);
    auto s = e.stats();
    EXPECT_EQ(s.cycles, 100u);
    EXPECT_EQ(s.missed, 0u);
    EXPECT_EQ(s.exec_max_ns, 100'000u);
    EXPECT_EQ(s.latency_max_ns, 0u); // virtual time wakes exactly on schedule
    ASSERT_EQ(s.stages.size(), 2u);
    EXPECT_EQ(s.stages[0].max_ns, 30'000u);
    EXPECT_EQ(s.stages[1].total_ns, 100 * 70'000u);
    // 100 cycles of 500 us: the last one started at t0 + 99 periods and took 100 us.
    EXPECT_EQ(clock.now_ns(), t0 + 99 * 500'000u + 100'000u);
}

TEST(Engine, OverrunsCountAsMissedCyclesWithoutBursts) {
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    Recorder slow("slow", nullptr, &clock, 2'500'000); // 2.5 ms of work in a 1 ms cycle
    e.add_stage(rt::StageOrder::Axes, slow);
    uint64_t t0 = clock.now_ns();
    e.run_cycles(10);
    auto s = e.stats();
    EXPECT_EQ(s.cycles, 10u);
    // 10 cycles of 2.5 ms take 25 ms = 25 slots of 1 ms: 10 run, 15 are missed (skipped, no
    // catch-up burst); cycles start on the next slot boundary or 0.5 ms after it.
    EXPECT_EQ(clock.now_ns() - t0, 25'000'000u);
    EXPECT_EQ(s.missed, 15u);
    EXPECT_EQ(s.latency_max_ns, 500'000u);
}

TEST(Engine, RejectsRatesOutsideOneToTwentyKilohertz) {
    rt::VirtualClock clock;
    EXPECT_THROW(rt::Engine({0.5}, clock), Error);
    EXPECT_THROW(rt::Engine({25000}, clock), Error);
}

TEST(Engine, FullBusCycleAllocatesNothing) {
    const auto& cat = ethercat::Catalog::builtin();
    const char* types[] = {"EK1100", "EL1008", "EL1008", "EL2008", "EL2808", "EL3104", "EL4134",
                           "EL5101", "EL7041", "EL7211", "EL5042", "EL3102", "EL4102", "EL1252"};
    ethercat::sim::Segment seg;
    std::vector<ethercat::SlaveConfig> cfg;
    for (int i = 0; i < 14; ++i) {
        seg.add(*cat.find(types[i]));
        cfg.push_back({i, types[i]});
    }
    ethercat::Bus bus(0, std::make_unique<ethercat::InProcessLink>(seg), cfg, cat);
    bus.bring_up();
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    bus.add_stages(e);
    const ethercat::SignalInfo* bo = bus.master().find_signal("ec0.s3.binaryOutput02");
    ASSERT_NE(bo, nullptr);
    e.run_cycles(10); // warm up
    test::count_allocations(true);
    for (int i = 0; i < 10000; ++i) {
        if (i % 100 == 0) bus.write(*bo, uint64_t(i / 100 % 2)); // the non-RT side queues writes
        e.run_cycles(1);
    }
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    const auto& snap = bus.snapshot();
    EXPECT_EQ(snap.wkc, snap.expected_wkc);
    EXPECT_TRUE(snap.wkc_ok);
    EXPECT_EQ(snap.cycle, 10009u);
    EXPECT_EQ(e.stats().cycles, 10010u);
}

TEST(Engine, QueuedOutputWriteReachesTheSlaveInTheNextCycle) {
    const auto& cat = ethercat::Catalog::builtin();
    ethercat::sim::Segment seg;
    seg.add(*cat.find("EK1100"));
    seg.add(*cat.find("EL2008"));
    ethercat::Bus bus(0, std::make_unique<ethercat::InProcessLink>(seg), {{0, "EK1100"}, {1, "EL2008"}}, cat);
    bus.bring_up();
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    bus.add_stages(e);
    e.run_cycles(2);
    ASSERT_TRUE(bus.write(*bus.master().find_signal("ec0.s1.binaryOutput05"), 1));
    e.run_cycles(1); // applied at the end of this cycle (publish stage)
    EXPECT_EQ(*seg.slave(1).sm_buffer(0), 0);
    e.run_cycles(1); // sent in the next
    EXPECT_EQ(*seg.slave(1).sm_buffer(0), 0x10);
}

// Real time on a thread (the health thread needs the cycle to carry its datagrams): only
// behaviour is asserted, with generous time-outs.
TEST(Engine, LostSlaveIsRecoveredWhileTheOthersKeepCycling) {
    const auto& cat = ethercat::Catalog::builtin();
    ethercat::sim::Segment seg;
    std::vector<ethercat::SlaveConfig> cfg;
    const char* types[] = {"EK1100", "EL2008", "EL7041", "EL1008"};
    for (int i = 0; i < 4; ++i) {
        seg.add(*cat.find(types[i]));
        cfg.push_back({i, types[i]});
    }
    cfg[2].sdos.push_back({0x8010, 1, 900, 2}); // startup SDO, applied again on recovery
    ethercat::Bus bus(0, std::make_unique<ethercat::InProcessLink>(seg), cfg, cat);
    bus.bring_up();
    rt::MonotonicClock clock;
    rt::Engine e({1000}, clock);
    bus.add_stages(e);
    e.start();
    bus.start_health(0.02);
    auto& m = bus.master();
    auto wait = [](auto pred) {
        for (int i = 0; i < 1000 && !pred(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        return pred();
    };
    EXPECT_TRUE(wait([&] { return m.slave_online(2) && m.slave_al_status(2) == 8; }));
    seg.unplug(2);
    EXPECT_TRUE(wait([&] { return !m.slave_online(2); }));
    EXPECT_TRUE(m.slave_online(3)); // the others keep cycling
    seg.replug(2); // powered up again: INIT, no station address
    EXPECT_TRUE(wait([&] { return m.recoveries() == 1 && m.slave_online(2) && m.slave_al_status(2) == 8; }));
    EXPECT_TRUE(wait([&] { return bus.snapshot().wkc_ok; }));
    bus.stop_health();
    e.stop();
    EXPECT_EQ(seg.slave(2).al_state(), 8);
    EXPECT_EQ(seg.slave(2).station_address(), 0x1003);
}
