// SCAN "I/O Intr" on bus entries, in virtual time: the bus watches the entry in the cycle, so a
// pulse shorter than the IOC loop's look still processes the record, and the cycle wakes the loop
// (the bus's change_fd) instead of a fixed poll.
#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <poll.h>

using namespace beamctl;

namespace {

struct TempDir {
    std::filesystem::path path;
    TempDir() {
        char tmpl[] = "/tmp/beamctl_iointr_XXXXXX";
        path = mkdtemp(tmpl);
    }
    ~TempDir() { std::filesystem::remove_all(path); }
    std::string write(const std::string& name, const std::string& text) const {
        std::ofstream(path / name) << text;
        return (path / name).string();
    }
};

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
    EXPECT_EQ(bus.watch_count(), 2u); // both I/O Intr inputs, watched in the cycle
    ioc.engine().run_cycles(3);
    bus.drain_changes();
    ioc.database().scan_io_intr();
    double count0 = value(ioc, "T:Count"), quiet0 = value(ioc, "T:QuietCount");
    EXPECT_FALSE(readable(bus.change_fd()));
    // the pulse: up and down again within these cycles, long before the loop looks again
    ioc.engine().run_cycles(20);
    EXPECT_EQ(value(ioc, "T:In"), 0); // nothing processed it yet; it reads 0 again anyway
    EXPECT_TRUE(readable(bus.change_fd())); // the cycle woke the loop
    bus.drain_changes();
    EXPECT_FALSE(readable(bus.change_fd()));
    ioc.database().scan_io_intr();
    EXPECT_EQ(value(ioc, "T:Count"), count0 + 1); // processed once for the pulse
    EXPECT_EQ(value(ioc, "T:QuietCount"), quiet0); // an entry that did not change: not processed
    ioc.database().scan_io_intr(); // nothing new since
    EXPECT_EQ(value(ioc, "T:Count"), count0 + 1);
    ioc.engine().run_cycles(20);
    EXPECT_FALSE(readable(bus.change_fd())); // no change, no wake-up
}
