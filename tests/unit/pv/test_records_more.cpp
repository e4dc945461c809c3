// The remaining EPICS base record types (src/pv/records_more.cpp): values, alarms, link reads and
// writes and the fields that process, as base 7's record support and Soft Channel device support.
#include "db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct Recorder : Subscription {
    std::vector<unsigned> masks;
    void on_event(unsigned m) override { masks.push_back(m); }
};

struct RecordsMore : DbTest {
    // "rec" as `caget -S rec.VAL$` names a long string: its characters whole.
    static std::string whole(const char* n) {
        std::string s(n);
        return (s.find('.') == std::string::npos ? s + ".VAL" : s) + "$";
    }
    // A char array written as `caput -S` does: the characters and their NUL.
    PutStatus put_chars(const char* n, const char* s) {
        return db.put(addr(whole(n).c_str()), Prim::Char, s, uint32_t(std::strlen(s) + 1));
    }
    // A char array read as `caget -S` does.
    std::string get_chars(const char* n) {
        Address a = addr(whole(n).c_str());
        std::vector<char> buf(a.count + 1, 0);
        db.get(a, Prim::Char, buf.data(), a.count);
        return std::string(buf.data());
    }
    std::vector<double> get_array(const char* n) {
        Address a = addr(n);
        std::vector<double> v(a.count);
        uint32_t got = db.get(a, Prim::Double, v.data(), a.count);
        v.resize(std::min<uint32_t>(got, a.count));
        return v;
    }
    PutStatus put_array(const char* n, std::vector<double> v) {
        return db.put(addr(n), Prim::Double, v.data(), uint32_t(v.size()));
    }
};

} // namespace

// ---------------------------------------------------------------- mbbiDirect, mbboDirect

TEST_F(RecordsMore, MbbiDirectReadsItsInputAndSplitsVALIntoBits) {
    load(R"(
record(longout, "src") { field(VAL, "0") }
record(mbbiDirect, "in") { field(INP, "src") field(NOBT, "8") }
record(mbbiDirect, "c") { field(INP, "5") }
)");
    EXPECT_EQ(gets("in.SEVR"), "INVALID"); // never processed: UDF
    EXPECT_EQ(getd("in.MASK"), 255);       // from NOBT
    EXPECT_EQ(getd("c"), 5);               // a constant input is loaded at init
    EXPECT_EQ(getd("c.B0"), 1);
    EXPECT_EQ(getd("c.B2"), 1);
    put("src", -2147483643.0); // 0x80000005
    Recorder b0, b1f, b1;
    b0.addr = addr("in.B0");
    b1f.addr = addr("in.B1F");
    b1.addr = addr("in.B1");
    for (Recorder* r : {&b0, &b1f, &b1}) {
        r->mask = kDbeValue | kDbeAlarm;
        db.subscribe(*r);
    }
    put("in.PROC", 1);
    EXPECT_EQ(getd("in"), -2147483643.0);
    EXPECT_EQ(getd("in.B0"), 1);
    EXPECT_EQ(getd("in.B1"), 0);
    EXPECT_EQ(getd("in.B2"), 1);
    EXPECT_EQ(getd("in.B1F"), 1);
    EXPECT_EQ(gets("in.SEVR"), "NO_ALARM");
    put("src", 4);
    put("in.PROC", 1);
    EXPECT_EQ(getd("in.B0"), 0);
    EXPECT_EQ(getd("in.B2"), 1);
    for (Recorder* r : {&b0, &b1f, &b1}) db.unsubscribe(*r);
    EXPECT_EQ(b0.masks.size(), 2u);  // set, then cleared
    EXPECT_EQ(b1f.masks.size(), 2u);
    EXPECT_EQ(b1.masks.size(), 1u);  // the alarm change only (UDF cleared), never a value change
}

TEST_F(RecordsMore, MbboDirectBitsWriteVALAndVALWritesTheOutput) {
    load(R"(
record(mbboDirect, "o") { field(OUT, "dst PP") field(SHFT, "4") }
record(longin, "dst") {}
record(mbboDirect, "b") { field(B3, "1") field(B1, "1") }
)");
    EXPECT_EQ(getd("b"), 10); // bits given in the file define VAL
    EXPECT_EQ(getd("b.UDF"), 0);
    put("o", 6);
    EXPECT_EQ(getd("dst"), 6); // Soft Channel writes VAL
    EXPECT_EQ(getd("o.RVAL"), 96); // VAL << SHFT
    EXPECT_EQ(getd("o.B1"), 1);
    EXPECT_EQ(getd("o.B2"), 1);
    EXPECT_EQ(getd("o.B0"), 0);
    ASSERT_EQ(put("o.B0", 1), PutStatus::Ok); // a bit processes the record
    EXPECT_EQ(getd("o"), 7);
    EXPECT_EQ(getd("dst"), 7);
    put("o.B1F", 1);
    EXPECT_EQ(getd("o"), -2147483641.0);
    put("o.B1F", 0);
    put("o.B1", 0);
    EXPECT_EQ(getd("dst"), 5);
    EXPECT_EQ(gets("o.SEVR"), "NO_ALARM");
}

TEST_F(RecordsMore, MbboDirectClosedLoopReadsDolAndRefusesBitPuts) {
    load(R"(
record(longout, "src") { field(VAL, "9") }
record(mbboDirect, "o") { field(DOL, "src") field(OMSL, "closed_loop") field(OUT, "dst PP") }
record(longin, "dst") {}
record(mbboDirect, "u") { field(OUT, "udst PP") field(IVOA, "Set output to IVOV") field(IVOV, "3") }
record(longin, "udst") {}
)");
    put("o.PROC", 1);
    EXPECT_EQ(getd("o"), 9);
    EXPECT_EQ(getd("o.B3"), 1);
    EXPECT_EQ(getd("dst"), 9);
    EXPECT_NE(put("o.B2", 1), PutStatus::Ok);
    EXPECT_EQ(getd("o.B2"), 0);
    EXPECT_EQ(getd("o"), 9);
    // Never given a value: UDF/INVALID, and IVOA writes IVOV instead.
    put("u.PROC", 1);
    EXPECT_EQ(gets("u.SEVR"), "INVALID");
    EXPECT_EQ(gets("u.STAT"), "UDF");
    EXPECT_EQ(getd("udst"), 3);
}

// ---------------------------------------------------------------- int64in, int64out

TEST_F(RecordsMore, Int64inKeepsSixtyFourBitsAndChecksInt64Alarms) {
    load(R"(
record(int64in, "i") { field(HIHI, "5000000000") field(HHSV, "MAJOR") field(HIGH, "4000000000")
                       field(HSV, "MINOR") field(LOLO, "-5000000000") field(LLSV, "INVALID") }
record(int64out, "src") { field(VAL, "1") }
record(int64in, "r") { field(INP, "src") }
)");
    Address a = addr("i");
    EXPECT_EQ(a.native, Prim::Double); // INT64 over CA is DOUBLE
    int64_t big = 4500000000;
    // A string put keeps every digit.
    ASSERT_EQ(put_str("i", "4500000001"), PutStatus::Ok);
    EXPECT_EQ(gets("i"), "4500000001");
    EXPECT_EQ(gets("i.SEVR"), "MINOR");
    EXPECT_EQ(gets("i.STAT"), "HIGH");
    put("i", double(big) * 2);
    EXPECT_EQ(gets("i.SEVR"), "MAJOR");
    put("i", -6e9);
    EXPECT_EQ(gets("i.SEVR"), "INVALID");
    EXPECT_EQ(gets("i.STAT"), "LOLO");
    put("i", 0);
    EXPECT_EQ(gets("i.SEVR"), "NO_ALARM");
    put("src", 3e9);
    put("r.PROC", 1);
    EXPECT_EQ(getd("r"), 3e9);
    EXPECT_EQ(gets("r.SEVR"), "NO_ALARM");
}

TEST_F(RecordsMore, Int64inDeadbands) {
    load(R"(record(int64in, "i") { field(MDEL, "10") field(ADEL, "100") field(PINI, "YES") })");
    Recorder r;
    r.addr = addr("i");
    r.mask = kDbeValue | kDbeLog;
    db.subscribe(r);
    put("i", 5);    // within MDEL
    put("i", 11);   // > MDEL
    put("i", 200);  // > both
    put("i", 200);  // nothing
    db.unsubscribe(r);
    ASSERT_EQ(r.masks.size(), 2u);
    EXPECT_EQ(r.masks[0], unsigned(kDbeValue));
    EXPECT_EQ(r.masks[1], unsigned(kDbeValue | kDbeLog));
}

// longin/longout and int64in/int64out share their record support (record_support.hpp): as base's
// init_record, MLST, ALST and LALM start at VAL, so a first processing with the .db's value posts
// nothing; longout keeps its 32-bit drive limits.
TEST_F(RecordsMore, IntegerRecordsStartTheirDeadbandsAtVal) {
    load(R"(
record(longin, "l") { field(VAL, "5") field(MDEL, "-1") }
record(longout, "lo") { field(VAL, "7") field(DRVH, "100") field(DRVL, "-100") }
record(int64in, "i") { field(VAL, "6000000000") }
)");
    EXPECT_EQ(getd("l.MLST"), 5);
    EXPECT_EQ(getd("l.ALST"), 5);
    EXPECT_EQ(getd("l.LALM"), 5);
    EXPECT_EQ(getd("lo.MLST"), 7);
    EXPECT_EQ(getd("i.MLST"), 6e9);
    Recorder r;
    r.addr = addr("lo");
    r.mask = kDbeValue;
    db.subscribe(r);
    put("lo.PROC", 1); // the same value: no post
    EXPECT_TRUE(r.masks.empty());
    put("lo", 500); // clamped to DRVH
    EXPECT_EQ(getd("lo"), 100);
    ASSERT_EQ(r.masks.size(), 1u);
    db.unsubscribe(r);
    // MDEL -1 posts every processing
    Recorder all;
    all.addr = addr("l");
    all.mask = kDbeValue;
    db.subscribe(all);
    put("l.PROC", 1);
    put("l.PROC", 1);
    EXPECT_EQ(all.masks.size(), 2u);
    db.unsubscribe(all);
}

TEST_F(RecordsMore, Int64outDriveLimitsClosedLoopAndIvoa) {
    load(R"(
record(int64out, "o") { field(DRVH, "10000000000") field(DRVL, "-10") field(OUT, "dst PP") }
record(int64in, "dst") {}
record(longout, "src") { field(VAL, "77") }
record(int64out, "cl") { field(DOL, "src") field(OMSL, "closed_loop") field(OUT, "dst2 PP") }
record(int64in, "dst2") {}
record(int64out, "iv") { field(HIHI, "5") field(HHSV, "INVALID") field(OUT, "dst3 PP")
                         field(IVOA, "Don't drive outputs") }
record(int64in, "dst3") {}
)");
    put("o", 2e10);
    EXPECT_EQ(getd("o"), 1e10);
    EXPECT_EQ(getd("dst"), 1e10);
    put("o", -100);
    EXPECT_EQ(getd("dst"), -10);
    put("cl.PROC", 1);
    EXPECT_EQ(getd("cl"), 77);
    EXPECT_EQ(getd("dst2"), 77);
    put("iv", 3);
    EXPECT_EQ(getd("dst3"), 3);
    put("iv", 6);
    EXPECT_EQ(gets("iv.SEVR"), "INVALID");
    EXPECT_EQ(getd("dst3"), 3); // not driven
}

// ---------------------------------------------------------------- lsi, lso

TEST_F(RecordsMore, LsoHoldsLongStringsAndWritesThemThroughOut) {
    load(R"(
record(lso, "o") { field(SIZV, "100") field(OUT, "i PP") }
record(lsi, "i") { field(SIZV, "100") }
record(lso, "s") { field(OUT, "so PP") }
record(stringout, "so") {}
record(lso, "c") { field(DOL, {const: "from the start"}) }
record(lsi, "small") { field(SIZV, "3") }
)");
    EXPECT_EQ(addr("o.VAL$").count, 100u);
    EXPECT_EQ(addr("small.VAL$").count, 16u); // SIZV is at least 16
    EXPECT_EQ(get_chars("c"), "from the start");
    EXPECT_EQ(getd("c.LEN"), 15);
    const char* text = "a string much longer than the forty characters of DBR_STRING, 72 chars";
    ASSERT_EQ(put_chars("o", text), PutStatus::Ok);
    EXPECT_EQ(get_chars("o"), text);
    EXPECT_EQ(getd("o.LEN"), double(std::strlen(text) + 1));
    EXPECT_EQ(get_chars("i"), text); // char array to char array: all of it
    EXPECT_EQ(getd("i.LEN"), double(std::strlen(text) + 1));
    EXPECT_EQ(gets("i.SEVR"), "NO_ALARM");
    put_chars("s", text);
    EXPECT_EQ(gets("so"), std::string(text).substr(0, 39)); // to a DBF_STRING: its 39 characters
    // Longer than SIZV: truncated, still terminated.
    std::string longer(150, 'x');
    put_chars("o", longer.c_str());
    EXPECT_EQ(get_chars("o"), std::string(99, 'x'));
    EXPECT_EQ(getd("o.LEN"), 100);
}

// As base's cvt_dbaddr/get_array_info serve them: "VAL" is one DBF_STRING (its first 39
// characters; no element before a value), "VAL$" the char array; links to scalars carry a string.
TEST_F(RecordsMore, LongStringValIsOneStringAndVal$TheCharArray) {
    load(R"(
record(lso, "o") { field(SIZV, "100") }
record(lsi, "never") {}
record(stringin, "si") { field(INP, "o") }
record(longin, "li") { field(INP, "o") }
record(stringout, "so") { field(OUT, "o PP") }
)");
    Address head = addr("o"), oval = addr("o.OVAL"), chars = addr("o.VAL$");
    EXPECT_EQ(head.native, Prim::String);
    EXPECT_EQ(head.count, 1u);
    EXPECT_EQ(oval.native, Prim::String);
    EXPECT_EQ(chars.native, Prim::Char);
    EXPECT_EQ(chars.count, 100u);
    EXPECT_EQ(db.current_count(addr("never")), 0u); // LEN 0: no element
    char none[kStringSize] = "x";
    EXPECT_EQ(db.get(addr("never"), Prim::String, none, 1), 0u);
    EXPECT_EQ(none[0], 0);
    const std::string text = "a string much longer than the forty characters of DBR_STRING";
    ASSERT_EQ(put_chars("o", text.c_str()), PutStatus::Ok);
    EXPECT_EQ(db.current_count(head), 1u);
    EXPECT_EQ(gets("o"), text.substr(0, 39));
    EXPECT_EQ(gets("o.OVAL"), text.substr(0, 39));
    // A DBR_STRING put: the string, LEN from it; a number put: its text.
    ASSERT_EQ(put_str("o", "short one"), PutStatus::Ok);
    EXPECT_EQ(get_chars("o"), "short one");
    EXPECT_EQ(getd("o.LEN"), 10);
    double v = 2.5;
    ASSERT_EQ(db.put(head, Prim::Double, &v, 1), PutStatus::Ok);
    EXPECT_EQ(get_chars("o"), "2.500000"); // putDoubleString: precision 6 (lso has no PREC)
    EXPECT_EQ(getd("o"), 2.5); // a string that is a number reads as one
    put("si.PROC", 1);
    EXPECT_EQ(gets("si"), "2.500000");
    put("li.PROC", 1);
    EXPECT_EQ(getd("li"), 2);
    EXPECT_EQ(gets("li.SEVR"), "NO_ALARM");
    put_str("so", "from a stringout");
    EXPECT_EQ(get_chars("o"), "from a stringout");
    EXPECT_EQ(getd("o.LEN"), 17);
}

TEST_F(RecordsMore, LsiReadsStringsAndLsoPostsOnChangeOrAlways) {
    load(R"(
record(stringout, "src") { field(VAL, "short") }
record(lsi, "i") { field(INP, "src") }
record(lso, "o") {}
record(lso, "a") { field(MPST, "Always") }
record(lso, "cl") { field(OMSL, "closed_loop") field(DOL, "i") field(OUT, "src2 PP") }
record(stringin, "src2") {}
record(lso, "u") { field(OUT, "udst PP") field(IVOA, "Set output to IVOV") field(IVOV, "fallback") }
record(stringin, "udst") {}
)");
    put("i.PROC", 1);
    EXPECT_EQ(get_chars("i"), "short");
    EXPECT_EQ(getd("i.LEN"), 6);
    put("cl.PROC", 1);
    EXPECT_EQ(get_chars("cl"), "short"); // DOL from a char array
    EXPECT_EQ(gets("src2"), "short");
    Recorder on_change, always;
    on_change.addr = addr("o");
    always.addr = addr("a");
    for (Recorder* r : {&on_change, &always}) {
        r->mask = kDbeValue;
        db.subscribe(*r);
    }
    for (int k = 0; k < 2; ++k) {
        put_chars("o", "same");
        put_chars("a", "same");
    }
    for (Recorder* r : {&on_change, &always}) db.unsubscribe(*r);
    EXPECT_EQ(on_change.masks.size(), 1u);
    EXPECT_EQ(always.masks.size(), 2u);
    // Never given a value: UDF/INVALID; IVOA writes IVOV.
    put("u.PROC", 1);
    EXPECT_EQ(gets("u.SEVR"), "INVALID");
    EXPECT_EQ(gets("udst"), "fallback");
    EXPECT_EQ(get_chars("u"), "fallback");
}
