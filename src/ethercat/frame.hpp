// EtherCAT frames (ethercat.md §1): the EtherCAT header (u16 LE: length bits 0-10, type bits 12-15)
// followed by datagrams `cmd u8 | idx u8 | addr u32 | len u16 | irq u16 | data | wkc u16`, all
// little-endian. A "frame" here is that EtherCAT PDU; links add the Ethernet or UDP wrapping.
// FrameBuilder and for_each_datagram never allocate and are safe on the RT thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace beamctl::ethercat {

enum Command : uint8_t {
    kNop = 0, kAprd = 1, kApwr = 2, kAprw = 3, kFprd = 4, kFpwr = 5, kFprw = 6, kBrd = 7,
    kBwr = 8, kBrw = 9, kLrd = 10, kLwr = 11, kLrw = 12, kArmw = 13, kFrmw = 14,
};
const char* command_name(uint8_t cmd);

constexpr uint16_t kEtherType = 0x88A4;
constexpr uint16_t kUdpPort = 0x88A4;            // 34980
constexpr std::size_t kMaxEthernetPayload = 1500; // Ethernet MTU
constexpr std::size_t kEthernetHeader = 14;
constexpr std::size_t kMaxFrame = kMaxEthernetPayload; // EtherCAT PDU bytes (header + datagrams)
constexpr std::size_t kDatagramOverhead = 12;          // 10-byte header + 2-byte WKC
constexpr std::size_t kMaxDatagramData = kMaxFrame - 2 - kDatagramOverhead; // 1486

inline uint16_t le16(const uint8_t* p) { return uint16_t(p[0] | p[1] << 8); }
inline uint32_t le32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
inline uint64_t le64(const uint8_t* p) { return uint64_t(le32(p)) | uint64_t(le32(p + 4)) << 32; }
inline void put_le16(uint8_t* p, uint16_t v) {
    p[0] = uint8_t(v);
    p[1] = uint8_t(v >> 8);
}
inline void put_le32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline void put_le64(uint8_t* p, uint64_t v) {
    for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}

// A datagram inside a frame buffer (pointers into it).
struct Datagram {
    uint8_t* hdr;  // the 10-byte header
    uint8_t* data; // len bytes
    uint8_t cmd() const { return hdr[0]; }
    uint8_t idx() const { return hdr[1]; }
    uint16_t adp() const { return le16(hdr + 2); }
    uint16_t ado() const { return le16(hdr + 4); }
    uint32_t logical() const { return le32(hdr + 2); }
    uint16_t len() const { return le16(hdr + 6) & 0x07FF; }
    bool circulating() const { return le16(hdr + 6) & 0x4000; }
    bool more() const { return le16(hdr + 6) & 0x8000; }
    uint16_t wkc() const { return le16(data + len()); }
    void set_adp(uint16_t v) { put_le16(hdr + 2, v); }
    void set_wkc(uint16_t v) { put_le16(data + len(), v); }
    void add_wkc(uint16_t v) { set_wkc(uint16_t(wkc() + v)); }
};

// Builds one frame in a fixed buffer.
class FrameBuilder {
public:
    FrameBuilder() { reset(); }
    void reset() noexcept;
    // Appends a datagram; returns its data offset in the frame, or -1 if it doesn't fit.
    // `data` may be null (zeros).
    int add(uint8_t cmd, uint8_t idx, uint32_t addr, uint16_t len, const void* data = nullptr) noexcept;
    int add(uint8_t cmd, uint8_t idx, uint16_t adp, uint16_t ado, uint16_t len,
            const void* data = nullptr) noexcept {
        return add(cmd, idx, uint32_t(adp) | uint32_t(ado) << 16, len, data);
    }
    std::size_t size() const { return size_; }
    std::size_t datagram_count() const { return count_; }
    const uint8_t* data() const { return buf_.data(); }
    uint8_t* data() { return buf_.data(); }
    std::size_t room() const; // data bytes a further datagram could carry

private:
    std::array<uint8_t, kMaxFrame> buf_{};
    std::size_t size_ = 2;
    std::size_t count_ = 0;
    std::size_t last_hdr_ = 0;
};

// Calls fn(Datagram&) for each datagram of a frame. Returns false (after the datagrams that were
// well-formed) if the frame is truncated, has a bad header type or length fields that don't fit.
template <typename Fn> bool for_each_datagram(uint8_t* frame, std::size_t n, Fn&& fn) noexcept {
    if (n < 2) return false;
    uint16_t h = le16(frame);
    std::size_t len = h & 0x07FF;
    if ((h >> 12) != 1 || len + 2 > n) return false;
    std::size_t off = 2, end = 2 + len;
    for (;;) {
        if (end - off < kDatagramOverhead) return false;
        Datagram d{frame + off, frame + off + 10};
        std::size_t dl = d.len();
        if (end - off < kDatagramOverhead + dl) return false;
        fn(d);
        off += kDatagramOverhead + dl;
        if (!d.more()) return true;
        if (off >= end) return false;
    }
}

} // namespace beamctl::ethercat
