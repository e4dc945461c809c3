// The one YAML reader: every getter (absent, good, bad), ranges, required and unknown keys with
// close-match hints, duplicate keys, lists and mappings, places (file:line:col) and key paths,
// and every error of a file collected in one pass, sorted, then thrown as one MultiError.
#include "config/yaml_reader.hpp"

#include "core/error_list.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

using namespace beamctl;
using namespace beamctl::config;

namespace {

std::vector<std::string> errors_of(YamlReader& rd) {
    return rd.take_errors().messages();
}

std::string joined(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += x + "\n";
    return s;
}

} // namespace

TEST(YamlReader, GettersReadGoodValues) {
    YamlReader rd("t.yaml", "s: hello\nq: \"5\"\nn: -2.5e3\ni: 0x1F\nneg: -7\nu: 18446744073709551615\n"
                            "b1: yes\nb2: Off\nb3: 1\nc: udp\nl: [1, 2, 3]\nm: {A: 1, B: x}\n");
    YamlNode r = rd.root();
    EXPECT_TRUE(r.keys({"s", "q", "n", "i", "neg", "u", "b1", "b2", "b3", "c", "l", "m"}));
    EXPECT_EQ(r["s"].string(), "hello");
    EXPECT_EQ(r["q"].number(), 5.0) << "quotes do not change the type";
    EXPECT_EQ(r["n"].number(), -2500.0);
    EXPECT_EQ(r["i"].integer(), 31);
    EXPECT_EQ(r["neg"].integer(between(-10, 0)), -7);
    EXPECT_EQ(r["u"].unsigned_integer(), UINT64_MAX);
    EXPECT_EQ(r["b1"].boolean(), true);
    EXPECT_EQ(r["b2"].boolean(), false);
    EXPECT_EQ(r["b3"].boolean(), true);
    EXPECT_EQ(r["c"].one_of({"sim", "udp", "raw"}), "udp");
    auto l = r["l"].list();
    ASSERT_EQ(l.size(), 3u);
    EXPECT_EQ(l[2].integer(), 3);
    EXPECT_EQ(l[2].path(), "l[2]");
    EXPECT_EQ(l[2].where(), "t.yaml:11:11");
    auto m = r["m"].string_pairs();
    ASSERT_EQ(m.size(), 2u);
    EXPECT_EQ(m[0], (std::pair<std::string, std::string>("A", "1")));
    EXPECT_EQ(m[1], (std::pair<std::string, std::string>("B", "x")));
    EXPECT_TRUE(rd.ok()) << joined(errors_of(rd));
}

TEST(YamlReader, AbsentKeysGiveNothingAndNoError) {
    YamlReader rd("t.yaml", "a: 1\n");
    YamlNode r = rd.root();
    YamlNode x = r["x"];
    EXPECT_FALSE(x.present());
    EXPECT_EQ(x.path(), "x");
    EXPECT_FALSE(x.string());
    EXPECT_FALSE(x.number());
    EXPECT_FALSE(x.integer());
    EXPECT_FALSE(x.unsigned_integer());
    EXPECT_FALSE(x.boolean());
    EXPECT_FALSE(x.one_of({"a"}));
    EXPECT_TRUE(x.list().empty());
    EXPECT_TRUE(x.entries().empty());
    EXPECT_FALSE(x["deeper"].present());
    EXPECT_EQ(x["deeper"].path(), "x.deeper");
    EXPECT_EQ(r["x"]["deeper"].number(above(0)).value_or(7), 7);
    EXPECT_TRUE(rd.ok()) << joined(errors_of(rd));
}

TEST(YamlReader, BadValuesSayWhereWhatAndWhatWasGiven) {
    YamlReader rd("t.yaml", "a:\n  n: abc\n  r: 0\n  i: 1.5\n  u: -1\n  big: 300\n  b: maybe\n"
                            "  c: udpp\n  s: [1]\n  e:\n  l: 5\n  m: [x]\n  inf: .inf\n");
    YamlNode a = rd.root()["a"];
    EXPECT_FALSE(a["n"].number());
    EXPECT_FALSE(a["r"].number(above(0)));
    EXPECT_FALSE(a["i"].integer());
    EXPECT_FALSE(a["u"].unsigned_integer(255));
    EXPECT_FALSE(a["big"].unsigned_integer(255));
    EXPECT_FALSE(a["b"].boolean());
    EXPECT_FALSE(a["c"].one_of({"sim", "udp", "raw"}));
    EXPECT_FALSE(a["s"].string());
    EXPECT_FALSE(a["e"].integer());
    EXPECT_TRUE(a["l"].list().empty());
    EXPECT_TRUE(a["m"].entries().empty());
    EXPECT_FALSE(a["inf"].number());
    const auto e = errors_of(rd);
    const std::vector<std::string> want = {
        "t.yaml:2:6: a.n should be a number, got 'abc'",
        "t.yaml:3:6: a.r should be > 0, got 0",
        "t.yaml:4:6: a.i should be an integer, got '1.5'",
        "t.yaml:5:6: a.u should be an unsigned integer, got '-1'",
        "t.yaml:6:8: a.big should be from 0 to 255, got 300",
        "t.yaml:7:6: a.b should be true or false, got 'maybe'",
        "t.yaml:8:6: a.c should be sim, udp or raw, got 'udpp' (did you mean 'udp'?)",
        "t.yaml:9:6: a.s should be a text, got a list",
        "t.yaml:10:3: a.e has no value (should be an integer)",
        "t.yaml:11:6: a.l should be a list, got a single value",
        "t.yaml:12:6: a.m should be a mapping (key: value lines), got a list",
        "t.yaml:13:8: a.inf should be a number, got '.inf'",
    };
    EXPECT_EQ(e, want) << joined(e);
}

TEST(YamlReader, RangesSayTheirBounds) {
    EXPECT_EQ(above(0).str(), "> 0");
    EXPECT_EQ(at_least(1).str(), ">= 1");
    EXPECT_EQ(at_most(9).str(), "<= 9");
    EXPECT_EQ(between(1, 255).str(), "from 1 to 255");
    EXPECT_EQ((Range{0, 3600, true}).str(), "> 0 and <= 3600");
    EXPECT_TRUE(between(1, 2).ok(1));
    EXPECT_TRUE(between(1, 2).ok(2));
    EXPECT_FALSE(between(1, 2).ok(2.5));
    EXPECT_FALSE(above(0).ok(0));
    EXPECT_TRUE(above(0).ok(1e-9));
}

TEST(YamlReader, UnknownKeysGetTheClosestAllowedKeyOrTheList) {
    YamlReader rd("axis.yaml", "trajectory:\n  axis:\n    velocty: 5\n    acceleration: 1\n"
                               "    foo: 1\n");
    YamlNode t = rd.root()["trajectory"];
    t.keys({"axis", "jog"});
    YamlNode a = t["axis"];
    a.keys({"velocity", "acceleration", "jerk"});
    EXPECT_FALSE(a["velocity"].present()) << "a misspelt key is not read as the right one";
    const auto e = errors_of(rd);
    const std::vector<std::string> want = {
        "axis.yaml:3:5: unknown key 'velocty' in trajectory.axis (did you mean 'velocity'?)",
        "axis.yaml:5:5: unknown key 'foo' in trajectory.axis (expected one of: velocity, "
        "acceleration, jerk)",
    };
    EXPECT_EQ(e, want) << joined(e);
}

TEST(YamlReader, KnownKeysWarnOrExplain) {
    YamlReader rd("t.yaml", "web: {port: 1}\nold: 1\nok: 2\n", "the IOC file");
    YamlNode r = rd.root();
    r.keys({"ok"}, {{"web", "it is not supported yet", true}, {"old", "is ignored (use ok)"}});
    EXPECT_EQ(errors_of(rd),
              std::vector<std::string>{"t.yaml:1:1: unknown key 'web' in the IOC file: it is not "
                                       "supported yet"});
    EXPECT_EQ(rd.take_warnings(), std::vector<std::string>{"t.yaml:2:1: 'old' is ignored (use ok)"});
}

TEST(YamlReader, RequiredKeysDuplicateKeysAndKeysOfTheWrongKind) {
    YamlReader rd("t.yaml", "ioc:\n  prefix: X\n  prefix: Y\n? [a]\n: 1\nlist: [1]\n");
    YamlNode r = rd.root();
    r.keys({"ioc", "list"});
    YamlNode ioc = r.required("ioc");
    ioc.keys({"name", "prefix"});
    EXPECT_FALSE(ioc.required("name", " (the IOC's name)").present());
    EXPECT_EQ(ioc["prefix"].string(), "Y") << "the last of a duplicate key counts";
    r.required("engine");
    r["list"].required("x"); // not a mapping: said once, by whoever reads it as one
    r["list"].keys({"x"});
    r["list"].keys({"x"});
    const auto e = errors_of(rd);
    const std::vector<std::string> want = {
        "t.yaml:1:1: ioc: missing required key 'name' (the IOC's name)",
        "t.yaml:1:1: the file: missing required key 'engine'",
        "t.yaml:3:3: duplicate key 'prefix' in ioc (also at line 2)",
        "t.yaml:4:3: keys in the file should be names, got a list",
        "t.yaml:6:7: list should be a mapping (key: value lines), got a list",
    };
    EXPECT_EQ(e, want) << joined(e);
}

TEST(YamlReader, EveryErrorOfAFileInOnePassSortedThenThrownAsOne) {
    const char* text = "engine: {rate_hz: 0}\n"   // 1
                       "buses:\n"                 // 2
                       "  - id: x\n"              // 3
                       "    slaves: 5\n"          // 4
                       "  - id: 1\n"              // 5
                       "    lnk: {}\n"            // 6
                       "ioc: {nam: T}\n";         // 7
    YamlReader rd("ioc.yaml", text, "the IOC file");
    YamlNode r = rd.root();
    r.keys({"ioc", "engine", "buses"});
    // read out of file order: the errors still come out sorted
    YamlNode ioc = r.required("ioc");
    ioc.keys({"name", "prefix"});
    ioc.required("name"); // not said: 'nam' is there, and its error says "did you mean"
    EXPECT_EQ(r["engine"]["rate_hz"].number(between(1, 20000)).value_or(1000), 1000);
    for (const YamlNode& b : r["buses"].list()) {
        b.keys({"id", "link", "slaves"});
        b["id"].integer(between(0, 15));
        b.required("slaves").list();
    }
    EXPECT_EQ(rd.error_count(), 6u);
    try {
        rd.throw_if_errors();
        FAIL() << "no error thrown";
    } catch (const MultiError& e) {
        const std::vector<std::string> want = {
            "ioc.yaml:1:19: engine.rate_hz should be from 1 to 20000, got 0",
            "ioc.yaml:3:9: buses[0].id should be an integer, got 'x'",
            "ioc.yaml:4:13: buses[0].slaves should be a list, got a single value",
            "ioc.yaml:5:5: buses[1]: missing required key 'slaves'",
            "ioc.yaml:6:5: unknown key 'lnk' in buses[1] (did you mean 'link'?)",
            "ioc.yaml:7:7: unknown key 'nam' in ioc (did you mean 'name'?)",
        };
        EXPECT_EQ(e.errors(), want) << e.what();
        EXPECT_EQ(std::string(e.what()).substr(0, want[0].size() + 1), want[0] + "\n")
            << "the first line is the first error";
    }
    EXPECT_NO_THROW(rd.throw_if_errors()) << "the errors were taken";
}

TEST(YamlReader, SyntaxErrorsSecondDocumentsAndMissingFiles) {
    YamlReader bad("s.yaml", "a: [1, 2\n");
    EXPECT_FALSE(bad.root().present());
    auto e = errors_of(bad);
    ASSERT_EQ(e.size(), 1u);
    EXPECT_EQ(e[0].rfind("s.yaml:2:1: YAML syntax error: ", 0), 0u) << e[0];

    YamlReader two("d.yaml", "a: 1\n---\nb: 2\n");
    EXPECT_FALSE(two.root().present());
    e = errors_of(two);
    ASSERT_EQ(e.size(), 1u);
    EXPECT_NE(e[0].find("only one YAML document"), std::string::npos) << e[0];

    YamlReader empty("e.yaml", "# nothing\n");
    EXPECT_TRUE(empty.root().is_null());
    EXPECT_TRUE(empty.ok());

    YamlReader missing = YamlReader::load("/nonexistent/x.yaml");
    EXPECT_FALSE(missing.root().present());
    EXPECT_EQ(errors_of(missing),
              std::vector<std::string>{"/nonexistent/x.yaml: cannot open: No such file or directory"});
}

TEST(YamlReader, ExpanderSeesEveryScalarWithItsPlace) {
    YamlReader rd("m.yaml", "a: $(X)\nb: '$(Y)'\nc: 3\n");
    rd.set_expander([&rd](const std::string& raw, const SourceLoc& at,
                          const std::string& path) -> std::optional<std::string> {
        if (raw == "$(X)") return std::string("42");
        if (raw == "$(Y)") {
            rd.error(at, path + ": macro Y is undefined");
            return std::nullopt;
        }
        return raw;
    });
    YamlNode r = rd.root();
    EXPECT_EQ(r["a"].integer(), 42);
    EXPECT_FALSE(r["b"].string());
    EXPECT_EQ(r["c"].integer(), 3);
    EXPECT_EQ(errors_of(rd), std::vector<std::string>{"m.yaml:2:5: b: macro Y is undefined"})
        << "a quoted scalar starts after its quote";
}

TEST(YamlReader, CloseMatches) {
    EXPECT_EQ(edit_distance("velocty", "velocity"), 1u);
    EXPECT_EQ(edit_distance("EL7014", "EL7041"), 1u) << "a swap counts one";
    EXPECT_EQ(edit_distance("ABC", "abc"), 0u);
    const std::vector<std::string> types = {"EK1100", "EL1008", "EL7041", "EL7031", "EL7047",
                                            "EL2008", "EL9999"};
    EXPECT_EQ(close_matches("EL7014", types), (std::vector<std::string>{"EL7041", "EL7031", "EL7047"}));
    EXPECT_EQ(close_matches("EL1080", types), (std::vector<std::string>{"EL1008", "EL2008"}));
    EXPECT_TRUE(close_matches("XYZ123", types).empty());
    EXPECT_TRUE(close_matches("x", {"y", "xx"}).empty()) << "never the whole word";
    const auto exact = close_matches("EL7041", types);
    EXPECT_EQ(std::find(exact.begin(), exact.end(), "EL7041"), exact.end())
        << "the word itself is not a close match of it";
}

TEST(ErrorList, CollectsCapturesDropsRepeatsAndThrowsOnce) {
    ErrorList l;
    EXPECT_NO_THROW(l.throw_if_any());
    l.add("a.yaml:1:1: first");
    l.add(SourceLoc{"a.yaml", 2, 3}, "second");
    l.add("a.yaml:1:1: first");
    EXPECT_TRUE(l.capture([] {}));
    EXPECT_FALSE(l.capture([] { throw Error("b.yaml:4:1: third"); }));
    EXPECT_FALSE(l.capture([] { throw MultiError({"c: 4th", "c: 5th"}); }, "ioc.yaml:3:5: axes[0].file"));
    const std::vector<std::string> want = {"a.yaml:1:1: first", "a.yaml:2:3: second",
                                           "b.yaml:4:1: third", "ioc.yaml:3:5: axes[0].file: c: 4th",
                                           "ioc.yaml:3:5: axes[0].file: c: 5th"};
    EXPECT_EQ(l.messages(), want);
    try {
        l.throw_if_any();
        FAIL();
    } catch (const MultiError& e) {
        EXPECT_EQ(e.errors(), want);
        EXPECT_EQ(std::string(e.what()), joined(want).substr(0, joined(want).size() - 1));
    }
}
