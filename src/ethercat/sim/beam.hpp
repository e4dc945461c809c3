// A photon beam at one monitor plane, for the detectors behind the simulated terminals: a Gaussian
// spot whose centre the optics move (linear lever arms on stage positions and analog outputs: a
// mirror's jacks, a piezo), the source shakes (a sine vibration) and drifts (a constant rate), and
// a slit's four blades clip (the fraction of the spot inside the aperture passes). A quadrant diode
// centred on the monitor's origin reads it in quadEM's Square layout:
//     1 | 2        1 (-x, +y)  2 (+x, +y)
//     --+--   y^   4 (-x, -y)  3 (+x, -y)
//     4 | 3    +>x
// Diode 0 is a plain diode under the whole transmitted beam. The slit is taken to sit at the
// monitor plane (same coordinates, same spot). Units: mm, s, volts; the flux is in the unit the
// signals' gain turns into volts (e.g. uA of photocurrent, gain in V/uA).
// Threading: update() and the readings on the segment's thread (Plant::step); no allocation.
// tally() on one other thread (the IOC loop's detectors).
#pragma once

#include "core/triple_buffer.hpp"
#include "ethercat/sim/io_point.hpp"

#include <array>
#include <vector>

namespace beamctl::ethercat::sim {

class Segment;
class Stage;

struct BeamParams {
    double flux = 1;                    // diode current with the whole spot on the diode
    double x0 = 0, y0 = 0;              // spot centre with every lever at 0 [mm]
    double sigma_x = 0.2, sigma_y = 0.2; // Gaussian spot size [mm]
    double vibration_x = 0, vibration_y = 0; // sine amplitude of the source motion [mm]
    double vibration_hz = 0;
    double drift_x = 0, drift_y = 0;    // [mm/s], from the first frame on
};

// The spot moves by (x, y) [mm] per unit of a stage's position or per volt of an analog output.
struct BeamLever {
    const Stage* stage = nullptr;
    IoPoint output;               // a 16-bit analog output (EL4xxx): read as volts
    double volts_per_digit = 0;   // full scale / 32767
    double x = 0, y = 0;
};

// What a detector that integrates the beam (a camera, a spectrometer's sample) needs: running
// sums over the simulated time of the spot's centre and transmission, so that the difference of
// two tallies is an exposure (mean centre, its spread, mean transmission), plus the spot size and
// the slit's aperture at the latest step (mm; +-infinity for an open side).
struct BeamTally {
    double t = 0;              // simulated time of the latest step [s]
    double w = 0;              // the sums' weight: simulated seconds summed
    double sx = 0, sxx = 0;    // integral of x dt, x^2 dt [mm s, mm^2 s]
    double sy = 0, syy = 0;
    double st = 0;             // integral of the transmission dt [s]
    double x = 0, y = 0, transmission = 0; // at the latest step
    double sigma_x = 0, sigma_y = 0, flux = 0;
    double left = 0, right = 0, bottom = 0, top = 0;
};

// The mean of a tally difference `b - a` (an exposure from a to b).
struct BeamExposure {
    double seconds = 0;
    double x = 0, y = 0;              // mean centre [mm]
    double var_x = 0, var_y = 0;      // the centre's variance over the exposure [mm^2]
    double transmission = 0;          // mean fraction through the slit
    double sigma_x = 0, sigma_y = 0, flux = 0;
    double left = 0, right = 0, bottom = 0, top = 0;
};
BeamExposure exposure(const BeamTally& a, const BeamTally& b) noexcept;

class Beam {
public:
    explicit Beam(BeamParams p) : p_(p) {}
    BeamParams& params() { return p_; }
    std::vector<BeamLever> levers;
    const Stage* top = nullptr; // slit blades (nullptr: that side open); the aperture is
    const Stage* bottom = nullptr; //   bottom <= y <= top and left <= x <= right
    const Stage* left = nullptr;
    const Stage* right = nullptr;

    // Reads the optics (after the stages moved this step) and adds the step [t - dt, t] to the
    // published tally.
    void update(Segment& seg, double t, double dt) noexcept;
    // Any ONE other thread: the latest tally (its sums since the first step).
    BeamTally tally() noexcept;
    // The spot centre at simulated time t [s].
    double x(double t) const noexcept;
    double y(double t) const noexcept;
    // The fraction of the spot the slit lets through, at time t.
    double transmission(double t) const noexcept;
    // Current of diode 0 (the whole transmitted beam) or of quadrant 1..4, at time t.
    double diode(int which, double t) const noexcept;
    // The same from a given centre (tests).
    double diode_at(int which, double cx, double cy) const noexcept;

private:
    BeamParams p_;
    double dx_ = 0, dy_ = 0; // the optics' displacement of the spot [mm]
    BeamTally sum_;          // the segment thread's running sums
    TripleBuffer<BeamTally> published_;
};

} // namespace beamctl::ethercat::sim
