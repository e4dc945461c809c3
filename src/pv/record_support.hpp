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

inline double seconds_between(const EpicsTime& a, const EpicsTime& b);
inline int alarm_filter(double aftc, double& afvl, int range, double dt_s);

// aiRecord-style limit alarms with hysteresis; T is double or an integer. With `afvl`, AFTC > 0
// filters the alarm range over time (dt_s: seconds since the previous processing), as base's
// ai/longin/int64in/calc checkAlarms.
template <typename T>
void limit_alarms(Record& r, T val, T hihi, T high, T low, T lolo, uint16_t hhsv, uint16_t hsv,
                  uint16_t lsv, uint16_t llsv, T hyst, T& lalm, double aftc = 0, double* afvl = nullptr,
                  double dt_s = 0) {
    if (r.udf) {
        r.set_sevr(kStatUdf, r.udfs);
        if (afvl) *afvl = 0;
        return;
    }
    T alev;
    uint16_t asev;
    int range; // 1 LOLO, 2 LOW, 3 normal, 4 HIGH, 5 HIHI
    if ((asev = hhsv) && (val >= (alev = hihi) || (lalm == alev && val >= alev - hyst)))
        range = 5;
    else if ((asev = llsv) && (val <= (alev = lolo) || (lalm == alev && val <= alev + hyst)))
        range = 1;
    else if ((asev = hsv) && (val >= (alev = high) || (lalm == alev && val >= alev - hyst)))
        range = 4;
    else if ((asev = lsv) && (val <= (alev = low) || (lalm == alev && val <= alev + hyst)))
        range = 2;
    else {
        alev = val;
        asev = kNoAlarm;
        range = 3;
    }
    if (afvl) {
        if (aftc > 0) {
            bool first = *afvl == 0;
            range = alarm_filter(aftc, *afvl, range, dt_s);
            if (!first) switch (range) {
                case 5: asev = hhsv, alev = hihi; break;
                case 4: asev = hsv, alev = high; break;
                case 2: asev = lsv, alev = low; break;
                case 1: asev = llsv, alev = lolo; break;
                default: asev = kNoAlarm; break;
                }
        } else {
            *afvl = 0;
        }
    }
    static const uint16_t stat_of[6] = {kStatSoft, kStatLolo, kStatLow, kStatNone, kStatHigh, kStatHihi};
    if (asev) {
        if (r.set_sevr(stat_of[range], asev)) lalm = alev;
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


// FTVL/FTA (menuFtype) to the element type and size beamctl stores; false for ENUM.
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
    case 8: t = Dbf::UInt64; size = 8; return true;
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

// ---------------------------------------------------------------- simulation mode (recGbl*Simm)
// The input/output simulation fields of base's I/O records (dbCommonInput/dbCommonOutput): SIML
// reads SIMM before each processing; in simulation (SIMM YES, or RAW where the record has a raw
// value) the record raises SIMM_ALARM at SIMS, reads/writes its value through SIOL instead of its
// device, after SDLY seconds when SDLY >= 0 (asynchronous processing), and swaps SCAN with SSCN
// while SIMM changes (SSCN 65535: SCAN stays).
extern const Menu kMenuSimm; // NO YES RAW
constexpr uint16_t kSscnUnchanged = 65535;
constexpr int kSimDelayTag = 0x51d; // Record::on_delay tag of the SDLY delay

struct Simulation {
    uint16_t simm = 0, oldsimm = 0, sims = 0, sscn = kSscnUnchanged;
    double sdly = -1; // [s]; < 0: simulate synchronously
    Link siml, siol;
    bool resuming = false; // the delayed half of an SDLY processing
    bool waiting = false;  // an SDLY delay is pending (the record is busy)
    uint16_t seen = 0;     // SIMM as the last check saw it (a client's put is compared with it)
};

// SIML SIMM SIOL SIMS SDLY SSCN OLDSIMM in base's order; `raw` selects menuSimm (NO YES RAW) for
// SIMM, else menuYesNo; `siol_out` makes SIOL an output link.
#define BEAMCTL_SIM_FIELD(R, NAME, m, dbf, flags)                                                  \
    ::beamctl::pv::FieldDesc {                                                                     \
        #NAME, ::beamctl::pv::Dbf::dbf, uint16_t(flags), uint16_t(sizeof(R::sim.m)), nullptr,      \
            [](::beamctl::pv::Record& r) -> void* { return &static_cast<R&>(r).sim.m; }            \
    }
#define BEAMCTL_SIM_MENU(R, NAME, m, menu, flags)                                                  \
    ::beamctl::pv::FieldDesc {                                                                     \
        #NAME, ::beamctl::pv::Dbf::Menu, uint16_t(flags), uint16_t(sizeof(R::sim.m)), &menu,       \
            [](::beamctl::pv::Record& r) -> void* { return &static_cast<R&>(r).sim.m; }            \
    }
template <typename R> void add_simulation_fields(std::vector<FieldDesc>& v, bool raw, bool siol_out) {
    v.push_back(BEAMCTL_SIM_FIELD(R, SIML, siml, InLink, 0));
    v.push_back(raw ? BEAMCTL_SIM_MENU(R, SIMM, simm, kMenuSimm, 0) : BEAMCTL_SIM_MENU(R, SIMM, simm, kMenuYesNo, 0));
    v.push_back(siol_out ? BEAMCTL_SIM_FIELD(R, SIOL, siol, OutLink, 0) : BEAMCTL_SIM_FIELD(R, SIOL, siol, InLink, 0));
    v.push_back(BEAMCTL_SIM_MENU(R, SIMS, sims, kMenuAlarmSevr, 0));
    v.push_back(BEAMCTL_SIM_FIELD(R, SDLY, sdly, Double, 0));
    v.push_back(BEAMCTL_SIM_MENU(R, SSCN, sscn, kMenuScan, 0));
    v.push_back(BEAMCTL_SIM_MENU(R, OLDSIMM, oldsimm, kMenuSimm, kReadOnly));
}
#undef BEAMCTL_SIM_FIELD
#undef BEAMCTL_SIM_MENU

// recGblCheckSimm: SIMM changed from `before`: swap SCAN and SSCN (unless SSCN is 65535).
inline void sim_check_scan(Record& r, Simulation& s, uint16_t before) {
    s.seen = s.simm;
    if (s.sscn == kSscnUnchanged) return;
    s.oldsimm = before;
    if (s.simm == before) return;
    std::swap(r.scan, s.sscn);
    r.rescan();
    r.post("SCAN", kDbeValue | kDbeLog);
    r.post("SSCN", kDbeValue | kDbeLog);
}
// init_record (recGblInitSimm): a constant SIML gives SIMM.
inline void sim_init(Record& r, Simulation& s, const FieldDesc& simm_fd) {
    s.seen = s.simm;
    uint16_t before = s.simm;
    if (r.load_constant(s.siml, simm_fd)) sim_check_scan(r, s, before);
}
// special(): SIMM was written by a client: the scan swap. Records call it for every field.
inline void sim_special(Record& r, Simulation& s, const FieldDesc& f, const FieldDesc* simm_fd) {
    if (&f == simm_fd) sim_check_scan(r, s, s.seen);
}

enum class SimStep { Off, Now, Wait };
// Start of processing (readValue/writeValue): SIML read into SIMM (a failed read raises LINK on
// no pending alarm, as recGblGetSimm), then Off (the device as usual), Now (simulate: SIOL now) or
// Wait (SDLY >= 0: the delay started, process() returns Async; on_delay(kSimDelayTag) resumes).
inline SimStep sim_begin(Record& r, Simulation& s, const FieldDesc& simm_fd) {
    if (s.resuming) return SimStep::Now;
    if (s.siml.kind == Link::Kind::Db || s.siml.kind == Link::Kind::Hw) {
        uint16_t before = s.simm;
        if (!r.read_link(s.siml, simm_fd)) {
            // read_link raised LINK/INVALID; base only notes LINK when nothing is pending
        }
        if (s.simm > 2) s.simm = 1;
        sim_check_scan(r, s, before);
    }
    if (s.simm == 0) return SimStep::Off;
    r.set_sevr(kStatSimm, s.sims);
    if (s.sdly < 0) return SimStep::Now;
    s.waiting = true;
    r.pact = 1;
    r.call_after(s.sdly, kSimDelayTag);
    return SimStep::Wait;
}
// on_delay(kSimDelayTag): the delayed half. Processes the record again (simulated I/O now), then
// its forward link and the completion of a put-callback waiting on it.
inline void sim_resume(Record& r, Simulation& s) {
    if (!s.waiting) return;
    s.waiting = false;
    s.resuming = true;
    r.process();
    s.resuming = false;
    r.fwd_link(r.flnk);
    r.async_done();
}

// ---------------------------------------------------------------- conversion (ai, ao: menuConvert)
extern const Menu kMenuConvert; // NO CONVERSION, SLOPE, LINEAR, typeKdegF ... (breakpoint tables)
constexpr uint16_t kLinrNone = 0, kLinrSlope = 1, kLinrLinear = 2;

// ---------------------------------------------------------------- alarm filter (AFTC, AFVL)
// The level filter of ai/longin/int64in/mbbi/calc checkAlarms: `range` is the alarm range of this
// processing (1 LOLO .. 5 HIHI, 3 normal; mbbi: its own); returns the filtered range and keeps AFVL.
inline int alarm_filter(double aftc, double& afvl, int range, double dt_s) {
    if (aftc <= 0) {
        afvl = 0;
        return range;
    }
    if (afvl == 0) {
        afvl = range;
        return range;
    }
    double alpha = aftc / (dt_s + aftc);
    afvl = alpha * afvl + ((afvl > 0) ? (1 - alpha) : (alpha - 1)) * range;
    if (afvl - std::floor(afvl) > 0.6321) afvl = -afvl; // THRESHOLD: reverse the rounding
    return std::abs(int(std::floor(afvl)));
}
inline double seconds_between(const EpicsTime& a, const EpicsTime& b) {
    return (double(a.sec) - double(b.sec)) + (double(a.nsec) - double(b.nsec)) * 1e-9;
}


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

extern const Menu kMenuLongoutOopt; // longoutOOPT: Every Time, On Change, When Zero, ...

template <typename Self, typename T> struct IntegerBase : Record {
    using Record::Record;
    T val = 0;
    char egu[16] = {};
    T hopr = 0, lopr = 0;
    T hihi = 0, high = 0, low = 0, lolo = 0;
    uint16_t hhsv = 0, hsv = 0, lsv = 0, llsv = 0;
    T hyst = 0, mdel = 0, adel = 0;
    T lalm = 0, alst = 0, mlst = 0;
    T sval = 0;
    double aftc = 0, afvl = 0; // inputs: the alarm filter
    Link inp, dol, out; // Soft Channel: an input's INP; an output's DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0;
    T ivov = 0;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");

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
        sim_init(*this, sim, *simm_fd);
        if (sval_fd) load_constant(sim.siol, *sval_fd);
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
        mlst = alst = lalm = val;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    // |a - b| without overflow, as base's DELTA; a negative deadband posts every time.
    static bool beyond(T last, T v, T deadband) {
        uint64_t d = last > v ? uint64_t(last) - uint64_t(v) : uint64_t(v) - uint64_t(last);
        return deadband < 0 || d > uint64_t(deadband);
    }
    // The input's value: SIOL when simulated (SVAL), else INP.
    void integer_read(SimStep step) {
        if (step == SimStep::Now) {
            if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                val = sval;
                udf = 0;
            }
        } else if (soft_read(*this, inp, *val_fd)) {
            udf = 0;
        }
    }
    // IVOA of an INVALID output: false for "Don't drive outputs"; "Set output to IVOV" sets VAL.
    bool integer_drive() {
        if (nsev < kInvalid) return true;
        if (ivoa == 1) return false;
        if (ivoa == 2 && !sim.resuming) val = ivov;
        return true;
    }
    void integer_write(SimStep step) { write_link(step == SimStep::Now ? sim.siol : out, *val_fd); }
    void integer_finish() {
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
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};

template <typename T> struct IntegerInRecord : IntegerBase<IntegerInRecord<T>, T> {
    using IntegerBase<IntegerInRecord<T>, T>::IntegerBase;
    static std::vector<FieldDesc> fields() {
        using R = IntegerInRecord;
        auto v = R::integer_fields();
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        v.push_back(BEAMCTL_FIELD(R, AFTC, aftc, Double, 0));
        v.push_back(BEAMCTL_FIELD(R, AFVL, afvl, Double, kReadOnly));
        v.push_back(BEAMCTL_INT_FIELD(R, SVAL, sval, 0));
        add_simulation_fields<R>(v, false, false);
        return v;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, this->sim, *this->simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        this->pact = 1;
        EpicsTime last = this->time;
        this->integer_read(step);
        this->stamp_time();
        limit_alarms<T>(*this, this->val, this->hihi, this->high, this->low, this->lolo, this->hhsv, this->hsv,
                        this->lsv, this->llsv, this->hyst, this->lalm, this->aftc, &this->afvl,
                        seconds_between(this->time, last));
        this->integer_finish();
        this->pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        this->integer_metadata(f, md, double(this->hopr), double(this->lopr));
    }
};

// longout (and int64out without OOPT): OOPT decides when OUT is written (longoutRecord's
// conditional_write); OOCH YES writes at the next processing after OUT was changed.
template <typename T> struct IntegerOutRecord : IntegerBase<IntegerOutRecord<T>, T> {
    using IntegerBase<IntegerOutRecord<T>, T>::IntegerBase;
    T drvh = 0, drvl = 0;
    T pval = 0;         // longout: the value of the previous write decision
    uint16_t oopt = 0;  // Every Time
    uint16_t ooch = 1;  // YES
    bool out_changed = true; // first processing, or OUT changed with OOCH YES: write On Change
    static constexpr bool kHasOopt = sizeof(T) == 4; // base 7.0.8: longout only
    static std::vector<FieldDesc> fields() {
        using R = IntegerOutRecord;
        auto v = R::integer_fields();
        v.push_back(BEAMCTL_INT_FIELD(R, DRVH, drvh, kProcess | kProp | kEgu));
        v.push_back(BEAMCTL_INT_FIELD(R, DRVL, drvl, kProcess | kProp | kEgu));
        add_output_fields<R>(v, kIntegerDbf<T>);
        if (kHasOopt) {
            v.push_back(BEAMCTL_INT_FIELD(R, PVAL, pval, 0));
            v.push_back(BEAMCTL_MENU(R, OOCH, ooch, kMenuYesNo, 0));
            v.push_back(BEAMCTL_MENU(R, OOPT, oopt, kMenuLongoutOopt, 0));
        }
        add_simulation_fields<R>(v, false, true);
        return v;
    }
    void init() override {
        IntegerBase<IntegerOutRecord<T>, T>::init();
        pval = this->val;
    }
    PutStatus special(const FieldDesc& f) override {
        if (kHasOopt && is(f, "OUT") && ooch == 1) out_changed = true;
        return IntegerBase<IntegerOutRecord<T>, T>::special(f);
    }
    bool oopt_write() {
        T v = this->val;
        bool w = true;
        switch (oopt) {
        case 1: w = out_changed || v != pval; break; // On Change
        case 2: w = v == 0; break;                   // When Zero
        case 3: w = v != 0; break;                   // When Non-zero
        case 4: w = v == 0 && pval != 0; break;      // Transition To Zero
        case 5: w = v != 0 && pval == 0; break;      // Transition To Non-zero
        default: break;                              // Every Time
        }
        pval = v;
        out_changed = false;
        return w;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, this->sim, *this->simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        this->pact = 1;
        if (!this->sim.resuming) {
            if (this->omsl == 1 && soft_read(*this, this->dol, *this->val_fd)) this->udf = 0;
            if (drvh > drvl) this->val = std::clamp(this->val, drvl, drvh); // convert(): the drive limits
            this->stamp_time();
        }
        limit_alarms<T>(*this, this->val, this->hihi, this->high, this->low, this->lolo, this->hhsv, this->hsv,
                        this->lsv, this->llsv, this->hyst, this->lalm);
        if (this->integer_drive() && (!kHasOopt || oopt_write())) this->integer_write(step);
        this->integer_finish();
        this->pact = 0;
        return ProcessResult::Done;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        this->integer_metadata(f, md, double(drvh), double(drvl));
    }
};
#undef BEAMCTL_INT_FIELD

} // namespace beamctl::pv::support
