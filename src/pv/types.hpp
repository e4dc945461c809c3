// Database field types, CA primitive types, alarm codes, monitor masks and the EPICS timestamp.
// Shared by the PV database (src/pv) and the Channel Access server (src/ca).
#pragma once

#include <cstdint>
#include <string_view>

namespace beamctl::pv {

// Storage type of a record field (EPICS DBF_*).
enum class Dbf : uint8_t {
    String, // fixed-size char array, NUL-terminated
    Char,
    UChar,
    Short,
    UShort,
    Long,
    ULong,
    Int64,
    UInt64, // UTAG, FTVL UINT64 (served over CA as DBR_DOUBLE, as base does)
    Float,
    Double,
    Enum, // record-defined state strings (bi/bo/mbbi/mbbo VAL)
    Menu, // fixed menu choices (SCAN, SEVR, ...)
    // Links (pv/link.hpp): stored as a Link; read over CA as their text (DBR_STRING).
    InLink,  // INP, DOL, INPA, SDIS, ...: a value is read through it
    OutLink, // OUT, OUTA, ...: a value is written through it
    FwdLink, // FLNK, LNK1, ...: the target record is processed
};
constexpr bool is_link(Dbf f) { return f >= Dbf::InLink; }

// The seven value types of Channel Access (DBR_STRING..DBR_DOUBLE); numeric value = DBR code.
enum class Prim : uint8_t { String = 0, Short = 1, Float = 2, Enum = 3, Char = 4, Long = 5, Double = 6 };
constexpr int kStringSize = 40; // MAX_STRING_SIZE: one DBR_STRING element, NUL included
constexpr int kEnumStates = 16;
constexpr int kEnumStringSize = 26;

std::size_t prim_size(Prim p);
Prim native_prim(Dbf f); // how a field of type f looks over CA (db_convert.h)
const char* dbf_name(Dbf f);

// Alarm severities and status codes (alarm.h).
enum Severity : uint16_t { kNoAlarm = 0, kMinor = 1, kMajor = 2, kInvalid = 3 };
enum AlarmStatus : uint16_t {
    kStatNone = 0, kStatRead, kStatWrite, kStatHihi, kStatHigh, kStatLolo, kStatLow, kStatState,
    kStatCos, kStatComm, kStatTimeout, kStatHwLimit, kStatCalc, kStatScan, kStatLink, kStatSoft,
    kStatBadSub, kStatUdf, kStatDisable, kStatSimm, kStatReadAccess, kStatWriteAccess,
};
extern const char* const kSeverityNames[4];
extern const char* const kStatusNames[22];

// Monitor event masks (caeventmask.h).
enum EventMask : unsigned { kDbeValue = 1, kDbeLog = 2, kDbeAlarm = 4, kDbeProperty = 8 };

// EPICS timestamp: seconds since 1990-01-01 UTC plus nanoseconds.
struct EpicsTime {
    uint32_t sec = 0;
    uint32_t nsec = 0;
    static constexpr int64_t kPosixEpochOffset = 631152000; // 1990-01-01 in POSIX seconds
    static EpicsTime now();
};

// Result of a put or get on a field, mapped to ECA codes by the CA server.
enum class PutStatus : uint8_t {
    Ok,
    ReadOnly,     // field is SPC_NOMOD
    BadValue,     // value cannot be converted (bad string, unknown enum state)
    NoAccess,     // access security denied
    Failed,       // the record refused the put
    Disconnected, // the record went away before completion
};

} // namespace beamctl::pv
