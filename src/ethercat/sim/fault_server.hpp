// The control socket of `beamctl sim --control PATH`: a local UNIX stream socket (mode 0600, only
// this process's user and root may connect, as the IOC shell) taking one fault command per line
// (faults.hpp) and answering one line: "ok: power 3 off" or "error: ...". `beamctl sim fault PATH
// FAULT...` is its client (send_fault). The segment applies a fault at its next frame.
// Threading: the server runs its own thread; it only parses and posts to the segment.
#pragma once

#include "core/local_socket.hpp"
#include "ethercat/sim/segment.hpp"

#include <atomic>
#include <string>
#include <thread>

namespace beamctl::ethercat {
class Catalog;
}

namespace beamctl::ethercat::sim {

class FaultServer {
public:
    // Throws Error if the socket cannot be made (path too long, in use, no such directory).
    FaultServer(Segment& seg, const Catalog& catalog, std::string path);
    ~FaultServer();
    const std::string& path() const { return path_; }
    uint64_t applied() const { return posted_.load(); }
    uint64_t refused() const { return refused_.load(); }

private:
    void serve();
    std::string handle(const std::string& line);
    Segment& seg_;
    const Catalog& catalog_;
    std::string path_;
    int fd_ = -1;
    std::atomic<bool> stop_{false};
    std::atomic<uint64_t> posted_{0}, refused_{0};
    core::SocketGroup group_; // who besides this user and root may connect
    double refusal_logged_s_ = -1e300;
    std::thread thread_;
};

// Sends one fault command to a control socket; returns its answer line. Throws Error if nothing
// listens there.
std::string send_fault(const std::string& path, const std::string& command);

} // namespace beamctl::ethercat::sim
