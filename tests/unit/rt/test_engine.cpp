// The RT engine in virtual time: stage order, cycle timing statistics, missed cycles, and a full
// cycle (bus receive, send, publish over a simulated 14-terminal segment) that allocates nothing.
#include "../alloc_counter.hpp"
#include "ethercat/bus.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/inprocess_link.hpp"
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
    ethercat::Bus bus(0, std::make_unique<ethercat::sim::InProcessLink>(seg), cfg, cat);
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
    ethercat::Bus bus(0, std::make_unique<ethercat::sim::InProcessLink>(seg), {{0, "EK1100"}, {1, "EL2008"}}, cat);
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
    ethercat::Bus bus(0, std::make_unique<ethercat::sim::InProcessLink>(seg), cfg, cat);
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

namespace {

// Wakes up late by a scripted amount each time the engine sleeps (cycle k is late by late[k]).
struct LateWakeClock : rt::Clock {
    uint64_t t = 1'000'000'000;
    std::vector<uint64_t> late;
    std::size_t k = 0;
    uint64_t now_ns() noexcept override { return t; }
    void sleep_until(uint64_t t_ns) noexcept override {
        if (t_ns > t) t = t_ns;
        t += k < late.size() ? late[k] : 0;
        ++k;
    }
};

} // namespace

TEST(Engine, LatencyBucketsFollowTheDocumentedEdges) {
    EXPECT_EQ(rt::latency_bucket(0), 0u);
    EXPECT_EQ(rt::latency_bucket(999), 0u);       // [0, 1) us
    EXPECT_EQ(rt::latency_bucket(1'000), 1u);     // [1, 2) us
    EXPECT_EQ(rt::latency_bucket(9'999), 3u);     // [5, 10) us
    EXPECT_EQ(rt::latency_bucket(10'000), 4u);    // [10, 20) us
    EXPECT_EQ(rt::latency_bucket(499'999), 8u);   // [200, 500) us
    EXPECT_EQ(rt::latency_bucket(50'000'000), rt::kLatencyBuckets - 1);
    EXPECT_EQ(rt::latency_bucket(~uint64_t(0)), rt::kLatencyBuckets - 1);
    for (std::size_t i = 0; i < rt::kLatencyBuckets; ++i)
        EXPECT_EQ(rt::latency_bucket(uint64_t(rt::kLatencyEdgesUs[i]) * 1000), i);
}

TEST(Engine, LateWakeUpsFillTheLatencyHistogramMaxAndMean) {
    LateWakeClock clock;
    rt::Engine e({1000}, clock); // 1 ms period
    struct Work : rt::Stage {
        const char* name() const noexcept override { return "work"; }
        void run(const rt::CycleInfo&) noexcept override {}
    } stage;
    e.add_stage(rt::StageOrder::Axes, stage);
    // Cycle 0 is not measured (nothing to be late against yet); then 3 cycles on time, 2 late by
    // 15 us, 1 by 120 us, 1 by 700 us.
    clock.late = {0, 0, 0, 0, 15'000, 15'000, 120'000, 700'000};
    e.run_cycles(8);
    rt::EngineStats s = e.stats();
    EXPECT_EQ(s.latency_samples, 7u);
    EXPECT_EQ(s.latency_max_ns, 700'000u);
    EXPECT_EQ(s.latency_total_ns, 850'000u);
    EXPECT_DOUBLE_EQ(s.latency_mean_ns(), 850'000.0 / 7);
    std::array<uint64_t, rt::kLatencyBuckets> expect{};
    expect[rt::latency_bucket(0)] = 3;
    expect[rt::latency_bucket(15'000)] = 2;      // [10, 20) us
    expect[rt::latency_bucket(120'000)] = 1;     // [100, 200) us
    expect[rt::latency_bucket(700'000)] = 1;     // [500, 1000) us
    EXPECT_EQ(s.latency_hist, expect);
    EXPECT_EQ(rt::latency_bucket(15'000), 4u);
    EXPECT_EQ(rt::latency_bucket(700'000), 9u);
}

TEST(Engine, ResetClearsMaxTimesCountersAndHistogramInTheNextCycle) {
    LateWakeClock clock;
    rt::Engine e({1000}, clock);
    struct Slow : rt::Stage {
        LateWakeClock* c;
        uint64_t work_ns = 0;
        const char* name() const noexcept override { return "slow"; }
        void run(const rt::CycleInfo&) noexcept override { c->t += work_ns; }
    } slow;
    slow.c = &clock;
    e.add_stage(rt::StageOrder::Axes, slow);
    slow.work_ns = 2'500'000; // overruns: missed slots
    clock.late = {0, 300'000, 300'000};
    e.run_cycles(4);
    slow.work_ns = 100'000;
    e.run_cycles(5); // back on schedule; the max times stay
    rt::EngineStats before = e.stats();
    EXPECT_GT(before.missed, 0u);
    EXPECT_GT(before.latency_max_ns, 0u);
    EXPECT_EQ(before.exec_max_ns, 2'500'000u);
    EXPECT_GT(before.latency_samples, 0u);
    EXPECT_EQ(before.stages[0].max_ns, 2'500'000u);
    EXPECT_EQ(before.resets, 0u);

    e.request_reset();
    EXPECT_EQ(e.stats().latency_samples, before.latency_samples); // applied by the RT side, not here
    e.run_cycles(1); // the reset happens first in this cycle, then the cycle is measured
    rt::EngineStats after = e.stats();
    EXPECT_EQ(after.resets, 1u);
    EXPECT_EQ(after.missed, 0u);
    EXPECT_EQ(after.exec_max_ns, 100'000u);
    EXPECT_EQ(after.stages[0].max_ns, 100'000u);
    EXPECT_EQ(after.stages[0].total_ns, 100'000u);
    EXPECT_EQ(after.latency_samples, 1u);
    EXPECT_EQ(after.jitter_max_ns, 0);
    uint64_t sum = 0;
    for (uint64_t c : after.latency_hist) sum += c;
    EXPECT_EQ(sum, 1u);
    EXPECT_EQ(after.cycles, before.cycles + 1); // the cycle number runs on

    e.run_cycles(10); // and counts grow again
    rt::EngineStats later = e.stats();
    EXPECT_EQ(later.latency_samples, 11u);
    EXPECT_EQ(later.latency_hist[0], 11u);
    EXPECT_EQ(later.latency_max_ns, 0u);
}

TEST(Engine, CyclesWithTheHistogramAndAResetAllocateNothing) {
    LateWakeClock clock;
    rt::Engine e({1000}, clock);
    struct Nop : rt::Stage {
        const char* name() const noexcept override { return "nop"; }
        void run(const rt::CycleInfo&) noexcept override {}
    } nop;
    e.add_stage(rt::StageOrder::Axes, nop);
    clock.late.assign(2000, 0);
    for (std::size_t i = 0; i < clock.late.size(); ++i) clock.late[i] = (i * 7919) % 2'000'000;
    e.run_cycles(10);
    test::count_allocations(true);
    e.run_cycles(500);
    e.request_reset();
    e.run_cycles(500);
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_EQ(e.stats().latency_samples, 500u);
}

namespace {
// A scanner's tick in virtual time: ticks at `first + k * period` until `stop_at`, and again from
// `resume_at`; a wait jumps the clock to the tick (or to the deadline when none comes before it).
struct FakeTick : rt::TickSource {
    rt::VirtualClock& clock;
    uint64_t first, period, stop_at, resume_at, next;
    FakeTick(rt::VirtualClock& c, uint64_t f, uint64_t p, uint64_t s, uint64_t r)
        : clock(c), first(f), period(p), stop_at(s), resume_at(r), next(f) {}
    bool wait(uint64_t deadline, uint64_t& t) noexcept override {
        while (next <= clock.now_ns() || (next >= stop_at && next < resume_at)) next += period; // passed or silent
        if (next > deadline) {
            clock.sleep_until(deadline);
            return false;
        }
        clock.sleep_until(next);
        t = next;
        next += period;
        return true;
    }
};
struct TimeLog : rt::Stage {
    std::vector<uint64_t> t;
    const char* name() const noexcept override { return "times"; }
    void run(const rt::CycleInfo& c) noexcept override { t.push_back(c.t_ns); }
};
} // namespace

// An IOC on a scanner's bus cycles on the scanner's tick, at its times; without ticks it runs on
// its own clock half a period later (free run, counted) and follows the ticks again when they return.
TEST(Engine, FollowsATickSourceAndFreeRunsWithoutIt) {
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    const uint64_t t0 = clock.now_ns() + 300'000; // ticks 0.3 ms off the engine's own grid
    FakeTick tick(clock, t0, 1'000'000, t0 + 10'000'000, t0 + 20'000'000);
    e.set_tick_source(&tick, 500'000);
    TimeLog log;
    e.add_stage(rt::StageOrder::Publish, log);
    e.run_cycles(30);
    ASSERT_EQ(log.t.size(), 30u);
    for (int k = 0; k < 10; ++k) EXPECT_EQ(log.t[std::size_t(k)], t0 + uint64_t(k) * 1'000'000) << k; // on the tick
    // ticks stop at t0 + 10 ms: the next cycle is due then; it runs 0.5 ms later on its own clock,
    // then every period until the ticks return at t0 + 20 ms
    EXPECT_EQ(log.t[10], t0 + 10'000'000 + 500'000);
    EXPECT_EQ(log.t[11], t0 + 11'000'000 + 500'000);
    std::size_t back = 0;
    for (std::size_t k = 10; k < log.t.size(); ++k)
        if ((log.t[k] - t0) % 1'000'000 == 0) {
            back = k;
            break;
        }
    ASSERT_GT(back, 10u);
    EXPECT_GE(log.t[back], t0 + 20'000'000);
    for (std::size_t k = back; k < log.t.size(); ++k) EXPECT_EQ((log.t[k] - t0) % 1'000'000, 0u) << k; // on the ticks again
    for (std::size_t k = 1; k < log.t.size(); ++k) EXPECT_GT(log.t[k], log.t[k - 1]);
    rt::EngineStats s = e.stats();
    EXPECT_EQ(s.ticks + s.free_run, 30u);
    EXPECT_EQ(s.free_run, back - 10);
    EXPECT_EQ(s.latency_max_ns, 0u); // virtual time: each cycle starts at its tick
}

TEST(Engine, ATickCycleAllocatesNothing) {
    rt::VirtualClock clock;
    rt::Engine e({1000}, clock);
    FakeTick tick(clock, clock.now_ns() + 1'000'000, 1'000'000, ~0ull, ~0ull);
    e.set_tick_source(&tick, 500'000);
    TimeLog log;
    log.t.reserve(200);
    e.add_stage(rt::StageOrder::Publish, log);
    e.run_cycles(10);
    test::count_allocations(true);
    e.run_cycles(100);
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
}
