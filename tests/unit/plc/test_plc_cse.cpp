// Common subexpressions: a pure arithmetic expression computes each distinct subexpression once
// (fewer instructions, the same value bit for bit); anything with side effects, control flow or
// vector elements is left as written.
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

using namespace beamctl::plc;

namespace {

double eval(const std::string& code, test::TableHost& h, std::size_t* size = nullptr) {
    Program p = Program::compile(code, "t.plc", h);
    if (size) *size = p.size();
    EXPECT_EQ(p.run(), 0);
    return h["r"];
}

} // namespace

TEST(PlcCse, RepeatedSubexpressionsAreComputedOnce) {
    test::TableHost h;
    h.add("r");
    h.add("a", 0.3);
    h.add("b", -1.7);
    std::size_t same = 0, different = 0;
    double v = eval("r := sin(a / 1000) * cos(b) + sin(a / 1000) * cos(b) - sin(a / 1000);", h, &same);
    eval("r := sin(a / 1000) * cos(b) + sin(b / 1000) * cos(a) - sin(a / 999);", h, &different);
    EXPECT_LT(same + 4, different);
    const double x = std::sin(0.3 / 1000) * std::cos(-1.7);
    const double want = x + x - std::sin(0.3 / 1000);
    EXPECT_EQ(std::memcmp(&v, &want, sizeof v), 0);
}

TEST(PlcCse, SideEffectsAndControlFlowAreNotShared) {
    test::TableHost h;
    h.add("r");
    h.add("a", 1);
    // each (a += 1) runs: 2 + 3
    EXPECT_EQ(eval("r := (a += 1) + (a += 1);", h), 5);
    h["a"] = 1;
    // the short-circuit `&` must not reuse a value computed only on one path
    EXPECT_EQ(eval("r := (a > 5 & (a * 2) > 1) + (a * 2);", h), 2);
    // a host call may have side effects: called twice
    int calls = 0;
    h.add_function("tick", 0, 0, [&](const double*, int) { return double(++calls); });
    EXPECT_EQ(eval("r := tick() + tick();", h), 3);
    EXPECT_EQ(calls, 2);
    // the destination appears in the expression: read before it is written
    h["r"] = 2;
    EXPECT_EQ(eval("r := r * r + r * r;", h), 8);
}
