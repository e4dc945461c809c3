// Device support on axis data items and the declarative PV tables (issue 12): the axis PVs are
// records made from one table, on the items ax<n>.actpos, .status, .control, ...; any record of a
// .db file reads and writes the same items ("@ax1.actpos", ecmccfg's "@asyn(...)/ax1.actpos?"),
// I/O Intr records follow the axis, writes are the axis's commands, and a name records cannot
// reach is refused at load with its reason. In virtual time.
#include "../temp_dir.hpp"
#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "ioc/ioc.hpp"
#include "module/pv_table.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

using namespace beamctl;

namespace {

const std::string kData = std::string(BEAMCTL_SOURCE_DIR) + "/tests/system/data/axes/";
using beamctl::test::TempDir;

std::string ioc_yaml(const std::string& db) {
    return "ioc: {name: T, prefix: 'T:'}\n"
           "engine: {rate_hz: 1000}\n"
           "buses:\n"
           "  - id: 0\n"
           "    link: {type: sim, plant: " + kData + "plant.yaml}\n"
           "    slaves:\n"
           "      - {position: 0, type: EK1100}\n"
           "      - {position: 1, type: EL1008}\n"
           "      - {position: 2, type: EL7041}\n"
           "axes:\n"
           "  - {file: " + kData + "stepper.yaml, macros: {AX_NAME: X, DRV_SLAVE: 2}}\n" +
           (db.empty() ? std::string() : "db:\n  - {file: " + db + "}\n");
}

struct Rig {
    TempDir d;
    rt::VirtualClock clock;
    std::unique_ptr<ioc::Ioc> ioc;
    explicit Rig(const std::string& db_text) {
        std::string db = db_text.empty() ? std::string() : d.write("x.db", db_text);
        ioc = std::make_unique<ioc::Ioc>(config::IocConfig::load(d.write("ioc.yaml", ioc_yaml(db))), clock);
        ioc->bring_up();
        step(5);
    }
    // n cycles, then the IOC loop's look (publish, I/O Intr)
    void step(int n) {
        ioc->engine().run_cycles(uint64_t(n));
        ioc->publish();
    }
    double get(const std::string& name) {
        pv::Address a;
        EXPECT_TRUE(ioc->database().resolve(name, a)) << name;
        double v = 0;
        ioc->database().get(a, pv::Prim::Double, &v, 1);
        return v;
    }
    void put(const std::string& name, double v) {
        pv::Address a;
        ASSERT_TRUE(ioc->database().resolve(name, a)) << name;
        ASSERT_EQ(ioc->database().put(a, pv::Prim::Double, &v, 1), pv::PutStatus::Ok) << name;
    }
    const motion::AxisStatus& st() { return ioc->axes().status(0); }
    // steps until `done` or n looks
    template <class F> bool until(F done, int looks = 2000) {
        for (int i = 0; i < looks && !done(); ++i) step(10);
        return done();
    }
};

std::string load_error(const std::string& db_text) {
    try {
        Rig r(db_text);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(AxisItems, TheAxisPvsAreTableRecordsOnTheItems) {
    Rig r("");
    pv::Record* pos = r.ioc->database().find("T:X-PosAct");
    ASSERT_NE(pos, nullptr);
    EXPECT_EQ(pos->scan, 2); // I/O Intr on ax1.actpos
    const registry::Registry& s = r.ioc->signals();
    EXPECT_EQ(s.find("ax1.actpos")->pv, "T:X-PosAct");
    EXPECT_EQ(s.find("ax1.enc.actpos")->pv, "T:X-PosAct"); // the PLC name of the same value
    EXPECT_EQ(s.find("ax1.status")->pv, "T:X-Stat");
    EXPECT_EQ(s.find("ax1.control")->pv, ""); // its bits have PVs (EnaCmd, ExeCmd, ...), the word none
    EXPECT_EQ(s.find("ax1.control")->direction, registry::Direction::Variable);
    EXPECT_EQ(s.find("ax1.status")->direction, registry::Direction::Input);
    // enable and move through the table's PVs: EnaCmd, MtnCmd, TgtPosCmd, ExeCmd are item writes
    r.put("T:X-EnaCmd", 1);
    ASSERT_TRUE(r.until([&] { return r.get("T:X-EnaAct") == 1; }));
    EXPECT_EQ(int(r.get("T:X-Stat")) & 3, 3);
    r.put("T:X-TgtPosCmd", 4);
    r.put("T:X-ExeCmd", 1);
    ASSERT_TRUE(r.until([&] { return r.get("T:X-Busy") == 1; }));
    ASSERT_TRUE(r.until([&] { return r.get("T:X-Busy") == 0 && r.get("T:X-AtTarget") == 1; }));
    EXPECT_NEAR(r.get("T:X-PosAct"), 4.0, 0.01);
    EXPECT_NEAR(r.get("T:X-PosAct"), r.st().act_pos, 1e-12); // the snapshot, not a copy of it
    EXPECT_NEAR(r.get("T:X-PosSet"), 4.0, 1e-9);
    EXPECT_EQ(r.get("T:X-LimFwd"), 1); // 1 = limit OK (status bit 6)
}

TEST(AxisItems, EnaCmdFollowsTheAxisWhenItDisablesItselfWithoutCommandingIt) {
    Rig r("");
    r.put("T:X-EnaCmd", 1);
    ASSERT_TRUE(r.until([&] { return r.get("T:X-EnaAct") == 1; }));
    // the axis drops its enable (as on an error): the command record follows, sends nothing
    motion::AxisCommand off{motion::CommandType::Power};
    off.on = false;
    ASSERT_NE(r.ioc->axes().send(0, off), 0u);
    ASSERT_TRUE(r.until([&] { return r.get("T:X-EnaAct") == 0; }));
    EXPECT_EQ(r.get("T:X-EnaCmd"), 0);
    EXPECT_FALSE(r.st().enable_cmd);
    r.step(200);
    EXPECT_FALSE(r.st().enable_cmd); // the read-back did not enable it again
}

TEST(AxisItems, RecordsOfADbFileReadAndWriteTheItems) {
    Rig r(R"(
record(ai, "T:Pos") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.actpos")
  field(SCAN, "I/O Intr")
  field(FLNK, "T:Count")
}
record(calc, "T:Count") { field(CALC, "VAL+1") }
record(ai, "T:EcmcPos") {
  field(DTYP, "asynFloat64")
  field(INP, "@asyn(MC_CPU1,0,1)T_SMP_MS=10/TYPE=asynFloat64/ax1.actpos?")
  field(SCAN, "I/O Intr")
}
record(bi, "T:Busy") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.traj.busy")
  field(SCAN, "I/O Intr")
}
record(bi, "T:InError") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.errorid")
  field(SCAN, "I/O Intr")
}
record(ai, "T:Enc") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.enc01.actpos")
  field(SCAN, "I/O Intr")
}
record(bo, "T:Ena") {
  field(DTYP, "asynUInt32Digital")
  field(OUT, "@asynMask(MC_CPU1,0,0x1,1)T_SMP_MS=10/TYPE=asynUInt32Digital/ax1.control?")
}
record(ao, "T:Target") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.traj.targetpos")
  field(FLNK, "T:Go")
}
record(bo, "T:Go") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.traj.execute")
  field(VAL, "1")
}
)");
    double count0 = r.get("T:Count");
    r.step(50);
    EXPECT_EQ(r.get("T:Count"), count0); // nothing moved: not processed again
    r.put("T:Ena", 1);
    ASSERT_TRUE(r.until([&] { return r.st().enabled; }));
    r.put("T:Target", -3); // FLNK: execute
    ASSERT_TRUE(r.until([&] { return r.get("T:Busy") == 1; }));
    ASSERT_TRUE(r.until([&] { return !r.st().busy; }));
    r.step(10);
    EXPECT_NEAR(r.st().act_pos, -3.0, 0.01);
    EXPECT_EQ(r.get("T:Pos"), r.st().act_pos);
    EXPECT_EQ(r.get("T:EcmcPos"), r.st().act_pos);
    EXPECT_NEAR(r.get("T:Enc"), r.st().enc_pos[0], 1e-12);
    EXPECT_GT(r.get("T:Count"), count0 + 10); // processed as the position changed
    EXPECT_EQ(r.get("T:Busy"), 0);
    EXPECT_EQ(r.get("T:InError"), 0);
    // a move while disabled: the axis refuses it with an error id; a bi reads it as 1
    r.put("T:Ena", 0);
    ASSERT_TRUE(r.until([&] { return !r.st().enabled; }));
    r.put("T:Target", 1);
    ASSERT_TRUE(r.until([&] { return r.st().error_id != 0; }));
    r.step(10);
    EXPECT_EQ(r.get("T:InError"), 1);
    EXPECT_EQ(r.get("T:X-ErrId"), double(r.st().error_id));
}

TEST(AxisItems, NamesRecordsCannotReachAreRefusedAtLoadWithTheReason) {
    std::string e = load_error(R"(
record(ao, "T:A") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.actpos")
}
record(ai, "T:B") {
  field(DTYP, "beamctl")
  field(INP, "@ax1.traj.extsetpos")
}
record(ai, "T:C") {
  field(DTYP, "beamctl")
  field(INP, "@ax7.actpos")
}
record(bo, "T:D") {
  field(DTYP, "beamctl")
  field(OUT, "@ax1.status.3")
}
)");
    EXPECT_NE(e.find("T:A field OUT \"@ax1.actpos\": 'ax1.actpos' is a readback of axis 1 (X); an output link cannot write it"),
              std::string::npos)
        << e;
    EXPECT_NE(e.find("'ax1.traj.extsetpos' lives in the cycle only (PLC code reads and writes it)"), std::string::npos) << e;
    EXPECT_NE(e.find("no signal 'ax7.actpos' in this IOC"), std::string::npos) << e;
    EXPECT_NE(e.find("T:D field OUT"), std::string::npos) << e;
}

TEST(PvTable, RowsBecomeDeviceRecordsWithTheInstanceMacros) {
    registry::Registry reg;
    for (const char* n : {"ax3.actpos", "ax3.control"}) {
        registry::Signal s;
        s.name = n;
        s.type = "LREAL";
        s.owner_kind = registry::OwnerKind::Axis;
        reg.declare(s);
    }
    module::PvTable t{"test", {
        {"-Pos", "ai", "actpos", {{"EGU", "$(EGU)"}, {"DESC", "Position"}}},
        {"-Ena", "bo", "control.0", {{"ZNAM", "Off"}}, true},
        {"-Note", "stringin", "", {{"DESC", "text"}}},
    }};
    module::PvInstance in{"P:M3", "ax3.", {{"EGU", "mm"}}};
    pv::DbFile f = module::make_records(t, in, reg);
    ASSERT_EQ(f.records.size(), 3u);
    auto field = [&](std::size_t i, const std::string& k) {
        for (const auto& fl : f.records[i].fields)
            if (fl.name == k) return fl.value;
        return std::string("<none>");
    };
    EXPECT_EQ(f.records[0].name, "P:M3-Pos");
    EXPECT_EQ(field(0, "DTYP"), "beamctl");
    EXPECT_EQ(field(0, "INP"), "@ax3.actpos");
    EXPECT_EQ(field(0, "SCAN"), "I/O Intr");
    EXPECT_EQ(field(0, "EGU"), "mm");
    EXPECT_EQ(field(1, "OUT"), "@ax3.control.0");
    EXPECT_EQ(field(1, "SCAN"), "<none>"); // an output is processed by its puts
    ASSERT_EQ(f.records[1].infos.size(), 1u);
    EXPECT_EQ(f.records[1].infos[0].name, "asyn:READBACK");
    EXPECT_EQ(field(2, "DTYP"), "<none>"); // a soft record
    module::name_pvs(t, in, reg);
    EXPECT_EQ(reg.find("ax3.actpos")->pv, "P:M3-Pos");
    EXPECT_EQ(reg.find("ax3.control")->pv, ""); // a bit of it is not the signal's PV
    std::string text = module::to_db_text(t);
    EXPECT_NE(text.find("record(ai, \"$(P)-Pos\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@$(S)actpos\")\n  field(SCAN, \"I/O Intr\")\n"),
              std::string::npos)
        << text;
    EXPECT_NE(text.find("info(asyn:READBACK, \"1\")"), std::string::npos) << text;
    // a row on a signal the registry does not know is a programming error, named
    module::PvTable bad{"bad", {{"-X", "ai", "nothing", {}}}};
    try {
        module::make_records(bad, in, reg);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "PV table 'bad', row -X: no signal 'ax3.nothing'");
    }
}

// The bus and engine status PVs are table records on IOC-loop items (ec0.ok, ec0.s2.slavestatus,
// ecmc.thread.*), which records of a .db file read too; the cycle (PLC code) cannot use them.
TEST(BusItems, StatusPvsAndRecordsReadTheBusAndEngineItems) {
    Rig r(R"(
record(bi, "T:Ok") {
  field(DTYP, "asynInt32")
  field(INP, "@asyn(MC_CPU1,0,1)T_SMP_MS=10/TYPE=asynInt32/ec0.ok?")
  field(SCAN, "I/O Intr")
}
record(bi, "T:DriveOp") {
  field(DTYP, "beamctl")
  field(INP, "@ec0.s2.slavestatus.1")
  field(SCAN, "I/O Intr")
}
record(longin, "T:Cycles") {
  field(DTYP, "beamctl")
  field(INP, "@ecmc.thread.cycles")
  field(SCAN, "I/O Intr")
}
)");
    const registry::Registry& s = r.ioc->signals();
    EXPECT_EQ(s.find("ec0.ok")->pv, "T:m0-Stat-OK");
    EXPECT_EQ(s.find("ec0.slavecounter")->pv, "T:m0-SlvCntr");
    EXPECT_EQ(s.find("ecmc.thread.reset")->owner_kind, registry::OwnerKind::Engine);
    EXPECT_TRUE(s.find("ec0.s2.slavestatus")->loop_only);
    r.step(20);
    EXPECT_EQ(r.get("T:m0-Stat-OK"), 1);
    EXPECT_EQ(r.get("T:Ok"), 1);
    EXPECT_EQ(r.get("T:m0-SlvCntr"), 3);
    EXPECT_EQ(r.get("T:m0-Dom-WC-Complete"), 1);
    EXPECT_EQ(r.get("T:m0-Dom-WC"), r.get("T:m0-Dom-WC-Exp"));
    EXPECT_EQ(r.get("T:m0s002-Online"), 1);
    EXPECT_EQ(r.get("T:m0s002-Operational"), 1);
    EXPECT_EQ(r.get("T:DriveOp"), 1);
    EXPECT_GT(r.get("T:Cycles"), 0); // virtual time: cycles are counted, latencies are 0
    EXPECT_EQ(r.get("T:Cycles"), r.get("T:m0-ThdCycles"));
    // ThdStat-Reset: a put of 1 clears the counts in the next cycle and reads 0 once done
    pv::Address reset;
    ASSERT_TRUE(r.ioc->database().resolve("T:m0-ThdStat-Reset", reset));
    double one = 1;
    ASSERT_EQ(r.ioc->database().put(reset, pv::Prim::Double, &one, 1), pv::PutStatus::Ok);
    EXPECT_EQ(r.get("T:m0-ThdStat-Reset"), 1);
    r.step(3);
    EXPECT_EQ(r.get("T:m0-ThdStat-Reset"), 0);
    EXPECT_LE(r.get("T:m0-ThdCycles"), 3);
}

TEST(BusItems, TheCycleCannotUseThemAndOutputsCannotWriteThem) {
    TempDir d;
    d.write("a.plc", "static.x := ec0.ok;\n");
    d.write("x.db", "record(bo, \"T:A\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@ec0.linkup\")\n}\n"
                    "record(longin, \"T:B\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@ec0.wkcerrors.2\")\n}\n");
    std::string yaml = ioc_yaml(d.file("x.db"));
    std::string e;
    rt::VirtualClock clock;
    try {
        ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", yaml + "plcs:\n  - {id: 0, file: a.plc}\n")), clock);
    } catch (const Error& err) {
        e = err.what();
    }
    EXPECT_NE(e.find("no process-data entry 'ec0.ok' on the configured buses"), std::string::npos) << e;
    try {
        Rig bad(std::string("record(bo, \"T:A\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@ec0.linkup\")\n}\n"
                            "record(longin, \"T:B\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@ec0.wkcerrors.2\")\n}\n"));
        e.clear();
    } catch (const Error& err) {
        e = err.what();
    }
    EXPECT_NE(e.find("'ec0.linkup' is a status of the IOC; an output link cannot write it"), std::string::npos) << e;
    EXPECT_NE(e.find("'ec0.wkcerrors' is a number; it has no bit 2"), std::string::npos) << e;
}

// The entry PVs are table records too: an input reads its entry with I/O Intr and shows
// LINK/INVALID while the bus's data is not valid; a free output's PV writes its entry; an output
// an axis drives is read-only and follows what the axis sends.
TEST(BusItems, EntryPvsReadWriteAndShowTheBusState) {
    Rig r("");
    pv::Database& db = r.ioc->database();
    pv::Record* in = db.find("T:m0s001-BI01");
    ASSERT_NE(in, nullptr);
    EXPECT_EQ(in->scan, 2);
    EXPECT_TRUE(in->val_read_only);
    r.step(10);
    EXPECT_EQ(in->sevr, pv::kNoAlarm);
    EXPECT_EQ(r.get("T:m0s001-BI01"), 1); // forward limit OK (the switch input is 1 = not on it)
    // the drive's control word: driven by the axis, read-only, shows the image
    pv::Record* ctrl = db.find("T:m0s002-driveControl01");
    ASSERT_NE(ctrl, nullptr);
    EXPECT_TRUE(ctrl->val_read_only);
    r.put("T:X-EnaCmd", 1);
    ASSERT_TRUE(r.until([&] { return r.get("T:X-EnaAct") == 1; }));
    EXPECT_NE(int(r.get("T:m0s002-driveControl01")) & 1, 0); // the enable bit the axis sends
    EXPECT_EQ(ctrl->sevr, pv::kNoAlarm);                      // not UDF: it was read back
    // a free output (the encoder control word): its PV writes it
    pv::Record* enc = db.find("T:m0s002-encoderControl01");
    ASSERT_NE(enc, nullptr);
    EXPECT_FALSE(enc->val_read_only);
    // unplugging the input terminal: its PVs go COMM/INVALID (as ECMC), the bus is not OK, the
    // drive's entries stay valid
    r.ioc->segment(0)->unplug(1);
    r.step(20);
    EXPECT_EQ(r.get("T:m0-Stat-OK"), 0);
    EXPECT_EQ(in->sevr, pv::kInvalid);
    EXPECT_EQ(in->stat, pv::kStatComm);
    EXPECT_EQ(r.get("T:m0s001-Valid"), 0);
    EXPECT_EQ(r.get("T:m0s002-Valid"), 1);
    EXPECT_EQ(r.get("T:m0-SlvOP"), 2);
    EXPECT_EQ(ctrl->sevr, pv::kNoAlarm);
}

// One writer per output at run time: a record relinked to another output (a put to OUT, as dbpf
// does) gives the first one back, whose own PV is writable again with its DESC; removing nothing
// else.
TEST(BusItems, ARelinkedOutputRecordGivesItsOutputBack) {
    Rig r(R"(
record(longout, "T:Out") {
  field(DTYP, "beamctl")
  field(OUT, "@ec0.s2.encoderControl01")
}
)");
    pv::Database& db = r.ioc->database();
    const registry::Registry& s = r.ioc->signals();
    pv::Record* pv1 = db.find("T:m0s002-encoderControl01");
    ASSERT_NE(pv1, nullptr);
    EXPECT_EQ(s.find("ec0.s2.encoderControl01")->writer, "record T:Out");
    EXPECT_TRUE(pv1->val_read_only);
    EXPECT_STREQ(pv1->desc, "set by record T:Out");
    // relink it to the drive's velocity setpoint: refused (the axis drives it), nothing changes
    pv::Address out;
    ASSERT_TRUE(db.resolve("T:Out.OUT", out));
    char text[40] = "@ec0.s2.velocitySetpoint01";
    EXPECT_NE(db.put(out, pv::Prim::String, text, 1), pv::PutStatus::Ok);
    EXPECT_EQ(s.find("ec0.s2.encoderControl01")->writer, "record T:Out");
    EXPECT_TRUE(pv1->val_read_only);
    // relink it to an empty link: the output is free, its PV writes it again
    char empty[40] = "";
    ASSERT_EQ(db.put(out, pv::Prim::String, empty, 1), pv::PutStatus::Ok);
    EXPECT_EQ(s.find("ec0.s2.encoderControl01")->writer, "");
    EXPECT_FALSE(pv1->val_read_only);
    EXPECT_STREQ(pv1->desc, "EL7041 encoderControl01");
    // and back: claimed again
    char again[40] = "@ec0.s2.encoderControl01";
    ASSERT_EQ(db.put(out, pv::Prim::String, again, 1), pv::PutStatus::Ok);
    EXPECT_EQ(s.find("ec0.s2.encoderControl01")->writer, "record T:Out");
    EXPECT_TRUE(pv1->val_read_only);
}
