// The simulator's configuration (SIM.yaml, also the `plant:` file of an IOC's sim link):
//   slaves: [{position: 0, type: EK1100}, {position: 1, type: EL2008}, ...]   (optional when the
//            IOC configuration already lists the bus)
//   wiring: [{from: s1.binaryOutput01, to: s2.binaryInput01}, ...]          (outputs -> inputs)
// Plant models (stages, switches, signal sources) extend this file in later steps.
#pragma once

#include "ethercat/catalog.hpp"
#include "ethercat/sim/segment.hpp"

#include <string>
#include <vector>

namespace beamctl::ethercat::sim {

// Where an entry lives in a simulated slave: bit range inside one SM buffer (default PDOs).
struct EntryLocation {
    uint8_t sm = 0;
    uint32_t bit = 0;
    uint8_t bits = 0;
    bool output = false; // RxPDO (master -> slave)
};
// Throws Error naming the device and entry if it has no such entry.
EntryLocation locate_entry(const DeviceDesc& d, std::string_view entry);

struct Wire {
    int from_slave = 0, to_slave = 0;
    std::string from_entry, to_entry;
    EntryLocation from, to;
};

struct SimConfig {
    std::vector<std::pair<int, std::string>> slaves; // {position, type}
    std::vector<Wire> wiring;
    // Loads SIM.yaml; every error has file:line:col. Unknown keys are errors.
    static SimConfig load(const std::string& path, const Catalog& catalog);
    static SimConfig parse(const std::string& text, const std::string& filename, const Catalog& catalog);
    // Builds the segment (if `slaves` is given) and installs the wiring as its on_frame hook.
    void build(Segment& seg, const Catalog& catalog) const;
};

// Runs a segment behind a UDP socket: every datagram is an EtherCAT frame, processed and sent
// back to its sender (what `beamctl sim --udp PORT` does).
class UdpServer {
public:
    UdpServer(Segment& seg, const std::string& bind_addr, uint16_t port);
    ~UdpServer();
    uint16_t port() const { return port_; }
    // Serves frames until `stop` becomes true (checked every `poll_ms`).
    void run(const volatile bool& stop, int poll_ms = 100);
    // Serves at most one frame; returns false on timeout.
    bool serve_one(int timeout_ms);
    uint64_t frames = 0, malformed = 0;

private:
    Segment& seg_;
    int fd_ = -1;
    uint16_t port_ = 0;
};

} // namespace beamctl::ethercat::sim
