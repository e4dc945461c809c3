// ExprTk's operators and math functions on doubles, shared by the constant folder (compile time)
// and the evaluator (RT, noexcept, allocation-free).
#pragma once

#include <cmath>
#include <cstddef>
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
