#include "ethercat/sim/raw_server.hpp"

#include <chrono>
#include <cstring>

namespace beamctl::ethercat::sim {

RawServer::RawServer(Segment& seg, const std::string& iface, bool busy_poll)
    : seg_(seg)
    , sock_(iface, busy_poll) {}

bool RawServer::serve_one(int timeout_ms) {
    std::size_t n = sock_.receive(buf_.data(), buf_.size(), timeout_ms * 1000);
    if (n == 0) return false;
    uint8_t* src_mac = buf_.data() + 6;
    if (src_mac[0] & 0x02) { // already passed an ESC: a segment's return, not a master's frame
        ++ignored;
        return true;
    }
    uint8_t* pdu = buf_.data() + kEthernetHeader;
    std::size_t len = ethercat_pdu_length(pdu, n - kEthernetHeader);
    auto now = std::chrono::system_clock::now().time_since_epoch();
    int64_t ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count() -
                 946684800LL * 1000000000LL;
    seg_.set_time(uint64_t(ns)); // EtherCAT time: ns since 2000-01-01
    ++frames;
    if (!seg_.process(pdu, len)) return true; // lost on purpose
    src_mac[0] |= 0x02;
    if (n < kMinEthernetFrame) { // the sender did not pad
        std::memset(buf_.data() + n, 0, kMinEthernetFrame - n);
        n = kMinEthernetFrame;
    }
    if (!sock_.send(buf_.data(), n)) ++send_errors;
    return true;
}

void RawServer::run(const volatile bool& stop, int poll_ms) {
    while (!stop) serve_one(poll_ms);
}

} // namespace beamctl::ethercat::sim
