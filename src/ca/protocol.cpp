#include "ca/protocol.hpp"

namespace beamctl::ca {

std::size_t encode_header(uint8_t* p, uint16_t cmd, uint32_t payload, uint16_t dtype,
                          uint32_t count, uint32_t p1, uint32_t p2) {
    put16(p, cmd);
    put16(p + 4, dtype);
    put32(p + 8, p1);
    put32(p + 12, p2);
    if (payload >= 0xFFFF || count >= 0xFFFF) {
        put16(p + 2, 0xFFFF);
        put16(p + 6, 0);
        put32(p + 16, payload);
        put32(p + 20, count);
        return 24;
    }
    put16(p + 2, uint16_t(payload));
    put16(p + 6, uint16_t(count));
    return 16;
}

void append_message(std::string& out, uint16_t cmd, uint16_t dtype, uint32_t count, uint32_t p1,
                    uint32_t p2, const void* payload, std::size_t payload_len) {
    std::size_t padded = pad8(payload_len);
    uint8_t hdr[24];
    std::size_t hs = encode_header(hdr, cmd, uint32_t(padded), dtype, count, p1, p2);
    out.append(reinterpret_cast<const char*>(hdr), hs);
    if (payload_len) out.append(static_cast<const char*>(payload), payload_len);
    out.append(padded - payload_len, '\0');
}

std::size_t decode_header(const uint8_t* p, std::size_t n, bool extended_ok, Header& h) {
    if (n < 16) return 0;
    h.cmd = get16(p);
    uint16_t ps = get16(p + 2);
    h.dtype = get16(p + 4);
    uint16_t cnt = get16(p + 6);
    h.p1 = get32(p + 8);
    h.p2 = get32(p + 12);
    if (ps == 0xFFFF && extended_ok) {
        if (n < 24) return 0;
        h.payload_size = get32(p + 16);
        h.count = get32(p + 20);
        h.header_size = 24;
        return 24;
    }
    h.payload_size = ps;
    h.count = cnt;
    h.header_size = 16;
    return 16;
}

const char* cmd_name(uint16_t cmd) {
    static const char* names[] = {
        "VERSION", "EVENT_ADD", "EVENT_CANCEL", "READ", "WRITE", "SNAPSHOT", "SEARCH", "BUILD",
        "EVENTS_OFF", "EVENTS_ON", "READ_SYNC", "ERROR", "CLEAR_CHANNEL", "RSRV_IS_UP",
        "NOT_FOUND", "READ_NOTIFY", "READ_BUILD", "REPEATER_CONFIRM", "CREATE_CHAN",
        "WRITE_NOTIFY", "CLIENT_NAME", "HOST_NAME", "ACCESS_RIGHTS", "ECHO",
        "REPEATER_REGISTER", "SIGNAL", "CREATE_CH_FAIL", "SERVER_DISCONN"};
    return cmd < sizeof(names) / sizeof(names[0]) ? names[cmd] : "UNKNOWN";
}

} // namespace beamctl::ca
