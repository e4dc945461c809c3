// Preprocessing as ecmccfg does it: msi macros, include/substitute, ECMC's VAR aliases and
// function libraries; and the form of compile errors.
#include "plc/program.hpp"
#include "table_host.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

using beamctl::Error;
using beamctl::plc::CompileError;
using beamctl::plc::CompileOptions;
using beamctl::plc::Program;
using beamctl::plc::test::TableHost;

namespace {

const std::filesystem::path kData = std::filesystem::path(__FILE__).parent_path() / "data";

std::string data(const std::string& name) {
    return (kData / name).string();
}

CompileError compile_error(TableHost& h, const std::string& code, const CompileOptions& o = {}) {
    try {
        Program::compile(code, "t.plc", h, o);
    } catch (const CompileError& e) {
        return e;
    }
    ADD_FAILURE() << "no compile error for:\n" << code;
    return CompileError({"<no error>"});
}

std::string first_error(const std::string& code, const CompileOptions& o = {}) {
    TableHost h;
    return compile_error(h, code, o).what();
}

} // namespace

// ---- macros ---------------------------------------------------------------------------------

TEST(PlcMacros, BracesParenthesesAndDefaults) {
    TableHost h;
    CompileOptions o;
    o.macros = {{"AX", "2"}, {"SELF", "plc0"}};
    h.add("ax2.traj.extsetpos");
    h.add("plc0.enable", 1);
    Program p = Program::compile("ax${AX}.traj.extsetpos := $(GAIN=2.5) * 4;\n$(SELF).enable := 0;",
                                 "t.plc", h, o);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ax2.traj.extsetpos"], 10);
    EXPECT_EQ(h["plc0.enable"], 0);
}

TEST(PlcMacros, UndefinedMacroIsAnErrorWithLocationAndCaret) {
    EXPECT_EQ(first_error("static.a := 1;\nstatic.b := ${GAIN} + 1;"),
              "t.plc:2:13: undefined macro 'GAIN'\n"
              "static.b := ${GAIN} + 1;\n"
              "            ^");
}

TEST(PlcMacros, NotExpandedInsideSingleQuotes) {
    // msi (macLib) leaves macros in single quotes alone, so ECMC prints them as written.
    TableHost h;
    CompileOptions o;
    o.macros = {{"SELF", "plc0"}};
    Program p = Program::compile("println('${SELF} is running: ', ${SELF_ID=7});", "t.plc", h, o);
    ASSERT_EQ(p.run(), 0);
    ASSERT_EQ(h.printed.size(), 1u);
    EXPECT_EQ(h.printed[0], "${SELF} is running:    7.00000\n");
}

TEST(PlcMacros, MacroThatTurnsALineIntoAComment) {
    // ecmccfg's debug idiom: ${DBG=#}println(...) prints only when DBG is defined empty.
    const std::string code = "${DBG=#}println('debug');\nprintln('always');";
    TableHost quiet;
    ASSERT_EQ(Program::compile(code, "t.plc", quiet).run(), 0);
    EXPECT_EQ(quiet.printed, std::vector<std::string>{"always\n"});
    TableHost loud;
    CompileOptions o;
    o.macros = {{"DBG", ""}};
    ASSERT_EQ(Program::compile(code, "t.plc", loud, o).run(), 0);
    EXPECT_EQ(loud.printed, (std::vector<std::string>{"debug\n", "always\n"}));
}

TEST(PlcMacros, UndefinedMacrosInCommentsAreIgnored) {
    TableHost h;
    Program p = Program::compile("static.a := 1; # uses ${NOT_DEFINED}\n"
                                 "static.b := 2; // and $(ALSO_NOT)\n"
                                 "/* ${NOR_THIS} */ static.c := 3;\n",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.c"], 3);
}

TEST(PlcMacros, ErrorsInExpandedCodeShowTheExpansion) {
    CompileOptions o;
    o.macros = {{"OFFSET", "1 +"}};
    EXPECT_EQ(first_error("static.a := 2 * ${OFFSET};", o),
              "t.plc:1:26: expected a value, found ';'\n"
              "static.a := 2 * ${OFFSET};\n"
              "                         ^\n"
              "after macro expansion:\n"
              "static.a := 2 * 1 +;\n"
              "                   ^");
}

// ---- include and substitute -----------------------------------------------------------------

TEST(PlcInclude, IncludeSubstituteAndSearchPath) {
    TableHost h;
    h.add("ec0.s3.binaryOutput01", 0);
    h.add("ec0.s3.binaryOutput02", 1);
    CompileOptions o;
    o.include_path = {(kData / "inc").string()};
    o.macros = {{"NAME", "A"}};
    Program p = Program::compile_file(data("outputs.plc"), h, o);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ec0.s3.binaryOutput01"], 1);
    EXPECT_EQ(h["ec0.s3.binaryOutput02"], 0);
    EXPECT_EQ(h["static.countA"], 1);
}

TEST(PlcInclude, MissingIncludeFileIsAnError) {
    TableHost h;
    CompileOptions o;
    o.include_path = {"/nonexistent/dir"};
    std::string e;
    try {
        Program::compile_file(data("missing_include.plc"), h, o);
    } catch (const CompileError& err) {
        e = err.what();
    }
    const std::string loc = data("missing_include.plc") + ":2:11: include file 'nowhere.plc_inc' "
                                                          "not found (searched: ";
    EXPECT_EQ(e.rfind(loc, 0), 0u) << e;
    EXPECT_NE(e.find("/nonexistent/dir/nowhere.plc_inc)"), std::string::npos) << e;
    EXPECT_NE(e.find("\n  include \"nowhere.plc_inc\"\n          ^"), std::string::npos) << e;
}

TEST(PlcInclude, RecursiveIncludeIsAnError) {
    TableHost h;
    try {
        Program::compile_file(data("recursive.plc"), h);
        FAIL() << "no error";
    } catch (const CompileError& e) {
        EXPECT_NE(std::string(e.what()).find("recursive include of 'recursive.plc'"),
                  std::string::npos)
            << e.what();
    }
}

TEST(PlcInclude, ErrorsInIncludedFilesNameThatFileAndTheIncluder) {
    TableHost h;
    try {
        Program::compile_file(data("bad_include_user.plc"), h);
        FAIL() << "no error";
    } catch (const CompileError& e) {
        EXPECT_EQ(std::string(e.what()), data("bad.plc_inc") +
                                             ":2:13: unknown name 'ax7.enc.actpos'\n"
                                             "static.y := ax7.enc.actpos;\n"
                                             "            ^\n"
                                             "  included from " +
                                             data("bad_include_user.plc") + ":2");
    }
}

TEST(PlcInclude, UnreadableProgramFileThrows) {
    TableHost h;
    EXPECT_THROW(Program::compile_file(data("no_such_file.plc"), h), Error);
}

// ---- VAR aliases ----------------------------------------------------------------------------

TEST(PlcVarBlock, AliasesForPrefixesFullNamesAndConstants) {
    TableHost h;
    h.add("ax1.enc.actpos", 4);
    h.add("ax1.traj.targetpos");
    Program p = Program::compile(R"(
        early := 1;            // ECMC substitutes in the whole file
        VAR
          myAxis : ax1;        // a prefix: myAxis.enc.actpos is ax1.enc.actpos
          target : ax1.traj.targetpos;
          early  : static.early;
          gain   : 2.5;        # a constant
        END_VAR
        target := myAxis.enc.actpos * gain;
    )",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["ax1.traj.targetpos"], 10);
    EXPECT_EQ(h["static.early"], 1);
}

TEST(PlcVarBlock, Errors) {
    EXPECT_NE(first_error("VAR\n a : static.a;\n a : static.b;\nEND_VAR")
                  .find("t.plc:3:2: 'a' is declared twice in VAR blocks (first at t.plc:2:2)"),
              std::string::npos);
    EXPECT_NE(first_error("VAR\n a static.a;\nEND_VAR").find("t.plc:2:4: expected ':' after 'a'"),
              std::string::npos);
    EXPECT_NE(first_error("VAR\n k : 3;\nEND_VAR\nstatic.x := k.v;")
                  .find("'k' is an alias of a constant and cannot be followed by '.v'"),
              std::string::npos);
}

TEST(PlcVarBlock, WithoutEndVarVarIsExprTksKeyword) {
    TableHost h;
    Program p = Program::compile("VAR t := 3; static.t := t;", "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.t"], 3);
}

// ---- functions ------------------------------------------------------------------------------

TEST(PlcFunctions, LibraryFunctions) {
    TableHost h;
    CompileOptions o;
    o.libraries = {data("lib/kinematics.plc_lib")};
    Program p = Program::compile(R"(
        static.h := half(7);
        static.m := mean(2, 5);
        static.f := fact(6);
        static.w := weighted(4, 8);
        static.t := ten + ten();
    )",
                                 "t.plc", h, o);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.h"], 3.5);
    EXPECT_EQ(h["static.m"], 3.5);
    EXPECT_EQ(h["static.f"], 720);
    EXPECT_EQ(h["static.w"], 7);
    EXPECT_EQ(h["static.t"], 20);
}

TEST(PlcFunctions, DefinedInTheProgramCalledBeforeTheDefinition) {
    TableHost h;
    h.add("ax1.enc.actpos", 3);
    h.add_function("mc_get_busy", 1, 1, [](const double* a, int) { return a[0] == 1 ? 1.0 : 0.0; });
    Program p = Program::compile(R"(
        static.r := scaled(ax1.enc.actpos) + idle(1) + idle(2);
        function scaled(x) { var k := 10; k * x }
        function idle(ax) { not(mc_get_busy(ax)) }
        function nothing() { return []; }
        static.n := nothing();
    )",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.r"], 31);
    EXPECT_TRUE(std::isnan(h["static.n"]));
}

TEST(PlcFunctions, ParametersAreValuesAndLocalsDoNotLeak) {
    TableHost h;
    Program p = Program::compile(R"(
        function bump(a) { a += 1; a }
        var x := 5;
        static.r := bump(x) * 10 + x;
    )",
                                 "t.plc", h);
    ASSERT_EQ(p.run(), 0);
    EXPECT_EQ(h["static.r"], 65);
}

TEST(PlcFunctions, Errors) {
    EXPECT_NE(first_error("function f(a, b) { a + b }\nstatic.x := f(1);")
                  .find("t.plc:2:13: function 'f' takes 2 arguments, got 1"),
              std::string::npos);
    EXPECT_NE(first_error("function f(a) { 1 }\nfunction F(b) { 2 }")
                  .find("function 'F' is defined twice (first at t.plc:1:10)"),
              std::string::npos);
    EXPECT_NE(first_error("function abs(a) { 1 }").find("'abs' cannot be used as a function name"),
              std::string::npos);
    EXPECT_NE(first_error("if (1) { function g() { 1 } };")
                  .find("a function can only be defined at the top level"),
              std::string::npos);
    TableHost h;
    CompileOptions o;
    o.libraries = {data("lib/no_such.plc_lib")};
    EXPECT_THROW(Program::compile("static.a := 1;", "t.plc", h, o), Error);
}

// ---- error reporting ------------------------------------------------------------------------

TEST(PlcErrors, AllErrorsAreCollected) {
    TableHost h;
    const CompileError e = compile_error(h, "static.a := foo;\n"
                                            "static.b := 1 +* 2;\n"
                                            "static.c := bar + baz;\n");
    ASSERT_EQ(e.errors().size(), 4u);
    EXPECT_EQ(std::string(e.what()), e.errors()[0]);
    EXPECT_EQ(e.errors()[0].substr(0, e.errors()[0].find('\n')), "t.plc:1:13: unknown name 'foo'");
    EXPECT_EQ(e.errors()[1].substr(0, e.errors()[1].find('\n')),
              "t.plc:2:16: expected a value, found '*'");
    EXPECT_EQ(e.errors()[2].substr(0, e.errors()[2].find('\n')), "t.plc:3:13: unknown name 'bar'");
    EXPECT_EQ(e.errors()[3].substr(0, e.errors()[3].find('\n')), "t.plc:3:19: unknown name 'baz'");
}

TEST(PlcErrors, StatementsBeforeABracketMismatchStillReportTheirErrors) {
    // an unbalanced bracket hides where later statements begin, not the errors before it
    TableHost h;
    const CompileError e = compile_error(h, "static.a := foo;\n"
                                            "static.b := 1 +* 2;\n"
                                            "static.c := (1 + 2;\n"
                                            "static.d := bar;\n");
    ASSERT_EQ(e.errors().size(), 3u) << e.what();
    EXPECT_EQ(e.errors()[0].substr(0, e.errors()[0].find('\n')), "t.plc:1:13: unknown name 'foo'");
    EXPECT_EQ(e.errors()[1].substr(0, e.errors()[1].find('\n')), "t.plc:2:16: expected a value, found '*'");
    EXPECT_EQ(e.errors()[2].substr(0, e.errors()[2].find('\n')), "t.plc:3:13: '(' is never closed");
    const CompileError u = compile_error(h, "static.a := foo;\nstatic.b := 2);\n");
    ASSERT_EQ(u.errors().size(), 2u) << u.what();
    EXPECT_EQ(u.errors()[1].substr(0, u.errors()[1].find('\n')), "t.plc:2:14: unmatched ')'");
}

TEST(PlcErrors, SyntaxErrorsNameWhatWasExpected) {
    EXPECT_NE(first_error("static.a := (1 + 2];").find("t.plc:1:19: ']' does not match '('"),
              std::string::npos);
    EXPECT_NE(first_error("static.a := (1 + 2;").find("'(' is never closed"), std::string::npos);
    EXPECT_NE(first_error("static.a := 2 static.b := 2;")
                  .find("t.plc:1:15: the left side of ':=' is not a variable: a missing ';'"),
              std::string::npos);
    EXPECT_NE(first_error("break;").find("'break' outside a loop"), std::string::npos);
    EXPECT_NE(first_error("static.a := 1;\n} else {").find("t.plc:2:1: unmatched '}'"),
              std::string::npos);
    EXPECT_NE(first_error("static.a := 3 ? 1;").find("expected ':' between the two values"),
              std::string::npos);
    EXPECT_NE(first_error("static.a := \"x\";").find("strings are written in single quotes"),
              std::string::npos);
}

TEST(PlcErrors, DeepNestingIsAnErrorNotACrash) {
    const std::string deep =
        "static.a := " + std::string(5000, '(') + "1" + std::string(5000, ')') + ";";
    EXPECT_NE(first_error(deep).find("nested more than 400 levels"), std::string::npos);
    const std::string ok =
        "static.a := " + std::string(300, '(') + "1" + std::string(300, ')') + ";";
    TableHost h;
    EXPECT_EQ(Program::compile(ok, "t.plc", h).run(), 0);
}

TEST(PlcErrors, TabsAreKeptInTheCaretLine) {
    EXPECT_EQ(first_error("\tstatic.a := nope;"), "t.plc:1:14: unknown name 'nope'\n"
                                                  "\tstatic.a := nope;\n"
                                                  "\t            ^");
}
