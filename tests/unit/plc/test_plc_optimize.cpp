// Constant `var`s (plc/optimize.hpp): folded into the code they feed, with the same bits as the
// unoptimised evaluation and as ExprTk (which computes them at run time).
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

using namespace beamctl::plc;

namespace {

bool same_bits(double a, double b) {
    return std::memcmp(&a, &b, sizeof a) == 0;
}

struct Eval {
    test::TableHost h;
    std::size_t size = 0;
    double operator()(const std::string& code, double x = 0) {
        h["r"];
        h["x"] = x;
        Program p = Program::compile(code, "t.plc", h);
        size = p.size();
        EXPECT_EQ(p.run(), 0) << code;
        return h["r"];
    }
};

} // namespace

TEST(PlcOptimize, ConstantVarsFoldIntoTheCode) {
    Eval run;
    // geometry as the kinematics includes write it: one multiplication (and halt) remains
    const double r = run("var dz := 800; var half := dz / 2; var k := sqrt(half) + 1; r := x * k;", 3);
    EXPECT_EQ(run.size, 2u);
    EXPECT_TRUE(same_bits(r, 3 * (std::sqrt(800.0 / 2) + 1)));
    // a condition on constants keeps the branch taken
    run("var c := 1; r := c > 0 ? x : x / 0;", 5);
    EXPECT_EQ(run.size, 2u);
    EXPECT_EQ(run.h["r"], 5);
    // a var without a value is 0
    EXPECT_EQ(run("var z; r := z + x;", 2), 2);
}

TEST(PlcOptimize, WrittenVarsStayVariables) {
    Eval run;
    EXPECT_EQ(run("var a := 1; a += 1; r := a;"), 2);
    EXPECT_EQ(run("var s := 0; for (var i := 0; i < 4; i += 1) { s += i; }; r := s;"), 6);
    EXPECT_EQ(run("var a := 1; var b := 5; a <=> b; r := a * 10 + b;"), 51);
    EXPECT_EQ(run("var a := 2; if (x > 0) { a := 3; }; r := a;", 1), 3);
}

TEST(PlcOptimize, OnlyExactRewrites) {
    Eval run;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    // x * k with k = 0 stays a multiplication (NaN * 0 is NaN, -1 * 0 is -0)
    EXPECT_TRUE(std::isnan(run("var k := 0; r := x * k;", nan)));
    EXPECT_TRUE(same_bits(run("var k := 0; r := x * k;", -1), -0.0));
    // x + 0 stays (-0 + 0 is +0); x - 0, x * 1 and x / 1 are x for every x
    EXPECT_TRUE(same_bits(run("var k := 0; r := x + k;", -0.0), 0.0));
    EXPECT_TRUE(same_bits(run("var k := 0; var o := 1; r := (x - k) * o / o;", -0.0), -0.0));
    EXPECT_EQ(run.size, 2u); // r := x
    // a power of a constant-var exponent is pow (ExprTk's run-time pow), not the literal
    // exponent's multiplication chain: find an x where the two differ and check pow's bits
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(1, 2);
    double x = 0;
    for (int i = 0; i < 100000 && x == 0; ++i) {
        const double c = u(rng);
        if (!same_bits(c * c * c, std::pow(c, 3.0))) x = c;
    }
    ASSERT_NE(x, 0);
    EXPECT_TRUE(same_bits(run("var n := 3; r := x ^ n;", x), std::pow(x, 3.0)));
    EXPECT_TRUE(same_bits(run("r := x ^ 3;", x), x * x * x));
    // a constant base with a literal exponent folds as the chain would compute it
    EXPECT_TRUE(same_bits(run("var b := 1.1; r := b ^ 7 + x;", 0), [] {
        const double b = 1.1, b3 = b * b * b;
        return b3 * b3 * b + 0;
    }()));
}
