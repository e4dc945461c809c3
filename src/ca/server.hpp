// The Channel Access server: UDP name search, beacons, and TCP circuits over one PV database.
// Runs on the IOC EventLoop thread (the thread that owns the Database). Configured from the
// EPICS_CAS_* / EPICS_CA_* environment like RSRV (ca-protocol.md §8), or programmatically.
#pragma once

#include "ca/access_security.hpp"
#include "ca/circuit.hpp"
#include "core/event_loop.hpp"
#include "pv/database.hpp"

#include <cstdint>
#include <iosfwd>
#include <memory>
#include <netinet/in.h>
#include <string>
#include <unordered_map>
#include <vector>

namespace beamctl::ca {

struct ServerConfig {
    uint16_t port = kDefaultServerPort;             // UDP and TCP [EPICS_CAS_SERVER_PORT]
    std::vector<in_addr> interfaces;                // bind addresses; empty = all [EPICS_CAS_INTF_ADDR_LIST]
    std::vector<sockaddr_in> beacon_addrs;          // [EPICS_CAS_BEACON_ADDR_LIST]
    bool auto_beacon_addrs = true;                  // + interface broadcasts [EPICS_CAS_AUTO_BEACON_ADDR_LIST]
    double beacon_period_s = 15.0;                  // [EPICS_CAS_BEACON_PERIOD]
    uint16_t beacon_port = kDefaultRepeaterPort;    // [EPICS_CAS_BEACON_PORT]
    std::vector<in_addr> ignore_addrs;              // searches from these are dropped [EPICS_CAS_IGNORE_ADDR_LIST]
    std::size_t max_array_bytes = 64u << 20;        // largest payload [EPICS_CA_MAX_ARRAY_BYTES]
    // Where `port` and `interfaces` came from, for error messages ("EPICS_CAS_SERVER_PORT=5064").
    std::string port_source = "the default port";
    std::string interfaces_source;                  // empty: not configured (all interfaces)
    // Reads the environment; throws Error naming the variable on a malformed value.
    static ServerConfig from_env();
    // Sets the port from another source, e.g. ("ioc.yaml: ca: port").
    void set_port(uint16_t p, std::string source) {
        port = p;
        port_source = std::move(source);
    }
};

// Beacon timing (ca-protocol.md §8): beacons at +0, 20, 60, 140, 300 ms, ... (the interval starts
// at 20 ms and doubles up to the period) with ids 0, 0, 1, 2, 3, ... as RSRV sends them.
class BeaconSchedule {
public:
    explicit BeaconSchedule(double period_s) : period_s_(period_s) {}
    // The id of the beacon to send now and the delay to the next one [s].
    struct Next {
        uint32_t id;
        double delay_s;
    };
    Next next();

private:
    double period_s_;
    uint64_t sent_ = 0;
    double interval_s_ = 0.02;
};

class Server {
public:
    Server(EventLoop& loop, pv::Database& db, ServerConfig cfg);
    ~Server();
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    // Opens the sockets and starts beacons. Throws Error if a socket can't be bound.
    void start();
    uint16_t tcp_port() const { return ctx_.tcp_port; }
    uint16_t udp_port() const { return cfg_.port; }
    std::string listen_description() const; // "127.0.0.1:5064" etc.
    // Replaces the access-security configuration; rights of open channels are re-sent.
    void set_access_security(AccessSecurity acf);
    // Loads an ACF file and applies it; on an error logs it and keeps the current rules.
    bool reload_access_security(const std::string& path);
    const ServerStats& stats() const { return ctx_.stats; }
    std::size_t client_count() const { return conns_.size(); }
    std::size_t channel_count() const; // over every circuit
    // casr: the connected circuits as EPICS casr prints them (peer, user, protocol version,
    // channels), with subscriptions and channel names (level 1) and the server's sockets and
    // counters (level 2). Loop thread.
    void report(int level, std::ostream& os) const;

private:
    struct Conn;
    void on_accept(int lfd);
    void on_conn_io(int fd, uint32_t events);
    void on_udp(int fd);
    void handle_datagram(int fd, const uint8_t* p, std::size_t n, const sockaddr_in& from);
    void flush(Conn& c);
    void close_conn(int fd);
    void send_beacons();
    void refresh_all_rights();
    // "TCP 127.0.0.1:5064 (address from ..., port from ...)" for bind errors.
    std::string bind_context(const char* proto, in_addr ip, uint16_t port) const;

    EventLoop& loop_;
    ServerContext ctx_;
    ServerConfig cfg_;
    std::vector<int> tcp_fds_, udp_fds_;
    int beacon_fd_ = -1;
    std::vector<sockaddr_in> beacon_targets_;
    BeaconSchedule beacons_{15.0};
    EventLoop::TimerId beacon_timer_ = 0;
    EventLoop::HookId after_batch_ = 0; // flushes the circuits written in a batch
    std::unordered_map<int, std::unique_ptr<Conn>> conns_;
    std::vector<int> dirty_;
    std::vector<uint8_t> rxbuf_;
};

} // namespace beamctl::ca
