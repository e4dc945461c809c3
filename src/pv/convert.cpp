#include "pv/convert.hpp"

#include "core/error.hpp"
#include "pv/link.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cfloat>
#include <cinttypes>
#include <climits>
#include <cstdio>
#include <cstdlib>

namespace beamctl::pv {
namespace {

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\n' || s.back() == '\r'))
        s.remove_suffix(1);
    return s;
}

template <typename T> T saturate(double v) {
    if (std::isnan(v)) return T(0);
    if (v >= double(std::numeric_limits<T>::max())) return std::numeric_limits<T>::max();
    if (v <= double(std::numeric_limits<T>::lowest())) return std::numeric_limits<T>::lowest();
    return T(v);
}

template <typename T> T saturate_int(int64_t v) {
    if (v > int64_t(std::numeric_limits<T>::max())) return std::numeric_limits<T>::max();
    if (v < int64_t(std::numeric_limits<T>::lowest())) return std::numeric_limits<T>::lowest();
    return T(v);
}

template <typename T> void store(void* dest, T v) { std::memcpy(dest, &v, sizeof v); }

bool is_integer_dbf(Dbf t) {
    return t != Dbf::Float && t != Dbf::Double && t != Dbf::String && !is_link(t);
}

double read_double(const Elements& e, uint32_t i) {
    const char* p = static_cast<const char*>(e.data) + std::size_t(i) * e.stride;
    switch (e.type) {
    case Dbf::Char: return *reinterpret_cast<const int8_t*>(p);
    case Dbf::UChar: return *reinterpret_cast<const uint8_t*>(p);
    case Dbf::Short: return *reinterpret_cast<const int16_t*>(p);
    case Dbf::UShort:
    case Dbf::Enum:
    case Dbf::Menu: return *reinterpret_cast<const uint16_t*>(p);
    case Dbf::Long: return *reinterpret_cast<const int32_t*>(p);
    case Dbf::ULong: return *reinterpret_cast<const uint32_t*>(p);
    case Dbf::Int64: return double(*reinterpret_cast<const int64_t*>(p));
    case Dbf::UInt64: return double(*reinterpret_cast<const uint64_t*>(p));
    case Dbf::Float: return *reinterpret_cast<const float*>(p);
    case Dbf::Double: return *reinterpret_cast<const double*>(p);
    case Dbf::String: {
        double d = 0;
        parse_double(p, d);
        return d;
    }
    default: return 0; // links have no numeric value
    }
}

int64_t read_int(const Elements& e, uint32_t i) {
    if (!is_integer_dbf(e.type)) { // a double read as an integer: saturated to 32 bits (x86's cast)
        double d = read_double(e, i);
        return saturate<int32_t>(d);
    }
    const char* p = static_cast<const char*>(e.data) + std::size_t(i) * e.stride;
    switch (e.type) {
    case Dbf::Char: return *reinterpret_cast<const int8_t*>(p);
    case Dbf::UChar: return *reinterpret_cast<const uint8_t*>(p);
    case Dbf::Short: return *reinterpret_cast<const int16_t*>(p);
    case Dbf::UShort:
    case Dbf::Enum:
    case Dbf::Menu: return *reinterpret_cast<const uint16_t*>(p);
    case Dbf::Long: return *reinterpret_cast<const int32_t*>(p);
    case Dbf::ULong: return *reinterpret_cast<const uint32_t*>(p);
    case Dbf::Int64: return *reinterpret_cast<const int64_t*>(p);
    case Dbf::UInt64: return int64_t(*reinterpret_cast<const uint64_t*>(p)); // above 2^63: wraps, as a C cast
    default: return 0;
    }
}

void write_double(const Elements& e, uint32_t i, double v) {
    char* p = static_cast<char*>(e.data) + std::size_t(i) * e.stride;
    switch (e.type) {
    case Dbf::Char: *reinterpret_cast<int8_t*>(p) = saturate<int8_t>(v); break;
    case Dbf::UChar: *reinterpret_cast<uint8_t*>(p) = saturate<uint8_t>(v); break;
    case Dbf::Short: *reinterpret_cast<int16_t*>(p) = saturate<int16_t>(v); break;
    case Dbf::UShort:
    case Dbf::Enum:
    case Dbf::Menu: *reinterpret_cast<uint16_t*>(p) = saturate<uint16_t>(v); break;
    case Dbf::Long: *reinterpret_cast<int32_t*>(p) = saturate<int32_t>(v); break;
    case Dbf::ULong: *reinterpret_cast<uint32_t*>(p) = saturate<uint32_t>(v); break;
    case Dbf::Int64: *reinterpret_cast<int64_t*>(p) = saturate<int64_t>(v); break;
    case Dbf::UInt64: *reinterpret_cast<uint64_t*>(p) = saturate<uint64_t>(v); break;
    case Dbf::Float: *reinterpret_cast<float*>(p) = float(v); break;
    case Dbf::Double: *reinterpret_cast<double*>(p) = v; break;
    case Dbf::String: format_double(v, 6, p, e.stride); break; // putDoubleString's default precision
    default: break; // links are written as text only
    }
}

void write_int(const Elements& e, uint32_t i, int64_t v) {
    char* p = static_cast<char*>(e.data) + std::size_t(i) * e.stride;
    switch (e.type) {
    case Dbf::Char: *reinterpret_cast<int8_t*>(p) = saturate_int<int8_t>(v); break;
    case Dbf::UChar: *reinterpret_cast<uint8_t*>(p) = saturate_int<uint8_t>(v); break;
    case Dbf::Short: *reinterpret_cast<int16_t*>(p) = saturate_int<int16_t>(v); break;
    case Dbf::UShort:
    case Dbf::Enum:
    case Dbf::Menu: *reinterpret_cast<uint16_t*>(p) = saturate_int<uint16_t>(v); break;
    case Dbf::Long: *reinterpret_cast<int32_t*>(p) = saturate_int<int32_t>(v); break;
    case Dbf::ULong: *reinterpret_cast<uint32_t*>(p) = saturate_int<uint32_t>(v); break;
    case Dbf::Int64: *reinterpret_cast<int64_t*>(p) = v; break;
    case Dbf::UInt64: *reinterpret_cast<uint64_t*>(p) = uint64_t(v); break; // dbConvert's cast
    case Dbf::Float: *reinterpret_cast<float*>(p) = float(v); break;
    case Dbf::Double: *reinterpret_cast<double*>(p) = double(v); break;
    case Dbf::String: std::snprintf(p, e.stride, "%" PRId64, v); break;
    default: break;
    }
}

// Index of a state string among the field's enum strings or menu choices, -1 if none matches.
int match_state(const Record& r, const FieldDesc& f, std::string_view s, int& n_states) {
    const char* strs[kEnumStates] = {};
    n_states = r.enum_strings(f, strs);
    for (int k = 0; k < n_states; ++k)
        if (strs[k] && s == strs[k]) return k;
    if (f.menu) // menus may have more than 16 choices (menuAlarmStat)
        for (std::size_t k = kEnumStates; k < f.menu->choices.size(); ++k)
            if (s == f.menu->choices[k]) return int(k);
    return -1;
}

bool put_string(Record& r, const FieldDesc& f, const Elements& e, uint32_t i, std::string_view s) {
    char* p = static_cast<char*>(e.data) + std::size_t(i) * e.stride;
    if (e.type == Dbf::String) {
        copy_string(p, e.stride, s);
        return true;
    }
    if (e.type == Dbf::Enum || e.type == Dbf::Menu) {
        int n = 0;
        int k = match_state(r, f, s, n);
        if (k < 0) {
            int64_t v;
            if (!parse_int(s, v) || v < 0) return false;
            std::size_t limit = f.menu ? f.menu->choices.size() : std::size_t(n);
            if (std::size_t(v) >= limit) return false;
            k = int(v);
        }
        *reinterpret_cast<uint16_t*>(p) = uint16_t(k);
        return true;
    }
    if (is_integer_dbf(e.type)) {
        int64_t v;
        if (parse_int(s, v)) {
            write_int(e, i, v);
            return true;
        }
        double d;
        if (!parse_double(s, d)) return false;
        write_double(e, i, d);
        return true;
    }
    double d;
    if (!parse_double(s, d)) return false;
    write_double(e, i, d);
    return true;
}

} // namespace

void format_double(double v, int prec, char* out, std::size_t size) {
    // libCom's cvtDoubleToString, which dbConvert uses for every DBR_STRING of a double: up to 8
    // decimals and |v| <= 1e7 in fixed point, the last digit rounded half up from the truncated
    // next one; otherwise "%*.*e" (more decimals, or |v| > 1e16) or "%.*f" with at most 3.
    if (prec < 0) prec = 0;
    if (std::isnan(v) || prec > 8 || v > 1e7 || v < -1e7) {
        if (prec > 8 || v > 1e16 || v < -1e16)
            std::snprintf(out, size, "%*.*e", std::min(prec, 17) + 7, std::min(prec, 17), v);
        else
            std::snprintf(out, size, "%.*f", std::min(prec, 3), v);
        return;
    }
    static constexpr int32_t kScale[] = {1, 10, 100, 1000, 10000, 100000, 1000000, 10000000, 100000000};
    char buf[32];
    char* p = buf;
    if (v < 0) {
        *p++ = '-';
        v = -v;
    }
    int32_t whole = int32_t(v);
    const int32_t scale = kScale[prec];
    int32_t fraction = int32_t((v - whole) * scale * 10);
    fraction = (fraction + 5) / 10; // half up
    if (fraction / scale >= 1) {
        ++whole;
        fraction -= scale;
    }
    p += std::snprintf(p, buf + sizeof buf - p, "%d", int(whole));
    if (prec > 0) p += std::snprintf(p, buf + sizeof buf - p, ".%0*d", prec, int(fraction));
    copy_string(out, size, std::string_view(buf, std::size_t(p - buf)));
}

bool parse_double(std::string_view s, double& out) {
    s = trim(s);
    if (s.empty()) {
        out = 0;
        return true;
    }
    char buf[128];
    if (s.size() >= sizeof buf) return false;
    std::memcpy(buf, s.data(), s.size());
    buf[s.size()] = 0;
    char* end = nullptr;
    errno = 0;
    double d = std::strtod(buf, &end);
    if (end != buf + s.size()) return false;
    out = d;
    return true;
}

bool parse_int(std::string_view s, int64_t& out) {
    s = trim(s);
    if (s.empty()) {
        out = 0;
        return true;
    }
    char buf[64];
    if (s.size() >= sizeof buf) return false;
    std::memcpy(buf, s.data(), s.size());
    buf[s.size()] = 0;
    char* end = nullptr;
    errno = 0;
    long long v = std::strtoll(buf, &end, 0);
    if (end != buf + s.size() || errno == ERANGE) {
        // unsigned 32/64-bit hex like 0xFFFFFFFF
        errno = 0;
        unsigned long long u = std::strtoull(buf, &end, 0);
        if (end != buf + s.size() || errno == ERANGE || buf[0] == '-') return false;
        out = int64_t(u);
        return true;
    }
    out = v;
    return true;
}

void get_element(const Record& r, const FieldDesc& f, const Elements& e, uint32_t i, Prim p,
                 void* dest) {
    switch (p) {
    case Prim::String: {
        char* d = static_cast<char*>(dest);
        const char* src = static_cast<const char*>(e.data) + std::size_t(i) * e.stride;
        if (e.type == Dbf::String) {
            copy_string(d, kStringSize, std::string_view(src, strnlen(src, e.stride)));
        } else if (is_link(e.type)) {
            copy_string(d, kStringSize, link_text(r, *reinterpret_cast<const Link*>(src)));
        } else if (e.type == Dbf::Enum || e.type == Dbf::Menu) {
            uint16_t v = *reinterpret_cast<const uint16_t*>(src);
            const char* strs[kEnumStates] = {};
            int n = r.enum_strings(f, strs);
            if (f.menu == &kMenuSoftDtyp && !has_device_support(r.type().name()))
                d[0] = 0; // a DBF_DEVICE field with no choices
            else if (v < n && strs[v])
                copy_string(d, kStringSize, strs[v]);
            else if (f.menu && v < f.menu->choices.size())
                copy_string(d, kStringSize, f.menu->choices[v]);
            else if (f.menu) // a menu index without a choice (SSCN's 65535): its number, as softIoc serves it
                std::snprintf(d, kStringSize, "%u", unsigned(v));
            else if (n > 0 || v <= 15) // a state without a string, or none: empty, as softIoc
                d[0] = 0;
            else // mbbi/mbbo get_enum_str beyond the 16 states
                copy_string(d, kStringSize, "Illegal Value");
        } else if (e.type == Dbf::Float || e.type == Dbf::Double) {
            format_double(read_double(e, i), r.precision(f), d, kStringSize);
        } else if (e.type == Dbf::UInt64) {
            std::snprintf(d, kStringSize, "%" PRIu64, *reinterpret_cast<const uint64_t*>(src));
        } else {
            std::snprintf(d, kStringSize, "%" PRId64, read_int(e, i));
        }
        break;
    }
    // dest may be unaligned (inside a message buffer): store through memcpy. An integer field
    // read as a narrower integer type is truncated as base's dbConvert does (a C cast: a longout
    // of -7 read as DBR_ENUM is 65529); a floating-point one is saturated first.
    case Prim::Short: store(dest, int16_t(read_int(e, i))); break;
    case Prim::Enum: store(dest, uint16_t(read_int(e, i))); break;
    case Prim::Char: store(dest, uint8_t(read_int(e, i))); break;
    case Prim::Long: store(dest, int32_t(read_int(e, i))); break;
    case Prim::Float: store(dest, float(read_double(e, i))); break;
    case Prim::Double: store(dest, read_double(e, i)); break;
    }
}

bool put_element(Record& r, const FieldDesc& f, const Elements& e, uint32_t i, Prim p,
                 const void* src) {
    if (is_link(e.type)) return false; // Database::put re-links them (it resolves the target)
    if (e.type == Dbf::Menu && f.menu && p != Prim::String) {
        // A number put to a menu field must index one of its choices. EPICS checks only strings
        // (dbConvert's putShortEnum stores any number); we refuse the rest as out of range.
        double v = p == Prim::Short  ? double(*static_cast<const int16_t*>(src))
                   : p == Prim::Enum ? double(*static_cast<const uint16_t*>(src))
                   : p == Prim::Char ? double(*static_cast<const uint8_t*>(src))
                   : p == Prim::Long ? double(*static_cast<const int32_t*>(src))
                   : p == Prim::Float ? double(*static_cast<const float*>(src))
                                      : *static_cast<const double*>(src);
        if (!(v >= 0 && v < double(f.menu->choices.size()))) return false;
    }
    switch (p) {
    case Prim::String: {
        const char* s = static_cast<const char*>(src);
        return put_string(r, f, e, i, std::string_view(s, strnlen(s, kStringSize)));
    }
    case Prim::Short: write_int(e, i, *static_cast<const int16_t*>(src)); return true;
    case Prim::Enum: write_int(e, i, *static_cast<const uint16_t*>(src)); return true;
    case Prim::Char:
        // DBR_CHAR is unsigned on the wire for UCHAR fields and signed for CHAR ones.
        if (e.type == Dbf::Char)
            write_int(e, i, *static_cast<const int8_t*>(src));
        else
            write_int(e, i, *static_cast<const uint8_t*>(src));
        return true;
    case Prim::Long: write_int(e, i, *static_cast<const int32_t*>(src)); return true;
    case Prim::Float: {
        float v = *static_cast<const float*>(src);
        if (is_integer_dbf(e.type) && std::isnan(v)) return false;
        write_double(e, i, v);
        return true;
    }
    case Prim::Double: {
        double v = *static_cast<const double*>(src);
        if (is_integer_dbf(e.type) && std::isnan(v)) return false;
        if (e.type == Dbf::String && (f.flags & kArray)) { // a STRING array's VAL: its PREC
            format_double(v, r.precision(f), static_cast<char*>(e.data) + std::size_t(i) * e.stride, e.stride);
            return true;
        }
        write_double(e, i, v);
        return true;
    }
    }
    return false;
}

bool parse_field(Record& r, const FieldDesc& f, std::string_view text, std::string* err) {
    Elements e = r.elements(f);
    if (is_link(f.dbf)) {
        std::string why;
        Link l;
        if (!parse_link(text, f.dbf, l, &why)) {
            if (err) *err = SB() << "field " << f.name << ": " << why;
            return false;
        }
        *static_cast<Link*>(e.data) = std::move(l);
        return true;
    }
    if (f.dbf == Dbf::String) {
        if (text.size() >= f.size) {
            if (err) *err = SB() << "string of " << text.size() << " characters is too long for field "
                                 << f.name << " (at most " << (f.size - 1) << ")";
            return false;
        }
        copy_string(static_cast<char*>(e.data), f.size, text);
        return true;
    }
    if (f.dbf == Dbf::Menu) {
        int n = 0;
        int k = match_state(r, f, trim(text), n);
        if (k < 0) {
            int64_t v;
            if (parse_int(text, v) && v >= 0 && std::size_t(v) < f.menu->choices.size()) {
                k = int(v);
            } else {
                if (err) {
                    SB sb;
                    sb << "'" << text << "' is not a choice of " << f.name << " (";
                    for (std::size_t c = 0; c < f.menu->choices.size(); ++c)
                        sb << (c ? ", " : "") << '"' << f.menu->choices[c] << '"';
                    sb << ")";
                    *err = sb.str();
                }
                return false;
            }
        }
        *static_cast<uint16_t*>(e.data) = uint16_t(k);
        return true;
    }
    if (f.dbf == Dbf::UInt64) { // the full unsigned range (epicsParseUInt64)
        uint64_t u = 0;
        std::string_view t = text;
        while (!t.empty() && (t.front() == ' ' || t.front() == '\t')) t.remove_prefix(1);
        int base = 10;
        if (t.size() > 2 && t[0] == '0' && (t[1] == 'x' || t[1] == 'X')) {
            t.remove_prefix(2);
            base = 16;
        }
        auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), u, base);
        if (ec != std::errc() || end != t.data() + t.size()) {
            if (err) *err = SB() << "'" << text << "' is not an unsigned 64-bit integer (field " << f.name << ", DBF_UINT64)";
            return false;
        }
        *static_cast<uint64_t*>(e.data) = u;
        return true;
    }
    if (is_integer_dbf(f.dbf)) {
        int64_t v;
        if (!parse_int(text, v)) {
            double d;
            if (!parse_double(text, d) || d != std::floor(d)) {
                if (err) *err = SB() << "'" << text << "' is not an integer (field " << f.name << ", "
                                     << dbf_name(f.dbf) << ")";
                return false;
            }
            v = int64_t(d);
        }
        double lo = 0, hi = 0;
        switch (f.dbf) {
        case Dbf::Char: lo = -128; hi = 127; break;
        case Dbf::UChar: lo = 0; hi = 255; break;
        case Dbf::Short: lo = -32768; hi = 32767; break;
        case Dbf::UShort:
        case Dbf::Enum: lo = 0; hi = 65535; break;
        case Dbf::Long: lo = -2147483648.0; hi = 2147483647.0; break;
        case Dbf::ULong: lo = -2147483648.0; hi = 4294967295.0; break; // EPICS accepts -1 as 0xFFFFFFFF
        default: lo = -9.3e18; hi = 9.3e18;
        }
        if (double(v) < lo || double(v) > hi) {
            if (err) *err = SB() << "value " << v << " is out of range for field " << f.name << " ("
                                 << dbf_name(f.dbf) << ")";
            return false;
        }
        if (f.dbf == Dbf::ULong && v < 0) v = int64_t(uint32_t(int32_t(v)));
        write_int(e, 0, v);
        return true;
    }
    double d;
    if (!parse_double(text, d)) {
        if (err) *err = SB() << "'" << text << "' is not a number (field " << f.name << ")";
        return false;
    }
    write_double(e, 0, d);
    return true;
}

std::string format_field(Record& r, const FieldDesc& f) {
    Elements e = r.elements(f);
    if (f.flags & kArray) return {};
    const char* p = static_cast<const char*>(e.data);
    switch (f.dbf) {
    case Dbf::InLink:
    case Dbf::OutLink:
    case Dbf::FwdLink: return link_text(r, *reinterpret_cast<const Link*>(p));
    case Dbf::String: return std::string(p, strnlen(p, f.size));
    case Dbf::Menu: {
        uint16_t v = *reinterpret_cast<const uint16_t*>(p);
        if (v < f.menu->choices.size()) return f.menu->choices[v];
        return std::to_string(v);
    }
    case Dbf::Float:
    case Dbf::Double: {
        double v = read_double(e, 0);
        char buf[64];
        for (int prec = 6; prec <= 17; ++prec) {
            std::snprintf(buf, sizeof buf, "%.*g", prec, v);
            if (f.dbf == Dbf::Float ? float(std::strtod(buf, nullptr)) == float(v)
                                    : std::strtod(buf, nullptr) == v)
                break;
        }
        return buf;
    }
    case Dbf::UInt64: return std::to_string(*reinterpret_cast<const uint64_t*>(p));
    default: return std::to_string(read_int(e, 0));
    }
}

} // namespace beamctl::pv
