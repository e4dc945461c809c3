// EtherCAT frames straight on Ethernet (ethercat.md §1, §5): an AF_PACKET socket bound to one
// interface (a NIC or a veth) for EtherType 0x88A4, as SOEM's nicdrv does. Frames go out as
// Ethernet II, broadcast destination, source 01:01:01:01:01:01, padded to the 60-byte minimum.
// Opening needs root or CAP_NET_RAW. send/receive are called from one thread only (the master's
// RT thread, or the simulator's serving loop); they never allocate and never throw.
#pragma once

#include "ethercat/link.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace beamctl::ethercat {

constexpr std::size_t kMinEthernetFrame = 60;                          // without FCS [bytes]
constexpr std::size_t kMaxEthernetFrame = kEthernetHeader + kMaxFrame; // 1514 [bytes]

// An AF_PACKET socket on one interface that sees only EtherCAT frames arriving from the wire
// (never the host's own outgoing frames), with the interface in promiscuous mode while it is open.
class RawSocket {
public:
    // Throws Error naming the interface and the reason (no such interface, interface down,
    // permission). With busy_poll, receive spins on the socket until its timeout instead of
    // sleeping: no wake-up latency (tens of us on a VM), at the price of a busy CPU.
    explicit RawSocket(const std::string& iface, bool busy_poll = false);
    ~RawSocket();
    RawSocket(const RawSocket&) = delete;
    RawSocket& operator=(const RawSocket&) = delete;

    // Sends one whole Ethernet frame (header included, already padded). False if refused.
    bool send(const uint8_t* eth_frame, std::size_t len) noexcept;
    // Receives the next incoming EtherCAT Ethernet frame (header included) into buf; returns its
    // length, or 0 if none arrived within timeout_us (0: only what is already queued).
    std::size_t receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept;
    const std::string& iface() const { return iface_; }
    int ifindex() const { return ifindex_; }
    uint64_t ignored = 0; // frames received but not EtherCAT from another host

private:
    std::string iface_;
    int ifindex_ = 0;
    int fd_ = -1;
    bool busy_poll_ = false;
};

// Returns the EtherCAT PDU length inside an Ethernet payload of n bytes: 2 + the header's length
// field without the padding, or n if the header does not fit (the parser then rejects the frame).
std::size_t ethercat_pdu_length(const uint8_t* payload, std::size_t n) noexcept;

// The master's link over a raw socket. Receive returns the EtherCAT PDU without the Ethernet
// header and padding, and skips the master's own frames reflected back unmarked by any ESC.
class RawLink : public Link {
public:
    // Throws Error naming the interface and the reason; busy_poll as for RawSocket.
    explicit RawLink(const std::string& iface, bool busy_poll = false);
    bool send(const uint8_t* frame, std::size_t len) noexcept override;
    std::size_t receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept override;
    const char* kind() const noexcept override { return "raw"; }
    const std::string& iface() const { return sock_.iface(); }

private:
    RawSocket sock_;
    std::array<uint8_t, kMaxEthernetFrame> tx_{};
    std::array<uint8_t, kMaxEthernetFrame> rx_{};
};

} // namespace beamctl::ethercat
