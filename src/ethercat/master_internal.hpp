// The EtherCAT master's own helpers and register addresses, shared by its source files
// (master.cpp, master_bringup.cpp, master_cyclic.cpp, master_mailbox.cpp, master_recovery.cpp,
// master_dc.cpp). Internal: nothing outside src/ethercat/master*.cpp includes it.
#pragma once

#include "core/error.hpp"
#include "ethercat/sii.hpp"

#include <atomic>
#include <cstdint>
#include <iomanip>
#include <sstream>
#include <string>

namespace beamctl::ethercat::master_detail {
// Adds to a counter only the RT thread writes (other threads read whole values).
inline void bump(std::atomic<uint64_t>& a, uint64_t v) noexcept {
    a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
}

inline const char* al_state_name(uint8_t al) {
    switch (al & 0x0F) {
    case 1: return "INIT";
    case 2: return "PREOP";
    case 3: return "BOOT";
    case 4: return "SAFEOP";
    case 8: return "OP";
    default: return "an unknown state";
    }
}

constexpr uint16_t kAlControl = 0x0120, kAlStatus = 0x0130, kSiiControl = 0x0502,
                   kSiiAddress = 0x0504, kSiiData = 0x0508, kFmmu = 0x0600, kSm = 0x0800;
constexpr uint16_t kStationBase = 0x1001;
constexpr uint8_t kAcyclicIdx = 0xFE; // tag of the acyclic datagram travelling with the cycle
// Cyclic datagram index: bits 3-6 = cycle sequence (mod 16), bits 0-2 = frame number.
constexpr std::size_t kMaxCyclicFrames = 8;

inline std::string hex(uint32_t v, int w = 8) {
    std::ostringstream os;
    os << "0x" << std::hex << std::setw(w) << std::setfill('0') << v;
    return os.str();
}

// "0x1C12:01", as object addresses are written in CoE documentation.
inline std::string object_name(uint16_t index, uint8_t sub) {
    std::ostringstream os;
    os << "0x" << std::hex << std::uppercase << std::setw(4) << std::setfill('0') << index << ":"
       << std::setw(2) << int(sub);
    return os.str();
}

inline std::string sdo_context(int bus, int position, const char* what, uint16_t index, uint8_t sub) {
    return SB() << "ec" << bus << " position " << position << ": SDO " << what << " "
                << object_name(index, sub);
}

// CoE data type name for a mapped entry the SII does not describe.
inline std::string datatype_for_bits(unsigned bits) {
    switch (bits) {
    case 1:
        return "BOOL";
    case 8:
        return "UINT8";
    case 16:
        return "UINT16";
    case 32:
        return "UINT32";
    case 64:
        return "UINT64";
    default:
        return bits < 8 ? std::string(SB() << "BIT" << bits) : std::string();
    }
}

inline const char* state_name(uint8_t s) {
    switch (s & 0x0F) {
    case 1: return "INIT";
    case 2: return "PREOP";
    case 3: return "BOOT";
    case 4: return "SAFEOP";
    case 8: return "OP";
    default: return "UNKNOWN";
    }
}

inline std::string al_code_text(uint16_t c) {
    switch (c) {
    case 0x0011: return "0x0011 invalid requested state change";
    case 0x0012: return "0x0012 unknown requested state";
    case 0x0016: return "0x0016 invalid mailbox configuration";
    case 0x001B: return "0x001B sync manager watchdog";
    case 0x001D: return "0x001D invalid output configuration";
    case 0x001E: return "0x001E invalid input configuration";
    case 0x0030: return "0x0030 invalid DC synchronization configuration";
    default: return hex(c, 4);
    }
}

// The device at a slave's position is not the configured one (health pass: WrongId, not Error).
class IdentityMismatch : public Error {
public:
    using Error::Error;
};

// The slave's system time must be the bus's: it has a DC opmode or maps ESC DC registers
// (master_dc.cpp).
bool uses_dc_time(const SiiInfo& sii);

} // namespace beamctl::ethercat::master_detail
