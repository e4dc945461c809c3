#include "ca/search.hpp"

#include <cstring>

namespace beamctl::ca {

void answer_search(const pv::Database& db, uint16_t tcp_port, const uint8_t* p, std::size_t n,
                   std::vector<std::string>& replies, ServerStats& stats) {
    std::string reply;
    uint32_t seq = 0;
    auto start_reply = [&] {
        reply.clear();
        append_message(reply, kVersion, 1, kMinorVersion, seq, 0);
    };
    auto finish_reply = [&] {
        if (reply.size() > 16) replies.push_back(reply);
        start_reply();
    };
    start_reply();
    std::size_t off = 0;
    bool malformed = false;
    while (n - off >= 16) {
        Header h;
        decode_header(p + off, n - off, false, h);
        if (h.payload_size > n - off - 16) {
            malformed = true;
            break;
        }
        const uint8_t* payload = p + off + 16;
        off += 16 + h.payload_size;
        if (h.cmd == kVersion) {
            seq = h.p1;
            if (reply.size() == 16) start_reply();
            continue;
        }
        if (h.cmd != kSearch) continue; // repeater confirms, beacons of other servers, ...
        stats.searches_udp++;
        std::size_t len = strnlen(reinterpret_cast<const char*>(payload), h.payload_size);
        if (len == 0 || len == h.payload_size) { // empty or unterminated name
            malformed = true;
            continue;
        }
        if (h.count < 4) continue; // clients older than minor 4 are not served
        std::string_view name(reinterpret_cast<const char*>(payload), len);
        if (!db.has_record_for(name)) continue;
        stats.search_hits++;
        if (reply.size() + 24 > kMaxUdpReply) finish_reply();
        const uint8_t minor[8] = {0, uint8_t(kMinorVersion), 0, 0, 0, 0, 0, 0};
        append_message(reply, kSearch, tcp_port, 0, 0xFFFFFFFF, h.p2, minor, 8);
    }
    if (off != n) malformed = true;
    if (malformed) stats.udp_malformed++;
    finish_reply();
}

} // namespace beamctl::ca
