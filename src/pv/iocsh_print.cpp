// print_field (iocsh.hpp): a field's value as EPICS dbgf/dbpf print it (dbTest.c's layout).
#include "pv/iocsh.hpp"

#include "core/error.hpp"
#include "core/glob.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"

#include <algorithm>
#include <cctype>
#include <cinttypes>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <map>
#include <sstream>
#include <vector>
#include <ostream>
#include <string>

namespace beamctl::pv {

namespace {

// dbTest.c's message buffer: each item starts at a tab stop (every 10 columns) and is padded to
// the next one; a line holds at most 80 characters.
class TabLine {
public:
    explicit TabLine(std::ostream& os, std::size_t tab = 10)
        : os_(os), kTab(tab) {}
    void add(std::string msg) {
        constexpr std::size_t kMax = 80;
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
    const std::size_t kTab; // dbgf 10, dbpr 20
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
    case Dbf::UInt64:
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
    static const std::size_t kElemSize[] = {kStringSize, 1, 1, 2, 2, 4, 4, 8, 8, 4, 8, 2, 2};
    const uint32_t n = std::min<uint32_t>(e.count, uint32_t(800 / kElemSize[int(type)]));
    static const char* kNames[] = {"STRING", "CHAR",  "UCHAR", "SHORT",  "USHORT", "LONG",
                                   "ULONG",  "INT64", "UINT64", "FLOAT", "DOUBLE", "ENUM",   "ENUM"};
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
        case Dbf::UInt64: {
            uint64_t v;
            std::memcpy(&v, p, sizeof v);
            line.add(fmt("%" PRIu64 " = 0x%" PRIx64, v, v));
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

// --- dbl, dbpf, dbpr, scanppl ------------------------------------------------------------------

const char* put_status_text(PutStatus st) {
    switch (st) {
    case PutStatus::Ok:
        return "ok";
    case PutStatus::ReadOnly:
        return "the field is read-only";
    case PutStatus::BadValue:
        return "the value cannot be converted to the field's type";
    case PutStatus::NoAccess:
        return "access denied";
    case PutStatus::Failed:
        return "the record refused the value";
    case PutStatus::Disconnected:
        return "the record went away";
    }
    return "refused";
}

void print_record_list(const Database& db, std::string_view type, std::string_view pattern,
                       std::string_view fields, std::ostream& os) {
    std::vector<std::string> names;
    std::istringstream fs_{std::string(fields)};
    for (std::string f; fs_ >> f;) names.push_back(f);
    // Record types in name order, records in load order (as dbl walks the database).
    std::map<std::string, std::vector<Record*>, std::less<>> by_type;
    for (Record* r : db.records())
        if ((type.empty() || r->type().name() == type) &&
            (pattern.empty() || beamctl::glob_match(pattern, r->name())))
            by_type[r->type().name()].push_back(r);
    for (const auto& [t, recs] : by_type)
        for (Record* r : recs) {
            os << r->name();
            for (const auto& f : names) {
                if (f == "recordType") {
                    os << ", \"" << r->type().name() << "\"";
                } else if (const FieldDesc* fd = r->type().find(f)) {
                    os << ", \"" << format_field(*r, *fd) << "\"";
                } else {
                    os << ", ";
                }
            }
            os << "\n";
        }
}

namespace {

// dbpf's value for an array: a JSON array ([1, 2, "a"]) or one value.
std::vector<std::string> json_array(const std::string& v) {
    std::vector<std::string> items;
    std::size_t i = 0;
    auto skip = [&] {
        while (i < v.size() && std::isspace(static_cast<unsigned char>(v[i]))) ++i;
    };
    skip();
    if (i >= v.size() || v[i] != '[') {
        items.push_back(v);
        return items;
    }
    ++i;
    while (true) {
        skip();
        if (i >= v.size()) throw Error(SB() << "dbpf: array value '" << v << "' has no closing ']'");
        if (v[i] == ']') break;
        std::string item;
        if (v[i] == '"') {
            ++i;
            while (i < v.size() && v[i] != '"') {
                if (v[i] == '\\' && i + 1 < v.size()) ++i;
                item += v[i++];
            }
            if (i >= v.size())
                throw Error(SB() << "dbpf: array value '" << v << "' has an unterminated string");
            ++i;
        } else {
            while (i < v.size() && v[i] != ',' && v[i] != ']' &&
                   !std::isspace(static_cast<unsigned char>(v[i])))
                item += v[i++];
        }
        items.push_back(item);
        skip();
        if (i < v.size() && v[i] == ',')
            ++i;
        else if (i < v.size() && v[i] != ']')
            throw Error(SB() << "dbpf: array value '" << v << "': expected ',' or ']' at column "
                             << (i + 1));
    }
    return items;
}

} // namespace

void put_field_text(Database& db, const std::string& name, const std::string& value,
                    std::ostream& os) {
    Address a;
    if (!db.resolve(name, a)) throw Error(SB() << "dbpf: PV '" << name << "' not found");
    PutStatus st;
    if (a.count > 1 && a.native == Prim::Char) { // char arrays (and rec.FIELD$) take the text
        std::vector<char> s(value.begin(), value.end());
        s.push_back('\0');
        st = db.put(a, Prim::Char, s.data(), uint32_t(std::min<std::size_t>(s.size(), a.count)));
    } else if (a.count > 1) {
        std::vector<std::string> items = json_array(value);
        if (items.empty()) throw Error(SB() << "dbpf " << name << ": no value in '" << value << "'");
        std::vector<char> buf(items.size() * kStringSize, '\0');
        for (std::size_t k = 0; k < items.size(); ++k)
            copy_string(&buf[k * kStringSize], kStringSize, items[k]);
        st = db.put(a, Prim::String, buf.data(),
                    uint32_t(std::min<std::size_t>(items.size(), a.count)));
    } else {
        char s[kStringSize];
        copy_string(s, sizeof s, value);
        st = db.put(a, Prim::String, s, 1);
    }
    print_field(db, name, os);
    if (st != PutStatus::Ok)
        throw Error(SB() << "dbpf " << name << " \"" << value << "\": " << put_status_text(st));
}

bool print_record(const Database& db, std::string_view name, int level, std::ostream& os) {
    Record* r = db.find(name);
    if (!r) {
        os << "Record '" << name << "' not found\n";
        return false;
    }
    static const char* kLevel0[] = {"ASG", "DESC", "DISA", "DISP", "DISV",
                                    "NAME", "SEVR", "STAT", "TPRO", "VAL"};
    std::vector<const FieldDesc*> fields;
    for (const FieldDesc& f : r->type().fields()) {
        bool show = level > 0;
        for (const char* n : kLevel0) show = show || std::strcmp(f.name, n) == 0;
        if (show) fields.push_back(&f);
    }
    std::sort(fields.begin(), fields.end(),
              [](const FieldDesc* x, const FieldDesc* y) { return std::strcmp(x->name, y->name) < 0; });
    TabLine line(os, 20);
    for (const FieldDesc* f : fields) {
        std::string channel = std::string(r->name()) + "." + f->name;
        Address a;
        std::string value;
        if (!db.resolve(channel, a)) continue;
        if (f->flags & kArray) {
            value = fmt("(%u of %u elements)", db.current_count(a), a.count);
        } else {
            char s[kStringSize] = {};
            db.get(a, Prim::String, s, 1);
            value.assign(s, strnlen(s, sizeof s));
        }
        line.add(std::string(f->name) + ": " + value);
    }
    line.flush();
    return true;
}

void print_scan_lists(const Database& db, std::string_view period, std::ostream& os) {
    // The periodic choices of menuScan (3 and up) in menu order, slowest first.
    const auto& choices = kMenuScan.choices;
    std::string want(period);
    if (!want.empty() && want.find(' ') == std::string::npos) {
        double v = 0;
        if (parse_double(want, v))
            for (std::size_t i = 3; i < choices.size(); ++i) {
                double c = std::strtod(choices[i], nullptr);
                if (std::fabs(c - v) < 1e-9) want = choices[i];
            }
    }
    bool any = false;
    for (std::size_t i = 3; i < choices.size(); ++i) {
        if (!want.empty() && want != choices[i]) continue;
        any = true;
        std::vector<Record*> recs;
        for (Record* r : db.records())
            if (r->scan == i) recs.push_back(r);
        std::stable_sort(recs.begin(), recs.end(), [](Record* x, Record* y) { return x->phas < y->phas; });
        os << "Scan list for " << choices[i] << ":\n";
        for (Record* r : recs) os << "    " << r->name() << "\n";
    }
    if (!any) os << "No periodic scan list of period '" << period << "'\n";
}

} // namespace beamctl::pv
