// Channel Access 4.13 wire format: commands, ECA codes, big-endian helpers and the message header
// (16 bytes, or 24 with the extended form). See ../shared/specs/ca-protocol.md §1, §3, §4.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

namespace beamctl::ca {

constexpr uint16_t kMinorVersion = 13;
constexpr uint16_t kDefaultServerPort = 5064;
constexpr uint16_t kDefaultRepeaterPort = 5065;
constexpr std::size_t kMaxUdpReply = 1024;

enum Cmd : uint16_t {
    kVersion = 0, kEventAdd = 1, kEventCancel = 2, kRead = 3, kWrite = 4, kSnapshot = 5,
    kSearch = 6, kBuild = 7, kEventsOff = 8, kEventsOn = 9, kReadSync = 10, kError = 11,
    kClearChannel = 12, kRsrvIsUp = 13, kNotFound = 14, kReadNotify = 15, kReadBuild = 16,
    kRepeaterConfirm = 17, kCreateChan = 18, kWriteNotify = 19, kClientName = 20, kHostName = 21,
    kAccessRights = 22, kEcho = 23, kRepeaterRegister = 24, kSignal = 25, kCreateChFail = 26,
    kServerDisconn = 27,
};

constexpr uint16_t kSearchDontReply = 5;
constexpr uint16_t kSearchDoReply = 10;

// ECA status codes as they appear on the wire (msg_no << 3 | severity).
enum Eca : uint32_t {
    kEcaNormal = 1, kEcaAllocMem = 48, kEcaTooLarge = 72, kEcaBadType = 114, kEcaInternal = 142,
    kEcaGetFail = 152, kEcaPutFail = 160, kEcaBadCount = 176, kEcaBadStr = 186,
    kEcaBadMonId = 242, kEcaDefunct = 278, kEcaBadMask = 330, kEcaPutCbInProg = 362,
    kEcaNoRdAccess = 368, kEcaNoWtAccess = 376, kEcaNoConvert = 400, kEcaUnavailInServ = 432,
    kEca16kArrayClient = 464,
    kEcaTimeout = 80, kEcaDisconn = 192, // client side: no reply in time; channel disconnected
};

// The text of an ECA code as libca's ca_message() gives it ("unknown ECA code N" otherwise).
std::string eca_message(uint32_t eca);

inline uint16_t get16(const uint8_t* p) { return uint16_t(p[0] << 8 | p[1]); }
inline uint32_t get32(const uint8_t* p) {
    return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3];
}
inline void put16(uint8_t* p, uint16_t v) {
    p[0] = uint8_t(v >> 8);
    p[1] = uint8_t(v);
}
inline void put32(uint8_t* p, uint32_t v) {
    p[0] = uint8_t(v >> 24);
    p[1] = uint8_t(v >> 16);
    p[2] = uint8_t(v >> 8);
    p[3] = uint8_t(v);
}
inline void putf32(uint8_t* p, float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    put32(p, u);
}
inline void putf64(uint8_t* p, double v) {
    uint64_t u;
    std::memcpy(&u, &v, 8);
    put32(p, uint32_t(u >> 32));
    put32(p + 4, uint32_t(u));
}
inline float getf32(const uint8_t* p) {
    uint32_t u = get32(p);
    float v;
    std::memcpy(&v, &u, 4);
    return v;
}
inline double getf64(const uint8_t* p) {
    uint64_t u = uint64_t(get32(p)) << 32 | get32(p + 4);
    double v;
    std::memcpy(&v, &u, 8);
    return v;
}
inline std::size_t pad8(std::size_t n) { return (n + 7) & ~std::size_t(7); }

// A decoded message header. `payload_size` and `count` are the 32-bit values of the extended form.
struct Header {
    uint16_t cmd = 0;
    uint32_t payload_size = 0;
    uint16_t dtype = 0;
    uint32_t count = 0;
    uint32_t p1 = 0;
    uint32_t p2 = 0;
    std::size_t header_size = 16; // 16 or 24
};

// Size of the header needed to send (payload, count): 16, or 24 when either is >= 0xFFFF.
inline std::size_t header_size_for(std::size_t payload, uint32_t count) {
    return (payload >= 0xFFFF || count >= 0xFFFF) ? 24 : 16;
}
// Writes a header (standard or extended as needed) at p; returns its size.
std::size_t encode_header(uint8_t* p, uint16_t cmd, uint32_t payload, uint16_t dtype,
                          uint32_t count, uint32_t p1, uint32_t p2);
// Appends a header (and, if given, a payload padded with zeros to 8) to out.
void append_message(std::string& out, uint16_t cmd, uint16_t dtype, uint32_t count, uint32_t p1,
                    uint32_t p2, const void* payload = nullptr, std::size_t payload_len = 0);

// Decodes a header from at most n bytes. Returns 0 if more bytes are needed, else its size.
// `extended_ok` is false for peers with minor < 9 (0xFFFF is then an ordinary size).
std::size_t decode_header(const uint8_t* p, std::size_t n, bool extended_ok, Header& h);

const char* cmd_name(uint16_t cmd);

} // namespace beamctl::ca
