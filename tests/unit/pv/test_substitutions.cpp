// Substitution files (dbLoadTemplate / msi grammar): both instance forms, globals, quoting,
// comments, error locations, and robustness against random input.
#include "pv/substitutions.hpp"

#include "core/macros.hpp"

#include <gtest/gtest.h>

#include <random>

using beamctl::Error;
using beamctl::expand_macros;
using beamctl::MacroMap;
using beamctl::pv::parse_substitutions;
using beamctl::pv::TemplateInstance;

namespace {

std::vector<TemplateInstance> parse(const std::string& text, const MacroMap& m = {}) {
    return parse_substitutions(text, "t.substitutions", m);
}

std::string error_of(const std::string& text, const MacroMap& m = {}) {
    try {
        parse(text, m);
    } catch (const Error& e) {
        return e.what();
    }
    return "<no error>";
}

} // namespace

TEST(Substitutions, PatternRowsBecomeInstances) {
    auto v = parse("file x.db {\n  pattern { A, B }\n  { 1, 2 }\n  {3 4}\n}\n");
    ASSERT_EQ(v.size(), 2u);
    EXPECT_EQ(v[0].file, "x.db");
    EXPECT_EQ(v[0].macros, (MacroMap{{"A", "1"}, {"B", "2"}}));
    EXPECT_EQ(v[1].macros, (MacroMap{{"A", "3"}, {"B", "4"}}));
    EXPECT_EQ(v[0].loc.str(), "t.substitutions:3:3");
    EXPECT_EQ(v[1].loc.str(), "t.substitutions:4:3");
    EXPECT_EQ(v[0].file_loc.str(), "t.substitutions:1:6");
}

TEST(Substitutions, VariableSetsBecomeInstances) {
    auto v =
        parse("file \"dir/y.template\" {\n  { P=\"A:\", R = m1 }\n  {P=B: R=\"m 2\"}\n  {}\n}\n");
    ASSERT_EQ(v.size(), 3u);
    EXPECT_EQ(v[0].file, "dir/y.template");
    EXPECT_EQ(v[0].macros, (MacroMap{{"P", "A:"}, {"R", "m1"}}));
    EXPECT_EQ(v[1].macros, (MacroMap{{"P", "B:"}, {"R", "m 2"}}));
    EXPECT_TRUE(v[2].macros.empty()); // `{}` loads the file with no instance macros
}

TEST(Substitutions, GlobalsLastToTheEndAndInstancesOverrideThem) {
    const std::string text = R"(
global { G=1, P=glob }
file a.db {
  pattern {P}
  {x}
  global { G=2 }
  {y}
}
file b.db { {Q=q} }
)";
    auto v = parse(text, {{"G", "cmd"}, {"C", "c"}});
    ASSERT_EQ(v.size(), 3u);
    EXPECT_EQ(v[0].macros, (MacroMap{{"C", "c"}, {"G", "1"}, {"P", "x"}}));
    EXPECT_EQ(v[1].macros, (MacroMap{{"C", "c"}, {"G", "2"}, {"P", "y"}}));
    // The global inside a.db's block still holds for b.db; the instance's own P is gone.
    EXPECT_EQ(v[2].macros, (MacroMap{{"C", "c"}, {"G", "2"}, {"P", "glob"}, {"Q", "q"}}));
}

TEST(Substitutions, QuotingCommentsAndSeparators) {
    const std::string text = "# a comment { not a block }\n"
                             "file 'q.db' { # trailing comment\n"
                             "  pattern {A B C}\n"
                             "  {'it s', \"a,b\", \"say \\\"hi\\\"\"} # row\n"
                             "}\n";
    auto v = parse(text);
    ASSERT_EQ(v.size(), 1u);
    EXPECT_EQ(v[0].file, "q.db");
    EXPECT_EQ(v[0].macros.at("A"), "it s");
    EXPECT_EQ(v[0].macros.at("B"), "a,b");
    EXPECT_EQ(v[0].macros.at("C"), "say \"hi\"");
}

TEST(Substitutions, ValuesKeepMacroReferencesForTheTemplate) {
    auto v = parse("file x.db { {P=\"$(SYS):a\", Q=$(SYS)b} }", {{"SYS", "BL1"}});
    ASSERT_EQ(v.size(), 1u);
    EXPECT_EQ(v[0].macros.at("P"), "$(SYS):a");
    EXPECT_EQ(expand_macros("$(P)/$(Q)", v[0].macros), "BL1:a/BL1b");
}

TEST(Substitutions, FileNamesExpandKnownMacros) {
    auto v = parse("global {D=db}\nfile \"$(TOP)/$(D)/x.db\" { {} }", {{"TOP", "/opt/ioc"}});
    ASSERT_EQ(v.size(), 1u);
    EXPECT_EQ(v[0].file, "/opt/ioc/db/x.db");
    EXPECT_EQ(error_of("file \"$(NOPE)/x.db\" { {} }").rfind("t.substitutions:1:6: ", 0), 0u)
        << error_of("file \"$(NOPE)/x.db\" { {} }");
}

TEST(Substitutions, DeprecatedWordBeforeAnInstanceIsIgnored) {
    auto v = parse("file x.db { pattern {A} row1 {1} }\nfile y.db { set {B=2} }");
    ASSERT_EQ(v.size(), 2u);
    EXPECT_EQ(v[0].macros.at("A"), "1");
    EXPECT_EQ(v[1].macros.at("B"), "2");
}

TEST(Substitutions, FewerValuesThanNamesLeaveTheRestUndefined) {
    auto v = parse("file x.db { pattern {A B} {1} }");
    ASSERT_EQ(v.size(), 1u);
    EXPECT_EQ(v[0].macros, (MacroMap{{"A", "1"}}));
}

TEST(Substitutions, ErrorsSayWhereAndWhat) {
    EXPECT_EQ(error_of("file x.db { pattern {A} {1 2} }"),
              "t.substitutions:1:28: value 2 ('2') has no name: the pattern has 1 name");
    EXPECT_EQ(error_of("file x.db {\n  {A=1\n"),
              "t.substitutions:3:1: expected a macro name or '}', found end of file");
    EXPECT_EQ(error_of("file x.db { {A 1} }"),
              "t.substitutions:1:16: expected '=' after A, found '1'");
    EXPECT_EQ(error_of("file x.db { {A=\"1} }\n"),
              "t.substitutions:1:16: string starting here has no closing \" on its line");
    EXPECT_EQ(error_of("file x.db { {A=1} } ?"), "t.substitutions:1:21: invalid '?'");
    EXPECT_EQ(error_of("records x.db {}"),
              "t.substitutions:1:1: expected 'file' or 'global', found 'records'");
    EXPECT_EQ(error_of("file {}"),
              "t.substitutions:1:6: expected a template file name after 'file', found '{'");
    EXPECT_EQ(error_of("file x.db { {A=1}"), "t.substitutions:1:18: expected '{' (a set of "
                                             "NAME=VALUE), 'global' or '}', found end of file");
    EXPECT_EQ(error_of("global { A }"), "t.substitutions:1:12: expected '=' after A, found '}'");
}

TEST(Substitutions, EmptyFileAndEmptyBlocks) {
    EXPECT_TRUE(parse("").empty());
    EXPECT_TRUE(parse("# nothing\n\n").empty());
    EXPECT_TRUE(parse("global {}\nfile x.db {}\nfile y.db { pattern {A} }").empty());
}

// Random token soup: every input parses or is an Error with a location; nothing else escapes.
TEST(Substitutions, RandomInputParsesOrFailsCleanly) {
    const char* pieces[] = {"file", "global", "pattern", "{",   "}",    ",",  "=",
                            "x.db", "A",      "\"q v\"", "'s'", "#c\n", "\n", " ",
                            "$(A)", "${B",    "\"open",  "\\",  "?",    "1",  "\t"};
    std::mt19937 rng(20240611);
    int parsed = 0, failed = 0;
    for (int n = 0; n < 20000; ++n) {
        std::string text;
        const int len = int(rng() % 24);
        for (int k = 0; k < len; ++k) text += pieces[rng() % std::size(pieces)];
        try {
            parse(text, {{"A", "a"}});
            ++parsed;
        } catch (const Error& e) {
            ASSERT_EQ(std::string(e.what()).rfind("t.substitutions:", 0), 0u)
                << text << " -> " << e.what();
            ++failed;
        }
    }
    EXPECT_GT(parsed, 100);
    EXPECT_GT(failed, 100);
}
