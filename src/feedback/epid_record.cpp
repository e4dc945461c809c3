// The epid record (see epid_record.hpp). Semantics follow std's epidRecord.c (processing, alarms on
// VAL, monitors, metadata) and its device supports devEpidSoft.c, devEpidSoftCallback.c and
// devEpidFast.c (the parameter exchange); the code is ours.
#include "feedback/epid_record.hpp"

#include "feedback/epid.hpp"
#include "pv/database.hpp"
#include "pv/record_support.hpp"

#include <cmath>
#include <cstring>

namespace beamctl::feedback {
namespace {
using namespace pv;
using namespace pv::support;

const Menu kMenuEpidState{"epidFeedbackState", {"Off", "On"}};
const Menu kMenuEpidMode{"epidFeedbackMode", {"PID", "Max/Min"}};
const Menu kMenuEpidDtyp{"DTYP", {"Soft Channel", "Async Soft Channel", "Fast Epid"}};
enum : uint16_t { kSoft = 0, kAsyncSoft = 1, kFast = 2 };

bool linked(const Link& l) { return l.kind == Link::Kind::Db || l.kind == Link::Kind::Hw; }

struct EpidRecord : Record {
    using Record::Record;
    double val = 0;
    uint16_t smsl = 0;
    Link stpl, inp, outl, trig;
    double tval = 0, cval = 0, cvlp = 0, oval = 0, ovlp = 0;
    int16_t prec = 0;
    double mdt = 0;
    uint16_t fmod = 0, fbon = 0, fbop = 0;
    double kp = 0, ki = 0, kd = 0;
    char egu[16] = {};
    double hopr = 0, lopr = 0, drvh = 0, drvl = 0;
    double hihi = 0, lolo = 0, high = 0, low = 0;
    uint16_t hhsv = 0, llsv = 0, hsv = 0, lsv = 0;
    double hyst = 0, adel = 0, mdel = 0, odel = 0;
    double p = 0, pp = 0, i = 0, ip = 0, d = 0, dp = 0;
    double dt = 0, dtp = 0, err = 0, errp = 0;
    double lalm = 0, alst = 0, mlst = 0;
    double ct = NAN; // CT: the database clock at the last step [s] (NOACCESS in synApps)
    const FieldDesc* val_fd = type().find("VAL");
    const FieldDesc* cval_fd = type().find("CVAL");
    const FieldDesc *oval_fd = type().find("OVAL"), *p_fd = type().find("P"), *i_fd = type().find("I"),
                    *d_fd = type().find("D"), *dt_fd = type().find("DT"), *err_fd = type().find("ERR");

    static std::vector<FieldDesc> fields() {
        using R = EpidRecord;
        auto v = common_fields();
        for (auto& f : v)
            if (std::strcmp(f.name, "DTYP") == 0) f.menu = &kMenuEpidDtyp;
        constexpr uint16_t kRo = kReadOnly;
        auto add = {
            BEAMCTL_FIELD(R, VAL, val, Double, kVal),
            BEAMCTL_MENU(R, SMSL, smsl, kMenuOmsl, 0),
            BEAMCTL_FIELD(R, STPL, stpl, InLink, 0),
            BEAMCTL_FIELD(R, INP, inp, InLink, 0),
            BEAMCTL_FIELD(R, OUTL, outl, OutLink, 0),
            BEAMCTL_FIELD(R, TRIG, trig, OutLink, 0),
            BEAMCTL_FIELD(R, TVAL, tval, Double, 0),
            BEAMCTL_FIELD(R, CVAL, cval, Double, kRo),
            BEAMCTL_FIELD(R, CVLP, cvlp, Double, kRo),
            BEAMCTL_FIELD(R, OVAL, oval, Double, kRo),
            BEAMCTL_FIELD(R, OVLP, ovlp, Double, kRo),
            BEAMCTL_FIELD(R, PREC, prec, Short, kMeta),
            BEAMCTL_FIELD(R, MDT, mdt, Double, 0),
            BEAMCTL_MENU(R, FMOD, fmod, kMenuEpidMode, 0),
            BEAMCTL_MENU(R, FBON, fbon, kMenuEpidState, 0),
            BEAMCTL_MENU(R, FBOP, fbop, kMenuEpidState, 0),
            BEAMCTL_FIELD(R, KP, kp, Double, 0),
            BEAMCTL_FIELD(R, KI, ki, Double, 0),
            BEAMCTL_FIELD(R, KD, kd, Double, 0),
            BEAMCTL_FIELD(R, EGU, egu, String, kMeta),
            BEAMCTL_FIELD(R, HOPR, hopr, Double, kMeta),
            BEAMCTL_FIELD(R, LOPR, lopr, Double, kMeta),
            BEAMCTL_FIELD(R, DRVH, drvh, Double, kMeta),
            BEAMCTL_FIELD(R, DRVL, drvl, Double, kMeta),
            BEAMCTL_FIELD(R, HIHI, hihi, Double, kMeta),
            BEAMCTL_FIELD(R, LOLO, lolo, Double, kMeta),
            BEAMCTL_FIELD(R, HIGH, high, Double, kMeta),
            BEAMCTL_FIELD(R, LOW, low, Double, kMeta),
            BEAMCTL_MENU(R, HHSV, hhsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, LLSV, llsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, HSV, hsv, kMenuAlarmSevr, 0),
            BEAMCTL_MENU(R, LSV, lsv, kMenuAlarmSevr, 0),
            BEAMCTL_FIELD(R, HYST, hyst, Double, 0),
            BEAMCTL_FIELD(R, ADEL, adel, Double, 0),
            BEAMCTL_FIELD(R, MDEL, mdel, Double, 0),
            BEAMCTL_FIELD(R, ODEL, odel, Double, 0),
            BEAMCTL_FIELD(R, P, p, Double, kRo),
            BEAMCTL_FIELD(R, PP, pp, Double, kRo),
            BEAMCTL_FIELD(R, I, i, Double, 0),
            BEAMCTL_FIELD(R, IP, ip, Double, 0),
            BEAMCTL_FIELD(R, D, d, Double, kRo),
            BEAMCTL_FIELD(R, DP, dp, Double, kRo),
            BEAMCTL_FIELD(R, DT, dt, Double, 0),
            BEAMCTL_FIELD(R, DTP, dtp, Double, 0),
            BEAMCTL_FIELD(R, ERR, err, Double, kRo),
            BEAMCTL_FIELD(R, ERRP, errp, Double, kRo),
            BEAMCTL_FIELD(R, LALM, lalm, Double, kRo),
            BEAMCTL_FIELD(R, ALST, alst, Double, kRo),
            BEAMCTL_FIELD(R, MLST, mlst, Double, kRo),
        };
        v.insert(v.end(), add.begin(), add.end());
        return v;
    }

    void init() override {
        if (load_constant(stpl, *val_fd)) udf = 0;
        if (dtyp == kFast && inp.kind != Link::Kind::Hw)
            throw Error(std::string("epid ") + std::string(name()) +
                        ": DTYP \"Fast Epid\" needs INP \"@<loop>\" naming a feedback loop of the IOC (feedback: in ioc.yaml)");
    }

    ProcessResult process() override {
        pact = 1;
        if (smsl == 1 && linked(stpl) && read_link(stpl, *val_fd)) udf = 0; // closed_loop setpoint
        if (udf) {
            set_sevr(kStatUdf, udfs);
        } else if (dtyp == kFast) {
            do_fast();
        } else {
            do_soft();
        }
        stamp_time();
        check_alarms();
        monitor();
        pact = 0;
        return ProcessResult::Done;
    }

    // devEpidSoft's do_pid (and devEpidSoftCallback's, whose TRIG write comes first).
    void do_soft() {
        if (!linked(inp)) { // nothing to control
            set_sevr(kStatSoft, kInvalid);
            return;
        }
        if (dtyp == kAsyncSoft && linked(trig) && !write_link(trig, tval)) return; // LINK alarm raised
        const double pcval = cval;
        if (!read_link(inp, *cval_fd)) return; // LINK/INVALID raised
        const double now = database() ? database()->now() : 0;
        const bool first = std::isnan(ct); // the first step: no dt yet (no integral, no derivative)
        const double step_dt = first ? 0 : now - ct;
        if (!first && step_dt < mdt) return;
        EpidInput in;
        in.setpoint = val;
        in.cval = cval;
        in.dt = step_dt;
        in.kp = kp, in.ki = ki, in.kd = kd;
        in.drvh = drvh, in.drvl = drvl;
        in.fbon = fbon != 0, in.fbop = fbop != 0;
        in.mode = EpidMode(fmod);
        if (in.fbon && !in.fbop && linked(outl)) { // bumpless start: I (Max/Min: OVAL) from the output
            in.have_readback = read_link(outl, in.readback);
        }
        EpidTerms t{err, p, i, d, oval, pcval};
        const double out = epid_step(in, t);
        ct = now;
        dt = step_dt;
        err = t.err;
        if (odel == 0 || std::fabs(oval - out) > odel) oval = out;
        p = t.p, i = t.i, d = t.d;
        fbop = fbon;
        if (fbon && linked(outl)) write_link(outl, oval); // a refused write raises LINK/INVALID
    }

    // devEpidFast's update_params: the loop's state in, the parameters out.
    void do_fast() {
        auto* dev = dynamic_cast<FastEpidDevice*>(inp.device());
        if (!dev) {
            set_sevr(kStatSoft, kInvalid);
            return;
        }
        FastEpidDevice::Params prm;
        prm.setpoint = val, prm.kp = kp, prm.ki = ki, prm.kd = kd;
        prm.drvh = drvh, prm.drvl = drvl, prm.dt = dt, prm.fbon = fbon != 0;
        const FastEpidDevice::State s = dev->exchange(prm);
        cval = s.cval, err = s.err, oval = s.oval;
        p = s.p, i = s.i, d = s.d, dt = s.dt;
        fbop = fbon;
        if (!s.ok) set_sevr(kStatLink, kInvalid);
    }

    // epidRecord.c checkAlarms: limit alarms on VAL (the setpoint) with hysteresis.
    void check_alarms() {
        if (udf) {
            set_sevr(kStatUdf, kInvalid);
            return;
        }
        limit_alarms<double>(*this, val, hihi, high, low, lolo, hhsv, hsv, lsv, llsv, hyst, lalm);
    }

    // epidRecord.c monitor: VAL with MDEL/ADEL; OVAL P I D DT ERR CVAL when they changed.
    void monitor() {
        unsigned mask = reset_alarms();
        check_deadband(mlst, val, mdel, mask, kDbeValue);
        check_deadband(alst, val, adel, mask, kDbeLog);
        if (mask) post(val_fd, mask);
        constexpr unsigned kVl = kDbeValue | kDbeLog;
        auto changed = [this](double& last, double now, const FieldDesc* f) {
            if (last != now) {
                post(f, kVl);
                last = now;
            }
        };
        changed(ovlp, oval, oval_fd);
        changed(pp, p, p_fd);
        changed(ip, i, i_fd);
        changed(dp, d, d_fd);
        changed(dtp, dt, dt_fd);
        changed(errp, err, err_fd);
        changed(cvlp, cval, cval_fd);
    }

    int16_t precision(const FieldDesc& f) const override {
        if (f.dbf == Dbf::Float || f.dbf == Dbf::Double) return (prec < 0 || prec > 15) ? 15 : prec;
        return 0;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override {
        Record::metadata(f, md);
        if (f.dbf == Dbf::Double) md.units = egu;
        const bool setpoint_like = &f == val_fd || &f == cval_fd || is(f, "HIHI") || is(f, "HIGH") || is(f, "LOW") || is(f, "LOLO");
        const bool output_like = &f == oval_fd || &f == p_fd || &f == i_fd || &f == d_fd;
        if (setpoint_like) fill_limits(md, hopr, lopr, hopr, lopr);
        if (output_like) fill_limits(md, drvh, drvl, drvh, drvl);
        if (&f == val_fd) {
            md.alarm_hihi = hihi;
            md.alarm_high = high;
            md.alarm_low = low;
            md.alarm_lolo = lolo;
        }
    }
};

} // namespace

void register_feedback_records(RecordTypes& types) {
    if (!types.find("epid")) add_type<EpidRecord>(types, "epid");
}

} // namespace beamctl::feedback
