// permissive, state and printf (src/pv/records_misc.cpp): posting on change and printf's
// formatting of INP0..INP9 as base 7's printfRecord (and its printfTest) does.
#include "db_fixture.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct Recorder : Subscription {
    std::vector<unsigned> masks;
    void on_event(unsigned m) override { masks.push_back(m); }
};

struct RecordsMisc : DbTest {
    // "rec" as `caget -S rec.VAL$` names a long string: its characters whole.
    static std::string whole(const char* n) {
        std::string s(n);
        return (s.find('.') == std::string::npos ? s + ".VAL" : s) + "$";
    }
    std::string get_chars(const char* n) {
        Address a = addr(whole(n).c_str());
        std::vector<char> buf(a.count + 1, 0);
        db.get(a, Prim::Char, buf.data(), a.count);
        return std::string(buf.data());
    }
    void process(const char* n) { db.process(*db.find(n)); }
};

} // namespace

TEST_F(RecordsMisc, PermissivePostsValAndWflgWhenTheyChange) {
    load(R"(record(permissive, "p") { field(LABL, "beam ok") })");
    Recorder val, wflg;
    val.addr = addr("p");
    val.mask = kDbeValue;
    wflg.addr = addr("p.WFLG");
    wflg.mask = kDbeValue;
    db.subscribe(val);
    db.subscribe(wflg);
    ASSERT_EQ(put("p", 1), PutStatus::Ok);
    EXPECT_EQ(val.masks.size(), 1u);
    EXPECT_EQ(getd("p.OVAL"), 1);
    ASSERT_EQ(put("p", 1), PutStatus::Ok); // unchanged: not posted
    EXPECT_EQ(val.masks.size(), 1u);
    std::size_t before = wflg.masks.size(); // the put itself posts WFLG
    ASSERT_EQ(put("p.WFLG", 1), PutStatus::Ok);
    EXPECT_GT(wflg.masks.size(), before);
    EXPECT_EQ(getd("p.OFLG"), 1);
    EXPECT_EQ(gets("p.LABL"), "beam ok");
    EXPECT_EQ(gets("p.SEVR"), "NO_ALARM");
    db.unsubscribe(val);
    db.unsubscribe(wflg);
}

TEST_F(RecordsMisc, StateHoldsAStringPostedOnChange) {
    load(R"(record(state, "s") { })");
    Recorder rec;
    rec.addr = addr("s");
    rec.mask = kDbeValue;
    db.subscribe(rec);
    ASSERT_EQ(put_str("s", "moving"), PutStatus::Ok);
    EXPECT_EQ(gets("s"), "moving");
    EXPECT_EQ(gets("s.OVAL"), "moving");
    EXPECT_EQ(rec.masks.size(), 1u);
    ASSERT_EQ(put_str("s", "moving"), PutStatus::Ok);
    EXPECT_EQ(rec.masks.size(), 1u);
    ASSERT_EQ(put_str("s", "a string longer than twenty"), PutStatus::Ok);
    EXPECT_EQ(gets("s"), "a string longer tha"); // 20 characters with the NUL
    db.unsubscribe(rec);
}

TEST_F(RecordsMisc, PrintfFormatsItsInputs) {
    load(R"(
record(ao, "d") { field(VAL, "3.14159") }
record(longout, "l") { field(VAL, "-42") }
record(stringout, "s") { field(VAL, "hello") }
record(printf, "p") {
    field(FMT, "%d|%5.2f|%s|%x|%c|%e|%g|%ld|100%%")
    field(INP0, "l") field(INP1, "d") field(INP2, "s") field(INP3, "255") field(INP4, "65")
    field(INP5, "d") field(INP6, "d") field(INP7, "l")
    field(SIZV, "100") field(OUT, "long PP")
}
record(lso, "long") { field(SIZV, "100") }
record(stringin, "dst") { }
record(printf, "q") { field(FMT, "v=%.1f") field(INP0, "d") field(OUT, "dst PP") }
)");
    process("p");
    // over CA VAL is a string (its first 40 characters); OUT to a char array carries all of it
    EXPECT_EQ(get_chars("long"), "-42| 3.14|hello|ff|A|3.141590e+00|3.14159|-42|100%");
    EXPECT_EQ(gets("p"), "-42| 3.14|hello|ff|A|3.141590e+00|3.141");
    EXPECT_EQ(getd("p.LEN"), 51); // strlen + 1
    EXPECT_EQ(gets("p.SEVR"), "NO_ALARM");
    process("q");
    EXPECT_EQ(gets("dst"), "v=3.1"); // OUT gets VAL
}

TEST_F(RecordsMisc, PrintfShowsIvlsForAMissingLinkAndTheDirectiveForABadOne) {
    load(R"(
record(printf, "p") { field(FMT, "a=%d b=%d") field(INP0, "7") field(IVLS, "??") }
record(printf, "bad") { field(FMT, "x%qy") field(INP0, "1") }
record(printf, "star") { field(FMT, "[%*d]") field(INP0, "4") field(INP1, "9") }
record(printf, "trunc") { field(FMT, "0123456789abcdefghijklmnop") field(SIZV, "16") }
)");
    process("p");
    EXPECT_EQ(gets("p"), "a=7 b=??"); // INP1 is empty
    process("bad");
    EXPECT_EQ(gets("bad"), "x%qy");
    process("star");
    EXPECT_EQ(gets("star"), "[   9]"); // width from INP0
    process("trunc");
    EXPECT_EQ(gets("trunc"), "0123456789abcde"); // SIZV - 1 characters
    EXPECT_EQ(getd("trunc.LEN"), 16);
}

// base's printfTest.c: each format with the value it puts, and the string it expects.
TEST_F(RecordsMisc, PrintfFormatsAsBasesPrintfTest) {
    load(R"(
record(printf, "p") { field(SIZV, 45) field(INP0, "i0") field(INP1, "i1") field(INP2, "i2") field(INP3, "i3")
    field(INP4, "i4") field(INP5, "i5") field(INP6, "i6") field(INP7, "i7") field(INP8, "i8") field(INP9, "i9") }
record(ai, "i0") { field(FLNK, "p") }
record(stringin, "i1") { field(FLNK, "p") }
record(int64in, "i2") { field(FLNK, "p") }
record(ai, "i3") { field(FLNK, "p") } record(ai, "i4") { field(FLNK, "p") } record(ai, "i5") { field(FLNK, "p") }
record(ai, "i6") { field(FLNK, "p") } record(ai, "i7") { field(FLNK, "p") } record(ai, "i8") { field(FLNK, "p") }
record(ai, "i9") { field(FLNK, "p") }
)");
    struct Case {
        const char* fmt;
        double in0;
        const char* want;
    };
    const Case cases[] = {
        {"Format test string %%d", 1, "Format test string %d"},
        {"Format test string %d", 7, "Format test string 7"},
        {"Format test string %c", 82, "Format test string R"},
        {"Format test string %i", -27, "Format test string -27"},
        {"Format test string %o", 06777, "Format test string 6777"},
        {"Format test string %u", 8009, "Format test string 8009"},
        {"Format test string %x", 0xfafa, "Format test string fafa"},
        {"Format test string %X", 0xba, "Format test string BA"},
        {"Format test string %e", -14, "Format test string -1.400000e+01"},
        {"Format test string %E", 1992, "Format test string 1.992000E+03"},
        {"Format test string %f", -0.062, "Format test string -0.062000"},
        {"Format test string %F", 6729982.999, "Format test string 6729982.999000"},
        {"Format test string %g", -93e-3, "Format test string -0.093"},
        {"Format test string %G", 728839938, "Format test string 7.2884E+08"},
        {"Format test string %+d", 7, "Format test string +7"},
        {"Format test string %-10d", 18, "Format test string 18        "},
        {"Format test string % d", 12, "Format test string  12"},
        {"Format test string %#o", 12, "Format test string 014"},
        {"Format test string %04i", 3, "Format test string 0003"},
        {"Format test string %.4f", 71.2, "Format test string 71.2000"},
        {"Format test string %hx", 0xffbaba, "Format test string baba"},
        {"Format test string %hhx", 0xffc0c1, "Format test string c1"},
        {"Format test string %lx", 0x70a1c0c1, "Format test string 70a1c0c1"},
    };
    for (const Case& c : cases) {
        ASSERT_EQ(put_str("p.FMT", c.fmt), PutStatus::Ok);
        ASSERT_EQ(put("i0", c.in0), PutStatus::Ok);
        EXPECT_EQ(gets("p"), c.want) << c.fmt;
    }
    ASSERT_EQ(put_str("p.FMT", "%d %s %llx"), PutStatus::Ok);
    ASSERT_EQ(put("i0", 2), PutStatus::Ok);
    ASSERT_EQ(put_str("i1", "Reperbahn"), PutStatus::Ok);
    ASSERT_EQ(put_str("i2", "-5043731713933328191"), PutStatus::Ok); // 0xba0110baa0a1c0c1
    EXPECT_EQ(gets("i2"), "-5043731713933328191");
    EXPECT_EQ(gets("p"), "2 Reperbahn ba0110baa0a1c0c1");
    ASSERT_EQ(put_str("p.FMT", "%d %s %i %i %i %i %i %i %i %i"), PutStatus::Ok);
    ASSERT_EQ(put("i0", 0), PutStatus::Ok);
    ASSERT_EQ(put_str("i1", "One"), PutStatus::Ok);
    for (int k = 2; k <= 9; ++k) ASSERT_EQ(put(("i" + std::to_string(k)).c_str(), k), PutStatus::Ok);
    EXPECT_EQ(gets("p"), "0 One 2 3 4 5 6 7 8 9");
}
