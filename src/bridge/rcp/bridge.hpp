// The RCP UDP bridge of a running IOC: a BridgeCore (bridge_core.hpp: PVs, data, writes,
// time-outs, diagnostics) fed from UDP sockets served on the IOC's event loop. One socket on
// listen_address:port receives beacons and data and sends every write; further sockets are
// opened on the same address for data ports (port_ioc) that applications announce besides it.
// Threading: constructed, used and destroyed on the event loop's thread, which owns the
// Database; the Database and the EventLoop must outlive the bridge.
#pragma once

#include "bridge/rcp/bridge_core.hpp"
#include "core/event_loop.hpp"
#include "pv/database.hpp"

#include <cstdint>
#include <map>
#include <memory>

namespace beamctl::bridge::rcp {

class RcpBridge {
public:
    // Binds the beacon socket (port 0: any free port, see port()). Throws Error on a bad config,
    // a bind failure or a PV name clash.
    RcpBridge(pv::Database& db, EventLoop& loop, BridgeConfig cfg);
    ~RcpBridge();
    RcpBridge(const RcpBridge&) = delete;
    RcpBridge& operator=(const RcpBridge&) = delete;

    uint16_t port() const { return port_; } // the bound beacon port
    BridgeCore& core() { return *core_; }

private:
    int open_socket(uint16_t port); // bound, non-blocking; -1 with errno on failure
    void on_readable(int fd);
    void sync_ports();

    EventLoop& loop_;
    uint32_t listen_ip_ = 0;
    int fd_ = -1; // beacon socket, also the source of every write
    uint16_t port_ = 0;
    std::map<uint16_t, int> data_fds_; // extra data port -> socket
    uint64_t ports_version_ = 0;
    EventLoop::TimerId timer_ = 0;
    std::unique_ptr<BridgeCore> core_;
};

} // namespace beamctl::bridge::rcp
