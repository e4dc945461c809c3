#include "ca/dbr.hpp"

#include "ca/protocol.hpp"
#include "pv/convert.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace beamctl::ca {
namespace {

using pv::Prim;

constexpr DbrInfo kTable[] = {
    {Prim::String, DbrKind::Plain, 40, 0},   {Prim::Short, DbrKind::Plain, 2, 0},
    {Prim::Float, DbrKind::Plain, 4, 0},     {Prim::Enum, DbrKind::Plain, 2, 0},
    {Prim::Char, DbrKind::Plain, 1, 0},      {Prim::Long, DbrKind::Plain, 4, 0},
    {Prim::Double, DbrKind::Plain, 8, 0},
    {Prim::String, DbrKind::Sts, 44, 4},     {Prim::Short, DbrKind::Sts, 6, 4},
    {Prim::Float, DbrKind::Sts, 8, 4},       {Prim::Enum, DbrKind::Sts, 6, 4},
    {Prim::Char, DbrKind::Sts, 6, 5},        {Prim::Long, DbrKind::Sts, 8, 4},
    {Prim::Double, DbrKind::Sts, 16, 8},
    {Prim::String, DbrKind::Time, 52, 12},   {Prim::Short, DbrKind::Time, 16, 14},
    {Prim::Float, DbrKind::Time, 16, 12},    {Prim::Enum, DbrKind::Time, 16, 14},
    {Prim::Char, DbrKind::Time, 16, 15},     {Prim::Long, DbrKind::Time, 16, 12},
    {Prim::Double, DbrKind::Time, 24, 16},
    {Prim::String, DbrKind::Gr, 44, 4},      {Prim::Short, DbrKind::Gr, 26, 24},
    {Prim::Float, DbrKind::Gr, 44, 40},      {Prim::Enum, DbrKind::Gr, 424, 422},
    {Prim::Char, DbrKind::Gr, 20, 19},       {Prim::Long, DbrKind::Gr, 40, 36},
    {Prim::Double, DbrKind::Gr, 72, 64},
    {Prim::String, DbrKind::Ctrl, 44, 4},    {Prim::Short, DbrKind::Ctrl, 30, 28},
    {Prim::Float, DbrKind::Ctrl, 52, 48},    {Prim::Enum, DbrKind::Ctrl, 424, 422},
    {Prim::Char, DbrKind::Ctrl, 22, 21},     {Prim::Long, DbrKind::Ctrl, 48, 44},
    {Prim::Double, DbrKind::Ctrl, 88, 80},
    {Prim::Enum, DbrKind::PutAck, 2, 0},     {Prim::Enum, DbrKind::PutAck, 2, 0},
    {Prim::String, DbrKind::StsAck, 48, 8},  {Prim::String, DbrKind::ClassName, 40, 0},
};
static_assert(sizeof(kTable) / sizeof(kTable[0]) == 39);

template <typename T> T sat(double v) {
    if (std::isnan(v)) return T(0);
    if (v >= double(std::numeric_limits<T>::max())) return std::numeric_limits<T>::max();
    if (v <= double(std::numeric_limits<T>::lowest())) return std::numeric_limits<T>::lowest();
    return T(v);
}

// Writes one metadata limit of the element type at p. As base's db_access.c, DBR_CTRL_CHAR and
// DBR_CTRL_SHORT limits are the DBR_GR_LONG ones truncated (a limit of -100 reads 156 as a char).
void put_limit(uint8_t* p, Prim prim, double v) {
    switch (prim) {
    case Prim::Short: put16(p, uint16_t(sat<int32_t>(v))); break;
    case Prim::Char: *p = uint8_t(sat<int32_t>(v)); break;
    case Prim::Long: put32(p, uint32_t(sat<int32_t>(v))); break;
    case Prim::Float: putf32(p, float(v)); break;
    case Prim::Double: putf64(p, v); break;
    default: break;
    }
}

// Converts host-order elements at p (n of type prim) to big-endian in place.
void to_wire(uint8_t* p, Prim prim, uint32_t n) {
    switch (prim) {
    case Prim::Short:
    case Prim::Enum:
        for (uint32_t i = 0; i < n; ++i, p += 2) {
            uint16_t v;
            std::memcpy(&v, p, 2);
            put16(p, v);
        }
        break;
    case Prim::Long:
    case Prim::Float:
        for (uint32_t i = 0; i < n; ++i, p += 4) {
            uint32_t v;
            std::memcpy(&v, p, 4);
            put32(p, v);
        }
        break;
    case Prim::Double:
        for (uint32_t i = 0; i < n; ++i, p += 8) {
            uint64_t v;
            std::memcpy(&v, p, 8);
            v = __builtin_bswap64(v);
            std::memcpy(p, &v, 8);
        }
        break;
    default: break;
    }
}

} // namespace

void host_to_wire(Prim prim, uint8_t* p, uint32_t n) { to_wire(p, prim, n); }

bool dbr_valid(uint16_t t) { return t <= kLastDbr; }
const DbrInfo& dbr_info(uint16_t t) { return kTable[t]; }

std::size_t dbr_payload_size(uint16_t t, uint32_t count) {
    const DbrInfo& d = kTable[t];
    if (count == 0) count = 1;
    return d.size + std::size_t(count - 1) * pv::prim_size(d.prim);
}

uint32_t encode_dbr(const pv::Database& db, const pv::Address& a, uint16_t t, uint32_t count,
                    uint8_t* out) {
    const DbrInfo& d = kTable[t];
    const pv::Record& r = *a.rec;
    std::size_t total = dbr_payload_size(t, count);
    std::memset(out, 0, d.value_offset);

    if (d.kind == DbrKind::ClassName) {
        std::memset(out, 0, 40);
        pv::copy_string(reinterpret_cast<char*>(out), 40, r.type().name());
        return 1;
    }
    if (d.kind != DbrKind::Plain && d.kind != DbrKind::PutAck) {
        if (d.kind == DbrKind::StsAck) {
            put16(out, r.stat);
            put16(out + 2, r.sevr);
            put16(out + 4, r.ackt);
            put16(out + 6, r.acks);
        } else {
            put16(out, r.stat);
            put16(out + 2, r.sevr);
        }
        if (d.kind == DbrKind::Time) {
            put32(out + 4, r.time.sec);
            put32(out + 8, r.time.nsec);
        }
        if ((d.kind == DbrKind::Gr || d.kind == DbrKind::Ctrl) && d.prim != Prim::String) {
            pv::Metadata md;
            if (a.kind == pv::Address::Kind::Field) r.metadata(*a.field, md);
            if (d.prim == Prim::Enum) {
                const char* strs[pv::kEnumStates] = {};
                int n = a.kind == pv::Address::Kind::Field ? r.enum_strings(*a.field, strs) : 0;
                put16(out + 4, uint16_t(n));
                for (int i = 0; i < n; ++i)
                    if (strs[i])
                        std::strncpy(reinterpret_cast<char*>(out + 6 + i * pv::kEnumStringSize),
                                     strs[i], pv::kEnumStringSize);
            } else {
                bool fp = d.prim == Prim::Float || d.prim == Prim::Double;
                std::size_t units_at = fp ? 8 : 4;
                std::size_t lim_at = fp ? 16 : 12;
                if (fp) put16(out + 4, uint16_t(md.precision));
                std::strncpy(reinterpret_cast<char*>(out + units_at), md.units, 8);
                std::size_t w = d.prim == Prim::Char ? 1
                              : d.prim == Prim::Short ? 2
                              : (d.prim == Prim::Long || d.prim == Prim::Float) ? 4 : 8;
                double lims[8] = {md.disp_hi,   md.disp_lo,    md.alarm_hihi, md.alarm_high,
                                  md.alarm_low, md.alarm_lolo, md.ctrl_hi,    md.ctrl_lo};
                int nlim = d.kind == DbrKind::Ctrl ? 8 : 6;
                for (int i = 0; i < nlim; ++i) put_limit(out + lim_at + i * w, d.prim, lims[i]);
            }
        }
    }
    uint8_t* val = out + d.value_offset;
    std::size_t val_bytes = total - d.value_offset;
    uint32_t n = count ? count : 1;
    uint32_t valid = db.get(a, d.prim, val, n);
    // db.get zero-fills past the current count; strings too (char[40] each).
    (void)val_bytes;
    to_wire(val, d.prim, n);
    return valid;
}

bool decode_put(uint16_t t, const uint8_t* payload, std::size_t len, uint32_t count,
                std::vector<char>& host) {
    const DbrInfo& d = kTable[t];
    std::size_t esz = pv::prim_size(d.prim);
    host.resize(std::size_t(count) * esz);
    char* h = host.data();
    if (d.prim == Prim::String && count == 1 && len > 0 && len < esz) {
        // libca sends one DBR_STRING as strlen+1 bytes padded to 8, not 40.
        std::memset(h, 0, esz);
        std::memcpy(h, payload, len);
        h[esz - 1] = 0;
        return true;
    }
    if (len < std::size_t(count) * esz) return false;
    switch (d.prim) {
    case Prim::String:
        std::memcpy(h, payload, host.size());
        for (uint32_t i = 0; i < count; ++i) h[i * 40 + 39] = 0; // terminate every element
        break;
    case Prim::Char: std::memcpy(h, payload, count); break;
    case Prim::Short:
    case Prim::Enum:
        for (uint32_t i = 0; i < count; ++i) {
            uint16_t v = get16(payload + 2 * i);
            std::memcpy(h + 2 * i, &v, 2);
        }
        break;
    case Prim::Long:
    case Prim::Float:
        for (uint32_t i = 0; i < count; ++i) {
            uint32_t v = get32(payload + 4 * i);
            std::memcpy(h + 4 * i, &v, 4);
        }
        break;
    case Prim::Double:
        for (uint32_t i = 0; i < count; ++i) {
            uint64_t v;
            std::memcpy(&v, payload + 8 * i, 8);
            v = __builtin_bswap64(v);
            std::memcpy(h + 8 * i, &v, 8);
        }
        break;
    }
    return true;
}

namespace {
// Reads one metadata limit of the element type at p.
double get_limit(const uint8_t* p, Prim prim) {
    switch (prim) {
    case Prim::Short: return double(int16_t(get16(p)));
    case Prim::Char: return double(*p);
    case Prim::Long: return double(int32_t(get32(p)));
    case Prim::Float: return double(getf32(p));
    case Prim::Double: return getf64(p);
    default: return 0;
    }
}
std::string fixed_string(const uint8_t* p, std::size_t max) {
    const char* c = reinterpret_cast<const char*>(p);
    return std::string(c, strnlen(c, max));
}
} // namespace

bool decode_dbr(uint16_t t, const uint8_t* payload, std::size_t len, uint32_t count,
                DbrValue& out) {
    if (t > 34) return false;
    const DbrInfo& d = kTable[t];
    if (count == 0) count = 1;
    if (count > (1u << 28) || len < dbr_payload_size(t, count)) return false;
    out = DbrValue{};
    out.prim = d.prim;
    out.count = count;
    if (d.kind != DbrKind::Plain) {
        out.status = get16(payload);
        out.severity = get16(payload + 2);
    }
    if (d.kind == DbrKind::Time) {
        out.stamp.sec = get32(payload + 4);
        out.stamp.nsec = get32(payload + 8);
    }
    if ((d.kind == DbrKind::Gr || d.kind == DbrKind::Ctrl) && d.prim != Prim::String) {
        if (d.prim == Prim::Enum) {
            unsigned n = std::min<unsigned>(get16(payload + 4), pv::kEnumStates);
            for (unsigned i = 0; i < n; ++i)
                out.enum_strings.push_back(fixed_string(payload + 6 + i * pv::kEnumStringSize, pv::kEnumStringSize));
        } else {
            bool fp = d.prim == Prim::Float || d.prim == Prim::Double;
            std::size_t units_at = fp ? 8 : 4, lim_at = fp ? 16 : 12;
            if (fp) out.precision = int16_t(get16(payload + 4));
            out.units = fixed_string(payload + units_at, 8);
            std::size_t w = pv::prim_size(d.prim);
            double* lims[8] = {&out.disp_hi,   &out.disp_lo,    &out.alarm_hihi, &out.alarm_high,
                               &out.alarm_low, &out.alarm_lolo, &out.ctrl_hi,    &out.ctrl_lo};
            int nlim = d.kind == DbrKind::Ctrl ? 8 : 6;
            for (int i = 0; i < nlim; ++i) *lims[i] = get_limit(payload + lim_at + i * w, d.prim);
        }
    }
    return decode_put(t, payload + d.value_offset, len - d.value_offset, count, out.data);
}

} // namespace beamctl::ca
