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

std::string eca_message(uint32_t eca) {
    // libca's messages, indexed by the message number (eca >> 3).
    static const char* const texts[] = {
        "Normal successful completion",
        "Maximum simultaneous IOC connections exceeded",
        "Unknown internet host",
        "Unknown internet service",
        "Unable to allocate a new socket",
        "Unable to connect to internet host or service",
        "Unable to allocate additional dynamic memory",
        "Unknown IO channel",
        "Record field specified inappropriate for channel specified",
        "The requested data transfer is greater than available memory or EPICS_CA_MAX_ARRAY_BYTES",
        "User specified timeout on IO operation expired",
        "Sorry, that feature is planned but not supported at this time",
        "The supplied string is unusually large",
        "The request was ignored because the specified channel is disconnected",
        "The data type specifed is invalid",
        "Remote Channel not found",
        "Unable to locate all user specified channels",
        "Channel Access Internal Failure",
        "The requested local DB operation failed",
        "Channel read request failed",
        "Channel write request failed",
        "Channel subscription request failed",
        "Invalid element count requested",
        "Invalid string",
        "Virtual circuit disconnect",
        "Identical process variable names on multiple servers",
        "Request inappropriate within subscription (monitor) update callback",
        "Database value get for that channel failed during channel search",
        "Unable to initialize without the vxWorks VX_FP_TASK task option set",
        "Event queue overflow has prevented first pass event after event add",
        "Bad event subscription (monitor) identifier",
        "Remote channel has new network address",
        "New or resumed network connection",
        "Specified task isn't a member of a CA context",
        "Attempt to use defunct CA feature failed",
        "The supplied string is empty",
        "Unable to spawn the CA repeater thread- auto reconnect will fail",
        "No channel id match for search reply- search reply ignored",
        "Reseting dead connection- will try to reconnect",
        "Server (IOC) has fallen behind or is not responding- still waiting",
        "No internet interface with broadcast available",
        "Invalid event selection mask",
        "IO operations have completed",
        "IO operations are in progress",
        "Invalid synchronous group identifier",
        "Put callback timed out",
        "Read access denied",
        "Write access denied",
        "Requested feature is no longer supported",
        "Empty PV search address list",
        "No reasonable data conversion between client and server types",
        "Invalid channel identifier",
        "Invalid function pointer",
        "Thread is already attached to a client context",
        "Not supported by attached service",
        "User destroyed channel",
        "Invalid channel priority",
        "Preemptive callback not enabled - additional threads may not join context",
        "Client's protocol revision does not support transfers exceeding 16k bytes",
        "Virtual circuit connection sequence aborted",
        "Virtual circuit unresponsive",
    };
    std::size_t no = eca >> 3;
    if (no < sizeof(texts) / sizeof(texts[0])) return texts[no];
    return "unknown ECA code " + std::to_string(eca);
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
