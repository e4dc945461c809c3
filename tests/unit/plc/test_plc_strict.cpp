// Strict ECMC mode (issue 18): with CompileOptions::strict, each construct beamctl accepts and
// ECMC's ExprTk refuses is a compile error naming the place and the ECMC spelling; what ExprTk
// accepts still compiles. The table's verdicts come from ExprTk itself (strict_ecmc_table.hpp).
#include "plc/program.hpp"
#include "strict_ecmc_table.hpp"

#include <gtest/gtest.h>

#include <map>
#include <string>

using namespace beamctl::plc;

namespace {

// Every name is a variable of its own (as ECMC binds ax/ec/static names; here any name).
class AnyHost : public Host {
public:
    std::optional<Binding> resolve(std::string_view name) override {
        return Binding{&vars_[std::string(name)], true, 1};
    }

private:
    std::map<std::string, double> vars_;
};

std::string compile_error(const char* code, bool strict) {
    AnyHost h;
    CompileOptions o;
    o.strict = strict;
    try {
        Program::compile(code, "t.plc", h, o);
    } catch (const CompileError& e) {
        std::string all;
        for (const auto& m : e.errors()) all += m + "\n";
        return all.empty() ? "?" : all;
    }
    return {};
}

} // namespace

TEST(PlcStrict, TableOfConstructsAgainstExprTk) {
    for (const test::StrictCase& c : test::kStrictCases) {
        SCOPED_TRACE(c.code);
        EXPECT_EQ(compile_error(c.code, false), "") << "beamctl accepts every case of the table";
        const std::string strict = compile_error(c.code, true);
        if (c.exprtk_accepts) {
            EXPECT_EQ(strict, "");
        } else {
            EXPECT_NE(strict.find("t.plc:"), std::string::npos) << strict;
            EXPECT_NE(strict.find("strict ECMC: ExprTk refuses"), std::string::npos) << strict;
            EXPECT_NE(strict.find(c.ecmc_spelling), std::string::npos) << strict;
        }
    }
}

TEST(PlcStrict, ErrorsPointAtTheConstruct) {
    const std::string e = compile_error("x := 1;\nif (x) {\n  { y := 1; z := 2; };\n};\n", true);
    EXPECT_NE(e.find("t.plc:3:3: strict ECMC: ExprTk refuses a bare '{ ...; }' block"), std::string::npos) << e;
    const std::string f = compile_error("x := 1;\n\nfor (; x < 3; x += 1) { y := x; };\n", true);
    EXPECT_NE(f.find("t.plc:3:6: strict ECMC: ExprTk refuses 'for' without an initialiser"), std::string::npos) << f;
    // every refused construct of a file is reported, not only the first
    const std::string g = compile_error("x := 1;;\n{ y := 1; };\nswitch { case x : y := 2 };\n", true);
    EXPECT_NE(g.find("t.plc:1:8:"), std::string::npos) << g;
    EXPECT_NE(g.find("t.plc:2:1:"), std::string::npos) << g;
    EXPECT_NE(g.find("t.plc:3:"), std::string::npos) << g;
}

TEST(PlcStrict, FunctionsAreFineInLibraries) {
    AnyHost h;
    CompileOptions o;
    o.strict = true;
    o.libraries = {std::string(BEAMCTL_SOURCE_DIR) + "/tests/unit/plc/data/strict_lib.plc"};
    EXPECT_NO_THROW(Program::compile("x := twice(2);", "t.plc", h, o));
}

TEST(PlcStrict, ShippedExamplesPassStrictMode) {
    const std::string root = BEAMCTL_SOURCE_DIR;
    for (const char* f : {"examples/kinematics/mirror.plc", "examples/kinematics/mirror_matrix.plc",
                          "examples/kinematics/slit.plc", "examples/kinematics/spiral.plc",
                          "examples/kinematics/spiral_stage.plc", "examples/demo/plc/slit.plc",
                          "examples/demo/plc/mirror.plc"}) {
        SCOPED_TRACE(f);
        AnyHost h;
        CompileOptions o;
        o.strict = true;
        o.macros = {{"SELF", "plc0"}, {"SELF_ID", "0"}};
        o.include_path = {root + "/examples/plc_lib"};
        EXPECT_NO_THROW(Program::compile_file(root + "/" + f, h, o));
    }
}
