// SCAN "I/O Intr" on bus entries, in virtual time: the bus watches the entry in the cycle, so a
// pulse shorter than the IOC loop's look still processes the record, and the cycle wakes the loop
// (the bus's change_fd) instead of a fixed poll.
#include "../temp_dir.hpp"
#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "ioc/ioc.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <poll.h>

using namespace beamctl;

namespace {

using beamctl::test::TempDir;

// Output 1 of the EL2008 is wired to input 1 of the EL1008. The PLC sets the output in exactly
// one scan (the 5th), so the input is high in one cycle only; input 2 never changes.
const char* kIoc = "ioc: {name: T, prefix: 'T:'}\n"
                   "engine: {rate_hz: 1000}\n"
                   "buses:\n"
                   "  - id: 0\n"
                   "    link: {type: sim, plant: plant.yaml}\n"
                   "    slaves:\n"
                   "      - {position: 0, type: EK1100}\n"
                   "      - {position: 1, type: EL1008}\n"
                   "      - {position: 2, type: EL2008}\n"
                   "plcs:\n  - {id: 0, file: pulse.plc}\n"
                   "db:\n  - {file: io.db}\n";
const char* kPlant = "wiring:\n  - {from: s2.binaryOutput01, to: s1.binaryInput01}\n";
const char* kPlc = "static.n := static.n + 1;\nec0.s2.binaryOutput01 := static.n == 5;\n";
const char* kDb = R"(
record(bi, "T:In") {
  field(DTYP, "beamctl")
  field(INP, "@ec0.s1.binaryInput01")
  field(SCAN, "I/O Intr")
  field(FLNK, "T:Count")
}
record(calc, "T:Count") { field(CALC, "VAL+1") }
record(bi, "T:Quiet") {
  field(DTYP, "beamctl")
  field(INP, "@ec0.s1.binaryInput02")
  field(SCAN, "I/O Intr")
  field(FLNK, "T:QuietCount")
}
record(calc, "T:QuietCount") { field(CALC, "VAL+1") }
)";

double value(ioc::Ioc& ioc, const char* name) {
    pv::Address a;
    EXPECT_TRUE(ioc.database().resolve(name, a));
    double v = 0;
    ioc.database().get(a, pv::Prim::Double, &v, 1);
    return v;
}

bool readable(int fd) {
    pollfd p{fd, POLLIN, 0};
    return ::poll(&p, 1, 0) == 1;
}

} // namespace

TEST(IocIoIntr, APulseBetweenTwoLooksStillProcessesTheRecordAndWakesTheLoop) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("pulse.plc", kPlc);
    d.write("io.db", kDb);
    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", kIoc)), clock);
    ioc.bring_up();
    ethercat::Bus& bus = ioc.bus(0);
    EXPECT_EQ(bus.watch_count(), 8u); // every input of the EL1008 (its entry PVs are I/O Intr; the
                                      // records here share the watches of inputs 1 and 2)
    ioc.engine().run_cycles(3);
    ioc.bus_changed(0);
    double count0 = value(ioc, "T:Count"), quiet0 = value(ioc, "T:QuietCount");
    EXPECT_FALSE(readable(bus.change_fd()));
    // the pulse: up and down again within these cycles, long before the loop looks again
    ioc.engine().run_cycles(20);
    EXPECT_EQ(value(ioc, "T:In"), 0); // nothing processed it yet; it reads 0 again anyway
    EXPECT_TRUE(readable(bus.change_fd())); // the cycle woke the loop
    ioc.bus_changed(0);
    EXPECT_FALSE(readable(bus.change_fd()));
    EXPECT_EQ(value(ioc, "T:Count"), count0 + 1); // processed once for the pulse
    EXPECT_EQ(value(ioc, "T:QuietCount"), quiet0); // an entry that did not change: not processed
    ioc.bus_changed(0); // nothing new since
    EXPECT_EQ(value(ioc, "T:Count"), count0 + 1);
    ioc.engine().run_cycles(20);
    EXPECT_FALSE(readable(bus.change_fd())); // no change, no wake-up
}

// ecmccfg's records: DTYP asynInt32/asynUInt32Digital with "@asyn(...)" / "@asynMask(...)" addresses
// read and write the same signals as DTYP "beamctl" (a one-bit MASK is a bit of the entry).
TEST(IocIoIntr, EcmccfgAsynAddressesReachTheSameSignals) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("pulse.plc", "static.n := 0;\n");
    d.write("io.db", R"db(
record(bo, "T:Out") {
  field(DTYP, "asynUInt32Digital")
  field(OUT, "@asynMask(MC_CPU1,0,0x1,1)T_SMP_MS=10/TYPE=asynUInt32Digital/ec0.s2.binaryOutput01=")
}
record(longin, "T:In") {
  field(DTYP, "asynInt32")
  field(INP, "@asyn(MC_CPU1,0,1)T_SMP_MS=10/TYPE=asynInt32/ec0.s1.binaryInput01?")
  field(SCAN, "I/O Intr")
}
)db");
    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", kIoc)), clock);
    ioc.bring_up();
    EXPECT_EQ(ioc.signals().find("ec0.s2.binaryOutput01")->writer, "record T:Out");
    ioc.engine().run_cycles(3);
    pv::Address a;
    ASSERT_TRUE(ioc.database().resolve("T:Out", a));
    double one = 1;
    EXPECT_EQ(ioc.database().put(a, pv::Prim::Double, &one, 1), pv::PutStatus::Ok);
    ioc.engine().run_cycles(5); // sent, wired back, received
    ioc.bus_changed(0);
    EXPECT_EQ(value(ioc, "T:In"), 1);

    // a mask of more than one bit, and an asyn address without a signal name, are refused
    TempDir bad;
    bad.write("plant.yaml", kPlant);
    bad.write("pulse.plc", "static.n := 0;\n");
    bad.write("io.db", R"db(
record(mbbiDirect, "T:Two") {
  field(DTYP, "asynUInt32Digital")
  field(INP, "@asynMask(MC_CPU1,0,0x3,1)T_SMP_MS=10/TYPE=asynUInt32Digital/ec0.s1.binaryInput01?")
}
record(longin, "T:None") { field(DTYP, "asynInt32") field(INP, "@asyn(MC_CPU1,0,1)") }
)db");
    std::string e;
    try {
        ioc::Ioc b(config::IocConfig::load(bad.write("ioc.yaml", kIoc)), clock);
        b.bring_up();
    } catch (const Error& x) {
        e = x.what();
    }
    EXPECT_NE(e.find("MASK '0x3': only a mask of one bit is supported"), std::string::npos) << e;
    EXPECT_NE(e.find("no signal name after the asyn port"), std::string::npos) << e;
    EXPECT_NE(e.find("io.db:"), std::string::npos) << e;
}

// Records of one IOC-loop look read the same cycle: bus-entry devices read the snapshot the loop
// took for that look (Ioc::publish, a change wake-up), not whatever cycle is newest at each read.
TEST(IocIoIntr, RecordsOfOneLookReadTheSameCycle) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("pulse.plc", "static.n := static.n + 1;\nec0.s2.binaryOutput01 := static.n >= 10;\n");
    d.write("io.db", R"(
record(bi, "T:A") { field(DTYP, "beamctl") field(INP, "@ec0.s1.binaryInput01") }
record(bi, "T:B") { field(DTYP, "beamctl") field(INP, "@ec0.s1.binaryInput01") }
)");
    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", kIoc)), clock);
    ioc.bring_up();
    auto process = [&](const char* name) {
        pv::Address a;
        EXPECT_TRUE(ioc.database().resolve(std::string(name) + ".PROC", a));
        double one = 1;
        ioc.database().put(a, pv::Prim::Double, &one, 1);
        return value(ioc, name);
    };
    ioc.engine().run_cycles(3);
    ioc.publish(); // the look: the input is still low
    EXPECT_EQ(process("T:A"), 0);
    ioc.engine().run_cycles(20); // the PLC raised the output, the input followed
    EXPECT_EQ(process("T:B"), 0); // same look as T:A
    EXPECT_EQ(process("T:A"), 0);
    ioc.publish(); // the next look
    EXPECT_EQ(process("T:A"), 1);
    EXPECT_EQ(process("T:B"), 1);
}
