// The quad electrometer's arithmetic and averaging (quadEM's drvQuadEM::computePositions and its
// callbacks every NumAverage samples), fed one sample of four currents per engine cycle.
//   I_i    = raw_i * CurrentScale_i - CurrentOffset_i
//   Square   SumX = SumY = SumAll, DiffX = (I2 + I3) - (I1 + I4), DiffY = (I1 + I2) - (I3 + I4)
//   SquareCC SumX = SumY = SumAll, DiffX = (I3 + I4) - (I1 + I2), DiffY = (I1 + I4) - (I2 + I3)
//   Diamond  SumX = I1 + I2, SumY = I3 + I4, DiffX = I2 - I1, DiffY = I4 - I3
//   PosX   = PositionScaleX * DiffX / SumX - PositionOffsetX (a sum of 0 counts as 1); Y alike.
// Every sample's 11 values are the engine's cells (a fast EPID loop reads PosY in the cycle); every
// NumAverage samples a reading (mean, sigma, min, max of each value) goes to the IOC loop.
// Threading: sample() on the RT thread (noexcept, no allocation); set_params()/pop() on the IOC
// loop.
#pragma once

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"

#include <atomic>
#include <cstdint>

namespace beamctl::detector {

// quadEM's Geometry menu (Custom, its fourth choice, is not offered).
enum class QuadEmGeometry : uint8_t { Diamond = 0, Square = 1, SquareCC = 2 };

// The 11 values in quadEM's order (its QE_DOUBLE_DATA addresses 0..10).
enum QuadEmValue : int { kCurrent1, kCurrent2, kCurrent3, kCurrent4, kSumX, kSumY, kSumAll, kDiffX, kDiffY, kPosX, kPosY, kQuadEmValues };
// quadEM's names of the values: "Current1" .. "Current4", "SumX", "SumY", "SumAll", "DiffX",
// "DiffY", "PosX", "PosY" (its stats plugins' prefixes).
extern const char* const kQuadEmValueNames[kQuadEmValues];

struct QuadEmParams {
    double current_scale[4] = {1, 1, 1, 1};
    double current_offset[4] = {0, 0, 0, 0};
    double position_scale[2] = {1e6, 1e6}; // quadEM's default
    double position_offset[2] = {0, 0};
    QuadEmGeometry geometry = QuadEmGeometry::Square;
    double full_scale = 0; // the range: a scaled current beyond +-full_scale reads +-full_scale (0: no limit)
    int num_average = 1; // samples per reading (>= 1)
};

// One sample's values from four raw currents.
void quadem_compute(const double raw[4], const QuadEmParams& p, double out[kQuadEmValues]) noexcept;

// One sample's 11 values (what quadEM's time-series plugin gets point by point).
struct QuadEmSample {
    double v[kQuadEmValues];
    uint64_t cycle = 0;
};

struct QuadEmReading {
    double mean[kQuadEmValues], sigma[kQuadEmValues], min[kQuadEmValues], max[kQuadEmValues];
    int n = 0;          // samples averaged
    uint64_t cycle = 0; // the cycle of the last sample
};

class QuadEm {
public:
    explicit QuadEm(const QuadEmParams& initial);

    // IOC loop: new parameters (from the next sample on; a new NumAverage restarts the average).
    void set_params(const QuadEmParams& p);
    // IOC loop: the next reading, false when none is waiting.
    bool pop(QuadEmReading& r) noexcept { return readings_.pop(r); }

    // RT: one sample; `valid` false (the bus is down) keeps the cells and drops the partial average.
    void sample(const double raw[4], bool valid, uint64_t cycle) noexcept;
    // RT: the last sample's values, in quadEM's order (what the engine's qe signals read).
    const double* values() const noexcept { return v_; }
    uint64_t dropped() const noexcept { return dropped_; } // readings the IOC loop did not take

    // IOC loop: every sample's values are queued for pop_sample() while on (the time series);
    // off, the cycle skips the queue.
    void stream_samples(bool on) noexcept { stream_.store(on, std::memory_order_relaxed); }
    bool pop_sample(QuadEmSample& s) noexcept { return samples_.pop(s); }
    uint64_t samples_dropped() const noexcept { return samples_dropped_.load(std::memory_order_relaxed); }

private:
    TripleBuffer<QuadEmParams> params_;
    QuadEmParams p_; // RT copy
    double v_[kQuadEmValues] = {};
    double shift_[kQuadEmValues] = {}, sum_[kQuadEmValues] = {}, sum2_[kQuadEmValues] = {}, min_[kQuadEmValues] = {}, max_[kQuadEmValues] = {};
    int n_ = 0;
    uint64_t dropped_ = 0;
    SpscQueue<QuadEmReading> readings_{256};
    std::atomic<bool> stream_{false};
    std::atomic<uint64_t> samples_dropped_{0};
    SpscQueue<QuadEmSample> samples_{16384}; // 1.6 s at 10 kHz
};

} // namespace beamctl::detector
