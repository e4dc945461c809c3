// How the master reaches a segment: one interface, several transports (ethercat.md §5).
//   sim::InProcessLink (sim/inprocess_link.hpp): straight into a simulated segment in this process.
//   UdpLink: UDP to a `beamctl sim --udp` process; RawLink (raw_link.hpp): AF_PACKET on a NIC/veth.
// send/receive are called from the master's thread only; they never allocate.
#pragma once

#include "ethercat/frame.hpp"

#include <string>
#include <cstddef>
#include <cstdint>

namespace beamctl::ethercat {

class Link {
public:
    virtual ~Link() = default;
    // Sends one EtherCAT frame (header + datagrams). False if the transport refused it.
    virtual bool send(const uint8_t* frame, std::size_t len) noexcept = 0;
    // Receives the next returning frame into buf (capacity kMaxFrame). Returns its length, or
    // 0 when nothing arrived within timeout_us.
    virtual std::size_t receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept = 0;
    virtual const char* kind() const noexcept = 0;
};

} // namespace beamctl::ethercat

namespace beamctl::ethercat {

// EtherCAT frames as UDP payloads (ESC-I §2, port 0x88A4) to a `beamctl sim --udp` process.
class UdpLink : public Link {
public:
    // Throws Error if the host is not an IPv4 address or the socket can't be made.
    UdpLink(const std::string& host, uint16_t port);
    ~UdpLink() override;
    bool send(const uint8_t* frame, std::size_t len) noexcept override;
    std::size_t receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept override;
    const char* kind() const noexcept override { return "udp"; }

private:
    int fd_ = -1;
};

} // namespace beamctl::ethercat
