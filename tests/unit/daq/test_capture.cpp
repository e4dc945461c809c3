// The capture path: PCAP's modes and gate, arm/disarm, and a lossless ring between the cycle and a
// writer thread (10^6 cycles, every row once, in order).
#include "daq/capture.hpp"

#include "../alloc_counter.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

namespace beamctl::daq {
namespace {

TEST(Capture, ModesOverTheGatedCyclesBetweenTriggers) {
    // field 0 captured as Value, Diff, Sum, Min, Max
    Capture cap(1, {{0, CaptureMode::Value}, {0, CaptureMode::Diff}, {0, CaptureMode::Sum}, {0, CaptureMode::Min}, {0, CaptureMode::Max}}, 64);
    double v = 10;
    cap.sample(0, 0, &v, true, true, 0); // not armed: nothing
    EXPECT_EQ(cap.ring().size(), 0u);
    cap.request_arm(1);
    v = 100;
    cap.sample(1, 1000, &v, true, false, 0); // arms (Diff from 100), accumulates 100
    EXPECT_TRUE(cap.armed());
    v = 103;
    cap.sample(2, 2000, &v, false, false, 0); // gate low: not accumulated
    v = 97;
    cap.sample(3, 3000, &v, true, false, 0);
    v = 105;
    cap.sample(4, 4000, &v, true, true, 3500); // row: value 105, diff 5, sum 100+97+105, min 97, max 105
    v = 106;
    cap.sample(5, 5000, &v, true, true, 5000); // row: value 106, diff 1, sum 106, min=max=106
    RowHeader h[4];
    double vals[20];
    ASSERT_EQ(cap.ring().pop(h, vals, 4), 2u);
    EXPECT_EQ(h[0].cycle, 4u);
    EXPECT_EQ(h[0].t_ns, 3500u);
    EXPECT_EQ(h[0].capture, 1u);
    EXPECT_EQ(h[0].gated, 3u);
    EXPECT_DOUBLE_EQ(vals[0], 105);
    EXPECT_DOUBLE_EQ(vals[1], 5);
    EXPECT_DOUBLE_EQ(vals[2], 302);
    EXPECT_DOUBLE_EQ(vals[3], 97);
    EXPECT_DOUBLE_EQ(vals[4], 105);
    EXPECT_EQ(h[1].gated, 1u);
    EXPECT_DOUBLE_EQ(vals[5], 106);
    EXPECT_DOUBLE_EQ(vals[6], 1);
    EXPECT_DOUBLE_EQ(vals[7], 106);
    EXPECT_DOUBLE_EQ(vals[8], 106);
    EXPECT_DOUBLE_EQ(vals[9], 106);
    EXPECT_EQ(cap.pushed(), 2u);
    // no gated cycle since the last row: Min and Max are NaN, Sum 0
    cap.sample(6, 6000, &v, false, true, 6000);
    ASSERT_EQ(cap.ring().pop(h, vals, 4), 1u);
    EXPECT_DOUBLE_EQ(vals[2], 0);
    EXPECT_TRUE(std::isnan(vals[3]));
    EXPECT_TRUE(std::isnan(vals[4]));
    cap.request_disarm();
    cap.sample(7, 7000, &v, true, true, 7000);
    EXPECT_FALSE(cap.armed());
    EXPECT_EQ(cap.ring().size(), 0u);
    EXPECT_EQ(cap.capture(), 1u);
    EXPECT_EQ(cap.pushed(), 3u);
}

TEST(Capture, ArmAndDisarmInOneCycleEndAnEmptyCapture) {
    Capture cap(1, {{0, CaptureMode::Value}}, 16);
    double v = 1;
    cap.request_arm(1);
    cap.request_disarm();
    cap.sample(0, 0, &v, true, true, 0);
    EXPECT_FALSE(cap.armed());
    EXPECT_EQ(cap.capture(), 1u);
    EXPECT_EQ(cap.pushed(), 0u);
    cap.request_arm(2); // the next one starts its counts over
    cap.sample(1, 0, &v, true, true, 0);
    EXPECT_TRUE(cap.armed());
    EXPECT_EQ(cap.capture(), 2u);
    EXPECT_EQ(cap.pushed(), 1u);
}

TEST(Capture, AFullRingDropsAndCountsNeverBlocks) {
    Capture cap(1, {{0, CaptureMode::Value}}, 16);
    double v = 0;
    cap.request_arm(1);
    for (int k = 0; k < 40; ++k) {
        v = k;
        cap.sample(uint64_t(k), 0, &v, true, true, 0);
    }
    EXPECT_EQ(cap.pushed(), 16u);
    EXPECT_EQ(cap.dropped(), 24u);
    EXPECT_EQ(cap.dropped_total(), 24u);
    RowHeader h[32];
    double vals[32];
    ASSERT_EQ(cap.ring().pop(h, vals, 32), 16u);
    EXPECT_DOUBLE_EQ(vals[15], 15); // the oldest rows are kept, the newest dropped
}

TEST(Capture, ParseModes) {
    CaptureMode m;
    EXPECT_TRUE(parse_capture_mode("MAX", m));
    EXPECT_EQ(m, CaptureMode::Max);
    EXPECT_TRUE(parse_capture_mode("diff", m));
    EXPECT_EQ(m, CaptureMode::Diff);
    EXPECT_FALSE(parse_capture_mode("mean", m));
}

// 10^6 cycles, a row every cycle, 8 columns, a consumer thread draining as a writer would: every
// row arrives exactly once and in order, none dropped, and the cycle side allocates nothing.
TEST(Capture, MillionCyclesLosslessThroughTheRing) {
    constexpr std::size_t kCols = 8;
    std::vector<Capture::Column> cols;
    for (std::size_t c = 0; c < kCols; ++c) cols.push_back({c, CaptureMode::Value});
    Capture cap(kCols, cols, 1 << 14);
    constexpr uint64_t kCycles = 1000000;
    std::atomic<bool> done{false};
    uint64_t received = 0, bad = 0;
    std::vector<RowHeader> h(1024);
    std::vector<double> v(1024 * kCols);
    std::thread consumer([&] {
        for (;;) {
            bool finished = done.load(std::memory_order_acquire);
            std::size_t n = cap.ring().pop(h.data(), v.data(), h.size());
            for (std::size_t i = 0; i < n; ++i) {
                if (h[i].cycle != received || v[i * kCols] != double(received) || v[i * kCols + kCols - 1] != double(received) * 7)
                    ++bad;
                ++received;
            }
            if (n == 0) {
                if (finished) break;
                std::this_thread::yield();
            }
        }
    });
    cap.request_arm(1);
    double in[kCols];
    test::count_allocations(true);
    for (uint64_t k = 0; k < kCycles; ++k) {
        for (std::size_t c = 0; c < kCols; ++c) in[c] = double(k) * double(c);
        in[0] = double(k);
        // a slow consumer must not lose rows: the producer waits here, as a test, never in the cycle
        while (cap.ring().size() + 1 >= cap.ring().capacity()) std::this_thread::yield();
        cap.sample(k, k * 1000, in, true, true, k * 1000);
    }
    test::count_allocations(false);
    done.store(true, std::memory_order_release);
    consumer.join();
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_EQ(received, kCycles);
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(cap.pushed(), kCycles);
    EXPECT_EQ(cap.dropped(), 0u);
}

} // namespace
} // namespace beamctl::daq
