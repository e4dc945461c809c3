// Record semantics: alarms with hysteresis, deadbands, clamping, enum rules, UDF, property
// posts, put-callback ordering, .db load errors and export.
#include "pv/database.hpp"
#include "db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <sstream>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct Recorder : Subscription {
    std::vector<unsigned> masks;
    void on_event(unsigned m) override { masks.push_back(m); }
};

struct Fixture : DbTest {};

} // namespace

TEST_F(Fixture, NeverProcessedRecordIsUdfInvalid) {
    load(R"(record(ai, "a") {})");
    EXPECT_EQ(gets("a.SEVR"), "INVALID");
    EXPECT_EQ(gets("a.STAT"), "UDF");
    ASSERT_EQ(put("a", 1.0), PutStatus::Ok);
    EXPECT_EQ(gets("a.SEVR"), "NO_ALARM");
    EXPECT_EQ(getd("a.UDF"), 0);
}

TEST_F(Fixture, PiniProcessesAtInit) {
    load(R"(record(ai, "a") { field(VAL, "3") field(PINI, "YES") })");
    EXPECT_EQ(gets("a.SEVR"), "NO_ALARM");
    EXPECT_EQ(getd("a"), 3.0);
}

TEST_F(Fixture, AnalogAlarmsWithHysteresis) {
    load(R"(record(ai, "a") { field(HIHI, "10") field(HHSV, "MAJOR") field(HIGH, "5")
             field(HSV, "MINOR") field(LOLO, "-10") field(LLSV, "INVALID") field(HYST, "1") })");
    put("a", 4);
    EXPECT_EQ(gets("a.SEVR"), "NO_ALARM");
    put("a", 5);
    EXPECT_EQ(gets("a.SEVR"), "MINOR");
    EXPECT_EQ(gets("a.STAT"), "HIGH");
    put("a", 10.5);
    EXPECT_EQ(gets("a.SEVR"), "MAJOR");
    EXPECT_EQ(gets("a.STAT"), "HIHI");
    put("a", 9.5); // inside the hysteresis band of HIHI: stays MAJOR
    EXPECT_EQ(gets("a.SEVR"), "MAJOR");
    put("a", 8.9); // below HIHI - HYST: back to HIGH
    EXPECT_EQ(gets("a.SEVR"), "MINOR");
    put("a", -10);
    EXPECT_EQ(gets("a.SEVR"), "INVALID");
    EXPECT_EQ(gets("a.STAT"), "LOLO");
}

TEST_F(Fixture, DeadbandsFilterValueAndArchiveEvents) {
    load(R"(record(ai, "a") { field(MDEL, "0.5") field(ADEL, "2") field(VAL, "0") field(PINI, "YES") })");
    Recorder r;
    r.addr = addr("a");
    r.mask = kDbeValue | kDbeLog | kDbeAlarm;
    db.subscribe(r);
    put("a", 0.4); // |0.4 - 0| < MDEL
    put("a", 0.6); // > MDEL: VALUE, not LOG
    put("a", 3.0); // > both
    put("a", 3.0); // no change: nothing
    db.unsubscribe(r);
    ASSERT_EQ(r.masks.size(), 2u);
    EXPECT_EQ(r.masks[0], unsigned(kDbeValue));
    EXPECT_EQ(r.masks[1], unsigned(kDbeValue | kDbeLog));
}

TEST_F(Fixture, NegativeMdelPostsEveryProcess) {
    load(R"(record(ai, "a") { field(MDEL, "-1") field(PINI, "YES") })");
    Recorder r;
    r.addr = addr("a");
    r.mask = kDbeValue;
    db.subscribe(r);
    put("a", 0);
    put("a", 0);
    db.unsubscribe(r);
    EXPECT_EQ(r.masks.size(), 2u);
}

TEST_F(Fixture, AlarmChangePostsAlarmMaskOnValue) {
    load(R"(record(ai, "a") { field(HIGH, "5") field(HSV, "MINOR") field(VAL, "0") field(PINI, "YES") })");
    Recorder r;
    r.addr = addr("a");
    r.mask = kDbeAlarm;
    db.subscribe(r);
    put("a", 1); // value change only
    put("a", 6); // alarm raised
    put("a", 7); // same alarm
    put("a", 1); // alarm cleared
    db.unsubscribe(r);
    EXPECT_EQ(r.masks, (std::vector<unsigned>{kDbeAlarm, kDbeAlarm}));
}

TEST_F(Fixture, AoClampsToDrvlDrvh) {
    load(R"(record(ao, "o") { field(DRVH, "10") field(DRVL, "-2") })");
    put("o", 50);
    EXPECT_EQ(getd("o"), 10.0);
    EXPECT_EQ(getd("o.OVAL"), 10.0);
    put("o", -50);
    EXPECT_EQ(getd("o"), -2.0);
}

TEST_F(Fixture, LongoutClampsAndLonginDeadband) {
    load(R"(record(longout, "l") { field(DRVH, "100") field(DRVL, "0") })");
    put("l", 1000);
    EXPECT_EQ(getd("l"), 100.0);
}

TEST_F(Fixture, MetadataChangePostsProperty) {
    load(R"(record(ai, "a") { field(PINI, "YES") })");
    Recorder r;
    r.addr = addr("a");
    r.mask = kDbeProperty;
    db.subscribe(r);
    put_str("a.EGU", "mm");
    put("a.HOPR", 5);
    put_str("a.DESC", "not metadata");
    db.unsubscribe(r);
    EXPECT_EQ(r.masks.size(), 2u);
}

TEST_F(Fixture, EnumsByStringAndIndex) {
    load(R"(record(mbbo, "m") { field(ZRST, "Off") field(ONST, "Slow") field(TWST, "Fast") }
            record(bo, "b") { field(ZNAM, "Closed") field(ONAM, "Open") })");
    EXPECT_EQ(put_str("m", "Fast"), PutStatus::Ok);
    EXPECT_EQ(getd("m"), 2.0);
    EXPECT_EQ(put_str("m", "1"), PutStatus::Ok);
    EXPECT_EQ(gets("m"), "Slow");
    EXPECT_EQ(put_str("m", "Warp"), PutStatus::BadValue);
    EXPECT_EQ(gets("m"), "Slow"); // unchanged
    EXPECT_EQ(put("m", 16), PutStatus::BadValue);
    EXPECT_EQ(put_str("b", "Open"), PutStatus::Ok);
    EXPECT_EQ(getd("b"), 1.0);
    EXPECT_EQ(put("b", 2), PutStatus::BadValue);
    EXPECT_EQ(getd("b"), 1.0);
}

TEST_F(Fixture, MenuFieldsTakeOnlyTheirChoices) {
    // A number put to a menu field must index a choice (EPICS refuses only out-of-range strings;
    // we refuse numbers too: ao.OMSL 7 would otherwise read back as "Illegal_Value" and act).
    load(R"(record(ao, "o") { field(OMSL, "closed_loop") })");
    EXPECT_EQ(put("o.OMSL", 0), PutStatus::Ok);
    EXPECT_EQ(gets("o.OMSL"), "supervisory");
    EXPECT_EQ(put("o.OMSL", 7), PutStatus::BadValue);
    EXPECT_EQ(put("o.OMSL", -1), PutStatus::BadValue);
    EXPECT_EQ(put("o.OMSL", 2), PutStatus::BadValue);
    EXPECT_EQ(gets("o.OMSL"), "supervisory"); // unchanged
    EXPECT_EQ(put("o.OMSL", 1), PutStatus::Ok);
    EXPECT_EQ(gets("o.OMSL"), "closed_loop");
    EXPECT_EQ(put("o.HHSV", 3), PutStatus::Ok); // INVALID, the last of menuAlarmSevr
    EXPECT_EQ(put("o.HHSV", 4), PutStatus::BadValue);
    EXPECT_EQ(gets("o.HHSV"), "INVALID");
    EXPECT_EQ(put_str("o.HHSV", "4"), PutStatus::BadValue);
}

TEST_F(Fixture, StateAlarmsAndChangeOfState) {
    load(R"(record(bi, "b") { field(ZSV, "MAJOR") field(COSV, "MINOR") field(VAL, "0") field(PINI, "YES") })");
    EXPECT_EQ(gets("b.SEVR"), "MAJOR");
    put("b", 1);
    EXPECT_EQ(gets("b.SEVR"), "MINOR"); // change of state
    EXPECT_EQ(gets("b.STAT"), "COS");
    put("b", 1);
    EXPECT_EQ(gets("b.SEVR"), "NO_ALARM");
}

TEST_F(Fixture, StringToNumberConversionErrorsChangeNothing) {
    load(R"(record(ao, "o") { field(VAL, "1") })");
    EXPECT_EQ(put_str("o", "12.5"), PutStatus::Ok);
    EXPECT_EQ(getd("o"), 12.5);
    EXPECT_EQ(put_str("o", "twelve"), PutStatus::BadValue);
    EXPECT_EQ(getd("o"), 12.5);
}

TEST_F(Fixture, ReadOnlyFieldsRefusePuts) {
    load(R"(record(ai, "a") {})");
    EXPECT_EQ(put_str("a.NAME", "x"), PutStatus::ReadOnly);
    EXPECT_EQ(put("a.SEVR", 1), PutStatus::ReadOnly);
}

TEST_F(Fixture, LongStringAndRtyp) {
    load(R"(record(stringout, "a_rather_long_record_name_that_is_more_than_forty_chars") {})");
    Address a = addr("a_rather_long_record_name_that_is_more_than_forty_chars.NAME$");
    EXPECT_EQ(a.native, Prim::Char);
    EXPECT_EQ(a.count, 61u);
    char buf[61];
    db.get(a, Prim::Char, buf, 61);
    EXPECT_STREQ(buf, "a_rather_long_record_name_that_is_more_than_forty_chars");
    Address t = addr("a_rather_long_record_name_that_is_more_than_forty_chars.RTYP");
    char s[40];
    db.get(t, Prim::String, s, 1);
    EXPECT_STREQ(s, "stringout");
}

TEST_F(Fixture, WaveformPutSetsNord) {
    load(R"(record(waveform, "w") { field(FTVL, "FLOAT") field(NELM, "5") })");
    Address a = addr("w");
    EXPECT_EQ(a.count, 5u);
    EXPECT_EQ(db.current_count(a), 0u);
    double v[7] = {1, 2, 3, 4, 5, 6, 7};
    EXPECT_EQ(db.put(a, Prim::Double, v, 7), PutStatus::Ok); // truncated to NELM
    EXPECT_EQ(db.current_count(a), 5u);
    EXPECT_EQ(getd("w.NORD"), 5.0);
}

TEST_F(Fixture, UnknownFieldsAndTypesAreLoadErrors) {
    try {
        db.load(parse_db("record(ai, \"a\") {\n  field(BOGUS, \"1\")\n}\n", "x.db", {}));
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("x.db:2:9"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("BOGUS"), std::string::npos);
    }
    try {
        db.load(parse_db("record(bogus, \"c\") {}\n", "y.db", {}));
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("y.db:1:1"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("bogus"), std::string::npos);
    }
    EXPECT_THROW(db.load(parse_db("record(ai, \"a\") { field(PREC, \"x\") }", "z.db", {})), Error);
    EXPECT_THROW(db.load(parse_db("record(ai, \"a\") { field(HHSV, \"LOUD\") }", "z.db", {})), Error);
    EXPECT_EQ(db.size(), 0u); // nothing from failed files
}

TEST_F(Fixture, ExportRoundTrips) {
    load(R"(record(ao, "o") { field(DESC, "x \"q\"") field(DRVH, "0.1") field(VAL, "2") }
            record(mbbi, "m") { field(ZRST, "A") field(ZRSV, "MINOR") alias("m2") })");
    std::ostringstream os;
    db.write_db(os);
    Database db2;
    db2.load(parse_db(os.str(), "export.db", {}));
    db2.init_records();
    std::ostringstream os2;
    db2.write_db(os2);
    EXPECT_EQ(os.str(), os2.str());
    EXPECT_NE(os.str().find("field(DRVH, \"0.1\")"), std::string::npos) << os.str();
    EXPECT_NE(db2.find("m2"), nullptr);
}

// An asynchronous record: process() starts an action that completes later.
namespace {
struct SlowRecord : Record {
    using Record::Record;
    double val = 0;
    int started = 0;
    static std::vector<FieldDesc> fields() {
        auto v = common_fields();
        v.push_back(BEAMCTL_FIELD(SlowRecord, VAL, val, Double, kProcess | kAsl0));
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        ++started;
        return ProcessResult::Async;
    }
};
} // namespace

TEST_F(Fixture, PutCallbacksCompleteWhenTheActionEndsInArrivalOrder) {
    RecordTypes types;
    types.add(std::make_unique<RecordType>("slow", SlowRecord::fields(), [](const RecordType& t) {
        return std::unique_ptr<Record>(new SlowRecord(t));
    }));
    db.load(parse_db(R"(record(slow, "s") {})", "s.db", {}), types);
    db.init_records();
    auto* rec = static_cast<SlowRecord*>(db.find("s"));
    std::vector<std::string> log;
    put("s", 1, [&](PutStatus st) { log.push_back("a" + std::to_string(int(st))); });
    put("s", 2, [&](PutStatus st) { log.push_back("b" + std::to_string(int(st))); });
    EXPECT_TRUE(log.empty());
    EXPECT_EQ(rec->val, 1.0); // the second put waits behind the first
    EXPECT_EQ(rec->started, 1);
    rec->async_done();
    EXPECT_EQ(log, (std::vector<std::string>{"a0"}));
    EXPECT_EQ(rec->val, 2.0);
    EXPECT_EQ(rec->started, 2);
    rec->async_done();
    EXPECT_EQ(log, (std::vector<std::string>{"a0", "b0"}));
}

TEST_F(Fixture, RemovingARecordFailsPendingCallbacks) {
    RecordTypes types;
    types.add(std::make_unique<RecordType>("slow", SlowRecord::fields(), [](const RecordType& t) {
        return std::unique_ptr<Record>(new SlowRecord(t));
    }));
    db.load(parse_db(R"(record(slow, "s") {})", "s.db", {}), types);
    db.init_records();
    PutStatus got = PutStatus::Ok;
    put("s", 1, [&](PutStatus st) { got = st; });
    db.remove("s");
    EXPECT_EQ(got, PutStatus::Disconnected);
    EXPECT_EQ(db.find("s"), nullptr);
}

TEST_F(Fixture, PeriodicScanProcesses) {
    load(R"(record(ai, "a") { field(SCAN, ".1 second") })");
    EXPECT_EQ(gets("a.SEVR"), "INVALID");
    db.scan_periodic(100.0);
    EXPECT_EQ(gets("a.SEVR"), "NO_ALARM"); // processed: a soft ai defines its VAL (aiRecord)
    Record* r = db.find("a");
    EXPECT_NE(r->time.sec, 0u);
}
