// A simulated energy-dispersive detector behind an mca record: fluorescence lines (Gaussian peaks
// of a given FWHM) on a flat background, counted with Poisson statistics and a non-paralyzable
// dead time, acquired up to the time of each status read (a clock it is given: the IOC loop's, or
// a test's virtual one). Presets end the acquisition at the exact time they are reached (real and
// live time; counts in the preset region, events or triggers at the expected time), so ERTM/ELTM
// equal the preset. `intensity` scales every rate (the beam on the sample, 1 = as configured).
//
// The pulse processor's parameters (XIA's, as synApps' dxp serves them: dxpHighLevel.template)
// shape what is counted:
// - PeakingTime, GapTime: the energy filter. The dead time per event scales with its length
//   2 PeakingTime + GapTime; each line's electronic-noise part of the FWHM with 1/sqrt(PeakingTime)
//   (the configured FWHMs and dead time hold at the configured PeakingTime and GapTime).
// - PreampGain: the gain the processor assumes. Energies are recorded as E x true gain / PreampGain,
//   so a gain set wrong moves the peaks (a detector's true gain is configured per element).
// - TriggerThreshold: events below it are not seen (no dead time, not counted).
// - EnergyThreshold: events below it are counted as Underflows, not binned.
// - MaxEnergy: the spectrum's top (the bin width is (MaxEnergy - CALO) / channels).
// - ADCPercentRule, CalibrationEnergy: the ADC spans CalibrationEnergy x 100 / ADCPercentRule;
//   events above it are Overflows.
// Threading: the database thread (the record's processing).
#pragma once

#include "detector/mca_device.hpp"

#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace beamctl::detector {

// What dxp's PresetMode selects (NDDxp's order); Events and Triggers end an acquisition at
// PresetEvents / PresetTriggers, besides the mca record's presets.
enum class DxpPresetMode : int { None = 0, Real = 1, Live = 2, Events = 3, Triggers = 4 };

// The pulse processor's settings (dxp's names; times in us, energies in keV).
struct DxpSettings {
    double peaking_time = 2.0, gap_time = 0.15;        // energy filter [us]
    double trigger_threshold = 0, energy_threshold = 0; // [keV]
    double preamp_gain = 2.0;                           // [mV/keV] assumed
    double max_energy = 0;                              // [keV] spectrum top (0: CALO + CALS x channels)
    double adc_percent_rule = 0;                        // [%] (0: the ADC spans 1.25 x MaxEnergy)
    double calibration_energy = 5.9;                    // [keV]
    DxpPresetMode preset_mode = DxpPresetMode::None;
    int64_t preset_events = 0, preset_triggers = 0;
};

// What the processor counted in this acquisition (dxp's statistics).
struct DxpCounters {
    int64_t triggers = 0, events = 0, overflows = 0, underflows = 0;
    double real = 0, live = 0;        // [s] elapsed real, energy and trigger live time
    double input_rate = 0, output_rate = 0; // [counts/s] triggers / live, events / real
};

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
    double dead_time = 2e-6;  // s per event (non-paralyzable) at dxp's peaking and gap time
    DxpSettings dxp;          // the processor's settings at start (and the reference above)
    double true_preamp_gain = 0; // [mV/keV] the detector's (0: dxp.preamp_gain)
    double noise_fwhm = 0.1;  // [keV] electronic-noise part of each line's FWHM at dxp.peaking_time
    uint64_t seed = 1;
};

class SimMca : public McaDevice {
public:
    SimMca(SimMcaConfig cfg, std::function<double()> clock, std::function<double()> intensity = {});

    bool setup(const Setup& s) override;
    bool supports(McaMode m) const override { return m == McaMode::Pha; } // MCS and List are not simulated
    bool start() override;
    bool stop() override;
    bool erase() override;
    bool status(Status& s) override;
    uint32_t read(int32_t* data, uint32_t n) override;
    std::string describe() const override { return "simulated MCA (" + std::to_string(cfg_.channels) + " channels)"; }

    const SimMcaConfig& config() const { return cfg_; }
    bool acquiring() const { return acquiring_; } // as of the last status read
    uint64_t starts() const { return starts_; }   // acquisitions started so far
    // The processor's settings: applied from now on (what was acquired so far stays). false with
    // `why` for a value out of range (nothing changes).
    bool set_dxp(const DxpSettings& d, std::string& why);
    const DxpSettings& dxp() const { return dxp_; }
    DxpCounters counters() const;
    double cals() const { return cals_; }            // [keV/channel] now (MaxEnergy)
    double dynamic_range() const;                    // [keV] the ADC's top
    double event_dead_time() const;                  // [s] per event now
    // What scales every rate from now on (the beam's transmission through the slit; none: 1).
    void set_intensity(std::function<double()> intensity) { intensity_ = std::move(intensity); }
    // The expected input count rate [counts/s] now (what the trigger sees), and per channel (tests).
    double input_rate() const;
    const std::vector<double>& shape() const { return shape_; } // counts/s per channel at intensity 1

private:
    void advance(double now);
    void rebuild(); // shape_ and the rates from dxp_

    SimMcaConfig cfg_;
    DxpSettings dxp_;
    double cals_ = 0.01;
    double trigger_rate_ = 0, under_rate_ = 0, over_rate_ = 0, beyond_rate_ = 0; // counts/s at intensity 1
    int64_t triggers_ = 0, events_ = 0, overflows_ = 0, underflows_ = 0;
    double events_expected_ = 0, triggers_expected_ = 0; // so far (event/trigger presets)
    std::function<double()> clock_, intensity_;
    std::vector<double> shape_;    // counts/s per channel
    std::vector<int32_t> counts_;
    Setup setup_;
    bool acquiring_ = false;
    uint64_t starts_ = 0;
    double last_ = 0;              // clock at the last advance
    double real_ = 0, live_ = 0;
    double region_expected_ = 0;   // expected counts in pctl..pcth so far (counts preset)
    std::mt19937_64 rng_;
};

} // namespace beamctl::detector
