// The simulated detector's pulse processor (src/detector/sim_mca.cpp, dxp's parameters) and the
// sum of several elements (src/detector/mca_sum.cpp), in virtual time: the peaking time trades
// resolution for dead time, a preamp gain set wrong moves the peaks, the thresholds and the ADC
// range decide what is binned, counted as under/overflow or not seen, the statistics add up, an
// events preset ends the acquisition where it should, and refused settings change nothing.
#include "detector/mca_sum.hpp"
#include "detector/sim_mca.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>

using namespace beamctl::detector;

namespace {

SimMcaConfig one_line(double energy = 6.4, double rate = 10000, double fwhm = 0.2) {
    SimMcaConfig c;
    c.channels = 1024;
    c.cals = 0.02; // 0 .. 20.48 keV
    c.lines = {{"line", energy, rate, fwhm}};
    c.background = 0;
    c.dead_time = 4e-6; // at peaking time 2 us, gap 0.15 us
    c.noise_fwhm = 0.1;
    return c;
}

// The expected spectrum's peak: centroid [keV] and FWHM [keV] from its second moment.
struct Peak {
    double centre, fwhm;
};
Peak peak_of(const SimMca& m) {
    const auto& s = m.shape();
    double w = 0, x = 0, xx = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
        const double e = m.cals() * double(i);
        w += s[i], x += s[i] * e, xx += s[i] * e * e;
    }
    const double mu = x / w;
    return {mu, 2.354820045 * std::sqrt(std::max(0.0, xx / w - mu * mu))};
}

} // namespace

TEST(Dxp, ThePeakingTimeTradesResolutionForDeadTime) {
    SimMca m(one_line(), [] { return 0.0; });
    // at the configured peaking time: the configured FWHM and dead time (the bins add 0.02^2/12)
    EXPECT_NEAR(peak_of(m).fwhm, std::sqrt(0.2 * 0.2 + 0.02 * 0.02 * 5.545 / 12), 1e-3);
    EXPECT_DOUBLE_EQ(m.event_dead_time(), 4e-6);
    DxpSettings d = m.dxp();
    d.peaking_time = 0.5; // a quarter: the noise part of the FWHM doubles, the filter is 1.15 / 4.15 as long
    std::string why;
    ASSERT_TRUE(m.set_dxp(d, why)) << why;
    const double fwhm = std::sqrt(0.2 * 0.2 - 0.1 * 0.1 + 0.1 * 0.1 * 4);
    EXPECT_NEAR(peak_of(m).fwhm, std::sqrt(fwhm * fwhm + 0.02 * 0.02 * 5.545 / 12), 1e-3);
    EXPECT_NEAR(m.event_dead_time(), 4e-6 * 1.15 / 4.15, 1e-12);
    d.peaking_time = 8; // longer: better resolution, more dead time
    ASSERT_TRUE(m.set_dxp(d, why));
    EXPECT_LT(peak_of(m).fwhm, 0.2);
    EXPECT_GT(peak_of(m).fwhm, std::sqrt(0.2 * 0.2 - 0.1 * 0.1)); // never below the detector's own width
    EXPECT_NEAR(m.event_dead_time(), 4e-6 * 16.15 / 4.15, 1e-12);
    // the live time follows: non-paralyzable at 10000 counts/s
    double now = 0;
    SimMca t(one_line(), [&] { return now; });
    ASSERT_TRUE(t.set_dxp(d, why));
    t.start();
    now = 2;
    McaDevice::Status st;
    t.status(st);
    EXPECT_NEAR(st.live, 2 / (1 + 10000 * 4e-6 * 16.15 / 4.15), 1e-9);
}

TEST(Dxp, APreampGainSetWrongMovesThePeaksAndMaxEnergySetsTheBinWidth) {
    SimMcaConfig c = one_line();
    c.true_preamp_gain = 2.1; // the detector's; the processor assumes 2.0
    SimMca m(c, [] { return 0.0; });
    EXPECT_NEAR(peak_of(m).centre, 6.4 * 2.1 / 2.0, 1e-3);
    DxpSettings d = m.dxp();
    d.preamp_gain = 2.1;
    std::string why;
    ASSERT_TRUE(m.set_dxp(d, why));
    EXPECT_NEAR(peak_of(m).centre, 6.4, 1e-3);
    // MaxEnergy 10.24 keV: 10 eV per bin, the line at channel 640
    EXPECT_DOUBLE_EQ(m.cals(), 0.02);
    d.max_energy = 10.24;
    ASSERT_TRUE(m.set_dxp(d, why));
    EXPECT_DOUBLE_EQ(m.cals(), 0.01);
    const auto& s = m.shape();
    EXPECT_EQ(std::max_element(s.begin(), s.end()) - s.begin(), 640);
}

TEST(Dxp, ThresholdsAndTheAdcRangeDecideWhatIsBinnedAndTheStatisticsAddUp) {
    SimMcaConfig c = one_line();
    c.lines.push_back({"low", 1.0, 3000, 0.1});
    c.lines.push_back({"high", 18.0, 2000, 0.3});
    c.background = 1024; // 1 count/s per channel
    double now = 0;
    SimMca m(c, [&] { return now; });
    EXPECT_NEAR(m.input_rate(), 10000 + 3000 + 2000 + 1024, 1);
    DxpSettings d = m.dxp();
    d.trigger_threshold = 0.5; // the low line is seen, 25 background channels are not
    d.energy_threshold = 2.0;  // the low line is not binned: Underflows
    d.adc_percent_rule = 40;   // the ADC spans 5.9 x 100 / 40 = 14.75 keV: the high line overflows
    std::string why;
    ASSERT_TRUE(m.set_dxp(d, why)) << why;
    EXPECT_DOUBLE_EQ(m.dynamic_range(), 14.75);
    const double seen = 10000 + 3000 + 2000 + 1024 * (20.48 - 0.01 - 0.5) / 20.48;
    EXPECT_NEAR(m.input_rate(), seen, 2);
    const auto& s = m.shape();
    EXPECT_NEAR(std::accumulate(s.begin(), s.begin() + 99, 0.0), 0, 1e-9);  // below 2 keV (channel 100 = 2.0 keV)
    EXPECT_NEAR(std::accumulate(s.begin() + 738, s.end(), 0.0), 0, 1e-9);  // above 14.75 keV (channel 737.5)
    EXPECT_NEAR(std::accumulate(s.begin(), s.end(), 0.0), 10000 + 1024 * (14.75 - 2.0) / 20.48, 2);
    m.start();
    now = 10;
    McaDevice::Status st;
    m.status(st);
    const DxpCounters k = m.counters();
    EXPECT_EQ(k.triggers, k.events + k.underflows + k.overflows);
    const double live = st.live;
    EXPECT_NEAR(double(k.underflows), (3000 + 1024 * 1.5 / 20.48) * live, 5 * std::sqrt(3000 * live) + 2);
    EXPECT_NEAR(double(k.overflows), (2000 + 1024 * (20.48 - 0.01 - 14.75) / 20.48) * live, 5 * std::sqrt(2300 * live) + 2);
    std::vector<int32_t> data(1024);
    const uint32_t n = m.read(data.data(), 1024);
    EXPECT_EQ(k.events, std::accumulate(data.begin(), data.begin() + n, int64_t(0))); // every event in a channel
    EXPECT_NEAR(k.input_rate, seen, 5 * std::sqrt(seen / live));                       // ICR: triggers per live second
    EXPECT_DOUBLE_EQ(k.output_rate, double(k.events) / 10);                            // OCR: events per real second
    // the trigger threshold above the low line: not seen at all, no dead time
    d.trigger_threshold = 3.0;
    ASSERT_TRUE(m.set_dxp(d, why));
    EXPECT_NEAR(m.input_rate(), 10000 + 2000 + 1024 * (20.48 - 0.01 - 3.0) / 20.48, 2);
}

TEST(Dxp, AnEventsPresetEndsTheAcquisitionAtItsTime) {
    double now = 0;
    SimMca m(one_line(6.4, 10000), [&] { return now; });
    DxpSettings d = m.dxp();
    d.preset_mode = DxpPresetMode::Events;
    d.preset_events = 50000;
    std::string why;
    ASSERT_TRUE(m.set_dxp(d, why));
    m.start();
    McaDevice::Status st;
    for (int k = 0; k < 100 && (m.status(st), st.acquiring); ++k) now += 0.1;
    EXPECT_FALSE(st.acquiring);
    // 10000 events/s of live time: 5 s live
    EXPECT_NEAR(st.live, 5.0, 1e-9);
    EXPECT_NEAR(double(m.counters().events), 50000, 5 * std::sqrt(50000.0));
    // Triggers: the same with the trigger count
    d.preset_mode = DxpPresetMode::Triggers;
    d.preset_triggers = 20000;
    ASSERT_TRUE(m.set_dxp(d, why));
    m.erase();
    m.start();
    for (int k = 0; k < 100 && (m.status(st), st.acquiring); ++k) now += 0.1;
    EXPECT_NEAR(st.live, 2.0, 1e-9);
}

TEST(Dxp, ASettingOutOfRangeIsRefusedAndChangesNothing) {
    SimMca m(one_line(), [] { return 0.0; });
    const std::vector<double> before = m.shape();
    std::string why;
    DxpSettings d = m.dxp();
    d.peaking_time = 0;
    EXPECT_FALSE(m.set_dxp(d, why));
    EXPECT_NE(why.find("PeakingTime"), std::string::npos) << why;
    d = m.dxp();
    d.max_energy = -1; // below CALO = 0
    EXPECT_FALSE(m.set_dxp(d, why));
    EXPECT_NE(why.find("MaxEnergy"), std::string::npos) << why;
    d = m.dxp();
    d.adc_percent_rule = std::nan("");
    EXPECT_FALSE(m.set_dxp(d, why));
    EXPECT_EQ(m.shape(), before);
    EXPECT_DOUBLE_EQ(m.dxp().peaking_time, 2.0);
}

TEST(McaSum, AddsTheElementsAndDrivesThemAll) {
    double now = 0;
    SimMcaConfig c = one_line();
    c.seed = 1;
    SimMca a(c, [&] { return now; });
    c.seed = 2;
    c.lines[0].rate = 5000;
    SimMca b(c, [&] { return now; });
    McaSum sum({&a, &b});
    McaDevice::Setup s;
    s.nuse = 1024;
    s.prtm = 1.0;
    ASSERT_TRUE(sum.setup(s));
    ASSERT_TRUE(sum.start());
    McaDevice::Status st;
    now = 0.5;
    ASSERT_TRUE(sum.status(st));
    EXPECT_TRUE(st.acquiring && a.acquiring() && b.acquiring());
    now = 2;
    ASSERT_TRUE(sum.status(st));
    EXPECT_FALSE(st.acquiring); // both reached the preset real time
    EXPECT_DOUBLE_EQ(st.real, 1.0);
    McaDevice::Status sa, sb;
    a.status(sa), b.status(sb);
    EXPECT_DOUBLE_EQ(st.live, (sa.live + sb.live) / 2);
    EXPECT_EQ(st.total, sa.total + sb.total);
    std::vector<int32_t> va(1024), vb(1024), vs(1024);
    a.read(va.data(), 1024), b.read(vb.data(), 1024);
    ASSERT_EQ(sum.read(vs.data(), 1024), 1024u);
    for (std::size_t i = 0; i < 1024; ++i) ASSERT_EQ(vs[i], va[i] + vb[i]) << i;
    EXPECT_GT(std::accumulate(vs.begin(), vs.end(), 0), 10000);
    ASSERT_TRUE(sum.erase());
    sum.read(vs.data(), 1024);
    EXPECT_EQ(std::accumulate(vs.begin(), vs.end(), 0), 0);
}
