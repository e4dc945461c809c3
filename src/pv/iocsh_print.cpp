// print_field (iocsh.hpp): a field's value as EPICS dbgf/dbpf print it (dbTest.c's layout).
#include "pv/iocsh.hpp"

#include "pv/database.hpp"

#include <algorithm>
#include <cctype>
#include <cinttypes>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ostream>
#include <string>

namespace beamctl::pv {

namespace {

// dbTest.c's message buffer: each item starts at a tab stop (every 10 columns) and is padded to
// the next one; a line holds at most 80 characters.
class TabLine {
public:
    explicit TabLine(std::ostream& os)
        : os_(os) {}
    void add(std::string msg) {
        constexpr std::size_t kMax = 80, kTab = 10;
        if (msg.size() > kMax) msg.resize(kMax);
        if (line_.size() + msg.size() > kMax) flush();
        line_ += msg;
        line_.resize(std::min(kMax, (line_.size() / kTab + 1) * kTab), ' ');
    }
    void flush() {
        if (!line_.empty()) os_ << line_ << "\n";
        line_.clear();
    }

private:
    std::ostream& os_;
    std::string line_;
};

// epicsStrnEscapedFromRaw: C escapes for unprintable characters.
std::string escaped(std::string_view s) {
    std::string out;
    for (char c : s) {
        switch (c) {
        case '\a':
            out += "\\a";
            break;
        case '\b':
            out += "\\b";
            break;
        case '\f':
            out += "\\f";
            break;
        case '\n':
            out += "\\n";
            break;
        case '\r':
            out += "\\r";
            break;
        case '\t':
            out += "\\t";
            break;
        case '\v':
            out += "\\v";
            break;
        case '\\':
            out += "\\\\";
            break;
        case '\'':
            out += "\\'";
            break;
        case '"':
            out += "\\\"";
            break;
        default:
            if (std::isprint(static_cast<unsigned char>(c))) {
                out += c;
            } else {
                char b[8];
                std::snprintf(b, sizeof b, "\\x%02x", unsigned(static_cast<unsigned char>(c)));
                out += b;
            }
        }
    }
    return out;
}

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...) {
    char buf[128];
    va_list ap;
    va_start(ap, f);
    std::vsnprintf(buf, sizeof buf, f, ap);
    va_end(ap);
    return buf;
}

} // namespace

bool print_field(const Database& db, std::string_view channel, std::ostream& os) {
    Address a;
    if (!db.resolve(channel, a)) {
        os << "PV '" << channel << "' not found\n";
        return false;
    }
    TabLine line(os);
    auto label = [&](const char* type, uint32_t n) {
        std::string s = n == 1 ? fmt("DBF_%s: ", type) : fmt("DBF_%s[%u]: ", type, n);
        if (n == 0) s += "(empty)";
        line.add(s);
    };
    auto print_string = [&](std::string_view s) {
        line.add("\"" + escaped(s.substr(0, 77)) + "\"");
    };

    // Enum and menu fields (and links, the record type) are read as strings, as dbgf does.
    Dbf type = Dbf::String;
    Elements e{};
    const bool plain = a.kind == Address::Kind::Field;
    if (plain) {
        e = a.rec->elements(*a.field);
        type = e.type;
    } else if (a.kind == Address::Kind::LongString) {
        type = Dbf::Char;
    }
    switch (type) {
    case Dbf::Char:
    case Dbf::UChar:
    case Dbf::Short:
    case Dbf::UShort:
    case Dbf::Long:
    case Dbf::ULong:
    case Dbf::Int64:
    case Dbf::Float:
    case Dbf::Double:
        break;
    case Dbf::String:
        if (plain) break;
        [[fallthrough]];
    default: { // enum, menu, link, .RTYP: one string
        char s[kStringSize] = {};
        db.get(a, Prim::String, s, 1);
        label("STRING", 1);
        print_string(std::string_view(s, strnlen(s, sizeof s)));
        line.flush();
        return true;
    }
    }

    if (a.kind == Address::Kind::LongString) { // rec.FIELD$: the string as a char array
        const char* s = static_cast<const char*>(a.field->addr(*a.rec));
        std::string_view v(s, strnlen(s, a.field->size));
        label("CHAR", uint32_t(v.size() + 1));
        for (std::size_t i = 0; i < v.size(); i += 75) {
            std::string chunk = "\"" + escaped(v.substr(i, 75)) + "\"";
            if (i + 75 < v.size()) chunk += " +";
            line.add(chunk);
        }
        line.flush();
        return true;
    }

    // As many elements as dbgf's 800-byte buffer holds.
    static const std::size_t kElemSize[] = {kStringSize, 1, 1, 2, 2, 4, 4, 8, 4, 8, 2, 2};
    const uint32_t n = std::min<uint32_t>(e.count, uint32_t(800 / kElemSize[int(type)]));
    static const char* kNames[] = {"STRING", "CHAR",  "UCHAR", "SHORT",  "USHORT", "LONG",
                                   "ULONG",  "INT64", "FLOAT", "DOUBLE", "ENUM",   "ENUM"};
    label(kNames[int(type)], n);
    const char* p = static_cast<const char*>(e.data);
    if (type == Dbf::Char && n > 1) {
        std::string_view v(p, strnlen(p, n));
        for (std::size_t i = 0; i < v.size(); i += 75) {
            std::string chunk = "\"" + escaped(v.substr(i, 75)) + "\"";
            if (i + 75 < v.size()) chunk += " +";
            line.add(chunk);
        }
        line.flush();
        return true;
    }
    for (uint32_t i = 0; i < n; ++i, p += e.stride) {
        switch (type) {
        case Dbf::String:
            print_string(std::string_view(p, strnlen(p, e.stride)));
            break;
        case Dbf::Char: {
            int v = *reinterpret_cast<const int8_t*>(p);
            line.add(std::isprint(v) ? fmt("%d = 0x%x = '%c'", v, v & 0xff, v)
                                     : fmt("%d = 0x%x", v, v & 0xff));
            break;
        }
        case Dbf::UChar: {
            unsigned v = *reinterpret_cast<const uint8_t*>(p);
            line.add(fmt("%u = 0x%x", v, v));
            break;
        }
        case Dbf::Short: {
            int16_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%hd = 0x%hx", v, uint16_t(v)));
            break;
        }
        case Dbf::UShort: {
            uint16_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%hu = 0x%hx", v, v));
            break;
        }
        case Dbf::Long: {
            int32_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%d = 0x%x", v, uint32_t(v)));
            break;
        }
        case Dbf::ULong: {
            uint32_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%u = 0x%x", v, v));
            break;
        }
        case Dbf::Int64: {
            int64_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(v < 0 ? fmt("%" PRId64 " = -0x%" PRIx64, v, uint64_t(0) - uint64_t(v))
                           : fmt("%" PRId64 " = 0x%" PRIx64, v, uint64_t(v)));
            break;
        }
        case Dbf::Float: {
            float v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%.6g", double(v)));
            break;
        }
        case Dbf::Double: {
            double v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%.12g", v));
            break;
        }
        default:
            break;
        }
    }
    line.flush();
    return true;
}

} // namespace beamctl::pv
