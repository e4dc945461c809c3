// The socket plumbing on loopback with isolated ports (port 0): RcpBridge on a real EventLoop
// receiving beacons and data and sending writes, extra data ports, and `rcp-sim` (run_rcp_sim in a
// thread, stopped with SIGTERM) feeding it. Waits are "until it happened, at most N s" (a hung
// test fails); no timing is asserted.
#include "bridge/rcp/bridge.hpp"
#include "bridge/rcp/rcp_sim.hpp"

#include "core/error.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <functional>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

using namespace beamctl;
using namespace beamctl::bridge::rcp;

namespace {

// A UDP socket on 127.0.0.1 standing in for an RCP machine.
struct Peer {
    int fd = -1;
    uint16_t port = 0;
    Peer() {
        fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        sockaddr_in sa{};
        sa.sin_family = AF_INET;
        sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        ::bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof sa);
        socklen_t len = sizeof sa;
        getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
        port = ntohs(sa.sin_port);
    }
    ~Peer() { ::close(fd); }
    void send_to(uint16_t to, std::span<const uint8_t> p) {
        sockaddr_in sa{};
        sa.sin_family = AF_INET;
        sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        sa.sin_port = htons(to);
        ASSERT_EQ(::sendto(fd, p.data(), p.size(), 0, reinterpret_cast<sockaddr*>(&sa), sizeof sa),
                  ssize_t(p.size()));
    }
    // A datagram if one arrives within timeout_ms.
    std::vector<uint8_t> receive(int timeout_ms) {
        pollfd pfd{fd, POLLIN, 0};
        if (::poll(&pfd, 1, timeout_ms) != 1) return {};
        std::vector<uint8_t> b(2000);
        ssize_t n = ::recv(fd, b.data(), b.size(), 0);
        b.resize(n > 0 ? std::size_t(n) : 0);
        return b;
    }
};

// Runs the loop until `done` is true (checked every 10 ms) or `limit_s` passed.
bool run_until(EventLoop& loop, const std::function<bool()>& done, double limit_s = 10) {
    double end = EventLoop::now_s() + limit_s;
    bool ok = false, stopping = false; // one stop() a run (a queued second one ends the next run)
    auto id = loop.call_every(0.01, [&] {
        if (done()) ok = true;
        if (!stopping && (ok || EventLoop::now_s() > end)) {
            stopping = true;
            loop.stop();
        }
    });
    loop.run();
    loop.cancel(id);
    return ok;
}

double value(pv::Database& db, const char* name) {
    pv::Address a;
    if (!db.resolve(name, a)) return NAN;
    double v = NAN;
    db.get(a, pv::Prim::Double, &v, 1);
    return v;
}

BridgeConfig local_config() {
    BridgeConfig c;
    c.listen_address = "127.0.0.1";
    c.port = 0;
    c.prefix = "S:";
    return c;
}

} // namespace

TEST(RcpSocket, BeaconDataAndWritesOverUdp) {
    pv::Database db;
    EventLoop loop;
    RcpBridge bridge(db, loop, local_config());
    ASSERT_NE(bridge.port(), 0);
    Peer rcp;
    BeaconObject ai{1, ObjectType::AI, DataType::Float64, 0, 0, 0, 0, "Temp"};
    BeaconObject ao{2, ObjectType::AO, DataType::Float64, 0x7F000001, rcp.port, 0, 0, "Set"};
    BeaconObject objs[] = {ai, ao};
    Packet b;
    ASSERT_TRUE(write_beacon(b, 1, "udp", false, objs).ok());
    rcp.send_to(bridge.port(), b);
    double v = 21.5;
    DataEntry e{1, ObjectType::AI, DataType::Float64, 1, "Temp", std::span<const double>(&v, 1)};
    Packet d;
    ASSERT_TRUE(write_data(d, 2, std::span<const DataEntry>(&e, 1)).ok());
    rcp.send_to(bridge.port(), d);
    ASSERT_TRUE(run_until(loop, [&] { return value(db, "S:udp:Temp") == 21.5; }));
    // A write goes out at once, from the bridge's port, to ip_rcp:port_rcp.
    double w = 3;
    pv::Address a;
    ASSERT_TRUE(db.resolve("S:udp:Set", a));
    ASSERT_EQ(db.put(a, pv::Prim::Double, &w, 1), pv::PutStatus::Ok);
    std::vector<uint8_t> got = rcp.receive(5000);
    ASSERT_EQ(got.size(), 1000u);
    DataPacket p;
    ASSERT_TRUE(parse_data(std::span<const uint8_t>(got), p).ok());
    ASSERT_EQ(p.entry_count, 1u);
    EXPECT_EQ(p.entries[0].name, "Set");
    EXPECT_EQ(p.entries[0].values[0], 3);
    // Datagrams longer than 1000 bytes are refused as Long.
    std::vector<uint8_t> big(1500, 0);
    rcp.send_to(bridge.port(), big);
    ASSERT_TRUE(run_until(
        loop, [&] { return bridge.core().totals().malformed[size_t(Malformed::Long)] == 1; }));
}

TEST(RcpSocket, AnnouncedDataPortsAreOpened) {
    pv::Database db;
    EventLoop loop;
    RcpBridge bridge(db, loop, local_config());
    Peer rcp, probe;
    uint16_t data_port = probe.port; // a port known to be free once the probe closes
    ::close(probe.fd);
    probe.fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    BeaconObject ai{1, ObjectType::AI, DataType::Int32, 0, 0, 0x7F000001, data_port, "N"};
    Packet b;
    ASSERT_TRUE(write_beacon(b, 1, "ports", false, std::span<const BeaconObject>(&ai, 1)).ok());
    rcp.send_to(bridge.port(), b);
    ASSERT_TRUE(run_until(loop, [&] { return db.find("S:ports:N") != nullptr; }));
    ASSERT_TRUE(run_until(loop, [&] { return true; })); // one more tick opens the port
    double v = 7;
    DataEntry e{1, ObjectType::AI, DataType::Int32, 1, "N", std::span<const double>(&v, 1)};
    Packet d;
    ASSERT_TRUE(write_data(d, 2, std::span<const DataEntry>(&e, 1)).ok());
    rcp.send_to(data_port, d);
    EXPECT_TRUE(run_until(loop, [&] { return value(db, "S:ports:N") == 7; }));
}

TEST(RcpSocket, RcpSimFeedsTheBridge) {
    pv::Database db;
    EventLoop loop;
    BridgeConfig cfg = local_config();
    cfg.timeout_s = 0.5;
    RcpBridge bridge(db, loop, cfg);
    auto model = std::filesystem::temp_directory_path() /
                 ("beamctl_rcp_sim_" + std::to_string(::getpid()) + ".yaml");
    {
        std::ofstream f(model);
        f << "application: simtest\nrate_hz: 200\nlisten: {host: 127.0.0.1, port: 0}\nobjects:\n"
             "  - {id: 1, name: Count, type: LI, counter: {step: 1}}\n"
             "  - {id: 2, name: Set, type: AO}\n"
             "  - {id: 3, name: Out, type: AI, plant: {input: Set, time_constant_s: 0.05}}\n";
    }
    RcpSimOptions opt;
    opt.ioc_host = "127.0.0.1";
    opt.ioc_port = bridge.port();
    opt.duration_s = 60; // a safety net: the test ends it with SIGTERM
    std::thread sim([&] {
        try {
            run_rcp_sim(model.string(), opt);
        } catch (const Error& e) {
            ADD_FAILURE() << e.what();
        }
    });
    EXPECT_TRUE(run_until(loop, [&] { return value(db, "S:simtest:Count") > 20; }));
    pv::Address a;
    ASSERT_TRUE(db.resolve("S:simtest:Set", a));
    double w = 4;
    ASSERT_EQ(db.put(a, pv::Prim::Double, &w, 1), pv::PutStatus::Ok);
    EXPECT_TRUE(run_until(loop, [&] { return std::fabs(value(db, "S:simtest:Out") - 4) < 0.01; }));
    EXPECT_EQ(value(db, "S:simtest:Set_RBV"), 4);
    // SIGTERM (to the simulator's thread, which reads it from its signalfd) stops it cleanly;
    // the bridge then sees silence.
    pthread_kill(sim.native_handle(), SIGTERM);
    sim.join();
    EXPECT_TRUE(run_until(
        loop, [&] { return value(db, "S:simtest:Online") == 0; }, 10));
    std::filesystem::remove(model);
}
