// The calc engine (pv/calc.hpp) against EPICS base: the tables of base's epicsCalcTest.cpp
// (expressions, bit operations, arg usage, bad expressions), then precedences, conditionals,
// assignments, literals, error positions, base's integer conversions, runtime failures, a seeded
// randomized comparison with a tree evaluator, and no allocation in perform().
#include "../alloc_counter.hpp"
#include "pv/calc.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>

using namespace beamctl::pv::calc;

namespace {

constexpr double Inf = std::numeric_limits<double>::infinity();
constexpr double NaN = std::numeric_limits<double>::quiet_NaN();

// Args as base's test sets them (A..L = 1..12), continued to U = 21.
void fill_args(double* args) {
    for (int i = 0; i < kArgs; ++i) args[i] = i + 1;
}

struct Outcome {
    bool compiled = false;
    bool performed = false;
    double value = NaN;
    CompileError error{};
    double args[kArgs];
};

// Compiles and performs `expr` on A..U = 1..21 with VAL = `val`.
Outcome run(std::string_view expr, double val = NaN) {
    Outcome o;
    fill_args(o.args);
    Program p;
    o.compiled = compile(expr, p, &o.error);
    o.value = val;
    if (o.compiled) o.performed = perform(p, o.args, &o.value);
    return o;
}

// The value of `expr`, a test failure if it does not compile and perform.
double calc(std::string_view expr) {
    Outcome o = run(expr);
    EXPECT_TRUE(o.compiled) << expr << ": " << o.error.message << " at " << o.error.position;
    EXPECT_TRUE(o.performed) << expr;
    return o.value;
}

// Base's comparison: within 1e-8 when both are finite, NaN for NaN, else equal.
bool matches(double expected, double got) {
    if (std::isfinite(expected) && std::isfinite(got)) return std::fabs(expected - got) < 1e-8;
    if (std::isnan(expected)) return std::isnan(got);
    return expected == got;
}

// The same double, NaN equal to NaN.
bool identical(double a, double b) {
    return (std::isnan(a) && std::isnan(b)) || std::memcmp(&a, &b, sizeof a) == 0;
}

uint32_t as_uint32(double v) {
    return v < 0 ? static_cast<uint32_t>(static_cast<int32_t>(v)) : static_cast<uint32_t>(v);
}

// -----------------------------------------------------------------------------------------------
// The expression table of EPICS base's epicsCalcTest.cpp (expected values from EPICS base
// epicsCalcTest.cpp). Most entries are also C++ expressions: CALC_EXPR evaluates the same text
// as C++ for the expected value, with these stand-ins for the calc names C++ lacks.
namespace base_table {

// clang-format off
constexpr double a = 1, b = 2, c = 3, d = 4, e = 5, f = 6, g = 7, h = 8, i = 9, j = 10, k = 11,
                 l = 12;
constexpr double PI = 3.14159265358979;
constexpr double D2R = PI / 180., R2D = 180. / PI;
double ABS(double x) { return std::fabs(x); }
double ATAN2(double x, double y) { return std::atan2(y, x); } // calc's argument order
double LN(double x) { return std::log(x); }
double LOG(double x) { return std::log10(x); }
double LOGE(double x) { return std::log(x); }
double NINT(double x) { return double(long(x >= 0 ? x + 0.5 : x - 0.5)); }
double SQR(double x) { return std::sqrt(x); }
double finite(double x) { return std::isfinite(x); }
double isinf(double x) { return std::isinf(x); }
double isnan(double x) { return std::isnan(x); }
double max2(double x, double y) { return x < y || std::isnan(y) ? y : x; }
double min2(double x, double y) { return y < x || std::isnan(y) ? y : x; }
double MAX(double x) { return x; }
template <class... T> double MAX(double x, double y, T... rest) { return MAX(max2(x, y), rest...); }
double MIN(double x) { return x; }
template <class... T> double MIN(double x, double y, T... rest) { return MIN(min2(x, y), rest...); }

struct Case {
    const char* expr;
    double expected;
};

#define CALC_EXPR(x) Case{#x, double(x)}
#define AND &
#define OR |
#define XOR ^
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wparentheses"
#pragma GCC diagnostic ignored "-Wbool-compare"
#pragma GCC diagnostic ignored "-Wint-in-bool-context"

const Case kExpressions[] = {
    // literals
    CALC_EXPR(0), CALC_EXPR(1), CALC_EXPR(2), CALC_EXPR(3), CALC_EXPR(4), CALC_EXPR(5),
    CALC_EXPR(6), CALC_EXPR(7), CALC_EXPR(8), CALC_EXPR(9), CALC_EXPR(.1), CALC_EXPR(0.1),
    CALC_EXPR(0X0), CALC_EXPR(0x10), CALC_EXPR(0x7fffffff), {"0x80000000", -2147483648.0},
    {"0xffffffff", -1}, CALC_EXPR(Inf), {"Infinity", Inf}, CALC_EXPR(NaN),
    // operands
    CALC_EXPR(a), CALC_EXPR(b), CALC_EXPR(c), CALC_EXPR(d), CALC_EXPR(e), CALC_EXPR(f),
    CALC_EXPR(g), CALC_EXPR(h), CALC_EXPR(i), CALC_EXPR(j), CALC_EXPR(k), CALC_EXPR(l),
    CALC_EXPR(PI), CALC_EXPR(D2R), CALC_EXPR(R2D),
    // unary minus
    CALC_EXPR(-1), CALC_EXPR(-Inf), CALC_EXPR(- -1), {"-0x80000000", 2147483648.0},
    // unary operators and functions
    CALC_EXPR((1)), CALC_EXPR(!0), CALC_EXPR(!1), CALC_EXPR(!!0), CALC_EXPR(ABS(1.0)),
    CALC_EXPR(ABS(-1.)), CALC_EXPR(acos(1.)), CALC_EXPR(asin(0.5)), CALC_EXPR(atan(0.5)),
    CALC_EXPR(ATAN2(1., 2.)), CALC_EXPR(ceil(0.5)), CALC_EXPR(cos(0.5)), CALC_EXPR(cosh(0.5)),
    CALC_EXPR(exp(1.)), CALC_EXPR(floor(1.5)), CALC_EXPR(fmod(1.5, 1.0)),
    CALC_EXPR(fmod(-1.5, 1.0)), CALC_EXPR(fmod(1.5, -1.0)), CALC_EXPR(fmod(-1.5, -1.0)),
    CALC_EXPR(fmod(1.5, 0.0)),
    CALC_EXPR(finite(0.)), CALC_EXPR(finite(Inf)), CALC_EXPR(finite(-Inf)),
    CALC_EXPR(finite(NaN)), {"finite(0,1,2)", 1}, {"finite(0,1,NaN)", 0},
    {"finite(0,NaN,2)", 0}, {"finite(NaN,1,2)", 0}, {"finite(0,1,Inf)", 0},
    {"finite(0,Inf,2)", 0}, {"finite(Inf,1,2)", 0}, {"finite(0,1,-Inf)", 0},
    {"finite(0,-Inf,2)", 0}, {"finite(-Inf,1,2)", 0},
    CALC_EXPR(isinf(0.)), CALC_EXPR(isinf(Inf)), CALC_EXPR(!!isinf(-Inf)), CALC_EXPR(isinf(NaN)),
    CALC_EXPR(isnan(0.)), CALC_EXPR(isnan(Inf)), CALC_EXPR(isnan(-Inf)), CALC_EXPR(!!isnan(NaN)),
    {"isnan(0,1,2)", 0}, {"isnan(0,1,NaN)", 1}, {"isnan(0,NaN,2)", 1}, {"isnan(NaN,1,2)", 1},
    {"isnan(0,1,Inf)", 0}, {"isnan(0,Inf,2)", 0}, {"isnan(Inf,1,2)", 0},
    {"isnan(0,1,-Inf)", 0}, {"isnan(0,-Inf,2)", 0}, {"isnan(-Inf,1,2)", 0},
    CALC_EXPR(LN(5.)), CALC_EXPR(LOG(5.)), CALC_EXPR(LOGE(2.)),
    CALC_EXPR(MAX(-99)), CALC_EXPR(MAX(1., 2.)), CALC_EXPR(MAX(1., Inf)),
    CALC_EXPR(MAX(1., -Inf)), CALC_EXPR(MAX(1., NaN)), CALC_EXPR(MAX(Inf, 1.)),
    CALC_EXPR(MAX(-Inf, 1.)), CALC_EXPR(MAX(NaN, 1.)), CALC_EXPR(MAX(1., 2., 3.)),
    CALC_EXPR(MAX(1., 3., 2.)), CALC_EXPR(MAX(2., 1., 3.)), CALC_EXPR(MAX(2., 3., 1.)),
    CALC_EXPR(MAX(3., 1., 2.)), CALC_EXPR(MAX(3., 2., 1.)), CALC_EXPR(MAX(1., 2., Inf)),
    CALC_EXPR(MAX(1., 2., -Inf)), CALC_EXPR(MAX(1., 2., NaN)), CALC_EXPR(MAX(1., Inf, 2.)),
    CALC_EXPR(MAX(1., -Inf, 2.)), CALC_EXPR(MAX(1., NaN, 2.)), CALC_EXPR(MAX(Inf, 1., 2.)),
    CALC_EXPR(MAX(-Inf, 1., 2.)), CALC_EXPR(MAX(NaN, 1., 2.)), CALC_EXPR(MAX(1., 2., 3., 4.)),
    CALC_EXPR(MAX(1., 2., 4., 3.)), CALC_EXPR(MAX(1., 4., 3., 2.)),
    CALC_EXPR(MAX(4., 2., 3., 1.)), CALC_EXPR(MAX(1., 2., 3., NaN)),
    CALC_EXPR(MAX(1., 2., NaN, 3.)), CALC_EXPR(MAX(1., NaN, 3., 2.)),
    CALC_EXPR(MAX(NaN, 2., 3., 1.)), CALC_EXPR(MAX(1., 2., 3., 4., 5.)),
    CALC_EXPR(MAX(1., 2., 3., 5., 4.)), CALC_EXPR(MAX(1., 2., 5., 4., 3.)),
    CALC_EXPR(MAX(1., 5., 3., 4., 2.)), CALC_EXPR(MAX(5., 2., 3., 4., 1.)),
    CALC_EXPR(MAX(1., 2., 3., 4., NaN)), CALC_EXPR(MAX(1., 2., 3., NaN, 4.)),
    CALC_EXPR(MAX(1., 2., NaN, 4., 3.)), CALC_EXPR(MAX(1., NaN, 3., 4., 2.)),
    CALC_EXPR(MAX(NaN, 2., 3., 4., 1.)), CALC_EXPR(MAX(1., 2., 3., 4., 5., 6.)),
    CALC_EXPR(MAX(1., 2., 3., 4., 6., 5.)), CALC_EXPR(MAX(1., 2., 3., 6., 5., 4.)),
    CALC_EXPR(MAX(1., 2., 6., 4., 5., 3.)), CALC_EXPR(MAX(1., 6., 3., 4., 5., 2.)),
    CALC_EXPR(MAX(6., 2., 3., 4., 5., 1.)), CALC_EXPR(MAX(1., 2., 3., 4., 5., NaN)),
    CALC_EXPR(MAX(1., 2., 3., 4., NaN, 5.)), CALC_EXPR(MAX(1., 2., 3., NaN, 5., 4.)),
    CALC_EXPR(MAX(1., 2., NaN, 4., 5., 3.)), CALC_EXPR(MAX(1., NaN, 3., 4., 5., 2.)),
    CALC_EXPR(MAX(NaN, 2., 3., 4., 5., 1.)), CALC_EXPR(MAX(1., 2., 3., 4., 5., Inf)),
    CALC_EXPR(MAX(1., 2., 3., 4., Inf, 5.)), CALC_EXPR(MAX(1., 2., 3., Inf, 5., 4.)),
    CALC_EXPR(MAX(1., 2., Inf, 4., 5., 3.)), CALC_EXPR(MAX(1., Inf, 3., 4., 5., 2.)),
    CALC_EXPR(MAX(Inf, 2., 3., 4., 5., 1.)), CALC_EXPR(MAX(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12)),
    CALC_EXPR(MAX(5, 4, 3, 2, 1, 0, -1, -2, -3, -4, -5, -6)), CALC_EXPR(MAX(-1, 1, 0)),
    CALC_EXPR(MIN(99)), CALC_EXPR(MIN(1., 2.)), CALC_EXPR(MIN(1., Inf)), CALC_EXPR(MIN(1., -Inf)),
    CALC_EXPR(MIN(1., NaN)), CALC_EXPR(MIN(NaN, 1.)), CALC_EXPR(MIN(1., 2., 3.)),
    CALC_EXPR(MIN(1., 3., 2.)), CALC_EXPR(MIN(2., 1., 3.)), CALC_EXPR(MIN(2., 3., 1.)),
    CALC_EXPR(MIN(3., 1., 2.)), CALC_EXPR(MIN(3., 2., 1.)), CALC_EXPR(MIN(1., 2., Inf)),
    CALC_EXPR(MIN(1., 2., -Inf)), CALC_EXPR(MIN(1., 2., NaN)), CALC_EXPR(MIN(1., Inf, 2.)),
    CALC_EXPR(MIN(1., -Inf, 2.)), CALC_EXPR(MIN(1., NaN, 2.)), CALC_EXPR(MIN(Inf, 1., 2.)),
    CALC_EXPR(MIN(-Inf, 1., 2.)), CALC_EXPR(MIN(NaN, 1., 2.)), CALC_EXPR(MIN(1., 2., 3., 4.)),
    CALC_EXPR(MIN(1., 2., 4., 3.)), CALC_EXPR(MIN(1., 4., 3., 2.)),
    CALC_EXPR(MIN(4., 2., 3., 1.)), CALC_EXPR(MIN(1., 2., 3., NaN)),
    CALC_EXPR(MIN(1., 2., NaN, 3.)), CALC_EXPR(MIN(1., NaN, 3., 2.)),
    CALC_EXPR(MIN(NaN, 2., 3., 1.)), CALC_EXPR(MIN(1., 2., 3., 4., 5.)),
    CALC_EXPR(MIN(1., 2., 3., 5., 4.)), CALC_EXPR(MIN(1., 2., 5., 4., 3.)),
    CALC_EXPR(MIN(1., 5., 3., 4., 2.)), CALC_EXPR(MIN(5., 2., 3., 4., 1.)),
    CALC_EXPR(MIN(1., 2., 3., 4., NaN)), CALC_EXPR(MIN(1., 2., 3., NaN, 4.)),
    CALC_EXPR(MIN(1., 2., NaN, 4., 3.)), CALC_EXPR(MIN(1., NaN, 3., 4., 2.)),
    CALC_EXPR(MIN(NaN, 2., 3., 4., 1.)), CALC_EXPR(MIN(1., 2., 3., 4., 5., 6.)),
    CALC_EXPR(MIN(2., 1., 3., 4., 5., 6.)), CALC_EXPR(MIN(3., 2., 1., 4., 5., 6.)),
    CALC_EXPR(MIN(4., 2., 3., 1., 5., 6.)), CALC_EXPR(MIN(5., 2., 3., 4., 1., 6.)),
    CALC_EXPR(MIN(6., 2., 3., 4., 5., 1.)), CALC_EXPR(MIN(1., 2., 3., 4., 5., NaN)),
    CALC_EXPR(MIN(1., 2., 3., 4., NaN, 5.)), CALC_EXPR(MIN(1., 2., 3., NaN, 5., 4.)),
    CALC_EXPR(MIN(1., 2., NaN, 4., 5., 3.)), CALC_EXPR(MIN(1., NaN, 3., 4., 5., 2.)),
    CALC_EXPR(MIN(NaN, 2., 3., 4., 5., 1.)), CALC_EXPR(MIN(1., 2., 3., 4., 5., -Inf)),
    CALC_EXPR(MIN(1., 2., 3., 4., -Inf, 5.)), CALC_EXPR(MIN(1., 2., 3., -Inf, 5., 4.)),
    CALC_EXPR(MIN(1., 2., -Inf, 4., 5., 3.)), CALC_EXPR(MIN(1., -Inf, 3., 4., 5., 2.)),
    CALC_EXPR(MIN(-Inf, 2., 3., 4., 5., 1.)), CALC_EXPR(MIN(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12)),
    CALC_EXPR(MIN(5, 4, 3, 2, 1, 0, -1, -2, -3, -4, -5, -6)), CALC_EXPR(MIN(1, -1, 0)),
    CALC_EXPR(MAX(MIN(0, 2), MAX(0), MIN(3, 2, 1))),
    CALC_EXPR(NINT(0.4)), CALC_EXPR(NINT(0.6)), CALC_EXPR(NINT(-0.4)), CALC_EXPR(NINT(-0.6)),
    CALC_EXPR(sin(0.5)), CALC_EXPR(sinh(0.5)), CALC_EXPR(SQR(10.)), CALC_EXPR(sqrt(16.)),
    CALC_EXPR(tan(0.5)), CALC_EXPR(tanh(0.5)), CALC_EXPR(~5), CALC_EXPR(~~5),
    // binary operators
    CALC_EXPR(0 != 1), CALC_EXPR(0 != 0), CALC_EXPR(1 != 0), CALC_EXPR(1 != 0 != 2),
    CALC_EXPR(0.0 != Inf), CALC_EXPR(0.0 != -Inf), CALC_EXPR(0.0 != NaN), CALC_EXPR(Inf != 0.0),
    CALC_EXPR(Inf != Inf), CALC_EXPR(Inf != -Inf), CALC_EXPR(Inf != NaN),
    CALC_EXPR(-Inf != 0.0), CALC_EXPR(-Inf != Inf), CALC_EXPR(-Inf != -Inf),
    CALC_EXPR(-Inf != NaN), CALC_EXPR(NaN != 0.0), CALC_EXPR(NaN != Inf),
    CALC_EXPR(NaN != -Inf), CALC_EXPR(NaN != NaN),
    {"0 # 1", 0 != 1}, {"0 # 0", 0 != 0}, {"1 # 0", 1 != 0}, {"1 # 0 # 2", 1 != 0 != 2},
    CALC_EXPR(7 % 4), CALC_EXPR(-7 % 4), CALC_EXPR(63 % 16 % 6), {"1 % 0", NaN},
    CALC_EXPR(7 & 4),
    CALC_EXPR(0 && 0), CALC_EXPR(0 && 1), CALC_EXPR(1 && 0), CALC_EXPR(1 && 1),
    CALC_EXPR(2 * 2), CALC_EXPR(0.0 * Inf), CALC_EXPR(0.0 * -Inf), CALC_EXPR(0.0 * NaN),
    CALC_EXPR(Inf * 0.0), CALC_EXPR(Inf * Inf), CALC_EXPR(Inf * -Inf), CALC_EXPR(Inf * NaN),
    CALC_EXPR(-Inf * 0.0), CALC_EXPR(-Inf * Inf), CALC_EXPR(-Inf * -Inf),
    CALC_EXPR(-Inf * NaN), CALC_EXPR(NaN * 0.0), CALC_EXPR(NaN * Inf), CALC_EXPR(NaN * -Inf),
    CALC_EXPR(NaN * NaN),
    {"2 ** 0.2", std::pow(2., 0.2)}, {"2 ** -0.2", std::pow(2., -0.2)},
    {"-0.2 ** 2", std::pow(-0.2, 2.)}, {"-0.2 ** -2", std::pow(-0.2, -2)},
    {"2 ** 2 ** 3", std::pow(std::pow(2., 2.), 3.)},
    CALC_EXPR(0 + 1), CALC_EXPR(0.0 + Inf), CALC_EXPR(0.0 + -Inf), CALC_EXPR(0.0 + NaN),
    CALC_EXPR(Inf + 0.0), CALC_EXPR(Inf + Inf), CALC_EXPR(Inf + -Inf), CALC_EXPR(Inf + NaN),
    CALC_EXPR(-Inf + 0.0), CALC_EXPR(-Inf + Inf), CALC_EXPR(-Inf + -Inf),
    CALC_EXPR(-Inf + NaN), CALC_EXPR(NaN + 0.0), CALC_EXPR(NaN + Inf), CALC_EXPR(NaN + -Inf),
    CALC_EXPR(NaN + NaN),
    CALC_EXPR(0 - 1), CALC_EXPR(0 - 1 - 2), CALC_EXPR(0.0 - Inf), CALC_EXPR(0.0 - -Inf),
    CALC_EXPR(0.0 - NaN), CALC_EXPR(Inf - 0.0), CALC_EXPR(Inf - Inf), CALC_EXPR(Inf - -Inf),
    CALC_EXPR(Inf - NaN), CALC_EXPR(-Inf - 0.0), CALC_EXPR(-Inf - Inf), CALC_EXPR(-Inf - -Inf),
    CALC_EXPR(-Inf - NaN), CALC_EXPR(NaN - 0.0), CALC_EXPR(NaN - Inf), CALC_EXPR(NaN - -Inf),
    CALC_EXPR(NaN - NaN),
    CALC_EXPR(2.0 / 3.0), CALC_EXPR(1.0 / 2.0 / 3.0), CALC_EXPR(0.0 / Inf),
    CALC_EXPR(0.0 / -Inf), CALC_EXPR(0.0 / NaN), CALC_EXPR(Inf / 1.0), CALC_EXPR(Inf / Inf),
    CALC_EXPR(Inf / -Inf), CALC_EXPR(Inf / NaN), CALC_EXPR(-Inf / 1.0), CALC_EXPR(-Inf / Inf),
    CALC_EXPR(-Inf / -Inf), CALC_EXPR(-Inf / NaN), CALC_EXPR(NaN / 1.0), CALC_EXPR(NaN / Inf),
    CALC_EXPR(NaN / -Inf), CALC_EXPR(NaN / NaN),
    CALC_EXPR(0 < 1), CALC_EXPR(0 < 0), CALC_EXPR(1 < 0), CALC_EXPR(2 < 0 < 2),
    CALC_EXPR(0.0 < Inf), CALC_EXPR(0.0 < -Inf), CALC_EXPR(0.0 < NaN), CALC_EXPR(Inf < 0.0),
    CALC_EXPR(Inf < Inf), CALC_EXPR(Inf < -Inf), CALC_EXPR(Inf < NaN), CALC_EXPR(-Inf < 0.0),
    CALC_EXPR(-Inf < Inf), CALC_EXPR(-Inf < -Inf), CALC_EXPR(-Inf < NaN), CALC_EXPR(NaN < 0.0),
    CALC_EXPR(NaN < Inf), CALC_EXPR(NaN < -Inf), CALC_EXPR(NaN < NaN),
    CALC_EXPR(1 << 2), CALC_EXPR(1 << 3 << 2),
    CALC_EXPR(0 <= 1), CALC_EXPR(0 <= 0), CALC_EXPR(1 <= 0), CALC_EXPR(3 <= 2 <= 3),
    CALC_EXPR(0.0 <= Inf), CALC_EXPR(0.0 <= -Inf), CALC_EXPR(0.0 <= NaN), CALC_EXPR(Inf <= 0.0),
    CALC_EXPR(Inf <= Inf), CALC_EXPR(Inf <= -Inf), CALC_EXPR(Inf <= NaN),
    CALC_EXPR(-Inf <= 0.0), CALC_EXPR(-Inf <= Inf), CALC_EXPR(-Inf <= -Inf),
    CALC_EXPR(-Inf <= NaN), CALC_EXPR(NaN <= 0.0), CALC_EXPR(NaN <= Inf),
    CALC_EXPR(NaN <= -Inf), CALC_EXPR(NaN <= NaN),
    {"0 = 1", 0 == 1}, {"0 = 0", 0 == 0}, {"1 = 0", 1 == 0}, {"2 = 2 = 1", 2 == 2 == 1},
    CALC_EXPR(0 == 1), CALC_EXPR(0 == 0), CALC_EXPR(1 == 0), CALC_EXPR(2 == 2 == 1),
    CALC_EXPR(0.0 == Inf), CALC_EXPR(0.0 == -Inf), CALC_EXPR(0.0 == NaN), CALC_EXPR(Inf == 0.0),
    CALC_EXPR(Inf == Inf), CALC_EXPR(Inf == -Inf), CALC_EXPR(Inf == NaN),
    CALC_EXPR(-Inf == 0.0), CALC_EXPR(-Inf == Inf), CALC_EXPR(-Inf == -Inf),
    CALC_EXPR(-Inf == NaN), CALC_EXPR(NaN == 0.0), CALC_EXPR(NaN == Inf),
    CALC_EXPR(NaN == -Inf), CALC_EXPR(NaN == NaN),
    CALC_EXPR(0 > 1), CALC_EXPR(0 > 0), CALC_EXPR(1 > 0), CALC_EXPR(2 > 0 > 2),
    CALC_EXPR(0.0 > Inf), CALC_EXPR(0.0 > -Inf), CALC_EXPR(0.0 > NaN), CALC_EXPR(Inf > 0.0),
    CALC_EXPR(Inf > Inf), CALC_EXPR(Inf > -Inf), CALC_EXPR(Inf > NaN), CALC_EXPR(-Inf > 0.0),
    CALC_EXPR(-Inf > Inf), CALC_EXPR(-Inf > -Inf), CALC_EXPR(-Inf > NaN), CALC_EXPR(NaN > 0.0),
    CALC_EXPR(NaN > Inf), CALC_EXPR(NaN > -Inf), CALC_EXPR(NaN > NaN),
    CALC_EXPR(0 >= 1), CALC_EXPR(0 >= 0), CALC_EXPR(1 >= 0), CALC_EXPR(3 >= 2 >= 3),
    CALC_EXPR(0.0 >= Inf), CALC_EXPR(0.0 >= -Inf), CALC_EXPR(0.0 >= NaN), CALC_EXPR(Inf >= 0.0),
    CALC_EXPR(Inf >= Inf), CALC_EXPR(Inf >= -Inf), CALC_EXPR(Inf >= NaN),
    CALC_EXPR(-Inf >= 0.0), CALC_EXPR(-Inf >= Inf), CALC_EXPR(-Inf >= -Inf),
    CALC_EXPR(-Inf >= NaN), CALC_EXPR(NaN >= 0.0), CALC_EXPR(NaN >= Inf),
    CALC_EXPR(NaN >= -Inf), CALC_EXPR(NaN >= NaN),
    CALC_EXPR(8 >> 1), {"8 >>> 1", 8u >> 1u}, CALC_EXPR(64 >> 2 >> 1),
    {"64 >>> 2 >>> 1", 64u >> 2u >> 1u},
    CALC_EXPR(7 AND 4), CALC_EXPR(1 OR 8), CALC_EXPR(3 XOR 9),
    {"2 ^ 0.2", std::pow(2., 0.2)}, {"2 ^ -0.2", std::pow(2., -0.2)},
    {"(-0.2) ^ 2", std::pow(-0.2, 2.)}, {"(-0.2) ^ -2", std::pow(-0.2, -2.)},
    {"2 ^ 2 ^ 3", std::pow(std::pow(2., 2.), 3.)},
    CALC_EXPR(1 | 8), CALC_EXPR(0 || 0), CALC_EXPR(0 || 1), CALC_EXPR(1 || 0), CALC_EXPR(1 || 1),
    // conditionals
    CALC_EXPR(0 ? 1 : 2), CALC_EXPR(1 ? 1 : 2), CALC_EXPR(Inf ? 1 : 2), CALC_EXPR(NaN ? 1 : 2),
    CALC_EXPR(0 ? 0 ? 2 : 3 : 4), CALC_EXPR(0 ? 1 ? 2 : 3 : 4), CALC_EXPR(1 ? 0 ? 2 : 3 : 4),
    CALC_EXPR(1 ? 1 ? 2 : 3 : 4), CALC_EXPR(0 ? 2 : 0 ? 3 : 4), CALC_EXPR(0 ? 2 : 1 ? 3 : 4),
    CALC_EXPR(1 ? 2 : 0 ? 3 : 4), CALC_EXPR(1 ? 2 : 1 ? 3 : 4),
    // assignments and statements
    {"a := 0; a", 0}, {"b := 0; b", 0}, {"c := 0; c", 0}, {"d := 0; d", 0}, {"e := 0; e", 0},
    {"f := 0; f", 0}, {"g := 0; g", 0}, {"h := 0; h", 0}, {"i := 0; i", 0}, {"j := 0; j", 0},
    {"k := 0; k", 0}, {"l := 0; l", 0},
    {"a; a := 0", a}, {"b; b := 0", b}, {"c; c := 0", c}, {"d; d := 0", d}, {"e; e := 0", e},
    {"f; f := 0", f}, {"g; g := 0", g}, {"h; h := 0", h}, {"i; i := 0", i}, {"j; j := 0", j},
    {"k; k := 0", k}, {"l; l := 0", l},
    // relative precedences
    CALC_EXPR(0 ? 1 : 2 | 4), CALC_EXPR(1 ? 1 : 2 | 4), CALC_EXPR(0 ? 2 | 4 : 1),
    CALC_EXPR(1 ? 2 | 4 : 1), CALC_EXPR(0 ? 1 : 2 & 3), CALC_EXPR(1 ? 1 : 2 & 3),
    CALC_EXPR(0 ? 2 & 3 : 1), CALC_EXPR(1 ? 2 & 3 : 1), CALC_EXPR(0 ? 2 : 3 >= 1),
    CALC_EXPR(0 ? 3 >= 1 : 2), CALC_EXPR(1 ? 0 == 1 : 2), CALC_EXPR(1 ? 2 : 0 == 1),
    CALC_EXPR(0 ? 1 : 2 + 4), CALC_EXPR(1 ? 1 : 2 + 4), CALC_EXPR(0 ? 2 + 4 : 1),
    CALC_EXPR(1 ? 2 + 4 : 1), CALC_EXPR(0 ? 1 : 2 * 4), CALC_EXPR(1 ? 1 : 2 * 4),
    CALC_EXPR(0 ? 2 * 4 : 1), CALC_EXPR(1 ? 2 * 4 : 1),
    {"0 ? 1 : 2 ** 3", 8}, {"1 ? 1 : 2 ** 3", 1}, {"0 ? 2 ** 3 : 1", 1}, {"1 ? 2 ** 3 : 1", 8},
    {"1 | 3 XOR 1", (1 | 3) ^ 1}, CALC_EXPR(1 XOR 3 | 1), CALC_EXPR(3 | 1 & 2),
    CALC_EXPR(2 | 4 > 3), CALC_EXPR(2 OR 4 > 3), CALC_EXPR(2 XOR 3 >= 0), CALC_EXPR(2 | 1 - 3),
    CALC_EXPR(2 | 4 / 2), {"1 | 2 ** 3", double(1 | (int)std::pow(2., 3.))}, CALC_EXPR(3 << 2 & 10),
    {"18 & 6 << 2", (18 & 6) << 2}, CALC_EXPR(36 >> 2 & 10), {"36 >>> 2 & 10", 36u >> 2u & 10u},
    {"18 & 20 >> 2", (18 & 20) >> 2}, {"18 & 20 >>> 2", (18u & 20u) >> 2},
    CALC_EXPR(3 & 4 == 4), CALC_EXPR(3 AND 4 == 4), {"1 << 2 != 4", 1 << (2 != 4)},
    {"16 >> 2 != 4", 16 >> (2 != 4)}, {"16 >>> 2 != 4", 16u >> (2 != 4)}, CALC_EXPR(3 AND -2),
    CALC_EXPR(0 < 1 ? 2 : 3), CALC_EXPR(1 <= 0 ? 2 : 3), CALC_EXPR(0 + -1), CALC_EXPR(0 - -1),
    CALC_EXPR(10 + 10 * 2), CALC_EXPR(20 + 20 / 2), CALC_EXPR(-1 + 1), CALC_EXPR(-1 - 2),
    {"-2 ** 2", std::pow(-2., 2.)}, {"-2 ^ 2", std::pow(-2., 2.)},
    // parentheses
    {"(1 | 2) ** 3", std::pow((double)(1 | 2), 3.)},
    {"1+(1|2)**3", 1 + std::pow((double)(1 | 2), 3.)},
    CALC_EXPR(1 + (1 ? (1 < 2) : (1 > 2)) * 2),
};

#pragma GCC diagnostic pop
#undef AND
#undef OR
#undef XOR
#undef CALC_EXPR
// clang-format on

struct BitsCase {
    const char* expr;
    uint32_t expected;
};
// Bit operations around bit 31 (base's bug lp:1514520).
const BitsCase kBits[] = {
    {"0xaaaaaaaa AND 0xffff0000", 0xaaaa0000u},
    {"0xaaaaaaaa OR 0xffff0000", 0xffffaaaau},
    {"0xaaaaaaaa XOR 0xffff0000", 0x5555aaaau},
    {"~0xaaaaaaaa", 0x55555555u},
    {"~~0xaaaaaaaa", 0xaaaaaaaau},
    {"0xaaaaaaaa >> 8", 0xffaaaaaau},
    {"0x55555555 >> 8", 0x00555555u},
    {"0xaaaaaaaa >>> 8", 0x00aaaaaau},
    {"0x55555555 >>> 8", 0x00555555u},
    {"0xaaaaaaaa << 8", 0xaaaaaa00u},
    {"0x55555555 << 8", 0x55555500u},
    {"a:=0xaaaaaaaa; b:=0xffff0000; a AND b", 0xaaaa0000u},
    {"a:=0xaaaaaaaa; b:=0xffff0000; a OR b", 0xffffaaaau},
    {"a:=0xaaaaaaaa; b:=0xffff0000; a XOR b", 0x5555aaaau},
    {"a:=0xaaaaaaaa; ~a", 0x55555555u},
    {"a:=0xaaaaaaaa; ~~a", 0xaaaaaaaau},
    {"a:=0xaaaaaaaa; a >> 8", 0xffaaaaaau},
    {"a:=0xaaaaaaaa; a >>> 8", 0x00aaaaaau},
    {"a:=0xaaaaaaaa; a << 8", 0xaaaaaa00u},
    {"a:=0x55555555; a >> 8", 0x00555555u},
    {"a:=0x55555555; a >>> 8", 0x00555555u},
    {"a:=0x55555555; a << 8", 0x55555500u},
    {"-1431655766.1 OR 0", 0xaaaaaaaau},
    {"2863311530.1 OR 0", 0xaaaaaaaau},
    {"0 OR -1431655766.1", 0xaaaaaaaau},
    {"0 OR 2863311530.1", 0xaaaaaaaau},
    {"-1431655766.1 XOR 0", 0xaaaaaaaau},
    {"2863311530.1 XOR 0", 0xaaaaaaaau},
    {"0 XOR -1431655766.1", 0xaaaaaaaau},
    {"0 XOR 2863311530.1", 0xaaaaaaaau},
    {"-1431655766.1 AND 0xffffffff", 0xaaaaaaaau},
    {"2863311530.1 AND 0xffffffff", 0xaaaaaaaau},
    {"0xffffffff AND -1431655766.1", 0xaaaaaaaau},
    {"0xffffffff AND 2863311530.1", 0xaaaaaaaau},
    {"~ -1431655766.1", 0x55555555u},
    {"~ 2863311530.1", 0x55555555u},
    {"-1431655766.1 >> 0", 0xaaaaaaaau},
    {"-1431655766.1 >>> 0", 0xaaaaaaaau},
    {"2863311530.1 >> 0", 0xaaaaaaaau},
    {"2863311530.1 >>> 0", 0xaaaaaaaau},
    {"-1431655766.1 >> 0.1", 0xaaaaaaaau},
    {"-1431655766.1 >>> 0.1", 0xaaaaaaaau},
    {"2863311530.1 >> 0.1", 0xaaaaaaaau},
    {"2863311530.1 >>> 0.1", 0xaaaaaaaau},
    {"-1431655766.1 << 0", 0xaaaaaaaau},
    {"2863311530.1 << 0", 0xaaaaaaaau},
    {"-1431655766.1 << 0.1", 0xaaaaaaaau},
    {"2863311530.1 << 0.1", 0xaaaaaaaau},
};

struct ArgsCase {
    const char* expr;
    uint32_t inputs, stores;
};
constexpr uint32_t bit(char arg) {
    return 1u << (arg - 'A');
}
const ArgsCase kArgUsage[] = {
    {"a", bit('A'), 0},
    {"A", bit('A'), 0},
    {"B", bit('B'), 0},
    {"C", bit('C'), 0},
    {"D", bit('D'), 0},
    {"E", bit('E'), 0},
    {"F", bit('F'), 0},
    {"G", bit('G'), 0},
    {"H", bit('H'), 0},
    {"I", bit('I'), 0},
    {"J", bit('J'), 0},
    {"K", bit('K'), 0},
    {"L", bit('L'), 0},
    {"A+B+C+D+E+F+G+H+I+J+K+L", 0xfff, 0},
    {"0.1;A:=0", 0, bit('A')},
    {"1.1;B:=0", 0, bit('B')},
    {"2.1;C:=0", 0, bit('C')},
    {"3.1;D:=0", 0, bit('D')},
    {"4.1;E:=0", 0, bit('E')},
    {"5.1;F:=0", 0, bit('F')},
    {"6.1;G:=0", 0, bit('G')},
    {"7.1;H:=0", 0, bit('H')},
    {"8.1;I:=0", 0, bit('I')},
    {"9.1;J:=0", 0, bit('J')},
    {"10.1;K:=0", 0, bit('K')},
    {"11.1;L:=0", 0, bit('L')},
    {"12.1;A:=0;B:=A;C:=B;D:=C", 0, bit('A') | bit('B') | bit('C') | bit('D')},
    {"13.1;B:=A;A:=B;C:=D;D:=C", bit('A') | bit('D'), bit('A') | bit('B') | bit('C') | bit('D')},
};

struct BadCase {
    const char* expr;
    Errc code;
    std::size_t position; // ours: base reports no position
};
const BadCase kBad[] = {
    {"0x0.1", Errc::Syntax, 3},     {"1*", Errc::Incomplete, 2},    {"*1", Errc::Syntax, 0},
    {"MIN", Errc::Incomplete, 3},   {"MIN()", Errc::Syntax, 4},     {"MIN(A,)", Errc::Syntax, 6},
    {"MIN(A,B,)", Errc::Syntax, 8}, {"MAX", Errc::Incomplete, 3},   {"MAX()", Errc::Syntax, 4},
    {"MAX(A,)", Errc::Syntax, 6},   {"MAX(A,B,)", Errc::Syntax, 8}, {"1?", Errc::Conditional, 1},
    {"1?1", Errc::Conditional, 1},  {":1", Errc::Syntax, 0},        {"0,", Errc::BadSeparator, 1},
    {"0)", Errc::ParenNotOpen, 1},
};

} // namespace base_table

TEST(CalcBaseTable, Expressions) {
    for (const auto& c : base_table::kExpressions) {
        Outcome o = run(c.expr);
        EXPECT_TRUE(o.compiled) << c.expr << ": " << o.error.message;
        EXPECT_TRUE(o.performed) << c.expr;
        EXPECT_TRUE(matches(c.expected, o.value))
            << c.expr << ": expected " << c.expected << ", got " << o.value;
    }
}

TEST(CalcBaseTable, BitOperationsAroundBit31) {
    for (const auto& c : base_table::kBits)
        EXPECT_EQ(as_uint32(calc(c.expr)), c.expected) << c.expr;
}

TEST(CalcBaseTable, ArgUsage) {
    for (const auto& c : base_table::kArgUsage) {
        Program p;
        ASSERT_TRUE(compile(c.expr, p)) << c.expr;
        uint32_t inputs = 0xdead, stores = 0xbeef;
        arg_usage(p, &inputs, &stores);
        EXPECT_EQ(inputs, c.inputs) << c.expr;
        EXPECT_EQ(stores, c.stores) << c.expr;
    }
}

TEST(CalcBaseTable, BadExpressions) {
    for (const auto& c : base_table::kBad) {
        Program p;
        CompileError err{};
        EXPECT_FALSE(compile(c.expr, p, &err)) << c.expr;
        EXPECT_EQ(err.code, c.code) << c.expr << ": " << err.message;
        EXPECT_EQ(err.position, c.position) << c.expr << ": " << err.message;
        EXPECT_TRUE(p.empty());
    }
}

TEST(CalcBaseTable, RandomIsWithinZeroToOne) {
    double lowest = 1, highest = 0;
    for (int n = 0; n < 10000; ++n) {
        double r = calc("rndm");
        ASSERT_GE(r, 0.0);
        ASSERT_LT(r, 1.0);
        lowest = std::min(lowest, r);
        highest = std::max(highest, r);
    }
    EXPECT_LT(lowest, 0.01);
    EXPECT_GT(highest, 0.99);
}

// -----------------------------------------------------------------------------------------------

TEST(CalcLanguage, Precedence) {
    EXPECT_EQ(calc("1+2*3"), 7);
    EXPECT_EQ(calc("(1+2)*3"), 9);
    EXPECT_EQ(calc("7-2-1"), 4);       // left-associative
    EXPECT_EQ(calc("2^3^2"), 64);      // power is left-associative too: (2^3)^2
    EXPECT_EQ(calc("-2^2"), 4);        // unary minus binds tighter than power
    EXPECT_EQ(calc("2*3^2"), 18);      // power above * / %
    EXPECT_EQ(calc("1+2<4"), 1);       // + - above comparisons
    EXPECT_EQ(calc("1<2 && 0"), 0);    // comparisons above && & << >>
    EXPECT_EQ(calc("1 << 2 < 8"), 2);  // ... so this is 1 << (2 < 8)
    EXPECT_EQ(calc("1 || 0 && 0"), 1); // && above ||
    EXPECT_EQ(calc("0 && 0 || 1"), 1);
    EXPECT_EQ(calc("6 & 3 | 8"), 10); // & above | XOR OR
    EXPECT_EQ(calc("!0+1"), 2);       // ! binds to its operand
    EXPECT_EQ(calc("~0*2"), -2);
    EXPECT_EQ(calc("1 ? 2 : 3 + 10"), 2); // ?: below everything
    EXPECT_EQ(calc("SIN 0 + 1"), 1);      // a function without parentheses takes one operand
    EXPECT_EQ(calc("ABS -3"), 3);
    EXPECT_EQ(calc("-(2+3)*2"), -10);
    EXPECT_EQ(calc("10 % 4 * 3"), 6);
}

TEST(CalcLanguage, ConditionalsNest) {
    // A=1, B=2, C=3
    EXPECT_EQ(calc("A>B ? 10 : B>C ? 20 : C>A ? 30 : 40"), 30);
    EXPECT_EQ(calc("A ? B ? C ? 1 : 2 : 3 : 4"), 1);
    EXPECT_EQ(calc("A ? (B-B ? 1 : 2) : 3"), 2);
    EXPECT_EQ(calc("(A-A ? 1 : 2) + (A ? 10 : 20)"), 12);
    EXPECT_EQ(calc("MAX(A?5:6, A-A?7:8)"), 8);
    EXPECT_EQ(calc("0 ? MAX(1,2,3) : MIN(4,5)"), 4); // the skipped branch's counts are stepped over
    EXPECT_EQ(calc("1 ? 0x10 : 2.5"), 16);
    EXPECT_EQ(calc("0 ? 2.5 : 0 ? 1 : 0 ? 2 : 3"), 3);
    // Base quirks that follow from its translation: parentheses may split a conditional.
    EXPECT_EQ(calc("(1?2):3"), 2);
    EXPECT_EQ(calc("1?(2:3)"), 2);
}

TEST(CalcLanguage, AssignmentsStoreInTheArgs) {
    Outcome o = run("A:=A+1;B:=2;A*B");
    ASSERT_TRUE(o.performed);
    EXPECT_EQ(o.value, 4);
    EXPECT_EQ(o.args[0], 2);
    EXPECT_EQ(o.args[1], 2);
    EXPECT_EQ(o.args[2], 3); // untouched

    o = run("U:=M+N; T:=U*2; T");
    EXPECT_EQ(o.value, 54);
    EXPECT_EQ(o.args[20], 27);
    EXPECT_EQ(o.args[19], 54);

    EXPECT_EQ(calc("a := 5 ; b := a ; a + b"), 10); // blanks around := and ;
    EXPECT_EQ(calc("(A):=7;A"), 7);                 // base accepts a parenthesised target
    EXPECT_EQ(calc("C; C:=0"), 3);                  // the result may come first

    // The same program keeps counting when performed again on the same args.
    Program p;
    ASSERT_TRUE(compile("A:=A+1;A", p));
    double args[kArgs] = {};
    double v = 0;
    for (int n = 1; n <= 3; ++n) {
        ASSERT_TRUE(perform(p, args, &v));
        EXPECT_EQ(v, n);
    }
}

TEST(CalcLanguage, ValIsThePreviousResult) {
    Program p;
    ASSERT_TRUE(compile("VAL+1", p));
    double args[kArgs] = {};
    double v = 10;
    ASSERT_TRUE(perform(p, args, &v));
    EXPECT_EQ(v, 11);
    ASSERT_TRUE(perform(p, args, &v));
    EXPECT_EQ(v, 12);
    EXPECT_EQ(run("val*2", 3.5).value, 7);
}

TEST(CalcLanguage, ArgsAToUAndNamesThatStartWithTheirLetters) {
    EXPECT_EQ(calc("M+N+O+P+Q+R+S+T+U"), 153);
    EXPECT_EQ(calc("m*u"), 13 * 21);
    EXPECT_EQ(calc("NOTA"), ~1);            // the longest name wins: NOT A
    EXPECT_EQ(calc("SINA"), std::sin(1.0)); // SIN A
    EXPECT_EQ(calc("N+NINT(2.6)"), 14 + 3);
    EXPECT_EQ(calc("P*PI"), 16 * 3.14159265358979323);
    EXPECT_EQ(calc("R*R2D"), 18 * (180. / 3.14159265358979323));
    EXPECT_EQ(calc("T+TAN(0)"), 20);
    EXPECT_FALSE(run("PIA").compiled); // PI then A: an operator is missing
    EXPECT_FALSE(run("V").compiled);   // V..Z are no args
    EXPECT_FALSE(run("Z").compiled);
}

TEST(CalcLanguage, CaseAndBlanks) {
    EXPECT_EQ(calc("Sin(0)+cOs(0)+ABS(-1)+abs(-1)"), 3);
    EXPECT_EQ(calc("a AND b or C xor D"), ((1 & 2) | 3) ^ 4);
    EXPECT_EQ(calc(" \t1\n+\r2 "), 3);
    EXPECT_EQ(calc("max ( 1 , 2 )"), 2);
    EXPECT_FALSE(run("1 2").compiled);
    EXPECT_FALSE(run("* *2").compiled);    // "* *" is not "**"
    EXPECT_FALSE(run("A : = 1").compiled); // nor ": =" ":="
    EXPECT_FALSE(run("1 > = 2").compiled);
}

TEST(CalcLanguage, Literals) {
    EXPECT_EQ(calc("1.5e3"), 1500);
    EXPECT_EQ(calc("1.5E-3"), 0.0015);
    EXPECT_EQ(calc(".5"), 0.5);
    EXPECT_EQ(calc("5."), 5);
    EXPECT_EQ(calc("007"), 7);
    EXPECT_EQ(calc("0x1F"), 31);
    EXPECT_EQ(calc("0XfF"), 255);
    EXPECT_EQ(calc("0x80000000"), -2147483648.0); // 32 bits, signed
    EXPECT_EQ(calc("0xFFFFFFFF00000001"), 1);     // passes base's range check as "negative"
    EXPECT_EQ(calc("0xor1"), 1);                  // 0 XOR 1: "0x" without digits is 0
    EXPECT_TRUE(std::isinf(calc("INF")));
    EXPECT_TRUE(std::isinf(calc("infinity")));
    EXPECT_TRUE(std::isnan(calc("nan")));
    EXPECT_TRUE(std::isnan(calc("NaN(123)")));
    EXPECT_EQ(calc("-Inf < 0"), 1);
    EXPECT_NEAR(calc("2*PI - D2R*360"), 0, 1e-15);
    EXPECT_NEAR(calc("R2D*D2R"), 1, 1e-15);

    for (const char* bad :
         {"1e999", "1e-400", "1e-320", ".", ".e1", "0x100000000", "0x10000000000000000"}) {
        Outcome o = run(bad);
        EXPECT_FALSE(o.compiled) << bad;
        EXPECT_EQ(o.error.code, Errc::BadLiteral) << bad;
        EXPECT_EQ(o.error.position, 0u) << bad;
    }
    EXPECT_EQ(run("1+1e999").error.position, 2u);
    EXPECT_EQ(run("1e").error.code, Errc::Syntax); // "1" then "e" where an operator belongs
    EXPECT_EQ(run("1.5.3").error.code, Errc::Syntax);
}

TEST(CalcLanguage, FunctionsNotInTheTable) {
    EXPECT_NEAR(calc("log(100)+ln(1)+loge(exp(2))"), 4, 1e-12);
    EXPECT_EQ(calc("sqr(16)+sqrt(9)"), 7);
    EXPECT_EQ(calc("atan2(1,0)"), 0); // atan2(0, 1): arguments reversed
    EXPECT_NEAR(calc("atan2(0,1)"), std::numbers::pi / 2, 1e-15);
    EXPECT_EQ(calc("fmod(7,3)"), 1);
    EXPECT_EQ(calc("max(3)"), 3);
    EXPECT_EQ(calc("MAX A"), 1); // vararg without parentheses: one argument
    EXPECT_EQ(calc("MIN(U,T,S,R,Q,P,O,N,M,L,K,J,I,H,G,F,E,D,C,B,A)"), 1);
    EXPECT_EQ(calc("isinf(-Inf)"), -1); // glibc's isinf(), as base calls it
    EXPECT_EQ(calc("isinf(Inf)"), 1);
    EXPECT_EQ(calc("finite(1,2,3,4)"), 1);
}

// -----------------------------------------------------------------------------------------------

TEST(CalcPerform, IntegerConversionsAsBaseOnX86_64) {
    // NINT rounds half away from zero through a 32-bit integer.
    EXPECT_EQ(calc("NINT(2.5)"), 3);
    EXPECT_EQ(calc("NINT(-2.5)"), -3);
    EXPECT_EQ(calc("NINT(0.49999999999999994)"), 1); // x + 0.5 rounds up in double
    EXPECT_EQ(calc("NINT(3e9)"), -2147483648.0);
    EXPECT_EQ(calc("NINT(NaN)"), -2147483648.0);
    // % truncates both operands to int32; a divisor that truncates to 0 gives NaN.
    EXPECT_EQ(calc("-7 % 4"), -3);
    EXPECT_EQ(calc("7.9 % 4.9"), 3);
    EXPECT_TRUE(std::isnan(calc("5 % 0.5")));
    EXPECT_EQ(calc("NaN % 3"), -2); // INT32_MIN % 3
    EXPECT_EQ(calc("5 % NaN"), 5);
    EXPECT_EQ(calc("7 % -1"), 0);
    EXPECT_EQ(calc("-2147483648 % -1"), 0); // base traps with SIGFPE here
    EXPECT_EQ(calc("NaN % -1"), 0);
    // Bit operands: negative ones as int32 (INT32_MIN when out of range), others modulo 2^32
    // below 2^63 and 0 above (and for NaN, +Inf).
    EXPECT_EQ(calc("NaN | 0"), 0);
    EXPECT_EQ(calc("Inf | 0"), 0);
    EXPECT_EQ(calc("-Inf | 0"), -2147483648.0);
    EXPECT_EQ(calc("-3e9 | 0"), -2147483648.0);
    EXPECT_EQ(calc("4294967297 | 0"), 1);
    EXPECT_EQ(calc("1e19 | 0"), 0);
    EXPECT_EQ(calc("~NaN"), -1);
    // Shift counts use their low 5 bits.
    EXPECT_EQ(calc("1 << 32"), 1);
    EXPECT_EQ(calc("1 << 33"), 2);
    EXPECT_EQ(calc("1 << -1"), -2147483648.0);
    EXPECT_EQ(calc("-1 >> 1"), -1);
    EXPECT_EQ(calc("-1 >>> 1"), 2147483647);
    EXPECT_EQ(calc("-8 >>> 28"), 15);
    // Logic: any non-zero (NaN too) is true.
    EXPECT_EQ(calc("NaN && 1"), 1);
    EXPECT_EQ(calc("!NaN"), 0);
    EXPECT_EQ(calc("NaN ? 1 : 2"), 1);
}

TEST(CalcPerform, FailuresLeaveTheResultAlone) {
    double args[kArgs] = {};
    double v = 42;
    EXPECT_FALSE(perform(Program{}, args, &v));
    EXPECT_EQ(v, 42);

    // The count of a vararg function is fixed when compiled; a conditional can supply fewer.
    Program p;
    ASSERT_TRUE(compile("MAX(A?2,3:4)", p));
    args[0] = 1;
    ASSERT_TRUE(perform(p, args, &v));
    EXPECT_EQ(v, 3);
    args[0] = 0;
    v = 42;
    EXPECT_FALSE(perform(p, args, &v));
    EXPECT_EQ(v, 42);

    // Compiles in base: the lone ATAN2 reads base's unused stack slot, and the 2 is the result.
    EXPECT_EQ(calc("ATAN2(1);2"), 2);
    EXPECT_EQ(calc("FMOD 1;FMOD 2;3"), 3);
}

TEST(CalcPerform, HandMadeCodeCannotOverrun) {
    double args[kArgs] = {};
    double v = 0;
    std::mt19937 rng(7);
    for (int n = 0; n < 100000; ++n) {
        Program p;
        p.code.resize(rng() % 40);
        for (auto& byte : p.code) byte = static_cast<unsigned char>(rng());
        (void)perform(p, args, &v); // must not crash (ASan checks) nor hang
        uint32_t in, st;
        arg_usage(p, &in, &st);
    }
    // A literal cut short.
    Program p;
    ASSERT_TRUE(compile("2.5", p));
    p.code.resize(4);
    EXPECT_FALSE(perform(p, args, &v));
}

TEST(CalcPerform, DoesNotAllocate) {
    Program p;
    ASSERT_TRUE(compile("A:=A+1;B:=RNDM;MAX(A,B,C)*SIN(A*D2R)+(A>2?VAL:FMOD(A,3))", p));
    double args[kArgs] = {};
    double v = 0;
    ASSERT_TRUE(perform(p, args, &v));
    beamctl::test::count_allocations(true);
    bool ok = true;
    for (int n = 0; n < 10000; ++n) ok = perform(p, args, &v) && ok;
    uint32_t in, st;
    arg_usage(p, &in, &st);
    beamctl::test::count_allocations(false);
    EXPECT_TRUE(ok);
    EXPECT_EQ(beamctl::test::allocations(), 0);
    EXPECT_EQ(args[0], 10001);
}

// -----------------------------------------------------------------------------------------------

TEST(CalcErrors, CodesAndPositions) {
    struct Case {
        const char* expr;
        Errc code;
        std::size_t position;
    };
    const Case cases[] = {
        {"", Errc::Empty, 0},
        {"   ", Errc::Incomplete, 3},
        {"A+", Errc::Incomplete, 2},
        {"A;", Errc::Incomplete, 2},   // no trailing ';'
        {"A:=1", Errc::Incomplete, 4}, // one statement must give the result
        {"A;B", Errc::Incomplete, 3},
        {"A;B;C:=1", Errc::TooMany, 3},
        {"(1,2)", Errc::Incomplete, 5},
        {"SIN(1,2)", Errc::Incomplete, 8},
        {"ATAN2(1)", Errc::Incomplete, 8},
        {"ATAN2(1,2,3)", Errc::Incomplete, 12},
        {"FMOD(FMOD(1))+1", Errc::Underflow, 13},
        {"1+(2*3", Errc::ParenOpen, 2}, // at the '(' left open
        {"(1;2", Errc::ParenOpen, 0},
        {"1+2)", Errc::ParenNotOpen, 3},
        {"A:=1)", Errc::ParenNotOpen, 4},
        {"1,2", Errc::BadSeparator, 1},
        {"A:=1,2", Errc::BadSeparator, 4},
        {"1 ? 2", Errc::Conditional, 2}, // at the '?' without ':'
        {"1 ? 2 : 3 : 4", Errc::Conditional, 10},
        {"1?2;3", Errc::Conditional, 1},
        {"1 ? (2 ? 3) : 4", Errc::Conditional, 2}, // the ":" closes the inner "?"
        {"1:=2", Errc::BadAssignment, 1},
        {"PI:=2;1", Errc::BadAssignment, 2},
        {"VAL:=2;1", Errc::BadAssignment, 3},
        {"-A:=2;1", Errc::BadAssignment, 2},
        {"B+A:=2;1", Errc::BadAssignment, 3},
        {"A:=B:=2;1", Errc::BadAssignment, 4},
        {"A+=1", Errc::Syntax, 2},
        {"A $ B", Errc::Syntax, 2},
        {"V+1", Errc::Syntax, 0},
        {"1 + xyz", Errc::Syntax, 4},
        {"1 + foo", Errc::Syntax, 5}, // F, then no operator "oo"
        {"MAX()", Errc::Syntax, 4},
        {"A;;B", Errc::Syntax, 2},
        {";A", Errc::Syntax, 0},
        {"1 ! = 2", Errc::Syntax, 2},
        {"0x", Errc::Syntax, 1},
        {"1e400", Errc::BadLiteral, 0},
    };
    for (const auto& c : cases) {
        Outcome o = run(c.expr);
        EXPECT_FALSE(o.compiled) << c.expr;
        EXPECT_EQ(o.error.code, c.code) << c.expr << ": " << o.error.message;
        EXPECT_EQ(o.error.position, c.position) << c.expr << ": " << o.error.message;
        EXPECT_FALSE(o.error.message.empty());
    }
}

TEST(CalcErrors, MessagesSayWhat) {
    Outcome o = run("1 + xyz");
    EXPECT_EQ(o.error.message, "Syntax error: expected an operand at 'xyz'");
    o = run("A B");
    EXPECT_EQ(o.error.message, "Syntax error: expected an operator at 'B'");
    o = run("1e999");
    EXPECT_EQ(o.error.message, "Bad number: '1e999' is malformed or out of range");
    o = run("1 ? (2 : 3");
    EXPECT_EQ(o.error.message, "'(' not closed");
    EXPECT_EQ(o.error.position, 4u);
    o = run("A:=B:=1;2");
    EXPECT_EQ(o.error.message,
              "Bad assignment: ':=' must follow one of A..U at the start of a statement");
    EXPECT_STREQ(errc_text(Errc::Conditional), "Unpaired conditional");
}

TEST(CalcErrors, AFailedCompileKeepsTheProgram) {
    Program p;
    ASSERT_TRUE(compile("A+1", p));
    const auto code = p.code;
    EXPECT_FALSE(compile("A+", p));
    EXPECT_EQ(p.code, code);
    EXPECT_FALSE(compile("A+1", p, nullptr, 2)); // a null error is fine
}

TEST(CalcCompile, LengthLimitIsTheCalcField) {
    std::string fits = "1";
    while (fits.size() < kMaxInfix - 1) fits += "+1";
    fits.resize(kMaxInfix - 1);
    if (fits.back() == '+') fits.back() = ' ';
    EXPECT_EQ(calc(fits), 40);

    Program p;
    CompileError err{};
    std::string too_long = fits + "1";
    EXPECT_FALSE(compile(too_long, p, &err));
    EXPECT_EQ(err.code, Errc::TooLong);
    EXPECT_EQ(err.position, std::size_t(kMaxInfix - 1));
    EXPECT_EQ(err.message, "Expression too long: 80 characters, at most 79 fit");
    EXPECT_TRUE(compile(too_long, p, &err, 200)); // a longer limit for other users
}

TEST(CalcCompile, TextEndsAtNul) {
    using namespace std::string_view_literals;
    EXPECT_EQ(calc("1+2\0garbage"sv), 3);
    EXPECT_EQ(run("\0A"sv).error.code, Errc::Empty);
}

TEST(CalcCompile, StackLimit) {
    // 79 values on the stack at once fit, 80 do not (base's CALCPERFORM_STACK).
    auto values = [](int n) {
        std::string s = "MAX(1";
        for (int k = 1; k < n; ++k) s += ",1";
        return s + ")";
    };
    Program p;
    CompileError err{};
    ASSERT_TRUE(compile(values(79), p, &err, 1000)) << err.message;
    double args[kArgs] = {};
    double v = 0;
    EXPECT_TRUE(perform(p, args, &v));
    EXPECT_EQ(v, 1);
    EXPECT_FALSE(compile(values(80), p, &err, 1000));
    EXPECT_EQ(err.code, Errc::Overflow);
    EXPECT_EQ(err.position, values(80).size() - 2); // the 80th value
}

// -----------------------------------------------------------------------------------------------
// Seeded randomized: fully parenthesised random expressions, in random letter case and blanks,
// evaluate as a tree evaluator with C semantics does.

struct Gen {
    std::mt19937_64 rng;
    const double* args;
    int pick(int n) { return static_cast<int>(rng() % static_cast<uint64_t>(n)); }

    std::string spaced(std::string s) {
        for (auto& ch : s)
            if (pick(2)) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        return (pick(4) == 0 ? " " : "") + s;
    }
    // A small integer operand, for the integer operators.
    std::string small_int(double& v) {
        if (pick(2)) {
            int a = pick(kArgs);
            v = args[a];
            return spaced(std::string(1, char('A' + a)));
        }
        int n = pick(40) - 20;
        v = n;
        return n < 0 ? "(-" + std::to_string(-n) + ")" : std::to_string(n);
    }
    std::string expr(int depth, double& v) {
        if (depth == 0 || pick(5) == 0) {
            switch (pick(3)) {
            case 0: {
                int a = pick(kArgs);
                v = args[a];
                return spaced(std::string(1, char('A' + a)));
            }
            case 1: {
                v = pick(2000) / 8.0; // exact in binary and in decimal
                char buf[32];
                std::snprintf(buf, sizeof buf, "%.3f", v);
                return buf;
            }
            default:
                v = 3.14159265358979323;
                return spaced("PI");
            }
        }
        double x, y, z;
        switch (pick(9)) {
        case 0: {
            static const char* ops[] = {"+", "-", "*", "/", "**", "^"};
            int o = pick(6);
            std::string s = "(" + expr(depth - 1, x) + ops[o] + expr(depth - 1, y) + ")";
            v = o == 0 ? x + y : o == 1 ? x - y : o == 2 ? x * y : o == 3 ? x / y : std::pow(x, y);
            return s;
        }
        case 1: {
            static const char* ops[] = {"<", "<=", ">", ">=", "=", "==", "!=", "#", "&&", "||"};
            int o = pick(10);
            std::string s = "(" + expr(depth - 1, x) + spaced(ops[o]) + expr(depth - 1, y) + ")";
            const bool r[] = {x<y, x <= y, x> y, x >= y,          x == y, x == y, x != y, x != y,
                              x != 0 && y != 0,  x != 0 || y != 0};
            v = r[o];
            return s;
        }
        case 2: {
            static const char* ops[] = {"&", "|", " AND ", " OR ", " XOR ", "%", ">>", "<<"};
            int o = pick(8);
            std::string s = "(" + small_int(x) + spaced(ops[o]) + small_int(y) + ")";
            int32_t a = static_cast<int32_t>(x), b = static_cast<int32_t>(y);
            const double r[] = {double(a & b),
                                double(a | b),
                                double(a & b),
                                double(a | b),
                                double(a ^ b),
                                b ? double(a % b) : NaN,
                                double(a >> (b & 31)),
                                double(static_cast<int32_t>(static_cast<uint32_t>(a) << (b & 31)))};
            v = r[o];
            return s;
        }
        case 3: {
            std::string s = "(" + expr(depth - 1, x) + "?" + expr(depth - 1, y) + ":" +
                            expr(depth - 1, z) + ")";
            v = x != 0 ? y : z;
            return s;
        }
        case 4: {
            static const char* ops[] = {"-", "!"};
            int o = pick(2);
            std::string s = "(" + std::string(ops[o]) + expr(depth - 1, x) + ")";
            v = o == 0 ? -x : double(x == 0);
            return s;
        }
        case 5: {
            static const char* fns[] = {"SIN", "COS", "SQRT", "ABS", "EXP", "LN", "FLOOR", "CEIL"};
            static double (*const impl[])(double) = {
                [](double x) { return std::sin(x); },   [](double x) { return std::cos(x); },
                [](double x) { return std::sqrt(x); },  [](double x) { return std::fabs(x); },
                [](double x) { return std::exp(x); },   [](double x) { return std::log(x); },
                [](double x) { return std::floor(x); }, [](double x) { return std::ceil(x); }};
            int o = pick(8);
            std::string s = spaced(fns[o]) + "(" + expr(depth - 1, x) + ")";
            v = impl[o](x);
            return s;
        }
        case 6: {
            int n = 1 + pick(4);
            bool is_max = pick(2);
            std::string s = spaced(is_max ? "MAX" : "MIN") + "(";
            for (int k = 0; k < n; ++k) {
                s += (k ? "," : "") + expr(depth - 1, x);
                if (k == 0)
                    v = x;
                else if ((is_max ? v < x : v > x) || std::isnan(x))
                    v = x;
            }
            return s + ")";
        }
        case 7: {
            bool is_atan2 = pick(2);
            std::string s = spaced(is_atan2 ? "ATAN2" : "FMOD") + "(" + expr(depth - 1, x) + "," +
                            expr(depth - 1, y) + ")";
            v = is_atan2 ? std::atan2(y, x) : std::fmod(x, y);
            return s;
        }
        default:
            return "(" + expr(depth - 1, v) + ")";
        }
    }
};

TEST(CalcRandomized, MatchesATreeEvaluator) {
    double args[kArgs];
    for (int i = 0; i < kArgs; ++i) args[i] = (i - 10) * 0.75; // negatives, zero, fractions
    args[3] = 0;
    Gen gen{std::mt19937_64(20240917), args};
    for (int n = 0; n < 100000; ++n) {
        double expected = 0;
        std::string text = gen.expr(1 + gen.pick(5), expected);
        Program p;
        CompileError err{};
        ASSERT_TRUE(compile(text, p, &err, 100000)) << text << ": " << err.message;
        double a[kArgs];
        std::copy(args, args + kArgs, a);
        double v = 0;
        ASSERT_TRUE(perform(p, a, &v)) << text;
        ASSERT_TRUE(identical(v, expected)) << text << ": expected " << expected << ", got " << v;
    }
}

} // namespace
