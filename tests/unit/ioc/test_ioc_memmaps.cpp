// Oversampling terminals and ECMC's memory maps, in virtual time: an EL3702 and an EL4732 at
// factor 10 (ecmccfg NELM), the master's PDO assignment and DC SYNC0/SYNC1, the simulator's
// n samples per cycle, the memory maps' ids, the PLC functions ec_*_mm_* with ECMC's error
// codes, and the waveform PVs.
#include "../temp_dir.hpp"
#include "virtual_ioc.hpp"
#include "config/ioc_config.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/segment.hpp"
#include "ioc/ioc.hpp"
#include "plc/runtime.hpp"
#include "pv/convert.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

std::string ioc_yaml(const std::string& os3702, const std::string& extra = "") {
    return "ioc: {name: T, prefix: 'T:'}\n"
           "engine: {rate_hz: 1000}\n"
           "buses:\n"
           "  - id: 0\n"
           "    link: {type: sim, plant: plant.yaml}\n"
           "    slaves:\n"
           "      - {position: 0, type: EK1100}\n"
           "      - {position: 1, type: EL3702" + os3702 + "}\n"
           "      - {position: 2, type: EL4732, oversampling: 10}\n"
           "storages:\n"
           "  - {id: 0, size: 100}\n"
           "plcs:\n"
           "  - {id: 0, file: main.plc}\n" + extra;
}

// s1 ch1 sees a 100 Hz ramp (one period every 10 cycles); the EL4732's channel 1 is wired to
// the EL3702's channel 2, sample for sample.
const char* kPlant = R"(
signals:
  - {to: s1.analogInputArray01_1, shape: ramp, amplitude: 5, frequency: 100}
wiring:
  - {from: s2.analogOutput01_1, to: s1.analogInputArray02_1}
)";

// The IOC's PV element i.
double pv_element(test::VirtualIoc& v, const std::string& name, uint32_t i) {
    pv::Record* r = v.ioc->database().find(name);
    if (!r) throw std::runtime_error("no record " + name);
    const pv::FieldDesc* f = r->type().find("VAL");
    pv::Elements e = r->elements(*f);
    double x = 0;
    pv::get_element(*r, *f, e, i, pv::Prim::Double, &x);
    return x;
}

} // namespace

TEST(Oversampling, CatalogDescriptionWithFactorN) {
    const ethercat::Catalog& c = ethercat::Catalog::builtin();
    const ethercat::DeviceDesc* d = c.find("EL3702");
    ASSERT_NE(d, nullptr);
    EXPECT_EQ(d->oversampling.max, 100);
    EXPECT_EQ(d->oversampling_factor(), 1u);
    ethercat::DeviceDesc d4 = d->with_oversampling(4);
    EXPECT_EQ(d4.oversampling_factor(), 4u);
    EXPECT_EQ(d4.sm_bytes(0), 2u + 4 * 2); // cycle counter + 4 samples
    EXPECT_EQ(d4.sm_bytes(1), 2u + 4 * 2);
    const ethercat::Pdo* p = d4.find_pdo(0x1a83);
    ASSERT_NE(p, nullptr); // channel 2, sample 4
    ASSERT_EQ(p->entries.size(), 1u);
    EXPECT_EQ(p->entries[0].index, 0x6030);
    EXPECT_EQ(p->entries[0].sub, 2);
    EXPECT_EQ(p->entries[0].name, "analogInputArray02_4");
    auto mm = d4.memmaps();
    ASSERT_EQ(mm.size(), 2u);
    EXPECT_EQ(mm[0].name, "analogInputArray01");
    EXPECT_EQ(mm[0].first, "analogInputArray01_1");
    EXPECT_EQ(mm[0].count, 4);
    EXPECT_FALSE(mm[0].output);
    auto out = c.find("EL4732")->with_oversampling(3).memmaps();
    ASSERT_EQ(out.size(), 2u);
    EXPECT_EQ(out[1].name, "analogOutputArray02");
    EXPECT_TRUE(out[1].output);
    EXPECT_THROW((void)d->with_oversampling(101), Error);
    EXPECT_THROW((void)d->with_oversampling(0), Error);
    EXPECT_THROW((void)c.find("EL3104")->with_oversampling(2), Error);
    EXPECT_TRUE(c.find("EL3104")->memmaps().empty());
}

TEST(Oversampling, CatalogKeyErrorsNameTheChannel) {
    TempDir d;
    std::string base = R"(type: X3702
name: x
vendor: 2
product: 0x99
revision: 1
sync_managers:
  - {index: 0, start: 0x1000, control: 0x20, type: Inputs}
tx_pdos:
  - {index: 0x1a00, name: s, sm: 0, entries: [{index: 0x6000, sub: 1, bits: 16, name: a_1, datatype: INT16}]}
  - {index: 0x1a05, name: t, sm: 0, entries: [{index: 0x6000, sub: 2, bits: 16, name: b, datatype: INT16}]}
  - {index: 0x1a10, name: u, entries: [{index: 0x6000, sub: 3, bits: 16, name: c_1, datatype: INT16}]}
)";
    auto error_of = [&](const std::string& os) -> std::string {
        ethercat::Catalog c;
        try {
            c.load_yaml(d.write("x.yaml", base + os));
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    };
    EXPECT_EQ(error_of("oversampling: {max: 4, channels: [{pdo: 0x1a00, memmap: A}]}\n"), "");
    EXPECT_NE(error_of("oversampling: {max: 10, channels: [{pdo: 0x1a00, memmap: A}]}\n").find("PDO 0x1A05 would be sample 6"), std::string::npos)
        << error_of("oversampling: {max: 10, channels: [{pdo: 0x1a00, memmap: A}]}\n");
    EXPECT_NE(error_of("oversampling: {max: 4, channels: [{pdo: 0x1a05, memmap: B}]}\n").find("one entry named <channel>_1"), std::string::npos);
    EXPECT_NE(error_of("oversampling: {max: 4, channels: [{pdo: 0x1a10, memmap: C}]}\n").find("not a PDO assigned by default"), std::string::npos);
    EXPECT_NE(error_of("oversampling: {max: 1, channels: []}\n").find("at least 2"), std::string::npos);
    EXPECT_NE(error_of("oversampling: {max: 4, channels: [{pdo: 0x1a00}]}\n").find("memmap"), std::string::npos);
}

// The whole chain at factor 10: the master assigns 10 sample PDOs per channel (the terminal has
// no CoE: the SM lengths tell it the factor), DC SYNC0 every 100 us and SYNC1 the remaining
// 900 us; the simulator takes 10 samples across each cycle; the PLC reads and writes them by
// ECMC memory-map id; the waveforms show them.
TEST(Oversampling, MemMapsFromPlcAndPvs) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", R"(
        static.n := static.n + 1;
        static.size0 := ec_get_mm_size(0);
        static.size2 := ec_get_mm_size(2);
        static.type0 := ec_get_mm_type(0);
        for (var i := 0; i < 10; i += 1) {
            ec_set_mm_data(2, i, 1000 * i - 3000);     # EL4732 ch1, wired to EL3702 ch2
        };
        static.d1 := ec_get_mm_data(0, 1) - ec_get_mm_data(0, 0);  # ramp step between samples
        static.back7 := ec_get_mm_data(1, 7);          # what the EL4732 sent, sample 7
        ec_mm_cp(0, 3);                                 # EL3702 ch1 -> EL4732 ch2
        static.cp5 := ec_get_mm_data(3, 5) - ec_get_mm_data(0, 5);
        if (static.n == 20) { ec_mm_append_to_ds_scale_offset(1, 0, 2, 1); };
        if (static.n == 21) { static.ds_id := ds_get_buff_id(0); static.ds0 := ds_get_data(0, 0); static.ds9 := ds_get_data(0, 9); };
        static.bad := ec_get_mm_data(9, 0);  static.bad_err := ec_get_err();
        static.oor := ec_get_mm_data(0, 10); static.oor_err := ec_get_err();
        static.neg_type := ec_get_mm_type(-1);
        if (static.n == 30) { ec_mm_push_asyn(1); };
    )");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml(", oversampling: 10")));
    ethercat::sim::Segment& seg = *v.ioc->segment(0);
    EXPECT_EQ(seg.slave(1).oversampling(), 10u);
    EXPECT_EQ(seg.slave(2).oversampling(), 10u);
    EXPECT_EQ(seg.slave(1).sm_length(0), 2 + 10 * 2);
    const uint8_t* mem = seg.slave(1).memory();
    EXPECT_EQ(uint32_t(mem[0x9A0]) | uint32_t(mem[0x9A1]) << 8 | uint32_t(mem[0x9A2]) << 16 | uint32_t(mem[0x9A3]) << 24,
              100000u); // SYNC0 cycle [ns]
    EXPECT_EQ(uint32_t(mem[0x9A4]) | uint32_t(mem[0x9A5]) << 8 | uint32_t(mem[0x9A6]) << 16 | uint32_t(mem[0x9A7]) << 24,
              900000u); // SYNC1 cycle

    v.cycles(25);
    EXPECT_EQ(v.stat(0, "size0"), 10);
    EXPECT_EQ(v.stat(0, "size2"), 10);
    EXPECT_EQ(v.stat(0, "type0"), 8); // ECMC_EC_S16
    // A 100 Hz ramp of +-5 V sampled every 100 us rises 2 * 5 V * 100 Hz * 100 us = 0.1 V per
    // sample (327.67 digits), except where it wraps.
    EXPECT_NEAR(std::fmod(v.stat(0, "d1") + 65536, 65536), 327.67, 1.5) << v.stat(0, "d1");
    EXPECT_EQ(v.stat(0, "back7"), 1000 * 7 - 3000); // every sample crossed the wire
    EXPECT_EQ(v.stat(0, "cp5"), 0);                  // ec_mm_cp copied ch1's samples to the EL4732
    EXPECT_EQ(v.stat(0, "bad"), 0);
    EXPECT_EQ(v.stat(0, "bad_err"), 0x2002F); // ERROR_MAIN_MEM_MAP_NULL
    EXPECT_EQ(v.stat(0, "oor"), 0);
    EXPECT_EQ(v.stat(0, "oor_err"), 0x211002); // ERROR_MEM_INDEX_OUT_OF_RANGE
    EXPECT_EQ(v.stat(0, "neg_type"), -0x2002F);
    // ds0 got ch2's 10 samples, scaled and offset, in order
    EXPECT_EQ(v.stat(0, "ds_id"), 10);
    EXPECT_EQ(v.stat(0, "ds0"), 2 * -3000 + 1);
    EXPECT_EQ(v.stat(0, "ds9"), 2 * 6000 + 1);

    // The waveforms: EL3702 channel 2 shows the samples the EL4732 sent.
    v.ioc->publish();
    for (uint32_t k = 0; k < 10; ++k) EXPECT_EQ(pv_element(v, "T:m0s001-AI02-Arr", k), 1000.0 * k - 3000) << k;
    pv::Record* ai = v.ioc->database().find("T:m0s001-AI02-Arr");
    ASSERT_NE(ai, nullptr);
    EXPECT_EQ(ai->sevr, pv::kNoAlarm);
    EXPECT_TRUE(ai->val_read_only);
    ASSERT_NE(v.ioc->database().find("T:m0s002-AO01-Arr"), nullptr);
    ASSERT_NE(v.ioc->database().find("T:m0s001-AI01-Arr"), nullptr);
}

// A waveform put to an output memory map sends its samples; a slave that drops out turns the
// input waveform INVALID/COMM.
TEST(Oversampling, OutputWaveformPutAndInvalidInput) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "static.n := static.n + 1;\n");
    VirtualIoc v(d.write("ioc.yaml", ioc_yaml(", oversampling: 10")));
    v.cycles(5);
    pv::Address a;
    ASSERT_TRUE(v.ioc->database().resolve("T:m0s002-AO01-Arr", a));
    std::vector<double> samples;
    for (int k = 0; k < 10; ++k) samples.push_back(-100.0 * k);
    ASSERT_EQ(v.ioc->database().put(a, pv::Prim::Double, samples.data(), 10), pv::PutStatus::Ok);
    v.cycles(5);
    v.ioc->publish();
    for (uint32_t k = 0; k < 10; ++k) EXPECT_EQ(pv_element(v, "T:m0s001-AI02-Arr", k), -100.0 * k) << k;
    // power off the EL3702: its arrays go INVALID with COMM
    ethercat::sim::Segment& seg = *v.ioc->segment(0);
    ASSERT_TRUE(seg.post(ethercat::sim::parse_fault("power 1 off", ethercat::Catalog::builtin(), seg.size())));
    v.cycles(5);
    v.ioc->publish();
    pv::Record* ai = v.ioc->database().find("T:m0s001-AI02-Arr");
    EXPECT_EQ(ai->sevr, pv::kInvalid);
    EXPECT_EQ(ai->stat, pv::kStatComm);
}

TEST(Oversampling, BadFactorIsAConfigurationError) {
    TempDir d;
    d.write("plant.yaml", kPlant);
    d.write("main.plc", "static.n := 1;\n");
    rt::VirtualClock clock;
    try {
        ioc::Ioc ioc(config::IocConfig::load(d.write("ioc.yaml", ioc_yaml(", oversampling: 101"))), clock);
        FAIL() << "factor 101 accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("ioc.yaml:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("oversampling factor 101 should be 1..100"), std::string::npos) << e.what();
    }
}
