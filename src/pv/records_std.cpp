// The standard soft record types of EPICS base: ai ao bi bo longin longout mbbi mbbo stringin
// stringout waveform, with "Soft Channel" device support (no links). Semantics follow base's
// record support (checkAlarms, monitor, convert) so clients see what a softIoc would show.
#include "core/error.hpp"
#include "pv/record.hpp"
#include "pv/database.hpp"
#include "pv/record_support.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>

namespace beamctl::pv {
namespace {
using namespace support;

// The conversion fields of ai and ao (base's order of use: ROFF, ASLO/AOFF, LINR with
// ESLO/EOFF, breakpoint tables refused at init).
template <typename R> void add_conversion_fields(std::vector<FieldDesc>& v) {
    auto add = {
        BEAMCTL_MENU(R, LINR, linr, kMenuConvert, kProcess),
        BEAMCTL_FIELD(R, EGUF, eguf, Double, kProcess | kEgu),
        BEAMCTL_FIELD(R, EGUL, egul, Double, kProcess | kEgu),
        BEAMCTL_FIELD(R, AOFF, aoff, Double, kProcess),
        BEAMCTL_FIELD(R, ASLO, aslo, Double, kProcess),
        BEAMCTL_FIELD(R, ESLO, eslo, Double, kProcess),
        BEAMCTL_FIELD(R, EOFF, eoff, Double, kProcess),
        BEAMCTL_FIELD(R, ROFF, roff, ULong, kProcess),
        BEAMCTL_FIELD(R, RVAL, rval, Long, kProcess),
        BEAMCTL_FIELD(R, ORAW, oraw, Long, kReadOnly),
        BEAMCTL_FIELD(R, INIT, init_flag, Short, kReadOnly),
        BEAMCTL_FIELD(R, LBRK, lbrk, Short, kReadOnly),
    };
    v.insert(v.end(), add.begin(), add.end());
}
// aiRecord/aoRecord init_record: a breakpoint table is refused by name (beamctl ships none);
// "old device support" without EOFF: EOFF = EGUL when ESLO is 1 and EOFF 0, kept for SLOPE.
template <typename R> void init_conversion(R& r) {
    if (r.linr > kLinrLinear)
        throw Error(SB() << "LINR \"" << kMenuConvert.choices[r.linr] << "\" names breakpoint table "
                         << kMenuConvert.choices[r.linr]
                         << ", which beamctl does not provide (it ships no breakpoint tables); use SLOPE or "
                            "LINEAR with ESLO/EOFF, or a calc record");
    r.init_flag = 1;
    double eoff = r.eoff, eslo = r.eslo;
    if (r.eslo == 1.0 && r.eoff == 0.0) r.eoff = r.egul;
    if (r.linr == kLinrSlope) {
        r.eoff = eoff;
        r.eslo = eslo;
    }
}

struct AiRecord : AnalogBase<AiRecord> {
    using AnalogBase::AnalogBase;
    Link inp;
    double smoo = 0;
    uint16_t linr = 0;
    double eguf = 0, egul = 0, aoff = 0, aslo = 1, eslo = 1, eoff = 0;
    uint32_t roff = 0;
    int32_t rval = 0, oraw = 0;
    int16_t init_flag = 0, lbrk = 0;
    double aftc = 0, afvl = 0;
    double sval = 0;
    Simulation sim;
    bool smoothed = false; // a value was read before (smoothing starts from the second)
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");
    static std::vector<FieldDesc> fields() {
        using R = AiRecord;
        auto v = analog_fields(common_fields());
        auto add = {BEAMCTL_FIELD(R, INP, inp, InLink, 0), BEAMCTL_FIELD(R, SMOO, smoo, Double, 0),
                    BEAMCTL_FIELD(R, AFTC, aftc, Double, 0), BEAMCTL_FIELD(R, AFVL, afvl, Double, kReadOnly),
                    BEAMCTL_FIELD(R, SVAL, sval, Double, 0)};
        v.insert(v.end(), add.begin(), add.end());
        add_conversion_fields<R>(v);
        add_simulation_fields<R>(v, true, false);
        return v;
    }
    void init() override {
        sim_init(*this, sim, *simm_fd);
        load_constant(sim.siol, *sval_fd);
        init_conversion(*this);
        if (dtyp == kDtypRawSoft) {
            load_constant(inp, *rval_fd); // devAiSoftRaw: a constant INP is RVAL
        } else if (load_constant(inp, *val_fd)) {
            udf = std::isnan(val);
        }
        oraw = rval;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        if (is(f, "LINR") || is(f, "EGUF") || is(f, "EGUL")) {
            if (linr > kLinrLinear) return PutStatus::BadValue; // no breakpoint tables
            init_flag = 1;
        }
        return PutStatus::Ok;
    }
    // aiRecord's convert(): RVAL to VAL through ROFF, ASLO/AOFF and LINR; then smoothing.
    void convert() {
        double v = double(rval) + double(roff);
        if (aslo != 0.0) v *= aslo;
        v += aoff;
        if (linr == kLinrSlope || linr == kLinrLinear) v = v * eslo + eoff;
        if (smoo != 0.0 && std::isfinite(val)) {
            if (init_flag) val = v; // initial condition
            val = v * (1.0 - smoo) + val * smoo;
        } else {
            val = v;
        }
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        EpicsTime last = time;
        bool convert_raw = false;
        if (step == SimStep::Now) {
            if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                if (sim.simm == 1) {
                    val = sval;
                    udf = std::isnan(val);
                } else {
                    rval = int32_t(std::floor(sval));
                    convert_raw = true;
                }
            }
        } else if (dtyp == kDtypRawSoft) { // devAiSoftRaw: INP into RVAL, then converted
            if (inp.kind != Link::Kind::Db && inp.kind != Link::Kind::Hw) convert_raw = true;
            else convert_raw = read_link(inp, *rval_fd);
        } else if (dtyp == kDtypTimestamp) { // devTimestampAI: the time now, in EPICS seconds
            time = EpicsTime::now();
            val = time.sec + time.nsec * 1e-9;
            udf = 0;
        } else {
            double before = val;
            if (soft_read(*this, inp, *val_fd)) { // devAiSoft: the value, smoothed by SMOO
                if (smoo != 0 && smoothed && std::isfinite(before)) val = val * (1 - smoo) + before * smoo;
                smoothed = true;
                if (inp.kind == Link::Kind::Hw) udf = std::isnan(val); // a device's read defines VAL
            }
        }
        if (convert_raw) {
            convert();
            udf = std::isnan(val);
        }
        if (dtyp != kDtypTimestamp) stamp_time();
        if (dtyp == kDtypSoft && step == SimStep::Off) udf = std::isnan(val); // soft: VAL defines it
        limit_alarms<double>(*this, val, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm, aftc, &afvl,
                             seconds_between(time, last));
        if (unsigned m = analog_monitor_mask()) {
            post(val_fd, m);
            if (oraw != rval) {
                post(rval_fd, m);
                oraw = rval;
            }
        }
        init_flag = 0;
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
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
    uint16_t linr = 0;
    double eguf = 0, egul = 0, aoff = 0, aslo = 0, eslo = 1, eoff = 0;
    uint32_t roff = 0;
    int32_t rval = 0, oraw = 0, rbv = 0, orbv = 0;
    int16_t init_flag = 0, lbrk = 0;
    uint8_t omod = 0;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* oval_fd = type().find("OVAL");
    const FieldDesc* rval_fd = type().find("RVAL");
    const FieldDesc* rbv_fd = type().find("RBV");
    const FieldDesc* simm_fd = type().find("SIMM");
    static std::vector<FieldDesc> fields() {
        using R = AoRecord;
        auto v = analog_fields(common_fields());
        auto add = {
            BEAMCTL_FIELD(R, OVAL, oval, Double, kEgu | kDisplayHopr),
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
            BEAMCTL_FIELD(R, RBV, rbv, Long, kReadOnly),
            BEAMCTL_FIELD(R, ORBV, orbv, Long, kReadOnly),
            BEAMCTL_FIELD(R, OMOD, omod, UChar, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_conversion_fields<R>(v);
        add_simulation_fields<R>(v, true, true);
        return v;
    }
    void init() override {
        sim_init(*this, sim, *simm_fd);
        if (load_constant(dol, *val_fd)) udf = std::isnan(val);
        init_conversion(*this);
        oval = pval = val;
        mlst = alst = lalm = val;
        oraw = rval;
        orbv = rbv;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        if (is(f, "LINR") || is(f, "EGUF") || is(f, "EGUL")) {
            if (linr > kLinrLinear) return PutStatus::BadValue; // no breakpoint tables
            init_flag = 1;
        }
        return PutStatus::Ok;
    }
    // aoRecord's convert(): drive limits, OROC, then OVAL to RVAL (LINR, AOFF/ASLO, ROFF, rounded).
    void convert(double value) {
        if (drvh > drvl) value = std::clamp(value, drvl, drvh);
        val = value;
        pval = value;
        if (oroc != 0) {
            double diff = value - oval;
            if (diff < 0) {
                if (oroc < -diff) value = oval - oroc;
            } else if (oroc < diff) {
                value = oval + oroc;
            }
        }
        omod = oval != value;
        oval = value;
        if (linr == kLinrSlope || linr == kLinrLinear) value = eslo == 0.0 ? 0 : (value - eoff) / eslo;
        value -= aoff;
        if (aslo != 0) value /= aslo;
        value -= double(roff);
        if (value >= 0.0)
            rval = value >= 0x7fffffff - 0.5 ? 0x7fffffff : int32_t(value + 0.5);
        else
            rval = value > 0.5 - 2147483648.0 ? int32_t(value - 0.5) : int32_t(0x80000000u);
    }
    // writeValue: the device (Soft Channel: OVAL; Raw: RVAL) or, simulated, SIOL.
    void write_value(bool simulated) {
        if (simulated) write_link(sim.siol, sim.simm == 1 ? *oval_fd : *rval_fd);
        else write_link(out, dtyp == kDtypRawSoft ? *rval_fd : *oval_fd);
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (!sim.resuming) {
            double value = val;
            bool ok = true;
            if (omsl == 1 && (dol.is_db() || dol.kind == Link::Kind::Hw)) { // closed_loop: VAL from DOL
                double v = 0;
                ok = read_link(dol, v);
                if (ok) value = oif == 1 ? val + v : v; // Incremental adds to VAL
            }
            if (ok) convert(value);
            udf = std::isnan(val);
            stamp_time();
        }
        analog_alarms();
        if (nsev < kInvalid || ivoa == 0) {
            write_value(step == SimStep::Now);
        } else if (ivoa == 2) { // Set output to IVOV
            if (!sim.resuming) {
                val = ivov;
                convert(ivov);
            }
            write_value(step == SimStep::Now);
        }
        unsigned m = analog_monitor_mask();
        if (m) post(val_fd, m);
        if (omod) m |= kDbeValue | kDbeLog;
        if (m) {
            omod = 0;
            post(oval_fd, m);
            if (oraw != rval) {
                post(rval_fd, m | kDbeValue | kDbeLog);
                oraw = rval;
            }
            if (orbv != rbv) {
                post(rbv_fd, m | kDbeValue | kDbeLog);
                orbv = rbv;
            }
        }
        init_flag = 0;
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        analog_metadata(f, md, drvh, drvl);
    }
};

// ---------------------------------------------------------------- long (longin, longout)
using LonginRecord = IntegerInRecord<int32_t>;  // record_support.hpp, shared with int64in
using LongoutRecord = IntegerOutRecord<int32_t>;

// ---------------------------------------------------------------- binary (bi, bo)
constexpr int kHighDelayTag = 0x4819; // bo HIGH: the pulse's end (Record::on_delay)

template <typename Self> struct BinaryBase : Record {
    using Record::Record;
    uint16_t val = 0;
    char znam[26] = {}, onam[26] = {};
    uint16_t zsv = 0, osv = 0, cosv = 0;
    uint32_t rval = 0, mask = 0, oraw = 0, sval = 0;
    int32_t rbv = 0, orbv = 0;
    uint16_t lalm = 0, mlst = 0;
    Link inp, dol, out; // Soft Channel: bi INP; bo DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0, ivov = 0;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");

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
            BEAMCTL_FIELD(R, ORAW, oraw, ULong, kReadOnly),
            BEAMCTL_FIELD(R, MASK, mask, ULong, 0),
            BEAMCTL_FIELD(R, LALM, lalm, UShort, kReadOnly),
            BEAMCTL_FIELD(R, MLST, mlst, UShort, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == val_fd && val > 1) return PutStatus::BadValue; // two states only
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    int enum_strings(const FieldDesc& f, const char* out[kEnumStates]) const override {
        if (&f != val_fd) return Record::enum_strings(f, out);
        out[0] = znam;
        out[1] = onam;
        return 2;
    }
    void init() override {
        if (simm_fd) {
            sim_init(*this, sim, *simm_fd);
            if (sval_fd) load_constant(sim.siol, *sval_fd);
        }
        if (dtyp == kDtypRawSoft && load_constant(inp, *rval_fd)) { // devBiSoftRaw
            val = rval ? 1 : 0;
            udf = 0;
        } else if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) {
            udf = 0;
        }
        oraw = rval;
        orbv = rbv;
    }
    // bo: VAL to RVAL (MASK: a one is MASK).
    void to_raw() { rval = mask ? (val ? mask : 0) : val; }
    void write_value(SimStep step) {
        if (step == SimStep::Now) write_link(sim.siol, sim.simm == 1 ? *val_fd : *rval_fd);
        else write_link(out, dtyp == kDtypRawSoft ? *rval_fd : *val_fd);
    }
    void binary_process(bool output, SimStep step) {
        if (!output) {
            if (step == SimStep::Now) { // simulated: SIOL into SVAL, YES as VAL, RAW as RVAL
                if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                    if (sim.simm == 1) val = uint16_t(sval);
                    else rval = sval, val = rval ? 1 : 0;
                    udf = 0;
                }
            } else if (dtyp == kDtypRawSoft) { // devBiSoftRaw: RVAL, masked, then VAL
                if (soft_read(*this, inp, *rval_fd)) {
                    if (mask) rval &= mask;
                    val = rval ? 1 : 0;
                    udf = 0;
                }
            } else if (soft_read(*this, inp, *val_fd)) {
                udf = 0;
            }
        }
        if (output && !sim.resuming) {
            if (omsl == 1 && soft_read(*this, dol, *val_fd)) {
                if (val > 1) val = 1; // boRecord: any non-zero DOL value is 1
                udf = 0;
            }
            to_raw();
        }
        const uint16_t sevr_of[2] = {zsv, osv};
        state_alarms(*this, val, 2, sevr_of, kNoAlarm, cosv, lalm);
        if (output) {
            if (nsev < kInvalid || ivoa == 0) {
                write_value(step);
            } else if (ivoa == 2) { // Set output to IVOV
                if (!sim.resuming) {
                    val = ivov ? 1 : 0;
                    to_raw();
                }
                write_value(step);
            }
        }
        stamp_time();
        unsigned m = reset_alarms();
        if (mlst != val) {
            m |= kDbeValue | kDbeLog;
            mlst = val;
        }
        if (m) post(val_fd, m);
        if (oraw != rval) {
            post(rval_fd, m | kDbeValue | kDbeLog);
            oraw = rval;
        }
        if (output && orbv != rbv) {
            post("RBV", m | kDbeValue | kDbeLog);
            orbv = rbv;
        }
    }
};

struct BiRecord : BinaryBase<BiRecord> {
    using BinaryBase::BinaryBase;
    static std::vector<FieldDesc> fields() {
        using R = BiRecord;
        auto v = binary_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        v.push_back(BEAMCTL_FIELD(R, SVAL, sval, ULong, 0));
        add_simulation_fields<R>(v, true, false);
        return v;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        binary_process(false, step);
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};

// bo: HIGH > 0 makes a one a pulse: HIGH seconds after the processing that wrote it (the last
// one, when it is written again before), VAL returns to 0 and the record processes (boRecord's
// myCallbackFunc).
struct BoRecord : BinaryBase<BoRecord> {
    using BinaryBase::BinaryBase;
    double high = 0; // [s]
    int high_pending = 0; // HIGH delays asked for and not yet passed
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (&f == val_fd) md.ctrl_hi = 65535; // boRecord's get_control_double (as softIoc serves)
    }
    int16_t precision(const FieldDesc& f) const override {
        if (is(f, "HIGH")) return 2; // boHIGHprecision
        return Record::precision(f);
    }
    static std::vector<FieldDesc> fields() {
        using R = BoRecord;
        auto v = binary_fields(common_fields());
        add_output_fields<R>(v, Dbf::UShort);
        v.push_back(BEAMCTL_FIELD(R, HIGH, high, Double, 0));
        v.push_back(BEAMCTL_FIELD(R, RBV, rbv, ULong, kReadOnly));
        v.push_back(BEAMCTL_FIELD(R, ORBV, orbv, ULong, kReadOnly));
        add_simulation_fields<R>(v, true, true);
        return v;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        binary_process(true, step);
        if (val == 1 && high > 0) {
            ++high_pending;
            call_after(high, kHighDelayTag);
        }
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) return sim_resume(*this, sim);
        if (tag != kHighDelayTag || --high_pending > 0 || !database()) return; // a later one 
        if (pact) { // busy (simulation delay): the pulse ends after another HIGH
            if (val == 1 && high > 0) {
                ++high_pending;
                call_after(high, kHighDelayTag);
            }
            return;
        }
        val = 0;
        database()->process(*this);
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
        binary_process(true, SimStep::Off);
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
    uint32_t rval = 0, mask = 0, oraw = 0, sval = 0;
    int32_t rbv = 0, orbv = 0;
    int16_t nobt = 0, shft = 0;
    uint16_t lalm = 0, mlst = 0;
    int16_t sdef = 0; // DBF_SHORT
    double aftc = 0, afvl = 0;
    Link inp, dol, out; // Soft Channel: mbbi INP; mbbo DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0, ivov = 0;
    Simulation sim;
    uint32_t raw_mask = 0; // Raw Soft Channel's mask (MASK, or all bits without NOBT), shifted
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* rval_fd = type().find("RVAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");

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
            BEAMCTL_FIELD(R, ORAW, oraw, ULong, kReadOnly),
            BEAMCTL_FIELD(R, MASK, mask, ULong, 0),
            BEAMCTL_FIELD(R, NOBT, nobt, UShort, 0),
            BEAMCTL_FIELD(R, SHFT, shft, UShort, 0),
            BEAMCTL_FIELD(R, LALM, lalm, UShort, kReadOnly),
            BEAMCTL_FIELD(R, MLST, mlst, UShort, kReadOnly),
            BEAMCTL_FIELD(R, SDEF, sdef, Short, kReadOnly),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }
    void init() override {
        update_sdef();
        if (mask == 0 && nobt > 0 && nobt <= 32) mask = uint32_t((uint64_t(1) << nobt) - 1); // from NOBT
        raw_mask = nobt == 0 ? 0xffffffffu : mask;
        if (shft > 0 && shft < 32) raw_mask <<= shft;
        if (simm_fd) {
            sim_init(*this, sim, *simm_fd);
            if (sval_fd) load_constant(sim.siol, *sval_fd);
        }
        if (dtyp == kDtypRawSoft && load_constant(inp, *rval_fd)) {
            to_val();
            udf = 0;
        } else if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) {
            udf = 0;
        }
        oraw = rval;
        orbv = rbv;
    }
    // init_common: states are defined when any value or string is set.
    void update_sdef() {
        sdef = 0;
        for (int i = 0; i < 16; ++i)
            if (vals[i] || strs[i][0]) sdef = 1;
    }
    // mbbi convert: RVAL (shifted down by SHFT) to the state whose value it is (65535: none), or
    // to itself without states.
    void to_val() {
        uint32_t r = rval;
        if (shft > 0 && shft < 32) r >>= shft;
        if (!sdef) {
            val = uint16_t(r);
            return;
        }
        val = 65535;
        for (int i = 0; i < 16; ++i)
            if (vals[i] == r) {
                val = uint16_t(i);
                break;
            }
    }
    // mbbo convert: VAL to its state's value (or itself), shifted up by SHFT; false: VAL > 15.
    bool to_raw() {
        if (sdef) {
            if (val > 15) return false;
            rval = vals[val];
        } else {
            rval = val;
        }
        if (shft > 0 && shft < 32) rval <<= shft;
        return true;
    }
    PutStatus special(const FieldDesc& f) override {
        if (&f == val_fd && val > 15) return PutStatus::BadValue; // sixteen states only
        sim_special(*this, sim, f, simm_fd);
        if ((f.name[2] == 'V' && f.name[3] == 'L' && !f.name[4]) || (f.name[2] == 'S' && f.name[3] == 'T' && !f.name[4]))
            update_sdef();
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
    void write_value(SimStep step) {
        if (step == SimStep::Now) {
            write_link(sim.siol, sim.simm == 1 ? *val_fd : *rval_fd);
        } else if (dtyp == kDtypRawSoft) { // devMbboSoftRaw: RVAL & MASK
            uint32_t keep = rval;
            rval &= raw_mask;
            write_link(out, *rval_fd);
            rval = keep;
        } else {
            write_link(out, *val_fd);
        }
    }
    void mbb_process(bool output, SimStep step) {
        EpicsTime last = time;
        if (!output) {
            if (step == SimStep::Now) {
                if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                    if (sim.simm == 1) val = uint16_t(sval);
                    else rval = sval, to_val();
                    udf = 0;
                }
            } else if (dtyp == kDtypRawSoft) { // devMbbiSoftRaw: RVAL & MASK, then the state
                if (soft_read(*this, inp, *rval_fd)) {
                    rval &= raw_mask;
                    to_val();
                    udf = 0;
                }
            } else if (soft_read(*this, inp, *val_fd)) {
                udf = 0;
            }
        }
        if (output && !sim.resuming) {
            if (omsl == 1 && soft_read(*this, dol, *val_fd)) udf = 0;
            if (!to_raw()) set_sevr(kStatSoft, kInvalid);
        }
        stamp_time();
        if (!output && aftc > 0 && !udf) { // mbbi's alarm filter over the state's severity
            uint16_t alarm = val > 15 ? unsv : sevs[val];
            bool first = afvl == 0;
            int filtered = alarm_filter(aftc, afvl, alarm, seconds_between(time, last));
            if (!first) alarm = uint16_t(filtered);
            set_sevr(kStatState, alarm);
            if (val != lalm && !set_sevr(kStatCos, cosv)) lalm = val;
        } else {
            if (udf) afvl = 0;
            state_alarms(*this, val, 16, sevs, unsv, cosv, lalm);
        }
        if (output) {
            if (nsev < kInvalid || ivoa == 0) {
                write_value(step);
            } else if (ivoa == 2) {
                if (!sim.resuming) {
                    val = ivov;
                    to_raw();
                }
                write_value(step);
            }
        }
        unsigned m = reset_alarms();
        if (mlst != val) {
            m |= kDbeValue | kDbeLog;
            mlst = val;
        }
        if (m) post(val_fd, m);
        if (oraw != rval) {
            post(rval_fd, m | kDbeValue | kDbeLog);
            oraw = rval;
        }
        if (output && orbv != rbv) {
            post("RBV", m | kDbeValue | kDbeLog);
            orbv = rbv;
        }
    }
};

struct MbbiRecord : MbbBase<MbbiRecord> {
    using MbbBase::MbbBase;
    static std::vector<FieldDesc> fields() {
        using R = MbbiRecord;
        auto v = mbb_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        v.push_back(BEAMCTL_FIELD(R, AFTC, aftc, Double, 0));
        v.push_back(BEAMCTL_FIELD(R, AFVL, afvl, Double, kReadOnly));
        v.push_back(BEAMCTL_FIELD(R, SVAL, sval, ULong, 0));
        add_simulation_fields<R>(v, true, false);
        return v;
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        mbb_process(false, step);
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};

struct MbboRecord : MbbBase<MbboRecord> {
    using MbbBase::MbbBase;
    static std::vector<FieldDesc> fields() {
        using R = MbboRecord;
        auto v = mbb_fields(common_fields());
        add_output_fields<R>(v, Dbf::UShort);
        v.push_back(BEAMCTL_FIELD(R, RBV, rbv, ULong, kReadOnly));
        v.push_back(BEAMCTL_FIELD(R, ORBV, orbv, ULong, kReadOnly));
        add_simulation_fields<R>(v, true, true);
        return v;
    }
    // mbboRecord's cvt_dbaddr: without any state defined (SDEF 0), VAL is a DBF_USHORT (a number
    // to clients: DBR_LONG natively, its digits as DBR_STRING, and a string put is a number).
    Elements elements(const FieldDesc& f) override {
        if (&f == val_fd && !sdef) return Elements{Dbf::UShort, &val, 1, 1, 2};
        return MbbBase::elements(f);
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        mbb_process(true, step);
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};

// ---------------------------------------------------------------- strings (stringin, stringout)
// epicsTimeToStrftime: strftime (local time) with %f / %0<n>f for the fraction of the second
// (n digits, at most 9; %f is 9). Returns false when the text does not fit in `size`.
bool format_epics_time(std::string_view fmt, const EpicsTime& t, char* out, std::size_t size) {
    std::string result;
    time_t posix = time_t(int64_t(t.sec) + EpicsTime::kPosixEpochOffset);
    std::tm tm{};
    localtime_r(&posix, &tm);
    std::string piece;
    auto flush = [&] {
        if (piece.empty()) return;
        char buf[256];
        std::size_t n = std::strftime(buf, sizeof buf, piece.c_str(), &tm);
        result.append(buf, n);
        piece.clear();
    };
    for (std::size_t i = 0; i < fmt.size(); ++i) {
        if (fmt[i] == '%' && i + 1 < fmt.size()) {
            if (fmt[i + 1] == '%') {
                piece += "%%";
                ++i;
                continue;
            }
            std::size_t j = i + 1;
            unsigned width = 0;
            while (j < fmt.size() && fmt[j] >= '0' && fmt[j] <= '9') width = width * 10 + unsigned(fmt[j++] - '0');
            if (j < fmt.size() && fmt[j] == 'f' && (j == i + 1 || width > 0)) {
                flush();
                if (j == i + 1 || width > 9) width = 9;
                static const uint32_t div[] = {1000000000, 100000000, 10000000, 1000000, 100000,
                                               10000,      1000,      100,      10,      1};
                uint32_t frac = std::min<uint32_t>(t.nsec + div[width] / 2, 999999999) / div[width];
                char buf[16];
                std::snprintf(buf, sizeof buf, "%0*u", int(width), unsigned(frac));
                result += buf;
                i = j;
                continue;
            }
        }
        piece += fmt[i];
    }
    flush();
    if (result.size() >= size) return false;
    copy_string(out, size, result);
    return true;
}

template <typename Self> struct StringBase : Record {
    using Record::Record;
    char val[40] = {}, oval[40] = {}, ivov[40] = {}, sval[40] = {};
    uint16_t mpst = 0, apst = 0; // On Change by default
    Link inp, dol, out; // Soft Channel: stringin INP; stringout DOL (OMSL closed_loop) and OUT
    uint16_t omsl = 0, ivoa = 0;
    bool output = false;
    Simulation sim;
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* sval_fd = type().find("SVAL");
    const FieldDesc* simm_fd = type().find("SIMM");
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
        sim_init(*this, sim, *simm_fd);
        if (sval_fd) load_constant(sim.siol, *sval_fd);
        if (load_constant(inp, *val_fd) || load_constant(dol, *val_fd)) udf = 0;
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
    }
    // The INST_IO text of INP/OUT ("@text") for the soft device supports that take one.
    std::string_view address(const Link& l) const {
        return l.kind == Link::Kind::Hw ? std::string_view(l.s().address) : std::string_view();
    }
    void read_value(SimStep step) {
        if (step == SimStep::Now) {
            if (read_link(sim.siol, *sval_fd) || sim.siol.kind != Link::Kind::Db) {
                std::memcpy(val, sval, sizeof val);
                udf = 0;
            }
        } else if (dtyp == kDtypTimestamp) { // devTimestampSI: the time now, formatted by INP
            time = EpicsTime::now();
            if (format_epics_time(address(inp), time, val, sizeof val)) {
                udf = 0;
            } else {
                udf = 1;
                set_sevr(kStatUdf, udfs);
            }
        } else if (dtyp == kDtypGetenv) { // devSiEnviron: the environment variable INP names
            std::string name(address(inp));
            if (const char* v = std::getenv(name.c_str())) {
                copy_string(val, sizeof val, v);
                udf = 0;
            } else {
                val[0] = 0;
                udf = 1;
                set_sevr(kStatUdf, udfs, "No such ENV");
            }
        } else if (soft_read(*this, inp, *val_fd)) {
            udf = 0;
        }
    }
    void write_value(SimStep step) {
        if (step == SimStep::Now) {
            write_link(sim.siol, *val_fd);
        } else if (dtyp == kDtypStdio) { // devSoStdio: OUT "@stdout", "@stderr" or "@errlog"
            std::string_view where = address(out);
            std::FILE* f = where == "stderr" || where == "errlog" ? stderr : stdout;
            std::fprintf(f, "%.*s\n", int(strnlen(val, sizeof val)), val);
            std::fflush(f);
        } else {
            write_link(out, *val_fd);
        }
    }
    ProcessResult process() override {
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (!output) read_value(step);
        if (output && !sim.resuming && omsl == 1 && soft_read(*this, dol, *val_fd)) udf = 0;
        if (udf) set_sevr(kStatUdf, udfs);
        if (output) {
            if (nsev < kInvalid || ivoa == 0) {
                write_value(step);
            } else if (ivoa == 2) {
                if (!sim.resuming) std::memcpy(val, ivov, sizeof val);
                write_value(step);
            }
        }
        if (dtyp != kDtypTimestamp) stamp_time();
        unsigned m = reset_alarms();
        bool changed = std::strncmp(oval, val, sizeof val) != 0;
        if (mpst == 1 || changed) m |= kDbeValue;
        if (apst == 1 || changed) m |= kDbeLog;
        std::memcpy(oval, val, sizeof val);
        if (m) post(val_fd, m);
        pact = 0;
        return ProcessResult::Done;
    }
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
};
struct StringinRecord : StringBase<StringinRecord> {
    using StringBase::StringBase;
    static std::vector<FieldDesc> fields() {
        using R = StringinRecord;
        auto v = string_fields(common_fields());
        v.push_back(BEAMCTL_FIELD(R, INP, inp, InLink, 0));
        v.push_back(BEAMCTL_FIELD(R, SVAL, sval, String, 0));
        add_simulation_fields<R>(v, false, false);
        return v;
    }
};
struct StringoutRecord : StringBase<StringoutRecord> {
    explicit StringoutRecord(const RecordType& t) : StringBase(t) { output = true; }
    static std::vector<FieldDesc> fields() {
        using R = StringoutRecord;
        auto v = string_fields(common_fields());
        add_output_fields<R>(v, Dbf::String);
        add_simulation_fields<R>(v, false, true);
        return v;
    }
};

// ---------------------------------------------------------------- waveform
struct WaveformRecord : Record {
    using Record::Record;
    uint16_t ftvl = 0; // STRING: menuFtype choice 0, base's default (no initial())
    uint32_t nelm = 1, nord = 0;
    char egu[16] = {};
    int16_t prec = 0;
    double hopr = 0, lopr = 0;
    uint16_t mpst = 0, apst = 0; // Always by default
    int16_t rarm = 0, busy = 0;  // RARM: written by clients (no device rearms here); BUSY: not busy
    uint32_t hash = 0;           // of the valid elements, for On Change posting (FNV-1a)
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
            BEAMCTL_FIELD(R, RARM, rarm, Short, kProcess),
            BEAMCTL_FIELD(R, BUSY, busy, Short, kReadOnly),
            BEAMCTL_FIELD(R, HASH, hash, ULong, 0),
        };
        v.insert(v.end(), add.begin(), add.end());
        add_simulation_fields<R>(v, false, false);
        return v;
    }
    Simulation sim;
    const FieldDesc* simm_fd = type().find("SIMM");
    void on_delay(int tag) override {
        if (tag == kSimDelayTag) sim_resume(*this, sim);
    }
    PutStatus special(const FieldDesc& f) override {
        sim_special(*this, sim, f, simm_fd);
        return PutStatus::Ok;
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
        case 8: t = Dbf::UInt64; size = 8; return true;
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
        sim_init(*this, sim, *simm_fd);
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
    int16_t precision(const FieldDesc& f) const override { // PREC for VAL and every double field
        if (&f == val_fd) return prec;
        if (f.dbf == Dbf::Float || f.dbf == Dbf::Double) return (prec < 0 || prec > 15) ? 15 : prec;
        return 0;
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
        SimStep step = sim_begin(*this, sim, *simm_fd);
        if (step == SimStep::Wait) return ProcessResult::Async;
        pact = 1;
        if (step == SimStep::Now) { // simulated: SIOL into VAL
            if (sim.siol.kind == Link::Kind::Db && read_link(sim.siol, *val_fd)) udf = 0;
        } else if (soft_read(*this, inp, *val_fd)) {
            udf = 0; // devWfSoft: up to NELM elements, NORD set
        }
        stamp_time();
        if (udf) set_sevr(kStatUdf, udfs);
        unsigned m = reset_alarms();
        if (mpst == 0) m |= kDbeValue;
        if (apst == 0) m |= kDbeLog;
        if (mpst == 1 || apst == 1) { // On Change: only when the valid elements changed (HASH)
            Elements e = elements(*val_fd);
            uint32_t h = 2166136261u;
            const char* p = static_cast<const char*>(e.data);
            for (std::size_t i = 0, n = std::size_t(e.count) * e.stride; i < n; ++i) h = (h ^ uint8_t(p[i])) * 16777619u;
            if (h != hash) {
                if (mpst == 1) m |= kDbeValue;
                if (apst == 1) m |= kDbeLog;
                hash = h;
                post("HASH", kDbeValue);
            }
        }
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
