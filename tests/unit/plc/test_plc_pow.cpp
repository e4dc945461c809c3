// Powers with a literal exponent are strength-reduced as ExprTk compiles them (issue 18): an
// integer exponent |c| <= 60 to ExprTk's multiplication chain (fast_exp, so results agree with
// ECMC bit for bit), x ^ 0.5 to a square root. Checked against std::pow over random and special
// inputs: equal where the reduction is exact, else within the rounding of the multiplications.
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>

using namespace beamctl::plc;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Distance in representable doubles (both finite, same sign or zero).
std::uint64_t ulps(double a, double b) {
    if (a == b) return 0;
    std::int64_t x, y;
    std::memcpy(&x, &a, sizeof x);
    std::memcpy(&y, &b, sizeof y);
    if ((x < 0) != (y < 0)) return std::numeric_limits<std::uint64_t>::max();
    return static_cast<std::uint64_t>(x > y ? x - y : y - x);
}

bool same_bits(double a, double b) {
    return std::memcmp(&a, &b, sizeof a) == 0 || (std::isnan(a) && std::isnan(b));
}

struct PowProgram {
    test::TableHost h;
    Program p;
    explicit PowProgram(const std::string& exponent)
        : p((h.add("r"), h.add("x"), Program::compile("r := x ^ " + exponent + ";", "t.plc", h))) {}
    double operator()(double x) {
        h["x"] = x;
        EXPECT_EQ(p.run(), 0);
        return h["r"];
    }
};

// Error bound of ExprTk's chain for x^n against std::pow, in ulp: a rounding in the chain is
// raised to the power still to come, so the relative errors add up to about (|n| - 1) half-ulps
// of the result (at most 2 ulp per half-ulp of relative error across a binade), plus the
// division for n < 0 and pow's own error below 1 ulp.
std::uint64_t ulp_bound(int n) {
    return static_cast<std::uint64_t>(std::abs(n) + (n < 0 ? 1 : 0));
}

} // namespace

TEST(PlcPow, LiteralPowersCompileToMultiplicationsNotPowCalls) {
    for (const char* e : {"2", "3", "7", "60", "-1", "-4", "0.5"}) {
        PowProgram p(e);
        const std::string code = p.p.disassemble();
        EXPECT_EQ(code.find("pow "), std::string::npos) << e << ":\n" << code;
    }
    // Exponents that are not literal integers within ExprTk's range stay std::pow calls.
    for (const char* e : {"61", "2.5", "-0.5", "x"}) {
        PowProgram p(e);
        EXPECT_NE(p.p.disassemble().find("pow "), std::string::npos) << e;
    }
}

TEST(PlcPow, IntegerPowersAreWithinTheirRoundingsOfStdPow) {
    std::mt19937_64 rng(18);
    std::uniform_real_distribution<double> mantissa(-2.0, 2.0);
    std::uniform_int_distribution<int> scale(-20, 20);
    for (int n : {2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 16, 31, 60, -1, -2, -3, -5, -10, -17}) {
        PowProgram p(std::to_string(n));
        std::uint64_t worst = 0;
        for (int i = 0; i < 20000; ++i) {
            // bases of both signs over many magnitudes, kept where x^n stays a normal number
            const double x = std::ldexp(mantissa(rng), scale(rng) * 6 / std::max(1, std::abs(n)));
            const double want = std::pow(x, n);
            if (!std::isnormal(want) || x == 0) continue;
            const double got = p(x);
            worst = std::max(worst, ulps(got, want));
        }
        EXPECT_LE(worst, ulp_bound(n)) << "x ^ " << n;
        if (n == 2 || n == -1) {
            EXPECT_LE(worst, 1u) << "x ^ " << n; // one rounding against pow's
        }
    }
}

TEST(PlcPow, ResultsFollowExprTksMultiplicationOrder) {
    // ExprTk's fast_exp spelled out: x^6 is (x*x*x)^2, x^10 is (x^4 * x)^2, x^11 squares and
    // multiplies. Bit-for-bit agreement with ECMC rests on this order.
    const double x = 1.0000001234567;
    auto v2 = x * x, v3 = x * x * x, v4 = v2 * v2, v5 = v4 * x;
    EXPECT_TRUE(same_bits(PowProgram("3")(x), v3));
    EXPECT_TRUE(same_bits(PowProgram("4")(x), v4));
    EXPECT_TRUE(same_bits(PowProgram("6")(x), v3 * v3));
    EXPECT_TRUE(same_bits(PowProgram("7")(x), v3 * v3 * x));
    EXPECT_TRUE(same_bits(PowProgram("10")(x), v5 * v5));
    EXPECT_TRUE(same_bits(PowProgram("-6")(x), 1.0 / (v3 * v3)));
    const double x8 = v4 * v4;
    EXPECT_TRUE(same_bits(PowProgram("11")(x), ((x * v2) * x8)));
}

TEST(PlcPow, SpecialValuesAgreeWithStdPow) {
    const double specials[] = {0.0, -0.0, 1.0, -1.0, kInf, -kInf, kNaN, 2.0, -3.0, 0.25, 1e-300, 1e300};
    for (const char* e : {"0", "1", "2", "3", "4", "7", "-1", "-2", "-3", "0.5"}) {
        PowProgram p(e);
        const double c = std::stod(e);
        for (double x : specials) {
            const double want = std::pow(x, c);
            const double got = p(x);
            if (std::isnormal(want) && std::isnormal(got)) {
                EXPECT_LE(ulps(got, want), 4u) << x << " ^ " << e;
            } else if (!(std::fabs(x) == 1e-300 || std::fabs(x) == 1e300)) {
                // zeros, infinities and NaN: the same value, sign included
                EXPECT_TRUE(same_bits(got, want)) << x << " ^ " << e << ": " << got << " vs " << want;
            }
        }
    }
    // Where ExprTk's chain leaves pow's range: 1 / x^n is 0 once x^n overflows, while pow is
    // still subnormal (kept as ExprTk so ECMC and beamctl agree).
    EXPECT_EQ(PowProgram("-4")(1e80), 0.0);
    EXPECT_GT(std::pow(1e80, -4.0), 0.0);
}

TEST(PlcPow, SquareRootForAHalf) {
    PowProgram p("0.5");
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(0, 1e6);
    for (int i = 0; i < 20000; ++i) {
        const double x = u(rng);
        EXPECT_LE(ulps(p(x), std::pow(x, 0.5)), 1u) << x;
        EXPECT_TRUE(same_bits(p(x), std::sqrt(x)));
    }
    EXPECT_TRUE(std::isnan(p(-4)));
}

TEST(PlcPow, PowersInsideLargerExpressionsAndVectors) {
    test::TableHost h;
    h.add("r");
    h.add("a", 3);
    h.add("b", -2);
    Program p = Program::compile("r := (a + b) ^ 2 + a ^ -1 + sqrt(a ^ 2 + b ^ 2) + (b ^ 3) ^ 0.5;",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_TRUE(std::isnan(h["r"])); // (-8) ^ 0.5
    Program q = Program::compile("var v[3] := {1, -2, 3}; var w[3] := v ^ 2; r := w[0] + w[1] * 10 + w[2] * 100;",
                                 "t.plc", h);
    ASSERT_EQ(q.run(), 0);
    EXPECT_EQ(h["r"], 1 + 40 + 900);
    Program z = Program::compile("r := (a := a + 1) ^ 0;", "t.plc", h);
    ASSERT_EQ(z.run(), 0);
    EXPECT_EQ(h["r"], 1);
    EXPECT_EQ(h["a"], 4); // the base's side effect still happens
}
