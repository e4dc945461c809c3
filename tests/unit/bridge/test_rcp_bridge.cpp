// The IOC side of the RCP bridge in virtual time: beacons build records (and the .db file),
// continuations, data updates, writes laid out byte by byte, malformed input that changes no
// PV, beacon changes, silence -> INVALID/COMM and recovery, several applications, diagnostics,
// data ports, and no allocation on the steady-state data path.
#include "rcp_harness.hpp"

#include "../alloc_counter.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/db_file.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {

using OT = ObjectType;
using DT = DataType;

std::vector<BeaconObject> standard() {
    return {obj(1, OT::AI, DT::Float64, "Temp"),     obj(2, OT::AO, DT::Float64, "Set"),
            obj(3, OT::BI, DT::Bool, "Ok"),          obj(4, OT::BO, DT::Bool, "Valve"),
            obj(5, OT::LI, DT::Int32, "Count"),      obj(6, OT::LO, DT::Int16, "Mode"),
            obj(7, OT::Motor, DT::Float64, "Stage"), obj(8, OT::AI, DT::Float32, "Spec")};
}

std::string temp_path(const std::string& name) {
    auto p = std::filesystem::temp_directory_path() /
             ("beamctl_rcp_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::remove(p);
    return p.string();
}

std::vector<std::string> db_file_records(const std::string& path, std::string* types = nullptr) {
    pv::DbFile f = pv::load_db_file(path, {});
    std::vector<std::string> names;
    for (const auto& r : f.records) {
        names.push_back(r.name);
        if (types) *types += r.name + "=" + r.type + " ";
    }
    return names;
}

bool contains(const std::vector<std::string>& v, const std::string& s) {
    return std::find(v.begin(), v.end(), s) != v.end();
}

struct Removed : pv::RecordObserver {
    int count = 0;
    void on_record_removed(pv::Record&) override { ++count; }
};

} // namespace

TEST(RcpBridge, BeaconCreatesRecordsOfEachObjectType) {
    Harness h;
    h.feed(beacon("app", standard()));
    EXPECT_TRUE(h.exists("T:app:RxCount")) << "diagnostics appear with the application";
    EXPECT_TRUE(h.exists("T:app:Temp")) << "a new application's objects appear at once";
    h.advance(0.15);
    EXPECT_EQ(h.type("T:app:Temp"), "ai");
    EXPECT_EQ(h.type("T:app:Set"), "ao");
    EXPECT_EQ(h.type("T:app:Set_RBV"), "ai");
    EXPECT_EQ(h.type("T:app:Ok"), "bi");
    EXPECT_EQ(h.type("T:app:Valve"), "bo");
    EXPECT_EQ(h.type("T:app:Valve_RBV"), "bi");
    EXPECT_EQ(h.type("T:app:Count"), "longin");
    EXPECT_EQ(h.type("T:app:Mode"), "longout");
    EXPECT_EQ(h.type("T:app:Mode_RBV"), "longin");
    EXPECT_EQ(h.type("T:app:Stage"), "motor");
    EXPECT_EQ(h.type("T:app:Stage_PosErr"), "ai");
    EXPECT_EQ(h.type("T:app:Stage_ErrCode"), "longin");
    EXPECT_EQ(h.type("T:app:Spec"), "ai") << "a scalar until data shows a count";
    EXPECT_FALSE(h.exists("T:app:Temp_RBV"));
    EXPECT_EQ(h.alarm("T:app:Temp"), "INVALID/UDF");
    EXPECT_EQ(h.str("T:app:Temp.DESC"), "RCP app AI 1");
    EXPECT_FALSE(h.addr("T:app:Temp").writable()) << "inputs belong to the RCP";
    EXPECT_FALSE(h.addr("T:app:Set_RBV").writable());
    EXPECT_TRUE(h.addr("T:app:Set").writable());
    EXPECT_TRUE(h.addr("T:app:Stage").writable());
    EXPECT_EQ(h.get("T:app:Objects"), 8);
    EXPECT_EQ(h.get("T:Applications"), 1);
    EXPECT_TRUE(h.sent.empty());
}

TEST(RcpBridge, WritesTheGeneratedDbFile) {
    auto cfg = Harness::config();
    cfg.db_out = temp_path("gen.db");
    Harness h(cfg);
    h.announce("app", standard());
    std::string types;
    auto names = db_file_records(cfg.db_out, &types);
    for (const char* n : {"T:RxCount", "T:Malformed-Short", "T:app:RxCount", "T:app:Online",
                          "T:app:Temp", "T:app:Set", "T:app:Set_RBV", "T:app:Stage",
                          "T:app:Stage_PosErr", "T:app:Malformed-TypeMismatch"})
        EXPECT_TRUE(contains(names, n)) << n << " in " << types;
    EXPECT_NE(types.find("T:app:Stage=motor"), std::string::npos);
    EXPECT_EQ(names.size(), h.db.size()) << "the file lists every record the bridge made";
    std::ifstream f(cfg.db_out);
    std::stringstream ss;
    ss << f.rdbuf();
    EXPECT_NE(ss.str().find("info(rcp, \"app 7 MOTOR float64\")"), std::string::npos);
    EXPECT_NE(ss.str().find("field(OUT, \"@rcp(app,7)\")"), std::string::npos);
    std::filesystem::remove(cfg.db_out);
}

TEST(RcpBridge, ContinuationsJoinTheBeaconWithinTheWindow) {
    Harness h;
    std::vector<BeaconObject> objs;
    for (int i = 1; i <= 20; ++i)
        objs.push_back(obj(uint8_t(i), OT::AI, DT::Float64, std::string("s").append(std::to_string(i))));
    std::vector<BeaconObject> first(objs.begin(), objs.begin() + 17),
        rest(objs.begin() + 17, objs.end());
    h.feed(beacon("app", first));
    EXPECT_FALSE(h.exists("T:app:s18"));
    h.t += 0.05;
    h.feed(beacon("app", rest, true));
    EXPECT_TRUE(h.exists("T:app:s18")) << "added at once";
    h.advance(0.1);
    for (int i = 1; i <= 20; ++i) EXPECT_TRUE(h.exists("T:app:s" + std::to_string(i))) << i;
    EXPECT_EQ(h.get("T:app:Objects"), 20);
    // The next round: the beacon alone does not retire what its continuation will repeat.
    h.advance(1);
    h.feed(beacon("app", first));
    h.advance(0.05);
    EXPECT_TRUE(h.exists("T:app:s18"));
    h.feed(beacon("app", rest, true));
    h.advance(0.1);
    EXPECT_TRUE(h.exists("T:app:s18"));

    // A continuation repeating an object of its beacon is refused as a whole.
    h.advance(1);
    h.feed(beacon("app", first));
    std::vector<BeaconObject> dup = rest;
    dup.push_back(obj(1, OT::AI, DT::Float64, "again"));
    h.feed(beacon("app", dup, true));
    EXPECT_EQ(h.core->applications()[0].counters.malformed[size_t(Malformed::DuplicateObject)], 1u);
    h.advance(0.15);
    EXPECT_FALSE(h.exists("T:app:s18")) << "the model is the beacon alone now";
    EXPECT_FALSE(h.exists("T:app:again"));

    // A continuation later than the window is not part of the model.
    h.advance(1);
    h.feed(beacon("app", first));
    h.advance(0.15);
    h.t += 0.05;
    h.feed(beacon("app", rest, true));
    h.advance(0.15);
    EXPECT_FALSE(h.exists("T:app:s18"));
    EXPECT_TRUE(h.exists("T:app:s17"));
}

TEST(RcpBridge, DataUpdatesInputsAndReadbacks) {
    Harness h;
    h.announce("app", standard());
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {21.5}},
                 {2, OT::AO, DT::Float64, "Set", {3.25}},
                 {3, OT::BI, DT::Bool, "Ok", {1}},
                 {4, OT::BO, DT::Bool, "Valve", {1}},
                 {5, OT::LI, DT::Int32, "Count", {-7}},
                 {6, OT::LO, DT::Int16, "Mode", {2}}}));
    EXPECT_EQ(h.get("T:app:Temp"), 21.5);
    EXPECT_EQ(h.alarm("T:app:Temp"), "NO_ALARM/NO_ALARM");
    EXPECT_NE(h.db.find("T:app:Temp")->time.sec, 0u) << "stamped on arrival";
    EXPECT_EQ(h.get("T:app:Ok"), 1);
    EXPECT_EQ(h.str("T:app:Ok"), "On");
    EXPECT_EQ(h.get("T:app:Count"), -7);
    EXPECT_EQ(h.get("T:app:Set_RBV"), 3.25);
    EXPECT_EQ(h.get("T:app:Set"), 3.25) << "the setpoint starts at the RCP's value";
    EXPECT_EQ(h.get("T:app:Valve_RBV"), 1);
    EXPECT_EQ(h.get("T:app:Mode_RBV"), 2);
    EXPECT_TRUE(h.sent.empty()) << "initialising a setpoint from its readback sends nothing";
    h.feed(data({{2, OT::AO, DT::Float64, "Set", {4}}, {1, OT::AI, DT::Float64, "Temp", {22}}}));
    EXPECT_EQ(h.get("T:app:Set_RBV"), 4);
    EXPECT_EQ(h.get("T:app:Set"), 3.25) << "after that the setpoint is the operator's";
    EXPECT_EQ(h.get("T:app:Temp"), 22);
    // A BI of a non-bool data type: any non-zero value is 1.
    Harness g;
    g.announce("app", {obj(1, OT::BI, DT::UInt8, "B")});
    g.feed(data({{1, OT::BI, DT::UInt8, "B", {7}}}));
    EXPECT_EQ(g.get("T:app:B"), 1);
}

TEST(RcpBridge, WaveformsFollowTheCountOfTheFirstData) {
    auto cfg = Harness::config();
    cfg.db_out = temp_path("wf.db");
    Harness h(cfg);
    h.announce("app", {obj(8, OT::AI, DT::Float32, "Spec"), obj(9, OT::AO, DT::Float64, "Gains"),
                       obj(10, OT::LI, DT::Int16, "Hist")});
    EXPECT_EQ(h.type("T:app:Spec"), "ai");
    h.feed(data({{8, OT::AI, DT::Float32, "Spec", {1, 2, 3, 4, 5, 6, 7, 8}},
                 {9, OT::AO, DT::Float64, "Gains", {0.5, 1.5, 2.5}},
                 {10, OT::LI, DT::Int16, "Hist", {-1, 2}}}));
    EXPECT_EQ(h.type("T:app:Spec"), "waveform");
    EXPECT_EQ(h.str("T:app:Spec.FTVL"), "DOUBLE");
    EXPECT_EQ(h.get("T:app:Spec.NELM"), 8);
    EXPECT_EQ(h.get_array("T:app:Spec"), (std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8}));
    EXPECT_EQ(h.type("T:app:Gains"), "waveform");
    EXPECT_EQ(h.type("T:app:Gains_RBV"), "waveform");
    EXPECT_EQ(h.get_array("T:app:Gains_RBV"), (std::vector<double>{0.5, 1.5, 2.5}));
    EXPECT_EQ(h.get_array("T:app:Gains"), (std::vector<double>{0.5, 1.5, 2.5}));
    EXPECT_EQ(h.str("T:app:Hist.FTVL"), "LONG");
    EXPECT_EQ(h.get_array("T:app:Hist"), (std::vector<double>{-1, 2}));
    std::string types;
    db_file_records(cfg.db_out, &types);
    EXPECT_NE(types.find("T:app:Spec=waveform"), std::string::npos) << "the .db file is rewritten";

    // The count is fixed from now on.
    h.feed(data({{8, OT::AI, DT::Float32, "Spec", {9, 9, 9, 9}}}));
    EXPECT_EQ(h.get_array("T:app:Spec")[0], 1);
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::CountMismatch)], 1u);

    // A waveform setpoint sends all its values.
    double v[3] = {7, 8, 9};
    ASSERT_EQ(h.db.put(h.addr("T:app:Gains"), pv::Prim::Double, v, 3), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    DataPacket d;
    const DataEntry& e = h.sent_entry(0, d);
    EXPECT_EQ(e.count, 3);
    EXPECT_EQ(std::vector<double>(e.values.begin(), e.values.end()),
              (std::vector<double>{7, 8, 9}));
    std::filesystem::remove(cfg.db_out);
}

TEST(RcpBridge, WritesSendOnePacketToTheObjectsAddress) {
    Harness h;
    h.announce("app", standard());
    ASSERT_EQ(h.put("T:app:Set", 1.5), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    EXPECT_EQ(h.sent[0].to, (Endpoint{kRcpIp, 18066}));
    const auto& b = h.sent[0].bytes;
    ASSERT_EQ(b.size(), 1000u);
    // timestamp: the RCP's model time of its latest packet (the beacon's 1.0)
    EXPECT_EQ(std::vector<uint8_t>(b.begin(), b.begin() + 8),
              (std::vector<uint8_t>{0, 0, 0, 0, 0, 0, 0xf0, 0x3f}));
    EXPECT_EQ(b[8], 2);  // object id
    EXPECT_EQ(b[9], 2);  // AO
    EXPECT_EQ(b[10], 8); // float64
    EXPECT_EQ(b[11], 1); // count
    EXPECT_EQ(b[12], 0);
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(&b[13])), "Set");
    EXPECT_EQ(std::vector<uint8_t>(b.begin() + 53, b.begin() + 61),
              (std::vector<uint8_t>{0, 0, 0, 0, 0, 0, 0xf8, 0x3f}));
    EXPECT_EQ(std::count(b.begin() + 61, b.end(), 0), 1000 - 61) << "end byte and zero padding";

    ASSERT_EQ(h.put("T:app:Valve", 1), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 2u);
    EXPECT_EQ(h.sent[1].bytes[9], 4);
    EXPECT_EQ(h.sent[1].bytes[10], 0);
    EXPECT_EQ(h.sent[1].bytes[53], 1);
    EXPECT_EQ(h.sent[1].bytes[54], 0);

    ASSERT_EQ(h.put("T:app:Mode", 300), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 3u);
    EXPECT_EQ(h.sent[2].bytes[53], 0x2c);
    EXPECT_EQ(h.sent[2].bytes[54], 0x01);
    EXPECT_EQ(h.sent[2].bytes[55], 0) << "int16: two bytes, then the end";

    // A value the data type cannot carry is refused and nothing is sent.
    EXPECT_EQ(h.put("T:app:Mode", 40000), pv::PutStatus::BadValue);
    EXPECT_EQ(h.sent.size(), 3u);
    EXPECT_EQ(h.get("T:app:Mode"), 300);

    // DRVH/DRVL apply to what is sent.
    ASSERT_EQ(h.put("T:app:Set.DRVH", 2), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:app:Set.DRVL", -2), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:app:Set", 5), pv::PutStatus::Ok);
    DataPacket d;
    EXPECT_EQ(h.sent_entry(3, d).values[0], 2);
    EXPECT_EQ(h.get("T:app:Set"), 2);

    // A failed send fails the put.
    h.send_ok = false;
    EXPECT_EQ(h.put("T:app:Set", 1), pv::PutStatus::Failed);
    EXPECT_EQ(h.get("T:app:Set"), 2);
    h.advance(1);
    EXPECT_EQ(h.get("T:app:TxCount"), 4);
    EXPECT_EQ(h.get("T:TxCount"), 4);
}

TEST(RcpBridge, ZeroAddressInTheBeaconMeansItsSource) {
    Harness h;
    auto o = obj(2, OT::AO, DT::Float64, "Set");
    o.ip_rcp = 0;
    o.port_rcp = 0;
    h.announce("app", {o});
    ASSERT_EQ(h.put("T:app:Set", 1), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    EXPECT_EQ(h.sent[0].to, kRcp);
}

TEST(RcpBridge, MalformedInputNeverChangesAPv) {
    Harness h;
    h.announce("app", standard());
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {1}}, {5, OT::LI, DT::Int32, "Count", {10}}}));
    auto app_count = [&](Malformed m) {
        return h.core->applications()[0].counters.malformed[size_t(m)];
    };
    auto unchanged = [&](const char* what) {
        EXPECT_EQ(h.get("T:app:Temp"), 1) << what;
        EXPECT_EQ(h.get("T:app:Count"), 10) << what;
    };
    Packet good = data({{1, OT::AI, DT::Float64, "Temp", {5}}});
    h.feed_bytes(std::vector<uint8_t>(good.begin(), good.begin() + 500));
    unchanged("short");
    EXPECT_EQ(app_count(Malformed::Short), 1u) << "attributed by its source address";
    h.feed(data({{1, OT::AO, DT::Float64, "Temp", {5}}}));
    unchanged("object type");
    h.feed(data({{1, OT::AI, DT::Float32, "Temp", {5}}}));
    unchanged("data type");
    EXPECT_EQ(app_count(Malformed::TypeMismatch), 2u);
    h.feed(data({{1, OT::AI, DT::Float64, "Tmp", {5}}}));
    unchanged("name");
    EXPECT_EQ(app_count(Malformed::NameMismatch), 1u);
    h.feed(data({{99, OT::AI, DT::Float64, "Temp", {5}}}));
    unchanged("unknown id");
    EXPECT_EQ(app_count(Malformed::UnknownObject), 1u);
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {5, 6}}}));
    unchanged("count");
    EXPECT_EQ(app_count(Malformed::CountMismatch), 1u);
    // One bad entry refuses the whole packet.
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {5}},
                 {5, OT::LI, DT::Int32, "Count", {11}},
                 {3, OT::BI, DT::Int8, "Ok", {1}}}));
    unchanged("second entry");
    EXPECT_EQ(app_count(Malformed::TypeMismatch), 3u);
    // Structural faults.
    Packet bad = good;
    bad[9] = 42;
    h.feed(bad);
    unchanged("unknown type");
    EXPECT_EQ(app_count(Malformed::UnknownType), 1u);
    bad = good;
    bad[11] = 0xFF;
    bad[12] = 0x7F;
    h.feed(bad);
    unchanged("count overflow");
    EXPECT_EQ(app_count(Malformed::CountOverflow), 1u);
    bad = good;
    std::memset(&bad[13], 'x', 40);
    h.feed(bad);
    unchanged("unterminated name");
    EXPECT_EQ(app_count(Malformed::UnterminatedName), 1u);
    Packet wrong = beacon("app", standard());
    wrong[8] = 3;
    h.feed(wrong);
    EXPECT_EQ(app_count(Malformed::WrongVersion), 1u);
    // From an address without an application: data before its beacon, not malformed.
    h.feed(good, Endpoint{0x0A000063, 5000});
    unchanged("unknown source");
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::UnknownApplication)], 0u);
    EXPECT_EQ(h.core->totals().before_beacon, 1u);
    // A beacon refused (its name is taken by another address) is.
    std::vector<BeaconObject> same_names = standard();
    for (auto& o : same_names) o.ip_rcp = 0; // (naming 10.0.0.2 for writes would be refused first)
    h.feed(beacon("app", same_names), Endpoint{0x0A000063, 5000});
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::UnknownApplication)], 1u);
    h.advance(1);
    EXPECT_EQ(h.get("T:app:Malformed-TypeMismatch"), 3);
    EXPECT_EQ(h.get("T:Malformed-TypeMismatch"), 3);
    EXPECT_EQ(h.get("T:Malformed-UnknownApplication"), 1);
    EXPECT_EQ(h.get("T:DataBeforeBeacon"), 1);
    EXPECT_FALSE(h.exists("T:app:Malformed-UnknownApplication"))
        << "never attributed to an application";
    EXPECT_EQ(h.alarm("T:app:Temp"), "NO_ALARM/NO_ALARM");
    // And the good packet still works.
    h.feed(good);
    EXPECT_EQ(h.get("T:app:Temp"), 5);
}

TEST(RcpBridge, MalformedPacketsAreLoggedAtMostOncePerSecondPerReason) {
    Harness h;
    h.announce("app", standard());
    Packet good = data({{1, OT::AI, DT::Float64, "Temp", {5}}});
    std::vector<uint8_t> shorty(good.begin(), good.begin() + 100);
    beamctl::log::configure("rcp=warn"); // whatever BEAMCTL_LOG says
    testing::internal::CaptureStderr();
    for (int i = 0; i < 50; ++i) h.feed_bytes(shorty);
    h.feed(data({{1, OT::AO, DT::Float64, "Temp", {5}}}));
    h.t += 0.5;
    for (int i = 0; i < 10; ++i) h.feed_bytes(shorty);
    h.t += 0.6;
    h.feed_bytes(shorty);
    std::string text = testing::internal::GetCapturedStderr();
    beamctl::log::configure(); // back to BEAMCTL_LOG
    auto count = [&](const std::string& s) {
        std::size_t n = 0;
        for (std::size_t at = text.find(s); at != std::string::npos; at = text.find(s, at + 1)) ++n;
        return n;
    };
    EXPECT_EQ(count(": Short at byte 100"), 2u) << text;
    EXPECT_EQ(count("59 more since the last report"), 1u) << text;
    EXPECT_EQ(count("TypeMismatch at byte 9"), 1u) << text;
    EXPECT_NE(text.find("10.0.0.2:5000 (application app)"), std::string::npos) << text;
    EXPECT_NE(
        text.find("entry object 1 'Temp' AO/float64 count 1, the beacon has 'Temp' AI/float64"),
        std::string::npos)
        << text;
}

TEST(RcpBridge, ChangedBeaconAddsRetiresAndRewritesTheDb) {
    auto cfg = Harness::config();
    cfg.db_out = temp_path("change.db");
    Harness h(cfg);
    h.announce("app", {obj(1, OT::AI, DT::Float64, "Temp"), obj(2, OT::AO, DT::Float64, "Set"),
                       obj(3, OT::BI, DT::Bool, "Ok")});
    pv::Record* set = h.db.find("T:app:Set");
    Removed removed;
    h.db.observe(*h.db.find("T:app:Temp"), removed);
    EXPECT_TRUE(contains(db_file_records(cfg.db_out), "T:app:Temp"));

    // The same beacon again changes nothing and does not rewrite the file.
    std::filesystem::remove(cfg.db_out);
    h.advance(1);
    h.announce("app", {obj(1, OT::AI, DT::Float64, "Temp"), obj(2, OT::AO, DT::Float64, "Set"),
                       obj(3, OT::BI, DT::Bool, "Ok")});
    EXPECT_FALSE(std::filesystem::exists(cfg.db_out));
    EXPECT_EQ(removed.count, 0);

    h.advance(1);
    h.announce("app", {obj(2, OT::AO, DT::Float64, "Set"), obj(3, OT::BO, DT::Bool, "Ok"),
                       obj(9, OT::LI, DT::Int32, "New")});
    EXPECT_EQ(removed.count, 1) << "clients of a retired PV are disconnected";
    EXPECT_FALSE(h.exists("T:app:Temp"));
    EXPECT_EQ(h.db.find("T:app:Set"), set) << "an unchanged object keeps its record";
    EXPECT_EQ(h.type("T:app:Ok"), "bo");
    EXPECT_TRUE(h.exists("T:app:Ok_RBV"));
    EXPECT_EQ(h.type("T:app:New"), "longin");
    EXPECT_EQ(h.get("T:app:Objects"), 3);
    auto names = db_file_records(cfg.db_out);
    EXPECT_FALSE(contains(names, "T:app:Temp"));
    EXPECT_TRUE(contains(names, "T:app:New"));
    EXPECT_TRUE(contains(names, "T:app:Ok_RBV"));
    // Data for the retired object is now refused.
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {1}}}));
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::UnknownObject)], 1u);
    std::filesystem::remove(cfg.db_out);
}

TEST(RcpBridge, ChangedObjectsChangeWhenTheWindowClosesAndTheirEarlyDataIsDropped) {
    Harness h;
    h.announce("app", {obj(1, OT::AI, DT::Float64, "Temp"), obj(3, OT::BI, DT::Bool, "Ok")});
    h.advance(1);
    h.feed(beacon("app", {obj(1, OT::AI, DT::Float64, "Temp"), obj(3, OT::BO, DT::Bool, "Ok"),
                          obj(4, OT::AI, DT::Float64, "Temp2"), obj(5, OT::AI, DT::Float64, "T.x"),
                          obj(6, OT::AI, DT::Float64, "T_x")}));
    EXPECT_EQ(h.type("T:app:Ok"), "bi") << "a changed object waits for the end of the window";
    EXPECT_TRUE(h.exists("T:app:Temp2")) << "a new one does not";
    // Data in the new shape before the window closes: dropped, not malformed; the rest applies.
    h.feed(data({{3, OT::BO, DT::Bool, "Ok", {1}}, {4, OT::AI, DT::Float64, "Temp2", {2}}}));
    EXPECT_EQ(h.get("T:app:Temp2"), 2);
    h.advance(0.15);
    EXPECT_EQ(h.type("T:app:Ok"), "bo");
    EXPECT_EQ(h.alarm("T:app:Ok_RBV"), "INVALID/UDF");
    for (uint64_t n : h.core->totals().malformed) EXPECT_EQ(n, 0u);
    // Two objects with one PV name ('.' becomes '_'): the later one gets no PVs.
    EXPECT_EQ(h.get("T:app:Objects"), 5);
    h.feed(data({{5, OT::AI, DT::Float64, "T.x", {7}}, {6, OT::AI, DT::Float64, "T_x", {8}}}));
    EXPECT_EQ(h.get("T:app:T_x"), 7);
}

TEST(RcpBridge, SilenceMakesEveryPvInvalidCommUntilTheNextPacket) {
    Harness h;
    h.announce("app", standard());
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {1}},
                 {2, OT::AO, DT::Float64, "Set", {2}},
                 {7, OT::Motor, DT::Float64, "Stage", {0, 0, 1 | 64, 0, 0}}}));
    h.advance(1);
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
    h.advance(1.9); // 2.9 s of silence
    EXPECT_EQ(h.alarm("T:app:Temp"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.get("T:app:Online"), 1);
    h.advance(0.15);
    for (const char* pv :
         {"T:app:Temp", "T:app:Set", "T:app:Set_RBV", "T:app:Ok", "T:app:Valve", "T:app:Valve_RBV",
          "T:app:Count", "T:app:Mode", "T:app:Mode_RBV", "T:app:Spec", "T:app:Stage",
          "T:app:Stage_PosErr", "T:app:Stage_ErrCode"})
        EXPECT_EQ(h.alarm(pv), "INVALID/COMM") << pv;
    EXPECT_EQ(h.get("T:app:Temp"), 1) << "values stay";
    EXPECT_EQ(h.get("T:app:Online"), 0);
    EXPECT_FALSE(h.core->applications()[0].online);
    EXPECT_EQ(h.alarm("T:app:RxCount"), "NO_ALARM/NO_ALARM") << "diagnostics describe the link";
    // Writes are refused (test_rcp_offline.cpp), and the setpoint keeps the alarm.
    EXPECT_EQ(h.put("T:app:Set", 5), pv::PutStatus::Failed);
    EXPECT_TRUE(h.sent.empty());
    EXPECT_EQ(h.alarm("T:app:Set"), "INVALID/COMM");
    h.advance(0.1);
    // The next packet clears it; objects that never had a value go back to UDF.
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {2}}}));
    EXPECT_EQ(h.alarm("T:app:Temp"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.get("T:app:Temp"), 2);
    EXPECT_EQ(h.alarm("T:app:Set"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.alarm("T:app:Set_RBV"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.alarm("T:app:Ok"), "INVALID/UDF");
    EXPECT_EQ(h.alarm("T:app:Valve"), "INVALID/UDF");
    EXPECT_EQ(h.alarm("T:app:Stage"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.get("T:app:Online"), 1);
    // A beacon alone also counts as life.
    h.advance(3);
    EXPECT_EQ(h.alarm("T:app:Temp"), "INVALID/COMM");
    h.feed(beacon("app", standard()));
    EXPECT_EQ(h.alarm("T:app:Temp"), "NO_ALARM/NO_ALARM");
}

TEST(RcpBridge, ApplicationsAreToldApartByNameAndSource) {
    Harness h;
    Endpoint a_src{kRcpIp, 5000}, b_src{kRcpIp, 5001};
    h.announce("a", {obj(1, OT::AI, DT::Float64, "X")}, a_src);
    h.announce("b", {obj(1, OT::AI, DT::Float64, "Y"), obj(2, OT::AO, DT::Float64, "Z", 19000)},
               b_src);
    h.feed(data({{1, OT::AI, DT::Float64, "X", {1}}}), a_src);
    h.feed(data({{1, OT::AI, DT::Float64, "Y", {2}}}), b_src);
    EXPECT_EQ(h.get("T:a:X"), 1);
    EXPECT_EQ(h.get("T:b:Y"), 2);
    // From another port of the same machine: the application whose objects match.
    h.feed(data({{1, OT::AI, DT::Float64, "Y", {3}}}), Endpoint{kRcpIp, 6000});
    EXPECT_EQ(h.get("T:b:Y"), 3);
    EXPECT_EQ(h.get("T:a:X"), 1);
    // Writes go to each object's own address.
    ASSERT_EQ(h.put("T:b:Z", 1), pv::PutStatus::Ok);
    EXPECT_EQ(h.sent.back().to, (Endpoint{kRcpIp, 19000}));
    // The same name from another machine would clash with the PVs: refused.
    BeaconObject other = obj(1, OT::AI, DT::Float64, "X");
    other.ip_rcp = 0; // writes to its own address (naming 10.0.0.2 would be refused anyway)
    h.feed(beacon("a", {other}), Endpoint{0x0A000003, 5000});
    EXPECT_EQ(h.core->applications().size(), 2u);
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::UnknownApplication)], 1u);
    h.advance(1);
    EXPECT_EQ(h.get("T:Applications"), 2);
    EXPECT_EQ(h.get("T:a:RxCount"), 2);
    EXPECT_EQ(h.get("T:b:RxCount"), 3);
    EXPECT_EQ(h.get("T:b:TxCount"), 1);
    // One application falls silent, the other stays.
    h.advance(2.0);
    h.feed(data({{1, OT::AI, DT::Float64, "X", {4}}}), a_src);
    h.advance(1.0);
    EXPECT_EQ(h.alarm("T:a:X"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.alarm("T:b:Y"), "INVALID/COMM");
}

TEST(RcpBridge, DiagnosticsArePublishedEverySecond) {
    Harness h;
    h.announce("app", standard());
    for (int i = 0; i < 5; ++i) h.feed(data({{1, OT::AI, DT::Float64, "Temp", {double(i)}}}));
    EXPECT_EQ(h.get("T:app:RxCount"), 1) << "not per packet";
    h.advance(1);
    EXPECT_EQ(h.get("T:app:RxCount"), 6);
    EXPECT_EQ(h.get("T:RxCount"), 6);
    EXPECT_NEAR(h.get("T:app:BeaconAge"), 1.15, 1e-9);
    EXPECT_EQ(h.get("T:app:Online"), 1);
    EXPECT_EQ(h.str("T:app:BeaconAge.EGU"), "s");
}

TEST(RcpBridge, DataPortsFollowTheBeacons) {
    Harness h;
    uint64_t v0 = h.core->ports_version();
    auto o = obj(1, OT::AI, DT::Float64, "Temp");
    o.port_ioc = 18070;
    h.announce("app", {o, obj(2, OT::AI, DT::Float64, "Other")});
    EXPECT_EQ(h.core->data_ports(), (std::vector<uint16_t>{18070}));
    EXPECT_GT(h.core->ports_version(), v0);
    uint64_t v1 = h.core->ports_version();
    h.advance(1);
    h.announce("app", {o, obj(2, OT::AI, DT::Float64, "Other")});
    EXPECT_EQ(h.core->ports_version(), v1) << "unchanged";
    h.advance(1);
    h.announce("app", {obj(2, OT::AI, DT::Float64, "Other")});
    EXPECT_TRUE(h.core->data_ports().empty());
}

TEST(RcpBridge, PvNamePatternAndNameMapping) {
    auto cfg = Harness::config();
    cfg.pv_pattern = "<prefix><name>";
    Harness h(cfg);
    h.announce("my.app", {obj(1, OT::AI, DT::Float64, "a.b"), obj(2, OT::AI, DT::Float64, "c:d")});
    EXPECT_TRUE(h.exists("T:a_b"));
    EXPECT_TRUE(h.exists("T:c:d"));
    EXPECT_TRUE(h.exists("T:my_app:RxCount"));
    EXPECT_EQ(h.core->pv_name("my.app", "a.b"), "T:a_b");
}

TEST(RcpBridge, ObjectsWhosePvNameIsTakenAreSkipped) {
    Harness h;
    h.db.load(pv::parse_db(R"(record(ai, "T:app:Temp") { field(DESC, "mine") })", "test.db", {}));
    h.db.init_records();
    h.announce("app", {obj(1, OT::AI, DT::Float64, "Temp"), obj(2, OT::AI, DT::Float64, "Other")});
    EXPECT_EQ(h.str("T:app:Temp.DESC"), "mine");
    EXPECT_TRUE(h.exists("T:app:Other"));
    h.feed(data({{1, OT::AI, DT::Float64, "Temp", {3}}, {2, OT::AI, DT::Float64, "Other", {4}}}));
    EXPECT_EQ(h.get("T:app:Other"), 4);
    EXPECT_NE(h.get("T:app:Temp"), 3) << "someone else's record is never written";
    // A name too long for a record is skipped as well.
    std::string app(21, 'A'); // "T:" + 21 + ":" + 39 = 63 characters
    h.announce(
        app,
        {obj(2, OT::AI, DT::Float64, "Other"), obj(3, OT::AI, DT::Float64, std::string(39, 'L'))},
        Endpoint{kRcpIp, 7000});
    EXPECT_TRUE(h.exists("T:" + app + ":Other"));
    EXPECT_TRUE(h.exists("T:" + app + ":Malformed-UnterminatedName"));
    EXPECT_EQ(h.db.find("T:" + app + ":" + std::string(39, 'L')), nullptr);
    h.feed(data({{3, OT::AI, DT::Float64, std::string(39, 'L'), {1}}}), Endpoint{kRcpIp, 7000});
    EXPECT_EQ(h.core->totals().malformed[size_t(Malformed::UnknownObject)], 0u)
        << "accepted and ignored";
}

TEST(RcpBridge, ApplicationLimit) {
    auto cfg = Harness::config();
    cfg.max_applications = 1;
    Harness h(cfg);
    h.announce("a", {obj(1, OT::AI, DT::Float64, "X")});
    h.announce("b", {obj(1, OT::AI, DT::Float64, "X")}, Endpoint{kRcpIp, 5001});
    EXPECT_FALSE(h.exists("T:b:X"));
    EXPECT_EQ(h.core->totals().refused[size_t(Refusal::TooManyApplications)], 1u);
    h.advance(1);
    EXPECT_EQ(h.get("T:Refused-TooManyApplications"), 1);
}

TEST(RcpBridge, ConfigurationIsValidated) {
    pv::Database db;
    auto make = [&](BridgeConfig c) { BridgeCore core(db, c, {}, {}); };
    BridgeConfig c;
    c.timeout_s = 0;
    EXPECT_THROW(make(c), Error);
    c = {};
    c.pv_pattern = "<prefix>";
    EXPECT_THROW(make(c), Error);
    c = {};
    c.listen_address = "localhost";
    try {
        make(c);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("listen address 'localhost'"), std::string::npos)
            << e.what();
    }
    // Two bridges with one prefix clash on their diagnostic PVs.
    BridgeCore first(db, BridgeConfig{}, {}, {});
    EXPECT_THROW(make(BridgeConfig{}), Error);
}

TEST(RcpBridge, DestructionRemovesEveryRecord) {
    auto h = std::make_unique<Harness>();
    h->announce("app", standard());
    EXPECT_GT(h->db.size(), 40u);
    h->core.reset();
    EXPECT_EQ(h->db.size(), 0u);
}

TEST(RcpBridge, SteadyStateDataAllocatesNothing) {
    Harness h;
    h.announce("app", standard());
    Packet p = data({{1, OT::AI, DT::Float64, "Temp", {1}},
                     {2, OT::AO, DT::Float64, "Set", {2}},
                     {3, OT::BI, DT::Bool, "Ok", {1}},
                     {4, OT::BO, DT::Bool, "Valve", {0}},
                     {5, OT::LI, DT::Int32, "Count", {3}},
                     {6, OT::LO, DT::Int16, "Mode", {1}},
                     {7, OT::Motor, DT::Float64, "Stage", {1, 0, 1 | 64, 0, 0}},
                     {8, OT::AI, DT::Float32, "Spec", {1, 2, 3, 4}}});
    for (int i = 0; i < 10; ++i) h.feed(p); // learn counts, build waveforms
    Packet q = data({{1, OT::AI, DT::Float64, "Temp", {2}},
                     {7, OT::Motor, DT::Float64, "Stage", {2, 0.5, 2 | 64, 0, 0}},
                     {8, OT::AI, DT::Float32, "Spec", {4, 3, 2, 1}}});
    h.feed(q);
    beamctl::test::count_allocations(true);
    for (int i = 0; i < 1000; ++i) {
        h.feed(i % 2 ? p : q);
        h.t += 0.0001;
    }
    beamctl::test::count_allocations(false);
    EXPECT_EQ(beamctl::test::allocations(), 0);
    EXPECT_EQ(h.get("T:app:Temp"), 1);
}
