#include "detector/sim_mca.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::detector {

namespace {

constexpr double kFwhmPerSigma = 2.354820045;
double phi(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); } // the standard normal CDF

} // namespace

SimMca::SimMca(SimMcaConfig cfg, std::function<double()> clock, std::function<double()> intensity)
    : cfg_(std::move(cfg)), clock_(std::move(clock)), intensity_(std::move(intensity)), rng_(cfg_.seed) {
    if (cfg_.channels == 0) cfg_.channels = 1;
    if (!(cfg_.cals != 0)) cfg_.cals = 0.01;
    if (!(cfg_.dxp.peaking_time > 0)) cfg_.dxp.peaking_time = 2.0;
    if (!(cfg_.dxp.preamp_gain > 0)) cfg_.dxp.preamp_gain = 2.0;
    if (!(cfg_.dxp.calibration_energy > 0)) cfg_.dxp.calibration_energy = 5.9;
    if (!(cfg_.dxp.max_energy != 0)) cfg_.dxp.max_energy = cfg_.calo + cfg_.cals * cfg_.channels;
    if (!(cfg_.dxp.adc_percent_rule > 0)) // the ADC spans 1.25 x the spectrum's top
        cfg_.dxp.adc_percent_rule = std::min(100.0, 100.0 * cfg_.dxp.calibration_energy / (1.25 * std::max(std::fabs(cfg_.dxp.max_energy), 1e-3)));
    if (!(cfg_.true_preamp_gain > 0)) cfg_.true_preamp_gain = cfg_.dxp.preamp_gain;
    dxp_ = cfg_.dxp;
    counts_.assign(cfg_.channels, 0);
    setup_.nuse = int32_t(cfg_.channels);
    rebuild();
}

double SimMca::dynamic_range() const { return dxp_.calibration_energy * 100.0 / dxp_.adc_percent_rule; }

double SimMca::event_dead_time() const {
    const double ref = 2 * cfg_.dxp.peaking_time + cfg_.dxp.gap_time;
    return ref > 0 ? cfg_.dead_time * (2 * dxp_.peaking_time + dxp_.gap_time) / ref : cfg_.dead_time;
}

// The expected rates [counts/s at intensity 1] of what the processor records now: per channel,
// and the triggered events that are not binned (below EnergyThreshold, above the ADC, beyond the
// last channel).
void SimMca::rebuild() {
    cals_ = (dxp_.max_energy - cfg_.calo) / cfg_.channels;
    const double k = cfg_.true_preamp_gain / dxp_.preamp_gain; // recorded / true energy
    const double inf = HUGE_VAL;
    // the background: flat in true energy over the configured spectrum
    const double b0 = cfg_.calo - 0.5 * cfg_.cals, b1 = b0 + cfg_.cals * cfg_.channels;
    const double lo_b = k * std::min(b0, b1), hi_b = k * std::max(b0, b1);
    struct Peak {
        double mu, sigma, rate;
    };
    std::vector<Peak> peaks;
    for (const auto& l : cfg_.lines) {
        // the electronic noise part of the FWHM goes as 1/sqrt(peaking time)
        const double fwhm = std::max(l.fwhm, 1e-6), n = std::min(cfg_.noise_fwhm, fwhm);
        const double f = std::sqrt(fwhm * fwhm - n * n + n * n * cfg_.dxp.peaking_time / dxp_.peaking_time);
        peaks.push_back({k * l.energy, std::max(k * f / kFwhmPerSigma, 1e-9), l.rate});
    }
    auto rate_in = [&](double a, double b) { // recorded energies in [a, b)
        if (!(b > a)) return 0.0;
        double r = 0;
        if (hi_b > lo_b) r += cfg_.background * std::max(0.0, std::min(b, hi_b) - std::max(a, lo_b)) / (hi_b - lo_b);
        for (const Peak& p : peaks) r += p.rate * std::max(0.0, phi((b - p.mu) / p.sigma) - phi((a - p.mu) / p.sigma));
        return r;
    };
    const double trig = dxp_.trigger_threshold > 0 ? dxp_.trigger_threshold : -inf;
    const double elo = std::max(trig, dxp_.energy_threshold > 0 ? dxp_.energy_threshold : -inf);
    const double top = dynamic_range();
    trigger_rate_ = rate_in(trig, inf);
    under_rate_ = rate_in(trig, elo);
    over_rate_ = rate_in(std::max(elo, top), inf);
    shape_.assign(cfg_.channels, 0);
    double binned = 0;
    for (uint32_t i = 0; i < cfg_.channels; ++i) {
        double e0 = cfg_.calo + cals_ * (double(i) - 0.5), e1 = cfg_.calo + cals_ * (double(i) + 0.5);
        if (e1 < e0) std::swap(e0, e1);
        shape_[i] = rate_in(std::max(e0, elo), std::min(e1, top));
        binned += shape_[i];
    }
    beyond_rate_ = std::max(0.0, trigger_rate_ - under_rate_ - over_rate_ - binned);
}

bool SimMca::set_dxp(const DxpSettings& d, std::string& why) {
    auto out = [&](const char* what, double v, const char* range) {
        why = SB() << what << " " << v << " is out of range (" << range << ")";
        return false;
    };
    if (!(d.peaking_time >= 0.01 && d.peaking_time <= 100)) return out("PeakingTime", d.peaking_time, "0.01 .. 100 us");
    if (!(d.gap_time >= 0 && d.gap_time <= 100)) return out("GapTime", d.gap_time, "0 .. 100 us");
    if (!(d.trigger_threshold >= 0 && d.trigger_threshold <= 1000)) return out("TriggerThreshold", d.trigger_threshold, "0 .. 1000 keV");
    if (!(d.energy_threshold >= 0 && d.energy_threshold <= 1000)) return out("EnergyThreshold", d.energy_threshold, "0 .. 1000 keV");
    if (!(d.preamp_gain > 0 && d.preamp_gain <= 1e4)) return out("PreampGain", d.preamp_gain, "> 0 .. 10000 mV/keV");
    if (!((d.max_energy - cfg_.calo) * cfg_.cals > 0 && std::fabs(d.max_energy) <= 1e4))
        return out("MaxEnergy", d.max_energy, cfg_.cals > 0 ? "above the spectrum's offset CALO, up to 10000 keV" : "below CALO");
    if (!(d.adc_percent_rule > 0 && d.adc_percent_rule <= 100)) return out("ADCPercentRule", d.adc_percent_rule, "> 0 .. 100 %");
    if (!(d.calibration_energy > 0 && d.calibration_energy <= 1000)) return out("CalibrationEnergy", d.calibration_energy, "> 0 .. 1000 keV");
    if (int(d.preset_mode) < 0 || int(d.preset_mode) > 4) return out("PresetMode", int(d.preset_mode), "0 .. 4");
    if (d.preset_events < 0) return out("PresetEvents", double(d.preset_events), ">= 0");
    if (d.preset_triggers < 0) return out("PresetTriggers", double(d.preset_triggers), ">= 0");
    if (acquiring_) advance(clock_()); // what was acquired so far, with the settings it had
    dxp_ = d;
    rebuild();
    return true;
}

DxpCounters SimMca::counters() const {
    DxpCounters c;
    c.triggers = triggers_, c.events = events_, c.overflows = overflows_, c.underflows = underflows_;
    c.real = real_, c.live = live_;
    c.input_rate = live_ > 0 ? double(triggers_) / live_ : 0;
    c.output_rate = real_ > 0 ? double(events_) / real_ : 0;
    return c;
}

double SimMca::input_rate() const {
    return trigger_rate_ * (intensity_ ? std::max(0.0, intensity_()) : 1.0);
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
    ++starts_;
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
    real_ = live_ = region_expected_ = events_expected_ = triggers_expected_ = 0;
    triggers_ = events_ = overflows_ = underflows_ = 0;
    return true;
}

// Acquires from last_ to `now` (or to the preset that ends the acquisition first).
void SimMca::advance(double now) {
    double dt = now - last_;
    last_ = now;
    if (!acquiring_ || !(dt > 0)) return;
    const double scale = intensity_ ? std::max(0.0, intensity_()) : 1.0;
    const double live_per_real = 1.0 / (1.0 + input_rate() * event_dead_time()); // non-paralyzable
    const int32_t n = std::min<int32_t>(setup_.nuse, int32_t(cfg_.channels));
    bool ended = false;
    // each preset: the time at which it is reached, if within dt
    auto preset = [&](double so_far, double per_second, double target) {
        if (target > 0 && per_second > 0 && so_far + per_second * dt >= target) {
            dt = std::max(0.0, (target - so_far) / per_second);
            ended = true;
        }
    };
    preset(real_, 1.0, setup_.prtm);
    preset(live_, live_per_real, setup_.pltm);
    double region = 0; // expected counts/s in pctl..pcth
    if (setup_.pct > 0) {
        const int32_t lo = std::max(0, setup_.pctl), hi = std::min(n - 1, setup_.pcth);
        for (int32_t i = lo; i <= hi; ++i) region += shape_[std::size_t(i)];
        region *= scale * live_per_real;
        preset(region_expected_, region, setup_.pct);
    }
    const double triggers = trigger_rate_ * scale * live_per_real;
    const double events = (trigger_rate_ - under_rate_ - over_rate_) * scale * live_per_real;
    if (dxp_.preset_mode == DxpPresetMode::Events) preset(events_expected_, events, double(dxp_.preset_events));
    if (dxp_.preset_mode == DxpPresetMode::Triggers) preset(triggers_expected_, triggers, double(dxp_.preset_triggers));
    region_expected_ += region * dt;
    events_expected_ += events * dt;
    triggers_expected_ += triggers * dt;
    const double live_dt = dt * live_per_real;
    auto poisson = [&](double mean) -> int64_t { return mean > 0 ? std::poisson_distribution<int64_t>(mean)(rng_) : 0; };
    int64_t binned = 0;
    double beyond = beyond_rate_; // and the channels past NUSE
    for (int32_t i = 0; i < int32_t(cfg_.channels); ++i) {
        if (i >= n) {
            beyond += shape_[std::size_t(i)];
            continue;
        }
        const int64_t k = poisson(shape_[std::size_t(i)] * scale * live_dt);
        binned += k;
        counts_[std::size_t(i)] = int32_t(std::min<int64_t>(int64_t(counts_[std::size_t(i)]) + k, INT32_MAX));
    }
    const int64_t past = poisson(beyond * scale * live_dt), under = poisson(under_rate_ * scale * live_dt),
                  over = poisson(over_rate_ * scale * live_dt);
    events_ += binned + past;
    underflows_ += under;
    overflows_ += over;
    triggers_ += binned + past + under + over;
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
