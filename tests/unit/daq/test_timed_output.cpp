// The timestamped output's schedule (daq::TimedPcompOutput) in isolation: a 1 ms cycle, INP
// sampled at the DC time of the last frame, the terminal's sequence (startTime, level and activate
// 0, then activate 3), edges at their interpolated times, and edges too close together counted late.
#include "daq/timed_output.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

using namespace beamctl::daq;

namespace {

constexpr uint64_t kT = 1'000'000; // ns
constexpr uint64_t kDc0 = 800'000'000'000'000'000ull; // a DC time of 2025

struct Frame {
    uint64_t start;
    bool level;
    uint8_t activate;
};

// Runs `n` cycles of INP = x(t) (t in ns after kDc0, at the last frame's time); returns each
// cycle's frame.
template <class F> std::vector<Frame> run(TimedPcompOutput& o, const PcompParams& p, F x, int n) {
    std::vector<Frame> f;
    for (int k = 1; k <= n; ++k) {
        const uint64_t dc = kDc0 + uint64_t(k) * kT;
        o.step(p, true, x(double(k) * double(kT)), dc, dc, kT);
        f.push_back({o.start_time(), o.level(), o.activate()});
    }
    return f;
}

TEST(TimedOutput, EdgesAtTheInterpolatedCrossingTime) {
    // 1 mm/s: x = t[ns] * 1e-9 mm; points every 0.01 mm (10 ms), 4 ms wide
    PcompParams p{0, 0.0123, 0.004, 0.01, 3, false, PcompDir::Positive};
    TimedPcompOutput o;
    auto f = run(o, p, [](double t) { return t * 1e-6 * 1e-3; }, 60);
    std::vector<std::pair<uint64_t, bool>> sent; // (start time, level) when armed
    for (std::size_t k = 1; k < f.size(); ++k) {
        if (f[k].activate == 3 && f[k - 1].activate == 0) {
            EXPECT_EQ(f[k].start, f[k - 1].start);  // the time loaded the frame before
            EXPECT_EQ(f[k].level, f[k - 1].level);
            // armed with frame k (at kDc0 + (k+2) T): its time is after it
            EXPECT_GT(f[k].start, kDc0 + (k + 2) * kT);
            sent.emplace_back(f[k].start, f[k].level);
        }
    }
    ASSERT_EQ(sent.size(), 6u); // 3 pulses
    for (std::size_t i = 0; i < 3; ++i) {
        const double rise = (0.0123 + 0.01 * double(i)) * 1e9, fall = rise + 0.004e9;
        EXPECT_TRUE(sent[2 * i].second);
        EXPECT_FALSE(sent[2 * i + 1].second);
        EXPECT_NEAR(double(sent[2 * i].first - kDc0), rise, 2.0) << i; // ns (rounding)
        EXPECT_NEAR(double(sent[2 * i + 1].first - kDc0), fall, 2.0) << i;
    }
    EXPECT_EQ(o.scheduled(), 6u);
    EXPECT_EQ(o.late(), 0u);
}

TEST(TimedOutput, EdgesOneCycleApartAreLate) {
    // 1 mm/s, points every 2 us of travel (2 ms) and 1 ms wide: an edge every cycle, but the
    // terminal takes one per two cycles
    PcompParams p{0, 0.0105, 0.001, 0.002, 10, false, PcompDir::Positive};
    TimedPcompOutput o;
    run(o, p, [](double t) { return t * 1e-6 * 1e-3; }, 40);
    EXPECT_GT(o.late(), 0u);
    EXPECT_EQ(o.scheduled() + o.late(), 20u);
}

TEST(TimedOutput, TimeTrainFromTheClock) {
    // INP = the engine clock [s], taken one period after the last frame; a 2 ms pulse every 4.5 ms
    PcompParams p{0, 0.0105, 0.002, 0.0045, 4, false, PcompDir::Positive};
    TimedPcompOutput o;
    std::vector<uint64_t> starts;
    uint8_t last_act = 0;
    for (int k = 1; k <= 40; ++k) {
        const uint64_t dc = kDc0 + uint64_t(k) * kT;
        o.step(p, true, double(k + 1) * 1e-3, dc + kT, dc, kT);
        if (o.activate() == 3 && last_act == 0) starts.push_back(o.start_time() - kDc0);
        last_act = o.activate();
    }
    ASSERT_EQ(starts.size(), 8u);
    for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_NEAR(double(starts[2 * i]), (10.5 + 4.5 * double(i)) * 1e6, 2.0) << i;
        EXPECT_NEAR(double(starts[2 * i + 1]), (12.5 + 4.5 * double(i)) * 1e6, 2.0) << i;
    }
    EXPECT_EQ(o.late(), 0u);
}

// EL4732 at 10 samples per cycle: sample k of a frame plays at frame + (k + 1) * 100 us; the
// edge switches from the first sample at or after the crossing.
TEST(TimedOutput, OversampledEdgeInTheSampleOfTheCrossing) {
    // 1 mm/s; a 5 ms pulse at 12.34 ms
    PcompParams p{0, 0.01234, 0.005, 0.02, 1, false, PcompDir::Positive};
    OversampledPcompOutput o;
    std::vector<std::vector<bool>> frames; // frame k passes at kDc0 + (k + 1) T
    for (int k = 1; k <= 30; ++k) {
        const uint64_t dc = kDc0 + uint64_t(k) * kT;
        o.step(p, true, double(k) * 1e-3, dc, dc, kT, 10); // 1 um per 1 ms cycle
        std::vector<bool> f;
        for (unsigned i = 0; i < 10; ++i) f.push_back(o.sample(i));
        frames.push_back(f);
    }
    // the rise at 12.34 ms: the frame passing at 12 ms (k = 11), from sample 3 (12.4 ms) on
    for (std::size_t k = 0; k < frames.size(); ++k) {
        const double frame_ms = double(k + 2);
        for (unsigned i = 0; i < 10; ++i) {
            const double t_ms = frame_ms + double(i + 1) * 0.1;
            const bool want = t_ms >= 12.34 - 1e-9 && t_ms < 17.34 - 1e-9;
            EXPECT_EQ(frames[k][i], want) << "frame at " << frame_ms << " ms, sample " << i;
        }
    }
    EXPECT_EQ(o.edges(), 2u);
}

} // namespace
