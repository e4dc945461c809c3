// `beamctl scanner SCANNER.yaml`: the process that runs one or more EtherCAT buses and lets IOCs
// share them (seed 002, Diamond's bus scanner; docs/scanner.md).
//
// RT thread (one engine, every bus on its cycle), per bus and cycle:
//   bus receive -> Fanout (the image, counters and slave states into every attached client's
//   ring; wake the clients asleep on it) -> Gather (with a gather window, first wait for each
//   client's answer to this cycle until the window closes; then each client's newest output
//   commit, only its claimed bits, merged into the image) -> bus send -> publish.
// The RT thread never waits for a client: a slow client loses its own oldest cycles (counted on
// its side), a torn commit waits for the next cycle, a client gone has its claimed outputs set to
// zero (or held) by the gather stage before its memory is released.
// Control thread (core EventLoop): the local socket (mode 0660, the socket group, peers checked),
// the protocol (protocol.hpp): hello, chain, attach with claims (a conflict is refused naming
// both clients), SDO and AL state through the scanner's master, status, detach; a closed
// connection detaches its client.
// Threading: construct, start() and run the loop on one thread; the engine's thread runs the
// stages; clients enter and leave the RT side through atomic slots (no locks on the RT path).
#pragma once

#include "config/ioc_config.hpp"
#include "core/event_loop.hpp"
#include "core/local_socket.hpp"
#include "ethercat/sim/local_bus.hpp"
#include "rt/engine.hpp"
#include "scanner/protocol.hpp"

#include <array>
#include <atomic>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::scanner {

struct ScannerConfig {
    std::string path;       // the file
    std::string name = "scanner";
    std::string socket;     // resolved path
    std::string socket_group; // the socket's group (name or gid); "" = BEAMCTL_SOCKET_GROUP, else the process's
    double rate_hz = 1000;
    int cpu = -1, priority = 80;
    unsigned max_clients = 16;   // attached at once
    unsigned default_depth = 64; // cycles in a client's ring unless it asks otherwise
    // How long, as a fraction of the cycle, the scanner waits for every client's outputs answering
    // this cycle's inputs before it sends the frame (0: it sends at once and client outputs reach
    // the bus one cycle later; 0.5: at most half a cycle, then the frame goes with what came).
    double gather_window = 0;
    std::vector<config::BusConfig> buses;

    // Reads and checks SCANNER.yaml; every error at once (file:line:col). Throws MultiError.
    static ScannerConfig load(const std::string& path);
    static ScannerConfig parse(const std::string& text, const std::string& path, ErrorList& errors);
};

constexpr std::size_t kMaxClients = 64;
constexpr std::size_t kOutLatencyBins = 1000; // output latency histogram: 1 µs bins, the last one 999 µs and beyond

class Scanner {
public:
    Scanner(ScannerConfig cfg, const ethercat::Catalog& catalog, rt::Clock& clock);
    ~Scanner();

    // Brings every bus up (slaves missing at start are reported, as in an IOC), starts the cycle
    // and the health threads, and listens on the socket. Throws Error.
    void start();
    // Adds the control socket to `loop` (its thread serves clients).
    void serve(EventLoop& loop);
    // Says goodbye to every client, stops the cycle, slaves to SAFEOP. Loop thread.
    void stop(const std::string& reason);

    // For tests in virtual time: bring-up without threads or socket, then cycles on this thread.
    void start_virtual();
    rt::Engine& engine() { return *engine_; }
    ethercat::Bus& bus(std::size_t i);
    std::size_t bus_count() const { return buses_.size(); }

    // The protocol without a socket (tests): one request from connection `conn`, its replies and
    // the file descriptors that go with them.
    struct Reply {
        proto::Message msg;
        std::vector<int> fds; // owned by the receiver
    };
    std::vector<Reply> handle(int conn, const proto::Message& m, pid_t pid);
    void disconnect(int conn);
    // Clients attached (RT slots in use).
    std::size_t clients() const;
    uint64_t instance() const { return instance_; }
    proto::Status status() const;
    // Per attached client (loop thread): commits merged, late ones, and the time from a commit to
    // its merge into the frame (the send follows in the same cycle).
    struct ClientFigures {
        std::string name;
        uint64_t commits = 0, late = 0, missed_window = 0, out_latency_max_ns = 0;
        std::array<uint64_t, kOutLatencyBins> out_latency_us{};
    };
    std::vector<ClientFigures> client_figures() const;

private:
    struct RtClient;
    struct Conn;
    struct BusRt;
    struct FanoutStage;
    struct GatherStage;

    proto::Message attach(Conn& c, const proto::Attach& a, std::vector<int>& fds);
    void release(Conn& c); // detach its client (RT stops using it first)
    void accept_one(EventLoop& loop);
    void on_readable(EventLoop& loop, int fd);

    ScannerConfig cfg_;
    const ethercat::Catalog& catalog_;
    rt::Clock& clock_;
    std::unique_ptr<rt::Engine> engine_;
    std::vector<std::unique_ptr<BusRt>> buses_;
    uint64_t instance_ = 0;
    int listen_fd_ = -1;
    core::SocketGroup group_; // who may attach: this user, root, members of this group
    std::map<int, std::unique_ptr<Conn>> conns_;
    int next_conn_ = 1;
    uint32_t next_client_id_ = 1;
};

} // namespace beamctl::scanner
