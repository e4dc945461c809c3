// A signal bound to its address: what RT code holds after a configuration named a signal
// (`ec0.s3.driveStatus01.3`) and the registry resolved it. get/set are a few instructions on the
// process image; the address never moves once the cycle runs (ARCHITECTURE.md §1).
// Threading: RT thread only (the image belongs to the bus's cycle).
#pragma once

#include "registry/image.hpp"

#include <cstdint>

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
        uint64_t v = image_read(image, bit_offset, bits);
        if (bit >= 0) return int64_t(v >> bit & 1);
        return is_signed ? sign_extend(v, bits) : int64_t(v);
    }
    uint64_t get_raw() const noexcept { return image ? image_read(image, bit_offset, bits) : 0; }
    bool get_bit(unsigned n) const noexcept { return get_raw() >> n & 1; }
    // Writes the entry (truncated to its width), or only the one bit when `bit` >= 0.
    void set(int64_t v) const noexcept {
        if (!image) return;
        if (bit >= 0) {
            set_bit(unsigned(bit), v != 0);
            return;
        }
        image_write(image, bit_offset, bits, uint64_t(v));
    }
    void set_bit(unsigned n, bool on) const noexcept {
        if (image) image_write(image, bit_offset + n, 1, on ? 1 : 0);
    }
};

} // namespace beamctl::registry
