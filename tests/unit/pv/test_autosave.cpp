// Autosave (pv/autosave.hpp): the .sav format, atomic writes, restore before PINI, the .savB
// fallback and the save rate, in virtual time.
#include "../temp_dir.hpp"
#include "pv/autosave.hpp"

#include "db_fixture.hpp"

#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/resource.h>
#include <unistd.h>

namespace beamctl::pv {
namespace {

namespace fs = std::filesystem;

using beamctl::test::TempDir;

std::string slurp(const std::string& p) {
    std::ifstream in(p);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

void spit(const std::string& p, const std::string& text) {
    std::ofstream(p) << text;
}

const char* kDb = R"(
record(ao, "A") { field(PREC, "3") info(autosaveFields, "VAL DESC EGU") }
record(stringout, "S") { info(autosaveFields, "VAL") }
record(waveform, "W") { field(FTVL, "DOUBLE") field(NELM, "5") info(autosaveFields_pass0, "VAL") }
record(ao, "NOTSAVED") { }
)";

TEST(AutosaveFormat, RoundTripOfScalarsStringsAndArrays) {
    std::vector<SavedValue> in = {
        {"A.VAL", false, {"1.2345678901234"}, 0},
        {"S.VAL", false, {"with spaces and \"quotes\""}, 0},
        {"E.DESC", false, {""}, 0},
        {"W.VAL", true, {"1", "2.5", "a \"q\" \\ b"}, 0},
    };
    std::string text = format_save_file(in, "251125-120000");
    EXPECT_EQ(text.substr(0, text.find('\n')),
              "# save/restore V5.11\tAutomatically generated - DO NOT MODIFY - 251125-120000");
    EXPECT_NE(text.find("W.VAL @array@ { \"1\" \"2.5\" \"a \\\"q\\\" \\\\ b\" }\n"), std::string::npos);
    EXPECT_TRUE(text.ends_with("<END>\n"));
    auto out = parse_save_file(text, "x.sav");
    ASSERT_EQ(out.size(), in.size());
    for (std::size_t i = 0; i < in.size(); ++i) {
        EXPECT_EQ(out[i].name, in[i].name);
        EXPECT_EQ(out[i].array, in[i].array);
        EXPECT_EQ(out[i].values, in[i].values) << in[i].name;
        EXPECT_EQ(out[i].line, int(i) + 2);
    }
}

TEST(AutosaveFormat, ReadsSynAppsFilesAndRejectsBrokenOnesWithTheirLine) {
    auto v = parse_save_file("# save/restore V5.10\tAutomatically generated\n"
                             "! 1 channel(s) not connected - or not all gets were successful\n"
                             "#lost.VAL Search Issued\n"
                             "xxx:m1.VAL 12.5\n"
                             "xxx:bo.VAL @ENUM@ 1 \"On\"\n"
                             "<END>\n",
                             "s.sav");
    ASSERT_EQ(v.size(), 2u);
    EXPECT_EQ(v[0].values[0], "12.5");
    EXPECT_EQ(v[1].values[0], "1");
    try {
        parse_save_file("# h\nA.VAL 1\nB.VAL 2\n", "t.sav");
        FAIL() << "no error for a file without <END>";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("t.sav:3: no <END> line"), std::string::npos) << e.what();
    }
    try {
        parse_save_file("# h\nA.VAL 1\nW.VAL @array@ { \"1\" \"2\n<END>\n", "u.sav");
        FAIL() << "no error for a broken array";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("u.sav:3: W.VAL"), std::string::npos) << e.what();
    }
}

TEST(AutosaveRequest, MacrosIncludesAndComments) {
    TempDir d;
    spit(d.file("inner.req"), "# motors\n$(P)m$(N).VELO\n$(P)m$(N)\n");
    spit(d.file("top.req"), "$(P)ao.VAL\n\nfile inner.req N=1\nfile \"inner.req\" N=2\n");
    auto ch = read_request_file("top.req", {{"P", "x:"}}, {d.path.string()});
    std::vector<std::string> want = {"x:ao.VAL", "x:m1.VELO", "x:m1", "x:m2.VELO", "x:m2"};
    EXPECT_EQ(ch, want);
    EXPECT_THROW(read_request_file("none.req", {}, {d.path.string()}), Error);
    spit(d.file("bad.req"), "$(Q)rec\n");
    try {
        read_request_file("bad.req", {}, {d.path.string()});
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("bad.req:1"), std::string::npos) << e.what();
    }
}

TEST(AutosaveWrite, AtomicWriteKeepsThePreviousFileAsBackupAndIntactOnFailure) {
    TempDir d;
    const std::string p = d.file("a.sav");
    write_file_atomically(p, "one\n", true);
    EXPECT_EQ(slurp(p), "one\n");
    EXPECT_FALSE(fs::exists(p + "B"));
    write_file_atomically(p, "two\n", true);
    EXPECT_EQ(slurp(p), "two\n");
    EXPECT_EQ(slurp(p + "B"), "one\n");

    // A write that fails (the file size limit: EFBIG, even for root) leaves the file as it was
    // and no temporary file behind.
    auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
    rlimit old{};
    ::getrlimit(RLIMIT_FSIZE, &old);
    rlimit small = old;
    small.rlim_cur = 8;
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
    bool threw = false;
    try {
        write_file_atomically(p, std::string(100, 'x'), true);
    } catch (const Error& e) {
        threw = true;
        EXPECT_NE(std::string(e.what()).find("write failed"), std::string::npos) << e.what();
    }
    ::setrlimit(RLIMIT_FSIZE, &old);
    std::signal(SIGXFSZ, old_handler);
    EXPECT_TRUE(threw);
    EXPECT_EQ(slurp(p), "two\n");
    EXPECT_EQ(slurp(p + "B"), "one\n");
    int files = 0;
    for (auto& e : fs::directory_iterator(d.path)) (void)e, ++files;
    EXPECT_EQ(files, 2);
}

struct AutosaveTest : DbTest {
    TempDir dir;
    std::vector<std::string> notes;
    std::unique_ptr<Autosave> as;
    void make() {
        as = std::make_unique<Autosave>(db, [this](const std::string& m) { notes.push_back(m); });
        as->set_save_dir(dir.path.string());
    }
    bool noted(const std::string& part) const {
        for (const auto& n : notes)
            if (n.find(part) != std::string::npos) return true;
        return false;
    }
};

TEST_F(AutosaveTest, SavesInfoTaggedFieldsAndRestoresThemInAFreshDatabase) {
    load(kDb);
    make();
    as->add_set("info_settings.sav", channels_from_info(db, "autosaveFields"), 5);
    as->add_set("info_positions.sav", channels_from_info(db, "autosaveFields_pass0"), 5);
    EXPECT_EQ(put("A", 1.0 / 3), PutStatus::Ok);
    EXPECT_EQ(put_str("A.DESC", "a description"), PutStatus::Ok);
    EXPECT_EQ(put_str("S", "hello world"), PutStatus::Ok);
    double w[3] = {1, 2.5, -3};
    EXPECT_EQ(db.put(addr("W"), Prim::Double, w, 3), PutStatus::Ok);
    as->tick(100);
    EXPECT_EQ(as->writes(), 2u);
    std::string text = slurp(dir.file("info_settings.sav"));
    EXPECT_NE(text.find("\nA.VAL 0.3333333333333333\n"), std::string::npos) << text;
    EXPECT_NE(text.find("\nS.VAL hello world\n"), std::string::npos) << text;
    EXPECT_EQ(text.find("NOTSAVED"), std::string::npos);
    EXPECT_NE(slurp(dir.file("info_positions.sav")).find("W.VAL @array@ { \"1\" \"2.5\" \"-3\" }"),
              std::string::npos);

    Database fresh;
    Autosave restorer(fresh, [this](const std::string& m) { notes.push_back(m); });
    restorer.set_save_dir(dir.path.string());
    restorer.add_restore_file("info_positions.sav", 0);
    restorer.add_restore_file("info_settings.sav", 1);
    fresh.set_restore_hook([&] { restorer.restore(); });
    fresh.load(parse_db(kDb, "test.db", {}));
    fresh.init_records();
    Address a;
    ASSERT_TRUE(fresh.resolve("A", a));
    double v = 0;
    fresh.get(a, Prim::Double, &v, 1);
    EXPECT_EQ(v, 1.0 / 3); // full precision, not PREC's 3 digits
    char s[40];
    ASSERT_TRUE(fresh.resolve("A.DESC", a));
    fresh.get(a, Prim::String, s, 1);
    EXPECT_STREQ(s, "a description");
    ASSERT_TRUE(fresh.resolve("W", a));
    double got[5] = {};
    EXPECT_EQ(fresh.get(a, Prim::Double, got, 5), 3u);
    EXPECT_EQ(got[2], -3);
    EXPECT_EQ(restorer.restored(), 5u); // A: VAL DESC EGU, S, W
}

TEST_F(AutosaveTest, RestoreHappensBeforePiniSoThePiniRecordSeesTheValue) {
    spit(dir.file("s.sav"), "# save/restore V5.11\nA.VAL 42\n<END>\n");
    make();
    as->add_restore_file("s.sav", 1);
    db.set_restore_hook([this] { as->restore(); });
    // A's PINI processing writes its VAL on to B: B sees the restored 42, not the .db's 1.
    load(R"(
record(ao, "A") { field(VAL, "1") field(PINI, "YES") field(OUT, "B PP") }
record(ao, "B") { }
)");
    EXPECT_EQ(getd("A"), 42);
    EXPECT_EQ(getd("B"), 42);
}

TEST_F(AutosaveTest, LongStringsThroughDollarChannelsAndBadValuesSkipped) {
    load("record(stringout, \"S\") { }\nrecord(ao, \"N\") { field(VAL, \"3\") }\n");
    make();
    const std::string desc(39, 'd');
    ASSERT_EQ(put_str("S.DESC", desc.c_str()), PutStatus::Ok);
    as->add_set("l.sav", {"S.DESC$", "S.VAL"}, 5);
    as->tick(0);
    EXPECT_NE(slurp(dir.file("l.sav")).find("S.DESC$ " + desc + "\n"), std::string::npos);

    Database fresh;
    spit(dir.file("r.sav"), "# h\nS.DESC$ " + desc + "\nN.VAL not-a-number\nS.VAL ok\n<END>\n");
    Autosave r(fresh, [this](const std::string& m) { notes.push_back(m); });
    r.set_save_dir(dir.path.string());
    r.add_restore_file("r.sav", 1);
    fresh.set_restore_hook([&] { r.restore(); });
    fresh.load(parse_db("record(stringout, \"S\") { }\nrecord(ao, \"N\") { field(VAL, \"3\") }\n", "t.db", {}));
    fresh.init_records();
    Address a;
    char s[40];
    ASSERT_TRUE(fresh.resolve("S.DESC", a));
    fresh.get(a, Prim::String, s, 1);
    EXPECT_EQ(std::string(s), desc);
    ASSERT_TRUE(fresh.resolve("N", a));
    double v = 0;
    fresh.get(a, Prim::Double, &v, 1);
    EXPECT_EQ(v, 3); // the bad value was skipped, the record keeps its own
    EXPECT_TRUE(noted("r.sav:3: N.VAL: the value does not fit the field: skipped"))
        << ::testing::PrintToString(notes);
    EXPECT_EQ(r.restored(), 2u);
}

TEST_F(AutosaveTest, RestoresOnceNotAgainWhenRecordsAreAddedLater) {
    spit(dir.file("s.sav"), "# save/restore V5.11\nA.VAL 42\n<END>\n");
    make();
    as->add_restore_file("s.sav", 1);
    db.set_restore_hook([this] { as->restore(); });
    load("record(ao, \"A\") { }\n");
    EXPECT_EQ(getd("A"), 42);
    put("A", 5);
    load("record(ao, \"LATER\") { }\n"); // init_records again (an RCP application's records)
    EXPECT_EQ(getd("A"), 5);
    EXPECT_EQ(as->restored(), 1u);
}

TEST_F(AutosaveTest, TruncatedFileIsReportedAndTheBackupUsed) {
    spit(dir.file("s.sav"), "# save/restore V5.11\nA.VAL 42\nB.VAL 4"); // cut mid-write
    spit(dir.file("s.savB"), "# save/restore V5.11\nA.VAL 7\nGONE.VAL 3\n<END>\n");
    make();
    as->add_restore_file("s.sav", 1);
    as->add_restore_file("missing.sav", 0);
    db.set_restore_hook([this] { as->restore(); });
    load("record(ao, \"A\") { }\nrecord(ao, \"B\") { }\n");
    EXPECT_EQ(getd("A"), 7);
    EXPECT_EQ(getd("B"), 0);
    EXPECT_TRUE(noted("s.sav:3: no <END> line")) << ::testing::PrintToString(notes);
    EXPECT_TRUE(noted("s.savB:3: GONE.VAL: not in the database"));
    EXPECT_TRUE(noted("missing.sav: not found"));

    // The first save keeps the good .savB: a bad .sav is not worth keeping.
    as->add_set("s.sav", {"A.VAL"}, 5);
    as->tick(0);
    EXPECT_EQ(slurp(dir.file("s.savB")), "# save/restore V5.11\nA.VAL 7\nGONE.VAL 3\n<END>\n");
    EXPECT_NE(slurp(dir.file("s.sav")).find("\nA.VAL 7\n<END>"), std::string::npos);
}

TEST_F(AutosaveTest, SavesOnChangeAtMostOncePerPeriodInVirtualTime) {
    load("record(ao, \"A\") { info(autosaveFields, \"VAL\") }\n");
    make();
    as->add_set("a.sav", channels_from_info(db, "autosaveFields"), 5);
    as->tick(10);
    EXPECT_EQ(as->writes(), 1u); // the first write: the file exists from the start
    for (double t = 10; t < 30; t += 0.1) as->tick(t);
    EXPECT_EQ(as->writes(), 1u); // nothing changed: nothing written
    put("A", 1);
    as->tick(31);
    EXPECT_EQ(as->writes(), 2u);
    // Changes every 0.1 s for 20 s: one write per 5 s.
    double t = 31;
    for (int i = 0; i < 200; ++i, t += 0.1) {
        put("A", 2 + i);
        as->tick(t);
    }
    // Writes at 36, 41 and 46 s (each 5 s after the one before, give or take a 0.1 s tick).
    EXPECT_EQ(as->writes(), 2u + 3u);
    EXPECT_EQ(slurp(dir.file("a.sav")).find("A.VAL 201"), std::string::npos);
    as->flush(); // shutdown: the latest value, at once
    EXPECT_EQ(as->writes(), 6u);
    EXPECT_NE(slurp(dir.file("a.sav")).find("A.VAL 201"), std::string::npos);
    as->flush();
    EXPECT_EQ(as->writes(), 6u);
}

} // namespace
} // namespace beamctl::pv
