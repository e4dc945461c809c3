// Curve fits by MINPACK's Levenberg-Marquardt (see fit.hpp).
#include "automation/fit.hpp"

#include <cminpack.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

namespace beamctl::automation {

namespace {

constexpr double kFwhmPerSigma = 2.3548200450309493; // 2 sqrt(2 ln 2)
constexpr double kRisePerSigma = 2.5631031310892007; // 10 %..90 % of an erf edge, 2 * 1.28155
constexpr int kParams = 4;                            // centre, width parameter, amplitude, background

// The model at x for p = {x0, w, A, b} (w: Lorentzian HWHM, or the Gaussian/edge sigma), and,
// when d is given, its derivatives d f / d p.
double model_at(FitModel m, const double* p, double x, double* d) {
    const double x0 = p[0], w = p[1], a = p[2], b = p[3];
    switch (m) {
    case FitModel::Lorentzian: {
        const double u = (x - x0) / w, den = 1 + u * u, f = 1 / den;
        if (d) d[0] = a * 2 * u * f * f / w, d[1] = a * 2 * u * u * f * f / w, d[2] = f, d[3] = 1;
        return b + a * f;
    }
    case FitModel::Gaussian: {
        const double u = (x - x0) / w, e = std::exp(-0.5 * u * u);
        if (d) d[0] = a * e * u / w, d[1] = a * e * u * u / w, d[2] = e, d[3] = 1;
        return b + a * e;
    }
    case FitModel::Edge: {
        const double u = (x - x0) / (std::sqrt(2.0) * w), e = std::exp(-u * u), s = 0.5 * (1 + std::erf(u));
        if (d)
            d[0] = -a * e / (std::sqrt(2 * M_PI) * w), d[1] = -a * u * e / (std::sqrt(M_PI) * w), d[2] = s, d[3] = 1;
        return b + a * s;
    }
    }
    return 0;
}

// Width parameter <-> the reported width.
double width_scale(FitModel m) {
    switch (m) {
    case FitModel::Lorentzian: return 2;
    case FitModel::Gaussian: return kFwhmPerSigma;
    case FitModel::Edge: return kRisePerSigma;
    }
    return 1;
}

struct Problem {
    FitModel model;
    const double *x, *y, *sigma; // sigma may be null
};

int residuals(void* pv, int m, int n, const double* p, double* fvec, double* fjac, int ldfjac, int iflag) {
    const auto& pr = *static_cast<const Problem*>(pv);
    double d[kParams];
    for (int i = 0; i < m; ++i) {
        const double s = pr.sigma ? pr.sigma[i] : 1.0;
        if (iflag == 1) {
            fvec[i] = (pr.y[i] - model_at(pr.model, p, pr.x[i], nullptr)) / s;
            if (!std::isfinite(fvec[i])) return -1;
        } else {
            model_at(pr.model, p, pr.x[i], d);
            for (int j = 0; j < n; ++j) fjac[i + j * ldfjac] = -d[j] / s;
        }
    }
    return 0;
}

// Where y - base crosses `level` walking from index `from` by `step` over the x-sorted order;
// NaN when it never does.
double crossing(const std::vector<std::size_t>& order, std::span<const double> x, std::span<const double> y, std::size_t from,
                int step, double level) {
    for (std::size_t k = from; k + step < order.size(); k += step) {
        const std::size_t i = order[k], j = order[k + step];
        if ((y[i] - level) * (y[j] - level) <= 0 && y[i] != y[j])
            return x[i] + (level - y[i]) * (x[j] - x[i]) / (y[j] - y[i]);
    }
    return NAN;
}

// Starting values from the data's shape (x-sorted by `order`).
void initial_guess(FitModel m, std::span<const double> x, std::span<const double> y, const std::vector<std::size_t>& order,
                   double* p) {
    const double span_x = x[order.back()] - x[order.front()];
    if (m == FitModel::Edge) {
        const std::size_t k = std::max<std::size_t>(1, order.size() / 10);
        double lo = 0, hi = 0;
        for (std::size_t i = 0; i < k; ++i) lo += y[order[i]], hi += y[order[order.size() - 1 - i]];
        lo /= double(k), hi /= double(k);
        double mid = crossing(order, x, y, 0, 1, 0.5 * (lo + hi));
        if (!std::isfinite(mid)) mid = 0.5 * (x[order.front()] + x[order.back()]);
        p[0] = mid, p[1] = span_x / 10, p[2] = hi - lo, p[3] = lo;
        return;
    }
    std::vector<double> sorted(y.begin(), y.end());
    std::sort(sorted.begin(), sorted.end());
    const double lo = sorted.front(), hi = sorted.back(), median = sorted[sorted.size() / 2];
    const bool dip = median - lo > hi - median;
    std::size_t peak = 0; // position in `order` of the extreme
    for (std::size_t k = 0; k < order.size(); ++k)
        if (y[order[k]] == (dip ? lo : hi)) {
            peak = k;
            break;
        }
    const double base = dip ? hi : lo, amp = dip ? lo - hi : hi - lo, half = base + 0.5 * amp;
    const double left = peak > 0 ? crossing(order, x, y, peak, -1, half) : NAN;
    const double right = crossing(order, x, y, peak, 1, half);
    const double x0 = x[order[peak]];
    double fwhm = span_x / 4;
    if (std::isfinite(left) && std::isfinite(right)) fwhm = right - left;
    else if (std::isfinite(left)) fwhm = 2 * (x0 - left);
    else if (std::isfinite(right)) fwhm = 2 * (right - x0);
    if (!(fwhm > 0)) fwhm = span_x / 4;
    p[0] = x0, p[1] = fwhm / width_scale(m), p[2] = amp, p[3] = base;
}

const char* minpack_message(int info) {
    switch (info) {
    case 0: return "improper input parameters";
    case 1: return "converged (relative reduction of chi2 below tolerance)";
    case 2: return "converged (relative change of the parameters below tolerance)";
    case 3: return "converged (chi2 and parameters)";
    case 4: return "converged (residuals orthogonal to the Jacobian)";
    case 5: return "did not converge within the evaluation limit";
    case 6: return "converged (chi2 cannot be reduced further)";
    case 7: return "converged (parameters cannot be improved further)";
    case 8: return "converged (gradient at machine precision)";
    default: return "stopped: the model became non-finite";
    }
}

} // namespace

const char* fit_model_name(FitModel m) {
    switch (m) {
    case FitModel::Lorentzian: return "lorentzian";
    case FitModel::Gaussian: return "gaussian";
    case FitModel::Edge: return "edge";
    }
    return "?";
}

bool parse_fit_model(const std::string& name, FitModel& out) {
    for (FitModel m : {FitModel::Lorentzian, FitModel::Gaussian, FitModel::Edge})
        if (name == fit_model_name(m)) {
            out = m;
            return true;
        }
    return false;
}

double FitResult::operator()(double x) const {
    const double p[kParams] = {center, width / width_scale(model), amplitude, background};
    return model_at(model, p, x, nullptr);
}

FitResult fit_curve(FitModel model, std::span<const double> x, std::span<const double> y, std::span<const double> sigma) {
    FitResult r;
    r.model = model;
    const std::size_t n = x.size();
    if (y.size() != n || (!sigma.empty() && sigma.size() != n)) {
        r.message = "x, y and sigma differ in length (" + std::to_string(n) + ", " + std::to_string(y.size()) + ", " +
                    std::to_string(sigma.size()) + ")";
        return r;
    }
    for (std::size_t i = 0; i < n; ++i)
        if (!std::isfinite(x[i]) || !std::isfinite(y[i]) || (!sigma.empty() && !(sigma[i] > 0 && std::isfinite(sigma[i])))) {
            r.message = "point " + std::to_string(i) + " is not finite (or its sigma is not > 0)";
            return r;
        }
    if (n < 5) {
        r.message = "too few points (" + std::to_string(n) + "; a fit needs at least 5)";
        return r;
    }
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return x[a] < x[b]; });
    r.x_min = x[order.front()], r.x_max = x[order.back()];
    if (!(r.x_max > r.x_min)) {
        r.message = "all points have the same x";
        return r;
    }
    r.points = int(n), r.dof = int(n) - kParams;

    double p[kParams];
    initial_guess(model, x, y, order, p);
    Problem pr{model, x.data(), y.data(), sigma.empty() ? nullptr : sigma.data()};
    const int m = int(n);
    std::vector<double> fvec(n), fjac(n * kParams), qtf(kParams), wa1(kParams), wa2(kParams), wa3(kParams), wa4(n),
        diag(kParams);
    int ipvt[kParams], nfev = 0, njev = 0;
    const double tol = std::sqrt(__cminpack_func__(dpmpar)(1));
    const int info = __cminpack_func__(lmder)(residuals, &pr, m, kParams, p, fvec.data(), fjac.data(), m, tol, tol, 0.0,
                                              200 * (kParams + 1), diag.data(), 1, 100.0, 0, &nfev, &njev, ipvt,
                                              qtf.data(), wa1.data(), wa2.data(), wa3.data(), wa4.data());
    r.evaluations = nfev + njev;
    r.message = minpack_message(info);
    const bool converged = (info >= 1 && info <= 4) || (info >= 6 && info <= 8);

    // chi^2 at the solution, R^2.
    residuals(&pr, m, kParams, p, fvec.data(), nullptr, m, 1);
    r.chi2 = 0;
    for (double f : fvec) r.chi2 += f * f;
    r.reduced_chi2 = r.dof > 0 ? r.chi2 / r.dof : 0;
    const double mean_y = std::accumulate(y.begin(), y.end(), 0.0) / double(n);
    double ss_res = 0, ss_tot = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double e = y[i] - model_at(model, p, x[i], nullptr);
        ss_res += e * e, ss_tot += (y[i] - mean_y) * (y[i] - mean_y);
    }
    r.r_squared = ss_tot > 0 ? 1 - ss_res / ss_tot : 0;

    // Covariance (J^T J)^-1 from lmder's R factor; scaled by chi^2/dof without sigmas.
    __cminpack_func__(covar)(kParams, fjac.data(), m, ipvt, tol, wa1.data());
    const double scale = sigma.empty() ? r.reduced_chi2 : 1.0;
    double err[kParams];
    bool determined = true;
    for (int j = 0; j < kParams; ++j) {
        const double v = fjac[j + j * m] * scale;
        err[j] = std::sqrt(std::max(v, 0.0));
        if (!std::isfinite(err[j]) || fjac[j + j * m] == 0) determined = false;
    }
    const double ws = width_scale(model);
    r.center = p[0], r.width = std::abs(p[1]) * ws, r.amplitude = p[2], r.background = p[3];
    if (model == FitModel::Edge && p[1] < 0) r.amplitude = -p[2], r.background = p[3] + p[2]; // the same edge, rising
    r.center_err = err[0], r.width_err = err[1] * ws, r.amplitude_err = err[2], r.background_err = err[3];
    const bool finite = std::isfinite(r.center) && std::isfinite(r.width) && std::isfinite(r.amplitude) &&
                        std::isfinite(r.background) && r.width > 0;
    r.ok = converged && finite && determined;
    if (converged && !finite) r.message = "the fit ended at a non-finite or zero width";
    else if (converged && !determined) r.message = "the data do not determine every parameter (singular covariance)";
    return r;
}

std::string check_fit(const FitResult& fit, const FitLimits& limits) {
    char buf[200];
    if (!fit.ok) return "the fit failed: " + fit.message;
    if (limits.max_reduced_chi2 > 0 && !(fit.reduced_chi2 <= limits.max_reduced_chi2)) {
        std::snprintf(buf, sizeof buf, "reduced chi2 %.4g is above the limit %.4g", fit.reduced_chi2, limits.max_reduced_chi2);
        return buf;
    }
    if (limits.min_r_squared > 0 && !(fit.r_squared >= limits.min_r_squared)) {
        std::snprintf(buf, sizeof buf, "R^2 %.4g is below the limit %.4g", fit.r_squared, limits.min_r_squared);
        return buf;
    }
    if (limits.center_in_range && (fit.center < fit.x_min || fit.center > fit.x_max)) {
        std::snprintf(buf, sizeof buf, "the centre %.6g is outside the scanned range [%.6g, %.6g]", fit.center, fit.x_min,
                      fit.x_max);
        return buf;
    }
    if (limits.max_width > 0 && fit.width > limits.max_width) {
        std::snprintf(buf, sizeof buf, "the width %.4g is above the limit %.4g", fit.width, limits.max_width);
        return buf;
    }
    return {};
}

PeakStats peak_stats(std::span<const double> x, std::span<const double> y) {
    PeakStats s;
    const std::size_t n = std::min(x.size(), y.size());
    if (n < 2) return s;
    for (std::size_t i = 0; i < n; ++i)
        if (!std::isfinite(x[i]) || !std::isfinite(y[i])) return s;
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return x[a] < x[b]; });
    std::size_t imax = 0, imin = 0, kmax = 0;
    for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = order[k];
        if (y[i] > y[imax] || k == 0) imax = i, kmax = k;
        if (y[i] < y[imin] || k == 0) imin = i;
    }
    s.max_x = x[imax], s.max_y = y[imax], s.min_x = x[imin], s.min_y = y[imin];
    double sw = 0, swx = 0;
    for (std::size_t i = 0; i < n; ++i) sw += y[i] - s.min_y, swx += (y[i] - s.min_y) * x[i];
    s.centroid = sw > 0 ? swx / sw : s.max_x;
    const double half = s.min_y + 0.5 * (s.max_y - s.min_y);
    const double left = kmax > 0 ? crossing(order, x, y, kmax, -1, half) : NAN;
    const double right = crossing(order, x, y, kmax, 1, half);
    s.fwhm = std::isfinite(left) && std::isfinite(right) ? right - left : 0;
    s.ok = true;
    return s;
}

} // namespace beamctl::automation
