// The simulated beam behind the terminals, in virtual time (1 ms cycles): a quadrant diode on four
// EL3104 inputs sees the spot move with a stage lever and with an analog output (a piezo), the
// slit's blades clip it, the source's vibration shows at its frequency, and errors name their place.
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/beam.hpp"
#include "ethercat/sim/sim_config.hpp"

#include "sim_bus.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using namespace beamctl::ethercat;

namespace {

using simbus::PlantBus;

// A spot of sigma 0.5 mm on a quadrant diode: 2 V per flux unit on each EL3104 input, the whole
// beam on a fifth (EL3102) channel; a jack (stage j) and a piezo voltage (EL4134 output 1) move it.
const char* kBeamline = R"(
slaves:
  - {position: 0, type: EK1100}
  - {position: 1, type: EL3104}
  - {position: 2, type: EL3102}
  - {position: 3, type: EL7041}
  - {position: 4, type: EL7041}
  - {position: 5, type: EL7041}
  - {position: 6, type: EL4134}
stages:
  - {name: j, drive: s3, start: 0}
  - {name: top, drive: s4, start: 5}
  - {name: bottom, drive: s5, start: -5}
beam:
  flux: 4
  size: [0.5, 0.5]
  optics:
    - {stage: j, y: 0.25}            # 0.25 mm at the diode per mm of jack
    - {output: s6.analogOutput01, x: 0.1}   # 0.1 mm per volt
  slit: {top: top, bottom: bottom}
signals:
  - {to: s1.analogInput01, beam: 1, gain: 2}
  - {to: s1.analogInput02, beam: 2, gain: 2}
  - {to: s1.analogInput03, beam: 3, gain: 2}
  - {to: s1.analogInput04, beam: 4, gain: 2}
  - {to: s2.analogInput01, beam: 0, gain: 2}
)";

struct Quad {
    double i[5]; // volts: [0] the whole beam, [1..4] the quadrants
    double diff_x() const { return (i[2] + i[3]) - (i[1] + i[4]); }
    double diff_y() const { return (i[1] + i[2]) - (i[3] + i[4]); }
    double sum() const { return i[1] + i[2] + i[3] + i[4]; }
};

Quad read(PlantBus& b) {
    Quad q;
    q.i[0] = double(b.get_signed("ec0.s2.analogInput01")) / 3276.7;
    for (int k = 1; k <= 4; ++k) q.i[k] = double(b.get_signed("ec0.s1.analogInput0" + std::to_string(k))) / 3276.7;
    return q;
}

} // namespace

TEST(Beam, TheQuadrantsSplitTheSpotAsTheErrorFunctionSays) {
    sim::BeamParams p;
    p.flux = 1, p.sigma_x = 0.5, p.sigma_y = 0.5;
    sim::Beam beam(p);
    // centred: a quarter each, the whole beam on diode 0
    for (int k = 1; k <= 4; ++k) EXPECT_NEAR(beam.diode_at(k, 0, 0), 0.25, 1e-12) << k;
    EXPECT_NEAR(beam.diode_at(0, 0, 0), 1, 1e-12);
    // one sigma to the right and up: P(X > -0.5 | mu 0, s 0.5) = Phi(1) = 0.8413
    const double phi1 = 0.5 * std::erfc(-1 / std::sqrt(2.0));
    EXPECT_NEAR(beam.diode_at(2, 0.5, 0.5), phi1 * phi1, 1e-12);       // +x +y
    EXPECT_NEAR(beam.diode_at(4, 0.5, 0.5), (1 - phi1) * (1 - phi1), 1e-12); // -x -y
    EXPECT_NEAR(beam.diode_at(1, 0.5, 0.5) + beam.diode_at(2, 0.5, 0.5) + beam.diode_at(3, 0.5, 0.5) +
                    beam.diode_at(4, 0.5, 0.5), 1, 1e-12);
}

TEST(Beam, AJackAndAPiezoMoveTheSpotOnTheQuadrantDiode) {
    PlantBus b(kBeamline);
    b.cycles(20);
    Quad q = read(b);
    EXPECT_NEAR(q.i[0], 8, 0.01);     // flux 4, 2 V per unit: the slit (+-5 mm) passes it all
    EXPECT_NEAR(q.sum(), 8, 0.01);
    EXPECT_NEAR(q.diff_x(), 0, 0.01); // centred
    EXPECT_NEAR(q.diff_y(), 0, 0.01);
    // the jack 0.4 mm up: the spot 0.1 mm up, DiffY/Sum = erf(0.1 / (0.5 sqrt 2))
    b.plant->find_stage("j")->set_position(0.4);
    b.cycles(2);
    q = read(b);
    EXPECT_NEAR(q.diff_y() / q.sum(), std::erf(0.1 / (0.5 * std::sqrt(2.0))), 0.002);
    EXPECT_NEAR(q.diff_x() / q.sum(), 0, 0.002);
    // the piezo at -2 V: the spot 0.2 mm to -x
    b.set("ec0.s6.analogOutput01", uint64_t(int64_t(-6553)));
    b.cycles(3);
    q = read(b);
    EXPECT_NEAR(q.diff_x() / q.sum(), -std::erf(0.2 / (0.5 * std::sqrt(2.0))), 0.002);
    EXPECT_NEAR(q.sum(), 8, 0.01); // moving does not lose flux
}

TEST(Beam, TheSlitBladesClipTheBeam) {
    PlantBus b(kBeamline);
    b.cycles(20);
    // the top blade down to the centre: half the beam passes, and none of it on the upper quadrants
    b.plant->find_stage("top")->set_position(0);
    b.cycles(2);
    Quad q = read(b);
    EXPECT_NEAR(q.i[0], 4, 0.01);
    EXPECT_NEAR(q.i[1] + q.i[2], 0, 0.001);
    EXPECT_NEAR(q.sum(), 4, 0.01);
    // closed (the blades cross): nothing
    b.plant->find_stage("bottom")->set_position(1);
    b.cycles(2);
    EXPECT_NEAR(read(b).i[0], 0, 0.001);
    EXPECT_NEAR(b.plant->beam->transmission(b.plant->time()), 0, 1e-12);
}

TEST(Beam, TheSourceVibratesAndDrifts) {
    std::string yaml = kBeamline;
    yaml.replace(yaml.find("  size: [0.5, 0.5]"), 18, "  size: [0.5, 0.5]\n  vibration: {amplitude: [0, 0.05], frequency: 10}\n  drift: [0.01, 0]");
    PlantBus b(yaml);
    b.cycles(1);
    // DiffY/Sum over one period of the 10 Hz vibration (100 cycles): its extremes a quarter period
    // apart from its zeros, and the x drift of 0.01 mm/s adds 1 um per 100 ms
    double lo = 1, hi = -1, mean = 0;
    for (int k = 0; k < 100; ++k) {
        b.cycles(1);
        Quad q = read(b);
        double r = q.diff_y() / q.sum();
        lo = std::min(lo, r), hi = std::max(hi, r), mean += r / 100;
    }
    const double peak = std::erf(0.05 / (0.5 * std::sqrt(2.0)));
    EXPECT_NEAR(hi, peak, 0.003);
    EXPECT_NEAR(lo, -peak, 0.003);
    EXPECT_NEAR(mean, 0, 0.003);
    sim::Beam& beam = *b.plant->beam;
    const double t = b.plant->time();
    EXPECT_NEAR(beam.x(t), 0.01 * t, 1e-12);
    EXPECT_NEAR(beam.y(t), 0.05 * std::sin(2 * M_PI * 10 * t), 1e-12);
}

TEST(Beam, ConfigurationErrorsNameTheirPlace) {
    auto error = [](const std::string& yaml) -> std::string {
        try {
            sim::SimConfig::parse(yaml, "plant.yaml", Catalog::builtin());
        } catch (const Error& e) {
            return e.what();
        }
        return "(no error)";
    };
    const std::string slaves = "slaves:\n  - {position: 0, type: EL3104}\n  - {position: 1, type: EL7041}\n  - {position: 2, type: EL4134}\n";
    auto has = [](const std::string& e, const std::string& part) { return e.find(part) != std::string::npos; };
    std::string e = error(slaves + "signals:\n  - {to: s0.analogInput01, beam: 1}\n");
    EXPECT_TRUE(has(e, "plant.yaml:6:") && has(e, "needs the plant's beam: section")) << e;
    e = error(slaves + "beam: {flux: 1}\nsignals:\n  - {to: s0.analogInput01, beam: 5}\n");
    EXPECT_TRUE(has(e, "plant.yaml:7:") && has(e, "beam should be from 0 to 4")) << e;
    e = error(slaves + "beam: {optics: [{stage: nope, y: 1}]}\n");
    EXPECT_TRUE(has(e, "plant.yaml:5:") && has(e, "beam lever: no stage named 'nope'")) << e;
    e = error(slaves + "beam: {optics: [{output: s0.analogInput01, y: 1}]}\n");
    EXPECT_TRUE(has(e, "is not a 16-bit analog output")) << e;
    e = error(slaves + "beam: {optics: [{stage: s1, output: s2.analogOutput01}]}\n");
    EXPECT_TRUE(has(e, "one of them")) << e;
    e = error(slaves + "beam: {size: [0, 1]}\n");
    EXPECT_TRUE(has(e, "plant.yaml:5:") && has(e, "beam.size[0] should be > 0")) << e;
    e = error(slaves + "beam: {slit: {top: nope}}\n");
    EXPECT_TRUE(has(e, "slit top: no stage named 'nope'")) << e;
    e = error(slaves + "beam: {colour: red}\n");
    EXPECT_TRUE(has(e, "unknown key 'colour'")) << e;
    // a working one: the default stage of s1 is a lever
    EXPECT_EQ(error(slaves + "beam: {optics: [{stage: s1, y: 1}, {output: s2.analogOutput01, x: 0.1}]}\nsignals:\n  - {to: s0.analogInput01, beam: 2}\n"), "(no error)");
}

TEST(Beam, TheTallyIntegratesAnExposure) {
    // a camera's exposure over whole periods of the vibration: the mean centre is where the source
    // rests, the centre's variance is the sine's A^2 / 2, the transmission the slit's mean
    std::string yaml = kBeamline;
    yaml.replace(yaml.find("  size: [0.5, 0.5]"), 18, "  size: [0.5, 0.5]\n  vibration: {amplitude: [0, 0.05], frequency: 10}");
    PlantBus b(yaml);
    b.cycles(1);
    sim::Beam& beam = *b.plant->beam;
    const sim::BeamTally t0 = beam.tally();
    b.cycles(200); // 0.2 s: two periods
    const sim::BeamTally t1 = beam.tally();
    const sim::BeamExposure e = sim::exposure(t0, t1);
    EXPECT_NEAR(e.seconds, 0.2, 1e-9);
    EXPECT_NEAR(e.x, 0, 1e-9);
    EXPECT_NEAR(e.y, 0, 1e-4);
    EXPECT_NEAR(e.var_y, 0.05 * 0.05 / 2, 2e-6);
    EXPECT_NEAR(e.var_x, 0, 1e-12);
    EXPECT_NEAR(e.sigma_x, 0.5, 1e-12);
    EXPECT_NEAR(e.flux, 4, 1e-12);
    EXPECT_EQ(e.top, 5);
    EXPECT_EQ(e.bottom, -5);
    EXPECT_NEAR(e.transmission, beam.transmission(b.plant->time()), 1e-3);
    // the top blade moved down to the centre: half the beam
    b.plant->find_stage("top")->set_position(0);
    b.cycles(1);
    const sim::BeamTally t2 = beam.tally();
    b.cycles(100);
    const sim::BeamExposure h = sim::exposure(t2, beam.tally());
    EXPECT_NEAR(h.transmission, 0.5, 0.02);
    EXPECT_EQ(h.top, 0);
    // no time between two tallies: the latest centre, no spread
    const sim::BeamExposure z = sim::exposure(t2, t2);
    EXPECT_EQ(z.seconds, 0);
    EXPECT_EQ(z.var_y, 0);
    EXPECT_EQ(z.y, t2.y);
}
