// The CA repeater protocol without sockets: registration and confirm, fan-out of beacons to every
// registered client but the sender, the sender's address filled into beacons, and clients dropped
// once their port has closed (ca-protocol.md §8; EPICS repeater.cpp behaviour).
#include "ca/repeater.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <string>
#include <vector>

using namespace beamctl::ca;

namespace {

struct Sent {
    UdpEndpoint to;
    std::vector<uint8_t> data;
};

// A host with a set of open UDP ports and a set of local addresses; records every send.
struct FakeHost : RepeaterIo {
    std::vector<Sent> sent;
    std::set<uint16_t> open_ports;
    std::set<uint32_t> local_ips{kLoopbackIp, 0xC0A80105}; // 127.0.0.1, 192.168.1.5
    std::vector<UdpEndpoint> forgotten;

    bool send(const UdpEndpoint& to, const uint8_t* data, std::size_t n) override {
        if (!open_ports.count(to.port)) return false; // ICMP port unreachable -> ECONNREFUSED
        sent.push_back({to, std::vector<uint8_t>(data, data + n)});
        return true;
    }
    void forget(const UdpEndpoint& c) override { forgotten.push_back(c); }
    bool port_in_use(uint16_t port) override { return open_ports.count(port) != 0; }
    bool is_local(uint32_t ip) override { return local_ips.count(ip) != 0; }

    std::vector<Sent> to(const UdpEndpoint& e) const {
        std::vector<Sent> out;
        for (const auto& s : sent)
            if (s.to == e) out.push_back(s);
        return out;
    }
};

std::vector<uint8_t> header(uint16_t cmd, uint16_t dtype = 0, uint32_t count = 0, uint32_t p1 = 0,
                            uint32_t p2 = 0) {
    std::vector<uint8_t> m(16);
    encode_header(m.data(), cmd, 0, dtype, count, p1, p2);
    return m;
}

std::vector<uint8_t> beacon(uint16_t tcp_port, uint32_t id, uint32_t server_ip) {
    return header(kRsrvIsUp, kMinorVersion, tcp_port, id, server_ip);
}

struct Decoded {
    uint16_t cmd;
    uint16_t dtype;
    uint32_t count, p1, p2;
};
Decoded decode(const std::vector<uint8_t>& m) {
    EXPECT_GE(m.size(), 16u);
    return {get16(&m[0]), get16(&m[4]), get16(&m[6]), get32(&m[8]), get32(&m[12])};
}

const UdpEndpoint kClientA{kLoopbackIp, 40001};
const UdpEndpoint kClientB{kLoopbackIp, 40002};
const UdpEndpoint kClientC{0xC0A80105, 40003};     // a local interface address
const UdpEndpoint kServer{0xC0A80177, 5064};       // another host's server
const UdpEndpoint kLocalServer{kLoopbackIp, 5064}; // a server on this host

class RepeaterCoreTest : public ::testing::Test {
protected:
    FakeHost host;
    RepeaterCore core{host};

    void SetUp() override { host.open_ports = {40001, 40002, 40003, 5064}; }
    void receive(const UdpEndpoint& from, const std::vector<uint8_t>& m) {
        core.receive(from, m.data(), m.size());
    }
    void register_client(const UdpEndpoint& c) { receive(c, header(kRepeaterRegister, 0, 0, 0, c.ip)); }
};

TEST_F(RepeaterCoreTest, RegisterIsConfirmedWithTheClientsAddress) {
    register_client(kClientA);
    ASSERT_EQ(host.sent.size(), 1u);
    EXPECT_EQ(host.sent[0].to, kClientA);
    ASSERT_EQ(host.sent[0].data.size(), 16u) << "a confirm is one bare header";
    Decoded d = decode(host.sent[0].data);
    EXPECT_EQ(d.cmd, kRepeaterConfirm);
    EXPECT_EQ(d.p2, kLoopbackIp) << "REPEATER_CONFIRM carries the client's address in p2";
    EXPECT_EQ(core.clients(), std::vector<UdpEndpoint>{kClientA});

    register_client(kClientC);
    ASSERT_EQ(host.to(kClientC).size(), 1u);
    EXPECT_EQ(decode(host.to(kClientC)[0].data).p2, kClientC.ip);
    EXPECT_EQ(core.stats().registrations, 2u);
}

TEST_F(RepeaterCoreTest, AnEmptyDatagramRegistersToo) {
    core.receive(kClientA, nullptr, 0);
    EXPECT_EQ(core.clients(), std::vector<UdpEndpoint>{kClientA});
    ASSERT_EQ(host.to(kClientA).size(), 1u);
    EXPECT_EQ(decode(host.to(kClientA)[0].data).cmd, kRepeaterConfirm);
}

TEST_F(RepeaterCoreTest, RegisteringAgainKeepsOneEntryPerPortAndConfirmsAgain) {
    register_client(kClientA);
    register_client(kClientA);
    register_client({0xC0A80105, kClientA.port}); // libca alternates loopback / interface address
    EXPECT_EQ(core.clients(), std::vector<UdpEndpoint>{kClientA});
    int confirms = 0;
    for (const auto& s : host.to(kClientA)) confirms += decode(s.data).cmd == kRepeaterConfirm;
    EXPECT_EQ(confirms, 3);
}

TEST_F(RepeaterCoreTest, RegistrationsFromOtherHostsAreIgnored) {
    host.open_ports.insert(kServer.port);
    receive(kServer, header(kRepeaterRegister));
    EXPECT_TRUE(core.clients().empty());
    EXPECT_TRUE(host.sent.empty()) << "no confirm to a foreign address";
    EXPECT_EQ(core.stats().foreign, 1u);
}

TEST_F(RepeaterCoreTest, BeaconsFanOutToEveryClientWithTheSendersAddressFilledIn) {
    register_client(kClientA);
    register_client(kClientB);
    register_client(kClientC);
    host.sent.clear();

    receive(kServer, beacon(5064, 7, 0));
    ASSERT_EQ(host.sent.size(), 3u);
    for (const UdpEndpoint& c : {kClientA, kClientB, kClientC}) {
        auto got = host.to(c);
        ASSERT_EQ(got.size(), 1u) << to_string(c);
        ASSERT_EQ(got[0].data.size(), 16u);
        Decoded d = decode(got[0].data);
        EXPECT_EQ(d.cmd, kRsrvIsUp);
        EXPECT_EQ(d.dtype, kMinorVersion);
        EXPECT_EQ(d.count, 5064u) << "server TCP port unchanged";
        EXPECT_EQ(d.p1, 7u) << "beacon id unchanged";
        EXPECT_EQ(d.p2, kServer.ip) << "p2 = 0 is replaced by the sender's address";
    }
    host.sent.clear();
    receive(kServer, beacon(5064, 8, 0x0A000001)); // the server named its own address: kept
    ASSERT_EQ(host.sent.size(), 3u);
    for (const auto& s : host.sent) EXPECT_EQ(decode(s.data).p2, 0x0A000001u);
    EXPECT_EQ(core.stats().forwarded, 6u);
}

TEST_F(RepeaterCoreTest, OtherDatagramsAreForwardedUnchangedAndNeverBackToTheSender) {
    register_client(kClientA);
    register_client(kClientB);
    host.sent.clear();
    const std::vector<uint8_t> odd{1, 2, 3, 4, 5}; // shorter than a header: forwarded as is
    receive(kClientA, odd);
    ASSERT_EQ(host.sent.size(), 1u);
    EXPECT_EQ(host.sent[0].to, kClientB);
    EXPECT_EQ(host.sent[0].data, odd);

    host.sent.clear();
    std::vector<uint8_t> two = beacon(6000, 1, 0);
    std::vector<uint8_t> more = header(kVersion, 0, kMinorVersion);
    two.insert(two.end(), more.begin(), more.end());
    receive(kLocalServer, two);
    ASSERT_EQ(host.sent.size(), 2u);
    for (const auto& s : host.sent) {
        ASSERT_EQ(s.data.size(), 32u);
        EXPECT_EQ(decode(s.data).p2, kLoopbackIp);
        EXPECT_TRUE(std::equal(more.begin(), more.end(), s.data.begin() + 16)) << "the rest unchanged";
    }
}

TEST_F(RepeaterCoreTest, WhatFollowsARegistrationIsForwardedWithoutIt) {
    register_client(kClientB);
    host.sent.clear();
    std::vector<uint8_t> m = header(kRepeaterRegister, 0, 0, 0, kLoopbackIp);
    std::vector<uint8_t> tail = beacon(5064, 3, kLoopbackIp);
    m.insert(m.end(), tail.begin(), tail.end());
    receive(kClientA, m);
    EXPECT_EQ(core.clients(), (std::vector<UdpEndpoint>{kClientB, kClientA}));
    auto to_b = host.to(kClientB);
    // B gets the no-op of A's registration, then the tail
    ASSERT_EQ(to_b.size(), 2u);
    EXPECT_EQ(decode(to_b[0].data).cmd, kVersion);
    EXPECT_EQ(to_b[1].data, tail);
    auto to_a = host.to(kClientA);
    ASSERT_EQ(to_a.size(), 1u) << "A gets its confirm only, not its own tail";
    EXPECT_EQ(decode(to_a[0].data).cmd, kRepeaterConfirm);
}

TEST_F(RepeaterCoreTest, ARegistrationSendsANoOpToTheOtherClients) {
    register_client(kClientA);
    host.sent.clear();
    register_client(kClientB);
    auto to_a = host.to(kClientA);
    ASSERT_EQ(to_a.size(), 1u);
    EXPECT_EQ(to_a[0].data, std::vector<uint8_t>(16, 0)) << "VERSION, all zero";
    EXPECT_EQ(core.stats().forwarded, 0u) << "confirms and no-ops are not forwarded datagrams";
}

TEST_F(RepeaterCoreTest, ANewRegistrationDropsClientsWhosePortClosed) {
    register_client(kClientA);
    register_client(kClientB);
    host.open_ports.erase(kClientA.port); // client A exits
    host.open_ports.erase(kClientB.port); // so does B...
    host.open_ports.insert(kClientB.port); // ...but B's port is open again (still in use)
    register_client(kClientC);
    EXPECT_EQ(core.clients(), (std::vector<UdpEndpoint>{kClientB, kClientC}));
    EXPECT_EQ(host.forgotten, std::vector<UdpEndpoint>{kClientA}) << "its socket is released";
    EXPECT_EQ(core.stats().removed, 1u);
}

TEST_F(RepeaterCoreTest, AFailedSendDropsTheClientOnlyIfItsPortClosed) {
    register_client(kClientA);
    register_client(kClientB);
    host.sent.clear();
    host.open_ports.erase(kClientA.port); // A exits: sends to it are refused
    receive(kServer, beacon(5064, 1, 0));
    EXPECT_EQ(core.clients(), std::vector<UdpEndpoint>{kClientB});
    EXPECT_EQ(core.stats().send_failures, 1u);
    ASSERT_EQ(host.to(kClientB).size(), 1u);
    receive(kServer, beacon(5064, 2, 0));
    EXPECT_EQ(host.to(kClientB).size(), 2u);
    EXPECT_TRUE(host.to(kClientA).empty());
}

// A client whose sends fail while its port is still held (full buffer, transient error) stays.
struct FlakyHost : FakeHost {
    bool fail = false;
    bool send(const UdpEndpoint& to, const uint8_t* data, std::size_t n) override {
        return fail ? false : FakeHost::send(to, data, n);
    }
};

TEST(RepeaterCore, AClientThatStillHoldsItsPortIsKeptAfterAFailedSend) {
    FlakyHost host;
    host.open_ports = {40001};
    RepeaterCore core(host);
    auto reg = header(kRepeaterRegister, 0, 0, 0, kLoopbackIp);
    core.receive(kClientA, reg.data(), reg.size());
    host.fail = true;
    auto b = beacon(5064, 1, 0);
    core.receive(kServer, b.data(), b.size());
    EXPECT_EQ(core.clients(), std::vector<UdpEndpoint>{kClientA});
    host.fail = false;
    core.receive(kServer, b.data(), b.size());
    EXPECT_EQ(host.to(kClientA).size(), 2u) << "confirm, then the second beacon";
}

// Seeded random traffic: whatever arrives, every registered client is local and unique per port,
// and every datagram from a non-client goes to each live client exactly once.
TEST(RepeaterCore, RandomTrafficKeepsTheClientListConsistent) {
    std::mt19937 rng(20240611);
    for (int round = 0; round < 200; ++round) {
        FakeHost host;
        RepeaterCore core(host);
        for (uint16_t p = 40000; p < 40016; ++p) host.open_ports.insert(p);
        for (int step = 0; step < 200; ++step) {
            const uint16_t port = uint16_t(40000 + rng() % 20); // 40016..40019 never open
            const uint32_t ip = (rng() % 4 == 0) ? 0x0A0000FEu : kLoopbackIp;
            const int what = int(rng() % 5);
            if (what == 0) {
                host.open_ports.erase(uint16_t(40000 + rng() % 16));
            } else if (what == 1) {
                host.open_ports.insert(uint16_t(40000 + rng() % 16));
            } else {
                std::vector<uint8_t> m(rng() % 40);
                for (auto& b : m) b = uint8_t(rng());
                if (what == 2 && m.size() >= 16) put16(m.data(), kRepeaterRegister);
                const std::size_t before = host.sent.size();
                const auto clients_before = core.clients();
                core.receive({ip, port}, m.data(), m.size());
                const bool registers = m.empty() || (m.size() >= 16 && get16(m.data()) == kRepeaterRegister);
                if (!registers) {
                    // a plain datagram: one copy to each client other than the sender whose port is open
                    std::size_t expect = 0;
                    for (const auto& c : clients_before)
                        if (!(c == UdpEndpoint{ip, port}) && host.open_ports.count(c.port)) ++expect;
                    EXPECT_EQ(host.sent.size() - before, expect);
                }
            }
            std::set<uint16_t> ports;
            for (const auto& c : core.clients()) {
                EXPECT_TRUE(ports.insert(c.port).second) << "one client per port";
                EXPECT_TRUE(host.is_local(c.ip)) << to_string(c);
            }
        }
    }
}

} // namespace
