// Reading and writing one entry of an EtherCAT process image: the only place that knows bit
// offsets, widths and signedness. The bus (send/receive, output writes), the master, bound
// signals of axes and PLCs, and device support of records all go through these.
// Threading: none of its own; the caller owns the image (RT thread, or a snapshot copy).
#pragma once

#include <cstdint>
#include <cstring>
#include <string_view>

namespace beamctl::registry {

// Where an entry sits: its first bit in the image, its width and whether it is two's complement
// or an IEEE float (real: 32 for REAL32/REAL, 64 for REAL64/LREAL, 0 for an integer).
struct ImageEntry {
    uint32_t bit_offset = 0;
    uint8_t bits = 0;
    bool is_signed = false;
    uint8_t real = 0;
};

// The raw entry, zero-extended. Byte-aligned whole bytes are a memcpy (little-endian host, as EtherCAT).
inline uint64_t image_read(const uint8_t* image, uint32_t bit_offset, uint8_t bits) noexcept {
    uint64_t v = 0;
    if ((bit_offset & 7) == 0 && (bits & 7) == 0 && bits <= 64) {
        std::memcpy(&v, image + bit_offset / 8, bits / 8);
        return v;
    }
    for (uint32_t i = 0; i < bits && i < 64; ++i) v |= uint64_t(image[(bit_offset + i) >> 3] >> ((bit_offset + i) & 7) & 1) << i;
    return v;
}

// Writes the entry, truncated to its width; the bits around it are kept.
inline void image_write(uint8_t* image, uint32_t bit_offset, uint8_t bits, uint64_t v) noexcept {
    if ((bit_offset & 7) == 0 && (bits & 7) == 0 && bits <= 64) {
        std::memcpy(image + bit_offset / 8, &v, bits / 8);
        return;
    }
    for (uint32_t i = 0; i < bits && i < 64; ++i) {
        uint32_t b = bit_offset + i;
        if (v >> i & 1) image[b >> 3] |= uint8_t(1u << (b & 7));
        else image[b >> 3] &= uint8_t(~(1u << (b & 7)));
    }
}

// The raw value of a `bits` wide entry as a signed number (two's complement).
inline int64_t sign_extend(uint64_t raw, uint8_t bits) noexcept {
    if (bits > 0 && bits < 64 && (raw >> (bits - 1) & 1)) raw |= ~uint64_t(0) << bits;
    return int64_t(raw);
}

// The entry as a number: signed entries sign-extended, floats as their value.
inline double raw_to_double(uint64_t raw, const ImageEntry& e) noexcept {
    if (e.real == 32) {
        float f;
        const uint32_t r = uint32_t(raw);
        std::memcpy(&f, &r, sizeof f);
        return f;
    }
    if (e.real == 64) {
        double d;
        std::memcpy(&d, &raw, sizeof d);
        return d;
    }
    return e.is_signed ? double(sign_extend(raw, e.bits)) : double(raw);
}

// A number as the entry's raw bits: negative values in two's complement, then truncated to the
// width (what an output of that width sends).
inline uint64_t double_to_raw(double v, uint8_t bits) noexcept {
    uint64_t raw = v < 0 ? uint64_t(int64_t(v)) : uint64_t(v);
    if (bits < 64) raw &= (uint64_t(1) << bits) - 1;
    return raw;
}

// A number as the raw bits of entry `e`: a float entry gets the IEEE value, others as above.
inline uint64_t double_to_raw(double v, const ImageEntry& e) noexcept {
    if (e.real == 32) {
        const float f = float(v);
        uint32_t r;
        std::memcpy(&r, &f, sizeof r);
        return r;
    }
    if (e.real == 64) {
        uint64_t r;
        std::memcpy(&r, &v, sizeof r);
        return r;
    }
    return double_to_raw(v, e.bits);
}

// The float width of a data type name, ETG.1020 or CoE spelling (the catalog's): 32 for REAL and
// REAL32, 64 for LREAL and REAL64; 0 for every other (integer) type.
inline uint8_t datatype_float_bits(std::string_view t) noexcept {
    return t == "REAL" || t == "REAL32" ? 32 : t == "LREAL" || t == "REAL64" ? 64 : 0;
}

// Whether an EtherCAT (ETG.1020) data type name is two's complement: SINT, INT, DINT, LINT and
// the INTn spellings; USINT, UINT, UDINT, ULINT, BOOL, BITn and the UINTn spellings are not.
inline bool datatype_is_signed(std::string_view t) noexcept {
    return t.rfind("INT", 0) == 0 || t.rfind("SINT", 0) == 0 || t.rfind("DINT", 0) == 0 || t.rfind("LINT", 0) == 0;
}

} // namespace beamctl::registry
