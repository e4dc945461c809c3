#include "plc/builtins.hpp"

#include <algorithm>
#include <limits>
#include <numbers>

namespace beamctl::plc::detail {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kEqualEpsilon = 1e-10; // ExprTk's epsilon for equal()/not_equal() on doubles

// Formulas as ExprTk defines them (exprtk.hpp details::numeric); <cmath> where ExprTk's own
// approximation is only a less accurate version of the same function.
double f_abs(double v) noexcept {
    return v < 0 ? -v : v;
}
double f_acos(double v) noexcept {
    return std::acos(v);
}
double f_acosh(double v) noexcept {
    return std::acosh(v);
}
double f_asin(double v) noexcept {
    return std::asin(v);
}
double f_asinh(double v) noexcept {
    return std::asinh(v);
}
double f_atan(double v) noexcept {
    return std::atan(v);
}
double f_atanh(double v) noexcept {
    return std::atanh(v);
}
double f_ceil(double v) noexcept {
    return std::ceil(v);
}
double f_cos(double v) noexcept {
    return std::cos(v);
}
double f_cosh(double v) noexcept {
    return std::cosh(v);
}
double f_cot(double v) noexcept {
    return 1.0 / std::tan(v);
}
double f_csc(double v) noexcept {
    return 1.0 / std::sin(v);
}
double f_sec(double v) noexcept {
    return 1.0 / std::cos(v);
}
// 90 degrees are 100 gradians (as current ExprTk; the 2018 copy in exprtk-ecmc used 20/9).
double f_deg2grad(double v) noexcept {
    return v * (10.0 / 9.0);
}
double f_grad2deg(double v) noexcept {
    return v * (9.0 / 10.0);
}
double f_deg2rad(double v) noexcept {
    return v * (std::numbers::pi / 180.0);
}
double f_rad2deg(double v) noexcept {
    return v * (180.0 / std::numbers::pi);
}
double f_erf(double v) noexcept {
    return std::erf(v);
}
double f_erfc(double v) noexcept {
    return std::erfc(v);
}
double f_exp(double v) noexcept {
    return std::exp(v);
}
double f_expm1(double v) noexcept {
    return std::expm1(v);
}
double f_floor(double v) noexcept {
    return std::floor(v);
}
// ExprTk truncates through an integer, so -0.5 gives +0.
double f_trunc(double v) noexcept {
    const double t = std::trunc(v);
    return t == 0 ? 0.0 : t;
}
double f_frac(double v) noexcept {
    return std::isinf(v) ? v : v - std::trunc(v);
}
double f_log(double v) noexcept {
    return std::log(v);
}
double f_log10(double v) noexcept {
    return std::log10(v);
}
double f_log1p(double v) noexcept {
    return v > -1.0 ? std::log1p(v) : kNaN;
}
double f_log2(double v) noexcept {
    return std::log2(v);
}
double f_ncdf(double v) noexcept {
    const double cnd = 0.5 * (1.0 + std::erf(f_abs(v) / std::numbers::sqrt2));
    return v < 0 ? 1.0 - cnd : cnd;
}
// Half away from zero, computed as ExprTk does.
double f_round(double v) noexcept {
    return v < 0 ? std::ceil(v - 0.5) : std::floor(v + 0.5);
}
double f_sgn(double v) noexcept {
    return v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0);
}
double f_sin(double v) noexcept {
    return std::sin(v);
}
double f_sinc(double v) noexcept {
    return std::abs(v) >= std::numeric_limits<double>::epsilon() ? std::sin(v) / v : 1.0;
}
double f_sinh(double v) noexcept {
    return std::sinh(v);
}
double f_sqrt(double v) noexcept {
    return std::sqrt(v);
}
double f_tan(double v) noexcept {
    return std::tan(v);
}
double f_tanh(double v) noexcept {
    return std::tanh(v);
}

double f_atan2(double a, double b) noexcept {
    return std::atan2(a, b);
}
double f_equal(double a, double b) noexcept {
    const double scale = std::max(1.0, std::max(f_abs(a), f_abs(b)));
    return from_bool(f_abs(a - b) <= scale * kEqualEpsilon);
}
double f_not_equal(double a, double b) noexcept {
    const double scale = std::max(1.0, std::max(f_abs(a), f_abs(b)));
    return from_bool(f_abs(a - b) > scale * kEqualEpsilon);
}
double f_hypot(double a, double b) noexcept {
    return std::hypot(a, b);
}
double f_logn(double a, double b) noexcept {
    return std::log(a) / std::log(b);
}
double f_mod(double a, double b) noexcept {
    return std::fmod(a, b);
}
double f_pow(double a, double b) noexcept {
    return std::pow(a, b);
}
// ExprTk: n = (size_t)b; a NaN or huge b converts to 2^63 on x86.
double f_root(double a, double b) noexcept {
    if (b < 0) return kNaN;
    const double n = (b >= 0 && b < 9.2e18) ? std::floor(b) + 0.0 : 9223372036854775808.0;
    if (a < 0 && std::fmod(n, 2.0) == 0) return kNaN;
    return std::pow(a, 1.0 / n);
}
double f_roundn(double a, double b) noexcept {
    // ExprTk: clamp((int)floor(b), 0, 16); (int) of NaN or out of range is INT_MIN on x86.
    const double f = std::floor(b);
    const int i = !(f > -2147483649.0 && f < 2147483648.0)
                      ? 0
                      : (f < 0 ? 0 : (f > 16 ? 16 : static_cast<int>(f)));
    const double p10 = std::pow(10.0, i);
    return a < 0 ? std::ceil(a * p10 - 0.5) / p10 : std::floor(a * p10 + 0.5) / p10;
}
// ExprTk converts the count with (int); out of range (and NaN) that is INT_MIN on x86.
double shift_count(double b) noexcept {
    return (b > -2147483649.0 && b < 2147483648.0) ? std::trunc(b) : -2147483648.0;
}
double f_shl(double a, double b) noexcept {
    return a * std::pow(2.0, shift_count(b));
}
double f_shr(double a, double b) noexcept {
    return a * (1.0 / std::pow(2.0, shift_count(b)));
}

double f_clamp(double lo, double x, double hi) noexcept {
    return x < lo ? lo : (x > hi ? hi : x);
}
double f_iclamp(double lo, double x, double hi) noexcept {
    if (x <= lo || x >= hi) return x;
    return 2 * x <= hi + lo ? lo : hi;
}
double f_inrange(double lo, double x, double hi) noexcept {
    return x < lo ? 0.0 : (x > hi ? 0.0 : 1.0);
}

const Builtin kBuiltins[] = {
    {"abs", 1, f_abs, nullptr, nullptr},
    {"acos", 1, f_acos, nullptr, nullptr},
    {"acosh", 1, f_acosh, nullptr, nullptr},
    {"asin", 1, f_asin, nullptr, nullptr},
    {"asinh", 1, f_asinh, nullptr, nullptr},
    {"atan", 1, f_atan, nullptr, nullptr},
    {"atanh", 1, f_atanh, nullptr, nullptr},
    {"ceil", 1, f_ceil, nullptr, nullptr},
    {"cos", 1, f_cos, nullptr, nullptr},
    {"cosh", 1, f_cosh, nullptr, nullptr},
    {"cot", 1, f_cot, nullptr, nullptr},
    {"csc", 1, f_csc, nullptr, nullptr},
    {"deg2grad", 1, f_deg2grad, nullptr, nullptr},
    {"deg2rad", 1, f_deg2rad, nullptr, nullptr},
    {"erf", 1, f_erf, nullptr, nullptr},
    {"erfc", 1, f_erfc, nullptr, nullptr},
    {"exp", 1, f_exp, nullptr, nullptr},
    {"expm1", 1, f_expm1, nullptr, nullptr},
    {"floor", 1, f_floor, nullptr, nullptr},
    {"frac", 1, f_frac, nullptr, nullptr},
    {"grad2deg", 1, f_grad2deg, nullptr, nullptr},
    {"log", 1, f_log, nullptr, nullptr},
    {"log10", 1, f_log10, nullptr, nullptr},
    {"log1p", 1, f_log1p, nullptr, nullptr},
    {"log2", 1, f_log2, nullptr, nullptr},
    {"ncdf", 1, f_ncdf, nullptr, nullptr},
    {"rad2deg", 1, f_rad2deg, nullptr, nullptr},
    {"round", 1, f_round, nullptr, nullptr},
    {"sec", 1, f_sec, nullptr, nullptr},
    {"sgn", 1, f_sgn, nullptr, nullptr},
    {"sin", 1, f_sin, nullptr, nullptr},
    {"sinc", 1, f_sinc, nullptr, nullptr},
    {"sinh", 1, f_sinh, nullptr, nullptr},
    {"sqrt", 1, f_sqrt, nullptr, nullptr},
    {"tan", 1, f_tan, nullptr, nullptr},
    {"tanh", 1, f_tanh, nullptr, nullptr},
    {"trunc", 1, f_trunc, nullptr, nullptr},
    {"atan2", 2, nullptr, f_atan2, nullptr},
    {"equal", 2, nullptr, f_equal, nullptr},
    {"hypot", 2, nullptr, f_hypot, nullptr},
    {"logn", 2, nullptr, f_logn, nullptr},
    {"mod", 2, nullptr, f_mod, nullptr},
    {"not_equal", 2, nullptr, f_not_equal, nullptr},
    {"pow", 2, nullptr, f_pow, nullptr},
    {"root", 2, nullptr, f_root, nullptr},
    {"roundn", 2, nullptr, f_roundn, nullptr},
    {"shl", 2, nullptr, f_shl, nullptr},
    {"shr", 2, nullptr, f_shr, nullptr},
    {"clamp", 3, nullptr, nullptr, f_clamp},
    {"iclamp", 3, nullptr, nullptr, f_iclamp},
    {"inrange", 3, nullptr, nullptr, f_inrange},
};

} // namespace

const Builtin* find_builtin(std::string_view lower_name) {
    for (const Builtin& b : kBuiltins)
        if (lower_name == b.name) return &b;
    return nullptr;
}

double call(const Builtin& b, const double* args) noexcept {
    switch (b.arity) {
    case 1:
        return b.f1(args[0]);
    case 2:
        return b.f2(args[0], args[1]);
    default:
        return b.f3(args[0], args[1], args[2]);
    }
}

bool find_aggregate(std::string_view n, Aggregate& out) {
    static const struct {
        const char* name;
        Aggregate a;
    } table[] = {{"sum", Aggregate::sum}, {"mul", Aggregate::mul}, {"avg", Aggregate::avg},
                 {"min", Aggregate::min}, {"max", Aggregate::max}, {"mand", Aggregate::mand},
                 {"mor", Aggregate::mor}};
    for (const auto& e : table) {
        if (n == e.name) {
            out = e.a;
            return true;
        }
    }
    return false;
}

Fn1 builtin_abs() noexcept {
    return f_abs;
}
Fn1 builtin_sqrt() noexcept {
    return f_sqrt;
}

} // namespace beamctl::plc::detail
