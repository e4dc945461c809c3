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
    std::string get_chars(const char* n) {
        Address a = addr(n);
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
