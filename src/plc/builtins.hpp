// ExprTk's operators and math functions on doubles, shared by the constant folder (compile time)
// and the evaluator (RT, noexcept, allocation-free).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace beamctl::plc::detail {

// ExprTk truth: anything but 0 is true (NaN included).
inline bool is_true(double v) noexcept {
    return v != 0.0;
}
inline double from_bool(bool b) noexcept {
    return b ? 1.0 : 0.0;
}

enum class BinOp : unsigned char {
    add,
    sub,
    mul,
    div,
    mod,
    pow,
    lt,
    le,
    gt,
    ge,
    eq,
    ne,
    land,
    lor,
    lnand,
    lnor,
    lxor,
    lxnor, // `and or nand nor xor xnor`: both sides evaluated
    scand,
    scor, // `&` `|`: short-circuit
};

inline double apply(BinOp op, double a, double b) noexcept {
    switch (op) {
    case BinOp::add:
        return a + b;
    case BinOp::sub:
        return a - b;
    case BinOp::mul:
        return a * b;
    case BinOp::div:
        return a / b;
    case BinOp::mod:
        return std::fmod(a, b);
    case BinOp::pow:
        return std::pow(a, b);
    case BinOp::lt:
        return from_bool(a < b);
    case BinOp::le:
        return from_bool(a <= b);
    case BinOp::gt:
        return from_bool(a > b);
    case BinOp::ge:
        return from_bool(a >= b);
    case BinOp::eq:
        return from_bool(a == b);
    case BinOp::ne:
        return from_bool(a != b);
    case BinOp::land:
    case BinOp::scand:
        return from_bool(is_true(a) && is_true(b));
    case BinOp::lor:
    case BinOp::scor:
        return from_bool(is_true(a) || is_true(b));
    case BinOp::lnand:
        return from_bool(!(is_true(a) && is_true(b)));
    case BinOp::lnor:
        return from_bool(!(is_true(a) || is_true(b)));
    case BinOp::lxor:
        return from_bool(is_true(a) != is_true(b));
    case BinOp::lxnor:
        return from_bool(is_true(a) == is_true(b));
    }
    return a;
}

// `x ^ c` for a literal integer c with |c| <= 60, as ExprTk compiles it (its cardinal-pow
// optimisation, numeric::fast_exp): the same multiplications in the same order, so a PLC's
// powers agree bit for bit with ECMC's. They differ from std::pow by the rounding of each
// multiplication (a few ulp at most for n <= 10) and where an intermediate overflows: 1 / x^n
// is 0 where pow(x, -n) would still be subnormal.
constexpr double kMaxIntPow = 60;
inline double int_pow(double v, std::uint32_t n) noexcept {
    switch (n) {
    case 0:
        return 1.0;
    case 1:
        return v;
    case 2:
        return v * v;
    case 3:
        return v * v * v;
    case 4: {
        const double v2 = v * v;
        return v2 * v2;
    }
    case 5:
        return int_pow(v, 4) * v;
    case 6: {
        const double v3 = v * v * v;
        return v3 * v3;
    }
    case 7:
        return int_pow(v, 6) * v;
    case 8: {
        const double v4 = int_pow(v, 4);
        return v4 * v4;
    }
    case 9:
        return int_pow(v, 8) * v;
    case 10: {
        const double v5 = int_pow(v, 5);
        return v5 * v5;
    }
    default: { // square and multiply
        double l = 1.0;
        while (n) {
            if (n % 2 == 1) {
                l *= v;
                --n;
            }
            v *= v;
            n /= 2;
        }
        return l;
    }
    }
}
// True when `x ^ c` is compiled to int_pow (or its reciprocal), as ExprTk decides.
inline bool is_int_pow_exponent(double c) noexcept {
    return std::fabs(c) <= kMaxIntPow && std::fmod(c, 1.0) == 0.0;
}
// `x ^ 0.5` (beamctl's own reduction, ExprTk calls pow): sqrt, which is correctly rounded,
// with pow's results at -0 (+0) and -inf (+inf).
inline double pow_half(double v) noexcept {
    return v == -HUGE_VAL ? HUGE_VAL : std::sqrt(v) + 0.0;
}

inline double logical_not(double v) noexcept {
    return from_bool(!is_true(v));
}

using Fn1 = double (*)(double) noexcept;
using Fn2 = double (*)(double, double) noexcept;
using Fn3 = double (*)(double, double, double) noexcept;

// A fixed-arity math function (abs, atan2, clamp, ...).
struct Builtin {
    const char* name;
    int arity; // 1, 2 or 3
    Fn1 f1;
    Fn2 f2;
    Fn3 f3;
};

// abs and sqrt, which the compiler inlines (Builtin::f1 identifies them).
Fn1 builtin_abs() noexcept;
Fn1 builtin_sqrt() noexcept;

// The built-in function called `lower_name`, or nullptr.
const Builtin* find_builtin(std::string_view lower_name);
double call(const Builtin& b, const double* args) noexcept;

// Multi-argument functions: sum, mul, avg, min, max (and mand/mor, short-circuit).
enum class Aggregate : unsigned char { sum, mul, avg, min, max, mand, mor };

// std::min / std::max, which ExprTk uses (NaN handling depends on the order).
inline double min2(double a, double b) noexcept {
    return b < a ? b : a;
}
inline double max2(double a, double b) noexcept {
    return a < b ? b : a;
}
// min or max of arg(0..n-1) grouped as ExprTk does: pairs for 4 and 5 arguments, else left
// to right.
template <typename Arg> double min_max(bool is_max, std::size_t n, Arg arg) noexcept {
    auto f = is_max ? max2 : min2;
    if (n == 4) return f(f(arg(0), arg(1)), f(arg(2), arg(3)));
    if (n == 5) return f(f(f(arg(0), arg(1)), f(arg(2), arg(3))), arg(4));
    double r = arg(0);
    for (std::size_t i = 1; i < n; ++i) r = f(r, arg(i));
    return r;
}
bool find_aggregate(std::string_view lower_name, Aggregate& out);

} // namespace beamctl::plc::detail
