// The quad electrometer and the fast loop on it (examples/bpm: src/ioc/quadem.cpp,
// src/detector/quadem.cpp, the simulated beam) in virtual time: quadEM's arithmetic per geometry,
// the spot's height read back through the diode, a mirror jack move seen as PosY, averaging and
// AcquireMode, parameters through the PVs, and the fast EPID loop that rejects the source's
// vibration with the piezo.
#include "core/error.hpp"
#include "detector/quadem.hpp"
#include "virtual_ioc.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using beamctl::test::VirtualIoc;

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;

struct Bpm {
    VirtualIoc v{kSource + "/examples/bpm/ioc.yaml"};
    Bpm() { v.run(300); } // the bus in OP
    ethercat::sim::Plant& plant() { return *v.ioc->plant(0); }
    ethercat::sim::Beam& beam() { return *plant().beam; }
    const double* cells() { return v.ioc->quadem().unit(0).values(); }
    pv::PutStatus put(const std::string& name, double x) {
        pv::Address a;
        if (!v.ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        return v.ioc->database().put(a, pv::Prim::Double, &x, 1);
    }
    // PosY as the example's scale makes it [um] for a spot at height y [mm] (sigma 0.1 mm)
    static double pos_y(double y) { return 125.33 * std::erf(y / (0.1 * std::sqrt(2.0))); }
};

} // namespace

TEST(QuadEm, TheGeometriesAsQuadEmComputesThem) {
    using namespace detector;
    const double raw[4] = {1, 2, 3, 4};
    double v[kQuadEmValues];
    QuadEmParams p;
    p.position_scale[0] = p.position_scale[1] = 10;
    p.position_offset[1] = 1;
    p.current_scale[3] = 2;   // I4 = 8
    p.current_offset[0] = 0.5; // I1 = 0.5
    quadem_compute(raw, p, v); // Square
    EXPECT_DOUBLE_EQ(v[kCurrent1], 0.5);
    EXPECT_DOUBLE_EQ(v[kCurrent4], 8);
    EXPECT_DOUBLE_EQ(v[kSumAll], 13.5);
    EXPECT_DOUBLE_EQ(v[kSumX], 13.5);
    EXPECT_DOUBLE_EQ(v[kDiffX], (2 + 3) - (0.5 + 8));
    EXPECT_DOUBLE_EQ(v[kDiffY], (0.5 + 2) - (3 + 8));
    EXPECT_DOUBLE_EQ(v[kPosX], 10 * (-3.5) / 13.5);
    EXPECT_DOUBLE_EQ(v[kPosY], 10 * (-8.5) / 13.5 - 1);
    p.geometry = QuadEmGeometry::Diamond;
    quadem_compute(raw, p, v);
    EXPECT_DOUBLE_EQ(v[kSumX], 2.5);
    EXPECT_DOUBLE_EQ(v[kSumY], 11);
    EXPECT_DOUBLE_EQ(v[kDiffX], 1.5);
    EXPECT_DOUBLE_EQ(v[kDiffY], 5);
    EXPECT_DOUBLE_EQ(v[kPosX], 10 * 1.5 / 2.5);
    p.geometry = QuadEmGeometry::SquareCC;
    quadem_compute(raw, p, v);
    EXPECT_DOUBLE_EQ(v[kDiffX], (3 + 8) - (0.5 + 2));
    EXPECT_DOUBLE_EQ(v[kDiffY], (0.5 + 8) - (2 + 3));
    // a sum of 0 counts as 1 (no division by zero)
    const double zero[4] = {0, 0, 0, 0};
    p = QuadEmParams{};
    quadem_compute(zero, p, v);
    EXPECT_EQ(v[kPosX], 0);
    EXPECT_EQ(v[kPosY], 0);
}

TEST(QuadEm, AveragesEveryNumAverageSamplesWithTheirStatistics) {
    using namespace detector;
    QuadEmParams p;
    p.num_average = 4;
    QuadEm q(p);
    QuadEmReading r;
    for (int k = 0; k < 7; ++k) {
        const double raw[4] = {double(k), 1, 1, 1};
        q.sample(raw, true, uint64_t(k));
    }
    ASSERT_TRUE(q.pop(r));
    EXPECT_FALSE(q.pop(r) && false);
    EXPECT_EQ(r.n, 4);
    EXPECT_EQ(r.cycle, 3u);
    EXPECT_DOUBLE_EQ(r.mean[kCurrent1], 1.5);                // 0 1 2 3
    EXPECT_NEAR(r.sigma[kCurrent1], std::sqrt(1.25), 1e-12); // population sigma
    EXPECT_EQ(r.min[kCurrent1], 0);
    EXPECT_EQ(r.max[kCurrent1], 3);
    EXPECT_EQ(r.sigma[kCurrent2], 0);
    // an invalid sample (the bus down) drops the partial average: 4, 5, 6 then 7 8 9 10
    const double bad[4] = {100, 0, 0, 0};
    q.sample(bad, false, 7);
    EXPECT_EQ(q.values()[kCurrent1], 6); // the cells keep the last good sample
    for (int k = 7; k < 11; ++k) {
        const double raw[4] = {double(k), 1, 1, 1};
        q.sample(raw, true, uint64_t(k + 1));
    }
    ASSERT_TRUE(q.pop(r));
    EXPECT_DOUBLE_EQ(r.mean[kCurrent1], 8.5);
    EXPECT_FALSE(q.pop(r));
}

TEST(IocQuadEm, PosYReadsTheSpotAndFollowsTheMirrorJack) {
    Bpm b;
    // the spot at y(t) (source vibration and drift): the cell PosY agrees sample by sample within
    // the diode noise (1 mV on 1.25 V a quadrant: ~0.1 um). The sample is two frames old: the
    // plant sets the inputs after frame N, frame N+1 carries them, the cycle reads them after it.
    const double t = b.plant().time();
    EXPECT_NEAR(b.cells()[detector::kPosY], Bpm::pos_y(b.beam().y(t - 0.002)), 0.3);
    EXPECT_NEAR(b.cells()[detector::kSumAll], 1.0, 0.01); // uA: the whole spot on the diode
    // the jack 1 um up: the spot 25 um up
    b.plant().find_stage("MirrorJack")->set_position(0.001);
    b.v.run(10);
    EXPECT_NEAR(b.cells()[detector::kPosY], Bpm::pos_y(b.beam().y(b.plant().time() - 0.002)), 0.3);
    EXPECT_GT(b.cells()[detector::kPosY], 20);
    // the averaged PVs (0.1 s = 100 samples): the mean over the vibration's 0.7 periods
    EXPECT_EQ(b.v.get("BPM:QE1:NumAverage_RBV"), 100);
    EXPECT_DOUBLE_EQ(b.v.get("BPM:QE1:SampleTime_RBV"), 0.001);
    b.v.run(200);
    EXPECT_EQ(b.v.get("BPM:QE1:NumAveraged_RBV"), 100);
    EXPECT_GT(b.v.get("BPM:QE1:PosY:MeanValue_RBV"), 15);
    EXPECT_EQ(b.v.get("BPM:QE1:PositionYAve"), b.v.get("BPM:QE1:PosY:MeanValue_RBV"));
    EXPECT_GT(b.v.get("BPM:QE1:PosY:SigmaValue_RBV"), 1); // the 10 um vibration
    EXPECT_LE(b.v.get("BPM:QE1:PosY:MinValue_RBV"), b.v.get("BPM:QE1:PosY:MeanValue_RBV"));
    EXPECT_GE(b.v.get("BPM:QE1:PosY:MaxValue_RBV"), b.v.get("BPM:QE1:PosY:MeanValue_RBV"));
    EXPECT_NEAR(b.v.get("BPM:QE1:SumAll:MeanValue_RBV"), 1.0, 0.01);
}

TEST(IocQuadEm, AcquireModesAndParameters) {
    Bpm b;
    EXPECT_EQ(b.v.get("BPM:QE1:Acquire"), 1); // acquires from the start, continuously
    b.v.run(1000);
    EXPECT_GE(b.v.get("BPM:QE1:NumAcquired"), 9);
    // Single: one reading, then Acquire goes back to Done
    ASSERT_EQ(b.put("BPM:QE1:Acquire", 0), pv::PutStatus::Ok);
    ASSERT_EQ(b.put("BPM:QE1:AcquireMode", 2), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get("BPM:QE1:AcquireMode_RBV"), 2);
    ASSERT_EQ(b.put("BPM:QE1:Acquire", 1), pv::PutStatus::Ok);
    b.v.run(500);
    EXPECT_EQ(b.v.get("BPM:QE1:NumAcquired"), 1);
    EXPECT_EQ(b.v.get("BPM:QE1:Acquire"), 0);
    // Multiple: NumAcquire readings of AveragingTime 0.02 s (20 samples)
    ASSERT_EQ(b.put("BPM:QE1:AveragingTime", 0.02), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get("BPM:QE1:NumAverage_RBV"), 20);
    EXPECT_DOUBLE_EQ(b.v.get("BPM:QE1:AveragingTime_RBV"), 0.02);
    ASSERT_EQ(b.put("BPM:QE1:AcquireMode", 1), pv::PutStatus::Ok);
    ASSERT_EQ(b.put("BPM:QE1:NumAcquire", 5), pv::PutStatus::Ok);
    ASSERT_EQ(b.put("BPM:QE1:Acquire", 1), pv::PutStatus::Ok);
    b.v.run(1000);
    EXPECT_EQ(b.v.get("BPM:QE1:NumAcquired"), 5);
    EXPECT_EQ(b.v.get("BPM:QE1:NumAveraged_RBV"), 20);
    EXPECT_EQ(b.v.get("BPM:QE1:Acquire"), 0);
    // an offset and the geometry take effect on the next sample
    ASSERT_EQ(b.put("BPM:QE1:PositionOffsetY", 1000), pv::PutStatus::Ok);
    b.v.run(10);
    EXPECT_LT(b.cells()[detector::kPosY], -800);
    ASSERT_EQ(b.put("BPM:QE1:Geometry", 0), pv::PutStatus::Ok); // Diamond: SumX = I1 + I2
    b.v.run(10);
    EXPECT_EQ(b.v.get("BPM:QE1:Geometry_RBV"), 0);
    EXPECT_NEAR(b.cells()[detector::kSumX], b.cells()[detector::kCurrent1] + b.cells()[detector::kCurrent2], 1e-12);
    // refused: a negative averaging time, a geometry past the menu, readbacks
    EXPECT_NE(b.put("BPM:QE1:AveragingTime", -1), pv::PutStatus::Ok);
    EXPECT_DOUBLE_EQ(b.v.get("BPM:QE1:AveragingTime"), 0.02);
    EXPECT_NE(b.put("BPM:QE1:Geometry", 7), pv::PutStatus::Ok);
    EXPECT_NE(b.put("BPM:QE1:PosY:MeanValue_RBV", 1), pv::PutStatus::Ok);
}

TEST(IocQuadEm, TheTimeSeriesHoldsEverySampleAveraged) {
    Bpm b;
    const std::string ts = "BPM:QE1:TS:";
    EXPECT_EQ(b.v.get(ts + "TSNumPoints"), 1000); // quadEM's TSPOINTS
    EXPECT_EQ(b.v.get(ts + "TSTimePerPoint_RBV"), 0.001);
    // 200 points of 10 samples: 2 s, 14 periods of the source's 7 Hz vibration
    ASSERT_EQ(b.put(ts + "TSNumPoints", 200), pv::PutStatus::Ok);
    ASSERT_EQ(b.put(ts + "TSAveragingTime", 0.01), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get(ts + "TSNumAverage"), 10);
    EXPECT_DOUBLE_EQ(b.v.get(ts + "TSAveragingTime_RBV"), 0.01);
    int done = 0;
    pv::Address a;
    ASSERT_TRUE(b.v.ioc->database().resolve(ts + "TSAcquire", a));
    const double one = 1;
    ASSERT_EQ(b.v.ioc->database().put(a, pv::Prim::Double, &one, 1, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get(ts + "TSAcquiring"), 1);
    EXPECT_NE(b.put(ts + "TSNumPoints", 100), pv::PutStatus::Ok); // not while acquiring
    b.v.run(1000);
    EXPECT_EQ(done, 0);
    EXPECT_NEAR(b.v.get(ts + "TSCurrentPoint"), 100, 2);
    b.v.run(1100);
    EXPECT_EQ(done, 1); // Fixed length: done with the last point
    EXPECT_EQ(b.v.get(ts + "TSAcquiring"), 0);
    EXPECT_EQ(b.v.get(ts + "TSCurrentPoint"), 200);
    EXPECT_DOUBLE_EQ(b.v.get(ts + "TSElapsedTime"), 2.0);
    EXPECT_DOUBLE_EQ(b.v.get(ts + "TSTimeAxis", 1), 0.01);
    pv::Record* series = b.v.ioc->database().find(ts + "PosY:TimeSeries");
    ASSERT_EQ(series->elements(*series->type().find("VAL")).count, 200u);
    // PosY over whole periods: the vibration's 10 um amplitude is 7.1 um rms (10 ms means: 0.8 % less)
    double mean = 0, sq = 0, lo = 1e9, hi = -1e9;
    for (uint32_t i = 0; i < 200; ++i) {
        const double y = b.v.get(ts + "PosY:TimeSeries", i);
        mean += y / 200, sq += y * y / 200, lo = std::min(lo, y), hi = std::max(hi, y);
    }
    EXPECT_NEAR(std::sqrt(sq - mean * mean), 7.07, 0.3);
    EXPECT_NEAR((hi - lo) / 2, 10, 0.6); // the amplitude, around the drift's 0.5 um/s
    EXPECT_NEAR(mean, 0, 2);
    EXPECT_NEAR(b.v.get(ts + "SumAll:TimeSeries", 17), 1.0, 0.01);
    // Circ. buffer: runs until TSAcquire 0, the latest 200 points oldest first
    ASSERT_EQ(b.put(ts + "TSAcquireMode", 1), pv::PutStatus::Ok);
    ASSERT_EQ(b.put(ts + "TSAcquire", 1), pv::PutStatus::Ok);
    b.v.run(3000);
    EXPECT_EQ(b.v.get(ts + "TSAcquiring"), 1);
    EXPECT_EQ(b.v.get(ts + "TSCurrentPoint"), 200);
    ASSERT_EQ(b.put(ts + "TSAcquire", 0), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get(ts + "TSAcquiring"), 0);
    const double t_last = b.v.get(ts + "TSTimestamp", 199), t_first = b.v.get(ts + "TSTimestamp", 0);
    EXPECT_NEAR(t_last - t_first, 1.99, 1e-6);
}

TEST(IocQuadEm, TheFastLoopRejectsTheSourceVibration) {
    Bpm b;
    // residual of PosY over 2 s (14 periods of the 7 Hz vibration), loop off and on
    auto rms = [&] {
        double s2 = 0;
        const int n = 2000;
        for (int k = 0; k < n; ++k) {
            b.v.cycles(1);
            const double y = b.cells()[detector::kPosY];
            s2 += y * y;
        }
        return std::sqrt(s2 / n);
    };
    const double open = rms();
    EXPECT_GT(open, 5); // 10 um amplitude plus the drift: ~7 um rms
    ASSERT_EQ(b.put("BPM:epidFast1.FBON", 1), pv::PutStatus::Ok);
    b.v.ioc->database().process(*b.v.ioc->database().find("BPM:epidFast1"));
    b.v.run(500); // settle
    const double closed = rms();
    EXPECT_LT(closed, open / 4) << "open " << open << " um rms, closed " << closed << " um rms";
    std::printf("PosY residual: %.3f um rms open, %.3f um rms closed (factor %.1f)\n", open, closed, open / closed);
}

TEST(IocQuadEm, TheDemoBeamPassesTheSlitAndTheMirrorPitchesIt) {
    VirtualIoc v(kSource + "/examples/demo/ioc.yaml");
    v.run(300);
    ethercat::sim::Plant& plant = *v.ioc->plant(0);
    const double* qe = v.ioc->quadem().unit(0).values();
    EXPECT_NEAR(qe[detector::kSumAll], 1.0, 0.01); // the slit (blades at 6, -4, -7, 3 mm) passes it all
    // the fluorescence detector's sample sees the same beam: DEMO:mca1's lines and background at
    // their configured rates through the open slit
    const detector::SimMca& mca = v.ioc->detectors().mca(0);
    EXPECT_NEAR(mca.input_rate(), 8000 + 1100 + 5000 + 700 + 50, 15);
    // the downstream vertical jack (s24) 1 um down: the mirror pitches up, the spot ~24 um up
    const double at = 1.0; // the spot's height at a fixed time, before and after
    const double y0 = plant.beam->y(at);
    plant.find_stage("s24")->set_position(-0.001);
    v.run(10);
    EXPECT_NEAR(plant.beam->y(at) - y0, 0.024333, 1e-6); // 2 D theta - 2/3 of the jack's 1 um
    EXPECT_NEAR(qe[detector::kPosY], 125.33 * std::erf(plant.beam->y(plant.time() - 0.002) / (0.1 * std::sqrt(2.0))), 0.3);
    EXPECT_GT(qe[detector::kPosY], 5); // up, whatever the vibration (+-10 um) does
    // the top blade below the beam: no light
    plant.find_stage("SlitTop")->set_position(-1);
    v.run(10);
    EXPECT_NEAR(qe[detector::kSumAll], 0, 0.001);
    EXPECT_NEAR(mca.input_rate(), 0, 1); // and no fluorescence
    // the top blade at the spot's centre: half of it
    plant.find_stage("SlitTop")->set_position(plant.beam->y(plant.time()));
    v.run(2);
    EXPECT_NEAR(mca.input_rate() / 14850, 0.5, 0.05);
}

TEST(IocQuadEm, TheRangeSaturatesTheCurrents) {
    Bpm b;
    EXPECT_EQ(b.v.get("BPM:QE1:Range_RBV"), 0); // +-2 uA: the whole spot (1 uA) reads as it is
    b.v.run(200);
    EXPECT_NEAR(b.v.get("BPM:QE1:SumAll:MeanValue_RBV"), 1.0, 0.01);
    const double i1 = b.v.get("BPM:QE1:Current1:MeanValue_RBV");
    EXPECT_GT(i1, 0.2); // a quadrant's share is above the small range
    ASSERT_EQ(b.put("BPM:QE1:Range", 1), pv::PutStatus::Ok); // +-200 nA
    EXPECT_EQ(b.v.get("BPM:QE1:Range_RBV"), 1);
    b.v.run(300);
    EXPECT_DOUBLE_EQ(b.v.get("BPM:QE1:Current1:MaxValue_RBV"), 0.2); // saturated
    EXPECT_DOUBLE_EQ(b.cells()[detector::kCurrent1], 0.2);
    EXPECT_LT(b.v.get("BPM:QE1:SumAll:MeanValue_RBV"), 0.81);
    // a range that is not one of the choices: refused, nothing changes
    EXPECT_NE(b.put("BPM:QE1:Range", 2), pv::PutStatus::Ok);
    EXPECT_EQ(b.v.get("BPM:QE1:Range_RBV"), 1);
}
