// The array record types (src/pv/records_arrays.cpp): aai, aao, subArray, compress, histogram —
// link reads and writes of arrays, NORD, windows, compression algorithms and counts, as base 7's
// record support and Soft Channel device support (and base's own record tests) show them.
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

struct RecordsArrays : DbTest {
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
    void process(const char* n) { db.process(*db.find(n)); }
    using V = std::vector<double>;
};

} // namespace

// ---------------------------------------------------------------- aai, aao

TEST_F(RecordsArrays, AaiReadsAnArrayThroughItsInputLink) {
    load(R"(
record(waveform, "wf") { field(NELM, "10") field(FTVL, "LONG") }
record(aai, "in") { field(INP, "wf") field(NELM, "4") field(FTVL, "DOUBLE") }
record(aai, "c") { field(INP, "[1, 2, 3]") field(NELM, "5") field(FTVL, "SHORT") }
record(aai, "one") { }
)");
    EXPECT_EQ(get_array("c"), (V{1, 2, 3})); // a constant array at init
    EXPECT_EQ(getd("c.NORD"), 3);
    EXPECT_EQ(getd("one.NORD"), 1); // NELM 1: NORD starts 1
    ASSERT_EQ(put_array("wf", {5, 6, 7, 8, 9, 10}), PutStatus::Ok);
    process("in");
    EXPECT_EQ(get_array("in"), (V{5, 6, 7, 8})); // at most NELM
    EXPECT_EQ(getd("in.NORD"), 4);
    EXPECT_EQ(gets("in.SEVR"), "NO_ALARM");
    ASSERT_EQ(put_array("wf", {1, 2}), PutStatus::Ok);
    process("in");
    EXPECT_EQ(get_array("in"), (V{1, 2}));
    EXPECT_EQ(getd("in.NORD"), 2);
}

TEST_F(RecordsArrays, AaiPostsOnChangeOnlyWhenTheHashChanges) {
    load(R"(
record(aai, "a") { field(NELM, "3") field(MPST, "On Change") }
)");
    Recorder rec;
    rec.addr = addr("a");
    rec.mask = kDbeValue;
    db.subscribe(rec);
    ASSERT_EQ(put_array("a", {1, 2, 3}), PutStatus::Ok); // processes: first value posts
    ASSERT_EQ(rec.masks.size(), 1u);
    ASSERT_EQ(put_array("a", {1, 2, 3}), PutStatus::Ok); // same elements: no post
    EXPECT_EQ(rec.masks.size(), 1u);
    ASSERT_EQ(put_array("a", {1, 2, 4}), PutStatus::Ok);
    EXPECT_EQ(rec.masks.size(), 2u);
    EXPECT_NE(getd("a.HASH"), 0);
    db.unsubscribe(rec);
}

TEST_F(RecordsArrays, AaoWritesItsArrayToTheOutputAndReadsDolInClosedLoop) {
    load(R"(
record(waveform, "dst") { field(NELM, "8") field(FTVL, "DOUBLE") }
record(aao, "out") { field(OUT, "dst PP") field(NELM, "4") field(FTVL, "LONG") }
record(waveform, "src") { field(NELM, "8") field(FTVL, "DOUBLE") }
record(aao, "cl") { field(DOL, "src") field(OMSL, "closed_loop") field(OUT, "dst") field(NELM, "3") }
)");
    ASSERT_EQ(put_array("out", {1.7, 2, 3}), PutStatus::Ok); // LONG elements: 1.7 -> 1
    EXPECT_EQ(get_array("out"), (V{1, 2, 3}));
    EXPECT_EQ(get_array("dst"), (V{1, 2, 3}));
    EXPECT_EQ(getd("dst.NORD"), 3);
    ASSERT_EQ(put_array("src", {9, 8, 7, 6, 5}), PutStatus::Ok);
    process("cl");
    EXPECT_EQ(get_array("cl"), (V{9, 8, 7})); // at most NELM from DOL
    EXPECT_EQ(get_array("dst"), (V{9, 8, 7}));
    EXPECT_EQ(gets("cl.SEVR"), "NO_ALARM");
}

TEST_F(RecordsArrays, StringArraysTravelThroughLinks) {
    load(R"(
record(aao, "s") { field(FTVL, "STRING") field(NELM, "3") field(OUT, "t PP") }
record(aai, "t") { field(FTVL, "STRING") field(NELM, "3") }
)");
    char buf[2][40] = {"alpha", "beta"};
    ASSERT_EQ(db.put(addr("s"), Prim::String, buf, 2), PutStatus::Ok);
    char got[3][40] = {};
    EXPECT_EQ(db.get(addr("t"), Prim::String, got, 3), 2u);
    EXPECT_STREQ(got[0], "alpha");
    EXPECT_STREQ(got[1], "beta");
}

TEST_F(RecordsArrays, BadFtvlOrNelmIsAClearLoadError) {
    std::string e = load_error(R"(record(aai, "x") { field(FTVL, "ENUM") })");
    EXPECT_NE(e.find("record x"), std::string::npos) << e;
    EXPECT_NE(e.find("FTVL ENUM is not supported for aai"), std::string::npos) << e;
    e = load_error(R"(record(aao, "y") { field(NELM, "0") })");
    EXPECT_NE(e.find("record y: NELM is 0"), std::string::npos) << e;
    e = load_error(R"(record(subArray, "z") { field(MALM, "0") })");
    EXPECT_NE(e.find("record z: MALM is 0"), std::string::npos) << e;
    e = load_error(R"(record(compress, "w") { field(NSAM, "100000000") })");
    EXPECT_NE(e.find("NSAM 100000000 is too large"), std::string::npos) << e;
}

// ---------------------------------------------------------------- subArray

TEST_F(RecordsArrays, SubArrayReadsAWindowOfAnotherArray) {
    load(R"(
record(waveform, "wf") { field(NELM, "10") field(FTVL, "DOUBLE") }
record(subArray, "sa") { field(INP, "wf") field(MALM, "10") field(NELM, "3") field(INDX, "2") field(FTVL, "LONG") }
)");
    ASSERT_EQ(put_array("wf", {0, 1, 2, 3, 4, 5, 6}), PutStatus::Ok);
    process("sa");
    EXPECT_EQ(get_array("sa"), (V{2, 3, 4}));
    EXPECT_EQ(getd("sa.NORD"), 3);
    EXPECT_EQ(gets("sa.SEVR"), "NO_ALARM");
    ASSERT_EQ(put("sa.INDX", 5), PutStatus::Ok); // pp: processes
    EXPECT_EQ(get_array("sa"), (V{5, 6}));       // only two left from index 5
    EXPECT_EQ(getd("sa.NORD"), 2);
    ASSERT_EQ(put("sa.NELM", 1), PutStatus::Ok);
    EXPECT_EQ(get_array("sa"), (V{5}));
    ASSERT_EQ(put("sa.INDX", 8), PutStatus::Ok); // beyond the source's elements: none, UDF
    EXPECT_EQ(getd("sa.NORD"), 0);
    EXPECT_EQ(gets("sa.STAT"), "UDF");
    EXPECT_EQ(gets("sa.SEVR"), "INVALID");
    ASSERT_EQ(put("sa.INDX", 20), PutStatus::Ok); // clamped to MALM-1
    EXPECT_EQ(getd("sa.INDX"), 9);
}

TEST_F(RecordsArrays, SubArrayNelmIsAtMostMalm) {
    load(R"(
record(subArray, "sa") { field(INP, "[1, 2, 3, 4, 5, 6]") field(MALM, "4") field(NELM, "10") }
)");
    EXPECT_EQ(getd("sa.NELM"), 4);
    EXPECT_EQ(get_array("sa"), (V{1, 2, 3, 4})); // the constant, windowed at init
}

// ---------------------------------------------------------------- compress

TEST_F(RecordsArrays, CompressCircularBufferFifoAndLifo) {
    load(R"(
record(ao, "x") { }
record(compress, "fifo") { field(INP, "x") field(ALG, "Circular Buffer") field(NSAM, "3") }
record(compress, "lifo") { field(INP, "x") field(ALG, "Circular Buffer") field(NSAM, "3") field(BALG, "LIFO Buffer") }
)");
    for (double v : {1.0, 2.0, 3.0, 4.0}) {
        put("x", v);
        process("fifo");
        process("lifo");
    }
    EXPECT_EQ(get_array("fifo"), (V{2, 3, 4})); // oldest first, the first dropped
    EXPECT_EQ(get_array("lifo"), (V{4, 3, 2})); // newest first
    EXPECT_EQ(getd("fifo.NUSE"), 3);
    ASSERT_EQ(put("fifo.RES", 1), PutStatus::Ok); // reset
    EXPECT_EQ(getd("fifo.NUSE"), 0);
    EXPECT_EQ(get_array("fifo").size(), 0u);
}

TEST_F(RecordsArrays, CompressNTo1OfScalarsAndArrays) {
    load(R"(
record(ao, "x") { }
record(compress, "lo") { field(INP, "x") field(ALG, "N to 1 Low Value") field(N, "3") field(NSAM, "4") }
record(compress, "hi") { field(INP, "x") field(ALG, "N to 1 High Value") field(N, "3") field(NSAM, "4") }
record(compress, "avg") { field(INP, "x") field(ALG, "N to 1 Average") field(N, "3") field(NSAM, "4") }
record(waveform, "wf") { field(NELM, "7") }
record(compress, "med") { field(INP, "wf") field(ALG, "N to 1 Median") field(N, "3") field(NSAM, "4") }
record(compress, "amax") { field(INP, "wf") field(ALG, "N to 1 High Value") field(N, "3") field(NSAM, "4") field(PBUF, "YES") }
record(compress, "aavg") { field(INP, "wf") field(ALG, "Average") field(N, "2") field(NSAM, "3") }
)");
    for (double v : {5.0, 1.0, 3.0}) {
        put("x", v);
        process("lo");
        process("hi");
        process("avg");
        if (v != 3) EXPECT_EQ(getd("lo.NUSE"), 0); // nothing until N values
    }
    EXPECT_EQ(get_array("lo"), (V{1}));
    EXPECT_EQ(get_array("hi"), (V{5}));
    EXPECT_EQ(get_array("avg"), (V{3}));
    EXPECT_EQ(gets("lo.SEVR"), "NO_ALARM");
    ASSERT_EQ(put_array("wf", {9, 1, 5, 2, 8, 7, 4}), PutStatus::Ok);
    process("med");
    process("amax");
    // base 7.0.8's compress_array: an array of at least N elements becomes one sample of the
    // whole array (it sets n to the element count; bench/conformance_db.py compares it with softIoc)
    EXPECT_EQ(get_array("med"), (V{5}));  // the median of 9 1 5 2 8 7 4
    EXPECT_EQ(get_array("amax"), (V{9}));
    ASSERT_EQ(put_array("wf", {6, 2}), PutStatus::Ok); // fewer than N: nothing, unless PBUF
    process("med");
    process("amax");
    EXPECT_EQ(get_array("med"), (V{5}));
    EXPECT_EQ(get_array("amax"), (V{9, 6}));
    ASSERT_EQ(put_array("wf", {9, 1, 5, 2, 8, 7, 4}), PutStatus::Ok);
    process("aavg");
    EXPECT_EQ(getd("aavg.NUSE"), 0); // one of N=2 arrays
    ASSERT_EQ(put_array("wf", {1, 3, 5}), PutStatus::Ok);
    process("aavg");
    EXPECT_EQ(get_array("aavg"), (V{5, 2, 5})); // element-wise mean of the first NSAM elements
}

TEST_F(RecordsArrays, CompressWithoutAnInputRaisesALinkAlarm) {
    load(R"(record(compress, "c") { field(NSAM, "2") })");
    process("c");
    EXPECT_EQ(gets("c.STAT"), "LINK");
    EXPECT_EQ(gets("c.SEVR"), "INVALID");
}

// ---------------------------------------------------------------- histogram

TEST_F(RecordsArrays, HistogramCountsSignalsInBins) {
    load(R"(
record(ao, "s") { }
record(histogram, "h") { field(SVL, "s") field(NELM, "4") field(LLIM, "0") field(ULIM, "8") }
)");
    EXPECT_EQ(getd("h.WDTH"), 2);
    for (double v : {0.5, 1.0, 2.0, 2.5, 7.9, 8.0, -1.0}) { // 8 and -1 are outside [LLIM, ULIM)
        put("s", v);
        process("h");
    }
    EXPECT_EQ(get_array("h"), (V{3, 1, 0, 1})); // a value on a bin's upper edge counts in it
    ASSERT_EQ(put("h.SGNL", 5), PutStatus::Ok);   // a put to SGNL counts it
    EXPECT_EQ(get_array("h"), (V{3, 1, 1, 1}));
    ASSERT_EQ(put_str("h.CMD", "Stop"), PutStatus::Ok);
    EXPECT_EQ(getd("h.CSTA"), 0);
    put("s", 1);
    process("h");
    EXPECT_EQ(get_array("h"), (V{3, 1, 1, 1})); // stopped: not counted
    ASSERT_EQ(put_str("h.CMD", "Start"), PutStatus::Ok);
    ASSERT_EQ(put_str("h.CMD", "Clear"), PutStatus::Ok);
    EXPECT_EQ(get_array("h"), (V{0, 0, 0, 0}));
    EXPECT_EQ(gets("h.CMD"), "Read");
    ASSERT_EQ(put("h.ULIM", 4), PutStatus::Ok); // new limits: new width, cleared
    EXPECT_EQ(getd("h.WDTH"), 1);
}

TEST_F(RecordsArrays, HistogramPostsAfterMoreThanMdelCounts) {
    load(R"(
record(ao, "s") { field(VAL, "1") }
record(histogram, "h") { field(SVL, "s") field(NELM, "2") field(ULIM, "2") field(MDEL, "2") }
)");
    Recorder rec;
    rec.addr = addr("h");
    rec.mask = kDbeValue;
    db.subscribe(rec);
    process("h");
    process("h");
    EXPECT_EQ(rec.masks.size(), 0u); // 2 counts: not more than MDEL
    process("h");
    EXPECT_EQ(rec.masks.size(), 1u);
    db.unsubscribe(rec);
}

TEST_F(RecordsArrays, HistogramSimulationReadsSiol) {
    load(R"(
record(ao, "sim") { field(VAL, "3.5") }
record(histogram, "h") { field(SIOL, "sim") field(SIMM, "YES") field(SIMS, "MINOR") field(NELM, "4") field(ULIM, "4") }
)");
    process("h");
    EXPECT_EQ(get_array("h"), (V{0, 0, 0, 1}));
    EXPECT_EQ(getd("h.SGNL"), 3.5);
    EXPECT_EQ(gets("h.STAT"), "SIMM");
    EXPECT_EQ(gets("h.SEVR"), "MINOR");
}

TEST_F(RecordsArrays, HistogramWatchdogPostsCountsEverySdel) {
    double now = 0;
    db.set_clock([&] { return now; });
    load(R"(
record(ao, "s") { field(VAL, "1") }
record(histogram, "h") { field(SVL, "s") field(NELM, "2") field(ULIM, "2") field(MDEL, "5") field(SDEL, "1") }
)");
    Recorder rec;
    rec.addr = addr("h");
    rec.mask = kDbeValue;
    db.subscribe(rec);
    process("h");
    EXPECT_EQ(rec.masks.size(), 0u);
    now = 1.1;
    db.scan_periodic(now);
    EXPECT_EQ(rec.masks.size(), 1u); // the watchdog posts the count
    now = 2.2;
    db.scan_periodic(now);
    EXPECT_EQ(rec.masks.size(), 1u); // nothing new: nothing posted
    db.unsubscribe(rec);
}

// ---------------------------------------------------------------- base's compressTest.c, ported

namespace {
struct CompressBase : RecordsArrays {
    void setup(const char* alg, const char* balg, int nsam, int n, bool pbuf = false) {
        std::string db = R"(
record(ai, "ai") {}
record(waveform, "wf") { field(FTVL, "DOUBLE") field(NELM, "4") }
record(compress, "comp") { field(INP, ")" + std::string(std::strcmp(alg, "Circular Buffer") == 0 ? "ai" : "wf") +
                         R"( NPP") field(ALG, ")" + alg + R"(") field(BALG, ")" + balg + R"(") field(NSAM, ")" +
                         std::to_string(nsam) + R"(") field(N, ")" + std::to_string(n) + R"(") field(PBUF, ")" +
                         (pbuf ? "YES" : "NO") + "\") }\n";
        load(db.c_str());
    }
    void push(double v) {
        put("ai", v);
        process("comp");
    }
    void wf(V v) {
        ASSERT_EQ(put_array("wf", v), PutStatus::Ok);
        process("comp");
    }
    void state(double off, double inx, double nuse) {
        EXPECT_EQ(getd("comp.OFF"), off);
        EXPECT_EQ(getd("comp.INX"), inx);
        EXPECT_EQ(getd("comp.NUSE"), nuse);
    }
};
} // namespace

TEST_F(CompressBase, FifoCircularBufferAsBase) {
    setup("Circular Buffer", "FIFO Buffer", 4, 1);
    state(0, 0, 0);
    push(1.1);
    state(1, 0, 1);
    EXPECT_EQ(get_array("comp"), (V{1.1}));
    push(2.1);
    push(3.1);
    push(4.1);
    state(0, 0, 4);
    EXPECT_EQ(get_array("comp"), (V{1.1, 2.1, 3.1, 4.1}));
    push(5.1);
    state(1, 0, 4);
    push(6.1);
    state(2, 0, 4);
    EXPECT_EQ(get_array("comp"), (V{3.1, 4.1, 5.1, 6.1}));
    ASSERT_EQ(put("comp.RES", 0), PutStatus::Ok);
    state(0, 0, 0);
    EXPECT_EQ(get_array("comp").size(), 0u);
}

TEST_F(CompressBase, LifoCircularBufferAsBase) {
    setup("Circular Buffer", "LIFO Buffer", 4, 1);
    push(1.1);
    state(3, 0, 1);
    push(2.1);
    state(2, 0, 2);
    EXPECT_EQ(get_array("comp"), (V{2.1, 1.1}));
    push(3.1);
    push(4.1);
    state(0, 0, 4);
    push(5.1);
    state(3, 0, 4);
    push(6.1);
    state(2, 0, 4);
    EXPECT_EQ(get_array("comp"), (V{6.1, 5.1, 4.1, 3.1}));
}

TEST_F(CompressBase, ArrayAverageAsBase) {
    setup("Average", "FIFO Buffer", 4, 2);
    wf({1, 2, 3, 4});
    wf({2, 4, 6, 8});
    EXPECT_EQ(get_array("comp"), (V{1.5, 3, 4.5, 6}));
}

TEST_F(CompressBase, NTo1AverageAsBase) {
    setup("N to 1 Average", "FIFO Buffer", 1, 4);
    wf({1, 2, 3}); // incomplete: nothing
    EXPECT_EQ(get_array("comp").size(), 0u);
    wf({1, 2, 3, 4});
    EXPECT_EQ(get_array("comp"), (V{2.5}));
    wf({5}); // a single value: one of the next N scalars, nothing yet
    EXPECT_EQ(get_array("comp"), (V{2.5}));
}

// base 7.0.8 compresses an array of at least N elements whole into one sample (its
// compress_array sets n to the element count): softIoc 7.0.8 gives 2.5 here, not 1.5 and 3.5
// (bench/conformance_db.py's cf:cmpwf compares it)
TEST_F(CompressBase, NTo2AverageOfAnArrayIsOneSampleAsBase) {
    setup("N to 1 Average", "FIFO Buffer", 2, 2);
    wf({1, 2, 3, 4});
    EXPECT_EQ(get_array("comp"), (V{2.5}));
}

TEST_F(CompressBase, NTo1AveragePartialAsBase) {
    setup("N to 1 Average", "FIFO Buffer", 1, 4, true);
    wf({1, 2, 3});
    EXPECT_EQ(get_array("comp"), (V{2}));
    wf({6});
    EXPECT_EQ(get_array("comp"), (V{6}));
}
