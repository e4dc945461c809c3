// `beamctl shell`'s commands (pv/db_shell.hpp) on a database, without sockets.
#include "pv/db_shell.hpp"

#include "db_fixture.hpp"

#include <sstream>

namespace beamctl::pv {
namespace {

struct DbShellTest : DbTest {
    DbShell shell{db, {[this](int level, std::ostream& os) { os << "casr level " << level << "\n"; }}};
    bool ok = false;
    std::string run(const std::string& line) {
        std::ostringstream os;
        ok = shell.execute(line, os);
        return os.str();
    }
    void SetUp() override {
        load(R"(
record(ao, "x:ao") { field(DESC, "set point") field(PREC, "2") field(EGU, "mm") }
record(calc, "x:calc") { field(INPA, "x:ao") field(CALC, "A+1") }
record(ai, "x:slow") { field(SCAN, "1 second") }
record(ai, "x:fast") { field(SCAN, ".1 second") }
)");
    }
};

TEST_F(DbShellTest, DblListsByTypeAndPatternWithFields) {
    EXPECT_EQ(run("dbl"), "x:slow\nx:fast\nx:ao\nx:calc\n");
    EXPECT_EQ(run("dbl ao \"DESC EGU NOPE\""), "x:ao, \"set point\", \"mm\", \n");
    EXPECT_EQ(run("dbl x:*a*"), "x:fast\nx:ao\nx:calc\n");
    EXPECT_EQ(run("dbl(\"calc\", \"recordType\")"), "x:calc, \"calc\"\n");
    EXPECT_TRUE(ok);
}

TEST_F(DbShellTest, DbpfGoesThroughThePutRulesAndDbgfPrintsAsEpics) {
    EXPECT_EQ(run("dbpf x:ao 2.5"), "DBF_DOUBLE:         2.5       \n");
    EXPECT_TRUE(ok);
    EXPECT_EQ(getd("x:ao"), 2.5);
    EXPECT_EQ(run("dbgf x:ao.EGU"), "DBF_STRING:         \"mm\"      \n");
    std::string out = run("dbpf x:ao.STAT 1");
    EXPECT_FALSE(ok);
    EXPECT_NE(out.find("error: dbpf x:ao.STAT \"1\": the field is read-only"), std::string::npos) << out;
    out = run("dbpf x:ao abc");
    EXPECT_FALSE(ok);
    EXPECT_NE(out.find("cannot be converted"), std::string::npos) << out;
    EXPECT_EQ(getd("x:ao"), 2.5);
    run("dbgf x:nothing");
    EXPECT_FALSE(ok);
}

TEST_F(DbShellTest, DbprAndDbtr) {
    put("x:ao", 3);
    std::string out = run("dbpr x:ao");
    EXPECT_EQ(out.substr(0, out.find('\n')),
              "ASG:                DESC: set point     DISA: 0             DISP: 0             ");
    EXPECT_NE(out.find("NAME: x:ao"), std::string::npos);
    EXPECT_NE(out.find("VAL: 3.00"), std::string::npos) << out;
    EXPECT_EQ(out.find("EGU:"), std::string::npos);
    EXPECT_NE(run("dbpr x:ao 1").find("EGU: mm"), std::string::npos);
    EXPECT_EQ(run("dbpr x:none"), "Record 'x:none' not found\n");
    EXPECT_FALSE(ok);
    run("dbpr x:ao many");
    EXPECT_FALSE(ok);

    EXPECT_EQ(getd("x:calc"), 0);
    out = run("dbtr x:calc");
    EXPECT_TRUE(ok);
    EXPECT_NE(out.find("VAL: 4"), std::string::npos) << out;
    EXPECT_EQ(getd("x:calc"), 4);
}

TEST_F(DbShellTest, ScanpplCasrHelpAndBadLines) {
    std::string out = run("scanppl");
    EXPECT_NE(out.find("Scan list for 1 second:\n    x:slow\n"), std::string::npos) << out;
    EXPECT_NE(out.find("Scan list for .1 second:\n    x:fast\n"), std::string::npos) << out;
    EXPECT_EQ(run("scanppl 1"), "Scan list for 1 second:\n    x:slow\n");
    EXPECT_EQ(run("casr 2"), "casr level 2\n");
    EXPECT_NE(run("help").find("dbpf NAME[.FIELD] VALUE"), std::string::npos);
    EXPECT_EQ(run("   "), "");
    EXPECT_TRUE(ok);
    EXPECT_EQ(run("# comment"), "");
    EXPECT_EQ(run("dbgf \"x:ao"), "error: Unbalanced quote.\n");
    EXPECT_FALSE(ok);
    EXPECT_EQ(run("rm -rf /"), "error: unknown command 'rm' (help lists the commands)\n");
    DbShell bare(db);
    std::ostringstream os;
    EXPECT_FALSE(bare.execute("casr", os));
    EXPECT_EQ(os.str(), "error: casr: this IOC has no Channel Access server\n");
}

} // namespace
} // namespace beamctl::pv
