#include "detector/sim_mca.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::detector {

SimMca::SimMca(SimMcaConfig cfg, std::function<double()> clock, std::function<double()> intensity)
    : cfg_(std::move(cfg)), clock_(std::move(clock)), intensity_(std::move(intensity)), rng_(cfg_.seed) {
    if (cfg_.channels == 0) cfg_.channels = 1;
    shape_.assign(cfg_.channels, cfg_.background / cfg_.channels);
    for (const auto& l : cfg_.lines) {
        const double sigma = std::max(l.fwhm, 1e-6) / 2.354820045;
        for (uint32_t i = 0; i < cfg_.channels; ++i) {
            // the fraction of the line within the channel's energy bin
            const double e0 = cfg_.calo + cfg_.cals * (double(i) - 0.5), e1 = cfg_.calo + cfg_.cals * (double(i) + 0.5);
            const double p = 0.5 * (std::erf((e1 - l.energy) / (sigma * std::sqrt(2.0))) - std::erf((e0 - l.energy) / (sigma * std::sqrt(2.0))));
            shape_[i] += l.rate * std::fabs(p);
        }
    }
    counts_.assign(cfg_.channels, 0);
    setup_.nuse = int32_t(cfg_.channels);
}

double SimMca::input_rate() const {
    double r = 0;
    for (double s : shape_) r += s;
    return r * (intensity_ ? std::max(0.0, intensity_()) : 1.0);
}

bool SimMca::setup(const Setup& s) {
    setup_ = s;
    if (setup_.nuse <= 0 || uint32_t(setup_.nuse) > cfg_.channels) setup_.nuse = int32_t(cfg_.channels);
    return s.mode == McaMode::Pha; // MCS and List are not simulated
}

bool SimMca::start() {
    if (acquiring_) return true;
    last_ = clock_();
    acquiring_ = true;
    return true;
}

bool SimMca::stop() {
    if (acquiring_) advance(clock_());
    acquiring_ = false;
    return true;
}

bool SimMca::erase() {
    if (acquiring_) advance(clock_());
    std::fill(counts_.begin(), counts_.end(), 0);
    real_ = live_ = region_expected_ = 0;
    return true;
}

// Acquires from last_ to `now` (or to the preset that ends the acquisition first).
void SimMca::advance(double now) {
    double dt = now - last_;
    last_ = now;
    if (!acquiring_ || !(dt > 0)) return;
    const double scale = intensity_ ? std::max(0.0, intensity_()) : 1.0;
    const double in_rate = input_rate();
    const double live_per_real = 1.0 / (1.0 + in_rate * cfg_.dead_time); // non-paralyzable
    bool ended = false;
    if (setup_.prtm > 0 && real_ + dt >= setup_.prtm) {
        dt = std::max(0.0, setup_.prtm - real_);
        ended = true;
    }
    if (setup_.pltm > 0 && live_ + dt * live_per_real >= setup_.pltm) {
        dt = std::max(0.0, (setup_.pltm - live_) / live_per_real);
        ended = true;
    }
    const int32_t n = std::min<int32_t>(setup_.nuse, int32_t(cfg_.channels));
    if (setup_.pct > 0) {
        const int32_t lo = std::max(0, setup_.pctl), hi = std::min(n - 1, setup_.pcth);
        double region = 0;
        for (int32_t i = lo; i <= hi; ++i) region += shape_[std::size_t(i)];
        region *= scale * live_per_real;
        if (region > 0 && region_expected_ + region * dt >= setup_.pct) {
            dt = std::max(0.0, (setup_.pct - region_expected_) / region);
            ended = true;
        }
        region_expected_ += region * dt;
    }
    const double live_dt = dt * live_per_real;
    for (int32_t i = 0; i < n; ++i) {
        const double mean = shape_[std::size_t(i)] * scale * live_dt;
        if (mean <= 0) continue;
        const int64_t k = std::poisson_distribution<int64_t>(mean)(rng_);
        counts_[std::size_t(i)] = int32_t(std::min<int64_t>(int64_t(counts_[std::size_t(i)]) + k, INT32_MAX));
    }
    real_ += dt;
    live_ += live_dt;
    if (ended) acquiring_ = false;
}

bool SimMca::status(Status& s) {
    advance(clock_());
    s.real = real_;
    s.live = live_;
    s.dwell = setup_.dwel;
    s.acquiring = acquiring_;
    int64_t total = 0;
    const int32_t n = std::min<int32_t>(setup_.nuse, int32_t(cfg_.channels));
    const int32_t lo = std::max(0, setup_.pctl), hi = setup_.pct > 0 ? std::min(n - 1, setup_.pcth) : n - 1;
    for (int32_t i = lo; i <= hi; ++i) total += counts_[std::size_t(i)];
    s.total = int32_t(std::min<int64_t>(total, INT32_MAX));
    return true;
}

uint32_t SimMca::read(int32_t* data, uint32_t n) {
    const uint32_t m = std::min<uint32_t>({n, cfg_.channels, uint32_t(std::max(setup_.nuse, 1))});
    std::copy(counts_.begin(), counts_.begin() + m, data);
    return m;
}

} // namespace beamctl::detector
