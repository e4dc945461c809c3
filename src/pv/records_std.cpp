// The standard soft record types of EPICS base: ai ao bi bo longin longout mbbi mbbo stringin
// stringout waveform, with "Soft Channel" device support (no links). Semantics follow base's
// record support (checkAlarms, monitor, convert) so clients see what a softIoc would show.
#include "core/error.hpp"
#include "pv/record.hpp"
#include "pv/database.hpp"
#include "pv/record_support.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace beamctl::pv {
namespace {
using namespace support;

struct AiRecord : AnalogBase<AiRecord> {
    using AnalogBase::AnalogBase;
    Link inp;
    double smoo = 0;
    bool smoothed = false; // a value was read before (smoothing starts from the second)
    const FieldDesc* val_fd = type().find("VAL");
    static std::vector<FieldDesc> fields() {
        using R = AiRecord;
        auto v = analog_fields(common_fields());
        auto add = {BEAMCTL_FIELD(R, INP, inp, InLink, 0), BEAMCTL_FIELD(R, SMOO, smoo, Double, 0)};
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        if (load_constant(inp, *val_fd)) udf = std::isnan(val);
    }
    ProcessResult process() override {
        pact = 1;
        double before = val;
        if (soft_read(*this, inp, *val_fd)) { // devAiSoft: the value, smoothed by SMOO
            if (smoo != 0 && smoothed && std::isfinite(before)) val = val * (1 - smoo) + before * smoo;
            smoothed = true;
        }
        stamp_time();
        udf = std::isnan(val); // aiRecord: soft channel with a constant input defines VAL
        analog_alarms();
        if (unsigned m = analog_monitor_mask()) post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        analog_metadata(f, md, hopr, lopr);
    }
};

struct AoRecord : AnalogBase<AoRecord> {
    using AnalogBase::AnalogBase;
    double oval = 0, drvh = 0, drvl = 0, oroc = 0, pval = 0, ivov = 0;
    Link dol, out;
    uint16_t omsl = 0, oif = 0, ivoa = 0;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* oval_fd = type().find("OVAL");
    static std::vector<FieldDesc> fields() {
        using R = AoRecord;
        auto v = analog_fields(common_fields());
        auto add = {
            BEAMCTL_FIELD(R, OVAL, oval, Double, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, PVAL, pval, Double, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, DRVH, drvh, Double, kProcess | kProp | kEgu),
            BEAMCTL_FIELD(R, DRVL, drvl, Double, kProcess | kProp | kEgu),
            BEAMCTL_FIELD(R, OROC, oroc, Double, kEgu),
            BEAMCTL_FIELD(R, DOL, dol, InLink, 0),
            BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, 0),
            BEAMCTL_MENU(R, OIF, oif, kMenuOif, 0),
            BEAMCTL_FIELD(R, OUT, out, OutLink, 0),
            BEAMCTL_MENU(R, IVOA, ivoa, kMenuIvoa, 0),
            BEAMCTL_FIELD(R, IVOV, ivov, Double, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        if (load_constant(dol, *val_fd)) udf = std::isnan(val);
    }
    ProcessResult process() override {
        pact = 1;
        if (omsl == 1 && (dol.is_db() || dol.kind == Link::Kind::Hw)) { // closed_loop: VAL from DOL
            double v = 0;
            if (read_link(dol, v)) {
                val = oif == 1 ? val + v : v; // Incremental adds to VAL
                udf = std::isnan(val);
            }
        }
        double value = val;
        if (drvh > drvl) value = std::clamp(value, drvl, drvh);
        val = value;
        pval = value;
        double prev = oval;
        if (oroc != 0 && std::isfinite(prev)) {
            double diff = value - prev;
            if (diff < -oroc) value = prev - oroc;
            else if (diff > oroc) value = prev + oroc;
        }
        oval = value;
        analog_alarms();
        soft_write(*this, out, *oval_fd, ivoa, [this] { oval = ivov; });
        stamp_time();
        if (unsigned m = analog_monitor_mask()) post(val_fd, m);
        if (oval != prev) post(oval_fd, kDbeValue | kDbeLog);
        pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        analog_metadata(f, md, drvh, drvl);
    }
};

// ---------------------------------------------------------------- long (longin, longout)
using LonginRecord = IntegerInRecord<int32_t>;  // record_support.hpp, shared with int64in
using LongoutRecord = IntegerOutRecord<int32_t>;

// ---------------------------------------------------------------- binary (bi, bo)
template <typename Self> struct BinaryBase : Record {
    using Record::Record;
    uint16_t val = 0;
    char znam[26] = {}, onam[26] = {};
    uint16_t zsv = 0, osv = 0, cosv = 0;
    uint32_t rval = 0, mask = 0;
    uint16_t lalm = 0, mlst = 0;
    Link inp, dol, out; // Soft Channel: bi INP; bo DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0, ivov = 0;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");

    static std::vector<FieldDesc> binary_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Enum, kVal),
            BEAMCTL_FIELD(R, ZNAM, znam, String, kMeta | kProcess),
            BEAMCTL_FIELD(R, ONAM, onam, String, kMeta | kProcess),
            BEAMCTL_MENU(R, ZSV, zsv, kMenuAlarmSevr, kProcess),
            BEAMCTL_MENU(R, OSV, osv, kMenuAlarmSevr, kProcess),
            BEAMCTL_MENU(R, COSV, cosv, kMenuAlarmSevr, kProcess),
            BEAMCTL_FIELD(R, RVAL, rval, ULong, kProcess),
            BEAMCTL_FIELD(R, MASK, mask, ULong, 0),
            BEAMCTL_FIELD(R, LALM, lalm, UShort, kReadOnly),
            BEAMCTL_FIELD(R, MLST, mlst, UShort, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == val_fd && val > 1) return PutStatus::BadValue; // two states only
        return PutStatus::Ok;
    }
    int enum_strings(const FieldDesc& f, const char* out[kEnumStates]) const override {
        if (&f != val_fd) return Record::enum_strings(f, out);
        out[0] = znam;
        out[1] = onam;
        return 2;
    }
    void init() override {
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
    }
    void binary_process(bool output) {
        uint32_t old_rval = rval;
        if (!output && soft_read(*this, inp, *val_fd)) udf = 0;
        if (output && omsl == 1 && soft_read(*this, dol, *val_fd)) {
            if (val > 1) val = 1; // boRecord: any non-zero DOL value is 1
            udf = 0;
        }
        if (output) rval = mask ? (val ? mask : 0) : val;
        else if (rval != old_rval) val = rval ? 1 : 0;
        const uint16_t sevr_of[2] = {zsv, osv};
        state_alarms(*this, val, 2, sevr_of, kNoAlarm, cosv, lalm);
        if (output) soft_write(*this, out, *val_fd, ivoa, [this] { val = ivov ? 1 : 0; });
        stamp_time();
        unsigned m = reset_alarms();
        if (mlst != val) {
            m |= kDbeValue | kDbeLog;
            mlst = val;
        }
        if (m) post(val_fd, m);
        if (rval != old_rval) post(rval_fd, kDbeValue | kDbeLog);
    }
};

struct BiRecord : BinaryBase<BiRecord> {
    using BinaryBase::BinaryBase;
    static std::vector<FieldDesc> fields() {
        using R = BiRecord;
        auto v = binary_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        binary_process(false);
        pact = 0;
        return ProcessResult::Done;
    }
};

struct BoRecord : BinaryBase<BoRecord> {
    using BinaryBase::BinaryBase;
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) md.ctrl_hi = 65535; // boRecord's get_control_double (as softIoc serves)
    }
    static std::vector<FieldDesc> fields() {
        using R = BoRecord;
        auto v = binary_fields(common_fields());
        add_output_fields<R>(v, Dbf::UShort);
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        binary_process(true);
        pact = 0;
        return ProcessResult::Done;
    }
};

// synApps' busy record (the busy module's busyRecord.c): a bo whose forward link, and so the
// completion of a put-callback, waits while VAL is 1. A client puts 1 with a callback; the owner of
// the work (a driver, a sequence) puts 0 when it is done, and the callback completes then. HIGH > 0:
// VAL returns to 0 by itself after HIGH seconds (the database's clock).
struct BusyRecord : BinaryBase<BusyRecord> {
    using BinaryBase::BinaryBase;
    double high = 0;
    bool waiting = false; // returned Async: a put-callback and the forward link wait for VAL 0
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) md.ctrl_hi = 65535;
    }
    static std::vector<FieldDesc> fields() {
        using R = BusyRecord;
        auto v = binary_fields(common_fields());
        add_output_fields<R>(v, Dbf::UShort);
        v.push_back(BEAMCTL_FIELD(R, HIGH, high, Double, 0));
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        binary_process(true);
        pact = 0; // busy, but not in processing: the owner's put of 0 processes it
        if (val != 0) {
            if (high > 0) call_after(high);
            waiting = true;
            return ProcessResult::Async;
        }
        if (waiting) {
            waiting = false;
            async_done(); // the put-callback that waited for the 1 completes; FLNK follows (Done)
        }
        return ProcessResult::Done;
    }
    void on_delay() override { // HIGH passed: back to 0
        if (val == 0 || !database()) return;
        val = 0;
        database()->process(*this);
    }
};

// ---------------------------------------------------------------- multi-bit (mbbi, mbbo)
#define MBB_STATE_FIELDS(R, P, V, S)                                                                \
    BEAMCTL_FIELD(R, P##ST, strs[V], String, kMeta | kProcess),                                    \
        BEAMCTL_FIELD(R, P##VL, vals[V], ULong, kProcess),                                          \
        BEAMCTL_MENU(R, P##SV, sevs[V], kMenuAlarmSevr, kProcess)

template <typename Self> struct MbbBase : Record {
    using Record::Record;
    uint16_t val = 0;
    char strs[16][26] = {};
    uint32_t vals[16] = {};
    uint16_t sevs[16] = {};
    uint16_t unsv = 0, cosv = 0;
    uint32_t rval = 0, mask = 0;
    int16_t nobt = 0, shft = 0;
    uint16_t lalm = 0, mlst = 0;
    uint8_t sdef = 0;
    Link inp, dol, out; // Soft Channel: mbbi INP; mbbo DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0, ivov = 0;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");

    static std::vector<FieldDesc> mbb_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Enum, kVal),
            MBB_STATE_FIELDS(R, ZR, 0, zr),  MBB_STATE_FIELDS(R, ON, 1, on),
            MBB_STATE_FIELDS(R, TW, 2, tw),  MBB_STATE_FIELDS(R, TH, 3, th),
            MBB_STATE_FIELDS(R, FR, 4, fr),  MBB_STATE_FIELDS(R, FV, 5, fv),
            MBB_STATE_FIELDS(R, SX, 6, sx),  MBB_STATE_FIELDS(R, SV, 7, sv),
            MBB_STATE_FIELDS(R, EI, 8, ei),  MBB_STATE_FIELDS(R, NI, 9, ni),
            MBB_STATE_FIELDS(R, TE, 10, te), MBB_STATE_FIELDS(R, EL, 11, el),
            MBB_STATE_FIELDS(R, TV, 12, tv), MBB_STATE_FIELDS(R, TT, 13, tt),
            MBB_STATE_FIELDS(R, FT, 14, ft), MBB_STATE_FIELDS(R, FF, 15, ff),
            BEAMCTL_MENU(R, UNSV, unsv, kMenuAlarmSevr, kProcess),
            BEAMCTL_MENU(R, COSV, cosv, kMenuAlarmSevr, kProcess),
            BEAMCTL_FIELD(R, RVAL, rval, ULong, kProcess),
            BEAMCTL_FIELD(R, MASK, mask, ULong, 0),
            BEAMCTL_FIELD(R, NOBT, nobt, Short, 0),
            BEAMCTL_FIELD(R, SHFT, shft, Short, 0),
            BEAMCTL_FIELD(R, LALM, lalm, UShort, kReadOnly),
            BEAMCTL_FIELD(R, MLST, mlst, UShort, kReadOnly),
            BEAMCTL_FIELD(R, SDEF, sdef, UChar, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        update_sdef();
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
    }
    void update_sdef() {
        sdef = 0;
        for (int i = 0; i < 16; ++i)
            if (vals[i]) sdef = 1;
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == val_fd && val > 15) return PutStatus::BadValue; // sixteen states only
        if (f.name[2] == 'V' && f.name[3] == 'L' && !f.name[4]) update_sdef();
        return PutStatus::Ok;
    }
    int enum_strings(const FieldDesc& f, const char* out[kEnumStates]) const override {
        if (&f != val_fd) return Record::enum_strings(f, out);
        int n = 0;
        for (int i = 0; i < 16; ++i) {
            out[i] = strs[i];
            if (strs[i][0]) n = i + 1;
        }
        return n;
    }
    void mbb_process(bool output) {
        uint32_t old_rval = rval;
        if (!output && soft_read(*this, inp, *val_fd)) udf = 0;
        if (output && omsl == 1 && soft_read(*this, dol, *val_fd)) udf = 0;
        if (output) rval = sdef ? (val < 16 ? vals[val] : 0) : val;
        state_alarms(*this, val, 16, sevs, unsv, cosv, lalm);
        if (output) soft_write(*this, out, *val_fd, ivoa, [this] { val = ivov; });
        stamp_time();
        unsigned m = reset_alarms();
        if (mlst != val) {
            m |= kDbeValue | kDbeLog;
            mlst = val;
        }
        if (m) post(val_fd, m);
        if (rval != old_rval) post(rval_fd, kDbeValue | kDbeLog);
    }
};

struct MbbiRecord : MbbBase<MbbiRecord> {
    using MbbBase::MbbBase;
    static std::vector<FieldDesc> fields() {
        using R = MbbiRecord;
        auto v = mbb_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        mbb_process(false);
        pact = 0;
        return ProcessResult::Done;
    }
};

struct MbboRecord : MbbBase<MbboRecord> {
    using MbbBase::MbbBase;
    static std::vector<FieldDesc> fields() {
        using R = MbboRecord;
        auto v = mbb_fields(common_fields());
        add_output_fields<R>(v, Dbf::UShort);
        return v;
    }
    ProcessResult process() override {
        pact = 1;
        mbb_process(true);
        pact = 0;
        return ProcessResult::Done;
    }
};

// ---------------------------------------------------------------- strings (stringin, stringout)
template <typename Self> struct StringBase : Record {
    using Record::Record;
    char val[40] = {}, oval[40] = {}, ivov[40] = {};
    uint16_t mpst = 0, apst = 0; // On Change by default
    Link inp, dol, out; // Soft Channel: stringin INP; stringout DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0;
    bool output = false;
    const FieldDesc* val_fd = type().find("VAL");
    static std::vector<FieldDesc> string_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, String, kVal),
            BEAMCTL_FIELD(R, OVAL, oval, String, kReadOnly),
            BEAMCTL_MENU(R, MPST, mpst, kMenuPostOnChange, 0),
            BEAMCTL_MENU(R, APST, apst, kMenuPostOnChange, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
    }
    ProcessResult process() override {
        pact = 1;
        if (!output && soft_read(*this, inp, *val_fd)) udf = 0;
        if (output && omsl == 1 && soft_read(*this, dol, *val_fd)) udf = 0;
        if (udf) set_sevr(kStatUdf, udfs);
        if (output) soft_write(*this, out, *val_fd, ivoa, [this] { std::memcpy(val, ivov, sizeof val); });
        stamp_time();
        unsigned m = reset_alarms();
        bool changed = std::strncmp(oval, val, sizeof val) != 0;
        if (mpst == 1 || changed) m |= kDbeValue;
        if (apst == 1 || changed) m |= kDbeLog;
        std::memcpy(oval, val, sizeof val);
        if (m) post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
};
struct StringinRecord : StringBase<StringinRecord> {
    using StringBase::StringBase;
    static std::vector<FieldDesc> fields() {
        using R = StringinRecord;
        auto v = string_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        return v;
    }
};
struct StringoutRecord : StringBase<StringoutRecord> {
    explicit StringoutRecord(const RecordType& t) : StringBase(t) { output = true; }
    static std::vector<FieldDesc> fields() {
        using R = StringoutRecord;
        auto v = string_fields(common_fields());
        add_output_fields<R>(v, Dbf::String);
        return v;
    }
};

// ---------------------------------------------------------------- waveform
struct WaveformRecord : Record {
    using Record::Record;
    uint16_t ftvl = 10; // DOUBLE
    uint32_t nelm = 1, nord = 0;
    char egu[16] = {};
    int16_t prec = 0;
    double hopr = 0, lopr = 0;
    uint16_t mpst = 0, apst = 0; // Always by default
    std::vector<char> storage;   // NELM elements of FTVL
    char val_placeholder = 0;
    Link inp;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* nord_fd = type().find("NORD");

    static std::vector<FieldDesc> fields() {
        using R = WaveformRecord;
        auto v = common_fields();
        auto add = {
            BEAMCTL_FIELD(R, VAL, val_placeholder, Double, kVal | kArray | kEgu | kDisplayHopr),
            BEAMCTL_MENU(R, FTVL, ftvl, kMenuFtype, kInitOnly),
            BEAMCTL_FIELD(R, NELM, nelm, ULong, kInitOnly),
            BEAMCTL_FIELD(R, NORD, nord, ULong, kReadOnly),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta | kEgu),
            BEAMCTL_MENU(R, MPST, mpst, kMenuPostAlways, 0),
            BEAMCTL_MENU(R, APST, apst, kMenuPostAlways, 0),
            BEAMCTL_FIELD(R, INP, inp, InLink, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    static bool elem_type(uint16_t ftvl, Dbf& t, uint16_t& size) {
        switch (ftvl) {
        case 0: t = Dbf::String; size = 40; return true;
        case 1: t = Dbf::Char; size = 1; return true;
        case 2: t = Dbf::UChar; size = 1; return true;
        case 3: t = Dbf::Short; size = 2; return true;
        case 4: t = Dbf::UShort; size = 2; return true;
        case 5: t = Dbf::Long; size = 4; return true;
        case 6: t = Dbf::ULong; size = 4; return true;
        case 7: t = Dbf::Int64; size = 8; return true;
        case 9: t = Dbf::Float; size = 4; return true;
        case 10: t = Dbf::Double; size = 8; return true;
        default: return false;
        }
    }
    void init() override {
        Dbf t;
        uint16_t size;
        if (!elem_type(ftvl, t, size))
            throw Error(SB() << "FTVL " << kMenuFtype.choices[ftvl] << " is not supported for waveform");
        if (nelm == 0) nelm = 1;
        if (nelm > 64u * 1024 * 1024)
            throw Error(SB() << "NELM " << nelm << " is too large (at most 67108864)");
        storage.assign(std::size_t(nelm) * size, 0);
        if (load_constant(inp, *val_fd)) udf = 0;
    }
    Elements elements(const FieldDesc& f) override {
        if (&f != val_fd) return Record::elements(f);
        Dbf t = Dbf::Double;
        uint16_t size = 8;
        elem_type(ftvl, t, size);
        return Elements{t, storage.data(), std::min<uint32_t>(nord, nelm),
                        uint32_t(storage.size() / size), size};
    }
    void set_count(const FieldDesc& f, uint32_t n) override {
        if (&f == val_fd) nord = n;
    }
    int16_t precision(const FieldDesc& f) const override {
        if (&f == val_fd) return prec;
        return Record::precision(f);
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) {
            Dbf t = Dbf::Double;
            uint16_t size;
            elem_type(ftvl, t, size);
            if (t == Dbf::Float || t == Dbf::Double) md.precision = prec;
            else md.precision = 0;
        }
        if (f.flags & kEgu) md.units = egu;
        if (f.flags & kDisplayHopr) fill_limits(md, hopr, lopr, hopr, lopr);
    }
    uint32_t last_nord = 0;
    ProcessResult process() override {
        pact = 1;
        if (soft_read(*this, inp, *val_fd)) udf = 0; // devWfSoft: up to NELM elements, NORD set
        stamp_time();
        if (udf) set_sevr(kStatUdf, udfs);
        unsigned m = reset_alarms();
        if (mpst == 0) m |= kDbeValue;
        if (apst == 0) m |= kDbeLog;
        if (m) post(val_fd, m);
        if (nord != last_nord) {
            post(nord_fd, kDbeValue | kDbeLog);
            last_nord = nord;
        }
        pact = 0;
        return ProcessResult::Done;
    }
};

} // namespace

void register_standard_records(RecordTypes& types) {
    add_type<AiRecord>(types, "ai");
    add_type<AoRecord>(types, "ao");
    add_type<BiRecord>(types, "bi");
    add_type<BoRecord>(types, "bo");
    add_type<BusyRecord>(types, "busy");
    add_type<LonginRecord>(types, "longin");
    add_type<LongoutRecord>(types, "longout");
    add_type<MbbiRecord>(types, "mbbi");
    add_type<MbboRecord>(types, "mbbo");
    add_type<StringinRecord>(types, "stringin");
    add_type<StringoutRecord>(types, "stringout");
    add_type<WaveformRecord>(types, "waveform");
}

} // namespace beamctl::pv
