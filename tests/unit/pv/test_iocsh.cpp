// The startup-script interpreter (st.cmd): iocsh's line handling (macros from the environment,
// quoting, comments, includes), the commands of soft IOCs, dbpf/dbgf/dbl output as EPICS prints
// it, and errors that name file:line. No sockets: iocInit's serving is a hook here.
#include "pv/iocsh.hpp"

#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <unistd.h>

using namespace beamctl;
using namespace beamctl::pv;
namespace fs = std::filesystem;

namespace {

class Iocsh : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() /
               (std::string("beamctl_iocsh_") + info->name() + "_" + std::to_string(::getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
        cwd_ = fs::current_path();
        fs::current_path(dir_); // relative paths in scripts are from the current directory
        make_shell(false);
    }
    void TearDown() override {
        fs::current_path(cwd_);
        fs::remove_all(dir_);
    }

    void make_shell(bool echo) {
        shell_.reset();
        IocShellOptions o;
        o.out = &out_;
        o.err = &err_;
        o.echo = echo;
        IocShellHooks h;
        h.init = [this] { ++inits_; };
        h.exit = [this](int status) { exits_.push_back(status); };
        shell_ = std::make_unique<IocShell>(*db_, o, h);
    }

    void write(const std::string& rel, const std::string& text) {
        fs::create_directories((dir_ / rel).parent_path());
        std::ofstream(dir_ / rel, std::ios::binary) << text;
    }

    // Runs `text` as "st.cmd"; returns the error ("" if none).
    std::string run(const std::string& text) {
        try {
            shell_->run_text(text, "st.cmd");
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    }

    std::string gets(const std::string& pv) {
        Address a;
        if (!db_->resolve(pv, a)) return "<no " + pv + ">";
        char s[40] = {};
        db_->get(a, Prim::String, s, 1);
        return s;
    }

    std::string output() {
        std::string s = out_.str();
        out_.str("");
        return s;
    }

    fs::path dir_, cwd_;
    std::unique_ptr<Database> db_ = std::make_unique<Database>();
    std::ostringstream out_, err_;
    std::unique_ptr<IocShell> shell_;
    int inits_ = 0;
    std::vector<int> exits_;
};

const char* kDb =
    R"DB(record(ao, "$(P)sp") { field(DRVH, "100") field(DRVL, "-100") field(PREC, "2") }
record(bo, "$(P)sw") { field(ZNAM, "Off") field(ONAM, "On") }
record(longout, "$(P)n") { field(VAL, "7") }
record(stringout, "$(P)s") { field(VAL, "hello") }
)DB";

} // namespace

TEST_F(Iocsh, EnvSetExpandsLaterLinesAndSetsTheEnvironment) {
    ASSERT_EQ(run("epicsEnvSet(\"BCT_IOCSH_A\", \"v 1\")\n"
                  "echo \"$(BCT_IOCSH_A)|${BCT_IOCSH_A}|$(BCT_IOCSH_NONE=dflt)\"\n"),
              "");
    EXPECT_STREQ(std::getenv("BCT_IOCSH_A"), "v 1");
    EXPECT_EQ(output(), "v 1|v 1|dflt\n");
    ::unsetenv("BCT_IOCSH_A");
}

TEST_F(Iocsh, WordsAreSplitAsIocshDoes) {
    ASSERT_EQ(run("echo a,b\n"        // ',' separates: the first word only
                  "echo(\"a,b\")\n"   // parentheses and commas separate, quotes group
                  "echo 'x \"y\"'\n"  // single quotes keep double quotes
                  "echo a\\ b\n"      // a backslash outside quotes: the next character
                  "echo \"c\\\\d\"\n" // ... inside quotes a backslash is kept (echo then unescapes)
                  "   echo   indented  \n"
                  "echo \"\"\n"),
              "");
    EXPECT_EQ(output(), "a\na,b\nx \"y\"\na b\nc\\d\nindented\n\n");
}

TEST_F(Iocsh, EchoTranslatesEscapes) {
    ASSERT_EQ(run("echo 'tab\\there\\x41\\101'\n"), "");
    EXPECT_EQ(output(), "tab\thereAA\n");
}

TEST_F(Iocsh, LinesAreEchoedAfterExpansionCommentsAsWritten) {
    make_shell(true);
    ::setenv("BCT_IOCSH_E", "xyz", 1);
    ASSERT_EQ(run("# comment $(UNDEFINED)\n#- quiet comment\n\necho $(BCT_IOCSH_E)\n"), "");
    EXPECT_EQ(output(), "# comment $(UNDEFINED)\necho xyz\nxyz\n");
    ::unsetenv("BCT_IOCSH_E");
}

TEST_F(Iocsh, QuotingErrorsNameTheLine) {
    EXPECT_EQ(run("echo ok\necho \"open\n"), "st.cmd:2: Unbalanced quote.");
    EXPECT_EQ(run("\n\necho trailing\\"), "st.cmd:3: Trailing backslash.");
    EXPECT_EQ(run("echo x >\n"), "st.cmd:1: Illegal redirection.");
}

TEST_F(Iocsh, UndefinedMacroIsAnErrorWithItsColumn) {
    EXPECT_EQ(run("echo fine\n  dbLoadRecords(\"$(BCT_IOCSH_UNDEFINED)/x.db\")\n"),
              "st.cmd:2:18: undefined macro 'BCT_IOCSH_UNDEFINED'");
}

TEST_F(Iocsh, UnknownCommandStopsTheScriptWithFileAndLine) {
    write("x.db", kDb);
    EXPECT_EQ(run("dbLoadRecords x.db P=A:\n\ndbLoadRecrods x.db P=B:\necho not reached\n"),
              "st.cmd:3: unknown command 'dbLoadRecrods' (did you mean 'dbLoadRecords'?)");
    EXPECT_EQ(output(), "");
    EXPECT_NE(db_->find("A:sp"), nullptr);
    EXPECT_EQ(run("frobnicate\n"), "st.cmd:1: unknown command 'frobnicate'");
}

TEST_F(Iocsh, OnErrorContinueReportsAndGoesOn) {
    EXPECT_EQ(run("on error continue\nbogus 1\necho after\n"), "");
    EXPECT_EQ(output(), "after\n");
    EXPECT_EQ(err_.str(), "st.cmd:2: unknown command 'bogus'\n");
    EXPECT_EQ(run("on error sometimes\n"),
              "st.cmd:1: on error sometimes: not supported (continue or break)");
}

TEST_F(Iocsh, LoadRecordsWithMacrosInitAndDbpfProcesses) {
    write("db/x.db", kDb);
    ASSERT_EQ(run("dbLoadDatabase \"dbd/softIoc.dbd\"\n"
                  "softIoc_registerRecordDeviceDriver(pdbbase)\n"
                  "dbLoadRecords(\"db/x.db\", \"P=T:\")\n"
                  "iocInit\n"
                  "dbpf T:sp 3.5\n"
                  "dbpf T:sw On\n"
                  "dbpf T:n 12\n"
                  "dbpf T:s \"new text\"\n"),
              "");
    EXPECT_EQ(shell_->records_loaded(), 4u);
    EXPECT_TRUE(shell_->initialised());
    EXPECT_EQ(inits_, 1);
    // dbgf's layout: items at tab stops of 10 columns, each padded to the next one.
    EXPECT_EQ(output(), "DBF_DOUBLE:         3.5       \n"
                        "DBF_STRING:         \"On\"      \n"
                        "DBF_LONG:           12 = 0xc  \n"
                        "DBF_STRING:         \"new text\"          \n");
    // The puts processed the records: no longer UDF/INVALID.
    EXPECT_EQ(gets("T:sp.SEVR"), "NO_ALARM");
    EXPECT_EQ(gets("T:sp"), "3.50");
    EXPECT_EQ(gets("T:sw"), "On");
    EXPECT_EQ(gets("T:sw.SEVR"), "NO_ALARM");
    EXPECT_EQ(gets("T:n"), "12");
    // The notes say what was ignored.
    EXPECT_NE(err_.str().find("st.cmd:1: note: dbLoadDatabase ignored"), std::string::npos)
        << err_.str();
    EXPECT_NE(err_.str().find("st.cmd:2: note: softIoc_registerRecordDeviceDriver ignored"),
              std::string::npos);
}

TEST_F(Iocsh, DbpfRefusalsAndOrder) {
    write("x.db", kDb);
    EXPECT_EQ(run("dbLoadRecords x.db P=T:\ndbpf T:sp 1\n"),
              "st.cmd:2: dbpf only works after iocInit");
    EXPECT_EQ(run("iocInit\ndbpf T:nope 1\n"), "st.cmd:2: dbpf: PV 'T:nope' not found");
    EXPECT_EQ(run("dbpf T:sw Maybe\n"),
              "st.cmd:1: dbpf T:sw \"Maybe\": the value cannot be converted to the field's type");
    EXPECT_EQ(run("dbpf T:sp.RTYP ai\n")
                  .rfind("st.cmd:1: dbpf T:sp.RTYP \"ai\": the field is read-only", 0),
              0u);
    EXPECT_EQ(run("dbpf T:sp\n"), "st.cmd:1: dbpf: missing the value (usage: dbpf PV VALUE)");
    EXPECT_EQ(run("iocInit\n"),
              "st.cmd:1: iocInit: the IOC is already initialised (iocInit runs once)");
    EXPECT_EQ(run("dbLoadRecords x.db P=U:\n"),
              "st.cmd:1: dbLoadRecords: records cannot be loaded after iocInit");
    EXPECT_EQ(inits_, 1);
}

TEST_F(Iocsh, DbpfArraysAndDbgf) {
    write("w.db", R"DB(record(waveform, "wd") { field(FTVL, "DOUBLE") field(NELM, "4") }
record(waveform, "wc") { field(FTVL, "CHAR") field(NELM, "16") }
record(waveform, "wl") { field(FTVL, "LONG") field(NELM, "3") }
)DB");
    ASSERT_EQ(run("dbLoadRecords w.db\niocInit\ndbpf wd \"[1.5, 2, -3]\"\ndbpf wc \"hi "
                  "there\"\ndbpf wl [7]\ndbgf wd.NELM\n"),
              "");
    EXPECT_EQ(output(), "DBF_DOUBLE[3]:      1.5       2         -3        \n"
                        "DBF_CHAR[9]:        \"hi there\"          \n"
                        "DBF_LONG:           7 = 0x7   \n"
                        "DBF_ULONG:          4 = 0x4   \n");
    EXPECT_EQ(run("dbpf wd \"[1, 2\"\n"), "st.cmd:1: dbpf: array value '[1, 2' has no closing ']'");
}

TEST_F(Iocsh, DblListsRecordsByTypeWithFields) {
    write("x.db", kDb);
    ASSERT_EQ(run("dbLoadRecords x.db P=A:\ndbLoadRecords x.db P=B:\ndbl\n"), "");
    EXPECT_EQ(output(), "A:sp\nB:sp\nA:sw\nB:sw\nA:n\nB:n\nA:s\nB:s\n");
    ASSERT_EQ(run("dbl bo \"ZNAM recordType NOPE\"\ndbl calcX\ndbl \"\" > list.txt\n"), "");
    EXPECT_EQ(output(), "A:sw, \"Off\", \"bo\", \nB:sw, \"Off\", \"bo\", \nNo record type\n");
    std::ifstream f(dir_ / "list.txt");
    std::stringstream ss;
    ss << f.rdbuf();
    EXPECT_EQ(ss.str(), "A:sp\nB:sp\nA:sw\nB:sw\nA:n\nB:n\nA:s\nB:s\n");
}

TEST_F(Iocsh, DbFileErrorsKeepTheirLocationAndNameTheScriptLine) {
    write("bad.db", "record(ao, \"x\") {\n    field(NOPE, \"1\")\n}\n");
    const std::string e = run("echo one\ndbLoadRecords bad.db\n");
    EXPECT_EQ(e.rfind("bad.db:2:11: ", 0), 0u) << e;
    EXPECT_NE(e.find("\n  loaded by st.cmd:2 (dbLoadRecords)"), std::string::npos) << e;
    EXPECT_EQ(
        run("dbLoadRecords missing.db\n"),
        "missing.db: cannot open: No such file or directory\n  loaded by st.cmd:1 (dbLoadRecords)");
    EXPECT_EQ(run("dbLoadRecords x.db \"P=1,=2\"\n"),
              "st.cmd:1: dbLoadRecords: macros \"P=1,=2\", column 5: in macro definitions: empty "
              "macro name before '='");
}

TEST_F(Iocsh, LoadTemplateBothFormsWithGlobalsAndCommandMacros) {
    write("t/axis.template", R"DB(record(ao, "$(SYS)$(P)$(N)") { field(DESC, "$(D=none)") })DB");
    write("t/ioc.substitutions", R"DB(# two forms
global { P=m }
file "t/axis.template" {
    pattern { N, D }
    { 1, "first axis" }
    { 2, second }
}
file t/axis.template { { N=3 } { P=x, N=4 } }
)DB");
    ASSERT_EQ(
        run("epicsEnvSet SYS BL1:\ndbLoadTemplate(\"t/ioc.substitutions\", \"SYS=$(SYS)\")\ndbl\n"),
        "");
    EXPECT_EQ(output(), "BL1:m1\nBL1:m2\nBL1:m3\nBL1:x4\n");
    EXPECT_EQ(gets("BL1:m1.DESC"), "first axis");
    EXPECT_EQ(gets("BL1:m2.DESC"), "second");
    EXPECT_EQ(gets("BL1:m3.DESC"), "none");
    ::unsetenv("SYS");
}

TEST_F(Iocsh, TemplateFilesAreAlsoFoundInTheIncludePath) {
    write("lib/one.template", R"DB(record(bo, "$(P)b") {})DB");
    write("s.substitutions", "file one.template { {P=a:} }\n");
    make_shell(false);
    IocShellOptions o;
    o.out = &out_;
    o.err = &err_;
    o.echo = false;
    o.include_path = {"lib"};
    IocShell shell(*db_, o);
    shell.run_text("dbLoadTemplate s.substitutions\n", "st.cmd");
    EXPECT_NE(db_->find("a:b"), nullptr);
}

TEST_F(Iocsh, TemplateErrorsNameTheInstanceAndTheScriptLine) {
    write("x.db", R"DB(record(ao, "$(P)v") { field(DRVH, "$(H)") })DB");
    write("s.substitutions", "file x.db {\n  pattern {P H}\n  {a: 1}\n  {b: oops}\n}\n");
    const std::string e = run("dbLoadTemplate s.substitutions\n");
    EXPECT_EQ(e.rfind("x.db:1:", 0), 0u) << e;
    EXPECT_NE(e.find("\n  instance at s.substitutions:4:3\n  loaded by st.cmd:1 (dbLoadTemplate)"),
              std::string::npos)
        << e;
    write("bad.substitutions", "file x.db {\n  {P=a H=1\n}\n");
    EXPECT_EQ(run("dbLoadTemplate bad.substitutions\n"),
              "bad.substitutions:4:1: expected '{' (a set of NAME=VALUE), 'global' or '}', found "
              "end of file\n"
              "  loaded by st.cmd:1 (dbLoadTemplate)");
}

TEST_F(Iocsh, IncludesAreRelativeToTheCurrentDirectoryAndCdMovesIt) {
    write("sub/x.db", kDb);
    write("sub/more.cmd", "dbLoadRecords x.db P=$(Q=M:)\n");
    write("sub/bad.cmd", "echo ok\nnot_a_command\n");
    ASSERT_EQ(run("cd sub\n< more.cmd\niocshLoad(\"more.cmd\", \"Q=N:\")\n"), "");
    EXPECT_NE(db_->find("M:sp"), nullptr);
    EXPECT_NE(db_->find("N:sp"), nullptr);
    EXPECT_EQ(fs::current_path(), fs::canonical(dir_ / "sub"));
    EXPECT_EQ(std::string(std::getenv("PWD")), fs::canonical(dir_ / "sub").string());
    EXPECT_EQ(run("echo $(Q)\n"),
              "st.cmd:1:6: undefined macro 'Q'"); // iocshLoad's macros end with it
    EXPECT_EQ(run("< bad.cmd\n"),
              "bad.cmd:2: unknown command 'not_a_command'\n  included from st.cmd:1");
    EXPECT_EQ(run("\niocshLoad bad.cmd\n"),
              "bad.cmd:2: unknown command 'not_a_command'\n  loaded by st.cmd:2 (iocshLoad)");
    EXPECT_EQ(run("cd nowhere\n"),
              "st.cmd:1: cd: cannot change to \"nowhere\": No such file or directory");
    EXPECT_EQ(run("< nope.cmd\n"), "st.cmd:1: nope.cmd: cannot open: No such file or directory");
    write("sub/loop.cmd", "< loop.cmd\n");
    EXPECT_NE(run("< loop.cmd\n").find("nested more than 32 deep"), std::string::npos);
}

TEST_F(Iocsh, ExitEndsTheScriptItIsIn) {
    write("inner.cmd", "echo inner\nexit\necho not reached\n");
    ASSERT_EQ(run("echo a\n< inner.cmd\necho b\nexit\necho c\n"), "");
    EXPECT_EQ(output(), "a\ninner\nb\n");
}

TEST_F(Iocsh, ExitRecordsStopTheIocOnAPut) {
    shell_->load_exit_records("T", "beamctl 9.9");
    ASSERT_EQ(run("iocInit\ndbgf T:BaseVersion\n"), "");
    EXPECT_EQ(output(), "DBF_STRING:         \"beamctl 9.9\"       \n");
    EXPECT_TRUE(exits_.empty());
    Address a;
    ASSERT_TRUE(db_->resolve("T:exit", a));
    double one = 1;
    EXPECT_EQ(db_->put(a, Prim::Double, &one, 1), PutStatus::Ok);
    EXPECT_EQ(exits_, std::vector<int>{0});
    ASSERT_EQ(run("dbpf T:exit 0\n"), "");
    EXPECT_EQ(exits_, (std::vector<int>{0, 0}));
    ASSERT_TRUE(db_->resolve("T:exit.DESC", a));
    char desc[40] = "changed";
    EXPECT_EQ(db_->put(a, Prim::String, desc, 1), PutStatus::Ok); // not VAL/PROC: no exit
    EXPECT_EQ(exits_.size(), 2u);
}

TEST_F(Iocsh, AccessSecurityFileSurvivesCdAndIsSetBeforeInit) {
    fs::create_directories(dir_ / "conf");
    ASSERT_EQ(run("asSetSubstitutions \"U=ops\"\nasSetFilename conf/x.acf\n"), "");
    EXPECT_EQ(shell_->acf_file(), "conf/x.acf");
    ASSERT_EQ(run("cd conf\n"), "");
    EXPECT_EQ(shell_->acf_file(), (fs::canonical(dir_) / "conf/x.acf").string());
    EXPECT_EQ(shell_->acf_substitutions(), "U=ops");
    EXPECT_EQ(run("asSetSubstitutions \"U\"\n").rfind("st.cmd:1: asSetSubstitutions \"U\"", 0), 0u);
    ASSERT_EQ(run("iocInit\n"), "");
    EXPECT_EQ(run("asSetFilename y.acf\n"), "st.cmd:1: asSetFilename must come before iocInit");
}

TEST_F(Iocsh, EnvShowAndUnset) {
    ::setenv("BCT_IOCSH_SHOW1", "a", 1);
    ::setenv("BCT_IOCSH_SHOW2", "b", 1);
    ASSERT_EQ(run("epicsEnvShow BCT_IOCSH_SHOW*\nepicsEnvUnset BCT_IOCSH_SHOW1\nepicsEnvShow "
                  "BCT_IOCSH_SHOW?\n"),
              "");
    std::string out = output();
    EXPECT_EQ(out, "BCT_IOCSH_SHOW1=a\nBCT_IOCSH_SHOW2=b\nBCT_IOCSH_SHOW2=b\n");
    ::unsetenv("BCT_IOCSH_SHOW2");
}

TEST_F(Iocsh, MissingArgumentsSayTheUsage) {
    EXPECT_EQ(run("dbLoadRecords\n"),
              "st.cmd:1: dbLoadRecords: missing argument 1 (usage: dbLoadRecords FILE [MACROS])");
    EXPECT_EQ(run("epicsEnvSet X\n"),
              "st.cmd:1: epicsEnvSet: missing the value of X (usage: epicsEnvSet NAME VALUE)");
    EXPECT_EQ(run("epicsThreadSleep soon\n"),
              "st.cmd:1: epicsThreadSleep: 'soon' should be a number of seconds from 0 to 3600");
    EXPECT_EQ(
        run("dbl > /nonexistent/dir/x\n").rfind("st.cmd:1: cannot open \"/nonexistent/dir/x\"", 0),
        0u);
    EXPECT_EQ(run("dbl < x.cmd\n"),
              "st.cmd:1: dbl: '<' (input from a file) works only on a line of its own");
}

TEST_F(Iocsh, PrintFieldOfAnUnknownPv) {
    std::ostringstream os;
    EXPECT_FALSE(print_field(*db_, "nope", os));
    EXPECT_EQ(os.str(), "PV 'nope' not found\n");
}

// Random lines: each one runs or is an Error that says file:line; nothing else escapes, nothing
// crashes (scripts that include themselves end at the nesting limit).
TEST_F(Iocsh, RandomLinesRunOrFailCleanly) {
    write("x.db", kDb);
    const char* pieces[] = {"echo",
                            "epicsEnvSet",
                            "BCT_F",
                            "dbpf",
                            "dbgf",
                            "dbl",
                            "iocInit",
                            "dbLoadRecords",
                            "x.db",
                            "P=R:",
                            "R:sp",
                            "R:sw",
                            "On",
                            "(",
                            ")",
                            ",",
                            "\"",
                            "'",
                            "\\",
                            "$(",
                            "$(BCT_F)",
                            "${BCT_F=1}",
                            "<",
                            ">",
                            ">>",
                            "out.cmd",
                            "#",
                            " ",
                            "  ",
                            "exit",
                            "12",
                            "on error continue",
                            "dbLoadTemplate",
                            "asSetFilename",
                            "[1,2]",
                            "cd",
                            "."};
    std::mt19937 rng(7);
    int ok = 0, failed = 0;
    for (int n = 0; n < 3000; ++n) {
        std::string text;
        const int lines = 1 + int(rng() % 4);
        for (int l = 0; l < lines; ++l) {
            const int len = int(rng() % 7);
            for (int k = 0; k < len; ++k) text += pieces[rng() % std::size(pieces)];
            text += "\n";
        }
        try {
            shell_->run_text(text, "st.cmd");
            ++ok;
        } catch (const Error& e) {
            const std::string what = e.what();
            const bool located = what.rfind("st.cmd:", 0) == 0 || what.rfind("out.cmd:", 0) == 0 ||
                                 what.rfind("x.db:", 0) == 0 || what.rfind("R:", 0) == 0 ||
                                 what.find(": cannot open:") != std::string::npos;
            ASSERT_TRUE(located) << text << " -> " << what;
            ++failed;
        }
        if (n % 100 == 99) { // a fresh database and shell now and then
            fs::current_path(dir_);
            shell_.reset();
            db_ = std::make_unique<Database>();
            make_shell(false);
            fs::remove(dir_ / "out.cmd");
        }
    }
    EXPECT_GT(ok, 100);
    EXPECT_GT(failed, 100);
    ::unsetenv("BCT_F");
}
