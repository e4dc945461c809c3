// Who may talk to the RCP bridge, and how much (issue 19): loopback only by default; machines by
// name and address; allowed networks; writes only to the address a beacon comes from; caps on
// applications, objects and model changes. Every refusal changes nothing, is counted (totals,
// Refused-<Reason> PVs) and logged at most once a second per reason.
#include "rcp_harness.hpp"

#include "core/log.hpp"

#include <gtest/gtest.h>

#include <random>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {
using OT = ObjectType;
using DT = DataType;

constexpr Endpoint kLoopback{0x7F000001, 5000};
constexpr Endpoint kStranger{0xC0A80107, 5000}; // 192.168.1.7

BeaconObject local(uint8_t id, ObjectType t, std::string name) {
    BeaconObject o = obj(id, t, DT::Float64, std::move(name));
    o.ip_rcp = 0; // writes back to the beacon's source
    return o;
}

uint64_t refused(Harness& h, Refusal r) { return h.core->totals().refused[std::size_t(r)]; }
} // namespace

TEST(RcpAccess, LoopbackOnlyByDefault) {
    BridgeConfig c = Harness::config();
    c.allow.clear();
    Harness h(c);
    h.announce("far", {local(1, OT::AI, "X")}, kRcp); // 10.0.0.2: refused
    h.feed(data({{1, OT::AI, DT::Float64, "X", {1}}}), kRcp);
    EXPECT_FALSE(h.exists("T:far:X"));
    EXPECT_EQ(refused(h, Refusal::NotAllowed), 2u);
    EXPECT_EQ(h.core->totals().before_beacon, 0u); // refused before being looked at
    h.announce("near", {local(1, OT::AI, "X")}, kLoopback);
    EXPECT_TRUE(h.exists("T:near:X"));
    h.advance(1);
    EXPECT_EQ(h.get("T:Refused-NotAllowed"), 2);
    EXPECT_FALSE(h.exists("T:near:Refused-NotAllowed")); // not attributable to an application
    EXPECT_TRUE(h.exists("T:near:Refused-ForeignWriteAddress"));
}

TEST(RcpAccess, MachinesByNameAndAddressAllowByNetwork) {
    BridgeConfig c = Harness::config();
    c.allow.clear();
    c.machines = {{"sg1", "10.0.0.2"}, {"sg2", "10.0.5.0/24"}};
    Harness h(c);
    h.announce("sg1", {local(1, OT::AI, "X")}, kRcp);
    EXPECT_TRUE(h.exists("T:sg1:X"));
    h.announce("sg2", {local(1, OT::AI, "X")}, kRcp); // sg2 is not at 10.0.0.2
    EXPECT_FALSE(h.exists("T:sg2:X"));
    h.announce("sg2", {local(1, OT::AI, "X")}, Endpoint{0x0A000509, 5000});
    EXPECT_TRUE(h.exists("T:sg2:X"));
    h.announce("sg1", {local(1, OT::AI, "Y")}, kStranger);
    EXPECT_EQ(refused(h, Refusal::NotAllowed), 2u);
    // allow: any application from that network
    c.allow = {"192.168.1.0/24"};
    Harness h2(c);
    h2.announce("whatever", {local(1, OT::AI, "X")}, kStranger);
    EXPECT_TRUE(h2.exists("T:whatever:X"));
    // bad configuration names the entry
    BridgeConfig bad = Harness::config();
    bad.machines = {{"sg1", "10.0.0.300"}};
    pv::Database db;
    try {
        BridgeCore core(db, bad, {}, {});
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("machines[0] (sg1): address '10.0.0.300'"), std::string::npos) << e.what();
    }
    bad.machines.clear();
    bad.allow = {"10.0.0.0/33"};
    EXPECT_THROW(BridgeCore(db, bad, {}, {}), Error);
}

// A beacon may not direct the IOC's writes to a third host: refused whole, nothing created, and
// no datagram ever goes anywhere but to the beacon's own address.
TEST(RcpAccess, ForeignWriteAddressIsRefused) {
    Harness h;
    BeaconObject o = obj(1, OT::AO, DT::Float64, "SP");
    o.ip_rcp = 0x0A000063; // 10.0.0.99, not the source 10.0.0.2
    h.announce("app", {local(2, OT::AI, "X"), o}, kRcp);
    EXPECT_FALSE(h.exists("T:app:SP"));
    EXPECT_FALSE(h.exists("T:app:X"));
    EXPECT_EQ(refused(h, Refusal::ForeignWriteAddress), 1u);
    // the same object writing to its own source is fine, and writes go there
    o.ip_rcp = kRcpIp;
    h.announce("app", {o}, kRcp);
    ASSERT_TRUE(h.exists("T:app:SP"));
    ASSERT_EQ(h.put("T:app:SP", 2), pv::PutStatus::Ok);
    ASSERT_EQ(h.sent.size(), 1u);
    EXPECT_EQ(h.sent[0].to.ip, kRcpIp);
    // a later beacon of the served application naming a third host changes nothing
    o.ip_rcp = 0x0A000063;
    h.announce("app", {o}, kRcp);
    EXPECT_EQ(refused(h, Refusal::ForeignWriteAddress), 2u);
    ASSERT_EQ(h.put("T:app:SP", 3), pv::PutStatus::Ok);
    EXPECT_EQ(h.sent.back().to.ip, kRcpIp);
    h.advance(1);
    EXPECT_EQ(h.get("T:app:Refused-ForeignWriteAddress"), 1); // the second: attributed to it
    EXPECT_EQ(h.get("T:Refused-ForeignWriteAddress"), 2);
}

TEST(RcpAccess, ObjectAndChangeCapsHoldAndChangeNothing) {
    BridgeConfig c = Harness::config();
    c.max_objects = 3;
    c.max_model_changes_per_minute = 2;
    Harness h(c);
    h.announce("app", {local(1, OT::AI, "A"), local(2, OT::AI, "B"), local(3, OT::AI, "C"), local(4, OT::AI, "D")});
    EXPECT_FALSE(h.exists("T:app:A"));
    EXPECT_EQ(refused(h, Refusal::TooManyObjects), 1u);
    h.announce("app", {local(1, OT::AI, "A")}); // change 1 (its first model)
    h.announce("app", {local(1, OT::AI, "A")}); // the same: no change
    h.announce("app", {local(1, OT::AI, "A"), local(2, OT::AI, "B")}); // change 2
    EXPECT_TRUE(h.exists("T:app:B"));
    h.announce("app", {local(1, OT::AI, "A"), local(3, OT::AI, "C")}); // change 3: refused
    EXPECT_FALSE(h.exists("T:app:C"));
    EXPECT_TRUE(h.exists("T:app:B")); // nothing already served changed
    EXPECT_EQ(refused(h, Refusal::TooManyChanges), 1u);
    h.advance(61); // a minute later it may change again
    h.announce("app", {local(1, OT::AI, "A"), local(3, OT::AI, "C")});
    EXPECT_TRUE(h.exists("T:app:C"));
}

// One machine cannot take every application slot: max_applications_per_address.
TEST(RcpAccess, ApplicationsPerAddress) {
    BridgeConfig c = Harness::config();
    c.max_applications_per_address = 2;
    Harness h(c);
    h.announce("a", {local(1, OT::AI, "X")});
    h.announce("b", {local(1, OT::AI, "X")});
    h.announce("c", {local(1, OT::AI, "X")});
    EXPECT_FALSE(h.exists("T:c:X"));
    EXPECT_EQ(refused(h, Refusal::TooManyApplications), 1u);
    h.announce("c", {local(1, OT::AI, "X")}, Endpoint{0x0A000003, 5000}); // another machine still gets in
    EXPECT_TRUE(h.exists("T:c:X"));
}

// A flood of beacons with random application and object names from an allowed network: the
// number of applications and PVs stays bounded, nothing crashes, and the log is rate-limited.
TEST(RcpAccess, FloodOfRandomBeaconsStaysBounded) {
    BridgeConfig c = Harness::config();
    c.max_applications = 4;
    c.max_objects = 8;
    Harness h(c);
    std::mt19937 rng(1);
    auto name = [&] {
        std::string s;
        for (int k = 0; k < 8; ++k) s += char('a' + rng() % 26);
        return s;
    };
    std::size_t records_after_caps = 0;
    for (int k = 0; k < 2000; ++k) {
        std::vector<BeaconObject> objs;
        int n = 1 + int(rng() % 12);
        for (int i = 0; i < n; ++i) objs.push_back(local(uint8_t(i + 1), OT::AI, name()));
        h.feed(beacon(name(), objs), Endpoint{0x0A000000u | (rng() % 200 + 1), 5000});
        if (k % 10 == 0) h.advance(0.2);
        if (k == 999) records_after_caps = h.db.size();
    }
    h.advance(1);
    EXPECT_LE(h.core->applications().size(), 4u);
    for (const auto& a : h.core->applications()) EXPECT_LE(a.objects, 8u);
    EXPECT_GT(refused(h, Refusal::TooManyApplications), 1000u);
    EXPECT_EQ(h.db.size(), records_after_caps); // flat once the caps are reached
}
