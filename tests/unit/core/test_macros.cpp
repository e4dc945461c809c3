#include "core/macros.hpp"

#include <gtest/gtest.h>

#include <random>

using beamctl::Error;
using beamctl::expand_macro_ref;
using beamctl::expand_macros;
using beamctl::MacroEscapes;
using beamctl::MacroMap;
using beamctl::parse_macro_defs;
using beamctl::SourceLoc;

namespace {

template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "<no error>";
}

const MacroMap kBase = {{"P", "DEMO:"}, {"R", "m1"}, {"EMPTY", ""}};

} // namespace

// ---- parse_macro_defs -------------------------------------------------------------------------

TEST(ParseMacroDefs, TypicalLine) {
    const MacroMap m = parse_macro_defs(R"(P=DEMO:,R=motor1,DESC="a, b",E=)");
    const MacroMap expected = {{"P", "DEMO:"}, {"R", "motor1"}, {"DESC", "a, b"}, {"E", ""}};
    EXPECT_EQ(m, expected);
}

TEST(ParseMacroDefs, WhitespaceAroundNamesAndValuesIsDropped) {
    const MacroMap m = parse_macro_defs(" P = DEMO: ,\tR= m 1 ,\n");
    EXPECT_EQ(m, (MacroMap{{"P", "DEMO:"}, {"R", "m 1"}}));
}

TEST(ParseMacroDefs, QuotedWhitespaceIsKept) {
    const MacroMap m = parse_macro_defs(R"(A=" x ",B=' y')");
    EXPECT_EQ(m.at("A"), " x ");
    EXPECT_EQ(m.at("B"), " y");
}

TEST(ParseMacroDefs, QuotesAnywhereInValueAreRemoved) {
    const MacroMap m = parse_macro_defs(R"(A=a "b, c" d,B="it's",C='say "hi"')");
    EXPECT_EQ(m.at("A"), "a b, c d");
    EXPECT_EQ(m.at("B"), "it's");
    EXPECT_EQ(m.at("C"), "say \"hi\"");
}

TEST(ParseMacroDefs, EscapesKeepOnlyBackslashAndDollarEscaped) {
    const MacroMap m = parse_macro_defs(R"(A=a\,b,B=\"q\",C=back\\slash,D=\$(X),E=\n)");
    EXPECT_EQ(m.at("A"), "a,b");
    EXPECT_EQ(m.at("B"), "\"q\"");
    EXPECT_EQ(m.at("C"), R"(back\\slash)");
    EXPECT_EQ(m.at("D"), R"(\$(X))");
    EXPECT_EQ(m.at("E"), "n");
    EXPECT_EQ(expand_macros("$(C)|$(D)", m), R"(back\slash|$(X))");
}

TEST(ParseMacroDefs, SingleQuotesStopExpansion) {
    const MacroMap m = parse_macro_defs(R"~(A='$(X)',B="$(X)")~");
    EXPECT_EQ(m.at("A"), R"(\$(X))");
    EXPECT_EQ(m.at("B"), "$(X)");
    EXPECT_EQ(expand_macros("$(A)", m), "$(X)");
    EXPECT_EQ(error_of([&] { expand_macros("$(B)", m); }),
              "<input>:1:1: undefined macro 'X' in the value of macro 'B'");
}

TEST(ParseMacroDefs, ReferencesAreKeptWithTheirCommasAndQuotes) {
    const MacroMap m = parse_macro_defs(R"(A=$(B,C=1),D=2,E=${F="p,q"}x,G=$(H=$(I,J=1)))");
    EXPECT_EQ(m.at("A"), "$(B,C=1)");
    EXPECT_EQ(m.at("D"), "2");
    EXPECT_EQ(m.at("E"), R"(${F="p,q"}x)");
    EXPECT_EQ(m.at("G"), "$(H=$(I,J=1))");
    EXPECT_EQ(m.size(), 4u);
    EXPECT_EQ(expand_macros("$(E)", m), "p,qx");
}

TEST(ParseMacroDefs, EmptyEntriesAndEmptyInput) {
    EXPECT_TRUE(parse_macro_defs("").empty());
    EXPECT_TRUE(parse_macro_defs("  , ,\t").empty());
    EXPECT_EQ(parse_macro_defs(",A=1,,B=2,"), (MacroMap{{"A", "1"}, {"B", "2"}}));
    EXPECT_EQ(parse_macro_defs("E=,F=1"), (MacroMap{{"E", ""}, {"F", "1"}}));
}

TEST(ParseMacroDefs, LaterDefinitionWins) {
    EXPECT_EQ(parse_macro_defs("A=1,A=2").at("A"), "2");
}

TEST(ParseMacroDefs, ErrorsNameThePosition) {
    EXPECT_EQ(error_of([] { parse_macro_defs("A=1,B"); }),
              "<input>:1:6: in macro definitions: expected '=' after macro name 'B', "
              "found end of input");
    EXPECT_EQ(error_of([] { parse_macro_defs("A,B=1"); }),
              "<input>:1:2: in macro definitions: expected '=' after macro name 'A', found ','");
    EXPECT_EQ(error_of([] { parse_macro_defs("A B=1"); }),
              "<input>:1:3: in macro definitions: expected '=' after macro name 'A', found 'B'");
    EXPECT_EQ(error_of([] { parse_macro_defs("X=1, =2"); }),
              "<input>:1:6: in macro definitions: empty macro name before '='");
    EXPECT_EQ(error_of([] { parse_macro_defs(R"(A="abc)"); }),
              "<input>:1:3: in macro definitions: unterminated quote \" in value of 'A'");
    EXPECT_EQ(error_of([] { parse_macro_defs(R"(A=x\)"); }),
              "<input>:1:4: in macro definitions: backslash at end of input");
    EXPECT_EQ(error_of([] { parse_macro_defs(R"("A"=1)"); }),
              "<input>:1:1: in macro definitions: character '\"' is not allowed in a macro name");
    EXPECT_EQ(error_of([] { parse_macro_defs("A$(B)=1"); }),
              "<input>:1:2: in macro definitions: character '$' is not allowed in a macro name");
}

TEST(ParseMacroDefs, ErrorLocationCountsFromStart) {
    EXPECT_EQ(error_of([] {
                  parse_macro_defs("A=1,B", SourceLoc{"ioc.yaml", 7, 20});
              }),
              "ioc.yaml:7:25: in macro definitions: expected '=' after macro name 'B', "
              "found end of input");
}

// ---- expand_macros ------------------------------------------------------------------------------

TEST(ExpandMacros, ParenthesesAndBraces) {
    EXPECT_EQ(expand_macros("$(P)$(R)", kBase), "DEMO:m1");
    EXPECT_EQ(expand_macros("${P}x${R}", kBase), "DEMO:xm1");
    EXPECT_EQ(expand_macros("a$(EMPTY)b", kBase), "ab");
}

TEST(ExpandMacros, TextWithoutReferencesIsUnchanged) {
    EXPECT_EQ(expand_macros("", kBase), "");
    EXPECT_EQ(expand_macros("$ $x a$ $) $", kBase), "$ $x a$ $) $");
    EXPECT_EQ(expand_macros("line1\nline2", kBase), "line1\nline2");
}

TEST(ExpandMacros, TextWithoutDollarOrBackslashIsUnchangedRandomized) {
    std::mt19937 rng(12345);
    const std::string alphabet = "abcXYZ09 (){}=,'\"\n\t:._-";
    for (int i = 0; i < 2000; ++i) {
        std::string s(rng() % 40, ' ');
        for (char& c : s) c = alphabet[rng() % alphabet.size()];
        ASSERT_EQ(expand_macros(s, kBase), s) << s;
        ASSERT_EQ(expand_macros(s, kBase, MacroEscapes::unescape), s) << s;
    }
}

TEST(ExpandMacros, Defaults) {
    EXPECT_EQ(expand_macros("$(X=def)", kBase), "def");
    EXPECT_EQ(expand_macros("${X=def}", kBase), "def");
    EXPECT_EQ(expand_macros("$(P=zzz)", kBase), "DEMO:");
    EXPECT_EQ(expand_macros("[$(X=)]", kBase), "[]");
    EXPECT_EQ(expand_macros("$(X=a b)", kBase), "a b");
}

TEST(ExpandMacros, NestedReferenceInName) {
    const MacroMap m = {{"B", "1"}, {"A1", "yes"}, {"AXIS", "X"}, {"M_X", "motorX"}};
    EXPECT_EQ(expand_macros("$(A$(B))", m), "yes");
    EXPECT_EQ(expand_macros("${M_$(AXIS)}", m), "motorX");
}

TEST(ExpandMacros, NestedReferenceInDefault) {
    EXPECT_EQ(expand_macros("$(X=$(P))", kBase), "DEMO:");
    EXPECT_EQ(expand_macros("$(X=$(Y=deep))", kBase), "deep");
    EXPECT_EQ(expand_macros("$(X=<$(P)$(R)>)", kBase), "<DEMO:m1>");
}

TEST(ExpandMacros, UnusedDefaultIsNotExpanded) {
    EXPECT_EQ(expand_macros("$(P=$(UNDEFINED))", kBase), "DEMO:");
}

TEST(ExpandMacros, ValuesReferenceOtherMacros) {
    const MacroMap m = {{"A", "$(B)-$(C)"}, {"B", "b$(C)"}, {"C", "c"}, {"D", "$(C)$(C)"}};
    EXPECT_EQ(expand_macros("$(A)", m), "bc-c");
    EXPECT_EQ(expand_macros("$(D)$(D)", m), "cccc"); // repeated use is not recursion
}

TEST(ExpandMacros, ValueEscapes) {
    const MacroMap m = {{"B", "x"},
                        {"LIT", R"(a\$(B))"},
                        {"WIN", R"(C:\dir\new)"},
                        {"BS", R"(x\\y)"},
                        {"Q", R"(say "hi" 'now')"}};
    EXPECT_EQ(expand_macros("$(LIT)", m), "a$(B)");
    EXPECT_EQ(expand_macros("$(WIN)", m), R"(C:\dir\new)");
    EXPECT_EQ(expand_macros("$(BS)", m), R"(x\y)");
    EXPECT_EQ(expand_macros("$(Q)", m), R"(say "hi" 'now')");
}

TEST(ExpandMacros, KeepModeCopiesEscapesAndDoesNotExpandEscapedDollar) {
    EXPECT_EQ(expand_macros(R"(\$(P) $(P))", kBase), R"(\$(P) DEMO:)");
    EXPECT_EQ(expand_macros(R"(a\\b\n\)", kBase), R"(a\\b\n\)");
    EXPECT_EQ(expand_macros(R"(\\$(P))", kBase), R"(\\DEMO:)");
}

TEST(ExpandMacros, UnescapeModeTranslatesOnlyDollarAndBackslash) {
    const auto u = MacroEscapes::unescape;
    EXPECT_EQ(expand_macros(R"(\$(P) $(P))", kBase, u), "$(P) DEMO:");
    EXPECT_EQ(expand_macros(R"(a\\b\n\)", kBase, u), R"(a\b\n\)");
    EXPECT_EQ(expand_macros(R"(\\$(P))", kBase, u), R"(\DEMO:)");
}

TEST(ExpandMacros, QuotesAndEscapesInsideReferences) {
    EXPECT_EQ(expand_macros(R"($(X="a,b"))", kBase), "a,b");
    EXPECT_EQ(expand_macros(R"($(X="a)b"))", kBase), "a)b");
    EXPECT_EQ(expand_macros(R"($(X='$(P)'))", kBase), "$(P)");
    EXPECT_EQ(expand_macros(R"~($(X="$(P)"))~", kBase), "DEMO:");
    EXPECT_EQ(expand_macros(R"($(X=a\)b))", kBase), "a)b");
    EXPECT_EQ(expand_macros(R"($(X=a(b)c))", kBase), "a(bc)"); // parentheses are not counted
}

TEST(ExpandMacros, QuotesOutsideReferencesDoNotStopExpansion) {
    EXPECT_EQ(expand_macros(R"~('$(P)' "$(R)")~", kBase), R"~('DEMO:' "m1")~");
}

TEST(ExpandMacros, ScopedDefinitions) {
    const MacroMap m = {{"T", "$(A)+$(B)"}, {"P", "DEMO:"}};
    EXPECT_EQ(expand_macros("$(T,A=1,B=2)", m), "1+2");
    EXPECT_EQ(expand_macros("$(T,A=1,B=2)$(A=none)", m), "1+2none");
    EXPECT_EQ(expand_macros("$(P,P=other)", m), "other");
    EXPECT_EQ(expand_macros("$(T,A=$(P),B=${P})", m), "DEMO:+DEMO:");
    EXPECT_EQ(expand_macros("$(T,A=\\$x,B=y)", m), "$x+y");
    EXPECT_EQ(expand_macros("$(X=$(A),A=scoped)", m), "scoped");
}

TEST(ExpandMacros, UndefinedMacroIsAnErrorAtTheDollar) {
    EXPECT_EQ(error_of([] { expand_macros("ab $(Q) cd", kBase); }),
              "<input>:1:4: undefined macro 'Q'");
    EXPECT_EQ(error_of([] {
                  expand_macros("x\n  $(Q)", kBase, SourceLoc{"f.db", 10, 5});
              }),
              "f.db:11:3: undefined macro 'Q'");
    EXPECT_EQ(error_of([] {
                  expand_macros("ab ${Q}", kBase, SourceLoc{"f.db", 2, 7});
              }),
              "f.db:2:10: undefined macro 'Q'");
}

TEST(ExpandMacros, ErrorPointsAtNestedReference) {
    EXPECT_EQ(error_of([] { expand_macros("$(A$(Q))", kBase); }),
              "<input>:1:4: undefined macro 'Q'");
    EXPECT_EQ(error_of([] { expand_macros("$(X=ab$(Q))", kBase); }),
              "<input>:1:7: undefined macro 'Q'");
    EXPECT_EQ(error_of([] { expand_macros("$(A$(B=))", kBase); }),
              "<input>:1:1: undefined macro 'A'");
}

TEST(ExpandMacros, ErrorInsideValuePointsAtOriginalReference) {
    const MacroMap m = {{"A", "x$(B)"}, {"B", "$(Q)"}};
    EXPECT_EQ(error_of([&] { expand_macros("  $(A)", m); }),
              "<input>:1:3: undefined macro 'Q' in the value of macro 'B'");
}

TEST(ExpandMacros, ColumnsCountCharacters) {
    EXPECT_EQ(error_of([] { expand_macros("\xC3\xA9\xC3\xA9 $(Q)", kBase); }),
              "<input>:1:4: undefined macro 'Q'");
}

TEST(ExpandMacros, RecursionIsAnError) {
    EXPECT_EQ(error_of([] {
                  expand_macros("$(A)", MacroMap{{"A", "$(A)"}});
              }),
              "<input>:1:1: recursive macro 'A' (A -> A)");
    const MacroMap m = {{"A", "$(B)"}, {"B", "x$(C)"}, {"C", "$(A)"}};
    EXPECT_EQ(error_of([&] { expand_macros("..$(B)", m); }),
              "<input>:1:3: recursive macro 'B' (B -> C -> A -> B)");
}

TEST(ExpandMacros, UnterminatedReference) {
    EXPECT_EQ(error_of([] { expand_macros("$(P", kBase); }),
              "<input>:1:1: unterminated macro reference '$(P': expected ')', found end of text");
    EXPECT_EQ(error_of([] { expand_macros("x $(P\n)", kBase); }),
              "<input>:1:3: unterminated macro reference '$(P': expected ')', found end of line");
    EXPECT_EQ(error_of([] { expand_macros("${P)", kBase); }),
              "<input>:1:1: unterminated macro reference '${P)': expected '}', found end of text");
    EXPECT_EQ(error_of([] {
                  expand_macros("$(A)", MacroMap{{"A", "$(B"}});
              }),
              "<input>:1:1: unterminated macro reference '$(B': expected ')', found end of value "
              "in the value of macro 'A'");
    EXPECT_EQ(error_of([] { expand_macros(R"($(X="ab))", kBase); }),
              "<input>:1:5: unterminated quote \" in macro reference");
}

TEST(ExpandMacros, EmptyName) {
    EXPECT_EQ(error_of([] { expand_macros("ok $()", kBase); }),
              "<input>:1:4: empty macro name in reference");
    EXPECT_EQ(error_of([] { expand_macros("$($(EMPTY))", kBase); }),
              "<input>:1:1: empty macro name in reference");
}

// ---- expand_macro_ref ---------------------------------------------------------------------------

TEST(ExpandMacroRef, ExpandsOneReferenceAndAdvances) {
    const std::string text = "ab$(P)cd";
    std::size_t pos = 2;
    SourceLoc loc{"f.db", 3, 3};
    EXPECT_EQ(expand_macro_ref(text, pos, loc, kBase), "DEMO:");
    EXPECT_EQ(pos, 6u);
    EXPECT_EQ(loc.line, 3);
    EXPECT_EQ(loc.col, 7);
    EXPECT_EQ(loc.file, "f.db");
}

TEST(ExpandMacroRef, RejectsNonReference) {
    std::size_t pos = 0;
    SourceLoc loc{"f.db", 1, 1};
    EXPECT_EQ(error_of([&] { expand_macro_ref("$x", pos, loc, kBase); }),
              "f.db:1:1: expected a macro reference '$(' or '${'");
    EXPECT_TRUE(beamctl::is_macro_ref("a${", 1));
    EXPECT_FALSE(beamctl::is_macro_ref("a$", 1));
    EXPECT_FALSE(beamctl::is_macro_ref("a$[", 1));
}
