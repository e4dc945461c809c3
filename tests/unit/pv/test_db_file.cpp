#include "pv/db_file.hpp"

#include "core/error_list.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

using beamctl::Error;
using beamctl::MacroMap;
using beamctl::MultiError;
using beamctl::SourceLoc;
using beamctl::pv::DbField;
using beamctl::pv::DbFile;
using beamctl::pv::DbRecord;
using beamctl::pv::load_db_file;
using beamctl::pv::merge_db;
using beamctl::pv::parse_db;

namespace fs = std::filesystem;

namespace {

template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "<no error>";
}

// Parses `text` as "t.db" and returns the error message ("<no error>" when it parses).
std::string parse_error(const std::string& text, const MacroMap& macros = {}) {
    return error_of([&] { parse_db(text, "t.db", macros); });
}

std::string loc_of(const SourceLoc& loc) {
    return loc.str();
}

// A fresh directory per test, removed afterwards.
class DbFileDir : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() /
               (std::string("beamctl_db_") + info->name() + "_" + std::to_string(::getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::string write(const std::string& rel, const std::string& text) {
        const fs::path p = dir_ / rel;
        fs::create_directories(p.parent_path());
        std::ofstream(p, std::ios::binary) << text;
        return p.string();
    }
    std::string path(const std::string& rel) const { return (dir_ / rel).string(); }

    fs::path dir_;
};

const MacroMap kMacros = {
    {"P", "DEMO:"}, {"R", "m1"}, {"LONG", "a-much-longer-value-than-the-ref"}};

} // namespace

// ---- constructs -----------------------------------------------------------------------------

TEST(ParseDb, SimpleRecord) {
    const DbFile db = parse_db("record(ai, \"DEMO:x\") {\n"
                               "    field(DESC, \"hello world\")\n"
                               "    field(VAL, 1.5)\n"
                               "}\n",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 1u);
    const DbRecord& r = db.records[0];
    EXPECT_EQ(r.type, "ai");
    EXPECT_EQ(r.name, "DEMO:x");
    EXPECT_EQ(loc_of(r.loc), "t.db:1:1");
    ASSERT_EQ(r.fields.size(), 2u);
    EXPECT_EQ(r.fields[0].name, "DESC");
    EXPECT_EQ(r.fields[0].value, "hello world");
    EXPECT_EQ(loc_of(r.fields[0].loc), "t.db:2:11");
    EXPECT_EQ(r.fields[1].name, "VAL");
    EXPECT_EQ(r.fields[1].value, "1.5");
    EXPECT_EQ(loc_of(r.fields[1].loc), "t.db:3:11");
    EXPECT_TRUE(r.infos.empty());
    EXPECT_TRUE(r.aliases.empty());
    EXPECT_TRUE(db.aliases.empty());
}

TEST(ParseDb, EmptyText) {
    const DbFile db = parse_db("  # only a comment\n\n", "t.db", {});
    EXPECT_TRUE(db.records.empty());
    EXPECT_TRUE(db.aliases.empty());
}

TEST(ParseDb, QuotedAndBareTypeAndName) {
    const DbFile db = parse_db("record(\"calc\", DEMO:a-b+c_d[1]<x>;y) {}\n"
                               "grecord(bo, \"DEMO:g\")\n",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 2u);
    EXPECT_EQ(db.records[0].type, "calc");
    EXPECT_EQ(db.records[0].name, "DEMO:a-b+c_d[1]<x>;y");
    EXPECT_EQ(db.records[1].type, "bo");
    EXPECT_EQ(db.records[1].name, "DEMO:g");
    EXPECT_EQ(loc_of(db.records[1].loc), "t.db:2:1");
}

TEST(ParseDb, RecordBodyMayBeOmitted) {
    const DbFile db =
        parse_db("record(ai, a)\nrecord(ao, b) record(bi, c){}record(bo,d)", "t.db", {});
    ASSERT_EQ(db.records.size(), 4u);
    EXPECT_EQ(db.records[0].name, "a");
    EXPECT_EQ(db.records[1].name, "b");
    EXPECT_EQ(db.records[2].name, "c");
    EXPECT_EQ(db.records[3].name, "d");
    EXPECT_EQ(loc_of(db.records[3].loc), "t.db:2:30");
    for (const auto& r : db.records) EXPECT_TRUE(r.fields.empty());
}

TEST(ParseDb, InfoAndAliases) {
    const DbFile db = parse_db("record(ai, \"DEMO:x\") {\n"
                               "  alias(\"DEMO:y\")\n"
                               "  info(autosaveFields, \"VAL DESC\")\n"
                               "  field(VAL, 0)\n"
                               "  alias(DEMO:z)\n"
                               "}\n"
                               "alias(\"DEMO:x\", \"DEMO:w\")\n"
                               "alias(DEMO:other, DEMO:v)\n",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 1u);
    const DbRecord& r = db.records[0];
    EXPECT_EQ(r.aliases, (std::vector<std::string>{"DEMO:y", "DEMO:z"}));
    ASSERT_EQ(r.infos.size(), 1u);
    EXPECT_EQ(r.infos[0].name, "autosaveFields");
    EXPECT_EQ(r.infos[0].value, "VAL DESC");
    EXPECT_EQ(loc_of(r.infos[0].loc), "t.db:3:8");
    ASSERT_EQ(r.fields.size(), 1u);
    ASSERT_EQ(db.aliases.size(), 2u);
    EXPECT_EQ(db.aliases[0].record, "DEMO:x");
    EXPECT_EQ(db.aliases[0].alias, "DEMO:w");
    EXPECT_EQ(loc_of(db.aliases[0].loc), "t.db:7:1");
    EXPECT_EQ(db.aliases[1].record, "DEMO:other"); // target may be defined elsewhere
    EXPECT_EQ(db.aliases[1].alias, "DEMO:v");
}

TEST(ParseDb, CommentsAreSkippedAndNotExpanded) {
    const DbFile db = parse_db("# record(ai, $(UNDEFINED))\n"
                               "record(ai, x) { # $(ALSO_UNDEFINED) {\n"
                               "  field(DESC, \"a # not a comment\") # comment\n"
                               "  field(EGU, mm)# touching\n"
                               "}",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 1u);
    ASSERT_EQ(db.records[0].fields.size(), 2u);
    EXPECT_EQ(db.records[0].fields[0].value, "a # not a comment");
    EXPECT_EQ(db.records[0].fields[1].value, "mm");
}

TEST(ParseDb, StringEscapes) {
    const DbFile db = parse_db(
        R"~(record(ai, x) { field(DESC, "q\"b\\s\n\t\r\a\b\f\v\'\?\x41\x4a2\101\7\q\$(P)") })~",
        "t.db", {});
    const std::string expected = std::string("q\"b\\s\n\t\r\a\b\f\v'?AJ2A") + '\7' + "q$(P)";
    EXPECT_EQ(db.records[0].fields[0].value, expected);
}

TEST(ParseDb, EmptyStringValueAndUnicode) {
    const DbFile db = parse_db("record(ai, x) { field(DESC, \"\") field(EGU, \"\xC2\xB5m\") "
                               "field(VAL, 1) }",
                               "t.db", {});
    EXPECT_EQ(db.records[0].fields[0].value, "");
    EXPECT_EQ(db.records[0].fields[1].value, "\xC2\xB5m");
    EXPECT_EQ(loc_of(db.records[0].fields[2].loc), "t.db:1:56"); // µ counts as one column
}

TEST(ParseDb, JsonValues) {
    const DbFile db = parse_db("record(ai, x) {\n"
                               "  field(INP, {const: 1.5})\n"
                               "  field(VAL, [1, 2, \"$(P)]\"])\n"
                               "  info(Q:group, {\"$(P)grp\": {  # comment with } and $(NOPE)\n"
                               "      \"+id\": \"x\\\"y\", \"a\": [{}, []]}})\n"
                               "  field(DESC, done)\n"
                               "}\n",
                               "t.db", kMacros);
    const DbRecord& r = db.records[0];
    ASSERT_EQ(r.fields.size(), 3u);
    EXPECT_EQ(r.fields[0].value, "{const: 1.5}");
    EXPECT_EQ(r.fields[1].value, "[1, 2, \"DEMO:]\"]");
    ASSERT_EQ(r.infos.size(), 1u);
    EXPECT_EQ(r.infos[0].value, "{\"DEMO:grp\": {  \n      \"+id\": \"x\\\"y\", \"a\": [{}, []]}}");
    EXPECT_EQ(r.fields[2].value, "done");
    EXPECT_EQ(loc_of(r.fields[2].loc), "t.db:6:9");
}

// ---- macros -----------------------------------------------------------------------------------

TEST(ParseDb, MacrosInAllPositions) {
    const MacroMap m = {{"P", "DEMO:"}, {"T", "ai"}, {"F", "DESC"}, {"V", "text"}, {"I", "ifo"}};
    const DbFile db = parse_db("record($(T), \"$(P)x\") {\n"
                               "  field($(F), \"$(V) and ${V}\")\n"
                               "  field(\"E$(F=GU)\", $(V)-$(R=m1):b)\n"
                               "  info($(I), $(I=none))\n"
                               "  alias(\"$(P)al\")\n"
                               "}\n"
                               "alias($(P)x, $(P)al2)\n",
                               "t.db", m);
    const DbRecord& r = db.records[0];
    EXPECT_EQ(r.type, "ai");
    EXPECT_EQ(r.name, "DEMO:x");
    ASSERT_EQ(r.fields.size(), 2u);
    EXPECT_EQ(r.fields[0].name, "DESC");
    EXPECT_EQ(r.fields[0].value, "text and text");
    EXPECT_EQ(r.fields[1].name, "EDESC");
    EXPECT_EQ(r.fields[1].value, "text-m1:b");
    EXPECT_EQ(r.infos[0].name, "ifo");
    EXPECT_EQ(r.infos[0].value, "ifo");
    EXPECT_EQ(r.aliases, (std::vector<std::string>{"DEMO:al"}));
    EXPECT_EQ(db.aliases[0].record, "DEMO:x");
    EXPECT_EQ(db.aliases[0].alias, "DEMO:al2");
}

TEST(ParseDb, LocationsStayInTheOriginalFileThroughExpansion) {
    // Same line: $(LONG) expands to 32 characters but columns stay those of the file.
    const DbFile db = parse_db("record(ai, \"$(P)$(LONG)\") { field(DESC, \"$(LONG)\") "
                               "field(VAL, $(LONG)) info(x, 1) }\n"
                               "  record(ai, $(P)y)",
                               "t.db", kMacros);
    ASSERT_EQ(db.records.size(), 2u);
    const DbRecord& r = db.records[0];
    EXPECT_EQ(r.name, "DEMO:a-much-longer-value-than-the-ref");
    EXPECT_EQ(loc_of(r.fields[0].loc), "t.db:1:35");
    EXPECT_EQ(loc_of(r.fields[1].loc), "t.db:1:58");
    EXPECT_EQ(loc_of(r.infos[0].loc), "t.db:1:77");
    EXPECT_EQ(loc_of(db.records[1].loc), "t.db:2:3");
    EXPECT_EQ(
        parse_error("record(ai, \"$(LONG)\") { field(DESC, \"$(LONG)\") field(X, $(Q)) }", kMacros),
        "t.db:1:57: undefined macro 'Q'");
}

TEST(ParseDb, MacroErrorsPointAtTheDollar) {
    EXPECT_EQ(parse_error("record(ai, x) {\n    field(DESC, \"ab $(Q)\")\n}"),
              "t.db:2:21: undefined macro 'Q'");
    EXPECT_EQ(parse_error("record(ai, x$(R)$(Q)) {}", kMacros), "t.db:1:17: undefined macro 'Q'");
    EXPECT_EQ(parse_error("record(ai, x) { field(A, \"$(P$(Q))\") }", kMacros),
              "t.db:1:30: undefined macro 'Q'");
    EXPECT_EQ(parse_error("record(ai, \"$(A)\")", MacroMap{{"A", "$(B)"}, {"B", "$(A)"}}),
              "t.db:1:13: recursive macro 'A' (A -> B -> A)");
    EXPECT_EQ(parse_error("record(ai, \"$(A)\")", MacroMap{{"A", "x$(Q)"}}),
              "t.db:1:13: undefined macro 'Q' in the value of macro 'A'");
    EXPECT_EQ(parse_error("record(ai, \"$(P\")", kMacros),
              "t.db:1:16: unterminated quote \" in macro reference");
    EXPECT_EQ(parse_error("record(ai, $(P\n, x)", kMacros),
              "t.db:1:12: unterminated macro reference '$(P': expected ')', found end of line");
}

TEST(ParseDb, MacroValuesAreInsertedLiterally) {
    const MacroMap m = {{"D", R"(say "hi" \n)"}, {"W", R"(C:\dir)"}, {"S", "a b"}};
    const DbFile db = parse_db(
        R"~(record(ai, x) { field(DESC, "$(D)") field(A, "$(W)") field(B, $(S)) field(C, "\$(D)") })~",
        "t.db", m);
    const auto& f = db.records[0].fields;
    EXPECT_EQ(f[0].value, R"(say "hi" \n)");
    EXPECT_EQ(f[1].value, R"(C:\dir)");
    EXPECT_EQ(f[2].value, "a b");
    EXPECT_EQ(f[3].value, "$(D)");
}

TEST(ParseDb, MacroDefaultsAndQuotesInsideReferences) {
    const DbFile db = parse_db(
        R"~(record(ai, x) { field(A, "$(X="q,(u)o")") field(B, "$(X=a\"b)") field(C, $(X=d)) })~",
        "t.db", {});
    const auto& f = db.records[0].fields;
    EXPECT_EQ(f[0].value, "q,(u)o");
    EXPECT_EQ(f[1].value, "a\"b");
    EXPECT_EQ(f[2].value, "d");
}

// ---- redefinition -----------------------------------------------------------------------------

TEST(ParseDb, DuplicateFieldLaterWinsAndKeepsPlace) {
    const DbFile db = parse_db("record(ai, x) {\n"
                               "  field(A, 1)\n"
                               "  field(B, 2)\n"
                               "  field(A, 3)\n"
                               "  info(i, 1)\n"
                               "  info(i, 2)\n"
                               "}",
                               "t.db", {});
    const auto& f = db.records[0].fields;
    ASSERT_EQ(f.size(), 2u);
    EXPECT_EQ(f[0].name, "A");
    EXPECT_EQ(f[0].value, "3");
    EXPECT_EQ(loc_of(f[0].loc), "t.db:4:9");
    EXPECT_EQ(f[1].name, "B");
    ASSERT_EQ(db.records[0].infos.size(), 1u);
    EXPECT_EQ(db.records[0].infos[0].value, "2");
}

TEST(ParseDb, SameTypeOrStarMerges) {
    const DbFile db = parse_db("record(ai, x) { field(A, 1) field(B, 1) }\n"
                               "record(ao, y)\n"
                               "record(ai, x) { field(B, 2) field(C, 2) alias(x1) }\n"
                               "record(\"*\", x) { field(D, 3) info(i, v) alias(x2) }\n",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 2u);
    const DbRecord& r = db.records[0];
    EXPECT_EQ(r.name, "x");
    EXPECT_EQ(r.type, "ai");
    EXPECT_EQ(loc_of(r.loc), "t.db:1:1");
    ASSERT_EQ(r.fields.size(), 4u);
    EXPECT_EQ(r.fields[0].name + "=" + r.fields[0].value, "A=1");
    EXPECT_EQ(r.fields[1].name + "=" + r.fields[1].value, "B=2");
    EXPECT_EQ(r.fields[2].name + "=" + r.fields[2].value, "C=2");
    EXPECT_EQ(r.fields[3].name + "=" + r.fields[3].value, "D=3");
    EXPECT_EQ(loc_of(r.fields[3].loc), "t.db:4:24");
    EXPECT_EQ(r.infos.size(), 1u);
    EXPECT_EQ(r.aliases, (std::vector<std::string>{"x1", "x2"}));
    EXPECT_EQ(db.records[1].name, "y");
}

TEST(ParseDb, DifferentTypeIsAnError) {
    EXPECT_EQ(parse_error("record(ai, x)\n\nrecord(bo, \"x\") { field(A, 1) }"),
              "t.db:3:8: record 'x' redefined with type 'bo', but it has type 'ai' (defined at "
              "t.db:1:1)");
}

TEST(ParseDb, StarRecordNotDefinedHereIsKeptForTheInstaller) {
    const DbFile db = parse_db("record(\"*\", ext) { field(A, 1) }\n"
                               "record(\"*\", ext) { field(B, 2) }\n"
                               "record(ai, ext) { field(C, 3) }\n"
                               "record(\"*\", ext) { field(D, 4) }\n",
                               "t.db", {});
    ASSERT_EQ(db.records.size(), 2u);
    EXPECT_EQ(db.records[0].type, "*");
    EXPECT_EQ(db.records[0].name, "ext");
    ASSERT_EQ(db.records[0].fields.size(), 2u);
    EXPECT_EQ(db.records[0].fields[1].name, "B");
    EXPECT_EQ(db.records[1].type, "ai");
    EXPECT_EQ(loc_of(db.records[1].loc), "t.db:3:1");
    ASSERT_EQ(db.records[1].fields.size(), 2u);
    EXPECT_EQ(db.records[1].fields[1].name, "D");
}

TEST(ParseDb, AliasConflicts) {
    EXPECT_EQ(parse_error("record(ai, x) { alias(x) }"),
              "t.db:1:23: alias 'x' has the name of record 'x' (defined at t.db:1:1)");
    EXPECT_EQ(parse_error("record(ai, x) { alias(a) }\nalias(x, \"a\")"),
              "t.db:2:10: alias 'a' is already defined (at t.db:1:23)");
    EXPECT_EQ(parse_error("alias(x, a)\nrecord(ai, a)"),
              "t.db:2:12: record name 'a' is already an alias (defined at t.db:1:1)");
}

TEST(MergeDb, AppliesTheSameRulesAcrossFiles) {
    DbFile a = parse_db("record(ai, x) { field(A, 1) alias(xa) }", "a.db", {});
    const DbFile b = parse_db("record(\"*\", x) { field(A, 2) field(B, 2) }\n"
                              "record(bo, z) alias(x, xb) record(\"*\", other)",
                              "b.db", {});
    merge_db(a, b);
    ASSERT_EQ(a.records.size(), 3u);
    EXPECT_EQ(a.records[0].type, "ai");
    ASSERT_EQ(a.records[0].fields.size(), 2u);
    EXPECT_EQ(a.records[0].fields[0].value, "2");
    EXPECT_EQ(loc_of(a.records[0].fields[0].loc), "b.db:1:24");
    EXPECT_EQ(a.records[1].name, "z");
    EXPECT_EQ(a.records[2].type, "*");
    ASSERT_EQ(a.aliases.size(), 1u);

    const DbFile c = parse_db("record(ao, x)", "c.db", {});
    EXPECT_EQ(error_of([&] { merge_db(a, c); }),
              "c.db:1:1: record 'x' redefined with type 'ao', but it has type 'ai' (defined at "
              "a.db:1:1)");
    const DbFile d = parse_db("alias(z, xa)", "d.db", {});
    EXPECT_EQ(error_of([&] { merge_db(a, d); }),
              "d.db:1:1: alias 'xa' is already defined (at a.db:1:1)");
}

// ---- errors -----------------------------------------------------------------------------------

TEST(ParseDb, DbdKeywordsAreRejected) {
    EXPECT_EQ(parse_error("recordtype(ai) {}"),
              "t.db:1:1: 'recordtype' is a .dbd keyword, not allowed in a .db file");
    EXPECT_EQ(parse_error("\n  menu(x) {}"),
              "t.db:2:3: 'menu' is a .dbd keyword, not allowed in a .db file");
    EXPECT_EQ(parse_error("device(ai, CONSTANT, devAiSoft, \"Soft Channel\")"),
              "t.db:1:1: 'device' is a .dbd keyword, not allowed in a .db file");
    EXPECT_EQ(parse_error("path \".\""),
              "t.db:1:1: 'path' is not supported in .db files; give include directories to the "
              "loader instead");
}

TEST(ParseDb, UnknownTopLevelItems) {
    EXPECT_EQ(parse_error("foo(ai, x)"),
              "t.db:1:1: expected 'record', 'grecord', 'alias' or 'include', found 'foo'");
    EXPECT_EQ(parse_error("record(ai, x) {}\n}"),
              "t.db:2:1: expected 'record', 'grecord', 'alias' or 'include', found '}'");
    EXPECT_EQ(parse_error("\"record\"(ai, x)"),
              "t.db:1:1: expected 'record', 'grecord', 'alias' or 'include', found string "
              "\"record\"");
    EXPECT_EQ(parse_error("record(ai, x) field(A, 1)"),
              "t.db:1:15: expected 'record', 'grecord', 'alias' or 'include', found 'field'");
    EXPECT_EQ(parse_error("Record(ai, x)"),
              "t.db:1:1: expected 'record', 'grecord', 'alias' or 'include', found 'Record'");
}

TEST(ParseDb, RecordHeadErrors) {
    EXPECT_EQ(parse_error("record ai, x)"), "t.db:1:8: expected '(' after 'record', found 'ai'");
    EXPECT_EQ(parse_error("record(ai x)"),
              "t.db:1:11: expected ',' after record type 'ai', found 'x'");
    EXPECT_EQ(parse_error("record(ai, x"),
              "t.db:1:13: expected ')' after record name 'x', found end of file");
    EXPECT_EQ(parse_error("record(, x)"), "t.db:1:8: expected record type, found ','");
    EXPECT_EQ(parse_error("record(ai, )"), "t.db:1:12: expected record name, found ')'");
    EXPECT_EQ(parse_error("record(ai, {})"), "t.db:1:12: expected record name, found '{'");
    EXPECT_EQ(parse_error("record(\"\", x)"), "t.db:1:8: empty record type");
    EXPECT_EQ(parse_error("record(ai, \"\")"), "t.db:1:12: empty record name");
    EXPECT_EQ(parse_error("record(ai, \"a b\")"), "t.db:1:12: invalid ' ' in record name 'a b'");
    EXPECT_EQ(parse_error("record(ai, \"a.VAL\")"),
              "t.db:1:12: invalid '.' in record name 'a.VAL'");
    EXPECT_EQ(parse_error("record(ai, \"a\\tb\")"),
              "t.db:1:12: invalid character 0x09 in record name 'a\tb'");
    EXPECT_EQ(parse_error("record(ai, $(S))", MacroMap{{"S", "x y"}}),
              "t.db:1:12: invalid ' ' in record name 'x y'");
}

TEST(ParseDb, RecordBodyErrors) {
    EXPECT_EQ(parse_error("record(ai, x) { field(VAL 1) }"),
              "t.db:1:27: expected ',' after field name 'VAL', found '1'");
    EXPECT_EQ(parse_error("record(ai, x) { field(VAL, 1 }"),
              "t.db:1:30: expected ')' after value of field 'VAL', found '}'");
    EXPECT_EQ(parse_error("record(ai, x) { field(VAL, ) }"),
              "t.db:1:28: expected value of field 'VAL', found ')'");
    EXPECT_EQ(parse_error("record(ai, x) { field(DESC, some text) }"),
              "t.db:1:34: expected ')' after value of field 'DESC', found 'text'");
    EXPECT_EQ(parse_error("record(ai, x) { field(\"\", 1) }"), "t.db:1:23: empty field name");
    EXPECT_EQ(parse_error("record(ai, x) { info(, 1) }"),
              "t.db:1:22: expected info name, found ','");
    EXPECT_EQ(parse_error("record(ai, x) { field VAL }"),
              "t.db:1:23: expected '(' after 'field', found 'VAL'");
    EXPECT_EQ(parse_error("record(ai, x) { alias(a, b) }"),
              "t.db:1:24: expected ')' after alias name 'a', found ','");
    EXPECT_EQ(parse_error("record(ai, x) { field(VAL, 1); }"),
              "t.db:1:30: expected 'field', 'info', 'alias', 'include' or '}' in record 'x', "
              "found ';'");
    EXPECT_EQ(parse_error("record(ai, x) { record(ai, y) }"),
              "t.db:1:17: expected 'field', 'info', 'alias', 'include' or '}' in record 'x', "
              "found 'record'");
}

TEST(ParseDb, EndOfFileInRecord) {
    EXPECT_EQ(parse_error("record(ai, x) {\n  field(VAL, 1)\n"),
              "t.db:3:1: expected 'field', 'info', 'alias', 'include' or '}' in record 'x', "
              "found end of file (record body opened at t.db:1:15)");
    EXPECT_EQ(parse_error("record(ai, x) {\n  field(VAL,"),
              "t.db:2:13: expected value of field 'VAL', found end of file");
}

TEST(ParseDb, LexicalErrors) {
    EXPECT_EQ(parse_error("record(ai, \"x) {}"),
              "t.db:1:12: unterminated string: missing closing '\"' before end of file");
    EXPECT_EQ(parse_error("record(ai, x) {\n field(DESC, \"abc\n\") }"),
              "t.db:2:14: unterminated string: missing closing '\"' before end of line");
    EXPECT_EQ(parse_error("record(ai, x) { field(DESC, \"abc\\\n\") }"),
              "t.db:1:29: unterminated string: missing closing '\"' before end of line");
    EXPECT_EQ(parse_error("record(ai, x) { field(VAL, @) }"), "t.db:1:28: invalid '@'");
    EXPECT_EQ(parse_error("record(ai, x) { field(DESC, 'x') }"),
              "t.db:1:29: invalid character '\\'': strings are quoted with \"");
    EXPECT_EQ(parse_error("record(ai, x) $"), "t.db:1:15: invalid '$'");
    EXPECT_EQ(parse_error("record(*, x)"), "t.db:1:8: invalid '*'"); // EPICS needs "*" quoted
    EXPECT_EQ(parse_error(std::string("record(ai, x)\x01")), "t.db:1:14: invalid character 0x01");
}

TEST(ParseDb, EveryErrorOfAFileRecoveringAtTheNextRecord) {
    const std::string text = "record(ai, a) {\n"         // 1
                             "  field(VAL 1)\n"          // 2: ',' missing
                             "}\n"                       // 3
                             "record(ai, b) {\n"         // 4: fine
                             "  field(DESC, \"ok\")\n" // 5
                             "}\n"                       // 6
                             "record(ai, c) { field(EGU, @) }\n" // 7: bad character
                             "  record(bo, b)\n"         // 8: b is an ai
                             "grecord(ai, \"d e\")\n"  // 9: bad name
                             "record(ai, f) { field(PREC, 2) }\n";
    try {
        parse_db(text, "t.db", {});
        FAIL() << "no error";
    } catch (const MultiError& e) {
        const std::vector<std::string> want = {
            "t.db:2:13: expected ',' after field name 'VAL', found '1'",
            "t.db:7:28: invalid '@'",
            "t.db:8:10: record 'b' redefined with type 'bo', but it has type 'ai' (defined at "
            "t.db:4:1)",
            "t.db:9:13: invalid ' ' in record name 'd e'",
        };
        EXPECT_EQ(e.errors(), want) << e.what();
    }
}

TEST(ParseDb, AtMostAHundredErrors) {
    std::string text;
    for (int i = 0; i < 500; ++i) text += "record(ai, x) { field(A 1) }\n";
    try {
        parse_db(text, "t.db", {});
        FAIL() << "no error";
    } catch (const MultiError& e) {
        ASSERT_EQ(e.errors().size(), 101u);
        EXPECT_EQ(e.errors()[99], "t.db:100:25: expected ',' after field name 'A', found '1'");
        EXPECT_EQ(e.errors()[100], "t.db: too many errors (100); the rest is not read");
    }
}

TEST(ParseDb, JsonErrors) {
    EXPECT_EQ(parse_error("record(ai, x) {\n  field(INP, {a: [1}})\n}"),
              "t.db:2:20: mismatched '}' in JSON value: expected ']'");
    EXPECT_EQ(parse_error("record(ai, x) {\n  field(INP, {a: [1]\n"),
              "t.db:2:14: unterminated JSON value: expected '}' before end of file");
    EXPECT_EQ(parse_error("record(ai, x) { field(INP, {\"a: 1}) }"),
              "t.db:1:29: unterminated string: missing closing '\"' before end of file");
    EXPECT_EQ(parse_error("record(ai, {a: 1})"), "t.db:1:12: expected record name, found '{'");
}

TEST(ParseDb, BomAndCrLf) {
    const DbFile db =
        parse_db("\xEF\xBB\xBFrecord(ai, x) {\r\n  field(VAL, 1)\r\n}\r\n", "t.db", {});
    ASSERT_EQ(db.records.size(), 1u);
    EXPECT_EQ(loc_of(db.records[0].loc), "t.db:1:1");
    EXPECT_EQ(loc_of(db.records[0].fields[0].loc), "t.db:2:9");
}

// ---- files and includes ---------------------------------------------------------------------

TEST_F(DbFileDir, LoadFile) {
    const std::string p = write("a.db", "record(ai, \"$(P)a\") {\n  field(DESC, \"$(R)\")\n}\n");
    const DbFile db = load_db_file(p, kMacros);
    ASSERT_EQ(db.records.size(), 1u);
    EXPECT_EQ(db.records[0].name, "DEMO:a");
    EXPECT_EQ(db.records[0].fields[0].value, "m1");
    EXPECT_EQ(loc_of(db.records[0].fields[0].loc), p + ":2:9");
}

TEST_F(DbFileDir, MissingFile) {
    const std::string p = path("nope.db");
    EXPECT_EQ(error_of([&] { load_db_file(p, {}); }),
              p + ": cannot open: No such file or directory");
}

TEST_F(DbFileDir, IncludeRelativeToIncludingFileThenIncludePath) {
    write("main.db", "record(ai, first)\n"
                     "include \"sub/part.db\"\n"
                     "include common.db\n"
                     "record(ai, last)\n");
    write("sub/part.db", "record(ao, \"$(P)part\") { field(DESC, here) }\n"
                         "include \"sibling.db\"\n");
    write("sub/sibling.db", "record(bo, sibling)\n");
    write("lib/common.db", "record(bi, common) { field(ZNAM, \"$(R)\") }\n");
    write("main_dir_common/common.db", "record(bi, wrong)\n");
    const DbFile db =
        load_db_file(path("main.db"), kMacros, {path("lib"), path("main_dir_common")});
    ASSERT_EQ(db.records.size(), 5u);
    EXPECT_EQ(db.records[0].name, "first");
    EXPECT_EQ(db.records[1].name, "DEMO:part");
    EXPECT_EQ(db.records[2].name, "sibling");
    EXPECT_EQ(db.records[3].name, "common");
    EXPECT_EQ(db.records[3].fields[0].value, "m1");
    EXPECT_EQ(db.records[4].name, "last");
    EXPECT_EQ(loc_of(db.records[1].loc), path("sub/part.db") + ":1:1");
    EXPECT_EQ(loc_of(db.records[1].fields[0].loc), path("sub/part.db") + ":1:32");
    EXPECT_EQ(loc_of(db.records[2].loc), path("sub/sibling.db") + ":1:1");
    EXPECT_EQ(loc_of(db.records[3].loc), path("lib/common.db") + ":1:1");
    EXPECT_EQ(loc_of(db.records[4].loc), path("main.db") + ":4:1");
}

TEST_F(DbFileDir, IncludeFromTextUsesFilenameDirectory) {
    write("inc.db", "record(ai, inc)\n");
    const DbFile db = parse_db("include \"inc.db\"", path("virtual.db"), {});
    ASSERT_EQ(db.records.size(), 1u);
    EXPECT_EQ(db.records[0].name, "inc");
}

TEST_F(DbFileDir, IncludeInsideRecordBody) {
    write("fields.inc", "field(EGU, \"$(R)\")\n# comment\ninfo(i, 1) alias(\"x:al\")\n");
    write("main.db", "record(ai, x) {\n  field(VAL, 1)\n  include \"fields.inc\"\n}\n");
    const DbFile db = load_db_file(path("main.db"), kMacros);
    ASSERT_EQ(db.records.size(), 1u);
    const DbRecord& r = db.records[0];
    ASSERT_EQ(r.fields.size(), 2u);
    EXPECT_EQ(r.fields[1].name, "EGU");
    EXPECT_EQ(r.fields[1].value, "m1");
    EXPECT_EQ(loc_of(r.fields[1].loc), path("fields.inc") + ":1:7");
    EXPECT_EQ(r.infos.size(), 1u);
    EXPECT_EQ(r.aliases, (std::vector<std::string>{"x:al"}));

    write("bad.inc", "field(A, 1) }\n");
    write("bad.db", "record(ai, x) {\n  include \"bad.inc\"\n}\n");
    EXPECT_EQ(error_of([&] { load_db_file(path("bad.db"), {}); }),
              path("bad.inc") +
                  ":1:13: expected 'field', 'info', 'alias' or 'include' for "
                  "record 'x', found '}'\n  included from " +
                  path("bad.db") + ":2:3");
}

TEST_F(DbFileDir, IncludeNotFound) {
    write("main.db", "\n  include \"missing.db\"\n");
    EXPECT_EQ(error_of([&] { load_db_file(path("main.db"), {}, {path("lib")}); }),
              path("main.db") + ":2:11: include file 'missing.db' not found (searched " +
                  path("missing.db") + ", " + path("lib/missing.db") + ")");
    EXPECT_EQ(parse_error("include \"\""), "t.db:1:9: empty file name after 'include'");
    EXPECT_EQ(parse_error("include (x)"),
              "t.db:1:9: expected file name after 'include', found '('");
}

TEST_F(DbFileDir, ErrorInIncludedFileShowsTheIncludeChain) {
    write("main.db", "record(ai, a)\ninclude \"mid.db\"\n");
    write("mid.db", "\n\ninclude \"leaf.db\"\n");
    write("leaf.db", "record(ai, b) {\n  field(DESC, \"$(Q)\")\n}\n");
    EXPECT_EQ(error_of([&] { load_db_file(path("main.db"), {}); }),
              path("leaf.db") + ":2:16: undefined macro 'Q'\n  included from " + path("mid.db") +
                  ":3:1\n  included from " + path("main.db") + ":2:1");
}

TEST_F(DbFileDir, IncludeCycle) {
    write("a.db", "include \"b.db\"\n");
    write("b.db", "record(ai, b)\ninclude \"a.db\"\n");
    EXPECT_EQ(error_of([&] { load_db_file(path("a.db"), {}); }),
              path("b.db") + ":2:9: include cycle: '" + path("a.db") +
                  "' is already being read\n  included from " + path("a.db") + ":1:1");
    write("self.db", "include \"self.db\"\n");
    EXPECT_EQ(error_of([&] { load_db_file(path("self.db"), {}); }),
              path("self.db") + ":1:9: include cycle: '" + path("self.db") +
                  "' is already being read");
}

TEST_F(DbFileDir, SameFileIncludedTwiceIsNotACycle) {
    write("rec.db", "record(ai, \"$(P)r\") { field(VAL, 1) }\n");
    write("main.db", "include \"rec.db\"\ninclude \"rec.db\"\n");
    const DbFile db = load_db_file(path("main.db"), kMacros);
    ASSERT_EQ(db.records.size(), 1u); // merged: same type
    EXPECT_EQ(db.records[0].name, "DEMO:r");
}

// ---- a real-world-looking file ----------------------------------------------------------------

TEST(ParseDb, RealWorldTemplate) {
    const std::string text = R"~(# motor axis support records
# Macros: P, AXIS, EGU, PREC (default 3)

record(motor, "$(P)$(AXIS)")
{
    field(DESC, "Axis $(AXIS) ($(EGU))")
    field(DTYP, "asynMotor")
    field(OUT,  "@asyn(MC_CPU1,$(AXIS_NO=1))")
    field(EGU,  "$(EGU)")
    field(PREC, "$(PREC=3)")
    field(VELO, 2.5)
    field(ACCL, 0.2)
    field(HLM,  +100)
    field(LLM,  -1.5e2)
    info(autosaveFields, "VAL DVAL OFF")
    alias("$(P)$(AXIS):Motor")
}

grecord(ai, "$(P)$(AXIS)-PosAct") {
    field(INP,  "$(P)$(AXIS).RBV CP MS")
    field(SCAN, "Passive")
    field(LINR, "NO CONVERSION")
    field(FLNK, "$(P)$(AXIS)-Calc")   # forward link
}

record(calcout, "$(P)$(AXIS)-Calc") {
    field(CALC, "A>B?1:0")
    field(INPA, "$(P)$(AXIS)-PosAct NPP")
    field(DESC, "Tab\there, \"quoted\"")
    field(INPB, {const: 10})
    info(Q:group, {"$(P)grp": {"pos": {+channel: "VAL"}}})
}

record(bo, "$(P)$(AXIS)-Enable") {
    field(ZNAM, Off)
    field(ONAM, On)
}
alias("$(P)$(AXIS)-Enable", "$(P)$(AXIS)-Ena")

# Override the description set above
record("*", "$(P)$(AXIS)") {
    field(DESC, "Sample X")
}
)~";
    const MacroMap m = beamctl::parse_macro_defs("P=BL:ES1:,AXIS=SmpX,EGU=mm");
    const DbFile db = parse_db(text, "motor.template", m);

    ASSERT_EQ(db.records.size(), 4u);
    const DbRecord& motor = db.records[0];
    EXPECT_EQ(motor.type, "motor");
    EXPECT_EQ(motor.name, "BL:ES1:SmpX");
    EXPECT_EQ(loc_of(motor.loc), "motor.template:4:1");
    ASSERT_EQ(motor.fields.size(), 9u);
    EXPECT_EQ(motor.fields[0].name, "DESC");
    EXPECT_EQ(motor.fields[0].value, "Sample X");
    EXPECT_EQ(loc_of(motor.fields[0].loc), "motor.template:42:11");
    EXPECT_EQ(motor.fields[2].value, "@asyn(MC_CPU1,1)");
    EXPECT_EQ(motor.fields[3].value, "mm");
    EXPECT_EQ(motor.fields[4].value, "3");
    EXPECT_EQ(motor.fields[7].value, "+100");
    EXPECT_EQ(motor.fields[8].value, "-1.5e2");
    EXPECT_EQ(loc_of(motor.fields[8].loc), "motor.template:14:11");
    EXPECT_EQ(motor.infos.at(0).value, "VAL DVAL OFF");
    EXPECT_EQ(motor.aliases, (std::vector<std::string>{"BL:ES1:SmpX:Motor"}));

    const DbRecord& ai = db.records[1];
    EXPECT_EQ(ai.type, "ai");
    EXPECT_EQ(ai.name, "BL:ES1:SmpX-PosAct");
    EXPECT_EQ(ai.fields[0].value, "BL:ES1:SmpX.RBV CP MS");
    EXPECT_EQ(ai.fields[3].value, "BL:ES1:SmpX-Calc");

    const DbRecord& calc = db.records[2];
    EXPECT_EQ(calc.fields[1].value, "BL:ES1:SmpX-PosAct NPP");
    EXPECT_EQ(calc.fields[2].value, "Tab\there, \"quoted\"");
    EXPECT_EQ(calc.fields[3].value, "{const: 10}");
    EXPECT_EQ(calc.infos[0].name, "Q:group");
    EXPECT_EQ(calc.infos[0].value, R"~({"BL:ES1:grp": {"pos": {+channel: "VAL"}}})~");
    EXPECT_EQ(loc_of(calc.infos[0].loc), "motor.template:31:10");

    EXPECT_EQ(db.records[3].name, "BL:ES1:SmpX-Enable");
    ASSERT_EQ(db.aliases.size(), 1u);
    EXPECT_EQ(db.aliases[0].record, "BL:ES1:SmpX-Enable");
    EXPECT_EQ(db.aliases[0].alias, "BL:ES1:SmpX-Ena");
    EXPECT_EQ(loc_of(db.aliases[0].loc), "motor.template:38:1");
}
