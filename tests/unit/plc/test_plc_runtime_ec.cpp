// The PLC runtime's process-data cells on a plain image (no bus): copy-in before and write-back
// after a scan only when the scan changed the value (ECMC's rule), single bits, REAL entries,
// signed entries; and PLCs that wait for the first cycle with every bus OK (acceptance 12).
#include "plc/runtime.hpp"

#include <gtest/gtest.h>

#include <cstring>

using namespace beamctl;

namespace {

struct Image {
    uint8_t bytes[16] = {};
    registry::BoundSignal at(uint32_t byte, uint8_t bits, bool is_signed = false) {
        registry::BoundSignal s;
        s.image = bytes;
        s.bit_offset = byte * 8;
        s.bits = bits;
        s.is_signed = is_signed;
        return s;
    }
};

struct Runtime {
    Image img;
    std::unique_ptr<plc::PlcRuntime> rt;
    uint64_t cycle = 0;
    Runtime(const std::string& code, std::vector<registry::BoundSignal> bus_ok = {}) {
        plc::PlcRuntime::Options o;
        o.bus_ok = std::move(bus_ok);
        o.ec = [this](const std::string& name, std::string& why) -> std::optional<plc::EcEntry> {
            if (name == "ec0.s1.out") return plc::EcEntry{img.at(0, 16), plc::EcEntry::Kind::Integer, true};
            if (name == "ec0.s1.in") return plc::EcEntry{img.at(2, 16, true), plc::EcEntry::Kind::Integer, false};
            if (name == "ec0.s1.real") return plc::EcEntry{img.at(4, 32), plc::EcEntry::Kind::Float32, true};
            why = "no entry " + name;
            return std::nullopt;
        };
        rt = std::make_unique<plc::PlcRuntime>(o);
        plc::PlcSource s;
        s.file = "t.plc";
        s.text = code;
        rt->add(s);
    }
    void cycles(int n) {
        for (int i = 0; i < n; ++i) rt->run(rt::CycleInfo{cycle++, 0, 1000000});
    }
    uint16_t out() const { uint16_t v; std::memcpy(&v, img.bytes, 2); return v; }
    double stat(const char* n) { return *rt->static_variable(0, n); }
};

} // namespace

TEST(PlcRuntimeEc, WritesBackOnlyWhatTheScanChanged) {
    Runtime r("if (plc0.firstscan) { ec0.s1.out := 3; };\nstatic.seen := ec0.s1.out;\n");
    r.cycles(1);
    EXPECT_EQ(r.out(), 3);
    uint16_t nine = 9;
    std::memcpy(r.img.bytes, &nine, 2); // another writer (a PV) changes the output
    r.cycles(5);
    EXPECT_EQ(r.out(), 9); // the PLC only read it: not written back
    EXPECT_EQ(r.stat("seen"), 9);
}

TEST(PlcRuntimeEc, BitsRealsAndSignedEntries) {
    Runtime r("ec0.s1.out.2 := 1;\nec0.s1.out.0 := 0;\nstatic.in := ec0.s1.in;\nstatic.bit := ec0.s1.in.15;\n"
              "static.real := ec0.s1.real;\nec0.s1.real := static.real * 2;\n");
    uint16_t out = 0x0101;
    std::memcpy(r.img.bytes, &out, 2);
    int16_t in = -300;
    std::memcpy(r.img.bytes + 2, &in, 2);
    float f = 1.5f;
    std::memcpy(r.img.bytes + 4, &f, 4);
    r.cycles(1);
    EXPECT_EQ(r.out(), 0x0104);
    EXPECT_EQ(r.stat("in"), -300);
    EXPECT_EQ(r.stat("bit"), 1);
    EXPECT_EQ(r.stat("real"), 1.5);
    std::memcpy(&f, r.img.bytes + 4, 4);
    EXPECT_EQ(f, 3.0f);
}

TEST(PlcRuntimeEc, InputsAreReadOnlyAndUnknownEntriesSayWhy) {
    try {
        Runtime r("ec0.s1.in := 1;\nstatic.x := ec0.s1.nothing;\n");
        FAIL();
    } catch (const plc::CompileError& e) {
        ASSERT_EQ(e.errors().size(), 2u);
        EXPECT_NE(e.errors()[0].find("t.plc:1:1: 'ec0.s1.in' is read-only"), std::string::npos) << e.errors()[0];
        EXPECT_NE(e.errors()[1].find("unknown name 'ec0.s1.nothing': no entry ec0.s1.nothing"), std::string::npos) << e.errors()[1];
    }
}

// Acceptance 12 (PLC part): PLCs wait for the first cycle in which every bus is OK, then run
// whatever the bus state.
TEST(PlcRuntimeEc, PlcsWaitForTheFirstBusOk) {
    Image status;
    Runtime r("static.n := static.n + 1;\n", {status.at(0, 8)});
    r.cycles(5);
    EXPECT_EQ(r.rt->status(0).scans, 0u);
    status.bytes[0] = 1;
    r.cycles(5);
    EXPECT_EQ(r.stat("n"), 5);
    status.bytes[0] = 0;
    r.cycles(5);
    EXPECT_EQ(r.stat("n"), 10);
}
