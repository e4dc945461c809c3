// The Channel Access repeater (what EPICS ships as `caRepeater`): CA clients on this host register
// their UDP port by sending REPEATER_REGISTER to the repeater port (EPICS_CA_REPEATER_PORT, 5065);
// the repeater answers REPEATER_CONFIRM and fans every other datagram that reaches the port (server
// beacons, RSRV_IS_UP) out to each registered client, and forgets clients whose port has closed.
// It exists because only one socket on a host receives a unicast (or, on old kernels, a broadcast)
// sent to a port; see ../shared/specs/ca-protocol.md §1, §8.
// RepeaterCore is the protocol without sockets (datagrams in, sends out through RepeaterIo);
// Repeater puts it behind a UDP socket on an EventLoop. Threading: one thread (the loop's) calls all.
#pragma once

#include "ca/protocol.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ca {

// An IPv4 UDP endpoint, both fields in host byte order.
struct UdpEndpoint {
    uint32_t ip = 0;
    uint16_t port = 0;
    bool operator==(const UdpEndpoint&) const = default;
};
std::string to_string(const UdpEndpoint& e); // "127.0.0.1:5065"

constexpr uint32_t kLoopbackIp = 0x7F000001; // 127.0.0.1

// What the core needs from the host: sending to clients and two probes of the local sockets.
class RepeaterIo {
public:
    virtual ~RepeaterIo() = default;
    // Sends one datagram to a registered client; false if it failed (refused: nobody listens).
    virtual bool send(const UdpEndpoint& to, const uint8_t* data, std::size_t n) = 0;
    // The core no longer sends to `client`: release what send() holds for it.
    virtual void forget(const UdpEndpoint& client) = 0;
    // True while some socket on this host holds UDP port `port` (the client is still there).
    virtual bool port_in_use(uint16_t port) = 0;
    // True if `ip` is an address of this host (only local clients may register).
    virtual bool is_local(uint32_t ip) = 0;
};

struct RepeaterStats {
    uint64_t datagrams = 0;      // received on the repeater port
    uint64_t registrations = 0;  // REPEATER_REGISTER (or empty datagrams) from local clients
    uint64_t foreign = 0;        // registrations from addresses not on this host (ignored)
    uint64_t forwarded = 0;      // datagrams sent to clients (confirms and no-ops not counted)
    uint64_t send_failures = 0;  // sends that failed
    uint64_t removed = 0;        // clients forgotten because their port had closed
};

// The repeater protocol. Only whole datagrams go in; nothing in them can make it fail.
class RepeaterCore {
public:
    explicit RepeaterCore(RepeaterIo& io) : io_(io) {}

    // Handles one datagram (n may be 0) received on the repeater port from `from`.
    void receive(const UdpEndpoint& from, const uint8_t* data, std::size_t n);

    // Registered clients, in registration order.
    const std::vector<UdpEndpoint>& clients() const { return clients_; }
    const RepeaterStats& stats() const { return stats_; }

private:
    void register_client(const UdpEndpoint& from);
    void fan_out(const UdpEndpoint& from, const uint8_t* data, std::size_t n);
    void remove_closed_clients();
    void remove_at(std::size_t i);

    RepeaterIo& io_;
    std::vector<UdpEndpoint> clients_;
    RepeaterStats stats_;
    std::vector<uint8_t> patched_; // a beacon with the sender's address filled in
};

// Thrown by Repeater when another socket holds the repeater port.
class PortInUse : public Error {
public:
    using Error::Error;
};

// A repeater on UDP 0.0.0.0:`port` (all interfaces, so broadcast beacons arrive), served on `loop`.
class Repeater {
public:
    // Binds the port; throws PortInUse when another socket holds it, Error on any other failure.
    Repeater(EventLoop& loop, uint16_t port);
    ~Repeater();
    Repeater(const Repeater&) = delete;
    Repeater& operator=(const Repeater&) = delete;

    uint16_t port() const;
    const RepeaterCore& core() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The repeater port: EPICS_CA_REPEATER_PORT, or 5065 when unset; throws Error when malformed.
uint16_t repeater_port_from_env();

// True if a CA repeater on 127.0.0.1:`port` confirms a registration within `timeout_s` [s].
bool repeater_answers(uint16_t port, double timeout_s);

// `beamctl ca-repeater`: serves the repeater in the foreground until SIGINT/SIGTERM, printing
// "ready: ..." on stdout once bound. Returns 0 at once, quietly, when a repeater already serves the
// port (libca starts one per client until one holds it), 1 if something else holds it.
int run_ca_repeater(uint16_t port);

// The program when invoked as `caRepeater` (a symlink to beamctl on PATH, which libca spawns when
// no repeater answers): EPICS's options -h and -v; without -v it detaches from the terminal and
// from the spawning client's stdin/stdout/stderr like EPICS's caRepeater.
int ca_repeater_main(int argc, char** argv);

} // namespace beamctl::ca
