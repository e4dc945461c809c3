// A signal bound to its address: what RT code holds after a configuration named a signal
// (`ec0.s3.driveStatus01.3`) and the registry resolved it. get/set are a few instructions on the
// process image; the address never moves once the cycle runs (ARCHITECTURE.md §1).
// Threading: RT thread only (the image belongs to the bus's cycle).
#pragma once

#include <cstdint>
#include <cstring>

namespace beamctl::registry {

struct BoundSignal {
    uint8_t* image = nullptr; // nullptr: not bound (get() is 0, set() does nothing)
    uint32_t bit_offset = 0;  // of the entry in the image
    uint8_t bits = 0;         // entry width
    bool is_signed = false;   // two's complement entry (INT16, DINT, ...)
    int bit = -1;             // >= 0: only this bit of the entry (`.3`)

    bool bound() const noexcept { return image != nullptr; }
    // The raw entry (zero- or sign-extended), or 0/1 for a single bit.
    int64_t get() const noexcept {
        if (!image) return 0;
        uint64_t v = read(bit_offset, bits);
        if (bit >= 0) return int64_t(v >> bit & 1);
        if (is_signed && bits > 0 && bits < 64 && (v >> (bits - 1) & 1)) v |= ~uint64_t(0) << bits;
        return int64_t(v);
    }
    uint64_t get_raw() const noexcept { return image ? read(bit_offset, bits) : 0; }
    bool get_bit(unsigned n) const noexcept { return get_raw() >> n & 1; }
    // Writes the entry (truncated to its width), or only the one bit when `bit` >= 0.
    void set(int64_t v) const noexcept {
        if (!image) return;
        if (bit >= 0) {
            set_bit(unsigned(bit), v != 0);
            return;
        }
        write(bit_offset, bits, uint64_t(v));
    }
    void set_bit(unsigned n, bool on) const noexcept {
        if (!image) return;
        uint32_t b = bit_offset + n;
        if (on) image[b >> 3] |= uint8_t(1u << (b & 7));
        else image[b >> 3] &= uint8_t(~(1u << (b & 7)));
    }

private:
    uint64_t read(uint32_t at, uint8_t n) const noexcept {
        if ((at & 7) == 0 && (n & 7) == 0) {
            uint64_t v = 0;
            std::memcpy(&v, image + at / 8, n / 8); // little-endian host, as EtherCAT
            return v;
        }
        uint64_t v = 0;
        for (uint32_t i = 0; i < n; ++i) v |= uint64_t(image[(at + i) >> 3] >> ((at + i) & 7) & 1) << i;
        return v;
    }
    void write(uint32_t at, uint8_t n, uint64_t v) const noexcept {
        if ((at & 7) == 0 && (n & 7) == 0) {
            std::memcpy(image + at / 8, &v, n / 8);
            return;
        }
        for (uint32_t i = 0; i < n; ++i) {
            uint32_t b = at + i;
            if (v >> i & 1) image[b >> 3] |= uint8_t(1u << (b & 7));
            else image[b >> 3] &= uint8_t(~(1u << (b & 7)));
        }
    }
};

} // namespace beamctl::registry
