// Record links and processing (EPICS dbProcess/dbGetLink/dbPutLink semantics): INP/OUT/DOL with
// PP/NPP and MS modifiers, FLNK chains, constant links, CP links, link resolution errors with
// file:line:col, disable (SDIS/DISV/DISA), Event scans, PHAS order, PINI, put-callbacks that wait
// for the asynchronous records their processing reaches, and the calc, calcout, seq, fanout,
// dfanout, sel and event records. Time is virtual: scan_periodic(t) is the clock.
#include "pv/database.hpp"
#include "db_fixture.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

struct Links : DbTest {
    double now = 100.0;
    void load(const char* text, const char* file = "links.db") {
        DbTest::load(text, file);
        db.scan_periodic(now); // the clock starts (delays count from the last scan time)
    }
    void advance(double seconds) { // virtual time, in the 10 ms steps an IOC calls it with
        for (double end = now + seconds; now < end - 1e-9;) db.scan_periodic(now += 0.01);
    }
};


} // namespace

TEST_F(Links, InputLinkReadsAnotherRecordAndPpProcessesItFirst) {
    load(R"(
record(ao, "src") { field(VAL, "2.5") }
record(calc, "sq") { field(INPA, "src.VAL NPP") field(CALC, "A*A") }
record(calc, "cnt") { field(CALC, "VAL+1") }
record(ai, "pp") { field(INP, "cnt PP") }
record(ai, "npp") { field(INP, "cnt NPP") }
)");
    ASSERT_EQ(put("sq.PROC", 1), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("sq"), 6.25);
    EXPECT_DOUBLE_EQ(getd("sq.A"), 2.5);
    put("pp.PROC", 1);
    EXPECT_EQ(getd("pp"), 1); // cnt was processed by the PP read
    put("npp.PROC", 1);
    EXPECT_EQ(getd("npp"), 1); // NPP: read without processing
    put("pp.PROC", 1);
    EXPECT_EQ(getd("pp"), 2);
    EXPECT_EQ(gets("pp.SEVR"), "NO_ALARM");
}

TEST_F(Links, OutputLinkWritesAndPpProcessesTheTarget) {
    load(R"(
record(ao, "out") { field(OUT, "dst PP") field(DRVH, "10") field(DRVL, "-10") }
record(ao, "dst") {}
record(ao, "out2") { field(OUT, "dst2.VAL") }
record(calc, "dst2") { field(CALC, "A") field(INPA, "out2") }
)");
    put("out", 42); // clamped to DRVH, then written
    EXPECT_EQ(getd("out.OVAL"), 10);
    EXPECT_EQ(getd("dst"), 10);
    EXPECT_EQ(gets("dst.SEVR"), "NO_ALARM"); // processed (UDF cleared, alarms checked)
    put("out2", 3);
    EXPECT_EQ(getd("dst2"), 3); // a calc's VAL is written, but NPP: not processed
    EXPECT_EQ(gets("dst2.SEVR"), "INVALID"); // never processed: still UDF
}

TEST_F(Links, ForwardLinkChainProcessesInOrderAndOnlyPassiveRecords) {
    load(R"(
record(ao, "a") { field(FLNK, "b") }
record(calc, "b") { field(INPA, "a") field(CALC, "A+1") field(FLNK, "c") }
record(calc, "c") { field(INPA, "b") field(CALC, "A*10") field(FLNK, "d") }
record(calc, "d") { field(CALC, "VAL+1") field(SCAN, "1 second") }
)");
    double d0 = getd("d");
    put("a", 1);
    EXPECT_EQ(getd("b"), 2);
    EXPECT_EQ(getd("c"), 20);
    EXPECT_EQ(getd("d"), d0); // not Passive: a forward link does not process it
}

TEST_F(Links, ForwardLinkLoopDoesNotRecurse) {
    load(R"(
record(calc, "x") { field(CALC, "VAL+1") field(FLNK, "y") }
record(calc, "y") { field(CALC, "VAL+1") field(FLNK, "x") }
)");
    put("x.PROC", 1);
    EXPECT_EQ(getd("x"), 1);
    EXPECT_EQ(getd("y"), 1);
}

TEST_F(Links, MaximizeSeverityPropagatesThroughLinks) {
    load(R"(
record(ai, "src") { field(HIHI, "5") field(HHSV, "MAJOR") field(HIGH, "3") field(HSV, "MINOR") }
record(ai, "ms") { field(INP, "src MS") }
record(ai, "nms") { field(INP, "src NMS") }
record(ai, "mss") { field(INP, "src MSS") }
record(ai, "msi") { field(INP, "src MSI") }
record(ao, "w") { field(OUT, "wt PP MS") field(HIGH, "1") field(HSV, "MINOR") }
record(ao, "wt") {}
)");
    put("src", 6);
    for (const char* r : {"ms", "nms", "mss", "msi"}) put((std::string(r) + ".PROC").c_str(), 1);
    EXPECT_EQ(gets("ms.SEVR"), "MAJOR");
    EXPECT_EQ(gets("ms.STAT"), "LINK");
    EXPECT_EQ(gets("nms.SEVR"), "NO_ALARM");
    EXPECT_EQ(gets("mss.SEVR"), "MAJOR");
    EXPECT_EQ(gets("mss.STAT"), "HIHI");
    EXPECT_EQ(gets("msi.SEVR"), "NO_ALARM"); // MSI: only INVALID propagates
    put("w", 2);
    EXPECT_EQ(gets("wt.SEVR"), "MINOR"); // the target takes the writer's alarm
    EXPECT_EQ(gets("wt.STAT"), "LINK");
}

TEST_F(Links, ConstantLinksAreLoadedAtInit) {
    load(R"(
record(ai, "k") { field(INP, "3.5") }
record(calc, "c") { field(INPA, "2") field(INPB, "{const: 4}") field(CALC, "A*B") }
record(stringin, "s") { field(INP, "{const: \"hello\"}") }
record(ao, "d") { field(DOL, "7") }
)");
    EXPECT_EQ(getd("k"), 3.5);
    EXPECT_EQ(getd("k.UDF"), 0);
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 8);
    EXPECT_EQ(gets("s"), "hello");
    EXPECT_EQ(getd("d"), 7);
    put("k.PROC", 1); // a constant is not read again: VAL keeps what a client wrote
    EXPECT_EQ(getd("k"), 3.5);
}

TEST_F(Links, LinkFieldsReadBackAsEpicsPrintsThem) {
    load(R"(
record(ai, "a") { field(INP, "b.VAL PP MS") field(FLNK, "b") }
record(ai, "b") {}
)");
    EXPECT_EQ(gets("a.INP"), "b.VAL PP MS");
    EXPECT_EQ(gets("a.FLNK"), "b NPP NMS");
    EXPECT_EQ(gets("b.INP"), "");
}

TEST_F(Links, BadLinksAreLoadErrorsWithTheirLocation) {
    std::string e = load_error("record(ai, \"a\") {\n    field(INP, \"nowhere.VAL\")\n}\n");
    EXPECT_NE(e.find("bad.db:2:11"), std::string::npos) << e;
    EXPECT_NE(e.find("no record 'nowhere'"), std::string::npos) << e;
    e = load_error("record(ai, \"a\") { field(INP, \"b.NOPE\") }\nrecord(ai, \"b\") {}\n");
    EXPECT_NE(e.find("has no field NOPE"), std::string::npos) << e;
    e = load_error("record(ai, \"a\") { field(INP, \"b PPP\") }\nrecord(ai, \"b\") {}\n");
    EXPECT_NE(e.find("unknown link modifier 'PPP'"), std::string::npos) << e;
    e = load_error("record(ao, \"a\") { field(OUT, \"b.STAT\") }\nrecord(ai, \"b\") {}\n");
    EXPECT_NE(e.find("read-only"), std::string::npos) << e;
    e = load_error("record(ai, \"a\") { field(INP, \"@ec0.s3.x\") }\n");
    EXPECT_NE(e.find("needs DTYP \"beamctl\""), std::string::npos) << e;
    e = load_error("record(ai, \"a\") { field(DTYP, \"beamctl\") field(INP, \"@ec0.s3.x\") }\n");
    EXPECT_NE(e.find("needs device support"), std::string::npos) << e; // a softioc has none
    e = load_error("record(ai, \"a\") { field(SCAN, \"I/O Intr\") }\n");
    EXPECT_NE(e.find("I/O Intr"), std::string::npos) << e;
    // every error at once
    e = load_error("record(ai, \"a\") { field(INP, \"x1\") }\nrecord(ai, \"b\") { field(INP, \"x2\") }\n");
    EXPECT_NE(e.find("'x1'"), std::string::npos) << e;
    EXPECT_NE(e.find("'x2'"), std::string::npos) << e;
}

TEST_F(Links, ClientsCanRelinkAtRunTime) {
    load(R"(
record(ai, "a") { field(INP, "b") }
record(ai, "b") { field(VAL, "1") }
record(ai, "c") { field(VAL, "2") }
)");
    put("a.PROC", 1);
    EXPECT_EQ(getd("a"), 1);
    EXPECT_EQ(put_str("a.INP", "c NPP"), PutStatus::Ok);
    put("a.PROC", 1);
    EXPECT_EQ(getd("a"), 2);
    EXPECT_EQ(put_str("a.INP", "missing"), PutStatus::BadValue); // refused; the old link stays
    EXPECT_EQ(gets("a.INP"), "c NPP NMS");
}

TEST_F(Links, CpLinkProcessesTheRecordWhenTheTargetChanges) {
    load(R"(
record(ao, "src") {}
record(calc, "follow") { field(INPA, "src CP") field(CALC, "A*2") }
record(calc, "cpp") { field(INPA, "src CPP") field(CALC, "A*3") field(SCAN, "10 second") }
)");
    put("src", 4);
    EXPECT_EQ(getd("follow"), 8);
    EXPECT_EQ(getd("cpp"), 0); // CPP: only a Passive record is processed
}

TEST_F(Links, DisabledRecordIsNotProcessedAndShowsDisableAlarm) {
    load(R"(
record(bo, "off") { field(VAL, "1") }
record(calc, "c") { field(CALC, "VAL+1") field(SDIS, "off") field(DISV, "1") field(DISS, "MINOR") }
)");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 0);
    EXPECT_EQ(gets("c.STAT"), "DISABLE");
    EXPECT_EQ(gets("c.SEVR"), "MINOR");
    put("off", 0);
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 1);
    EXPECT_EQ(gets("c.STAT"), "NO_ALARM");
}

TEST_F(Links, PeriodicScansRunInPhaseOrderAtTheirRate) {
    load(R"(
record(calc, "second") { field(SCAN, ".1 second") field(PHAS, "2") field(INPA, "first") field(CALC, "A") }
record(calc, "first") { field(SCAN, ".1 second") field(PHAS, "1") field(CALC, "VAL+1") }
record(calc, "slow") { field(SCAN, "1 second") field(CALC, "VAL+1") }
)");
    advance(1.0); // from a first scan at t0: 0, .1, ... 1.0
    EXPECT_EQ(getd("first"), getd("second")); // same phase pass: 'second' reads the new value
    EXPECT_NEAR(getd("first"), 10, 1);
    EXPECT_NEAR(getd("slow"), 1, 1);
}

TEST_F(Links, PutToScanMovesTheRecordBetweenScanLists) {
    load(R"(record(calc, "c") { field(CALC, "VAL+1") })");
    advance(1);
    EXPECT_EQ(getd("c"), 0);
    put_str("c.SCAN", ".1 second");
    advance(1);
    EXPECT_NEAR(getd("c"), 10, 1);
    put_str("c.SCAN", "Passive");
    double v = getd("c");
    advance(1);
    EXPECT_EQ(getd("c"), v);
}

TEST_F(Links, EventRecordProcessesTheRecordsOfItsEvent) {
    load(R"(
record(event, "fire") { field(VAL, "go") }
record(calc, "l1") { field(SCAN, "Event") field(EVNT, "go") field(CALC, "VAL+1") }
record(calc, "l2") { field(SCAN, "Event") field(EVNT, "other") field(CALC, "VAL+1") }
)");
    put("fire.PROC", 1);
    EXPECT_EQ(getd("l1"), 1);
    EXPECT_EQ(getd("l2"), 0);
    db.post_event("other");
    EXPECT_EQ(getd("l2"), 1);
}

TEST_F(Links, PiniRecordsAreProcessedAtInitInPhaseOrder) {
    load(R"(
record(calc, "late") { field(PINI, "YES") field(PHAS, "1") field(INPA, "early") field(CALC, "A+1") }
record(calc, "early") { field(PINI, "YES") field(CALC, "5") }
record(calc, "never") { field(CALC, "5") }
)");
    EXPECT_EQ(getd("early"), 5);
    EXPECT_EQ(getd("late"), 6);
    EXPECT_EQ(getd("never"), 0);
}

TEST_F(Links, CalcAlarmsAndBadExpressions) {
    load(R"(
record(calc, "c") { field(CALC, "A/B") field(HIGH, "5") field(HSV, "MINOR") }
)");
    put("c.A", 12);
    put("c.B", 2);
    EXPECT_EQ(getd("c"), 6);
    EXPECT_EQ(gets("c.SEVR"), "MINOR");
    EXPECT_EQ(put_str("c.CALC", "A+"), PutStatus::BadValue); // refused, the old one stays
    EXPECT_EQ(gets("c.CALC"), "A/B");
    EXPECT_EQ(put_str("c.CALC", "A-B"), PutStatus::Ok);
    EXPECT_EQ(getd("c"), 10); // CALC is pp: processed with the new expression
    std::string e = load_error("record(calc, \"d\") {\n field(CALC, \"1+*2\")\n}\n");
    EXPECT_NE(e.find("CALC"), std::string::npos) << e;
}

TEST_F(Links, CalcoutOutputOptionsAndOcal) {
    load(R"(
record(calcout, "co") { field(CALC, "A") field(OOPT, "Transition To Non-zero") field(OUT, "t PP")
                        field(DOPT, "Use OCAL") field(OCAL, "A*100") }
record(ao, "t") {}
)");
    put("co.A", 0);
    EXPECT_EQ(getd("t"), 0);
    EXPECT_EQ(gets("t.SEVR"), "INVALID"); // not written yet
    put("co.A", 2);
    EXPECT_EQ(getd("t"), 200);
    put("co.A", 3); // non-zero to non-zero: no transition, no output
    EXPECT_EQ(getd("t"), 200);
    put("co.A", 0);
    put("co.A", 1);
    EXPECT_EQ(getd("t"), 100);
}

TEST_F(Links, CalcoutOutputDelayAndPutCallbackWaitsForIt) {
    load(R"(
record(calcout, "co") { field(CALC, "A") field(OUT, "t PP") field(ODLY, "0.5") }
record(ao, "t") {}
)");
    int done = 0;
    PutStatus st = PutStatus::Failed;
    put("co.A", 7, [&](PutStatus s) {
        ++done;
        st = s;
    });
    EXPECT_EQ(getd("co.DLYA"), 1);
    EXPECT_EQ(getd("t"), 0);
    EXPECT_EQ(done, 0);
    advance(0.3);
    EXPECT_EQ(getd("t"), 0);
    advance(0.3);
    EXPECT_EQ(getd("t"), 7);
    EXPECT_EQ(getd("co.DLYA"), 0);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(st, PutStatus::Ok);
}

// dbNotify and recGblFwdLink: a put to a record busy in asynchronous processing (PACT, here a
// calcout waiting ODLY after a scan or a plain put) processes it again when it completes (RPRO);
// a put-callback waits for the completion, then puts, processes and calls back.
TEST_F(Links, PutsToABusyRecordRunWhenItCompletes) {
    load(R"(
record(calcout, "co") { field(CALC, "A") field(OUT, "t PP") field(ODLY, "0.5") }
record(ao, "t") {}
)");
    put("co.A", 1); // no callback: busy for 0.5 s
    EXPECT_EQ(getd("co.PACT"), 1);
    put("co.A", 2); // stored, processing requested again (RPRO)
    EXPECT_EQ(getd("co.RPRO"), 1);
    advance(0.6);
    EXPECT_EQ(getd("t"), 1); // the output computed when it started
    EXPECT_EQ(getd("co.RPRO"), 0);
    EXPECT_EQ(getd("co.PACT"), 1); // processing again, for A = 2
    advance(0.6);
    EXPECT_EQ(getd("t"), 2);
    EXPECT_EQ(getd("co.PACT"), 0);

    put("co.A", 3);
    // a link field is put and answered at once, busy or not (dbProcessNotify)
    char link[kStringSize] = "t.VAL";
    int link_done = 0;
    db.put(addr("co.INPB"), Prim::String, link, 1, [&](PutStatus s) {
        ++link_done;
        EXPECT_EQ(s, PutStatus::Ok);
    });
    EXPECT_EQ(link_done, 1);
    EXPECT_EQ(gets("co.INPB"), "t.VAL NPP NMS");
    int done = 0;
    put("co.A", 4, [&](PutStatus s) {
        ++done;
        EXPECT_EQ(s, PutStatus::Ok);
    });
    EXPECT_EQ(getd("co.A"), 3); // not put yet: waits for the restart
    advance(0.6);
    EXPECT_EQ(getd("t"), 3);
    EXPECT_EQ(getd("co.A"), 4); // restarted: put, processing for 0.5 s
    EXPECT_EQ(done, 0);
    advance(0.6);
    EXPECT_EQ(getd("t"), 4);
    EXPECT_EQ(done, 1);
}

TEST_F(Links, PutCallbackWaitsForAsynchronousRecordsDownTheChain) {
    load(R"(
record(ao, "start") { field(FLNK, "co") }
record(calcout, "co") { field(INPA, "start") field(CALC, "A") field(OUT, "t PP") field(ODLY, "0.2") }
record(ao, "t") {}
)");
    int done = 0;
    put("start", 3, [&](PutStatus) { ++done; });
    EXPECT_EQ(done, 0); // waits for the calcout the forward link reached
    advance(0.3);
    EXPECT_EQ(getd("t"), 3);
    EXPECT_EQ(done, 1);
}

TEST_F(Links, SeqWritesItsGroupsInOrderWithDelays) {
    load(R"(
record(seq, "s") { field(DOL0, "1") field(LNK0, "a PP") field(DOL1, "src") field(LNK1, "b PP")
                   field(DLY2, "0.5") field(DO2, "9") field(LNK2, "c PP") }
record(ao, "src") { field(VAL, "4") }
record(ao, "a") {}
record(ao, "b") {}
record(ao, "c") {}
)");
    int done = 0;
    put("s.PROC", 1, [&](PutStatus) { ++done; });
    EXPECT_EQ(getd("a"), 1);
    EXPECT_EQ(getd("b"), 4);
    EXPECT_EQ(getd("c"), 0);
    EXPECT_EQ(done, 0);
    advance(0.6);
    EXPECT_EQ(getd("c"), 9);
    EXPECT_EQ(done, 1);
}

TEST_F(Links, SeqSpecifiedAndMaskSelection) {
    load(R"(
record(seq, "s") { field(SELM, "Specified") field(SELN, "1") field(DO0, "1") field(LNK0, "a")
                   field(DO1, "2") field(LNK1, "b") field(DO2, "3") field(LNK2, "c") field(SHFT, "0") }
record(ao, "a") {}
record(ao, "b") {}
record(ao, "c") {}
)");
    put("s.PROC", 1);
    EXPECT_EQ(getd("a"), 0);
    EXPECT_EQ(getd("b"), 2);
    put_str("s.SELM", "Mask");
    put("s.SELN", 5); // groups 0 and 2
    put("s.PROC", 1);
    EXPECT_EQ(getd("a"), 1);
    EXPECT_EQ(getd("c"), 3);
    put_str("s.SELM", "Specified");
    put("s.SELN", 20);
    put("s.PROC", 1);
    EXPECT_EQ(gets("s.SEVR"), "INVALID");
    EXPECT_EQ(gets("s.STAT"), "SOFT");
}

TEST_F(Links, FanoutAndDfanout) {
    load(R"(
record(fanout, "f") { field(LNK0, "x") field(LNK1, "y") field(LNK3, "z") }
record(calc, "x") { field(CALC, "VAL+1") }
record(calc, "y") { field(CALC, "VAL+1") }
record(calc, "z") { field(CALC, "VAL+1") }
record(dfanout, "d") { field(OUTA, "p PP") field(OUTB, "q PP") field(SELM, "All") }
record(ao, "p") {}
record(ao, "q") {}
)");
    put("f.PROC", 1);
    EXPECT_EQ(getd("x"), 1);
    EXPECT_EQ(getd("y"), 1);
    EXPECT_EQ(getd("z"), 1);
    put_str("f.SELM", "Specified");
    put("f.SELN", 3);
    put("f.PROC", 1);
    EXPECT_EQ(getd("x"), 1);
    EXPECT_EQ(getd("z"), 2);
    put("d", 6.5);
    EXPECT_EQ(getd("p"), 6.5);
    EXPECT_EQ(getd("q"), 6.5);
}

TEST_F(Links, SelPicksSpecifiedHighLowMedian) {
    load(R"(
record(sel, "s") { field(INPA, "1") field(INPB, "5") field(INPC, "3") field(SELM, "High Signal") }
)");
    put("s.PROC", 1);
    EXPECT_EQ(getd("s"), 5);
    put_str("s.SELM", "Low Signal");
    put("s.PROC", 1);
    EXPECT_EQ(getd("s"), 1);
    put_str("s.SELM", "Median Signal");
    put("s.PROC", 1);
    EXPECT_EQ(getd("s"), 3);
    put_str("s.SELM", "Specified");
    put("s.SELN", 1);
    EXPECT_EQ(getd("s"), 5);
}

TEST_F(Links, OutputRecordsDriveOutputsAndIvoa) {
    load(R"(
record(bo, "b") { field(OUT, "bt PP") field(ZNAM, "off") field(ONAM, "on") }
record(bi, "bt") { field(ZNAM, "off") field(ONAM, "on") }
record(longout, "l") { field(OUT, "lt PP") field(HIHI, "5") field(HHSV, "INVALID") field(IVOA, "Don't drive outputs") }
record(longin, "lt") {}
record(stringout, "s") { field(OUT, "st PP") }
record(stringin, "st") {}
record(mbbo, "m") { field(OUT, "mt PP") field(ZRST, "zero") field(ONST, "one") }
record(mbbi, "mt") { field(ZRST, "zero") field(ONST, "one") }
record(ao, "c") { field(OMSL, "closed_loop") field(DOL, "l") field(OUT, "ct PP") }
record(ao, "ct") {}
)");
    put("b", 1);
    EXPECT_EQ(gets("bt"), "on");
    put("l", 3);
    EXPECT_EQ(getd("lt"), 3);
    put("l", 7); // INVALID by HIHI: not written
    EXPECT_EQ(getd("lt"), 3);
    put_str("s", "hello");
    EXPECT_EQ(gets("st"), "hello");
    put_str("m", "one");
    EXPECT_EQ(gets("mt"), "one");
    put("c.PROC", 1);
    EXPECT_EQ(getd("c"), 7);
    EXPECT_EQ(getd("ct"), 7);
}

TEST_F(Links, WaveformReadsAnArrayThroughItsInputLink) {
    load(R"(
record(waveform, "w") { field(NELM, "4") field(FTVL, "DOUBLE") }
record(waveform, "copy") { field(NELM, "8") field(FTVL, "LONG") field(INP, "w") }
)");
    double v[3] = {1.5, 2.5, 3.5};
    ASSERT_EQ(db.put(addr("w"), Prim::Double, v, 3), PutStatus::Ok);
    put("copy.PROC", 1);
    EXPECT_EQ(getd("copy.NORD"), 3);
    int32_t out[8] = {};
    db.get(addr("copy"), Prim::Long, out, 8);
    EXPECT_EQ(out[0], 1); // converted to LONG by truncation, as EPICS's (epicsInt32) cast
    EXPECT_EQ(out[2], 3);
}

TEST_F(Links, ProcessingAPeriodicRecordByPutNeedsProc) {
    // dbPutField: a pp field processes only a Passive record; PROC always processes.
    load(R"(record(calc, "p") { field(SCAN, "10 second") field(CALC, "A") })");
    put("p.A", 3);
    EXPECT_EQ(getd("p"), 0);
    put("p.PROC", 1);
    EXPECT_EQ(getd("p"), 3);
}

namespace {
// A device for "@name" links: a value the test sets, and what the record wrote.
struct FakeDevice : LinkDevice {
    double value = 0, written = NAN, last = NAN;
    bool read(double& v) override {
        v = last = value;
        return true;
    }
    bool write(double v) override {
        written = v;
        return true;
    }
    std::string describe() const override { return "fake"; }
    bool changed() override { return !(value == last); }
};
} // namespace

TEST_F(Links, DeviceSupportReadsWritesAndScansOnChange) {
    FakeDevice in, out;
    db.set_link_binder([&](Record&, const FieldDesc& f, Link& l, std::string* why) -> LinkDevice* {
        if (l.s().address == "in" && f.dbf == Dbf::InLink) return &in;
        if (l.s().address == "out" && f.dbf == Dbf::OutLink) return &out;
        *why = "no signal '" + l.s().address + "'";
        return nullptr;
    });
    load(R"(
record(ai, "r") { field(DTYP, "beamctl") field(INP, "@in") field(SCAN, "I/O Intr") field(FLNK, "w") }
record(ao, "w") { field(DTYP, "beamctl") field(OUT, "@out") field(OMSL, "closed_loop") field(DOL, "r") }
)");
    in.value = 2.5;
    db.scan_io_intr(); // changed: processed, and its forward link writes the output
    EXPECT_EQ(getd("r"), 2.5);
    EXPECT_EQ(out.written, 2.5);
    out.written = NAN;
    db.scan_io_intr(); // unchanged: not processed
    EXPECT_TRUE(std::isnan(out.written));
    EXPECT_NE(load_error("record(ai, \"q\") { field(DTYP, \"beamctl\") field(INP, \"@nope\") }").find("needs device"),
              std::string::npos);
}

TEST_F(Links, BusyRecordHoldsThePutCallbackAndTheForwardLinkUntilZero) {
    load(R"(record(busy, "b") { field(ZNAM, "Done") field(ONAM, "Busy") field(FLNK, "n") }
            record(calc, "n") { field(CALC, "VAL+1") }
            record(busy, "h") { field(HIGH, "0.5") })");
    int called = 0;
    PutStatus got = PutStatus::Failed;
    ASSERT_EQ(put("b", 1, [&](PutStatus st) { ++called, got = st; }), PutStatus::Ok);
    EXPECT_EQ(called, 0); // busy: the callback waits
    EXPECT_EQ(gets("b"), "Busy");
    EXPECT_EQ(getd("n"), 0); // and so does the forward link
    advance(1);
    EXPECT_EQ(called, 0);
    ASSERT_EQ(put("b", 0), PutStatus::Ok); // the owner of the work: done
    EXPECT_EQ(called, 1);
    EXPECT_EQ(got, PutStatus::Ok);
    EXPECT_EQ(getd("n"), 1);
    // a put of 0 with a callback completes at once
    ASSERT_EQ(put("b", 0, [&](PutStatus) { ++called; }), PutStatus::Ok);
    EXPECT_EQ(called, 2);
    EXPECT_EQ(getd("n"), 2);
    // HIGH: back to 0 by itself, the callback then
    ASSERT_EQ(put("h", 1, [&](PutStatus) { ++called; }), PutStatus::Ok);
    advance(0.3);
    EXPECT_EQ(getd("h"), 1);
    EXPECT_EQ(called, 2);
    advance(0.3);
    EXPECT_EQ(getd("h"), 0);
    EXPECT_EQ(called, 3);
    EXPECT_EQ(put("b", 2), PutStatus::BadValue); // two states
}
