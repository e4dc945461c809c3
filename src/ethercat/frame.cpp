#include "ethercat/frame.hpp"

namespace beamctl::ethercat {

const char* command_name(uint8_t cmd) {
    static const char* names[] = {"NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD",
                                  "BWR", "BRW",  "LRD",  "LWR",  "LRW",  "ARMW", "FRMW"};
    return cmd < 15 ? names[cmd] : "UNKNOWN";
}

void FrameBuilder::reset() noexcept {
    size_ = 2;
    count_ = 0;
    last_hdr_ = 0;
    put_le16(buf_.data(), 0x1000); // type 1, length 0
}

std::size_t FrameBuilder::room() const {
    std::size_t used = size_ + kDatagramOverhead;
    return used >= kMaxFrame ? 0 : kMaxFrame - used;
}

int FrameBuilder::add(uint8_t cmd, uint8_t idx, uint32_t addr, uint16_t len, const void* data) noexcept {
    if (len > kMaxDatagramData || size_ + kDatagramOverhead + len > kMaxFrame) return -1;
    if (count_) { // set the "more follows" bit of the previous datagram
        uint8_t* prev = buf_.data() + last_hdr_;
        put_le16(prev + 6, uint16_t(le16(prev + 6) | 0x8000));
    }
    uint8_t* h = buf_.data() + size_;
    h[0] = cmd;
    h[1] = idx;
    put_le32(h + 2, addr);
    put_le16(h + 6, len);
    put_le16(h + 8, 0);
    if (data) std::memcpy(h + 10, data, len);
    else std::memset(h + 10, 0, len);
    put_le16(h + 10 + len, 0);
    last_hdr_ = size_;
    size_ += kDatagramOverhead + len;
    ++count_;
    put_le16(buf_.data(), uint16_t(0x1000 | ((size_ - 2) & 0x07FF)));
    return int(size_ - 2 - len);
}

} // namespace beamctl::ethercat
