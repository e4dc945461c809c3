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

TEST(PlcOptimize, ComparisonJumpsAgreeWithComparisonValues) {
    // `if (x op y)` and loop conditions test the comparison in the jump; every op, with NaN,
    // signed zeros and equal values, must take the branch the comparison's value (0/1) names.
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double values[] = {1, 2, nan, -0.0, 0.0};
    for (const char* op : {"<", "<=", ">", ">=", "==", "!="}) {
        test::TableHost h;
        h.add("r");
        h.add("v");
        h.add("x");
        h.add("y");
        const std::string s = op;
        Program branch = Program::compile("if (x " + s + " y) { r := 1; } else { r := 0; };", "t.plc", h);
        Program loop = Program::compile("r := 0; while (x " + s + " y and r < 1) { r += 1; };", "t.plc", h);
        Program value = Program::compile("v := x " + s + " y;", "t.plc", h);
        EXPECT_NE(branch.disassemble().find("jf_"), std::string::npos);
        for (double x : values)
            for (double y : values) {
                h["x"] = x;
                h["y"] = y;
                ASSERT_EQ(value.run(), 0);
                ASSERT_EQ(branch.run(), 0);
                EXPECT_EQ(h["r"], h["v"]) << x << " " << s << " " << y;
            }
        // the loop's condition is `(x op y) and r < 1`: not a plain comparison, still right
        h["x"] = 1;
        h["y"] = 2;
        ASSERT_EQ(loop.run(), 0);
        ASSERT_EQ(value.run(), 0);
        EXPECT_EQ(h["r"], h["v"]);
    }
}

TEST(PlcOptimize, InlineAbsSqrtMinMaxKeepExprTksResults) {
    Eval run;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    EXPECT_TRUE(same_bits(run("r := abs(x);", -0.0), -0.0)); // ExprTk's abs: x < 0 ? -x : x
    EXPECT_EQ(run("r := abs(x);", -2.5), 2.5);
    EXPECT_TRUE(std::isnan(run("r := sqrt(x);", -1)));
    EXPECT_TRUE(same_bits(run("r := sqrt(x);", 2), std::sqrt(2.0)));
    // std::max/std::min order, as ExprTk: max(NaN, 1) is NaN, max(1, NaN) is 1
    EXPECT_TRUE(std::isnan(run("r := max(x, 1);", nan)));
    EXPECT_EQ(run("r := max(1, x);", nan), 1);
    EXPECT_TRUE(std::isnan(run("r := min(x, 1);", nan)));
    EXPECT_EQ(run("r := min(1, x);", nan), 1);
    EXPECT_EQ(run("r := min(x, 3) + max(x, 3);", 5), 8);
}

TEST(PlcOptimize, AnIndexFromAConstantVarIsStillChecked) {
    test::TableHost h;
    h.add("r");
    // in range: a fixed element, no run-time index
    Program in = Program::compile("var k := 1; var v[3] := {1, 2, 3}; r := v[k];", "t.plc", h);
    ASSERT_EQ(in.run(), 0);
    EXPECT_EQ(h["r"], 2);
    EXPECT_EQ(in.disassemble().find("load"), std::string::npos);
    // out of range (or NaN): the scan faults at the element, as for any computed index
    for (const char* k : {"5", "-1", "0/0"}) {
        Program out = Program::compile(std::string("var k := ") + k + "; var v[3] := {1, 2, 3}; r := v[k]; v[k] := 4;",
                                       "t.plc", h);
        EXPECT_EQ(out.run(), static_cast<int>(RunStatus::index_out_of_range)) << k;
    }
}
