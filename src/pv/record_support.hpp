// Record support shared by the record types (EPICS recGbl and the common parts of the analog
// records): deadbands, limit and state alarms, metadata helpers, the analog base, registration.
// Internal to src/pv's record implementations. Threading: the database thread, as records.
#pragma once

#include "core/error.hpp"
#include "pv/record.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

namespace beamctl::pv::support {

// A run of consecutive fields in a type's table (A..U, DO0..DOF, B0..B1F): one pointer per record
// instead of a table of pointers per record. bind() takes the first by name and checks that the
// others follow it in order.
struct FieldRun {
    const FieldDesc* first = nullptr;
    const FieldDesc* operator[](int i) const { return first + i; }
    void bind(const RecordType& t, const char* const* names, int n) {
        first = t.find(names[0]);
        for (int i = 0; i < n; ++i)
            if (!first || t.find(names[i]) != first + i)
                throw Error(std::string("internal: fields from ") + names[0] + " of record type " + t.name() +
                            " are not consecutive");
    }
    // The position of f in the run of n, or -1.
    int index_of(const FieldDesc& f, int n) const {
        for (int i = 0; i < n; ++i)
            if (&f == first + i) return i;
        return -1;
    }
};

// recGblCheckDeadband: adds `bit` to mask and updates *last when |new - last| > deadband.
inline void check_deadband(double& last, double v, double deadband, unsigned& mask, unsigned bit) {
    double delta = 0;
    if (std::isfinite(v) && std::isfinite(last)) {
        delta = std::fabs(last - v);
    } else if (std::isnan(v) != std::isnan(last) || std::isinf(v) != std::isinf(last)) {
        delta = INFINITY;
    } else if (std::isinf(v) && v != last) {
        delta = INFINITY;
    }
    if (delta > deadband) {
        mask |= bit;
        last = v;
    }
}

// aiRecord-style limit alarms with hysteresis; T is double or int32.
template <typename T>
void limit_alarms(Record& r, T val, T hihi, T high, T low, T lolo, uint16_t hhsv, uint16_t hsv,
                  uint16_t lsv, uint16_t llsv, T hyst, T& lalm) {
    if (r.udf) {
        r.set_sevr(kStatUdf, r.udfs);
        return;
    }
    T alev;
    uint16_t asev, astat;
    if ((asev = hhsv) && (val >= (alev = hihi) || (lalm == alev && val >= alev - hyst)))
        astat = kStatHihi;
    else if ((asev = llsv) && (val <= (alev = lolo) || (lalm == alev && val <= alev + hyst)))
        astat = kStatLolo;
    else if ((asev = hsv) && (val >= (alev = high) || (lalm == alev && val >= alev - hyst)))
        astat = kStatHigh;
    else if ((asev = lsv) && (val <= (alev = low) || (lalm == alev && val <= alev + hyst)))
        astat = kStatLow;
    else {
        alev = val;
        asev = kNoAlarm;
        astat = kStatNone;
    }
    if (asev) {
        if (r.set_sevr(astat, asev)) lalm = alev;
    } else {
        lalm = val;
    }
}

// Binary/multi-bit state alarms with change-of-state (biRecord/mbbiRecord checkAlarms).
inline void state_alarms(Record& r, uint16_t val, uint16_t nstates, const uint16_t* state_sevr,
                  uint16_t unsv, uint16_t cosv, uint16_t& lalm) {
    if (r.udf) {
        r.set_sevr(kStatUdf, r.udfs);
        return;
    }
    if (val >= nstates)
        r.set_sevr(kStatState, unsv);
    else
        r.set_sevr(kStatState, state_sevr[val]);
    if (val == lalm) return;
    r.set_sevr(kStatCos, cosv);
    lalm = val;
}

inline void fill_limits(Metadata& md, double hopr, double lopr, double chi, double clo) {
    md.disp_hi = hopr;
    md.disp_lo = lopr;
    md.ctrl_hi = chi;
    md.ctrl_lo = clo;
}

inline bool is(const FieldDesc& f, const char* n) { return std::strcmp(f.name, n) == 0; }

constexpr uint16_t kVal = kProcess | kAsl0;
constexpr uint16_t kLim = kProcess | kProp | kEgu | kDisplayHopr; // alarm limits (pp, metadata)
constexpr uint16_t kMeta = kProp;                                  // metadata, no processing

// ---------------------------------------------------------------- analog (ai, ao)
template <typename Self> struct AnalogBase : Record {
    using Record::Record;
    double val = 0;
    int16_t prec = 0;
    char egu[16] = {};
    double hopr = 0, lopr = 0;
    double hihi = 0, high = 0, low = 0, lolo = 0;
    uint16_t hhsv = 0, hsv = 0, lsv = 0, llsv = 0;
    double hyst = 0, mdel = 0, adel = 0;
    double lalm = 0, alst = 0, mlst = 0;

    static std::vector<FieldDesc> analog_fields(std::vector<FieldDesc> v) {
        using R = Self;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Double, kVal | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta | kEgu),
            BEAMCTL_FIELD(R, HIHI, hihi, Double, kLim),
            BEAMCTL_FIELD(R, HIGH, high, Double, kLim),
            BEAMCTL_FIELD(R, LOW, low, Double, kLim),
            BEAMCTL_FIELD(R, LOLO, lolo, Double, kLim),
            BEAMCTL_MENU(R, HHSV, hhsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, HSV, hsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, LSV, lsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, LLSV, llsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_FIELD(R, HYST, hyst, Double, kEgu),
            BEAMCTL_FIELD(R, MDEL, mdel, Double, kEgu),
            BEAMCTL_FIELD(R, ADEL, adel, Double, kEgu),
            BEAMCTL_FIELD(R, LALM, lalm, Double, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, ALST, alst, Double, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, MLST, mlst, Double, kReadOnly | kEgu | kDisplayHopr),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }

    void analog_alarms() {
        limit_alarms<double>(*this, val, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm);
    }
    unsigned analog_monitor_mask() {
        unsigned mask = reset_alarms();
        check_deadband(mlst, val, mdel, mask, kDbeValue);
        check_deadband(alst, val, adel, mask, kDbeLog);
        return mask;
    }
    int16_t precision(const FieldDesc& f) const override {
        if (is(f, "VAL")) return prec;
        if (f.dbf == Dbf::Float || f.dbf == Dbf::Double) return (prec < 0 || prec > 15) ? 15 : prec;
        return 0;
    }
    void analog_metadata(const FieldDesc& f, Metadata& md, double chi, double clo) const {
        Record::metadata(f, md);
        if (f.flags & kEgu) md.units = egu;
        if (f.flags & kDisplayHopr) fill_limits(md, hopr, lopr, chi, clo);
        if (is(f, "VAL")) {
            md.alarm_hihi = hhsv ? hihi : NAN;
            md.alarm_high = hsv ? high : NAN;
            md.alarm_low = lsv ? low : NAN;
            md.alarm_lolo = llsv ? lolo : NAN;
        }
    }
};


// FTVL/FTA (menuFtype) to the element type and size beamctl stores; false for UINT64 and ENUM.
inline bool ftvl_type(uint16_t ftvl, Dbf& t, uint16_t& size) {
    switch (ftvl) {
    case 0: t = Dbf::String; size = kStringSize; return true;
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

template <typename R> void add_type(RecordTypes& types, const char* name) {
    types.add(std::make_unique<RecordType>(name, R::fields(), [](const RecordType& t) {
        return std::unique_ptr<Record>(new R(t));
    }));
}


} // namespace beamctl::pv::support

namespace beamctl::pv::support {

// Soft Channel device support (devAiSoft, devBoSoft, ...). An input's INP, an output's DOL: read
// into field f when the link reaches something (a constant was loaded at init instead). Returns
// true when a value was read.
inline bool soft_read(Record& r, Link& l, const FieldDesc& f) {
    if (l.kind != Link::Kind::Db && l.kind != Link::Kind::Hw) return false;
    return r.read_link(l, f);
}

// An output record's write after its alarms were checked (the pending ones): IVOA decides what an
// INVALID record does. `set_ivov` puts IVOV into the output value for "Set output to IVOV".
template <typename F> inline void soft_write(Record& r, Link& out, const FieldDesc& f, uint16_t ivoa, F&& set_ivov) {
    if (r.nsev >= kInvalid) {
        if (ivoa == 1) return; // Don't drive outputs
        if (ivoa == 2) set_ivov();
    }
    r.write_link(out, f);
}

// The Soft Channel output fields of output record R, in base's order: DOL, OMSL, OUT, IVOA and
// IVOV (of type `ivov`, the record's value type).
template <typename R> void add_output_fields(std::vector<FieldDesc>& v, Dbf ivov) {
    v.push_back(BEAMCTL_FIELD(R, DOL, dol, InLink, 0));
    v.push_back(BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, 0));
    v.push_back(BEAMCTL_FIELD(R, OUT, out, OutLink, 0));
    v.push_back(BEAMCTL_MENU(R, IVOA, ivoa, kMenuIvoa, 0));
    v.push_back(FieldDesc{"IVOV", ivov, 0, uint16_t(sizeof(R::ivov)), nullptr,
                          [](Record& r) -> void* { return &static_cast<R&>(r).ivov; }});
}

// ---------------------------------------------------------------- integers (longin/longout: T =
// int32_t, DBF_LONG; int64in/int64out: T = int64_t, DBF_INT64), as base's four record supports:
// limit alarms with hysteresis, MDEL/ADEL deadbands (negative: every processing posts), the
// output's DRVH/DRVL clamp, OMSL closed_loop DOL and IVOA. MLST/ALST/LALM start at VAL (init_record).
template <typename T> constexpr Dbf kIntegerDbf = sizeof(T) == 8 ? Dbf::Int64 : Dbf::Long;
#define BEAMCTL_INT_FIELD(R, NAME, m, flags)                                                       \
    ::beamctl::pv::FieldDesc {                                                                     \
        #NAME, kIntegerDbf<T>, uint16_t(flags), uint16_t(sizeof(R::m)), nullptr,                   \
            [](::beamctl::pv::Record& r) -> void* { return &static_cast<R&>(r).m; }                \
    }

template <typename Self, typename T> struct IntegerBase : Record {
    using Record::Record;
    T val = 0;
    char egu[16] = {};
    T hopr = 0, lopr = 0;
    T hihi = 0, high = 0, low = 0, lolo = 0;
    uint16_t hhsv = 0, hsv = 0, lsv = 0, llsv = 0;
    T hyst = 0, mdel = 0, adel = 0;
    T lalm = 0, alst = 0, mlst = 0;
    Link inp, dol, out; // Soft Channel: an input's INP; an output's DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0;
    T ivov = 0;
    const FieldDesc* val_fd = type().find("VAL");

    static std::vector<FieldDesc> integer_fields() {
        using R = Self;
        auto v = common_fields();
        auto add = {
            BEAMCTL_INT_FIELD(R, VAL, val, kVal | kEgu | kDisplayHopr),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_INT_FIELD(R, HOPR, hopr, kMeta | kEgu),
            BEAMCTL_INT_FIELD(R, LOPR, lopr, kMeta | kEgu),
            BEAMCTL_INT_FIELD(R, HIHI, hihi, kLim),
            BEAMCTL_INT_FIELD(R, HIGH, high, kLim),
            BEAMCTL_INT_FIELD(R, LOW, low, kLim),
            BEAMCTL_INT_FIELD(R, LOLO, lolo, kLim),
            BEAMCTL_MENU(R, HHSV, hhsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, HSV, hsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, LSV, lsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_MENU(R, LLSV, llsv, kMenuAlarmSevr, kProcess | kProp),
            BEAMCTL_INT_FIELD(R, HYST, hyst, kEgu),
            BEAMCTL_INT_FIELD(R, MDEL, mdel, kEgu),
            BEAMCTL_INT_FIELD(R, ADEL, adel, kEgu),
            BEAMCTL_INT_FIELD(R, LALM, lalm, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_INT_FIELD(R, ALST, alst, kReadOnly | kEgu | kDisplayHopr),
            BEAMCTL_INT_FIELD(R, MLST, mlst, kReadOnly | kEgu | kDisplayHopr),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
        mlst = alst = lalm = val;
    }
    // |a - b| without overflow, as base's DELTA; a negative deadband posts every time.
    static bool beyond(T last, T v, T deadband) {
        uint64_t d = last > v ? uint64_t(last) - uint64_t(v) : uint64_t(v) - uint64_t(last);
        return deadband < 0 || d > uint64_t(deadband);
    }
    void integer_process(bool output) {
        if (!output && soft_read(*this, inp, *val_fd)) udf = 0;
        limit_alarms<T>(*this, val, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm);
        if (output) soft_write(*this, out, *val_fd, ivoa, [this] { val = ivov; });
        stamp_time();
        unsigned mask = reset_alarms();
        if (beyond(mlst, val, mdel)) {
            mask |= kDbeValue;
            mlst = val;
        }
        if (beyond(alst, val, adel)) {
            mask |= kDbeLog;
            alst = val;
        }
        if (mask) post(val_fd, mask);
    }
    void integer_metadata(const FieldDesc& f, Metadata& md, double chi, double clo) const {
        Record::metadata(f, md);
        if (f.flags & kEgu) md.units = egu;
        if (f.flags & kDisplayHopr) fill_limits(md, double(hopr), double(lopr), chi, clo);
        if (is(f, "VAL")) {
            md.alarm_hihi = hhsv ? double(hihi) : NAN;
            md.alarm_high = hsv ? double(high) : NAN;
            md.alarm_low = lsv ? double(low) : NAN;
            md.alarm_lolo = llsv ? double(lolo) : NAN;
        }
    }
};

template <typename T> struct IntegerInRecord : IntegerBase<IntegerInRecord<T>, T> {
    using IntegerBase<IntegerInRecord<T>, T>::IntegerBase;
    static std::vector<FieldDesc> fields() {
        using R = IntegerInRecord;
        auto v = R::integer_fields();
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        return v;
    }
    ProcessResult process() override {
        this->pact = 1;
        this->integer_process(false);
        this->pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        this->integer_metadata(f, md, double(this->hopr), double(this->lopr));
    }
};

template <typename T> struct IntegerOutRecord : IntegerBase<IntegerOutRecord<T>, T> {
    using IntegerBase<IntegerOutRecord<T>, T>::IntegerBase;
    T drvh = 0, drvl = 0;
    static std::vector<FieldDesc> fields() {
        using R = IntegerOutRecord;
        auto v = R::integer_fields();
        v.push_back(BEAMCTL_INT_FIELD(R, DRVH, drvh, kProcess | kProp | kEgu));
        v.push_back(BEAMCTL_INT_FIELD(R, DRVL, drvl, kProcess | kProp | kEgu));
        add_output_fields<R>(v, kIntegerDbf<T>);
        return v;
    }
    ProcessResult process() override {
        this->pact = 1;
        if (this->omsl == 1 && soft_read(*this, this->dol, *this->val_fd)) this->udf = 0;
        if (drvh > drvl) this->val = std::clamp(this->val, drvl, drvh); // convert(): the drive limits
        this->integer_process(true);
        this->pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        this->integer_metadata(f, md, double(drvh), double(drvl));
    }
};
#undef BEAMCTL_INT_FIELD

} // namespace beamctl::pv::support
