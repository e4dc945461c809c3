// Curve fits (automation/fit.hpp) against data made from a known truth: noise-free data give the
// truth back; noisy data give it back within the reported errors, and those errors are calibrated
// (about 68 % of many runs lie within one standard error); bad input is refused with a reason.
#include "automation/fit.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace beamctl::automation {
namespace {

struct Truth {
    FitModel model;
    double center, width, amplitude, background;
};

// y on `n` points over [lo, hi], plus normal noise of standard deviation `noise`.
void make(const Truth& t, int n, double lo, double hi, double noise, unsigned seed, std::vector<double>& x,
          std::vector<double>& y) {
    FitResult f;
    f.model = t.model, f.center = t.center, f.width = t.width, f.amplitude = t.amplitude, f.background = t.background;
    std::mt19937 rng(seed);
    std::normal_distribution<double> gauss(0, noise > 0 ? noise : 1);
    x.resize(n), y.resize(n);
    for (int i = 0; i < n; ++i) {
        x[i] = lo + (hi - lo) * i / (n - 1);
        y[i] = f(x[i]) + (noise > 0 ? gauss(rng) : 0);
    }
}

TEST(Fit, NoiseFreeDataGiveTheTruthForEveryModel) {
    for (const Truth& t : {Truth{FitModel::Lorentzian, 10.02, 0.004, 0.8, 0.05}, Truth{FitModel::Gaussian, -3.5, 0.6, 120, 7},
                           Truth{FitModel::Edge, 2.0, 0.3, 5, 1}, Truth{FitModel::Edge, 2.0, 0.3, -5, 6}}) {
        std::vector<double> x, y;
        make(t, 101, t.center - 4 * t.width - 0.001, t.center + 3 * t.width, 0, 1, x, y);
        const FitResult r = fit_curve(t.model, x, y);
        SCOPED_TRACE(fit_model_name(t.model));
        ASSERT_TRUE(r.ok) << r.message;
        EXPECT_NEAR(r.center, t.center, 1e-6 * t.width);
        EXPECT_NEAR(r.width, t.width, 1e-6 * t.width);
        EXPECT_NEAR(r.amplitude, t.amplitude, 1e-6 * std::abs(t.amplitude));
        EXPECT_NEAR(r.background, t.background, 1e-6 * std::abs(t.amplitude));
        EXPECT_GT(r.r_squared, 0.999999);
        EXPECT_EQ(r.points, 101);
        EXPECT_EQ(r.dof, 97);
    }
}

TEST(Fit, NoisyLorentzianWithSigmasHasChi2NearOneAndTheTruthWithinItsErrors) {
    const Truth t{FitModel::Lorentzian, 0.3, 0.02, 1.0, 0.1};
    std::vector<double> x, y;
    make(t, 101, 0.22, 0.38, 0.02, 7, x, y);
    const std::vector<double> sigma(x.size(), 0.02);
    const FitResult r = fit_curve(t.model, x, y, sigma);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_NEAR(r.reduced_chi2, 1.0, 0.35);
    EXPECT_LT(std::abs(r.center - t.center), 4 * r.center_err);
    EXPECT_LT(std::abs(r.width - t.width), 4 * r.width_err);
    EXPECT_LT(std::abs(r.amplitude - t.amplitude), 4 * r.amplitude_err);
    EXPECT_LT(std::abs(r.center - t.center), 0.01 * t.width); // the 1 % of the width
    EXPECT_GT(r.center_err, 0);
    EXPECT_EQ(check_fit(r, FitLimits{2.0, 0.9, true, 0.1}), "");
}

// The standard errors mean what they say: over many noisy runs, about 68 % of the fitted centres
// and widths lie within one error of the truth (with sigmas given, and without: errors scaled by
// the residual variance).
TEST(Fit, ErrorsAreCalibrated) {
    const Truth t{FitModel::Lorentzian, 5.0, 0.5, 2.0, 0.3};
    for (bool with_sigma : {true, false}) {
        int center_in = 0, width_in = 0, runs = 300;
        for (int run = 0; run < runs; ++run) {
            std::vector<double> x, y;
            make(t, 41, 3.0, 7.0, 0.05, 1000 + run, x, y);
            const std::vector<double> sigma(with_sigma ? x.size() : 0, 0.05);
            const FitResult r = fit_curve(t.model, x, y, sigma);
            ASSERT_TRUE(r.ok) << r.message;
            center_in += std::abs(r.center - t.center) < r.center_err;
            width_in += std::abs(r.width - t.width) < r.width_err;
        }
        SCOPED_TRACE(with_sigma ? "with sigma" : "without");
        EXPECT_NEAR(center_in / double(runs), 0.683, 0.07);
        EXPECT_NEAR(width_in / double(runs), 0.683, 0.07);
    }
}

TEST(Fit, AFlankOnlyPutsTheCentreOutsideTheScanAndCheckFitSaysSo) {
    const Truth t{FitModel::Lorentzian, 1.0, 0.1, 1.0, 0.0};
    std::vector<double> x, y;
    make(t, 31, 0.5, 0.85, 0.0, 1, x, y); // only the rising flank
    FitResult r = fit_curve(t.model, x, y);
    const std::string why = check_fit(r, FitLimits{});
    EXPECT_NE(why, "");
    if (r.ok) {
        EXPECT_NE(why.find("outside the scanned range"), std::string::npos) << why;
    }
}

TEST(Fit, NoiseWithoutAPeakFailsTheLimits) {
    std::vector<double> x(51), y(51);
    std::mt19937 rng(3);
    std::normal_distribution<double> g(1.0, 0.1);
    for (int i = 0; i < 51; ++i) x[i] = i, y[i] = g(rng);
    const FitResult r = fit_curve(FitModel::Lorentzian, x, y);
    EXPECT_NE(check_fit(r, FitLimits{0, 0.8, true, 0}), "");
}

TEST(Fit, BadInputIsRefusedWithAReason) {
    const std::vector<double> x5{1, 2, 3, 4, 5}, y5{1, 2, 5, 2, 1};
    FitResult r = fit_curve(FitModel::Gaussian, std::vector<double>{1, 2, 3, 4}, std::vector<double>{1, 2, 3, 4});
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.message.find("too few points"), std::string::npos) << r.message;
    r = fit_curve(FitModel::Gaussian, x5, std::vector<double>{1, 2, NAN, 2, 1});
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.message.find("point 2"), std::string::npos) << r.message;
    r = fit_curve(FitModel::Gaussian, std::vector<double>{2, 2, 2, 2, 2}, y5);
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.message.find("same x"), std::string::npos) << r.message;
    r = fit_curve(FitModel::Gaussian, x5, std::vector<double>{1, 2});
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.message.find("differ in length"), std::string::npos) << r.message;
    r = fit_curve(FitModel::Gaussian, x5, y5, std::vector<double>{1, 1, 0, 1, 1});
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(check_fit(r, FitLimits{}).rfind("the fit failed: ", 0), 0u);
    // Constant data: nothing determines the centre or the width.
    r = fit_curve(FitModel::Lorentzian, x5, std::vector<double>{1, 1, 1, 1, 1});
    EXPECT_FALSE(r.ok && check_fit(r, FitLimits{0, 0.5, true, 0}).empty());
}

TEST(Fit, ModelNamesRoundTrip) {
    for (FitModel m : {FitModel::Lorentzian, FitModel::Gaussian, FitModel::Edge}) {
        FitModel back = FitModel::Lorentzian;
        ASSERT_TRUE(parse_fit_model(fit_model_name(m), back));
        EXPECT_EQ(back, m);
    }
    FitModel m;
    EXPECT_FALSE(parse_fit_model("voigt", m));
}

TEST(PeakStats, TriangleHasItsCentroidAndFwhm) {
    // A triangle on a background of 1: apex 5 at x = 3, base from 1 to 5 (unsorted input).
    const std::vector<double> x{5, 1, 2, 3, 4, 0, 6}, y{1, 1, 3, 5, 3, 1, 1};
    const PeakStats s = peak_stats(x, y);
    ASSERT_TRUE(s.ok);
    EXPECT_DOUBLE_EQ(s.max_x, 3);
    EXPECT_DOUBLE_EQ(s.max_y, 5);
    EXPECT_DOUBLE_EQ(s.min_y, 1);
    EXPECT_DOUBLE_EQ(s.centroid, 3);
    EXPECT_DOUBLE_EQ(s.fwhm, 2); // half height 3 at x = 2 and x = 4
    EXPECT_FALSE(peak_stats(std::vector<double>{1}, std::vector<double>{1}).ok);
}

} // namespace
} // namespace beamctl::automation
