#include "detector/quadem.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::detector {

const char* const kQuadEmValueNames[kQuadEmValues] = {"Current1", "Current2", "Current3", "Current4", "SumX", "SumY",
                                                       "SumAll",   "DiffX",    "DiffY",    "PosX",     "PosY"};

void quadem_compute(const double raw[4], const QuadEmParams& p, double v[kQuadEmValues]) noexcept {
    for (int i = 0; i < 4; ++i) {
        double c = raw[i] * p.current_scale[i];
        if (p.full_scale > 0) c = c > p.full_scale ? p.full_scale : c < -p.full_scale ? -p.full_scale : c; // saturated in its range
        v[i] = c - p.current_offset[i];
    }
    const double i1 = v[kCurrent1], i2 = v[kCurrent2], i3 = v[kCurrent3], i4 = v[kCurrent4];
    v[kSumAll] = i1 + i2 + i3 + i4;
    switch (p.geometry) {
    case QuadEmGeometry::Square:
        v[kSumX] = v[kSumY] = v[kSumAll];
        v[kDiffX] = (i2 + i3) - (i1 + i4);
        v[kDiffY] = (i1 + i2) - (i3 + i4);
        break;
    case QuadEmGeometry::SquareCC:
        v[kSumX] = v[kSumY] = v[kSumAll];
        v[kDiffX] = (i3 + i4) - (i1 + i2);
        v[kDiffY] = (i1 + i4) - (i2 + i3);
        break;
    case QuadEmGeometry::Diamond:
        v[kSumX] = i1 + i2;
        v[kSumY] = i3 + i4;
        v[kDiffX] = i2 - i1;
        v[kDiffY] = i4 - i3;
        break;
    }
    const double dx = v[kSumX] == 0 ? 1 : v[kSumX], dy = v[kSumY] == 0 ? 1 : v[kSumY];
    v[kPosX] = p.position_scale[0] * v[kDiffX] / dx - p.position_offset[0];
    v[kPosY] = p.position_scale[1] * v[kDiffY] / dy - p.position_offset[1];
}

QuadEm::QuadEm(const QuadEmParams& initial) : p_(initial) {
    params_.init([&](QuadEmParams& b) { b = initial; });
    p_.num_average = std::max(1, p_.num_average);
}

void QuadEm::set_params(const QuadEmParams& p) {
    params_.write_buffer() = p;
    params_.publish();
}

void QuadEm::sample(const double raw[4], bool valid, uint64_t cycle) noexcept {
    if (params_.update()) {
        const int was = p_.num_average;
        p_ = params_.read_buffer();
        p_.num_average = std::max(1, p_.num_average);
        if (p_.num_average != was) n_ = 0;
    }
    if (!valid) { // no sample: the cells keep the last one, the partial average is dropped
        n_ = 0;
        return;
    }
    quadem_compute(raw, p_, v_);
    if (stream_.load(std::memory_order_relaxed)) {
        QuadEmSample s;
        for (int k = 0; k < kQuadEmValues; ++k) s.v[k] = v_[k];
        s.cycle = cycle;
        if (!samples_.push(s)) samples_dropped_.fetch_add(1, std::memory_order_relaxed);
    }
    for (int k = 0; k < kQuadEmValues; ++k) {
        const double x = v_[k];
        if (n_ == 0) sum_[k] = sum2_[k] = 0, min_[k] = max_[k] = shift_[k] = x;
        const double d = x - shift_[k]; // shifted sums: no cancellation for a large mean
        sum_[k] += d;
        sum2_[k] += d * d;
        min_[k] = std::min(min_[k], x);
        max_[k] = std::max(max_[k], x);
    }
    if (++n_ < p_.num_average) return;
    QuadEmReading r;
    r.n = n_;
    r.cycle = cycle;
    for (int k = 0; k < kQuadEmValues; ++k) {
        const double m = sum_[k] / n_;
        r.mean[k] = shift_[k] + m;
        r.sigma[k] = std::sqrt(std::max(0.0, sum2_[k] / n_ - m * m));
        r.min[k] = min_[k];
        r.max[k] = max_[k];
    }
    n_ = 0;
    if (!readings_.push(r)) ++dropped_;
}

} // namespace beamctl::detector
