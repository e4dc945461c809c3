// A simulated energy-dispersive detector behind an mca record: fluorescence lines (Gaussian peaks
// of a given FWHM) on a flat background, counted with Poisson statistics and a non-paralyzable
// dead time, acquired up to the time of each status read (a clock it is given: the IOC loop's, or
// a test's virtual one). Presets end the acquisition at the exact time they are reached (real and
// live time; counts in the preset region at the expected time), so ERTM/ELTM equal the preset.
// `intensity` scales every rate (the beam on the sample, 1 = as configured).
// Threading: the database thread (the record's processing).
#pragma once

#include "detector/mca_device.hpp"

#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace beamctl::detector {

struct SimMcaConfig {
    struct Line {
        std::string name;  // "Fe Ka"
        double energy = 0; // keV
        double rate = 0;   // counts/s into the detector (before dead time)
        double fwhm = 0.15; // keV
    };
    uint32_t channels = 2048;
    double calo = 0, cals = 0.01; // keV = calo + cals * channel
    std::vector<Line> lines;
    double background = 50;   // counts/s over the whole spectrum, flat
    double dead_time = 2e-6;  // s per event (non-paralyzable)
    uint64_t seed = 1;
};

class SimMca : public McaDevice {
public:
    SimMca(SimMcaConfig cfg, std::function<double()> clock, std::function<double()> intensity = {});

    bool setup(const Setup& s) override;
    bool start() override;
    bool stop() override;
    bool erase() override;
    bool status(Status& s) override;
    uint32_t read(int32_t* data, uint32_t n) override;
    std::string describe() const override { return "simulated MCA (" + std::to_string(cfg_.channels) + " channels)"; }

    const SimMcaConfig& config() const { return cfg_; }
    // What scales every rate from now on (the beam's transmission through the slit; none: 1).
    void set_intensity(std::function<double()> intensity) { intensity_ = std::move(intensity); }
    // The expected input count rate [counts/s] now, and per channel (tests).
    double input_rate() const;
    const std::vector<double>& shape() const { return shape_; } // counts/s per channel at intensity 1

private:
    void advance(double now);

    SimMcaConfig cfg_;
    std::function<double()> clock_, intensity_;
    std::vector<double> shape_;    // counts/s per channel
    std::vector<int32_t> counts_;
    Setup setup_;
    bool acquiring_ = false;
    double last_ = 0;              // clock at the last advance
    double real_ = 0, live_ = 0;
    double region_expected_ = 0;   // expected counts in pctl..pcth so far (counts preset)
    std::mt19937_64 rng_;
};

} // namespace beamctl::detector
