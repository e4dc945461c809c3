// The remaining soft record types of EPICS base 7: mbbiDirect, mbboDirect, int64in, int64out, lsi,
// lso, with "Soft Channel" device support. Semantics follow base's record support
// (mbbiDirectRecord.c, mbboDirectRecord.c, int64inRecord.c, int64outRecord.c, lsiRecord.c,
// lsoRecord.c and the devXxxSoft.c device support): inputs are read, alarms checked, outputs
// written (IVOA), monitors posted. The code is ours.
// Threading: the database thread, as every record.
#include "pv/record_support.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::pv {
namespace {
using namespace support;

bool linked(const Link& l) { return l.kind == Link::Kind::Db || l.kind == Link::Kind::Hw; }

// ---------------------------------------------------------------- mbbiDirect, mbboDirect
// VAL is a 32-bit word whose bits are also the fields B0..B1F (one UCHAR each, 0 or 1).
constexpr int kBits = 32;
const char* const kBitNames[kBits] = {
    "B0",  "B1",  "B2",  "B3",  "B4",  "B5",  "B6",  "B7",  "B8",  "B9",  "BA",
    "BB",  "BC",  "BD",  "BE",  "BF",  "B10", "B11", "B12", "B13", "B14", "B15",
    "B16", "B17", "B18", "B19", "B1A", "B1B", "B1C", "B1D", "B1E", "B1F"};

template <typename Self> struct MbbDirectBase : Record {
    using Record::Record;
    int32_t val = 0;
    int16_t nobt = 0;
    uint16_t shft = 0;
    uint32_t rval = 0, oraw = 0, mask = 0;
    int32_t mlst = 0;
    uint8_t bits[kBits] = {};
    int32_t sval = 0;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");
    FieldRun bit_fd; // B0..B1F
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }

    static std::vector<FieldDesc> direct_fields(std::vector<FieldDesc> v, uint16_t bit_flags) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Long, kVal),
            BEAMCTL_FIELD(R, NOBT, nobt, Short, kInitOnly),
            BEAMCTL_FIELD(R, SHFT, shft, UShort, 0),
            BEAMCTL_FIELD(R, MASK, mask, ULong, kInitOnly),
            BEAMCTL_FIELD(R, ORAW, oraw, ULong, kReadOnly),
            BEAMCTL_FIELD(R, MLST, mlst, Long, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_bits(v, bit_flags, std::make_index_sequence<kBits>{});
        return v;
    }
    template <std::size_t... I>
    static void add_bits(std::vector<FieldDesc>& v, uint16_t flags, std::index_sequence<I...>) {
        (v.push_back(FieldDesc{kBitNames[I], Dbf::UChar, flags, 1, nullptr,
                               [](Record& r) -> void* { return &static_cast<Self&>(r).bits[I]; }}),
         ...);
    }
    void direct_init() {
        bit_fd.bind(type(), kBitNames, kBits);
        if (mask == 0 && nobt >= 0 && nobt <= 32) mask = uint32_t((uint64_t(1) << nobt) - 1);
        sim_init(*this, sim, *simm_fd);
        if (sval_fd) load_constant(sim.siol, *sval_fd);
    }
    // Raw Soft Channel's mask: MASK shifted by SHFT (all bits without NOBT).
    uint32_t raw_mask() const {
        uint32_t m = nobt == 0 ? 0xffffffffu : mask;
        return shft > 0 && shft < 32 ? m << shft : m;
    }
    void bits_from_val() {
        for (int i = 0; i < kBits; ++i) bits[i] = (uint32_t(val) >> i) & 1u;
    }
    int bit_index(const FieldDesc& f) const { return bit_fd.index_of(f, kBits); }
    int16_t precision(const FieldDesc& f) const override {
        if (&f == val_fd) return nobt; // get_precision: NOBT digits
        return Record::precision(f);
    }
};

struct MbbiDirectRecord : MbbDirectBase<MbbiDirectRecord> {
    using MbbDirectBase::MbbDirectBase;
    Link inp;
    static std::vector<FieldDesc> fields() {
        using R = MbbiDirectRecord;
        auto v = direct_fields(common_fields(), kProcess);
        auto add = {BEAMCTL_FIELD(R, INP, inp, InLink, 0), BEAMCTL_FIELD(R, RVAL, rval, ULong, kProcess),
                    BEAMCTL_FIELD(R, SVAL, sval, Long, 0)};
        v.insert(v.end(), add.begin(), add.end());
        add_simulation_fields<R>(v, true, false);
        return v;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    void init() override {
        direct_init();
        if (load_constant(inp, *val_fd)) udf = 0;
        bits_from_val();
        mlst = val;
        oraw = rval;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (step == SimStep::Now) { // SIOL into SVAL: YES as VAL, RAW as RVAL (shifted down)
            if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                if (sim.simm == 1) val = sval;
                else rval = uint32_t(sval), val = int32_t(shft > 0 && shft < 32 ? rval >> shft : rval);
                udf = 0;
            }
        } else if (dtyp == kDtypRawSoft) { // devMbbiDirectSoftRaw: RVAL & MASK, then VAL = RVAL >> SHFT
            if (soft_read(*this, inp, *rval_fd)) {
                rval &= raw_mask();
                val = int32_t(shft > 0 && shft < 32 ? rval >> shft : rval);
                udf = 0;
            }
        } else if (soft_read(*this, inp, *val_fd)) { // devMbbiDirectSoft reads VAL itself
            udf = 0;
        }
        stamp_time();
        if (udf) set_sevr(kStatUdf, kInvalid);
        unsigned events = reset_alarms();
        unsigned vl = events | kDbeValue | kDbeLog;
        for (int i = 0; i < kBits; ++i) {
            uint8_t old = bits[i];
            bits[i] = (uint32_t(val) >> i) & 1u;
            if (old != bits[i]) post(bit_fd[i], vl);
            else if (events) post(bit_fd[i], events);
        }
        if (mlst != val) {
            events = vl;
            mlst = val;
        }
        if (events) post(val_fd, events);
        if (oraw != rval) {
            post(rval_fd, vl);
            oraw = rval;
        }
        pact = 0;
        return ProcessResult::Done;
    }
};

struct MbboDirectRecord : MbbDirectBase<MbboDirectRecord> {
    using MbbDirectBase::MbbDirectBase;
    Link dol, out;
    uint16_t omsl = 0, ivoa = 0;
    int32_t ivov = 0, obit = 0;
    uint32_t rbv = 0, orbv = 0;
    static std::vector<FieldDesc> fields() {
        using R = MbboDirectRecord;
        auto v = direct_fields(common_fields(), kProcess);
        auto add = {
            BEAMCTL_FIELD(R, RVAL, rval, ULong, kReadOnly),
            BEAMCTL_FIELD(R, RBV, rbv, ULong, kReadOnly),
            BEAMCTL_FIELD(R, ORBV, orbv, ULong, kReadOnly),
            BEAMCTL_FIELD(R, OBIT, obit, Long, kReadOnly),
            BEAMCTL_FIELD(R, DOL, dol, InLink, 0),
            BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, kProcess),
            BEAMCTL_FIELD(R, OUT, out, OutLink, 0),
            BEAMCTL_MENU(R, IVOA, ivoa, kMenuIvoa, 0),
            BEAMCTL_FIELD(R, IVOV, ivov, Long, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_simulation_fields<R>(v, true, true);
        return v;
    }
    void convert() { rval = shft > 0 && shft < 32 ? uint32_t(val) << shft : uint32_t(val); }
    void init() override {
        direct_init();
        if (load_constant(dol, *val_fd)) udf = 0;
        if (!udf) {
            bits_from_val();
        } else { // B0..B1F given in the file define VAL
            uint32_t v = 0;
            for (int i = 0; i < kBits; ++i)
                if (bits[i]) v |= 1u << i;
            if (v) {
                val = int32_t(v);
                udf = 0;
            }
        }
        mlst = val;
        obit = val;
        oraw = rval;
        orbv = rbv;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        int i = bit_index(f);
        if (i < 0) return PutStatus::Ok;
        if (omsl == 1) return PutStatus::Failed; // closed_loop: the bits belong to DOL
        uint32_t bit = 1u << i;
        if (bits[i]) {
            bits[i] = 1;
            val = int32_t(uint32_t(val) | bit);
            obit = int32_t(uint32_t(obit) | bit);
        } else {
            val = int32_t(uint32_t(val) & ~bit);
            obit = int32_t(uint32_t(obit) & ~bit);
        }
        udf = 0;
        convert();
        return PutStatus::Ok;
    }
    // writeValue: Soft Channel VAL, Raw Soft Channel RVAL & MASK, simulated SIOL (YES VAL, RAW RVAL).
    void write_value(SimStep step) {
        if (step == SimStep::Now) {
            write_link(sim.siol, sim.simm == 1 ? *val_fd : *rval_fd);
        } else if (dtyp == kDtypRawSoft) {
            uint32_t keep = rval;
            rval &= raw_mask();
            write_link(out, *rval_fd);
            rval = keep;
        } else {
            write_link(out, *val_fd);
        }
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        bool ok = true;
        if (sim.resuming) {
            // the delayed half: the value was taken before the delay
        } else if (omsl == 1 && linked(dol)) {
            double v = 0;
            if (read_link(dol, v)) val = int32_t(uint32_t(int64_t(v)));
            else ok = false; // read_link raised LINK/INVALID
        } else if (udf) {
            set_sevr(kStatUdf, udfs);
            ok = false;
        }
        if (ok && !sim.resuming) {
            udf = 0;
            bits_from_val();
            convert();
        }
        stamp_time();
        if (nsev < kInvalid || ivoa == 0) {
            write_value(step);
        } else if (ivoa == 2) { // Set output to IVOV
            if (!sim.resuming) {
                val = ivov;
                convert();
            }
            write_value(step);
        }
        bits_from_val();
        unsigned events = reset_alarms();
        if (mlst != val) {
            events |= kDbeValue | kDbeLog;
            mlst = val;
        }
        if (events) post(val_fd, events);
        uint32_t changed = uint32_t(obit) ^ uint32_t(val);
        for (int i = 0; i < kBits; ++i)
            if ((events & ~unsigned(kDbeValue | kDbeLog)) || (changed & (1u << i)))
                post(bit_fd[i], events | kDbeValue | kDbeLog);
        obit = val;
        if (oraw != rval) {
            post(rval_fd, events | kDbeValue | kDbeLog);
            oraw = rval;
        }
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- int64in, int64out
using Int64inRecord = IntegerInRecord<int64_t>; // record_support.hpp, shared with longin
using Int64outRecord = IntegerOutRecord<int64_t>;

// ---------------------------------------------------------------- lsi, lso
// Long strings: VAL is a char array of SIZV (16..32767) characters, NUL-terminated; over CA
// "VAL" is one DBF_STRING (its first 39 characters) and "VAL$" the char array whole, read and
// written as `caget -S` / `caput -S` do; LEN is strlen(VAL) + 1. Links to a char array
// carry the whole string; links to a scalar field carry its first 39 characters as DBR_STRING
// (dbGetLinkLS, dbPutLinkLS).
template <typename Self> struct LongStringBase : Record {
    explicit LongStringBase(const RecordType& t) : Record(t) { allocate(); }
    uint16_t sizv = 41;
    uint32_t len = 0, olen = 0;
    std::vector<char> val_buf, oval_buf;
    char val_placeholder = 0, oval_placeholder = 0;
    char scratch[kStringSize] = {}; // the scalar string of a link to a DBF_STRING (or numeric) field
    uint16_t mpst = 0, apst = 0;    // menuPost: On Change, Always
    Link inp, dol, out;
    uint16_t omsl = 0, ivoa = 0;
    char ivov[kStringSize] = {};
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* oval_fd = type().find("OVAL");
    const FieldDesc* len_fd = type().find("LEN");
    Simulation sim;
    const FieldDesc* simm_fd = type().find("SIMM");
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
    inline static const FieldDesc kScratch{"", Dbf::String, 0, kStringSize, nullptr,
                                           [](Record& r) -> void* { return static_cast<Self&>(r).scratch; }};

    static std::vector<FieldDesc> long_string_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val_placeholder, Char, kVal | kArray | kLongString),
            BEAMCTL_FIELD(R, OVAL, oval_placeholder, Char, kReadOnly | kArray | kLongString),
            BEAMCTL_FIELD(R, SIZV, sizv, UShort, kInitOnly),
            BEAMCTL_FIELD(R, LEN, len, ULong, kReadOnly),
            BEAMCTL_FIELD(R, OLEN, olen, ULong, kReadOnly),
            BEAMCTL_MENU(R, MPST, mpst, kMenuPostOnChange, 0),
            BEAMCTL_MENU(R, APST, apst, kMenuPostOnChange, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void allocate() {
        sizv = std::clamp<uint16_t>(sizv, 16, 0x7fff);
        val_buf.assign(sizv, 0);
        oval_buf.assign(sizv, 0);
        len = olen = 0;
    }
    Elements elements(const FieldDesc& f) override {
        if (&f == val_fd) return Elements{Dbf::Char, val_buf.data(), len, sizv, 1};
        if (&f == oval_fd) return Elements{Dbf::Char, oval_buf.data(), olen, sizv, 1};
        return Record::elements(f);
    }
    void set_count(const FieldDesc& f, uint32_t n) override { // put_array_info: terminated
        if (&f != val_fd) return;
        val_buf[std::min<uint32_t>(n, sizv - 1u)] = 0;
        val_buf[sizv - 1u] = 0;
        len = uint32_t(std::strlen(val_buf.data()) + 1);
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == val_fd) post(len_fd, kDbeValue | kDbeLog);
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    void set_value(std::string_view s) {
        copy_string(val_buf.data(), sizv, s);
        len = uint32_t(std::strlen(val_buf.data()) + 1);
    }
    // dbLoadLinkLS: a constant link's string (or number) into VAL at init.
    bool load_string_constant(const Link& link) {
        if (link.kind != Link::Kind::Constant) return false;
        const LinkSpec& l = link.s();
        if (l.is_string_constant) {
            set_value(l.string_constant);
        } else if (!l.numbers.empty()) {
            char buf[kStringSize];
            std::snprintf(buf, sizeof buf, "%.15g", l.numbers[0]);
            set_value(buf);
        } else {
            return false;
        }
        return len > 1;
    }
    bool read_string(Link& l) {
        if (l.target_field() && (l.target_field()->flags & kArray)) return read_link(l, *val_fd);
        if (!read_link(l, kScratch)) return false;
        set_value(std::string_view(scratch, strnlen(scratch, sizeof scratch)));
        return true;
    }
    bool write_string(Link& l) {
        if (l.target_field() && (l.target_field()->flags & kArray)) return write_link(l, *val_fd);
        copy_string(scratch, sizeof scratch, std::string_view(val_buf.data(), strnlen(val_buf.data(), sizv)));
        return write_link(l, kScratch);
    }
    void long_string_monitor() {
        unsigned ev = reset_alarms();
        if (len != olen || std::memcmp(oval_buf.data(), val_buf.data(), len) != 0) {
            ev |= kDbeValue | kDbeLog;
            std::memcpy(oval_buf.data(), val_buf.data(), len);
        }
        if (len != olen) {
            olen = len;
            post(len_fd, kDbeValue | kDbeLog);
        }
        if (mpst == 1) ev |= kDbeValue;
        if (apst == 1) ev |= kDbeLog;
        if (ev) post(val_fd, ev);
    }
};

struct LsiRecord : LongStringBase<LsiRecord> {
    using LongStringBase::LongStringBase;
    static std::vector<FieldDesc> fields() {
        using R = LsiRecord;
        auto v = long_string_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        add_simulation_fields<R>(v, false, false);
        return v;
    }
    void init() override {
        allocate();
        sim_init(*this, sim, *simm_fd);
        if (load_string_constant(inp)) udf = 0;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (step == SimStep::Now) { // simulated: SIOL instead of INP
            if (linked(sim.siol) && read_string(sim.siol)) udf = 0;
        } else if (dtyp == kDtypGetenv) { // devLsiEnviron: the variable INP names
            std::string name(inp.kind == Link::Kind::Hw ? inp.s().address : std::string());
            if (const char* v = std::getenv(name.c_str())) {
                set_value(v);
                udf = 0;
            } else {
                set_value("");
                udf = 1;
                set_sevr(kStatUdf, udfs, "No such ENV");
            }
        } else if (linked(inp) && read_string(inp)) {
            udf = 0; // devLsiSoft (lsi raises no UDF alarm)
        }
        stamp_time();
        long_string_monitor();
        pact = 0;
        return ProcessResult::Done;
    }
};

struct LsoRecord : LongStringBase<LsoRecord> {
    using LongStringBase::LongStringBase;
    static std::vector<FieldDesc> fields() {
        using R = LsoRecord;
        auto v = long_string_fields(common_fields());
        add_output_fields<R>(v, Dbf::String);
        add_simulation_fields<R>(v, false, true);
        return v;
    }
    void init() override {
        allocate();
        sim_init(*this, sim, *simm_fd);
        if (load_string_constant(dol)) {
            std::memcpy(oval_buf.data(), val_buf.data(), len);
            olen = len;
            udf = 0;
        }
    }
    // The device (OUT; "stdio": @stdout/@stderr) or, simulated, SIOL.
    void write_value(SimStep step) {
        if (step == SimStep::Now) {
            write_string(sim.siol);
        } else if (dtyp == kDtypStdio) {
            std::string_view where = out.kind == Link::Kind::Hw ? std::string_view(out.s().address) : "stdout";
            std::FILE* f = where == "stderr" || where == "errlog" ? stderr : stdout;
            std::fprintf(f, "%.*s\n", int(strnlen(val_buf.data(), sizv)), val_buf.data());
            std::fflush(f);
        } else {
            write_string(out);
        }
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (!sim.resuming && omsl == 1 && linked(dol) && read_string(dol)) udf = 0;
        if (udf) set_sevr(kStatUdf, kInvalid);
        if (nsev < kInvalid || ivoa == 0) {
            write_value(step);
        } else if (ivoa == 2) {
            if (!sim.resuming) set_value(std::string_view(ivov, strnlen(ivov, sizeof ivov)));
            write_value(step);
        }
        stamp_time();
        long_string_monitor();
        pact = 0;
        return ProcessResult::Done;
    }
};

} // namespace

void register_more_records(RecordTypes& types) {
    add_type<MbbiDirectRecord>(types, "mbbiDirect");
    add_type<MbboDirectRecord>(types, "mbboDirect");
    add_type<Int64inRecord>(types, "int64in");
    add_type<Int64outRecord>(types, "int64out");
    add_type<LsiRecord>(types, "lsi");
    add_type<LsoRecord>(types, "lso");
}

} // namespace beamctl::pv
