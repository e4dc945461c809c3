// Data storage in PLC code (ECMC's ds<n>.* variables and ds_* functions) on real storages, in
// virtual time: appends by function and by variable (every scan that assigns appends, as ECMC),
// clear, index, data, size, full, errors of bad ids, and what `plc check` accepts.
#include "plc/runtime.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;

namespace {

struct Runtime {
    daq::DataStorage ds0{0, 4, daq::BufferType::Normal, 8};
    daq::DataStorage ds2{2, 3, daq::BufferType::Ring};
    std::unique_ptr<plc::PlcRuntime> rt;
    uint64_t cycle = 0;
    explicit Runtime(const std::string& code) {
        plc::PlcRuntime::Options o;
        o.storages = {&ds0, &ds2};
        rt = std::make_unique<plc::PlcRuntime>(o);
        plc::PlcSource s;
        s.file = "t.plc";
        s.text = code;
        rt->add(s);
    }
    void cycles(int n) {
        for (int i = 0; i < n; ++i) rt->run(rt::CycleInfo{cycle++, 0, 1000000});
    }
    double stat(const char* n) { return *rt->static_variable(0, n); }
};

std::string compile_error(const std::string& code, plc::PlcRuntime::Options o) {
    plc::PlcRuntime rt(o);
    plc::PlcSource s;
    s.file = "t.plc";
    s.text = code;
    try {
        rt.add(s);
    } catch (const plc::CompileError& e) {
        return e.what();
    }
    return "<none>";
}

} // namespace

TEST(PlcDataStorage, FunctionsAppendReadAndReport) {
    Runtime r("static.n += 1;\n"
              "static.err := ds_append_data(0, static.n * 10);\n"
              "static.full := ds_is_full(0);\n"
              "static.size := ds_get_size(0);\n"
              "static.id := ds_get_buff_id(0);\n"
              "static.first := ds_get_data(0, 0);\n"
              "static.avg := ds_get_avg(0);\n"
              "static.max := ds_get_max(2);\n"
              "ds_append_data(2, static.n);\n");
    r.cycles(3);
    EXPECT_EQ(r.stat("err"), 0);
    EXPECT_EQ(r.stat("full"), 0);
    EXPECT_EQ(r.stat("size"), 4);
    EXPECT_EQ(r.stat("id"), 3);
    EXPECT_EQ(r.stat("first"), 10);
    EXPECT_EQ(r.stat("avg"), 20);
    EXPECT_EQ(r.stat("max"), 2); // ds2 before this scan's append
    r.cycles(2);
    EXPECT_EQ(r.stat("full"), 1);
    EXPECT_EQ(r.ds0.count(), 4u);
    EXPECT_EQ(r.ds0.data()[3], 40);
    EXPECT_EQ(r.ds2.data()[0], 4); // ring: 1 2 3, then 4 over 1
}

TEST(PlcDataStorage, VariablesActOnlyWhenTheScanAssignsThem) {
    Runtime r("if (plc0.firstscan) { ds0.index := 1; ds0.data := 7; };\n"
              "ds0.append := 5;\n"            // every scan appends (its read is NaN)
              "static.idx := ds0.index;\n"
              "static.full := ds0.full;\n"
              "static.size := ds0.size;\n"
              "static.appendRead := ds0.append;\n");
    r.cycles(1);
    // the index write, the element write at index 1 and the append apply after the scan, in
    // the order the code names them: index 1, data[1] = 7, then append at 1 (overwrites it)
    EXPECT_EQ(r.ds0.data()[1], 5);
    EXPECT_EQ(r.ds0.index(), 2u);
    EXPECT_EQ(r.stat("idx"), 1); // what the code assigned, within the scan
    EXPECT_EQ(r.stat("size"), 4);
    r.cycles(2);
    EXPECT_EQ(r.ds0.index(), 4u);
    EXPECT_EQ(r.ds0.data()[3], 5);
    EXPECT_EQ(r.stat("full"), 0); // read before the scan's append filled it
    r.cycles(1);
    // as ECMC, `full` counts the values written (3: the first scan started at index 1), not
    // the index: the buffer ends at its last slot without ever reporting full
    EXPECT_EQ(r.ds0.count(), 3u);
    EXPECT_EQ(r.stat("full"), 0);
    EXPECT_EQ(r.stat("appendRead"), 5);
}

TEST(PlcDataStorage, ClearSizeAndErrors) {
    Runtime r("ds_append_data(0, 1);\n"
              "if (static.n == 2) { ds0.clear := 1; };\n"
              "if (static.n == 3) { ds0.size := 6; };\n"
              "if (static.n == 4) { ds0.size := 9; };\n" // over the capacity 8: refused
              "static.n += 1;\n"
              "static.bad := ds_append_data(5, 1);\n"    // no storage 5
              "static.badErr := ds_get_err();\n"
              "static.range := ds_get_size(40);\n"
              "static.rangeErr := ds_get_err();\n"
              "static.dsErr := ds0.error;\n");
    r.cycles(3);
    EXPECT_EQ(r.ds0.count(), 0u); // cleared after the third scan's append
    EXPECT_EQ(r.stat("bad"), 0x2050A);
    EXPECT_EQ(r.stat("badErr"), 0x2050A);
    EXPECT_EQ(r.stat("range"), -1);
    EXPECT_EQ(r.stat("rangeErr"), 0x20509);
    r.cycles(2);
    EXPECT_EQ(r.ds0.size(), 6u);
    EXPECT_EQ(r.ds0.error(), daq::ds_error::kSizeOverCapacity);
    r.cycles(1);
    EXPECT_EQ(r.stat("dsErr"), double(daq::ds_error::kSizeOverCapacity));
}

TEST(PlcDataStorage, AppendToDsCopiesABlock) {
    Runtime r("if (plc0.firstscan) {\n"
              "  ds_append_data(0, 1); ds_append_data(0, 2); ds_append_data(0, 3);\n"
              "  static.r := ds_append_to_ds(0, 1, 10, 2);\n" // elements clamped to 3 - 1
              "  static.bad := ds_append_to_ds(0, 4, 1, 2);\n"
              "};\n");
    r.cycles(1);
    EXPECT_EQ(r.stat("r"), 0);
    EXPECT_EQ(r.stat("bad"), 0x20203);
    EXPECT_EQ(r.ds2.count(), 3u); // the clamp counts to the storage's size: 2, 3, and 0
    EXPECT_EQ(r.ds2.data()[0], 2);
    EXPECT_EQ(r.ds2.data()[1], 3);
}

TEST(PlcDataStorage, NamesAreCheckedAgainstTheStorages) {
    plc::PlcRuntime::Options o;
    daq::DataStorage ds0(0, 4, daq::BufferType::Normal);
    o.storages = {&ds0};
    EXPECT_NE(compile_error("ds1.append := 1;", o).find("no data storage 1 (storages: 0)"), std::string::npos)
        << compile_error("ds1.append := 1;", o);
    EXPECT_NE(compile_error("ds0.appnd := 1;", o).find("'appnd' is not one of append, data"), std::string::npos);
    EXPECT_NE(compile_error("ds0.full := 1;", o).find("read-only"), std::string::npos);
    plc::PlcRuntime::Options check;
    check.check_only = true; // `beamctl plc check` without an IOC: any ds0..ds31
    EXPECT_EQ(compile_error("ds31.append := ds_get_size(31);", check), "<none>");
    EXPECT_NE(compile_error("ds32.append := 1;", check).find("out of range (ds0..ds31)"), std::string::npos);
    check.known_storage_ids = std::vector<int>{3};
    EXPECT_NE(compile_error("ds1.append := 1;", check).find("no data storage 1 (storages: 3)"), std::string::npos);
}

TEST(PlcEpicsState, StartedOnceTheIocRuns) {
    Runtime r("static.started := epics_get_started();\nstatic.state := epics_get_state();\n");
    r.cycles(1);
    EXPECT_EQ(r.stat("started"), 0);
    r.rt->set_epics_state(16); // initHookAfterIocRunning
    r.cycles(1);
    EXPECT_EQ(r.stat("started"), 1);
    EXPECT_EQ(r.stat("state"), 16);
}
