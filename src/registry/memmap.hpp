// ECMC's memory map (ecmcEcMemMap): `count` equal entries of one slave, back to back in the
// process image, read and written as one array: the n samples per cycle of an oversampling
// channel (EL3702 `ec0.s5.mm.analogInputArray01`, EL4732 `...mm.analogOutputArray01`). PLC code
// reaches it by ECMC's id (the order the IOC creates them: bus, slave position, channel) through
// ec_get_mm_data/ec_set_mm_data/ec_mm_cp/...; records see it as a waveform.
// Threading: get/set/copy on the RT thread (the image belongs to the cycle); `pushes` is the
// RT thread's request (ec_mm_push_asyn) for the IOC loop to publish the array now.
#pragma once

#include "registry/signal.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace beamctl::registry {

// ECMC's ecmcEcDataType of a CoE type name (ec_get_mm_type); 0 (ECMC_EC_NONE) if unknown.
inline uint8_t ecmc_data_type(std::string_view coe) noexcept {
    struct T {
        const char* name;
        uint8_t id;
    };
    static constexpr T types[] = {{"UINT8", 5}, {"INT8", 6},   {"UINT16", 7},  {"INT16", 8},   {"UINT32", 9},
                                  {"INT32", 10}, {"UINT64", 11}, {"INT64", 12}, {"REAL32", 13}, {"REAL64", 14}};
    for (const T& t : types)
        if (coe == t.name) return t.id;
    return 0;
}

struct MemMap {
    static constexpr uint32_t kIndexOutOfRange = 0x211002; // ERROR_MEM_INDEX_OUT_OF_RANGE
    static constexpr uint32_t kNull = 0x2002F;             // ERROR_MAIN_MEM_MAP_NULL

    std::string name;    // "ec0.s5.mm.analogInputArray01"
    BoundSignal first;   // element 0: image, bit offset (byte aligned), width, signedness
    uint32_t count = 0;  // elements
    uint8_t type = 0;    // ecmcEcDataType (ecmc_data_type)
    bool output = false; // RxPDO: the cycle sends what is written
    std::atomic<uint32_t> pushes{0};

    uint32_t bytes() const noexcept { return count * (first.bits / 8u); }
    uint8_t* data() const noexcept { return first.image ? first.image + first.bit_offset / 8 : nullptr; }
    // Element i as ECMC's getDoubleDataAtIndex: 0 or kIndexOutOfRange.
    uint32_t get(double i, double& v) const noexcept {
        if (!(i >= 0 && i < double(count)) || !first.image) return kIndexOutOfRange;
        BoundSignal e = first;
        e.bit_offset += uint32_t(i) * first.bits;
        v = real() ? as_real(e.get_raw()) : double(e.get());
        return 0;
    }
    // Element i = v, converted as ECMC's setDoubleDataAtIndex (a C cast to the element type).
    uint32_t set(double i, double v) const noexcept {
        if (!(i >= 0 && i < double(count)) || !first.image) return kIndexOutOfRange;
        BoundSignal e = first;
        e.bit_offset += uint32_t(i) * first.bits;
        if (real()) {
            e.set(int64_t(from_real(v)));
        } else {
            // NaN and out-of-range values become the nearest representable value, never UB
            double c = std::isfinite(v) ? std::clamp(v, -9.2e18, 1.8e19) : 0.0;
            e.set(c < 0 ? int64_t(c) : int64_t(uint64_t(c)));
        }
        return 0;
    }

private:
    bool real() const noexcept { return type == 13 || type == 14; }
    double as_real(uint64_t raw) const noexcept {
        if (type == 13) {
            float f;
            uint32_t r = uint32_t(raw);
            std::memcpy(&f, &r, 4);
            return f;
        }
        double d;
        std::memcpy(&d, &raw, 8);
        return d;
    }
    uint64_t from_real(double v) const noexcept {
        if (type == 13) {
            float f = float(v);
            uint32_t r;
            std::memcpy(&r, &f, 4);
            return r;
        }
        uint64_t r;
        std::memcpy(&r, &v, 8);
        return r;
    }
};

} // namespace beamctl::registry
