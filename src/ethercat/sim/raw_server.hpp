// Serves a simulated segment on a network interface (what `beamctl sim SIM.yaml --iface IFACE`
// does): each EtherCAT frame arriving on the interface passes the segment and goes back out of
// the same interface with bit 1 of source-MAC byte 0 set, as an ESC marks a frame it processed
// (ethercat.md §1). Frames already carrying that bit (returns of a segment) are not served again.
// One thread calls serve_one/run; needs root or CAP_NET_RAW.
#pragma once

#include "ethercat/raw_link.hpp"
#include "ethercat/sim/segment.hpp"

#include <array>
#include <cstdint>
#include <string>

namespace beamctl::ethercat::sim {

class RawServer {
public:
    // Throws Error naming the interface and the reason. busy_poll: spin on the socket instead of
    // sleeping (answers at once, like hardware, but keeps one CPU busy).
    RawServer(Segment& seg, const std::string& iface, bool busy_poll = false);
    const std::string& iface() const { return sock_.iface(); }
    // Serves frames until `stop` becomes true (checked every `poll_ms`).
    void run(const volatile bool& stop, int poll_ms = 100);
    // Serves at most one frame; returns false on timeout.
    bool serve_one(int timeout_ms);
    uint64_t frames = 0, ignored = 0, send_errors = 0;

private:
    Segment& seg_;
    RawSocket sock_;
    std::array<uint8_t, kMaxEthernetFrame> buf_{};
};

} // namespace beamctl::ethercat::sim
