// The mca record (src/detector/mca_record.cpp) over a fake device and over the simulated detector
// (src/detector/sim_mca.cpp) in virtual time: ROI arithmetic as mcaRecord.c's sum_ROIs, presets
// that end the acquisition with ERTM/ELTM right, a put-callback on ERST that completes when the
// acquisition ends, erase, Poisson statistics and dead time.
#include "detector/mca_record.hpp"
#include "detector/sim_mca.hpp"

#include "../pv/db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

using namespace beamctl;
using namespace beamctl::detector;

namespace {

// A device holding a fixed spectrum; acquisition ends at the next status read after stop().
struct FakeMca : McaDevice {
    std::vector<int32_t> spectrum;
    bool acquiring = false;
    int starts = 0, erases = 0;
    Setup last;
    bool setup(const Setup& s) override { last = s; return true; }
    bool start() override { acquiring = true; ++starts; return true; }
    bool stop() override { acquiring = false; return true; }
    bool erase() override { ++erases; return true; }
    bool status(Status& s) override { s.acquiring = acquiring; return true; }
    uint32_t read(int32_t* d, uint32_t n) override {
        const uint32_t m = std::min<uint32_t>(n, uint32_t(spectrum.size()));
        std::copy(spectrum.begin(), spectrum.begin() + m, d);
        return m;
    }
    std::string describe() const override { return "fake"; }
};

struct McaTest : pv::DbTest {
    double now = 0;
    void SetUp() override {
        register_detector_records(pv::RecordTypes::global());
        db.set_clock([this] { return now; });
    }
    void attach(McaDevice& d) {
        ASSERT_TRUE(set_mca_device(*db.find("mca1"), &d));
    }
    void process() { db.process(*db.find("mca1")); }
    std::vector<int32_t> val() {
        pv::Address a = addr("mca1");
        std::vector<int32_t> v(a.count);
        db.get(a, pv::Prim::Long, v.data(), a.count);
        return v;
    }
};

const char* kMca = R"(record(mca, "mca1") { field(NMAX, "64") field(NUSE, "64") field(PREC, "2") })";

} // namespace

TEST_F(McaTest, RoisSumTotalAndNetOverAStraightBackground) {
    load(kMca);
    FakeMca dev;
    dev.spectrum.assign(64, 10);
    for (int i = 20; i <= 30; ++i) dev.spectrum[std::size_t(i)] = 10 + 5 * (i - 19); // a ramp on a background of 10
    dev.spectrum[40] = 100;                                                         // a maximum elsewhere
    attach(dev);
    ASSERT_EQ(put("mca1.R0LO", 18), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0HI", 32), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0BG", 1), pv::PutStatus::Ok);
    ASSERT_EQ(put_str("mca1.R0NM", "peak"), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R1LO", 5), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R1HI", 9), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R1BG", -1), pv::PutStatus::Ok); // no background
    ASSERT_EQ(put("mca1.READ", 1), pv::PutStatus::Ok);
    EXPECT_EQ(getd("mca1.NORD"), 64);
    double total = 0;
    for (int i = 18; i <= 32; ++i) total += dev.spectrum[std::size_t(i)];
    EXPECT_EQ(getd("mca1.R0"), total);
    // bg_lo = mean(data[17..19]) = 10, bg_hi = mean(data[31..33]) = 10: net = total - 15 * 10
    EXPECT_EQ(getd("mca1.R0N"), total - 150);
    EXPECT_EQ(gets("mca1.R0NM"), "peak");
    EXPECT_EQ(getd("mca1.R1"), 50);
    EXPECT_EQ(getd("mca1.R1N"), 50);
    EXPECT_EQ(getd("mca1.R2"), 0); // LO = HI = -1: no ROI
    // BG: the background line inside the ROI, its end channels at the spectrum's maximum
    pv::Address b = addr("mca1.BG");
    std::vector<int32_t> bg(b.count);
    db.get(b, pv::Prim::Long, bg.data(), b.count);
    EXPECT_EQ(bg[18], 100);
    EXPECT_EQ(bg[25], 10);
    EXPECT_EQ(bg[32], 100);
    // HI beyond the data is clipped to the last channel
    ASSERT_EQ(put("mca1.R1HI", 1000), pv::PutStatus::Ok);
    EXPECT_EQ(getd("mca1.R1"), std::accumulate(dev.spectrum.begin() + 5, dev.spectrum.end(), 0.0));
}

TEST_F(McaTest, AReadOnlyWhenAcquisitionEndsAndEraseZeroes) {
    load(kMca);
    FakeMca dev;
    dev.spectrum.assign(64, 3);
    attach(dev);
    ASSERT_EQ(put("mca1.STRT", 1), pv::PutStatus::Ok);
    EXPECT_EQ(dev.starts, 1);
    EXPECT_EQ(getd("mca1.ACQG"), 1);
    EXPECT_EQ(getd("mca1.NORD"), 0); // not read while acquiring
    dev.acquiring = false;
    process();
    EXPECT_EQ(getd("mca1.ACQG"), 0);
    EXPECT_EQ(getd("mca1.NORD"), 64);
    EXPECT_EQ(val()[10], 3);
    ASSERT_EQ(put("mca1.ERAS", 1), pv::PutStatus::Ok);
    EXPECT_EQ(dev.erases, 1);
    EXPECT_EQ(getd("mca1.ERAS"), 0);
    EXPECT_EQ(getd("mca1.NORD"), 0);
    EXPECT_EQ(val()[0], 0);
}

TEST_F(McaTest, APutCallbackOnEraseStartCompletesWhenTheAcquisitionEnds) {
    load(kMca);
    FakeMca dev;
    dev.spectrum.assign(64, 1);
    attach(dev);
    bool done = false;
    ASSERT_EQ(put("mca1.ERST", 1, [&](pv::PutStatus) { done = true; }), pv::PutStatus::Ok);
    EXPECT_FALSE(done);
    process(); // a status scan while acquiring
    EXPECT_FALSE(done);
    dev.acquiring = false;
    process();
    EXPECT_TRUE(done);
    EXPECT_EQ(getd("mca1.NORD"), 64);
}

TEST_F(McaTest, PresetRealTimeEndsTheAcquisitionExactly) {
    load(kMca);
    SimMcaConfig c;
    c.channels = 64;
    c.cals = 0.2;
    c.lines = {{"line", 6.4, 20000, 0.4}};
    c.background = 640;
    c.dead_time = 5e-6;
    SimMca dev(c, [this] { return now; });
    attach(dev);
    ASSERT_EQ(put("mca1.PRTM", 2.0), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.ERST", 1), pv::PutStatus::Ok);
    for (int k = 0; k < 25 && getd("mca1.ACQG") == 1; ++k) {
        now += 0.1;
        process();
    }
    EXPECT_EQ(getd("mca1.ACQG"), 0);
    EXPECT_DOUBLE_EQ(getd("mca1.ERTM"), 2.0);
    const double rate = dev.input_rate(); // 20640 counts/s
    EXPECT_NEAR(rate, 20640, 1);
    EXPECT_NEAR(getd("mca1.ELTM"), 2.0 / (1 + rate * 5e-6), 1e-9);
    EXPECT_NEAR(getd("mca1.DTIM"), 100.0 * (1 - 1 / (1 + rate * 5e-6)), 1e-6);
    // the counts: Poisson around the expected number, and the line where its energy says
    const std::vector<int32_t> v = val();
    const double counts = std::accumulate(v.begin(), v.end(), 0.0);
    const double expected = rate * getd("mca1.ELTM");
    EXPECT_NEAR(counts, expected, 5 * std::sqrt(expected));
    EXPECT_EQ(std::max_element(v.begin(), v.end()) - v.begin(), 32); // 6.4 keV / 0.2 keV
    EXPECT_EQ(getd("mca1.ACT"), counts);
    // an ROI over the line holds its counts
    ASSERT_EQ(put("mca1.R0LO", 28), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0HI", 36), pv::PutStatus::Ok);
    EXPECT_EQ(getd("mca1.R0"), std::accumulate(v.begin() + 28, v.begin() + 37, 0.0));
    EXPECT_NEAR(getd("mca1.R0N"), 20000 * getd("mca1.ELTM"), 5 * std::sqrt(20000 * 2.0) + 9 * 20);
}

TEST_F(McaTest, PresetLiveTimeAndAnRoiPreset) {
    load(kMca);
    SimMcaConfig c;
    c.channels = 64;
    c.cals = 0.2;
    c.lines = {{"line", 6.4, 50000, 0.4}};
    c.dead_time = 1e-5; // 33 % dead
    SimMca dev(c, [this] { return now; });
    attach(dev);
    ASSERT_EQ(put("mca1.PLTM", 1.0), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.ERST", 1), pv::PutStatus::Ok);
    for (int k = 0; k < 40 && getd("mca1.ACQG") == 1; ++k) {
        now += 0.1;
        process();
    }
    EXPECT_EQ(getd("mca1.ACQG"), 0);
    EXPECT_DOUBLE_EQ(getd("mca1.ELTM"), 1.0);
    EXPECT_NEAR(getd("mca1.ERTM"), 1.0 + 50050 * 1e-5, 1e-3); // real = live * (1 + R tau)
    // an ROI preset: stops once the net counts reach it (read at the next status)
    ASSERT_EQ(put("mca1.PLTM", 0), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0LO", 28), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0HI", 36), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0BG", -1), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0P", 5000), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.R0IP", 1), pv::PutStatus::Ok);
    ASSERT_EQ(put("mca1.READ", 1), pv::PutStatus::Ok); // ROIs only sum what was read
    ASSERT_EQ(put("mca1.ERST", 1), pv::PutStatus::Ok);
    int k = 0;
    for (; k < 100 && getd("mca1.ACQG") == 1; ++k) {
        now += 0.02;
        process();
        ASSERT_EQ(put("mca1.READ", 1), pv::PutStatus::Ok); // mca.db's Read record while acquiring
    }
    EXPECT_EQ(getd("mca1.ACQG"), 0);
    EXPECT_GE(getd("mca1.R0N"), 5000);
    EXPECT_LT(getd("mca1.ERTM"), 0.5); // ~33 000 counts/s in the ROI: well before the 2 s of 100 steps
}
