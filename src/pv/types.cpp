#include "pv/types.hpp"

#include <ctime>

namespace beamctl::pv {

std::size_t prim_size(Prim p) {
    switch (p) {
    case Prim::String: return kStringSize;
    case Prim::Short: return 2;
    case Prim::Float: return 4;
    case Prim::Enum: return 2;
    case Prim::Char: return 1;
    case Prim::Long: return 4;
    case Prim::Double: return 8;
    }
    return 0;
}

Prim native_prim(Dbf f) {
    switch (f) {
    case Dbf::String: return Prim::String;
    case Dbf::Char:
    case Dbf::UChar: return Prim::Char;
    case Dbf::Short: return Prim::Short;
    case Dbf::UShort:
    case Dbf::Long: return Prim::Long;
    case Dbf::ULong:
    case Dbf::Int64:
    case Dbf::UInt64: return Prim::Double;
    case Dbf::Float: return Prim::Float;
    case Dbf::Double: return Prim::Double;
    case Dbf::Enum:
    case Dbf::Menu: return Prim::Enum;
    case Dbf::InLink:
    case Dbf::OutLink:
    case Dbf::FwdLink: return Prim::String;
    }
    return Prim::Double;
}

const char* dbf_name(Dbf f) {
    static const char* names[] = {"DBF_STRING", "DBF_CHAR",   "DBF_UCHAR", "DBF_SHORT",
                                  "DBF_USHORT", "DBF_LONG",   "DBF_ULONG", "DBF_INT64", "DBF_UINT64",
                                  "DBF_FLOAT",  "DBF_DOUBLE", "DBF_ENUM",  "DBF_MENU",
                                  "DBF_INLINK", "DBF_OUTLINK", "DBF_FWDLINK"};
    return names[int(f)];
}

const char* const kSeverityNames[4] = {"NO_ALARM", "MINOR", "MAJOR", "INVALID"};
const char* const kStatusNames[22] = {
    "NO_ALARM", "READ",  "WRITE",   "HIHI",    "HIGH",  "LOLO",       "LOW",    "STATE",
    "COS",      "COMM",  "TIMEOUT", "HWLIMIT", "CALC",  "SCAN",       "LINK",   "SOFT",
    "BAD_SUB",  "UDF",   "DISABLE", "SIMM",    "READ_ACCESS", "WRITE_ACCESS"};

EpicsTime EpicsTime::now() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    EpicsTime t;
    t.sec = uint32_t(int64_t(ts.tv_sec) - kPosixEpochOffset);
    t.nsec = uint32_t(ts.tv_nsec);
    return t;
}

} // namespace beamctl::pv
