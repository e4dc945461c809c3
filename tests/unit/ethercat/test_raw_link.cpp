#include "config/ioc_config.hpp"
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/master.hpp"
#include "ethercat/raw_link.hpp"
#include "ethercat/sim/raw_server.hpp"

#include <gtest/gtest.h>

#include <string>
#include <thread>

using namespace beamctl;
using namespace beamctl::ethercat;

namespace {

std::string error_of(const std::string& iface) {
    try {
        RawLink link(iface);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(RawLink, MissingInterfaceIsAClearError) {
    std::string e = error_of("bcnosuch0");
    EXPECT_NE(e.find("'bcnosuch0'"), std::string::npos) << e;
    EXPECT_NE(e.find("no such network interface"), std::string::npos) << e;
    e = error_of("");
    EXPECT_NE(e.find("no interface given"), std::string::npos) << e;
    e = error_of("a_name_longer_than_15");
    EXPECT_NE(e.find("'a_name_longer_than_15'"), std::string::npos) << e;
    EXPECT_NE(e.find("at most 15 characters"), std::string::npos) << e;
    sim::Segment seg;
    EXPECT_THROW(sim::RawServer(seg, "bcnosuch0"), Error);
}

TEST(RawLink, PduLengthExcludesEthernetPadding) {
    uint8_t p[46] = {0x0E, 0x10}; // type 1, 14 bytes of datagrams, padded to 46
    EXPECT_EQ(ethercat_pdu_length(p, sizeof p), 16u);
    p[0] = 0xFF, p[1] = 0x17; // length 0x7FF does not fit: left to the parser to reject
    EXPECT_EQ(ethercat_pdu_length(p, sizeof p), sizeof p);
    EXPECT_EQ(ethercat_pdu_length(p, 1), 1u);
}

// Master and simulator on the loopback interface: the master's frame comes back to both sockets
// unmarked (the master must skip it), the served one comes back marked (the server must skip it).
TEST(RawLink, MasterBringsUpASegmentServedOnLoopback) {
    const Catalog& cat = Catalog::builtin();
    sim::Segment seg;
    for (const char* t : {"EK1100", "EL2008", "EL1008"}) seg.add(*cat.find(t));
    std::unique_ptr<sim::RawServer> server;
    try {
        server = std::make_unique<sim::RawServer>(seg, "lo");
    } catch (const Error& e) {
        GTEST_SKIP() << "no raw socket on lo here (needs root or CAP_NET_RAW): " << e.what();
    }
    volatile bool stop = false;
    std::thread t([&] { server->run(stop, 20); });
    {
        RawLink link("lo");
        Master m(link, 0, {{0, "EK1100"}, {1, "EL2008"}, {2, "EL1008"}}, cat);
        m.bring_up();
        for (int i = 0; i < 5; ++i) {
            m.send_process_data();
            EXPECT_EQ(m.receive_process_data(200000), CycleStatus::Ok);
        }
        EXPECT_EQ(m.wkc(), m.expected_wkc());
    }
    stop = true;
    t.join();
    EXPECT_GT(server->frames, 10u);
    EXPECT_GT(server->ignored, 10u); // its own returns
}

TEST(RawLink, IocConfigTakesARawLinkWithItsInterface) {
    auto bus = [](const std::string& link) {
        return "ioc: {name: T}\nbuses:\n  - id: 0\n    link: " + link +
               "\n    slaves:\n      - {position: 0, type: EK1100}\n";
    };
    auto cfg = config::IocConfig::parse(bus("{type: raw, iface: eth1}"), "ioc.yaml");
    ASSERT_EQ(cfg.buses.size(), 1u);
    EXPECT_EQ(cfg.buses[0].link.type, "raw");
    EXPECT_EQ(cfg.buses[0].link.iface, "eth1");
    EXPECT_FALSE(cfg.buses[0].link.busy_poll);
    EXPECT_TRUE(
        config::IocConfig::parse(bus("{type: raw, iface: eth1, busy_poll: true}"), "ioc.yaml")
            .buses[0]
            .link.busy_poll);
    try {
        config::IocConfig::parse(bus("{type: raw}"), "ioc.yaml");
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("ioc.yaml:4:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("needs 'iface'"), std::string::npos) << e.what();
    }
    try {
        config::IocConfig::parse(bus("{type: raw, iface: eth1, busy_poll: sometimes}"), "ioc.yaml");
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("busy_poll should be true or false"),
                  std::string::npos)
            << e.what();
    }
}
