// The PLC language: ExprTk's semantics as ECMC's PLC files rely on them. Expected values come
// from ExprTk (the exprtk-ecmc copy ECMC builds) or, for math functions, from <cmath>.
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

using beamctl::plc::CompileError;
using beamctl::plc::CompileOptions;
using beamctl::plc::Program;
using beamctl::plc::RunStatus;
using beamctl::plc::test::TableHost;

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

// Compiles `code` as t.plc and runs one scan; the scan must succeed.
Program run_once(TableHost& host, const std::string& code, const CompileOptions& options = {}) {
    Program p = Program::compile(code, "t.plc", host, options);
    EXPECT_EQ(p.run(), 0) << p.fault_location();
    return p;
}

// Value of an expression with x = 1.5, y = -2.25, z = 3, w = 0.5.
double value(const std::string& expr) {
    TableHost h;
    h.add("x", 1.5);
    h.add("y", -2.25);
    h.add("z", 3);
    h.add("w", 0.5);
    h.add("r");
    run_once(h, "r := " + expr + ";");
    return h["r"];
}

std::string compile_error(const std::string& code) {
    TableHost h;
    h.add("x", 1);
    try {
        Program::compile(code, "t.plc", h);
    } catch (const CompileError& e) {
        return e.what();
    }
    return "<no error>";
}

} // namespace

// ---- operators ------------------------------------------------------------------------------

TEST(PlcOperators, ArithmeticPrecedenceAndAssociativity) {
    EXPECT_EQ(value("2 + 3 * 4"), 14);
    EXPECT_EQ(value("10 - 4 - 3"), 3);
    EXPECT_EQ(value("2 * 3 % 4"), 2); // same level, left to right
    EXPECT_EQ(value("7 / 2"), 3.5);
    EXPECT_EQ(value("2 * 3 ^ 2"), 18);
    EXPECT_EQ(value("2 ^ 3 ^ 2"), 512); // '^' is right-associative
    EXPECT_EQ(value("3^2^4"), 43046721);
}

TEST(PlcOperators, UnaryMinusBindsLooserThanPower) {
    EXPECT_EQ(value("-2 ^ 2"), -4);
    EXPECT_EQ(value("(-2) ^ 2"), 4);
    EXPECT_EQ(value("-x ^ 2"), -2.25);
    EXPECT_EQ(value("-x * 2"), -3);
    EXPECT_EQ(value("2 ^ -3 ^ 2"), std::pow(2.0, -9.0));
    EXPECT_EQ(value("+2 ^ 2"), 4);
    EXPECT_EQ(value("- -x"), 1.5);
    EXPECT_EQ(value("x - -1"), 2.5);
}

TEST(PlcOperators, ModuloIsFmod) {
    EXPECT_EQ(value("-5 % 3"), -2);
    EXPECT_EQ(value("5.5 % 2"), 1.5);
    EXPECT_EQ(value("mod(7, 4)"), 3);
}

TEST(PlcOperators, ComparisonsAndTheirAliases) {
    EXPECT_EQ(value("x = 1.5"), 1);
    EXPECT_EQ(value("x == 1.5"), 1);
    EXPECT_EQ(value("x != 1.5"), 0);
    EXPECT_EQ(value("x <> 1.5"), 0);
    EXPECT_EQ(value("x <> 2"), 1);
    EXPECT_EQ(value("y < x"), 1);
    EXPECT_EQ(value("y <= -2.25"), 1);
    EXPECT_EQ(value("y > x"), 0);
    EXPECT_EQ(value("z >= 3"), 1);
    EXPECT_EQ(value("1 + 2 < 4"), 1); // arithmetic before comparison
    EXPECT_EQ(value("3 > 2 > 1"), 0); // (3 > 2) > 1
    EXPECT_EQ(value("1 < 2 = 1"), 1);
}

TEST(PlcOperators, LogicalOperatorTruthTables) {
    const struct {
        const char* op;
        double t[4]; // 00 01 10 11
    } table[] = {{"and", {0, 0, 0, 1}},  {"or", {0, 1, 1, 1}},  {"xor", {0, 1, 1, 0}},
                 {"nand", {1, 1, 1, 0}}, {"nor", {1, 0, 0, 0}}, {"xnor", {1, 0, 0, 1}},
                 {"&", {0, 0, 0, 1}},    {"|", {0, 1, 1, 1}}};
    for (const auto& row : table) {
        for (int i = 0; i < 4; ++i) {
            const std::string expr =
                std::to_string(i >> 1) + " " + row.op + " " + std::to_string(i & 1);
            EXPECT_EQ(value(expr), row.t[i]) << expr;
        }
    }
    EXPECT_EQ(value("not(0)"), 1);
    EXPECT_EQ(value("not(y)"), 0);
    EXPECT_EQ(value("2 and 0.5"), 1); // any non-zero is true
}

TEST(PlcOperators, LogicalPrecedenceAndOrXor) {
    EXPECT_EQ(value("1 or 0 and 0"), 1); // 'and' binds tighter than 'or'
    EXPECT_EQ(value("0 and 0 or 1"), 1);
    EXPECT_EQ(value("1 or 1 xor 1"), 0);   // 'or' and 'xor' share a level: (1 or 1) xor 1
    EXPECT_EQ(value("1 nand 1 nor 0"), 1); // (1 nand 1) nor 0
    EXPECT_EQ(value("1 < 2 and 3 < 2"), 0);
    EXPECT_EQ(value("1 + 2 < 4 and 5"), 1);
}

TEST(PlcOperators, NanIsTrue) {
    TableHost h;
    h.add("n", kNaN);
    h.add("a");
    h.add("b");
    h.add("c");
    run_once(h, "a := not(n); b := n and 1; if (n) { c := 7; };");
    EXPECT_EQ(h["a"], 0);
    EXPECT_EQ(h["b"], 1);
    EXPECT_EQ(h["c"], 7);
}

TEST(PlcOperators, AndOrEvaluateBothSidesAmpersandAndBarShortCircuit) {
    TableHost h;
    int calls = 0;
    h.add_function("count", 0, 0, [&](const double*, int) {
        ++calls;
        return 1.0;
    });
    h.add("r");
    const struct {
        const char* code;
        int calls;
        double r;
    } cases[] = {
        {"r := 0 and count();", 1, 0},       {"r := 1 or count();", 1, 1},
        {"r := 0 & count();", 0, 0},         {"r := 1 | count();", 0, 1},
        {"r := 1 & count();", 1, 1},         {"r := 0 | count();", 1, 1},
        {"r := mand(0, count());", 0, 0},    {"r := mor(1, count());", 0, 1},
        {"r := mand(1, 1, count());", 1, 1}, {"r := 0 nand count();", 1, 1},
    };
    for (const auto& c : cases) {
        calls = 0;
        run_once(h, c.code);
        EXPECT_EQ(calls, c.calls) << c.code;
        EXPECT_EQ(h["r"], c.r) << c.code;
    }
}

TEST(PlcOperators, AssignmentAndCompoundAssignment) {
    TableHost h;
    h.add("a", 10);
    h.add("b");
    h.add("c");
    run_once(h, "a += 2; a -= 4; a *= 3; a /= 4; a %= 4; b := c := 5;");
    EXPECT_EQ(h["a"], 2); // ((10+2-4)*3/4) % 4 = 6 % 4
    EXPECT_EQ(h["b"], 5);
    EXPECT_EQ(h["c"], 5);
    run_once(h, "a := 1; b := (a += 1) * 10;"); // an assignment has the assigned value
    EXPECT_EQ(h["b"], 20);
}

TEST(PlcOperators, EqualSignIsAComparisonNotAnAssignment) {
    TableHost h;
    h.add("a", 3);
    run_once(h, "a = 5;");
    EXPECT_EQ(h["a"], 3);
}

TEST(PlcOperators, ImplicitMultiplication) {
    EXPECT_EQ(value("2x"), 3);
    EXPECT_EQ(value("3(z - 1)"), 6);
    EXPECT_EQ(value("2pi"), 2 * std::numbers::pi);
    EXPECT_EQ(value("2x + 3(y - 1)"), -6.75);
}

TEST(PlcOperators, MissingSemicolonQuirkMatchesExprTk) {
    // `1 y` is `1*y`, which ExprTk simplifies to `y`: the line is x := (y := 7).
    TableHost h;
    h.add("x");
    h.add("y");
    run_once(h, "x := 1 y := 7;");
    EXPECT_EQ(h["x"], 7);
    EXPECT_EQ(h["y"], 7);
}

TEST(PlcOperators, SwapOperatorAndFunction) {
    TableHost h;
    h.add("a", 1);
    h.add("b", 2);
    run_once(h, "a <=> b;");
    EXPECT_EQ(h["a"], 2);
    EXPECT_EQ(h["b"], 1);
    run_once(h, "swap(a, b);");
    EXPECT_EQ(h["a"], 1);
}

TEST(PlcOperators, ConstantsAndKeywordsAreCaseInsensitive) {
    EXPECT_EQ(value("pi"), std::numbers::pi);
    EXPECT_EQ(value("epsilon"), 1e-10); // ExprTk's epsilon, not DBL_EPSILON
    EXPECT_EQ(value("-inf"), -kInf);
    EXPECT_EQ(value("TRUE + False"), 1);
    EXPECT_EQ(value("ABS(y) AND Not(0)"), 1);
    TableHost h;
    h.add("r");
    run_once(h, "IF (1) { VAR t := 4; r := T * 2; } ELSE { r := 0; };");
    EXPECT_EQ(h["r"], 8);
}

// ---- control structures ---------------------------------------------------------------------

TEST(PlcControl, IfElseIfElseChain) {
    TableHost h;
    h.add("s");
    h.add("r");
    const std::string code = R"(
        if (s < 0) {
            r := -1;
        } else if (s == 0) {
            r := 0;
        } else if (s < 10) {
            r := 1;
        } else {
            r := 2;
        };
    )";
    Program p = Program::compile(code, "t.plc", h);
    for (const auto& [in, out] : {std::pair{-5.0, -1.0}, {0.0, 0.0}, {3.0, 1.0}, {50.0, 2.0}}) {
        h["s"] = in;
        ASSERT_EQ(p.run(), 0);
        EXPECT_EQ(h["r"], out) << in;
    }
}

TEST(PlcControl, IfWithoutBracesAndWithoutTrailingSemicolonAfterBlocks) {
    TableHost h;
    h.add("a");
    h.add("b");
    // ECMC files often omit the ';' after '}' when the next statement starts with a keyword.
    run_once(h, "if (1) a := 1; else a := 2;\n"
                "if (0) { b := 1; }\n"
                "if (1) { b := b + 5; }\n");
    EXPECT_EQ(h["a"], 1);
    EXPECT_EQ(h["b"], 5);
}

TEST(PlcControl, IfValuesTernaryAndFunctionForm) {
    EXPECT_EQ(value("if (x > 1, 10, 20)"), 10);
    EXPECT_EQ(value("x > 2 ? 10 : 20"), 20);
    EXPECT_EQ(value("0 ? 1 : 0 ? 2 : 3"), 3);        // right-associative
    EXPECT_EQ(value("1 + 1 ? 5 : 6"), 5);            // the condition is everything before '?'
    EXPECT_TRUE(std::isnan(value("if (x < 0) 5;"))); // no branch taken: NaN
    TableHost h;
    h.add("r");
    h.add("c", 1);
    run_once(h, "r := c ? r + 1 : r - 1; r := c ? r + 1 : r - 1;");
    EXPECT_EQ(h["r"], 2);
}

TEST(PlcControl, ForWhileBreakContinue) {
    TableHost h;
    h.add("total");
    h.add("n");
    h.add("k");
    run_once(h, R"(
        total := 0;
        for (var i := 0; i < 10; i += 1) {
            if (i == 3) continue;
            if (i == 7) break;
            total += i;
        };
        n := 0;
        while (n < 100) { n += 7; };
        var j := 0;
        k := 0;
        while ((j += 1) < 10) {
            for (var m := 0; m < 5; m += 1) { if (m >= 2) break; k += 1; };
        };
    )");
    EXPECT_EQ(h["total"], 0 + 1 + 2 + 4 + 5 + 6);
    EXPECT_EQ(h["n"], 105);
    EXPECT_EQ(h["k"], 18); // the inner break leaves the inner loop only
}

TEST(PlcControl, LoopValuesAndBreakWithValue) {
    EXPECT_EQ(value("for (var i := 0; i < 5; i += 1) { i * 2 }"), 8);
    EXPECT_EQ(value("for (var i := 0; i < 5; i += 1) { if (i == 2) break[42]; i }"), 42);
    EXPECT_TRUE(std::isnan(value("for (var i := 0; i < 5; i += 1) { if (i == 2) break; i }")));
    EXPECT_TRUE(std::isnan(value("while (0) { 1 }")));
}

TEST(PlcControl, RepeatUntil) {
    TableHost h;
    h.add("n");
    run_once(h, "n := 0; repeat n += 3; until (n > 10);");
    EXPECT_EQ(h["n"], 12);
    run_once(h, "n := 50; repeat n += 1; until (1);"); // the body runs at least once
    EXPECT_EQ(h["n"], 51);
}

TEST(PlcControl, SwitchMultiSwitchAndSequence) {
    TableHost h;
    h.add("s", 2);
    h.add("r");
    h.add("a");
    h.add("b");
    run_once(h, R"(
        r := switch {
            case s == 1 : 10;
            case s == 2 : 20;
            default     : 30;
        };
        [*] {
            case s > 0 : a := 1;
            case s > 5 : b := 1;
        };
    )");
    EXPECT_EQ(h["r"], 20);
    EXPECT_EQ(h["a"], 1);
    EXPECT_EQ(h["b"], 0);
    EXPECT_EQ(value("~{x := 4; x * 2}"), 8);
    EXPECT_EQ(value("~(1, 2, 3)"), 3);
}

TEST(PlcControl, ReturnEndsTheScan) {
    TableHost h;
    h.add("a");
    h.add("b");
    h.add("stop", 1);
    Program p = run_once(h, R"(
        a += 1;
        for (var i := 0; i < 10; i += 1) { if (i == 2 and stop) { return []; }; };
        b += 1;
    )");
    EXPECT_EQ(h["a"], 1);
    EXPECT_EQ(h["b"], 0);
    h["stop"] = 0;
    EXPECT_EQ(p.run(), 0);
    EXPECT_EQ(h["a"], 2);
    EXPECT_EQ(h["b"], 1);
}

// ---- variables and vectors ------------------------------------------------------------------

TEST(PlcVariables, VarIsScanLocalAndStaticPersists) {
    TableHost h;
    Program p = Program::compile(R"(
        var count := 0;
        count += 1;
        static.count += 1;
        static.local := count;
    )",
                                 "t.plc", h);
    for (int i = 0; i < 5; ++i) ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.local"], 1);
    EXPECT_EQ(h["static.count"], 5);
}

TEST(PlcVariables, UninitialisedVarKeepsItsValue) {
    TableHost h;
    Program p =
        Program::compile("var n{}; n += 1; static.n := n; var z; static.z := z;", "t.plc", h);
    for (int i = 0; i < 3; ++i) ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.n"], 3);
    EXPECT_EQ(h["static.z"], 0); // `var z;` is 0
}

TEST(PlcVariables, BlockScopes) {
    TableHost h;
    h.add("r");
    run_once(h, "if (1) { var t := 2; r := t; }; if (1) { var t := 3; r += t; };");
    EXPECT_EQ(h["r"], 5);
    EXPECT_NE(compile_error("if (1) { var t := 2; }; x := t;").find("unknown name 't'"),
              std::string::npos);
}

TEST(PlcVariables, RedefinitionAndShadowingAreErrors) {
    EXPECT_NE(compile_error("var a := 1; var a := 2;").find("'a' is already defined"),
              std::string::npos);
    EXPECT_NE(compile_error("var a := 1; if (1) { var A := 2; };").find("already defined"),
              std::string::npos);
    EXPECT_NE(compile_error("var sin := 1;").find("cannot be used as a variable name"),
              std::string::npos);
}

TEST(PlcVectors, InitialiserListsIndexingAndSize) {
    TableHost h;
    for (const char* n : {"a", "b", "c", "d", "e", "f"}) h.add(n);
    h.add("i", 2);
    run_once(h, R"(
        var v[5] := {1, 2, 3};
        var w[3] := [7];
        var u[2];
        a := v[0] + v[2] + v[4];
        b := v[];
        c := w[1] + u[1];
        v[i] += 10;
        d := v[i];
        v[i + 1] := -1;
        e := v[3];
        f := v;              // a vector as a scalar: its first element
    )");
    EXPECT_EQ(h["a"], 4);
    EXPECT_EQ(h["b"], 5);
    EXPECT_EQ(h["c"], 7);
    EXPECT_EQ(h["d"], 13);
    EXPECT_EQ(h["e"], -1);
    EXPECT_EQ(h["f"], 1);
}

TEST(PlcVectors, VectorsAreReinitialisedEveryScan) {
    TableHost h;
    Program p = Program::compile("var v[2] := {1}; v[0] += 1; v[1] += 1; static.a := v[0] + v[1];",
                                 "t.plc", h);
    for (int i = 0; i < 3; ++i) ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.a"], 3);
}

TEST(PlcVectors, DotAggregatesAndElementWiseExpressions) {
    TableHost h;
    for (const char* n : {"d", "dr", "bad", "s", "m", "lo", "hi", "sw", "p"}) h.add(n);
    run_once(h, R"(
        var a[3] := {1, 2, 3};
        var b[3] := {4, 5, 6};
        d := dot(a, b);
        dr := dot(a, b, 1, 2);
        bad := dot(a, b, 2, 5);
        s := sum(a);
        m := avg(b);
        lo := min(b);
        hi := max(a * -1);
        sw := sum(a * b + 1);
        p := mul(a);
    )");
    EXPECT_EQ(h["d"], 32);
    EXPECT_EQ(h["dr"], 2 * 5 + 3 * 6);
    EXPECT_TRUE(std::isnan(h["bad"]));
    EXPECT_EQ(h["s"], 6);
    EXPECT_EQ(h["m"], 5);
    EXPECT_EQ(h["lo"], 4);
    EXPECT_EQ(h["hi"], -1);
    EXPECT_EQ(h["sw"], 35);
    EXPECT_EQ(h["p"], 6);
}

TEST(PlcVectors, WholeVectorAssignment) {
    TableHost h;
    h.add("a");
    h.add("b");
    h.add("c");
    run_once(h, R"(
        var v[12] := {1, 2, 3};
        var w[12];
        w := 2;               // every element
        v += w;               // element-wise
        w := v * v;
        var small[2] := v;    // from a vector: as many elements as fit
        a := sum(v);
        b := w[11];
        c := small[1];
    )");
    EXPECT_EQ(h["a"], 1 + 2 + 3 + 24);
    EXPECT_EQ(h["b"], 4);
    EXPECT_EQ(h["c"], 4);
}

TEST(PlcVectors, HostVectors) {
    TableHost h;
    std::vector<double>& data = h.add_vector("ds0.data", 4);
    data = {1, 2, 3, 4};
    h.add("r");
    run_once(h, "r := sum(ds0.data) + ds0.data[]; ds0.data[3] := 40;");
    EXPECT_EQ(h["r"], 14);
    EXPECT_EQ(data[3], 40);
}

TEST(PlcVectors, ConstantIndexOutOfRangeIsACompileError) {
    const std::string e = compile_error("var v[3]; x := v[3];");
    EXPECT_NE(e.find("t.plc:1:18: index 3 is out of range for 'v' (size 3)"), std::string::npos)
        << e;
    EXPECT_NE(compile_error("var v[0];").find("must be an integer from 1"), std::string::npos);
    EXPECT_NE(compile_error("var v[2] := {1, 2, 3};").find("3 initial values"), std::string::npos);
}

// ---- print ----------------------------------------------------------------------------------

TEST(PlcPrint, PrintlnFormatsLikeExprTk) {
    TableHost h;
    h.add("a", 2.5);
    run_once(h, R"(
        println('Step: ', a, ' done');
        print('no newline');
        println();
        var v[3] := {1, -2, 3.25};
        println('v = ', v);
        println('s//not a comment');
    )");
    ASSERT_EQ(h.printed.size(), 5u);
    EXPECT_EQ(h.printed[0], "Step:    2.50000 done\n");
    EXPECT_EQ(h.printed[1], "no newline");
    EXPECT_EQ(h.printed[2], "\n");
    EXPECT_EQ(h.printed[3], "v =    1.00000   -2.00000    3.25000\n");
    EXPECT_EQ(h.printed[4], "s//not a comment\n");
}

TEST(PlcPrint, ArgumentsAreEvaluatedBeforePrinting) {
    // A function that prints while println's arguments are evaluated (ECMC's lib example).
    TableHost h;
    run_once(h, R"(
        function twice(a) { println('in twice'); return [2a]; }
        println('result: ', twice(3));
    )");
    ASSERT_EQ(h.printed.size(), 2u);
    EXPECT_EQ(h.printed[0], "in twice\n");
    EXPECT_EQ(h.printed[1], "result:    6.00000\n");
}

TEST(PlcPrint, EscapesInStrings) {
    TableHost h;
    run_once(h, R"(println('it\'s\ta\\b');)");
    ASSERT_EQ(h.printed.size(), 1u);
    EXPECT_EQ(h.printed[0], "it's\ta\\b\n");
}

TEST(PlcPrint, StringsOutsidePrintAreErrors) {
    EXPECT_NE(compile_error("x := 'abc';").find("strings are only allowed as arguments"),
              std::string::npos);
}

// ---- comments -------------------------------------------------------------------------------

TEST(PlcComments, HashSlashSlashAndBlockComments) {
    TableHost h;
    h.add("a");
    h.add("b");
    h.add("c");
    run_once(h, "a := 1; # a := 2;\n"
                "b := 3; // b := 4;\n"
                "/* c := 5;\n"
                "   c := 6; */ c := 7;\n"
                "a := a + /* inline */ 10;\n");
    EXPECT_EQ(h["a"], 11);
    EXPECT_EQ(h["b"], 3);
    EXPECT_EQ(h["c"], 7);
}

TEST(PlcComments, HashEndsTheLineEvenInsideAString) {
    // ECMC strips from '#' to the end of the line before ExprTk sees the code.
    const std::string e = compile_error("println('a # b');");
    EXPECT_NE(e.find("t.plc:1:9: string not terminated"), std::string::npos) << e;
}

TEST(PlcComments, HashInsideABlockCommentHidesItsEnd) {
    // As in ECMC, where '#' is stripped before ExprTk looks for the end of the comment.
    TableHost h;
    h.add("a");
    run_once(h, "/* note # */ a := 1;\n a := 2; */ a := a + 10;");
    EXPECT_EQ(h["a"], 10);
}

TEST(PlcComments, UnclosedBlockCommentIsAnError) {
    const std::string e = compile_error("x := 1;\n  /* open\nx := 2;");
    EXPECT_EQ(e, "t.plc:2:3: '/*' comment is never closed\n  /* open\n  ^");
}

// ---- math -----------------------------------------------------------------------------------

TEST(PlcMath, UnaryFunctionsMatchCmath) {
    const struct {
        const char* name;
        double (*f)(double);
    } fns[] = {
        {"abs", [](double v) { return std::fabs(v); }},
        {"sqrt", [](double v) { return std::sqrt(v); }},
        {"exp", [](double v) { return std::exp(v); }},
        {"log", [](double v) { return std::log(v); }},
        {"log10", [](double v) { return std::log10(v); }},
        {"log2", [](double v) { return std::log2(v); }},
        {"log1p", [](double v) { return std::log1p(v); }},
        {"expm1", [](double v) { return std::expm1(v); }},
        {"sin", [](double v) { return std::sin(v); }},
        {"cos", [](double v) { return std::cos(v); }},
        {"tan", [](double v) { return std::tan(v); }},
        {"asin", [](double v) { return std::asin(v); }},
        {"acos", [](double v) { return std::acos(v); }},
        {"atan", [](double v) { return std::atan(v); }},
        {"sinh", [](double v) { return std::sinh(v); }},
        {"cosh", [](double v) { return std::cosh(v); }},
        {"tanh", [](double v) { return std::tanh(v); }},
        {"asinh", [](double v) { return std::asinh(v); }},
        {"acosh", [](double v) { return std::acosh(v); }},
        {"atanh", [](double v) { return std::atanh(v); }},
        {"floor", [](double v) { return std::floor(v); }},
        {"ceil", [](double v) { return std::ceil(v); }},
        {"trunc", [](double v) { return std::trunc(v) + 0.0; }},
        {"erf", [](double v) { return std::erf(v); }},
        {"erfc", [](double v) { return std::erfc(v); }},
        {"cot", [](double v) { return 1 / std::tan(v); }},
        {"sec", [](double v) { return 1 / std::cos(v); }},
        {"csc", [](double v) { return 1 / std::sin(v); }},
        {"deg2rad", [](double v) { return v * std::numbers::pi / 180; }},
        {"rad2deg", [](double v) { return v * 180 / std::numbers::pi; }},
        {"frac", [](double v) { return v - std::trunc(v); }},
        {"sgn", [](double v) { return v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0); }},
    };
    for (const double v : {-0.75, -0.3, 0.0, 0.2, 0.5, 0.9, 1.5, 2.0, 3.7}) {
        for (const auto& fn : fns) {
            const std::string expr = std::string(fn.name) + "(" + std::to_string(v) + ")";
            const double got = value(expr);
            const double want = fn.f(std::stod(std::to_string(v)));
            if (std::isnan(want)) {
                EXPECT_TRUE(std::isnan(got)) << expr;
            } else if (std::isinf(want)) {
                EXPECT_EQ(got, want) << expr;
            } else {
                EXPECT_NEAR(got, want, 1e-15 * std::max(1.0, std::fabs(want))) << expr;
            }
        }
    }
}

TEST(PlcMath, ExprTkSpecificFunctions) {
    EXPECT_EQ(value("round(2.5)"), 3);
    EXPECT_EQ(value("round(-2.5)"), -3); // half away from zero
    EXPECT_EQ(value("round(-2.4)"), -2);
    EXPECT_EQ(value("roundn(1.23456789, 4)"), 1.2346);
    EXPECT_EQ(value("roundn(-1.25, 1)"), -1.3);
    EXPECT_EQ(value("frac(-2.75)"), -0.75);
    EXPECT_EQ(value("trunc(-2.75)"), -2);
    EXPECT_EQ(value("clamp(0, 5, 3)"), 3);
    EXPECT_EQ(value("clamp(0, -5, 3)"), 0);
    EXPECT_EQ(value("iclamp(0, 1, 3)"), 0); // inside: to the nearer bound
    EXPECT_EQ(value("iclamp(0, 2, 3)"), 3);
    EXPECT_EQ(value("iclamp(0, 5, 3)"), 5); // outside: unchanged
    EXPECT_EQ(value("inrange(0, 3, 3)"), 1);
    EXPECT_EQ(value("inrange(0, 4, 3)"), 0);
    EXPECT_EQ(value("hypot(3, 4)"), 5);
    EXPECT_EQ(value("atan2(1, 1)"), std::atan2(1.0, 1.0));
    EXPECT_EQ(value("pow(2, 10)"), 1024);
    EXPECT_EQ(value("logn(8, 2)"), std::log(8.0) / std::log(2.0));
    EXPECT_EQ(value("root(27, 3)"), std::pow(27.0, 1.0 / 3));
    EXPECT_TRUE(std::isnan(value("root(-4, 2)")));
    EXPECT_EQ(value("shl(3, 2)"), 12);
    EXPECT_EQ(value("shr(12, 2)"), 3);
    EXPECT_EQ(value("equal(1, 1 + 1e-12)"), 1); // within ExprTk's epsilon 1e-10
    EXPECT_EQ(value("equal(1, 1.001)"), 0);
    EXPECT_EQ(value("not_equal(1, 1.001)"), 1);
    EXPECT_EQ(value("ncdf(0)"), 0.5);
    EXPECT_EQ(value("sinc(0)"), 1);
    EXPECT_EQ(value("deg2grad(90)"), 100);
}

TEST(PlcMath, MultiArgumentFunctions) {
    EXPECT_EQ(value("min(3, -1, 2)"), -1);
    EXPECT_EQ(value("max(3, -1, 2, 7, 0, 1)"), 7);
    EXPECT_EQ(value("sum(1, 2, 3, 4)"), 10);
    EXPECT_EQ(value("avg(1, 2, 3, 4)"), 2.5);
    EXPECT_EQ(value("mul(2, 3, 4)"), 24);
    EXPECT_EQ(value("min(x)"), 1.5);
    // ExprTk groups 4 arguments in pairs: min(min(a, b), min(c, d)) with std::min.
    EXPECT_EQ(value("min(1.5, 0.5, sqrt(-1), -3)"), 0.5);
}

TEST(PlcMath, LiteralZeroRewritesAsExprTk) {
    // ExprTk rewrites x/0 to NaN and 0*x to 0 at compile time (IEEE would give inf and NaN).
    EXPECT_TRUE(std::isnan(value("x / 0")));
    EXPECT_EQ(value("0 * sqrt(y)"), 0);
    EXPECT_EQ(value("0 / sqrt(y)"), 0);
    EXPECT_TRUE(std::isnan(value("x / (1 - 1)")));
}

TEST(PlcMath, WrongArgumentCountIsAnError) {
    EXPECT_NE(compile_error("x := atan2(1);").find("'atan2' takes 2 arguments, got 1"),
              std::string::npos);
    EXPECT_NE(compile_error("x := abs 3;").find("expected '(' after 'abs'"), std::string::npos);
}
