// The IOC's signal registry: what the buses, axes and PLCs declare, who writes each output, and
// a second writer refused at load with the first one named (issue 12, "one writer per output").
#include "../temp_dir.hpp"
#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "ioc/ioc.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

using namespace beamctl;

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;

using beamctl::test::TempDir;

// Digital in and out terminals and two general PLCs.
std::string ioc_yaml(const std::string& plcs, const std::string& extra = "") {
    return "ioc: {name: T, prefix: 'T:'}\n"
           "buses:\n"
           "  - id: 0\n"
           "    link: {type: sim}\n"
           "    slaves:\n"
           "      - {position: 0, type: EK1100}\n"
           "      - {position: 1, type: EL1008}\n"
           "      - {position: 2, type: EL2008}\n" +
           plcs + extra;
}

std::string load_error(const std::string& path) {
    rt::VirtualClock clock;
    try {
        ioc::Ioc ioc(config::IocConfig::load(path), clock);
        ioc.bring_up();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(IocSignals, TheDemoDeclaresBusAxisAndPlcSignalsWithOwnersWritersAndPvs) {
    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(kSource + "/examples/demo/ioc.yaml"), clock);
    const registry::Registry& r = ioc.signals();
    EXPECT_TRUE(r.frozen());
    const registry::Signal* ctrl = r.find("ec0.s11.driveControl01");
    ASSERT_NE(ctrl, nullptr);
    EXPECT_EQ(ctrl->direction, registry::Direction::Output);
    EXPECT_EQ(ctrl->owner, "ec0");
    EXPECT_EQ(ctrl->writer, "axis 1 (SlitTop)"); // the axis drives it every cycle
    EXPECT_EQ(ctrl->pv, "DEMO:m0s011-driveControl01");
    const registry::Signal* lim = r.find("ec0.s1.binaryInput01");
    ASSERT_NE(lim, nullptr);
    EXPECT_EQ(lim->direction, registry::Direction::Input);
    EXPECT_EQ(lim->pv, "DEMO:m0s001-BI01");
    const registry::Signal* act = r.find("ax1.enc.actpos");
    ASSERT_NE(act, nullptr);
    EXPECT_EQ(act->owner_kind, registry::OwnerKind::Axis);
    EXPECT_EQ(act->pv, "DEMO:SlitTop-PosAct");
    EXPECT_EQ(r.find("ax1.traj.extsetpos")->direction, registry::Direction::Variable);
    const registry::Signal* ena = r.find("plc0.enable");
    ASSERT_NE(ena, nullptr);
    EXPECT_EQ(ena->owner_kind, registry::OwnerKind::Plc);
    EXPECT_EQ(ena->pv, "DEMO:PLC00-EnaCmd");
    // every entry PV of the buses names its signal in the registry
    std::size_t with_pv = 0;
    for (const registry::Signal* s : r.match("ec0.*")) with_pv += !s->pv.empty();
    EXPECT_GT(with_pv, 100u);
}

TEST(IocSignals, TwoPlcsWritingOneOutputAreRefusedNamingTheFirst) {
    TempDir d;
    d.write("a.plc", "ec0.s2.binaryOutput01 := 1;\n");
    d.write("b.plc", "ec0.s2.binaryOutput01 := 0;\n");
    std::string e = load_error(d.write("ioc.yaml", ioc_yaml("plcs:\n  - {id: 0, file: a.plc}\n  - {id: 1, file: b.plc}\n")));
    EXPECT_NE(e.find("b.plc: plc1 cannot write: 'ec0.s2.binaryOutput01' is already written by plc0 (one writer per output)"),
              std::string::npos)
        << e;
}

TEST(IocSignals, ARecordCannotWriteAnOutputAPlcWrites) {
    TempDir d;
    d.write("a.plc", "ec0.s2.binaryOutput01 := 1;\n");
    d.write("x.db", "record(bo, \"T:Valve\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@ec0.s2.binaryOutput01\")\n}\n");
    std::string e = load_error(d.write("ioc.yaml", ioc_yaml("plcs:\n  - {id: 0, file: a.plc}\n", "db:\n  - {file: x.db}\n")));
    EXPECT_NE(e.find("x.db:"), std::string::npos) << e;
    EXPECT_NE(e.find("'ec0.s2.binaryOutput01' is already written by plc0"), std::string::npos) << e;
}

TEST(IocSignals, DeviceSupportNamesUnknownSignalsAndInputs) {
    TempDir d;
    d.write("x.db", "record(bo, \"T:A\") {\n  field(DTYP, \"beamctl\")\n  field(OUT, \"@ec0.s1.binaryInput01\")\n}\n"
                    "record(bi, \"T:B\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@ec0.s7.nothing\")\n}\n"
                    "record(ai, \"T:C\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@plc0.dbg\")\n}\n"
                    "record(bi, \"T:D\") {\n  field(DTYP, \"beamctl\")\n  field(INP, \"@ec0.s1.binaryInput9\")\n}\n");
    d.write("a.plc", "static.x := 1;\n");
    std::string e = load_error(d.write("ioc.yaml", ioc_yaml("plcs:\n  - {id: 0, file: a.plc}\n", "db:\n  - {file: x.db}\n")));
    EXPECT_NE(e.find("'ec0.s1.binaryInput01' is an input; an output link cannot write it"), std::string::npos) << e;
    EXPECT_NE(e.find("no signal 'ec0.s7.nothing' in this IOC (ec<bus>.s<slave>.<entry>[.<bit>]"), std::string::npos) << e;
    // a name on a slave that exists lists that slave's entries
    EXPECT_NE(e.find("no signal 'ec0.s1.binaryInput9' in this IOC (ec0.s1.* has: ONE, ZERO, binaryInput01, binaryInput02,"),
              std::string::npos)
        << e;
    EXPECT_NE(e.find("'plc0.dbg' lives in the cycle only (PLC code reads and writes it); records reach plc0.enable,"),
              std::string::npos)
        << e;
}
