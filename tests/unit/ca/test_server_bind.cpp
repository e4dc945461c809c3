// A CA server that cannot bind says which address and port, where each came from (environment
// variable or ioc.yaml) and why (the errno text); only a TCP port in use falls back to a free one.
#include "ca/server.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"
#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <cstdlib>
#include <netinet/in.h>
#include <optional>
#include <string>
#include <sys/socket.h>
#include <unistd.h>

using namespace beamctl;

namespace {

// Sets environment variables for one test and restores them after.
struct EnvGuard {
    std::vector<std::pair<std::string, std::optional<std::string>>> saved;
    void set(const char* name, const char* value) {
        const char* old = std::getenv(name);
        saved.emplace_back(name, old ? std::optional<std::string>(old) : std::nullopt);
        if (value) setenv(name, value, 1);
        else unsetenv(name);
    }
    ~EnvGuard() {
        for (auto it = saved.rbegin(); it != saved.rend(); ++it) {
            if (it->second) setenv(it->first.c_str(), it->second->c_str(), 1);
            else unsetenv(it->first.c_str());
        }
    }
};

std::string start_error(ca::ServerConfig cfg) {
    EventLoop loop;
    pv::Database db;
    ca::Server server(loop, db, std::move(cfg));
    try {
        server.start();
    } catch (const Error& e) {
        return e.what();
    }
    return {};
}

// A UDP port taken by a socket without SO_REUSEADDR (so the server's bind fails).
struct TakenUdpPort {
    int fd = socket(AF_INET, SOCK_DGRAM, 0);
    uint16_t port = 0;
    TakenUdpPort() {
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
        socklen_t len = sizeof a;
        getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
        port = ntohs(a.sin_port);
    }
    ~TakenUdpPort() { close(fd); }
};

} // namespace

TEST(CaServerBind, AnAddressNotOfThisHostNamesItsVariableAndTheReason) {
    EnvGuard env;
    env.set("EPICS_CAS_INTF_ADDR_LIST", "192.0.2.1"); // TEST-NET-1: never a local address
    env.set("EPICS_CAS_SERVER_PORT", nullptr);
    env.set("EPICS_CA_SERVER_PORT", nullptr);
    std::string e = start_error(ca::ServerConfig::from_env());
    EXPECT_NE(e.find("192.0.2.1:5064"), std::string::npos) << e;
    EXPECT_NE(e.find("EPICS_CAS_INTF_ADDR_LIST='192.0.2.1'"), std::string::npos) << e;
    EXPECT_NE(e.find("port from the default port"), std::string::npos) << e;
    EXPECT_NE(e.find("Cannot assign requested address"), std::string::npos) << e;
    EXPECT_EQ(e.find("in use"), std::string::npos) << e;
}

TEST(CaServerBind, APortInUseNamesTheVariableItCameFrom) {
    TakenUdpPort taken;
    ASSERT_NE(taken.port, 0);
    EnvGuard env;
    std::string port = std::to_string(taken.port);
    env.set("EPICS_CAS_INTF_ADDR_LIST", "127.0.0.1");
    env.set("EPICS_CAS_SERVER_PORT", port.c_str());
    std::string e = start_error(ca::ServerConfig::from_env());
    EXPECT_NE(e.find("UDP 127.0.0.1:" + port), std::string::npos) << e;
    EXPECT_NE(e.find("EPICS_CAS_SERVER_PORT=" + port), std::string::npos) << e;
    EXPECT_NE(e.find("Address already in use"), std::string::npos) << e;
}

TEST(CaServerBind, APortFromTheIocFileIsNamedSo) {
    TakenUdpPort taken;
    EnvGuard env;
    env.set("EPICS_CAS_INTF_ADDR_LIST", nullptr);
    env.set("EPICS_CAS_SERVER_PORT", nullptr);
    env.set("EPICS_CA_SERVER_PORT", nullptr);
    ca::ServerConfig cfg = ca::ServerConfig::from_env();
    cfg.set_port(taken.port, "/x/ioc.yaml: ca: port");
    std::string e = start_error(cfg);
    EXPECT_NE(e.find("UDP 0.0.0.0:" + std::to_string(taken.port)), std::string::npos) << e;
    EXPECT_NE(e.find("port from /x/ioc.yaml: ca: port"), std::string::npos) << e;
    EXPECT_NE(e.find("EPICS_CAS_INTF_ADDR_LIST is not set"), std::string::npos) << e;
    EXPECT_NE(e.find("Address already in use"), std::string::npos) << e;
}

TEST(CaServerBind, ATcpPortInUseFallsBackToAFreeOne) {
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ASSERT_EQ(listen(fd, 1), 0);
    socklen_t len = sizeof a;
    getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    ca::ServerConfig cfg;
    cfg.interfaces.push_back(a.sin_addr);
    cfg.auto_beacon_addrs = false;
    cfg.set_port(ntohs(a.sin_port), "test");
    EventLoop loop;
    pv::Database db;
    ca::Server server(loop, db, cfg);
    EXPECT_NO_THROW(server.start());
    EXPECT_NE(server.tcp_port(), ntohs(a.sin_port));
    EXPECT_NE(server.tcp_port(), 0);
    close(fd);
}
