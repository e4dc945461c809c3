// The small record types of EPICS base 7: permissive, state and printf (permissiveRecord.c,
// stateRecord.c, printfRecord.c and devPrintfSoft.c). printf formats FMT with values read from
// INP0..INP9 into a long-string VAL (SIZV characters) as base's doPrintf does; over CA VAL is a
// DBF_STRING (its first 39 characters, as softIoc serves it; VAL$ whole), links to char arrays get
// it whole.
// The code is ours.
// Threading: the database thread, as every record.
#include "pv/record_support.hpp"

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>
#include <vector>

namespace beamctl::pv {
namespace {
using namespace support;

bool linked(const Link& l) { return l.kind == Link::Kind::Db || l.kind == Link::Kind::Hw; }

// ---------------------------------------------------------------- permissive
// A handshake between two programs: VAL (button) and WFLG (wait flag), posted when they change.
struct PermissiveRecord : Record {
    using Record::Record;
    uint16_t val = 0, wflg = 0, oval = 0, oflg = 0;
    char labl[20] = {};
    static std::vector<FieldDesc> fields() {
        using R = PermissiveRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, UShort, kVal),
            BEAMCTL_FIELD(R, WFLG, wflg, UShort, kProcess),
            BEAMCTL_FIELD(R, LABL, labl, String, kProcess),
            BEAMCTL_FIELD(R, OVAL, oval, UShort, kReadOnly),
            BEAMCTL_FIELD(R, OFLG, oflg, UShort, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        fill_limits(md, 0, 0, 0, 0); // no get_graphic/control_double in permissiveRecord
    }
    ProcessResult process() override {
        pact = 1;
        udf = 0;
        stamp_time();
        unsigned m = reset_alarms();
        uint16_t old_val = oval, old_flg = oflg;
        oval = val;
        oflg = wflg;
        if (old_val != val) post("VAL", m | kDbeValue | kDbeLog);
        if (old_flg != wflg) post("WFLG", m | kDbeValue | kDbeLog);
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- state
// A 20-character string VAL (deprecated in base in favour of stringin), posted when it changes.
struct StateRecord : Record {
    using Record::Record;
    char val[20] = {}, oval[20] = {};
    static std::vector<FieldDesc> fields() {
        using R = StateRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, String, kVal),
            BEAMCTL_FIELD(R, OVAL, oval, String, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    ProcessResult process() override {
        udf = 0;
        pact = 1;
        stamp_time();
        unsigned m = reset_alarms();
        if (std::strncmp(oval, val, sizeof val) != 0) {
            post("VAL", m | kDbeValue | kDbeLog);
            std::memcpy(oval, val, sizeof oval);
        }
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- printf
constexpr int kPrintfLinks = 10;

struct PrintfRecord : Record {
    explicit PrintfRecord(const RecordType& t) : Record(t), val_buf(kStringSize, 0) { std::strcpy(ivls, "LNK"); }
    uint16_t sizv = 41;
    uint32_t len = 0;
    std::vector<char> val_buf;
    char fmt[81] = {};
    char ivls[16] = {};
    Link out;
    Link inp[kPrintfLinks];
    char scratch[kStringSize] = {}; // a string read through a link
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* len_fd = type().find("LEN");
    // a function-local static: the class is complete in a function body (clang requires it)
    static const FieldDesc& scratch_desc() {
        static const FieldDesc d{"", Dbf::String, 0, kStringSize, nullptr,
                                           [](Record& r) -> void* { return static_cast<PrintfRecord&>(r).scratch; }};
        return d;
    }

    static std::vector<FieldDesc> fields() {
        using R = PrintfRecord;
        auto v = common_fields();
        auto add = {
            FieldDesc{"VAL", Dbf::Char, kVal | kArray | kLongString, 1, nullptr,
                      [](Record& r) -> void* { return static_cast<R&>(r).val_buf.data(); }},
            BEAMCTL_FIELD(R, SIZV, sizv, UShort, kInitOnly),
            BEAMCTL_FIELD(R, LEN, len, ULong, kReadOnly),
            BEAMCTL_FIELD(R, OUT, out, OutLink, 0),
            BEAMCTL_FIELD(R, FMT, fmt, String, kProcess),
            BEAMCTL_FIELD(R, IVLS, ivls, String, 0),
            BEAMCTL_FIELD(R, INP0, inp[0], InLink, 0), BEAMCTL_FIELD(R, INP1, inp[1], InLink, 0),
            BEAMCTL_FIELD(R, INP2, inp[2], InLink, 0), BEAMCTL_FIELD(R, INP3, inp[3], InLink, 0),
            BEAMCTL_FIELD(R, INP4, inp[4], InLink, 0), BEAMCTL_FIELD(R, INP5, inp[5], InLink, 0),
            BEAMCTL_FIELD(R, INP6, inp[6], InLink, 0), BEAMCTL_FIELD(R, INP7, inp[7], InLink, 0),
            BEAMCTL_FIELD(R, INP8, inp[8], InLink, 0), BEAMCTL_FIELD(R, INP9, inp[9], InLink, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        sizv = std::clamp<uint16_t>(sizv, 16, 0x7fff);
        val_buf.assign(std::max<std::size_t>(sizv, kStringSize), 0); // VAL is read as a 40-char string
        len = 0;
    }
    Elements elements(const FieldDesc& f) override {
        if (&f == val_fd) return Elements{Dbf::Char, val_buf.data(), len, sizv, 1};
        return Record::elements(f);
    }

    // A number from link l (a constant: its value, as recGblInitConstantLink); false: no value.
    bool arg_number(Link& l, double& v) {
        if (l.is_constant()) return load_constant(l, v);
        if (!linked(l)) return false;
        return read_link(l, v);
    }
    bool arg_string(Link& l) {
        if (l.is_constant()) {
            const LinkSpec& s = l.s();
            if (s.is_string_constant) copy_string(scratch, sizeof scratch, s.string_constant);
            else if (!s.numbers.empty()) std::snprintf(scratch, sizeof scratch, "%.15g", s.numbers[0]);
            else return false;
            return true;
        }
        if (!linked(l)) return false;
        return read_link(l, scratch_desc());
    }

    // doPrintf: literal text copied, each conversion formatted from the next INPn.
    void do_printf() {
        const char* p = fmt;
        const char* fmt_end = fmt + strnlen(fmt, sizeof fmt);
        char* out_p = val_buf.data();
        int space = sizv - 1;
        int link = 0;
        enum : unsigned { kLeft = 1, kShort = 2, kLong = 4, kLongLong = 8, kChar = 16, kBadFmt = 32, kBadLnk = 64 };
        while (space > 0 && p < fmt_end) {
            char ch = *p++;
            if (ch != '%') {
                *out_p++ = ch;
                --space;
                continue;
            }
            char format[24];
            int fl = 0;
            format[fl++] = '%';
            int width = 0, precision = 0;
            int* num = &width;
            unsigned flags = 0;
            bool more = true;
            ch = 0;
            while (more && p < fmt_end && fl < int(sizeof format) - 8) {
                ch = *p++;
                format[fl++] = ch;
                switch (ch) {
                case '+': case ' ': case '#': break;
                case '-': flags |= kLeft; break;
                case '.': num = &precision; break;
                case '0': case '1': case '2': case '3': case '4':
                case '5': case '6': case '7': case '8': case '9': *num = *num * 10 + ch - '0'; break;
                case '*': {
                    double v;
                    if (*num) flags |= kBadFmt;
                    else if (link < kPrintfLinks && arg_number(inp[link++], v)) {
                        int16_t i = int16_t(v);
                        *num = i;
                        --fl;
                        fl += std::snprintf(format + fl, 7, "%d", i);
                    } else {
                        flags |= kBadLnk;
                    }
                    break;
                }
                case 'h':
                    if (flags & (kLongLong | kLong | kChar)) flags |= kBadFmt;
                    else if (flags & kShort) flags = (flags & ~kShort) | kChar;
                    else flags |= kShort;
                    break;
                case 'l':
                    if (flags & (kLongLong | kShort | kChar)) flags |= kBadFmt;
                    else if (flags & kLong) flags = (flags & ~kLong) | kLongLong;
                    else flags |= kLong;
                    break;
                default:
                    if (!std::strchr("diouxXeEfFgGcs%", ch)) flags |= kBadFmt;
                    more = false;
                    break;
                }
            }
            if (more) break; // the format ended inside a directive
            format[fl] = 0;
            int added = 0;
            double v = 0;
            auto print_int = [&](const char* len_mod, auto value) {
                // Rebuild the directive with the length modifier of the C type printed.
                char f2[32];
                int k = 0;
                for (int i = 0; i < fl - 1; ++i)
                    if (format[i] != 'h' && format[i] != 'l') f2[k++] = format[i];
                for (const char* m = len_mod; *m; ++m) f2[k++] = *m;
                f2[k++] = ch;
                f2[k] = 0;
                added = std::snprintf(out_p, space + 1, f2, value);
            };
            if (!(flags & (kBadFmt | kBadLnk))) {
                if (ch == '%') {
                    added = std::snprintf(out_p, space + 1, "%%");
                } else if (link >= kPrintfLinks) {
                    flags |= kBadLnk;
                } else if (ch == 's') {
                    if (arg_string(inp[link++])) {
                        char f2[32];
                        int k = 0;
                        for (int i = 0; i < fl - 1; ++i)
                            if (format[i] != 'l') f2[k++] = format[i];
                        f2[k++] = 's';
                        f2[k] = 0;
                        added = std::snprintf(out_p, space + 1, f2, scratch);
                    } else {
                        flags |= kBadLnk;
                    }
                } else if ((flags & kLongLong) && std::strchr("diouxX", ch)) {
                    // 64 bits: read as text (a DBR_STRING of an int64 keeps every digit)
                    if (!arg_string(inp[link++])) {
                        flags |= kBadLnk;
                    } else if (ch == 'd' || ch == 'i') {
                        print_int("ll", (long long)std::strtoll(scratch, nullptr, 10));
                    } else {
                        long long i = std::strtoll(scratch, nullptr, 10);
                        print_int("ll", (unsigned long long)(i));
                    }
                } else if (!arg_number(inp[link++], v)) {
                    flags |= kBadLnk;
                } else if (ch == 'c' || ch == 'd' || ch == 'i') {
                    if (ch == 'c' || (flags & kChar)) print_int("", int(int8_t(std::isfinite(v) ? int64_t(v) : 0)));
                    else if (flags & kShort) print_int("", int(int16_t(std::isfinite(v) ? int64_t(v) : 0)));
                    else print_int("", int(int32_t(std::isfinite(v) ? int64_t(v) : 0)));
                } else if (ch == 'o' || ch == 'x' || ch == 'X' || ch == 'u') {
                    int64_t i = std::isfinite(v) ? int64_t(v) : 0;
                    if (flags & kChar) print_int("", unsigned(uint8_t(i)));
                    else if (flags & kShort) print_int("", unsigned(uint16_t(i)));
                    else print_int("", unsigned(uint32_t(i)));
                } else { // e E f F g G (h: as a float)
                    if (flags & kShort) v = float(v);
                    char f2[32];
                    int k = 0;
                    for (int i = 0; i < fl; ++i)
                        if (format[i] != 'h' && format[i] != 'l') f2[k++] = format[i];
                    f2[k] = 0;
                    added = std::snprintf(out_p, space + 1, f2, v);
                }
            }
            if (flags & (kBadFmt | kBadLnk))
                added = std::snprintf(out_p, space + 1, "%s", (flags & kBadLnk) ? ivls : format);
            if (added < 0) added = 0;
            if (added <= space) {
                out_p += added;
                space -= added;
            } else { // truncated
                out_p += space;
                space = 0;
            }
        }
        *out_p++ = 0;
        len = uint32_t(out_p - val_buf.data());
    }

    ProcessResult process() override {
        pact = 1;
        do_printf();
        udf = 0;
        stamp_time();
        // devPrintfSoft: VAL to OUT (a char array target gets it whole, another field a string).
        if (out.target_field() && (out.target_field()->flags & kArray)) {
            write_link(out, *val_fd);
        } else if (linked(out)) {
            copy_string(scratch, sizeof scratch, std::string_view(val_buf.data(), strnlen(val_buf.data(), sizv)));
            write_link(out, scratch_desc());
        }
        unsigned m = reset_alarms() | kDbeValue | kDbeLog;
        post(val_fd, m);
        post(len_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
};

} // namespace

void register_misc_records(RecordTypes& types) {
    add_type<PermissiveRecord>(types, "permissive");
    add_type<StateRecord>(types, "state");
    add_type<PrintfRecord>(types, "printf");
}

} // namespace beamctl::pv
