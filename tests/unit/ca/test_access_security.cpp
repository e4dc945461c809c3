// Unit tests of the ACF parser and evaluator (beamctl::ca::AccessSecurity) against the semantics
// of EPICS base asLib and the examples of the Application Developer's Guide.
#include "ca/access_security.hpp"

#include "core/error.hpp"

#include <gtest/gtest.h>

#include <cctype>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

using beamctl::Error;
using beamctl::ca::AccessSecurity;
using beamctl::ca::kAccessNone;
using beamctl::ca::kAccessRead;
using beamctl::ca::kAccessWrite;

namespace {

constexpr unsigned kRW = kAccessRead | kAccessWrite;

AccessSecurity acf(const std::string& text) {
    return AccessSecurity::parse(text, "test.acf");
}

// The message of the Error thrown when parsing `text`, or "no error".
std::string parse_error(const std::string& text, const std::string& file = "test.acf") {
    try {
        AccessSecurity::parse(text, file);
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

// Rights with no peer address, for host-name based tests.
unsigned rights(const AccessSecurity& as, const std::string& asg, int level,
                const std::string& user, const std::string& host) {
    return as.rights(asg, level, user, host, "");
}

// The Application Developer's Guide "Simple Example".
const char* const kSimpleExample = R"(
UAG(uag) {user1,user2}
HAG(hag) {host1,host2}
ASG(DEFAULT) {
        RULE(1,READ)
        RULE(1,WRITE) {
                UAG(uag)
                HAG(hag)
       }
}
)";

// The Application Developer's Guide Linac example, verbatim apart from indentation.
const char* const kLinacExample = R"(UAG(op) {op1,op2,superguy}
UAG(opSup) {superguy}
UAG(linac) {waw,nassiri,grelick,berg,fuja,gsm}
UAG(linacSup) {gsm}
UAG(appDev) {nda,kko}
HAG(icr) {silver,phebos,gaea}
HAG(cr) {mars,hera,gold}
HAG(ioc) {ioclic1,ioclic2,ioclid1,ioclid2,ioclid3,ioclid4,ioclid5}
ASG(DEFAULT) {
    INPA(LI:OPSTATE)
    INPB(LI:lev1permit)
    RULE(0,WRITE) {
        UAG(op)
        HAG(icr,cr)
        CALC("A=1")
    }
}
)";

// The Linac example's groups that need no CALC.
const char* const kLinacWithoutCalc = R"(UAG(op) {op1,op2,superguy}
UAG(opSup) {superguy}
UAG(linac) {waw,nassiri,grelick,berg,fuja,gsm}
UAG(linacSup) {gsm}
UAG(appDev) {nda,kko}
HAG(icr) {silver,phebos,gaea}
HAG(cr) {mars,hera,gold}
HAG(ioc) {ioclic1,ioclic2,ioclid1,ioclid2,ioclid3,ioclid4,ioclid5}
ASG(DEFAULT) {
    RULE(1,READ)
    RULE(1,WRITE) {
        HAG(ioc)
    }
}
ASG(permit) {
    RULE(0,WRITE) {
        UAG(opSup,linacSup,appDev)
    }
    RULE(1,READ)
    RULE(1,WRITE) {
        HAG(ioc)
    }
}
)";

} // namespace

// ---------------------------------------------------------------------------------------------
// Disabled access security

TEST(AccessSecurityDisabled, GrantsReadWriteToEveryone) {
    AccessSecurity as;
    EXPECT_FALSE(as.enabled());
    EXPECT_EQ(as.rights("", 0, "", "", ""), kRW);
    EXPECT_EQ(as.rights("anything", 1, "nobody", "nowhere", "10.1.2.3"), kRW);
    EXPECT_FALSE(as.has_group(""));
    EXPECT_FALSE(as.has_group("DEFAULT"));
    EXPECT_TRUE(as.groups().empty());
}

// ---------------------------------------------------------------------------------------------
// AppDevGuide examples

TEST(AccessSecurityGuide, SimpleExampleReadForAllWriteForUagAtHag) {
    AccessSecurity as = acf(kSimpleExample);
    EXPECT_TRUE(as.enabled());
    EXPECT_EQ(as.groups(), std::vector<std::string>{"DEFAULT"});
    for (int level : {0, 1}) {
        EXPECT_EQ(rights(as, "", level, "user1", "host1"), kRW) << level;
        EXPECT_EQ(rights(as, "", level, "user2", "host2"), kRW) << level;
        EXPECT_EQ(rights(as, "", level, "user1", "host2"), kRW) << level;
        EXPECT_EQ(rights(as, "", level, "user1", "host3"), kAccessRead) << level;
        EXPECT_EQ(rights(as, "", level, "user3", "host1"), kAccessRead) << level;
        EXPECT_EQ(rights(as, "", level, "", ""), kAccessRead) << level;
    }
    // A record whose ASG is not in the file is in DEFAULT.
    EXPECT_EQ(rights(as, "undefined", 1, "user1", "host1"), kRW);
    EXPECT_EQ(rights(as, "undefined", 1, "user3", "host1"), kAccessRead);
}

TEST(AccessSecurityGuide, LinacExampleIsRejectedAtItsFirstInput) {
    EXPECT_EQ(parse_error(kLinacExample),
              "test.acf:10:5: INPA(...) in ASG 'DEFAULT': CALC and INPx rules are not supported");
}

TEST(AccessSecurityGuide, LinacExamplePermitGroup) {
    AccessSecurity as = acf(kLinacWithoutCalc);
    EXPECT_EQ(as.groups(), (std::vector<std::string>{"DEFAULT", "permit"}));
    // Supervisors and application developers write level 0 fields only, from anywhere.
    for (const char* user : {"superguy", "gsm", "nda", "kko"}) {
        EXPECT_EQ(rights(as, "permit", 0, user, "anywhere"), kRW) << user;
        EXPECT_EQ(rights(as, "permit", 1, user, "anywhere"), kAccessRead) << user;
    }
    // Operators and linac engineers only read.
    for (const char* user : {"op1", "op2", "waw", "berg"}) {
        EXPECT_EQ(rights(as, "permit", 0, user, "mars"), kAccessRead) << user;
        EXPECT_EQ(rights(as, "permit", 1, user, "mars"), kAccessRead) << user;
    }
    // IOCs always have level 1 write privilege; host names compare case-insensitively.
    EXPECT_EQ(rights(as, "permit", 1, "anyone", "ioclid3"), kRW);
    EXPECT_EQ(rights(as, "permit", 1, "anyone", "IOCLID3"), kRW);
    EXPECT_EQ(rights(as, "permit", 0, "anyone", "ioclic2"), kRW);
    EXPECT_EQ(rights(as, "permit", 1, "anyone", "ioclid6"), kAccessRead);
    // User names compare exactly.
    EXPECT_EQ(rights(as, "permit", 0, "GSM", "anywhere"), kAccessRead);
    // Records without ASG.
    EXPECT_EQ(rights(as, "", 0, "superguy", "mars"), kAccessRead);
    EXPECT_EQ(rights(as, "", 1, "x", "ioclic1"), kRW);
}

TEST(AccessSecurityGuide, LinacExampleMisspelledUagIsUndefined) {
    // The guide's example names UAG 'appdev' in rules but defines 'appDev'; asLib compares UAG
    // names exactly (strcmp in asAsgRuleUagAdd), so this is an undefined UAG.
    EXPECT_EQ(parse_error("UAG(appDev) {nda}\nASG(permit) {\n    RULE(0,WRITE) {\n"
                          "        UAG(appdev)\n    }\n}\n"),
              "test.acf:4:13: undefined UAG 'appdev' in RULE of ASG 'permit' (a UAG must be "
              "defined before the ASG that uses it)");
}

// ---------------------------------------------------------------------------------------------
// EPICS base aslibtest.c cases (host names, no asCheckClientIP)

TEST(AccessSecurityAslibtest, HostNames) {
    AccessSecurity as = acf("HAG(foo) {localhost}\n"
                            "ASG(DEFAULT) {RULE(0, NONE)}\n"
                            "ASG(ro) {RULE(0, NONE)RULE(1, READ) {HAG(foo)}}\n"
                            "ASG(rw) {RULE(1, WRITE) {HAG(foo)}}\n");
    EXPECT_EQ(as.rights("invalid", 0, "testing", "localhost", "127.0.0.1"), kAccessNone);
    EXPECT_EQ(as.rights("DEFAULT", 0, "testing", "localhost", "127.0.0.1"), kAccessNone);
    EXPECT_EQ(as.rights("ro", 0, "testing", "localhost", "127.0.0.1"), kAccessRead);
    EXPECT_EQ(as.rights("rw", 0, "testing", "localhost", "127.0.0.1"), kRW);
    // Host names in a HAG are not resolved: a client calling itself 127.0.0.1 is not localhost.
    for (const char* host : {"127.0.0.1", "guaranteed.invalid."}) {
        EXPECT_EQ(as.rights("invalid", 0, "testing", host, "127.0.0.1"), kAccessNone) << host;
        EXPECT_EQ(as.rights("DEFAULT", 0, "testing", host, "127.0.0.1"), kAccessNone) << host;
        EXPECT_EQ(as.rights("ro", 0, "testing", host, "127.0.0.1"), kAccessNone) << host;
        EXPECT_EQ(as.rights("rw", 0, "testing", host, "127.0.0.1"), kAccessNone) << host;
    }
}

TEST(AccessSecurityAslibtest, AlmostEmptyFileIsAnError) {
    EXPECT_EQ(parse_error("\n#almost empty file\n\n"),
              "test.acf:4:1: expected UAG, HAG or ASG, got end of file (an access security "
              "file needs at least one definition)");
    EXPECT_EQ(parse_error(""),
              "test.acf:1:1: expected UAG, HAG or ASG, got end of file (an access security "
              "file needs at least one definition)");
}

// ---------------------------------------------------------------------------------------------
// Levels

TEST(AccessSecurityLevels, Level0RuleCoversOnlyLevel0Fields) {
    AccessSecurity as = acf("ASG(g) { RULE(0, WRITE) RULE(1, READ) }");
    EXPECT_EQ(rights(as, "g", 0, "u", "h"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "u", "h"), kAccessRead);
}

TEST(AccessSecurityLevels, Level1RuleCoversLevel0And1Fields) {
    AccessSecurity as = acf("ASG(g) { RULE(1, WRITE) }");
    EXPECT_EQ(rights(as, "g", 0, "u", "h"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "u", "h"), kRW);
}

TEST(AccessSecurityLevels, OnlyLevel0ReadLeavesLevel1FieldsInaccessible) {
    AccessSecurity as = acf("ASG(g) { RULE(0, READ) }");
    EXPECT_EQ(rights(as, "g", 0, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "g", 1, "u", "h"), kAccessNone);
}

TEST(AccessSecurityLevels, HigherRuleLevelsAreAcceptedAsByAsLib) {
    AccessSecurity as = acf("ASG(g) { RULE(2, READ) }");
    EXPECT_EQ(rights(as, "g", 0, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "g", 1, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "g", 3, "u", "h"), kAccessNone);
}

// ---------------------------------------------------------------------------------------------
// Combining rules, UAG and HAG

TEST(AccessSecurityRules, AccessIsTheMaximumOfApplicableRulesInAnyOrder) {
    AccessSecurity a = acf("UAG(x) {x}\nASG(g) { RULE(1, WRITE) { UAG(x) } RULE(1, READ) }");
    AccessSecurity b = acf("UAG(x) {x}\nASG(g) { RULE(1, READ) RULE(1, WRITE) { UAG(x) } }");
    for (const AccessSecurity* as : {&a, &b}) {
        EXPECT_EQ(rights(*as, "g", 1, "x", "h"), kRW);
        EXPECT_EQ(rights(*as, "g", 1, "y", "h"), kAccessRead);
    }
}

TEST(AccessSecurityRules, NoneNeverTakesAccessAway) {
    AccessSecurity as = acf("ASG(g) { RULE(1, READ) RULE(1, NONE) }");
    EXPECT_EQ(rights(as, "g", 1, "u", "h"), kAccessRead);
}

TEST(AccessSecurityRules, GroupWithoutRulesGrantsNothing) {
    AccessSecurity as = acf("ASG(g)\nASG(h) { RULE(1, NONE) }");
    EXPECT_EQ(rights(as, "g", 0, "u", "h"), kAccessNone);
    EXPECT_EQ(rights(as, "h", 0, "u", "h"), kAccessNone);
}

TEST(AccessSecurityRules, UagAndHagMustBothMatch) {
    AccessSecurity as = acf(R"(
UAG(ops) {alice, bob}
HAG(console) {cr1, cr2}
ASG(g) {
    RULE(1, READ)
    RULE(1, WRITE) { UAG(ops) HAG(console) }
})");
    EXPECT_EQ(rights(as, "g", 1, "alice", "cr1"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "bob", "cr2"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "alice", "laptop"), kAccessRead);
    EXPECT_EQ(rights(as, "g", 1, "mallory", "cr1"), kAccessRead);
    EXPECT_EQ(rights(as, "g", 1, "Alice", "cr1"), kAccessRead); // users compare exactly
}

TEST(AccessSecurityRules, SeveralUagsOrHagsInARuleAreAlternatives) {
    AccessSecurity as = acf(R"(
UAG(a) {alice}
UAG(b) {bob}
UAG(c) {carol}
HAG(h1) {one}
HAG(h2) {two}
ASG(list) { RULE(1, WRITE) { UAG(a, b) HAG(h1, h2) } }
ASG(clauses) { RULE(1, WRITE) { UAG(a) UAG(b) HAG(h1) HAG(h2) } }
)");
    for (const char* asg : {"list", "clauses"}) {
        EXPECT_EQ(rights(as, asg, 1, "alice", "one"), kRW) << asg;
        EXPECT_EQ(rights(as, asg, 1, "bob", "two"), kRW) << asg;
        EXPECT_EQ(rights(as, asg, 1, "carol", "one"), kAccessNone) << asg;
        EXPECT_EQ(rights(as, asg, 1, "alice", "three"), kAccessNone) << asg;
    }
}

TEST(AccessSecurityRules, OnlyUagOrOnlyHag) {
    AccessSecurity as = acf(R"(
UAG(u) {alice}
HAG(h) {cr1}
ASG(users) { RULE(1, WRITE) { UAG(u) } }
ASG(hosts) { RULE(1, WRITE) { HAG(h) } }
)");
    EXPECT_EQ(rights(as, "users", 1, "alice", "anywhere"), kRW);
    EXPECT_EQ(rights(as, "users", 1, "bob", "cr1"), kAccessNone);
    EXPECT_EQ(rights(as, "hosts", 1, "anyone", "cr1"), kRW);
    EXPECT_EQ(rights(as, "hosts", 1, "alice", "cr2"), kAccessNone);
}

TEST(AccessSecurityRules, EmptyUagOrHagMatchesNobody) {
    AccessSecurity as = acf(R"(
UAG(nobody)
HAG(nowhere)
ASG(u) { RULE(1, WRITE) { UAG(nobody) } }
ASG(h) { RULE(1, WRITE) { HAG(nowhere) } }
)");
    EXPECT_EQ(rights(as, "u", 1, "", ""), kAccessNone);
    EXPECT_EQ(rights(as, "h", 1, "", ""), kAccessNone);
}

TEST(AccessSecurityRules, RepeatedMembersAndUsersInSeveralUagsAreAccepted) {
    AccessSecurity as = acf(R"(
UAG(a) {alice, alice}
UAG(b) {alice}
HAG(h) {cr1, CR1}
ASG(g) { RULE(1, READ) { UAG(a) } RULE(1, WRITE) { UAG(b) HAG(h) } }
)");
    EXPECT_EQ(rights(as, "g", 1, "alice", "cr1"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "alice", "cr2"), kAccessRead);
}

TEST(AccessSecurityRules, RpcGrantsNoChannelAccessRights) {
    AccessSecurity as = acf("ASG(rpc) { RULE(1, RPC) }\nASG(mix) { RULE(1, RPC) RULE(1, READ) }");
    EXPECT_EQ(rights(as, "rpc", 0, "u", "h"), kAccessNone);
    EXPECT_EQ(rights(as, "mix", 0, "u", "h"), kAccessRead);
}

TEST(AccessSecurityRules, TrapWriteOptionsDoNotChangeRights) {
    AccessSecurity as = acf("ASG(t) { RULE(1, WRITE, TRAPWRITE) }\n"
                            "ASG(n) { RULE(1, READ, NOTRAPWRITE) }");
    EXPECT_EQ(rights(as, "t", 1, "u", "h"), kRW);
    EXPECT_EQ(rights(as, "n", 1, "u", "h"), kAccessRead);
}

// ---------------------------------------------------------------------------------------------
// Hosts

TEST(AccessSecurityHosts, HostNamesCompareCaseInsensitively) {
    AccessSecurity as = acf("HAG(h) {Console1.Example.ORG}\nASG(g) { RULE(1, WRITE) { HAG(h) } }");
    EXPECT_EQ(rights(as, "g", 1, "u", "console1.example.org"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "u", "CONSOLE1.EXAMPLE.ORG"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "u", "console1"), kAccessNone);
    EXPECT_EQ(rights(as, "g", 1, "u", "console1.example.org."), kAccessNone);
}

TEST(AccessSecurityHosts, DottedIpv4EntryMatchesPeerAddress) {
    AccessSecurity as = acf(R"(
HAG(net) {10.0.0.5, "192.168.1.20"}
ASG(g) { RULE(1, WRITE) { HAG(net) } }
)");
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", "10.0.0.5"), kRW);
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", "192.168.1.20"), kRW);
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", "10.0.0.6"), kAccessNone);
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", ""), kAccessNone);
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", "10.0.0.5.1"), kAccessNone);
    EXPECT_EQ(as.rights("g", 1, "u", "somehost", "10.0.0"), kAccessNone);
    // As in asLib, the entry also matches a client whose HOST_NAME is that string.
    EXPECT_EQ(as.rights("g", 1, "u", "10.0.0.5", ""), kRW);
}

TEST(AccessSecurityHosts, HostNameEntryDoesNotMatchPeerAddress) {
    AccessSecurity as = acf("HAG(h) {cr1}\nASG(g) { RULE(1, WRITE) { HAG(h) } }");
    EXPECT_EQ(as.rights("g", 1, "u", "other", "cr1"), kAccessNone);
}

TEST(AccessSecurityHosts, AmbiguousAddressFormsAreOnlyHostNames) {
    // "010.0.0.5" could be octal (inet_aton) or decimal; it is compared as a host name only.
    AccessSecurity as = acf("HAG(h) {010.0.0.5, 10.0.0.256}\nASG(g) { RULE(1, WRITE) { HAG(h) } }");
    EXPECT_EQ(as.rights("g", 1, "u", "x", "10.0.0.5"), kAccessNone);
    EXPECT_EQ(as.rights("g", 1, "u", "x", "8.0.0.5"), kAccessNone);
    EXPECT_EQ(as.rights("g", 1, "u", "010.0.0.5", ""), kRW);
}

// ---------------------------------------------------------------------------------------------
// DEFAULT and groups

TEST(AccessSecurityDefault, MissingDefaultGroupExistsWithoutRules) {
    AccessSecurity as = acf("ASG(ro) { RULE(1, READ) }");
    EXPECT_EQ(as.groups(), (std::vector<std::string>{"DEFAULT", "ro"}));
    EXPECT_EQ(rights(as, "ro", 1, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "", 0, "u", "h"), kAccessNone);
    EXPECT_EQ(rights(as, "DEFAULT", 0, "u", "h"), kAccessNone);
    EXPECT_EQ(rights(as, "unknown", 0, "u", "h"), kAccessNone);
    EXPECT_TRUE(as.has_group("ro"));
    EXPECT_TRUE(as.has_group("DEFAULT"));
    EXPECT_TRUE(as.has_group(""));
    EXPECT_FALSE(as.has_group("unknown"));
}

TEST(AccessSecurityDefault, UnknownAndEmptyGroupsUseDefaultRules) {
    AccessSecurity as = acf("ASG(DEFAULT) { RULE(1, READ) }\nASG(rw) { RULE(1, WRITE) }");
    EXPECT_EQ(rights(as, "", 1, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "nope", 1, "u", "h"), kAccessRead);
    EXPECT_EQ(rights(as, "RW", 1, "u", "h"), kAccessRead); // group names compare exactly
    EXPECT_EQ(rights(as, "rw", 1, "u", "h"), kRW);
    EXPECT_FALSE(as.has_group("RW"));
}

TEST(AccessSecurityDefault, GroupsAreListedInByteOrder) {
    AccessSecurity as = acf("ASG(zeta)\nASG(Alpha)\nASG(beta)\nASG(DEFAULT)");
    EXPECT_EQ(as.groups(), (std::vector<std::string>{"Alpha", "DEFAULT", "beta", "zeta"}));
}

TEST(AccessSecurityDefault, DefaultMayBeReopenedWhileItHasNoRules) {
    // asAsgAdd: DEFAULT is created before parsing and reused while it has no rules.
    AccessSecurity as = acf("ASG(DEFAULT)\nASG(DEFAULT) { RULE(1, READ) }");
    EXPECT_EQ(rights(as, "", 1, "u", "h"), kAccessRead);
    EXPECT_EQ(parse_error("ASG(DEFAULT) { RULE(1, READ) }\nASG(DEFAULT) { RULE(1, WRITE) }"),
              "test.acf:2:5: duplicate ASG 'DEFAULT' (first defined at test.acf:1:5)");
}

TEST(AccessSecurityDefault, CopiesShareTheConfiguration) {
    AccessSecurity as = acf(kSimpleExample);
    AccessSecurity copy = as;
    as = AccessSecurity();
    EXPECT_FALSE(as.enabled());
    EXPECT_TRUE(copy.enabled());
    EXPECT_EQ(rights(copy, "", 1, "user3", "host1"), kAccessRead);
}

// ---------------------------------------------------------------------------------------------
// Lexical rules

TEST(AccessSecuritySyntax, QuotedNamesAndMembers) {
    AccessSecurity as = acf(R"(
UAG("ops team") {"alice smith", bob, "1234", "UAG"}
HAG("hosts") {"Console 1"}
ASG("my group") { RULE(1, "WRITE") { UAG("ops team") HAG(hosts) } }
ASG("RULE") { RULE(1, READ) }
)");
    EXPECT_EQ(rights(as, "my group", 1, "alice smith", "console 1"), kRW);
    EXPECT_EQ(rights(as, "my group", 1, "1234", "CONSOLE 1"), kRW);
    EXPECT_EQ(rights(as, "my group", 1, "UAG", "console 1"), kRW);
    EXPECT_EQ(rights(as, "my group", 1, "alice", "console 1"), kAccessNone);
    EXPECT_EQ(rights(as, "RULE", 1, "x", "y"), kAccessRead);
    EXPECT_EQ(as.groups(), (std::vector<std::string>{"DEFAULT", "RULE", "my group"}));
}

TEST(AccessSecuritySyntax, BareNamesUseTheDatabaseNameCharacters) {
    AccessSecurity as = acf("UAG(u) {a_b-c+d:e.f[g]<h>;i}\nASG(LI:grp-1.x) "
                            "{ RULE(1, WRITE) { UAG(u) } }");
    EXPECT_EQ(rights(as, "LI:grp-1.x", 1, "a_b-c+d:e.f[g]<h>;i", "h"), kRW);
}

TEST(AccessSecuritySyntax, QuotedStringsKeepEscapesAsWritten) {
    // asLib_lex.l copies the text between the quotes without interpreting backslashes.
    AccessSecurity as = acf(R"(UAG(u) {"a\"b"}
ASG(g) { RULE(1, WRITE) { UAG(u) } })");
    EXPECT_EQ(rights(as, "g", 1, R"(a\"b)", "h"), kRW);
    EXPECT_EQ(rights(as, "g", 1, R"(a"b)", "h"), kAccessNone);
}

TEST(AccessSecuritySyntax, CommentsAndWhitespace) {
    AccessSecurity as = acf("# header\r\n"
                            "UAG(u) { alice,  # trailing comment\n"
                            "\tbob }\r\n"
                            "ASG(g) {RULE(1,READ)RULE(1,WRITE){UAG(u)}} # done\n"
                            "# ASG(h) { RULE(1, WRITE) }\n"
                            "UAG(v) {\"x#y\"}\n");
    EXPECT_EQ(rights(as, "g", 1, "bob", "h"), kRW);
    EXPECT_EQ(rights(as, "g", 1, "carol", "h"), kAccessRead);
    EXPECT_EQ(as.groups(), (std::vector<std::string>{"DEFAULT", "g"}));
}

TEST(AccessSecuritySyntax, KeywordsAreCaseSensitiveAndWholeWords) {
    EXPECT_EQ(parse_error("uag(x) {a}"), "test.acf:1:1: expected UAG, HAG or ASG, got 'uag'");
    // "RULES" is a name, not the keyword RULE.
    EXPECT_EQ(parse_error("ASG(g) { RULES(1, READ) }"),
              "test.acf:1:10: expected RULE or '}' in ASG 'g', got 'RULES'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, read) }"),
              "test.acf:1:18: access right must be NONE, READ, WRITE or RPC, got 'read'");
}

// ---------------------------------------------------------------------------------------------
// Errors, with exact file:line:col

TEST(AccessSecurityErrors, CalcIsRejectedAtItsPosition) {
    EXPECT_EQ(parse_error("ASG(g) {\n  RULE(1, WRITE) {\n    CALC(\"A=1\")\n  }\n}\n"),
              "test.acf:3:5: CALC(...) in RULE of ASG 'g': CALC and INPx rules are not "
              "supported");
}

TEST(AccessSecurityErrors, InputLinksAreRejectedAtTheirPosition) {
    EXPECT_EQ(parse_error("ASG(g) {\n\tRULE(1, READ)\n\tINPL(\"LI:X\")\n}"),
              "test.acf:3:2: INPL(...) in ASG 'g': CALC and INPx rules are not supported");
    // INPM is not a link name but an ordinary word, which cannot start an ASG item.
    EXPECT_EQ(parse_error("ASG(g) { INPM(x) }"),
              "test.acf:1:10: expected RULE or '}' in ASG 'g', got 'INPM'");
}

TEST(AccessSecurityErrors, UndefinedUagOrHagInRule) {
    EXPECT_EQ(parse_error("UAG(ops) {a}\nASG(g) { RULE(1, WRITE) { UAG(ops, opz) } }"),
              "test.acf:2:36: undefined UAG 'opz' in RULE of ASG 'g' (a UAG must be defined "
              "before the ASG that uses it)");
    EXPECT_EQ(parse_error("ASG(g) {\n RULE(1, WRITE) { HAG(cr) }\n}"),
              "test.acf:2:23: undefined HAG 'cr' in RULE of ASG 'g' (a HAG must be defined "
              "before the ASG that uses it)");
}

TEST(AccessSecurityErrors, UagDefinedAfterItsUseIsUndefined) {
    // asAsgRuleUagAdd looks the name up while parsing the rule.
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, WRITE) { UAG(late) } }\nUAG(late) {a}"),
              "test.acf:1:31: undefined UAG 'late' in RULE of ASG 'g' (a UAG must be defined "
              "before the ASG that uses it)");
}

TEST(AccessSecurityErrors, DuplicateDefinitions) {
    EXPECT_EQ(parse_error("UAG(a) {x}\nUAG(b) {y}\n  UAG(a) {z}"),
              "test.acf:3:7: duplicate UAG 'a' (first defined at test.acf:1:5)");
    EXPECT_EQ(parse_error("HAG(h)\nHAG(\"h\") {x}"),
              "test.acf:2:5: duplicate HAG 'h' (first defined at test.acf:1:5)");
    EXPECT_EQ(parse_error("ASG(g)\nASG(g)"),
              "test.acf:2:5: duplicate ASG 'g' (first defined at test.acf:1:5)");
    // UAG, HAG and ASG names live in separate name spaces.
    EXPECT_EQ(parse_error("UAG(x)\nHAG(x)\nASG(x)"), "no error");
}

TEST(AccessSecurityErrors, BadRuleHeads) {
    EXPECT_EQ(parse_error("ASG(g) { RULE(one, READ) }"),
              "test.acf:1:15: expected a rule level (0 or 1) in RULE of ASG 'g', got 'one'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(\"1\", READ) }"),
              "test.acf:1:15: expected a rule level (0 or 1) in RULE of ASG 'g', got \"1\"");
    EXPECT_EQ(parse_error("ASG(g) { RULE(99999999999999999999, READ) }"),
              "test.acf:1:15: rule level 99999999999999999999 is out of range in RULE of ASG 'g'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1 READ) }"),
              "test.acf:1:17: expected ',' after the rule level in RULE of ASG 'g', got 'READ'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, WRITE, TRAP) }"),
              "test.acf:1:25: rule option must be TRAPWRITE or NOTRAPWRITE, got 'TRAP'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, WRITE, TRAPWRITE, x) }"),
              "test.acf:1:34: expected ')' to close RULE in RULE of ASG 'g', got ','");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, ) }"),
              "test.acf:1:18: expected an access right (NONE, READ, WRITE or RPC) in RULE of "
              "ASG 'g', got ')'");
}

TEST(AccessSecurityErrors, BadRuleBodies) {
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, READ) {\n  METHOD(\"x509\")\n} }"),
              "test.acf:2:3: expected UAG(...), HAG(...) or '}' in RULE of ASG 'g', got "
              "'METHOD'");
    EXPECT_EQ(parse_error("UAG(u)\nASG(g) { RULE(1, READ) { UAG(u,) } }"),
              "test.acf:2:32: expected a UAG name in RULE of ASG 'g', got ')'");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, READ) { } }"),
              "test.acf:1:26: empty {} body in RULE of ASG 'g' (omit the braces for a rule "
              "that applies to all)");
    EXPECT_EQ(parse_error("ASG(g) { }"),
              "test.acf:1:10: empty {} body in ASG 'g' (omit the braces for a group without "
              "rules)");
    EXPECT_EQ(parse_error("ASG(g) { RULE(1, READ)"),
              "test.acf:1:23: expected RULE or '}' in ASG 'g', got end of file");
}

TEST(AccessSecurityErrors, BadMemberLists) {
    EXPECT_EQ(parse_error("UAG(u) {}"),
              "test.acf:1:9: empty {} list in UAG 'u' (omit the braces for an empty group)");
    EXPECT_EQ(parse_error("UAG(u) {a,}"),
              "test.acf:1:11: expected a user name in UAG 'u', got '}'");
    EXPECT_EQ(parse_error("HAG(h) {a b}"),
              "test.acf:1:11: expected ',' or '}' in HAG 'h', got 'b'");
    EXPECT_EQ(parse_error("UAG(u) {alice, 1234}"),
              "test.acf:1:16: expected a user name in UAG 'u', got integer '1234' (a bare "
              "number is not a name; quote it: \"1234\")");
    EXPECT_EQ(parse_error("ASG(RULE)"),
              "test.acf:1:5: expected a group name after ASG, got keyword 'RULE' (quote it to "
              "use it as a name: \"RULE\")");
    EXPECT_EQ(parse_error("UAG u {a}"), "test.acf:1:5: expected '(' after UAG, got 'u'");
    EXPECT_EQ(parse_error("UAG(u {a}"), "test.acf:1:7: expected ')' after UAG name, got '{'");
}

TEST(AccessSecurityErrors, BadCharactersAndStrings) {
    EXPECT_EQ(parse_error("UAG(u) {a@b}"), "test.acf:1:10: invalid character '@'");
    EXPECT_EQ(parse_error("ASG($(P)) { RULE(1, READ) }"),
              "test.acf:1:5: invalid character '$' (macro substitution is not supported)");
    EXPECT_EQ(parse_error(std::string("ASG(g)\n\x01")), "test.acf:2:1: invalid character 0x01");
    // A UTF-8 byte order mark is not accepted (asLib rejects it too).
    EXPECT_EQ(parse_error("\xef\xbb\xbf"
                          "ASG(g)"),
              "test.acf:1:1: invalid character 0xef");
    EXPECT_EQ(parse_error(std::string("ASG(g\0h)", 8)), "test.acf:1:6: invalid character 0x00");
    EXPECT_EQ(parse_error("UAG(u) {\"alice,\n bob}"),
              "test.acf:1:9: newline in quoted string, closing quote missing");
    EXPECT_EQ(parse_error("UAG(u) {\"alice\\"), "test.acf:1:9: unterminated quoted string");
    EXPECT_EQ(parse_error("UAG(u) {\"alice"), "test.acf:1:9: unterminated quoted string");
}

TEST(AccessSecurityErrors, EmptyFileNameIsShownAsInput) {
    EXPECT_EQ(parse_error("ASG(", ""), "<input>:1:5: expected a group name after ASG, got end of "
                                       "file");
}

TEST(AccessSecurityErrors, ColumnsCountBytesAndTabsAsOne) {
    EXPECT_EQ(parse_error("\t\tASG(g) {\n\t\tRULE(1, WRITE) { HAG(x) }\n}"),
              "test.acf:2:24: undefined HAG 'x' in RULE of ASG 'g' (a HAG must be defined "
              "before the ASG that uses it)");
}

// ---------------------------------------------------------------------------------------------
// Files

TEST(AccessSecurityFile, LoadsAFile) {
    std::string path = "/tmp/beamctl_test_access_security_" + std::to_string(::getpid()) + ".acf";
    {
        std::ofstream out(path);
        out << kSimpleExample;
    }
    AccessSecurity as = AccessSecurity::load_file(path);
    EXPECT_EQ(rights(as, "", 1, "user2", "HOST2"), kRW);
    {
        std::ofstream out(path);
        out << "ASG(g) {\n  RULE(1, WRITE, x)\n}\n";
    }
    try {
        AccessSecurity::load_file(path);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  path + ":2:18: rule option must be TRAPWRITE or NOTRAPWRITE, got 'x'");
    }
    std::remove(path.c_str());
}

TEST(AccessSecurityFile, MissingFileIsAnError) {
    try {
        AccessSecurity::load_file("/nonexistent/dir/as.acf");
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  "/nonexistent/dir/as.acf: cannot open access security file: No such file or "
                  "directory");
    }
}

// ---------------------------------------------------------------------------------------------
// Seeded randomized comparison with the AppDevGuide's rule of evaluation, written directly:
// the access is the maximum over rules whose level covers the field and whose UAG and HAG
// lists (when given) contain the user and the host.

namespace {

struct ModelRule {
    int level;
    unsigned access; // NONE=0, READ=1, WRITE=3, RPC=0
    std::vector<int> uags, hags;
};

} // namespace

TEST(AccessSecurityProperty, MatchesReferenceModelOnRandomConfigurations) {
    std::mt19937 rng(20240611);
    const std::vector<std::string> users = {"alice", "bob", "carol", "dave"};
    const std::vector<std::string> hosts = {"cr1", "cr2", "lab", "10.0.0.1"};
    const char* const right_names[] = {"NONE", "READ", "WRITE", "RPC"};
    const unsigned right_bits[] = {kAccessNone, kAccessRead, kRW, kAccessNone};
    auto pick = [&](int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng); };

    int checks = 0;
    for (int config = 0; config < 2000; ++config) {
        // Three UAGs and three HAGs with random members.
        std::vector<std::vector<int>> uag_members(3), hag_members(3);
        std::string text;
        for (int g = 0; g < 3; ++g) {
            text += "UAG(u" + std::to_string(g) + ")";
            for (int m = 0; m < 4; ++m)
                if (pick(2)) uag_members[g].push_back(m);
            if (!uag_members[g].empty()) {
                text += " {";
                for (std::size_t i = 0; i < uag_members[g].size(); ++i)
                    text += (i ? "," : "") + users[uag_members[g][i]];
                text += "}";
            }
            text += "\nHAG(h" + std::to_string(g) + ")";
            for (int m = 0; m < 4; ++m)
                if (pick(2)) hag_members[g].push_back(m);
            if (!hag_members[g].empty()) {
                text += " {";
                for (std::size_t i = 0; i < hag_members[g].size(); ++i) {
                    std::string host = hosts[hag_members[g][i]];
                    if (pick(2)) host[0] = char(std::toupper(host[0]));
                    text += (i ? "," : "") + host;
                }
                text += "}";
            }
            text += "\n";
        }
        std::vector<ModelRule> rules;
        text += "ASG(DEFAULT) {\n";
        int nrules = 1 + pick(5);
        for (int r = 0; r < nrules; ++r) {
            ModelRule rule{pick(2), 0, {}, {}};
            int right = pick(4);
            rule.access = right_bits[right];
            text += "  RULE(" + std::to_string(rule.level) + "," + right_names[right] + ")";
            for (int g = 0; g < 3; ++g)
                if (pick(3) == 0) rule.uags.push_back(g);
            for (int g = 0; g < 3; ++g)
                if (pick(3) == 0) rule.hags.push_back(g);
            if (!rule.uags.empty() || !rule.hags.empty()) {
                text += " {";
                for (int g : rule.uags) text += " UAG(u" + std::to_string(g) + ")";
                for (int g : rule.hags) text += " HAG(h" + std::to_string(g) + ")";
                text += " }";
            }
            text += "\n";
            rules.push_back(rule);
        }
        text += "}\n";
        AccessSecurity as = acf(text);

        for (int u = 0; u < 4; ++u) {
            for (int h = 0; h < 4; ++h) {
                for (int level = 0; level < 2; ++level) {
                    unsigned expected = kAccessNone;
                    for (const ModelRule& rule : rules) {
                        if (level > rule.level) continue;
                        bool user_ok = rule.uags.empty();
                        for (int g : rule.uags)
                            for (int m : uag_members[g]) user_ok = user_ok || m == u;
                        bool host_ok = rule.hags.empty();
                        for (int g : rule.hags)
                            for (int m : hag_members[g]) host_ok = host_ok || m == h;
                        if (user_ok && host_ok && rule.access > expected) expected = rule.access;
                    }
                    ASSERT_EQ(as.rights("any", level, users[u], hosts[h], ""), expected)
                        << text << "user " << users[u] << " host " << hosts[h] << " level "
                        << level;
                    ++checks;
                }
            }
        }
    }
    EXPECT_EQ(checks, 2000 * 32);
}
