// sub and aSub records with routines from a library (tests/unit/plugin/record_routines_plugin.c,
// loaded as `dlload` loads it): inputs, VAL, return-value alarms, INAM, array arguments and
// output links, and the errors for a routine no library provides.
#include "db_fixture.hpp"
#include "pv/sub_routines.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct RecordsSub : DbTest {
    void SetUp() override { RecordRoutines::global().load(BEAMCTL_TEST_ROUTINES); }
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

TEST_F(RecordsSub, SubCallsItsRoutineWithTheInputs) {
    load(R"(
record(ao, "x") { field(VAL, "2.5") }
record(sub, "s") { field(SNAM, "sub_sum") field(INPA, "x") field(INPB, "10") field(C, "1") field(HIGH, "20") field(HSV, "MINOR") }
)");
    EXPECT_EQ(getd("s.B"), 10); // a constant input is loaded at init
    process("s");
    EXPECT_EQ(getd("s"), 13.5);
    EXPECT_EQ(getd("s.A"), 2.5);
    EXPECT_EQ(getd("s.LA"), 2.5);
    EXPECT_EQ(gets("s.SEVR"), "NO_ALARM");
    ASSERT_EQ(put("x", 9), PutStatus::Ok);
    process("s");
    EXPECT_EQ(getd("s"), 20);
    EXPECT_EQ(gets("s.STAT"), "HIGH"); // VAL's limit alarms as subRecord's checkAlarms
    EXPECT_EQ(gets("s.SEVR"), "MINOR");
    ASSERT_EQ(put("s.C", 100), PutStatus::Ok); // A..L process the record
    EXPECT_EQ(getd("s"), 119);
}

TEST_F(RecordsSub, ANegativeReturnRaisesASoftAlarmOfBrsv) {
    load(R"(
record(sub, "s") { field(SNAM, "sub_fail") field(BRSV, "MAJOR") field(VAL, "0") }
record(sub, "u") { field(SNAM, "sub_fail") field(BRSV, "MAJOR") }
)");
    process("s");
    EXPECT_EQ(gets("s.STAT"), "SOFT");
    EXPECT_EQ(gets("s.SEVR"), "MAJOR");
    process("u");
    EXPECT_EQ(getd("u.UDF"), 1); // not cleared: the UDF alarm (INVALID) wins, as in subRecord
    EXPECT_EQ(gets("u.STAT"), "UDF");
}

TEST_F(RecordsSub, InamRunsOnceAtInitAndSharesUser) {
    load(R"(record(sub, "s") { field(INAM, "sub_init") field(SNAM, "sub_count") })");
    EXPECT_EQ(getd("s"), 7); // set by the init routine
    process("s");
    EXPECT_GE(getd("s"), 1); // the count seen through `user`
}

TEST_F(RecordsSub, SnamCanBeChangedToAnotherLoadedRoutineOnly) {
    load(R"(record(sub, "s") { field(SNAM, "sub_sum") field(A, "4") field(VAL, "0") field(BRSV, "MINOR") })");
    EXPECT_EQ(put_str("s.SNAM", "no_such_routine"), PutStatus::BadValue);
    EXPECT_EQ(gets("s.SNAM"), "sub_sum");
    EXPECT_EQ(put_str("s.SNAM", "asub_scale"), PutStatus::BadValue); // an aSub routine
    EXPECT_EQ(put_str("s.SNAM", "sub_fail"), PutStatus::Ok);
    process("s");
    EXPECT_EQ(gets("s.STAT"), "SOFT");
}

// As EPICS: the database loads, the error names record, routine and the libraries loaded, and only
// that record fails (BAD_SUB/INVALID when processed) while the others work.
TEST_F(RecordsSub, AnUnknownRoutineFailsOnlyItsRecordNamingRoutineAndLibraries) {
    load(R"(
record(sub, "bad") { field(SNAM, "nowhere") }
record(aSub, "bad2") { field(INAM, "sub_sum") }
record(sub, "good") { field(SNAM, "sub_sum") field(INPA, "2") field(INPB, "3") }
)");
    ASSERT_EQ(db.record_errors().size(), 2u);
    const std::string& e = db.record_errors()[0];
    EXPECT_NE(e.find("record bad: SNAM 'nowhere'"), std::string::npos) << e;
    EXPECT_NE(e.find("record_routines_plugin"), std::string::npos) << e; // what is loaded
    EXPECT_NE(e.find("sub_sum"), std::string::npos) << e;
    EXPECT_NE(db.record_errors()[1].find("record bad2: INAM 'sub_sum'"), std::string::npos) << db.record_errors()[1];
    process("bad");
    EXPECT_EQ(gets("bad.STAT"), "BAD_SUB");
    EXPECT_EQ(gets("bad.SEVR"), "INVALID");
    process("good");
    EXPECT_DOUBLE_EQ(getd("good"), 5);
    EXPECT_EQ(gets("good.SEVR"), "NO_ALARM");
}

TEST_F(RecordsSub, LoadingALibraryWithoutRoutinesFailsClearly) {
    try {
        RecordRoutines::global().load(BEAMCTL_TEST_PLUGIN); // a PLC plugin
        FAIL() << "loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("exports no beamctl_record_routines_get"), std::string::npos) << e.what();
    }
    EXPECT_THROW(RecordRoutines::global().load("/nonexistent/lib.so"), Error);
}

TEST_F(RecordsSub, ASubPassesArraysAndWritesItsOutputs) {
    load(R"(
record(waveform, "wf") { field(NELM, "5") }
record(waveform, "res") { field(NELM, "5") }
record(longin, "sum") { }
record(aSub, "a") {
    field(SNAM, "asub_scale")
    field(INPA, "wf") field(FTA, "DOUBLE") field(NOA, "5")
    field(INPB, "3")
    field(FTVA, "DOUBLE") field(NOVA, "5") field(OUTA, "res PP")
    field(FTVB, "LONG") field(OUTB, "sum PP")
}
)");
    EXPECT_EQ(getd("a.NOA"), 5);
    EXPECT_EQ(getd("a.B"), 3);
    ASSERT_EQ(put_array("wf", {1, 2, 3}), PutStatus::Ok);
    process("a");
    EXPECT_EQ(getd("a.NEA"), 3);
    EXPECT_EQ(get_array("a.VALA"), (V{3, 6, 9}));
    EXPECT_EQ(getd("a.NEVA"), 3);
    EXPECT_EQ(get_array("res"), (V{3, 6, 9})); // OUTA wrote NEVA elements
    EXPECT_EQ(getd("sum"), 6);
    EXPECT_EQ(getd("a"), 0); // VAL: the return value
    EXPECT_EQ(gets("a.SEVR"), "NO_ALARM");
}

TEST_F(RecordsSub, ASubReturnValuesAsEpics) {
    load(R"(
record(ao, "dst") { }
record(aSub, "f") { field(SNAM, "asub_fail") field(BRSV, "MINOR") field(OUTA, "dst") }
record(aSub, "k") { field(SNAM, "asub_skip") field(OUTA, "dst") }
record(aSub, "none") { }
)");
    process("f");
    EXPECT_EQ(getd("f"), -2);
    EXPECT_EQ(gets("f.STAT"), "SOFT");
    EXPECT_EQ(gets("f.SEVR"), "MINOR");
    process("k");
    EXPECT_EQ(getd("k"), 1);
    EXPECT_EQ(gets("k.SEVR"), "NO_ALARM");
    EXPECT_EQ(getd("dst"), 0); // a nonzero return writes no outputs
    process("none"); // no SNAM: nothing is called, no alarm
    EXPECT_EQ(gets("none.SEVR"), "NO_ALARM");
}

TEST_F(RecordsSub, ASubReadsItsRoutineNameThroughSublWithLflgRead) {
    load(R"(
record(stringout, "name") { field(VAL, "asub_fail") }
record(aSub, "a") { field(LFLG, "READ") field(SUBL, "name") }
)");
    process("a");
    EXPECT_EQ(gets("a.SNAM"), "asub_fail");
    EXPECT_EQ(gets("a.ONAM"), "asub_fail");
    EXPECT_EQ(getd("a"), -2);
    ASSERT_EQ(put_str("name", "asub_skip"), PutStatus::Ok);
    process("a");
    EXPECT_EQ(getd("a"), 1);
}

TEST_F(RecordsSub, ASubBadFtIsALoadError) {
    std::string e = load_error(R"(record(aSub, "x") { field(FTC, "ENUM") })");
    EXPECT_NE(e.find("record x: FTC ENUM is not supported for aSub"), std::string::npos) << e;
    load(R"(record(aSub, "u") { field(FTC, "UINT64") field(NOC, "2") })"); // 64-bit unsigned arrays load
    EXPECT_EQ(gets("u.FTC"), "UINT64");
}
