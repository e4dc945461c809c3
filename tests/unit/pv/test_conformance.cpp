// Fields of EPICS base's records that real databases set (issue 41): conversion of ai/ao (LINR,
// ESLO/EOFF, ASLO/AOFF, ROFF, RVAL), Raw Soft Channel, simulation mode (SIMM, SIML, SIOL, SIMS,
// SDLY, SSCN), the alarm filter (AFTC), bo HIGH, longout OOPT/OOCH, AMSG, the soft INST_IO device
// supports (Soft Timestamp, getenv) and the refusals base makes (DBF_NOACCESS, DTYP choices).
// Expected values are base 7.0.8's record support worked by hand. Time is virtual: scan_periodic.
#include "db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <ctime>
#include <string>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct Conformance : DbTest {
    double now = 100;
    void start_clock() { db.scan_periodic(now); }
    void advance(double seconds) {
        for (double end = now + seconds; now < end - 1e-9;) db.scan_periodic(now += 0.01);
    }
    void process(const char* rec) { put((std::string(rec) + ".PROC").c_str(), 1); }
};

} // namespace

// ---------------------------------------------------------------- conversion

TEST_F(Conformance, AiRawSoftChannelConvertsRvalThroughRoffAsloAoffAndSlope) {
    load(R"(
record(longout, "raw") { field(VAL, "100") }
record(ai, "slope") { field(DTYP, "Raw Soft Channel") field(INP, "raw") field(LINR, "SLOPE")
    field(ROFF, "4") field(ASLO, "2") field(AOFF, "1") field(ESLO, "0.5") field(EOFF, "3") }
record(ai, "none") { field(DTYP, "Raw Soft Channel") field(INP, "raw") field(ASLO, "2") field(AOFF, "1") }
record(ai, "linear") { field(DTYP, "Raw Soft Channel") field(INP, "raw") field(LINR, "LINEAR")
    field(EGUL, "-10") field(EGUF, "10") }
)");
    process("slope");
    process("none");
    process("linear");
    EXPECT_DOUBLE_EQ(getd("slope.RVAL"), 100);
    EXPECT_DOUBLE_EQ(getd("slope"), ((100 + 4) * 2 + 1) * 0.5 + 3); // 107.5
    EXPECT_DOUBLE_EQ(getd("none"), 201);                           // NO CONVERSION: ASLO/AOFF only
    // LINEAR with ESLO 1 and EOFF 0 (no device support that sets them): EOFF takes EGUL
    EXPECT_DOUBLE_EQ(getd("linear.EOFF"), -10);
    EXPECT_DOUBLE_EQ(getd("linear"), 100 - 10);
    EXPECT_EQ(gets("slope.SEVR"), "NO_ALARM");
}

TEST_F(Conformance, AiSoftChannelReadsValAndDoesNotConvert) {
    load(R"(
record(ao, "src") { field(VAL, "2.5") }
record(ai, "in") { field(INP, "src") field(LINR, "SLOPE") field(ESLO, "10") field(EOFF, "1") }
)");
    process("in");
    EXPECT_DOUBLE_EQ(getd("in"), 2.5); // devAiSoft returns "don't convert"
}

TEST_F(Conformance, AoConvertsOvalToRvalAndRawSoftChannelWritesIt) {
    load(R"(
record(longin, "dst") {}
record(ao, "out") { field(DTYP, "Raw Soft Channel") field(OUT, "dst PP") field(LINR, "SLOPE")
    field(ESLO, "0.5") field(EOFF, "1") field(AOFF, "2") field(ASLO, "4") field(ROFF, "3") }
record(ao, "soft") { field(LINR, "SLOPE") field(ESLO, "0.25") }
)");
    put("out", 10);
    // ((10 - EOFF) / ESLO - AOFF) / ASLO - ROFF = ((9 / 0.5) - 2) / 4 - 3 = 1, rounded
    EXPECT_DOUBLE_EQ(getd("out.OVAL"), 10);
    EXPECT_DOUBLE_EQ(getd("out.RVAL"), 1);
    EXPECT_DOUBLE_EQ(getd("dst"), 1);
    put("soft", -1.3);
    EXPECT_DOUBLE_EQ(getd("soft.RVAL"), -5); // -1.3 / 0.25 = -5.2, rounded to -5
}

TEST_F(Conformance, AoOutputRateOfChangeLimitsEachStep) {
    load(R"(record(ao, "ramp") { field(OROC, "2") })");
    put("ramp", 5);
    EXPECT_DOUBLE_EQ(getd("ramp"), 5);
    EXPECT_DOUBLE_EQ(getd("ramp.OVAL"), 2);
    EXPECT_DOUBLE_EQ(getd("ramp.OMOD"), 0); // reset once OVAL was posted (aoRecord's monitor)
    process("ramp");
    EXPECT_DOUBLE_EQ(getd("ramp.OVAL"), 4);
    process("ramp");
    EXPECT_DOUBLE_EQ(getd("ramp.OVAL"), 5);
}

TEST_F(Conformance, BreakpointTablesAreRefusedByName) {
    std::string err = load_error(R"(record(ai, "tc") { field(LINR, "typeKdegC") })");
    EXPECT_NE(err.find("typeKdegC"), std::string::npos) << err;
    EXPECT_NE(err.find("breakpoint table"), std::string::npos) << err;
    EXPECT_NE(err.find("tc"), std::string::npos) << err;
}

// ---------------------------------------------------------------- Raw Soft Channel (binary, multi-bit)

TEST_F(Conformance, BiRawSoftChannelMasksRval) {
    load(R"(
record(longout, "w") { field(VAL, "4") }
record(bi, "b") { field(DTYP, "Raw Soft Channel") field(INP, "w") field(MASK, "2") }
)");
    process("b");
    EXPECT_DOUBLE_EQ(getd("b.RVAL"), 0); // 4 & 2
    EXPECT_DOUBLE_EQ(getd("b"), 0);
    put("w", 6);
    process("b");
    EXPECT_DOUBLE_EQ(getd("b.RVAL"), 2);
    EXPECT_DOUBLE_EQ(getd("b"), 1);
}

TEST_F(Conformance, MbbiRawSoftChannelShiftsAndMatchesStateValues) {
    load(R"(
record(longout, "w") { field(VAL, "48") }
record(mbbi, "m") { field(DTYP, "Raw Soft Channel") field(INP, "w") field(NOBT, "4") field(SHFT, "4")
    field(ZRVL, "0") field(ZRST, "zero") field(ONVL, "3") field(ONST, "three") field(UNSV, "MAJOR") }
)");
    process("m");
    EXPECT_DOUBLE_EQ(getd("m.RVAL"), 48); // 0x30 & (0xf << 4)
    EXPECT_EQ(gets("m"), "three");        // 0x30 >> 4 = 3 is ONVL
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM");
    put("w", 0x50);
    process("m");
    EXPECT_DOUBLE_EQ(getd("m"), 65535); // no state has 5: unknown
    EXPECT_EQ(gets("m"), "");           // as softIoc shows it (not "Illegal_Value")
    EXPECT_EQ(gets("m.SEVR"), "MAJOR"); // UNSV
}

TEST_F(Conformance, MbboWithStatesOfStringsOnlyWritesTheirZeroValues) {
    // base's init_common: states are defined by a value or a string, so RVAL is the state's value
    load(R"(record(mbbo, "m") { field(ZRST, "a") field(ONST, "b") field(TWST, "c") })");
    put("m", 2);
    EXPECT_DOUBLE_EQ(getd("m.SDEF"), 1);
    EXPECT_DOUBLE_EQ(getd("m.RVAL"), 0);
}

// ---------------------------------------------------------------- simulation mode

TEST_F(Conformance, SimulationModeReadsSiolAndRaisesSims) {
    load(R"(
record(ao, "hw") { field(VAL, "1") }
record(ao, "sim") { field(VAL, "42") }
record(bo, "mode") { field(VAL, "0") }
record(ai, "in") { field(INP, "hw") field(SIOL, "sim") field(SIML, "mode") field(SIMS, "MINOR") }
)");
    process("in");
    EXPECT_DOUBLE_EQ(getd("in"), 1);
    EXPECT_EQ(gets("in.SEVR"), "NO_ALARM");
    put("mode", 1);
    process("in");
    EXPECT_DOUBLE_EQ(getd("in"), 42);
    EXPECT_EQ(gets("in.SIMM"), "YES");
    EXPECT_EQ(gets("in.STAT"), "SIMM");
    EXPECT_EQ(gets("in.SEVR"), "MINOR");
    put("mode", 0);
    process("in");
    EXPECT_DOUBLE_EQ(getd("in"), 1);
    EXPECT_EQ(gets("in.SEVR"), "NO_ALARM");
}

TEST_F(Conformance, SimulationRawFeedsRvalThroughConversion) {
    load(R"(
record(ao, "sim") { field(VAL, "10.7") }
record(ai, "in") { field(SIOL, "sim") field(SIMM, "RAW") field(LINR, "SLOPE") field(ESLO, "2") }
)");
    process("in");
    EXPECT_DOUBLE_EQ(getd("in.SVAL"), 10.7);
    EXPECT_DOUBLE_EQ(getd("in.RVAL"), 10); // floor(SVAL)
    EXPECT_DOUBLE_EQ(getd("in"), 20);
}

TEST_F(Conformance, SimulatedOutputWritesSiolNotOut) {
    load(R"(
record(ao, "real") {}
record(ao, "fake") {}
record(ao, "o") { field(OUT, "real PP") field(SIOL, "fake PP") field(SIMM, "YES") }
record(longout, "lo") { field(OUT, "real PP") field(SIOL, "fake PP") field(SIMM, "YES") }
)");
    put("o", 3);
    EXPECT_DOUBLE_EQ(getd("fake"), 3);
    EXPECT_DOUBLE_EQ(getd("real"), 0);
    EXPECT_EQ(gets("o.SEVR"), "NO_ALARM"); // SIMS NO_ALARM: recGblSetSevr raises nothing
    EXPECT_EQ(gets("o.STAT"), "NO_ALARM");
    put("lo", 7);
    EXPECT_DOUBLE_EQ(getd("fake"), 7);
    EXPECT_DOUBLE_EQ(getd("real"), 0);
}

TEST_F(Conformance, SimulationScanSwapsScanWithSscn) {
    load(R"(record(ai, "in") { field(SCAN, "Passive") field(SSCN, "1 second") })");
    EXPECT_EQ(gets("in.SSCN"), "1 second");
    put_str("in.SIMM", "YES");
    EXPECT_EQ(gets("in.SCAN"), "1 second");
    EXPECT_EQ(gets("in.SSCN"), "Passive");
    EXPECT_EQ(gets("in.OLDSIMM"), "NO");
    put_str("in.SIMM", "NO");
    EXPECT_EQ(gets("in.SCAN"), "Passive");
    EXPECT_EQ(gets("in.SSCN"), "1 second");
}

TEST_F(Conformance, SimulationDelayMakesTheRecordAsynchronous) {
    load(R"(
record(ao, "sim") { field(VAL, "5") }
record(ai, "in") { field(SIOL, "sim") field(SIMM, "YES") field(SDLY, "0.5") }
)");
    start_clock();
    bool done = false;
    PutStatus status = PutStatus::Failed;
    put("in.PROC", 1, [&](PutStatus st) {
        done = true;
        status = st;
    });
    EXPECT_DOUBLE_EQ(getd("in.PACT"), 1); // waiting for SDLY
    EXPECT_DOUBLE_EQ(getd("in"), 0);
    EXPECT_FALSE(done);
    advance(0.3);
    EXPECT_FALSE(done);
    advance(0.3);
    EXPECT_TRUE(done);
    EXPECT_EQ(status, PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("in"), 5);
    EXPECT_DOUBLE_EQ(getd("in.PACT"), 0);
}

// ---------------------------------------------------------------- alarm filter

TEST_F(Conformance, AlarmFilterHoldsTheRangeOfARecentAlarm) {
    load(R"(
record(ao, "src") {}
record(ai, "filtered") { field(INP, "src") field(HIGH, "5") field(HSV, "MINOR") field(AFTC, "10") }
record(ai, "plain") { field(INP, "src") field(HIGH, "5") field(HSV, "MINOR") }
)");
    put("src", 10);
    process("filtered");
    process("plain");
    EXPECT_EQ(gets("filtered.SEVR"), "MINOR");
    EXPECT_DOUBLE_EQ(getd("filtered.AFVL"), 4); // HIGH's range
    put("src", 0);
    for (int i = 0; i < 3; ++i) {
        process("filtered");
        process("plain");
    }
    EXPECT_EQ(gets("plain.SEVR"), "NO_ALARM");
    EXPECT_EQ(gets("filtered.SEVR"), "MINOR"); // milliseconds against a 10 s time constant
    EXPECT_EQ(gets("filtered.STAT"), "HIGH");
}

// ---------------------------------------------------------------- bo HIGH

TEST_F(Conformance, BoHighEndsAPulseAfterItsSeconds) {
    load(R"(
record(bo, "pulse") { field(HIGH, "0.5") field(ZNAM, "off") field(ONAM, "on") }
)");
    start_clock();
    put("pulse", 1);
    EXPECT_EQ(gets("pulse"), "on");
    advance(0.3);
    EXPECT_EQ(gets("pulse"), "on");
    put("pulse", 1); // written again: the pulse lasts HIGH from now
    advance(0.3);
    EXPECT_EQ(gets("pulse"), "on");
    advance(0.3);
    EXPECT_EQ(gets("pulse"), "off");
}

// ---------------------------------------------------------------- longout OOPT / OOCH

TEST_F(Conformance, LongoutOoptDecidesWhenOutIsWritten) {
    load(R"(
record(calc, "n") { field(CALC, "A+1") field(INPA, "n") }
record(longout, "change") { field(OUT, "n.PROC") field(OOPT, "On Change") }
)");
    put("change", 5); // first processing writes
    EXPECT_DOUBLE_EQ(getd("n"), 1);
    put("change", 5);
    EXPECT_DOUBLE_EQ(getd("n"), 1);
    put("change", 6);
    EXPECT_DOUBLE_EQ(getd("n"), 2);
    EXPECT_DOUBLE_EQ(getd("change.PVAL"), 6);
}

TEST_F(Conformance, LongoutTransitionsAndZeroConditions) {
    load(R"(
record(calc, "n") { field(CALC, "A+1") field(INPA, "n") }
record(longout, "tz") { field(OUT, "n.PROC") field(OOPT, "Transition To Zero") field(VAL, "1") }
)");
    put("tz", 1);
    EXPECT_DOUBLE_EQ(getd("n"), 0);
    put("tz", 0); // 1 -> 0
    EXPECT_DOUBLE_EQ(getd("n"), 1);
    put("tz", 0); // 0 -> 0: no transition
    EXPECT_DOUBLE_EQ(getd("n"), 1);
    put_str("tz.OOPT", "When Non-zero");
    put("tz", 3);
    put("tz", 3);
    EXPECT_DOUBLE_EQ(getd("n"), 3);
}

// ---------------------------------------------------------------- dbCommon: AMSG, UTAG

TEST_F(Conformance, AlarmMessageFollowsTheAlarm) {
    ::unsetenv("BEAMCTL_TEST_NO_SUCH_VARIABLE");
    ::setenv("BEAMCTL_TEST_VARIABLE", "hello", 1);
    load(R"(
record(stringin, "missing") { field(DTYP, "getenv") field(INP, "@BEAMCTL_TEST_NO_SUCH_VARIABLE") }
record(stringin, "there") { field(DTYP, "getenv") field(INP, "@BEAMCTL_TEST_VARIABLE") }
)");
    process("missing");
    process("there");
    EXPECT_EQ(gets("missing.SEVR"), "INVALID");
    EXPECT_EQ(gets("missing.STAT"), "UDF");
    EXPECT_EQ(gets("missing.AMSG"), "No such ENV");
    EXPECT_EQ(gets("there"), "hello");
    EXPECT_EQ(gets("there.AMSG"), "");
    EXPECT_DOUBLE_EQ(getd("there.UTAG"), 0);
}

// ---------------------------------------------------------------- Soft Timestamp

TEST_F(Conformance, SoftTimestampGivesTheTimeNow) {
    load(R"(
record(ai, "t") { field(DTYP, "Soft Timestamp") }
record(stringin, "year") { field(DTYP, "Soft Timestamp") field(INP, "@%Y") }
)");
    process("t");
    process("year");
    double epics_now = double(EpicsTime::now().sec);
    EXPECT_NEAR(getd("t"), epics_now, 60); // seconds since 1990, not a time window
    std::time_t posix = std::time(nullptr);
    std::tm tm{};
    localtime_r(&posix, &tm);
    EXPECT_EQ(gets("year"), std::to_string(tm.tm_year + 1900));
    EXPECT_EQ(gets("t.SEVR"), "NO_ALARM");
}

// ---------------------------------------------------------------- refusals as base's

TEST_F(Conformance, NoaccessFieldsAreRefusedByName) {
    std::string err = load_error(R"(record(ai, "a") { field(PBRK, "0") })");
    EXPECT_NE(err.find("PBRK"), std::string::npos) << err;
    EXPECT_NE(err.find("DBF_NOACCESS"), std::string::npos) << err;
}

TEST_F(Conformance, DtypChoicesFollowTheRecordType) {
    std::string err = load_error(R"(record(longin, "li") { field(DTYP, "Raw Soft Channel") })");
    EXPECT_NE(err.find("Raw Soft Channel"), std::string::npos) << err;
    EXPECT_NE(err.find("longin"), std::string::npos) << err;
    EXPECT_EQ(load_error(R"(record(bo, "b") { field(DTYP, "Raw Soft Channel") }
record(ao, "a") { field(DTYP, "Async Soft Channel") }
record(waveform, "w") { field(DTYP, "asynInt8ArrayIn") })"),
              "(no error)");
}

// ---------------------------------------------------------------- CA conversions as base's

TEST_F(Conformance, IntegersReadAsNarrowerTypesAreTruncated) {
    load(R"(record(longout, "lo") { field(VAL, "-7") })");
    uint16_t e = 0;
    db.get(addr("lo"), Prim::Enum, &e, 1);
    EXPECT_EQ(e, 65529); // softIoc: (epicsEnum16)-7
    int16_t sh = 0;
    put("lo", 70000);
    db.get(addr("lo"), Prim::Short, &sh, 1);
    EXPECT_EQ(sh, int16_t(70000 - 65536));
}

// ---------------------------------------------------------------- more record types

TEST_F(Conformance, WaveformOnChangePostsOnlyWhenTheElementsChange) {
    load(R"(
record(waveform, "w") { field(NELM, "3") field(FTVL, "LONG") field(MPST, "On Change") }
)");
    struct Count : Subscription {
        int n = 0;
        void on_event(unsigned m) override {
            if (m & kDbeValue) ++n;
        }
    } count;
    count.addr = addr("w");
    count.mask = kDbeValue;
    db.subscribe(count);
    int32_t a[3] = {1, 2, 3};
    db.put(addr("w"), Prim::Long, a, 3);
    int after_first = count.n;
    db.put(addr("w"), Prim::Long, a, 3); // the same elements: no value event
    EXPECT_EQ(count.n, after_first);
    a[2] = 4;
    db.put(addr("w"), Prim::Long, a, 3);
    EXPECT_EQ(count.n, after_first + 1);
    EXPECT_NE(getd("w.HASH"), 0);
    db.unsubscribe(count);
}

TEST_F(Conformance, SelServesTheLastIndexAndCalcoutItsLinkStatus) {
    load(R"(
record(ao, "x") {}
record(sel, "s") { field(SELM, "Specified") field(INPA, "x") field(INPB, "2") field(SELN, "1") }
record(calcout, "co") { field(INPA, "x") field(INPB, "3") field(CALC, "A+B") field(OUT, "x") }
record(calc, "c") { field(INPA, "x") field(CALC, "A") field(HIGH, "1") field(HSV, "MAJOR") field(AFTC, "5") }
)");
    process("s");
    EXPECT_DOUBLE_EQ(getd("s.NLST"), 1);
    EXPECT_DOUBLE_EQ(getd("s"), 2);
    EXPECT_EQ(gets("co.INAV"), "Local PV");
    EXPECT_EQ(gets("co.INBV"), "Constant");
    EXPECT_EQ(gets("co.INCV"), "Constant"); // an empty link
    EXPECT_EQ(gets("co.OUTV"), "Local PV");
    EXPECT_DOUBLE_EQ(getd("co.CLCV"), 0);
    put("x", 2);
    process("c");
    EXPECT_EQ(gets("c.SEVR"), "MAJOR");
    put("x", 0);
    process("c");
    EXPECT_EQ(gets("c.SEVR"), "MAJOR"); // the filter holds HIGH's range
}

TEST_F(Conformance, MbbiDirectRawSoftChannelAndSimulation) {
    load(R"(
record(longout, "w") { field(VAL, "0xF3") }
record(ao, "sim") { field(VAL, "5") }
record(mbbiDirect, "raw") { field(DTYP, "Raw Soft Channel") field(INP, "w") field(NOBT, "4") field(SHFT, "4") }
record(mbbiDirect, "s") { field(INP, "w") field(SIOL, "sim") field(SIMM, "YES") field(SIMS, "MAJOR") }
record(mbboDirect, "o") { field(DTYP, "Raw Soft Channel") field(OUT, "w PP") field(NOBT, "2") }
)");
    process("raw");
    EXPECT_DOUBLE_EQ(getd("raw.RVAL"), 0xF0); // 0xF3 & (0xF << 4)
    EXPECT_DOUBLE_EQ(getd("raw"), 0xF);
    process("s");
    EXPECT_DOUBLE_EQ(getd("s"), 5);
    EXPECT_EQ(gets("s.SEVR"), "MAJOR");
    EXPECT_EQ(gets("s.STAT"), "SIMM");
    put("o", 7);
    EXPECT_DOUBLE_EQ(getd("w"), 3); // RVAL 7 & MASK 3
}

TEST_F(Conformance, InitErrorsOfEveryRecordNameWhereItWasDefined) {
    std::string err = load_error(R"(record(calc, "c1") { field(CALC, "A+") }
record(ai, "fine") {}
record(calc, "c2") { field(CALC, "B*(") })");
    EXPECT_NE(err.find("bad.db:1:"), std::string::npos) << err;
    EXPECT_NE(err.find("record c1"), std::string::npos) << err;
    EXPECT_NE(err.find("bad.db:3:"), std::string::npos) << err;
    EXPECT_NE(err.find("record c2"), std::string::npos) << err;
}

TEST_F(Conformance, EveryFieldErrorOfAFileIsReportedAtOnce) {
    std::string err = load_error(R"(record(ai, "a") { field(NOPE, "1") field(PREC, "x") }
record(bo, "b") { field(HIGH, "z") }
record(nosuchtype, "c") {})");
    EXPECT_NE(err.find("NOPE"), std::string::npos) << err;
    EXPECT_NE(err.find("PREC"), std::string::npos) << err;
    EXPECT_NE(err.find("bad.db:2:"), std::string::npos) << err;
    EXPECT_NE(err.find("nosuchtype"), std::string::npos) << err;
}

TEST_F(Conformance, LongStringsAndArraysSimulateThroughSiol) {
    ::setenv("BEAMCTL_TEST_LSI", "a long string from the environment", 1);
    load(R"(
record(stringout, "src") { field(VAL, "simulated") }
record(lsi, "l") { field(INP, "src") field(SIOL, "src") field(SIMM, "YES") field(SIMS, "MINOR") }
record(lsi, "env") { field(DTYP, "getenv") field(INP, "@BEAMCTL_TEST_LSI") field(SIZV, "64") }
record(waveform, "wf") { field(NELM, "3") field(FTVL, "DOUBLE") }
record(aai, "a") { field(NELM, "3") field(FTVL, "DOUBLE") field(SIOL, "wf") field(SIMM, "YES") }
record(aao, "o") { field(NELM, "3") field(FTVL, "DOUBLE") field(SIOL, "wf PP") field(SIMM, "YES") }
)");
    process("l");
    EXPECT_EQ(gets("l.SEVR"), "MINOR");
    EXPECT_EQ(gets("l.STAT"), "SIMM");
    char buf[64] = {};
    db.get(addr("l.VAL$"), Prim::Char, buf, 40);
    EXPECT_STREQ(buf, "simulated");
    process("env");
    char env[64] = {};
    db.get(addr("env.VAL$"), Prim::Char, env, 64);
    EXPECT_STREQ(env, "a long string from the environment");
    double v[3] = {1, 2, 3};
    db.put(addr("o"), Prim::Double, v, 3);
    double w[3] = {};
    db.get(addr("wf"), Prim::Double, w, 3);
    EXPECT_DOUBLE_EQ(w[2], 3); // aao simulated: SIOL got the array
    process("a");
    double got[3] = {};
    db.get(addr("a"), Prim::Double, got, 3);
    EXPECT_DOUBLE_EQ(got[1], 2); // aai simulated: read from SIOL
}

TEST_F(Conformance, EventInSimulationPostsTheEventSiolReads) {
    load(R"(
record(stringout, "name") { field(VAL, "sim_evt") }
record(stringout, "rname") { field(VAL, "real_evt") }
record(event, "ev") { field(INP, "rname") field(SIOL, "name") field(SIMS, "MINOR") }
record(calc, "real") { field(SCAN, "Event") field(EVNT, "real_evt") field(CALC, "VAL+1") }
record(calc, "simulated") { field(SCAN, "Event") field(EVNT, "sim_evt") field(CALC, "VAL+1") }
)");
    process("ev");
    EXPECT_EQ(gets("ev"), "real_evt");
    EXPECT_DOUBLE_EQ(getd("real"), 1);
    put("ev.SIMM", 1);
    process("ev");
    EXPECT_EQ(gets("ev"), "sim_evt"); // SVAL through SIOL
    EXPECT_EQ(gets("ev.SVAL"), "sim_evt");
    EXPECT_EQ(gets("ev.STAT"), "SIMM");
    EXPECT_EQ(gets("ev.SEVR"), "MINOR");
    EXPECT_DOUBLE_EQ(getd("simulated"), 1);
    EXPECT_DOUBLE_EQ(getd("real"), 1);
}

TEST_F(Conformance, HistogramSimulationDelaysSwapsScanAndCountsSval) {
    load(R"(
record(ao, "sim") { field(VAL, "2.5") }
record(ao, "mode") { field(VAL, "0") }
record(histogram, "h") { field(SIOL, "sim") field(SIML, "mode") field(SIMS, "MAJOR") field(SDLY, "0.5")
                         field(SSCN, "10 second") field(NELM, "4") field(ULIM, "4") }
)");
    start_clock();
    EXPECT_EQ(gets("h.SSCN"), "10 second");
    EXPECT_EQ(gets("h.OLDSIMM"), "NO");
    put("mode", 1);
    bool done = false;
    put("h.PROC", 1, [&](PutStatus) { done = true; });
    EXPECT_EQ(gets("h.SCAN"), "10 second"); // SIML gave SIMM YES: SCAN and SSCN swapped
    EXPECT_EQ(gets("h.SSCN"), "Passive");
    EXPECT_DOUBLE_EQ(getd("h.PACT"), 1); // waiting for SDLY
    EXPECT_FALSE(done);
    advance(0.6);
    EXPECT_TRUE(done);
    EXPECT_DOUBLE_EQ(getd("h.SGNL"), 2.5); // SVAL through SIOL, counted in bin 2
    Address a = addr("h");
    double counts[4] = {};
    db.get(a, Prim::Double, counts, 4);
    EXPECT_DOUBLE_EQ(counts[2], 1);
    EXPECT_EQ(gets("h.STAT"), "SIMM");
    EXPECT_EQ(gets("h.SEVR"), "MAJOR");
    put_str("h.SIMM", "NO"); // a client's put swaps back
    EXPECT_EQ(gets("h.SCAN"), "Passive");
    EXPECT_EQ(gets("h.OLDSIMM"), "YES");
}

TEST_F(Conformance, ReadOnlyFieldsAreSetFromAFileAsBaseSetsThemButNotByClients) {
    // base's dbPutString does not look at `special`: a .db may set an SPC_NOMOD field
    load(R"(
record(histogram, "h") { field(WDTH, "7") field(CSTA, "0") }
record(waveform, "w") { field(NELM, "4") field(NORD, "0") }
)");
    EXPECT_DOUBLE_EQ(getd("h.CSTA"), 0); // not counting, as the file said
    EXPECT_DOUBLE_EQ(getd("w.NORD"), 0);
    EXPECT_EQ(put("h.CSTA", 1), PutStatus::ReadOnly); // a client still cannot
    EXPECT_DOUBLE_EQ(getd("h.CSTA"), 0);
    EXPECT_NE(load_error(R"(record(ai, "r") { field(RTYP, "bo") })").find("RTYP"), std::string::npos);
}

TEST_F(Conformance, Uint64FieldsHoldTheFullUnsignedRange) {
    load(R"(
record(ai, "u") { field(UTAG, "18446744073709551615") }
record(waveform, "w") { field(FTVL, "UINT64") field(NELM, "3") }
)");
    EXPECT_DOUBLE_EQ(getd("u.UTAG"), 18446744073709551615.0); // DBR_DOUBLE over CA, as base
    EXPECT_EQ(gets("u.UTAG"), "18446744073709551615");
    const FieldDesc* f = db.find("u")->type().find("UTAG");
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(f->dbf, Dbf::UInt64);
    EXPECT_EQ(native_prim(f->dbf), Prim::Double);
    double v[3] = {1, 4294967296.0 * 8, -1};
    ASSERT_EQ(db.put(addr("w"), Prim::Double, v, 3), PutStatus::Ok);
    double got[3] = {};
    db.get(addr("w"), Prim::Double, got, 3);
    EXPECT_DOUBLE_EQ(got[0], 1);
    EXPECT_DOUBLE_EQ(got[1], 4294967296.0 * 8); // past 32 bits
    EXPECT_DOUBLE_EQ(got[2], 0);                // a negative double saturates at 0
    EXPECT_NE(load_error(R"(record(ai, "bad") { field(UTAG, "-1") })").find("DBF_UINT64"), std::string::npos);
}

TEST_F(Conformance, PutsToARecordWithDispSetFailAndCompleteTheirCallback) {
    // base's dbNotify: putDisabledType ends the put-callback with notifyError (ECA_PUTFAIL)
    load(R"(record(ao, "a") { field(DISP, "1") })");
    bool called = false;
    PutStatus seen = PutStatus::Ok;
    EXPECT_EQ(put("a", 3, [&](PutStatus st) {
                  called = true;
                  seen = st;
              }),
              PutStatus::Failed);
    EXPECT_TRUE(called);
    EXPECT_EQ(seen, PutStatus::Failed);
    EXPECT_DOUBLE_EQ(getd("a"), 0);
    EXPECT_EQ(put("a.DISP", 0), PutStatus::Ok); // DISP itself stays writable
    EXPECT_EQ(put("a", 3), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("a"), 3);
}

TEST_F(Conformance, ASubRecordWithoutSnamNeverProcesses) {
    // base's subRecord init_record: "SNAM is empty", PACT TRUE for good
    load(R"(record(sub, "s") { field(INPA, "2") })");
    EXPECT_DOUBLE_EQ(getd("s.PACT"), 1);
    db.process(*db.find("s"));
    EXPECT_DOUBLE_EQ(getd("s"), 0);
    EXPECT_DOUBLE_EQ(getd("s.A"), 2); // the constant input was loaded at init
}

TEST_F(Conformance, FieldsReadAsSoftIocServesThem) {
    // each case was a difference of bench/conformance_db.py's sweep of every field of every type
    load(R"(
record(ao, "a") { field(VAL, "2.5") }
record(ao, "p") { field(VAL, "123456789.125") field(PREC, "2") }
record(ao, "e") { field(VAL, "2.5") field(PREC, "10") }
record(longin, "li") {}
record(bo, "b") {}
record(calcout, "co") {}
record(seq, "s") { field(PREC, "3") }
record(mbbo, "m") {}
record(mbbo, "ms") { field(ZRST, "zero") field(ONST, "one") }
record(waveform, "w") {}
record(fanout, "f") {}
)");
    EXPECT_EQ(gets("a"), "3");               // cvtDoubleToString rounds the last digit half up
    EXPECT_EQ(gets("p"), "123456789.12");    // beyond 1e7: "%.*f", at most 3 decimals
    EXPECT_EQ(gets("e"), " 2.5000000000e+00"); // more than 8 decimals: "%*.*e"
    EXPECT_EQ(gets("li.SDLY"), "-1.000000"); // no get_precision: 6
    EXPECT_EQ(gets("b.HIGH"), "0.00");       // boHIGHprecision
    EXPECT_EQ(gets("co.ODLY"), "0.00");      // calcoutODLYprecision
    EXPECT_EQ(gets("s.DLY1"), "0.00");       // seqDLYprecision
    EXPECT_EQ(gets("s.DLY0"), "0.000");      // the group before DLY1: PREC
    EXPECT_EQ(gets("li.SSCN"), "65535");     // a menu index without a choice: its number
    EXPECT_EQ(gets("co.DTYP"), "Soft Channel");
    EXPECT_EQ(gets("s.DTYP"), "");           // seq has no device support
    EXPECT_EQ(gets("w.FTVL"), "STRING");     // menuFtype's first choice
    EXPECT_EQ(gets("f.SELN"), "1");
    EXPECT_EQ(addr("m").native, Prim::Long);  // no state defined: VAL is a DBF_USHORT
    EXPECT_EQ(put_str("m", "3"), PutStatus::Ok);
    EXPECT_EQ(gets("m"), "3");
    EXPECT_EQ(addr("ms").native, Prim::Enum);
    EXPECT_EQ(put_str("ms", "one"), PutStatus::Ok);
    EXPECT_EQ(gets("ms"), "one");
}
