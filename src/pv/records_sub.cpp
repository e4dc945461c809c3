// sub and aSub records (subRecord.c, aSubRecord.c of base 7) whose INAM/SNAM routines come from
// libraries loaded with dlload (pv/sub_routines.hpp, include/beamctl/record_routines.h). The
// routine sees the record's fields through a C struct that is the fields' own storage, so what
// it writes is the record's value. An INAM or SNAM that no loaded library provides is an init
// error naming the record, the routine and the routines loaded. The code is ours.
// Threading: the database thread, as every record.
#include "pv/record_support.hpp"
#include "pv/sub_routines.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>
#include <vector>

namespace beamctl::pv {
namespace {
// A routine no library provides: as EPICS, the database loads and this record alone fails (it
// raises BAD_SUB/INVALID when processed); the error is reported (Database::record_errors, logged).
void routine_missing(Record& r, const std::string& why) {
    r.init_error(why + "; the record raises BAD_SUB/INVALID when processed");
}
using namespace support;

bool linked(const Link& l) { return l.kind == Link::Kind::Db || l.kind == Link::Kind::Hw; }

// ---------------------------------------------------------------- sub
constexpr int kSubArgs = 12;
const char* const kSubIn[kSubArgs] = {"A", "B", "C", "D", "E", "F", "G", "H", "I", "J", "K", "L"};
const char* const kSubLast[kSubArgs] = {"LA", "LB", "LC", "LD", "LE", "LF", "LG", "LH", "LI", "LJ", "LK", "LL"};
const char* const kSubInp[kSubArgs] = {"INPA", "INPB", "INPC", "INPD", "INPE", "INPF",
                                       "INPG", "INPH", "INPI", "INPJ", "INPK", "INPL"};

struct SubRecord : AnalogBase<SubRecord> {
    using AnalogBase::AnalogBase;
    beamctl_sub c{};            // A..L live here (and VAL while the routine runs)
    double last[kSubArgs] = {}; // LA..LL
    Link inp[kSubArgs];
    char inam[41] = {}, snam[41] = {};
    uint16_t brsv = 0;
    beamctl_sub_routine routine = nullptr;
    const FieldDesc* val_fd = type().find("VAL");
    FieldRun arg_fd; // A..L

    double* arg(int i) { return &c.a + i; } // a..l are consecutive doubles
    static_assert(offsetof(beamctl_sub, l) == offsetof(beamctl_sub, a) + 11 * sizeof(double));

    static std::vector<FieldDesc> fields() {
        using R = SubRecord;
        auto v = analog_fields(common_fields());
        auto add = {
            BEAMCTL_FIELD(R, INAM, inam, String, kInitOnly),
            BEAMCTL_FIELD(R, SNAM, snam, String, 0),
            BEAMCTL_MENU(R, BRSV, brsv, kMenuAlarmSevr, kProcess),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_args(v, std::make_index_sequence<kSubArgs>{});
        return v;
    }
    template <std::size_t... I> static void add_args(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        (v.push_back(FieldDesc{kSubInp[I], Dbf::InLink, 0, sizeof(Link), nullptr,
                               [](Record& r) -> void* { return &static_cast<SubRecord&>(r).inp[I]; }}),
         ...);
        (v.push_back(FieldDesc{kSubIn[I], Dbf::Double, kProcess | kEgu, 8, nullptr,
                               [](Record& r) -> void* { return static_cast<SubRecord&>(r).arg(int(I)); }}),
         ...);
        (v.push_back(FieldDesc{kSubLast[I], Dbf::Double, kReadOnly, 8, nullptr,
                               [](Record& r) -> void* { return &static_cast<SubRecord&>(r).last[I]; }}),
         ...);
    }
    void init() override {
        c.name = name_;
        arg_fd.bind(type(), kSubIn, kSubArgs);
        for (int i = 0; i < kSubArgs; ++i) load_constant(inp[i], *arg(i));
        if (inam[0]) { // the init routine, called once
            const RecordRoutines::Routine* r = RecordRoutines::global().find(inam);
            if (!r || !r->sub) {
                routine_missing(*this, missing_routine_message("INAM", inam, "sub"));
            } else {
                c.val = val;
                r->sub(&c);
                val = c.val;
            }
        }
        if (!snam[0]) { // base's subRecord init_record: "SNAM is empty", and the record never processes
            init_error("SNAM is empty: the record never processes (PACT stays 1, as in EPICS base)");
            pact = 1;
            return;
        }
        const RecordRoutines::Routine* r = RecordRoutines::global().find(snam);
        if (!r || !r->sub) routine_missing(*this, missing_routine_message("SNAM", snam, "sub"));
        else routine = r->sub;
        mlst = alst = lalm = val;
    }
    PutStatus special(const FieldDesc& f) override {
        if (!is(f, "SNAM")) return PutStatus::Ok;
        if (!snam[0]) {
            routine = nullptr;
            return PutStatus::Ok;
        }
        const RecordRoutines::Routine* r = RecordRoutines::global().find(snam);
        if (!r || !r->sub) return PutStatus::BadValue; // the old name stays
        routine = r->sub;
        return PutStatus::Ok;
    }
    ProcessResult process() override {
        pact = 1;
        bool ok = true;
        for (int i = 0; i < kSubArgs && ok; ++i) // fetch_values: stops at the first failing link
            if (linked(inp[i])) ok = read_link(inp[i], *arg(i));
        if (ok) { // do_sub
            if (!routine) {
                set_sevr(kStatBadSub, kInvalid);
            } else {
                c.val = val;
                long status = routine(&c);
                val = c.val;
                if (status < 0) set_sevr(kStatSoft, brsv);
                else udf = std::isnan(val);
            }
        }
        stamp_time();
        analog_alarms();
        unsigned m = analog_monitor_mask();
        if (m) post(val_fd, m);
        for (int i = 0; i < kSubArgs; ++i)
            if (*arg(i) != last[i]) {
                post(arg_fd[i], m | kDbeValue | kDbeLog);
                last[i] = *arg(i);
            }
        pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        analog_metadata(f, md, hopr, lopr);
    }
};

// ---------------------------------------------------------------- aSub
constexpr int kArgs = BEAMCTL_ASUB_ARGS;
#define BEAMCTL_LETTERS(P, S)                                                                      \
    {P "A" S, P "B" S, P "C" S, P "D" S, P "E" S, P "F" S, P "G" S, P "H" S, P "I" S, P "J" S,  \
     P "K" S, P "L" S, P "M" S, P "N" S, P "O" S, P "P" S, P "Q" S, P "R" S, P "S" S, P "T" S,   \
     P "U" S}
const char* const kIn[kArgs] = BEAMCTL_LETTERS("", "");
const char* const kInp[kArgs] = BEAMCTL_LETTERS("INP", "");
const char* const kFt[kArgs] = BEAMCTL_LETTERS("FT", "");
const char* const kNo[kArgs] = BEAMCTL_LETTERS("NO", "");
const char* const kNe[kArgs] = BEAMCTL_LETTERS("NE", "");
const char* const kOut[kArgs] = BEAMCTL_LETTERS("OUT", "");
const char* const kVal[kArgs] = BEAMCTL_LETTERS("VAL", "");
const char* const kFtv[kArgs] = BEAMCTL_LETTERS("FTV", "");
const char* const kNov[kArgs] = BEAMCTL_LETTERS("NOV", "");
const char* const kNev[kArgs] = BEAMCTL_LETTERS("NEV", "");
const char* const kOnv[kArgs] = BEAMCTL_LETTERS("ONV", "");
#undef BEAMCTL_LETTERS

const Menu kMenuLflg{"aSubLFLG", {"IGNORE", "READ"}};
const Menu kMenuEflg{"aSubEFLG", {"NEVER", "ON CHANGE", "ALWAYS"}};

struct ASubRecord : Record {
    explicit ASubRecord(const RecordType& t) : Record(t) {
        for (int i = 0; i < kArgs; ++i) {
            c.fta[i] = c.ftva[i] = 10; // DOUBLE
            c.noa[i] = c.nea[i] = c.nova[i] = c.neva[i] = 1;
        }
    }
    beamctl_asub c{};
    int32_t oval = 0;
    char inam[41] = {}, snam[41] = {}, onam[41] = {};
    uint16_t lflg = 0, eflg = 1, brsv = 0;
    int16_t prec = 0;
    Link subl;
    Link inp[kArgs], out[kArgs];
    uint32_t onv[kArgs] = {};
    std::vector<char> in_buf[kArgs], out_buf[kArgs], old_buf[kArgs]; // A..U, VALA..VALU, OVLA..
    Dbf in_type[kArgs] = {}, out_type[kArgs] = {};
    uint16_t in_size[kArgs] = {}, out_size[kArgs] = {};
    char arr_placeholder = 0;
    beamctl_asub_routine routine = nullptr;
    const FieldDesc* val_fd = type().find("VAL");
    int a_index = type().find("A")->index, vala_index = type().find("VALA")->index;
    // a function-local static: the class is complete in a function body (clang requires it)
    static const FieldDesc& snam_field_desc() {
        static const FieldDesc d{"", Dbf::String, 0, 41, nullptr,
                                             [](Record& r) -> void* { return static_cast<ASubRecord&>(r).snam; }};
        return d;
    }

    static std::vector<FieldDesc> fields() {
        using R = ASubRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, c.val, Long, kAsl0),
            BEAMCTL_FIELD(R, OVAL, oval, Long, kReadOnly),
            BEAMCTL_FIELD(R, INAM, inam, String, kInitOnly),
            BEAMCTL_MENU(R, LFLG, lflg, kMenuLflg, 0),
            BEAMCTL_FIELD(R, SUBL, subl, InLink, kInitOnly),
            BEAMCTL_FIELD(R, SNAM, snam, String, 0),
            BEAMCTL_FIELD(R, ONAM, onam, String, kReadOnly),
            BEAMCTL_MENU(R, BRSV, brsv, kMenuAlarmSevr, kProcess),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_MENU(R, EFLG, eflg, kMenuEflg, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_args(v, std::make_index_sequence<kArgs>{});
        return v;
    }
    // Per argument, in this order (A..U and VALA..VALU consecutive, as elements() relies on).
    template <std::size_t... I> static void add_args(std::vector<FieldDesc>& v, std::index_sequence<I...>) {
        using R = ASubRecord;
        auto fd = [](const char* n, Dbf t, uint16_t flags, uint16_t size, const Menu* m, void* (*a)(Record&)) {
            return FieldDesc{n, t, flags, size, m, a};
        };
        (v.push_back(fd(kInp[I], Dbf::InLink, 0, sizeof(Link), nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).inp[I]; })), ...);
        (v.push_back(fd(kIn[I], Dbf::Double, kAsl0 | kArray, 1, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).arr_placeholder; })), ...);
        (v.push_back(fd(kFt[I], Dbf::Menu, kInitOnly, 2, &kMenuFtype, [](Record& r) -> void* { return &static_cast<R&>(r).c.fta[I]; })), ...);
        (v.push_back(fd(kNo[I], Dbf::ULong, kInitOnly, 4, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).c.noa[I]; })), ...);
        (v.push_back(fd(kNe[I], Dbf::ULong, 0, 4, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).c.nea[I]; })), ...);
        (v.push_back(fd(kOut[I], Dbf::OutLink, 0, sizeof(Link), nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).out[I]; })), ...);
        (v.push_back(fd(kVal[I], Dbf::Double, kAsl0 | kArray, 1, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).arr_placeholder; })), ...);
        (v.push_back(fd(kFtv[I], Dbf::Menu, kInitOnly, 2, &kMenuFtype, [](Record& r) -> void* { return &static_cast<R&>(r).c.ftva[I]; })), ...);
        (v.push_back(fd(kNov[I], Dbf::ULong, kInitOnly, 4, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).c.nova[I]; })), ...);
        (v.push_back(fd(kNev[I], Dbf::ULong, 0, 4, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).c.neva[I]; })), ...);
        (v.push_back(fd(kOnv[I], Dbf::ULong, kReadOnly, 4, nullptr, [](Record& r) -> void* { return &static_cast<R&>(r).onv[I]; })), ...);
    }
    void allocate(const char* ft_name, const char* no_name, uint16_t ft, uint32_t& no, uint32_t& ne,
                  Dbf& t, uint16_t& size, std::vector<char>& buf) {
        if (!ftvl_type(ft, t, size))
            throw Error(SB() << ft_name << " " << (ft < kMenuFtype.choices.size() ? kMenuFtype.choices[ft] : "?")
                             << " is not supported for aSub");
        if (no == 0) no = 1;
        if (no > 64u * 1024 * 1024) throw Error(SB() << no_name << " " << no << " is too large (at most 67108864)");
        buf.assign(std::size_t(no) * size, 0);
        ne = no;
    }
    const RecordRoutines::Routine* lookup(const char* field, const char* n) {
        const RecordRoutines::Routine* r = RecordRoutines::global().find(n);
        if (!r || !r->asub) {
            routine_missing(*this, missing_routine_message(field, n, "aSub"));
            return nullptr;
        }
        return r;
    }
    void init() override {
        c.name = name_;
        for (int i = 0; i < kArgs; ++i) {
            allocate(kFt[i], kNo[i], c.fta[i], c.noa[i], c.nea[i], in_type[i], in_size[i], in_buf[i]);
            allocate(kFtv[i], kNov[i], c.ftva[i], c.nova[i], c.neva[i], out_type[i], out_size[i], out_buf[i]);
            c.a[i] = in_buf[i].data();
            c.vala[i] = out_buf[i].data();
        }
        if (subl.is_constant() && subl.s().is_string_constant) copy_string(snam, sizeof snam, subl.s().string_constant);
        for (int i = 0; i < kArgs; ++i) {
            uint32_t before = c.nea[i];
            c.nea[i] = 0;
            if (!load_constant(inp[i], *field_at(a_index, i)) || c.nea[i] == 0) c.nea[i] = before;
        }
        if (inam[0])
            if (auto* r = lookup("INAM", inam)) r->asub(&c);
        if (lflg == 0 && snam[0])
            if (auto* r = lookup("SNAM", snam)) routine = r->asub;
        std::memcpy(onam, snam, sizeof onam);
        oval = c.val;
        for (int i = 0; i < kArgs; ++i) {
            onv[i] = c.neva[i];
            old_buf[i] = out_buf[i];
        }
    }
    const FieldDesc* field_at(int base, int i) const { return &type().fields()[std::size_t(base + i)]; }
    int arg_of(const FieldDesc& f, int base) const {
        int k = f.index - base;
        return k >= 0 && k < kArgs && (f.flags & kArray) ? k : -1;
    }
    Elements elements(const FieldDesc& f) override {
        if (int i = arg_of(f, a_index); i >= 0)
            return Elements{in_type[i], in_buf[i].data(), std::min(c.nea[i], c.noa[i]), c.noa[i], in_size[i]};
        if (int i = arg_of(f, vala_index); i >= 0)
            return Elements{out_type[i], out_buf[i].data(), std::min(c.neva[i], c.nova[i]), c.nova[i], out_size[i]};
        return Record::elements(f);
    }
    void set_count(const FieldDesc& f, uint32_t n) override {
        if (int i = arg_of(f, a_index); i >= 0) c.nea[i] = n;
        if (int i = arg_of(f, vala_index); i >= 0) c.neva[i] = n;
    }
    PutStatus special(const FieldDesc& f) override {
        if (!is(f, "SNAM") || lflg == 1) return PutStatus::Ok;
        if (!snam[0]) {
            routine = nullptr;
            return PutStatus::Ok;
        }
        const RecordRoutines::Routine* r = RecordRoutines::global().find(snam);
        if (!r || !r->asub) return PutStatus::BadValue;
        routine = r->asub;
        return PutStatus::Ok;
    }
    // fetch_values: SUBL (LFLG READ) and the input links; false stops processing before the routine.
    bool fetch() {
        if (lflg == 1 && linked(subl)) {
            if (!read_link(subl, snam_field_desc())) return false;
            if (snam[0] && std::strcmp(snam, onam) != 0) {
                const RecordRoutines::Routine* r = RecordRoutines::global().find(snam);
                if (!r || !r->asub) return false;
                routine = r->asub;
                std::memcpy(onam, snam, sizeof onam);
            }
        }
        for (int i = 0; i < kArgs; ++i)
            if (linked(inp[i]) && !read_link(inp[i], *field_at(a_index, i))) return false;
        return true;
    }
    ProcessResult process() override {
        pact = 1;
        long status = fetch() ? 0 : -1;
        if (status == 0) { // do_sub
            if (!snam[0]) {
                status = 0;
            } else if (!routine) {
                set_sevr(kStatBadSub, kInvalid);
                status = -1;
            } else {
                status = routine(&c);
                if (status < 0) set_sevr(kStatSoft, brsv);
                else udf = 0;
            }
            c.val = int32_t(status);
        }
        stamp_time();
        if (status == 0)
            for (int i = 0; i < kArgs; ++i)
                if (!out[i].empty()) write_link(out[i], *field_at(vala_index, i));
        monitor();
        pact = 0;
        return ProcessResult::Done;
    }
    void monitor() {
        unsigned m = reset_alarms() | kDbeValue | kDbeLog;
        if (c.val != oval) {
            post(val_fd, m);
            oval = c.val;
        }
        if (eflg == 0) return;
        for (int i = 0; i < kArgs; ++i) {
            uint32_t nev = std::min(c.neva[i], c.nova[i]);
            std::size_t bytes = std::size_t(nev) * out_size[i];
            bool changed = nev != onv[i] || std::memcmp(old_buf[i].data(), out_buf[i].data(), bytes) != 0;
            if (eflg == 1 && !changed) continue;
            std::memcpy(old_buf[i].data(), out_buf[i].data(), bytes);
            post(field_at(vala_index, i), m);
            if (nev != onv[i]) {
                onv[i] = nev;
                post(kNev[i], m);
            }
        }
    }
    int16_t precision(const FieldDesc& f) const override {
        if (f.flags & kArray) return prec;
        return Record::precision(f);
    }
};

} // namespace

void register_sub_records(RecordTypes& types) {
    add_type<SubRecord>(types, "sub");
    add_type<ASubRecord>(types, "aSub");
}

} // namespace beamctl::pv
