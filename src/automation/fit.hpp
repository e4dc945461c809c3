// Curve fits for alignment plans (seed 003: "fit a Lorentzian curve to the ratio of downstream
// beam intensity to upstream beam intensity, move to the position that maximizes the fit"):
// Lorentzian, Gaussian and error-function edge, each on a constant background, fitted by
// Levenberg-Marquardt (MINPACK's lmder, Debian's libcminpack, with analytic Jacobians), with the
// parameters' standard errors from the covariance at the solution, chi^2 / reduced chi^2 and R^2;
// plus model-free peak statistics (maximum, centroid, FWHM by interpolation) as bluesky's
// PeakStats reports them.
//
// Models (x in the scanned motor's units):
//   Lorentzian  y = b + A / (1 + ((x - x0) / g)^2)              width = FWHM = 2 g
//   Gaussian    y = b + A exp(-(x - x0)^2 / (2 s^2))            width = FWHM = 2 sqrt(2 ln 2) s
//   Edge        y = b + A/2 (1 + erf((x - x0) / (sqrt(2) s)))   width = 10 %..90 % rise = 2.5631 s
// Weights: with per-point standard deviations `sigma`, the residuals are (y - f) / sigma, chi^2
// is absolute and the errors come from (J^T J)^-1; without, every sigma is 1 and the errors are
// scaled by the residual variance (chi^2 / dof), as scipy's curve_fit does by default.
// Pure functions: any thread.
#pragma once

#include <span>
#include <string>
#include <vector>

namespace beamctl::automation {

enum class FitModel { Lorentzian, Gaussian, Edge };
const char* fit_model_name(FitModel m);
bool parse_fit_model(const std::string& name, FitModel& out); // "lorentzian", "gaussian", "edge"

struct FitResult {
    FitModel model = FitModel::Lorentzian;
    bool ok = false;         // converged to a finite solution with finite errors
    std::string message;     // why not (bad input, no convergence), or MINPACK's stop reason
    int evaluations = 0;     // function evaluations
    // The fitted parameters and their standard errors.
    double center = 0, width = 0, amplitude = 0, background = 0;
    double center_err = 0, width_err = 0, amplitude_err = 0, background_err = 0;
    int points = 0, dof = 0;       // data points used, points - parameters
    double chi2 = 0, reduced_chi2 = 0; // sum of squared weighted residuals, / dof
    double r_squared = 0;              // 1 - SS_res / SS_tot (unweighted)
    double x_min = 0, x_max = 0;       // the data's x range

    double operator()(double x) const; // the fitted curve
};

// Fits `model` to (x, y). Points with a non-finite x, y or sigma (or sigma <= 0) are refused:
// the result says which. Needs at least 5 points and two distinct x. Never throws.
FitResult fit_curve(FitModel model, std::span<const double> x, std::span<const double> y,
                    std::span<const double> sigma = {});

// Limits a plan puts on a fit before it moves to the fitted centre.
struct FitLimits {
    double max_reduced_chi2 = 0; // 0: not checked
    double min_r_squared = 0;    // 0: not checked
    bool center_in_range = true; // the centre inside the scanned x range
    double max_width = 0;        // 0: not checked (a width larger than this is no peak)
};
// Empty when the fit is good enough for `limits`, else why not (one sentence with the figures).
std::string check_fit(const FitResult& fit, const FitLimits& limits);

// Model-free statistics of a peak (bluesky's PeakStats): where y is largest, the centroid of
// y - min(y), and the FWHM where y - min(y) crosses half its maximum (linear interpolation; 0 when
// a side never crosses).
struct PeakStats {
    bool ok = false;
    double max_x = 0, max_y = 0, min_x = 0, min_y = 0;
    double centroid = 0, fwhm = 0;
};
PeakStats peak_stats(std::span<const double> x, std::span<const double> y);

} // namespace beamctl::automation
