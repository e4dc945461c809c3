// The motor record. Facts follow motorRecord.cc / motorRecord.dbd (epics-modules/motor R7-3) and
// specs/records.md §3; the code is ours. How it maps onto this framework:
//
// - Processing: process() (a put to a pp field, PROC, PINI, the periodic scan) reads the driver
//   status, advances the motion and then acts on what was written (do_work). poll() does the
//   first two only. Both post the fields that changed since they were last posted (a byte
//   snapshot per field), DMOV last, and complete a pending put-callback when DMOV is 1 at the end.
//   process() therefore always returns Async and reports completion itself through async_done():
//   the record is never "pact" between calls, so STOP and new targets are processed while a
//   motion is in progress (as the motor record must be: see the comment above process() in
//   motorRecord.cc), and a put-callback on VAL completes only when the motion is done.
// - Polling: the motor type's SCAN field is stored in its own member and Record::scan stays
//   Passive (so puts, PP links and forward links process the record); the database calls
//   poll_tick() every 0.1 s (poll_period_s), which processes the record as a status poll.
//   Clients still read and write the SCAN they configured.
// - Units: the driver speaks dial EGU; RRBV = NINT(dial/MRES) and DRBV = RRBV*MRES as in the
//   record (or REP*ERES with UEIP=Yes); targets go to the driver in dial EGU, unrounded.
//
// Differences from motorRecord.cc, on purpose: a new target while a positioning move is in
// progress retargets the driver at once (the record waits for the move to end and then retries);
// a problem bit or a limit switch ends a move without retries; STOP (or SPMG=Stop) also cancels a
// target that was waiting for SPMG=Go; refused HOMF/HOMR (at the switch) and JOGF/JOGR (while
// busy or at the switch) reset the button and never leave it stuck at 1 (HOMF pulses DMOV so
// ophyd's home() completes); HLSV's soft-limit part applies only when soft limits are enabled;
// URIP=Yes needs an RDBL link; NTM is always on (a new target retargets at once); HIHI..LOLO
// alarm on RBV. Kept but not acting: MDEL/ADEL (every change posts), INIT/PREM/POST (no driver
// strings). OMSL closed_loop reads DOL when the record is processed (not when it polls).
#include "pv/motor_record.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/database.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string_view>

namespace beamctl::pv {
namespace {

log::Logger lg("pv.motor");

double steady_now() {
    using namespace std::chrono;
    return duration<double>(steady_clock::now().time_since_epoch()).count();
}

// ---------------------------------------------------------------- SimMotorDriver motion model
} // namespace

struct SimMotorDriver::Impl {
    // Motion from (t0, x0, v0): segments of constant acceleration, then rest at the end (at x_end
    // exactly when `snap`), or, for a jog, cruise on forever.
    struct Segment {
        double dt; // [s]
        double a;  // [EGU/s^2]
    };
    MotorClock clock;
    double t0 = 0, x0 = 0, v0 = 0; // [s], [EGU], [EGU/s]
    std::array<Segment, 4> seg{};
    int nseg = 0;
    bool endless = false;
    bool snap = false;
    double x_end = 0;
    double home_position = 0;
    bool homing = false, homed = false, enabled = true, dir_positive = true;

    double now() const { return clock ? clock() : steady_now(); }

    struct State {
        double x, v;
        bool done;
    };
    State at(double t) const {
        double tau = std::max(0.0, t - t0);
        double x = x0, v = v0, total = 0;
        for (int i = 0; i < nseg; ++i) {
            double d = std::clamp(tau - total, 0.0, seg[i].dt);
            x += v * d + 0.5 * seg[i].a * d * d;
            v += seg[i].a * d;
            total += seg[i].dt;
        }
        if (endless) {
            x += v * std::max(0.0, tau - total);
            return {x, v, false};
        }
        if (tau >= total) return {snap ? x_end : x, 0.0, true};
        return {x, v, false};
    }
    // Starts a new plan at the present state.
    void restart() {
        double t = now();
        State s = at(t);
        t0 = t;
        x0 = s.x;
        v0 = s.done ? 0.0 : s.v;
        nseg = 0;
        endless = false;
        snap = false;
    }
    void add(double dt, double a) {
        if (dt > 0 && nseg < int(seg.size())) seg[nseg++] = {dt, a};
    }
    void plan_move(double target, double vmax, double a) {
        restart();
        homing = false;
        double x = x0, v = v0;
        if (!(vmax > 0) || !std::isfinite(vmax)) { // no speed given: arrive at once
            x0 = target;
            v0 = 0;
            return;
        }
        double d = target - x;
        double s = d >= 0 ? 1.0 : -1.0;
        if (d != 0) dir_positive = d > 0;
        if (!(a > 0) || !std::isfinite(a)) { // infinite acceleration: constant speed
            v0 = s * vmax;
            add(std::fabs(d) / vmax, 0);
            snap = true;
            x_end = target;
            return;
        }
        if (v != 0) { // moving away, or too fast to stop in time: stop first
            double ds = v * v / (2 * a);
            if (v * d < 0 || ds > std::fabs(d)) {
                double sv = v > 0 ? 1.0 : -1.0;
                add(std::fabs(v) / a, -sv * a);
                x += sv * ds;
                v = 0;
                d = target - x;
                s = d >= 0 ? 1.0 : -1.0;
            }
        }
        double dist = std::fabs(d), u = std::fabs(v);
        double vp = std::min(vmax, std::sqrt((2 * a * dist + u * u) / 2));
        double d1 = std::fabs(vp * vp - u * u) / (2 * a), d3 = vp * vp / (2 * a);
        add(std::fabs(vp - u) / a, vp >= u ? s * a : -s * a);
        if (vp > 0) add(std::max(0.0, dist - d1 - d3) / vp, 0);
        add(vp / a, -s * a);
        snap = true;
        x_end = target;
    }
    void plan_velocity(double vt, double a, bool keep) {
        restart();
        homing = false;
        if (vt != 0) dir_positive = vt > 0;
        if (!(a > 0) || !std::isfinite(a)) {
            v0 = vt;
        } else {
            add(std::fabs(vt - v0) / a, vt >= v0 ? a : -a);
        }
        endless = keep && vt != 0;
    }
};

SimMotorDriver::SimMotorDriver(MotorClock clock, double dial_position)
    : impl_(std::make_unique<Impl>()) {
    impl_->clock = std::move(clock);
    impl_->t0 = impl_->now();
    impl_->x0 = dial_position;
}
SimMotorDriver::~SimMotorDriver() = default;

void SimMotorDriver::set_clock(MotorClock clock) {
    Impl::State s = impl_->at(impl_->now());
    impl_->clock = std::move(clock);
    if (s.done) { // re-anchor a motor at rest on the new time base
        impl_->t0 = impl_->now();
        impl_->x0 = s.x;
        impl_->v0 = 0;
        impl_->nseg = 0;
        impl_->endless = impl_->snap = false;
    }
}
void SimMotorDriver::set_home_position(double p) {
    impl_->home_position = p;
}
void SimMotorDriver::move(double t, double v, double a) {
    impl_->plan_move(t, v, a);
}
void SimMotorDriver::move_velocity(double v, double a) {
    impl_->plan_velocity(v, a, true);
}
void SimMotorDriver::home(bool forward, double v, double a) {
    (void)forward; // no switches: home is a move to the home position
    impl_->plan_move(impl_->home_position, v, a);
    impl_->homing = true;
}
void SimMotorDriver::stop(double a) {
    impl_->plan_velocity(0, a, false);
}
void SimMotorDriver::set_position(double p) {
    Impl::State s = impl_->at(impl_->now());
    double delta = p - s.x;
    impl_->x0 += delta;
    impl_->x_end += delta;
}
void SimMotorDriver::set_closed_loop(bool on) {
    impl_->enabled = on;
}

MotorDriver::Status SimMotorDriver::status() {
    Impl::State s = impl_->at(impl_->now());
    if (impl_->homing && s.done) {
        impl_->homing = false;
        impl_->homed = true;
    }
    if (s.v != 0) impl_->dir_positive = s.v > 0;
    Status st;
    st.position = s.x;
    st.velocity = s.v;
    st.done = s.done;
    st.moving = !s.done;
    st.direction_positive = impl_->dir_positive;
    st.homed = impl_->homed;
    st.enabled = impl_->enabled;
    return st;
}

// ---------------------------------------------------------------- the record
namespace {

const Menu kMenuMotorDir{"motorDIR", {"Pos", "Neg"}};
const Menu kMenuMotorFoff{"motorFOFF", {"Variable", "Frozen"}};
const Menu kMenuMotorSet{"motorSET", {"Use", "Set"}};
const Menu kMenuMotorUeip{"motorUEIP", {"No", "Yes"}};
const Menu kMenuMotorSpmg{"motorSPMG", {"Stop", "Pause", "Move", "Go"}};
const Menu kMenuMotorTorq{"motorTORQ", {"Disable", "Enable"}};
const Menu kMenuMotorRstm{"motorRSTM", {"Never", "Always", "NearZero", "Conditional"}};
// "Compound Motor": automation/compound_motor (a virtual motor over other motor records).
const Menu kMenuMotorDtyp{"DTYP", {"Sim Motor", "asynMotor", "Compound Motor"}};
const Menu kMenuMotorAccu{"motorACCSUSED", {"Use ACCL", "Use ACCS"}};
const Menu kMenuMotorRmod{"motorRMOD", {"Default", "Arithmetic", "Geometric", "In-Position"}};
const Menu kMenuMotorStup{"motorSTUP", {"OFF", "ON", "BUSY"}};

enum : uint16_t { kSpmgStop = 0, kSpmgPause = 1, kSpmgMove = 2, kSpmgGo = 3 };
enum : uint16_t { kRstmNever = 0, kRstmAlways = 1, kRstmNearZero = 2, kRstmConditional = 3 };
enum : uint16_t { kRmodDefault = 0, kRmodArithmetic = 1, kRmodGeometric = 2, kRmodInPosition = 3 };

// MSTA bits (motor.h).
enum : uint32_t {
    kMstaDirection = 1u << 0,
    kMstaDone = 1u << 1,
    kMstaPlusLs = 1u << 2,
    kMstaHome = 1u << 3,
    kMstaPosition = 1u << 5,
    kMstaSlipStall = 1u << 6,
    kMstaEncHome = 1u << 7,
    kMstaEncPresent = 1u << 8,
    kMstaProblem = 1u << 9,
    kMstaMoving = 1u << 10,
    kMstaGainSupport = 1u << 11,
    kMstaCommErr = 1u << 12,
    kMstaMinusLs = 1u << 13,
    kMstaHomed = 1u << 14,
};

// MIP bits as motorRecord.cc shows them (read-only, for diagnosis).
enum : uint16_t {
    kMipJogF = 0x1,
    kMipJogR = 0x2,
    kMipHomF = 0x8,
    kMipHomR = 0x10,
    kMipMove = 0x20,
    kMipRetry = 0x40,
    kMipLoadP = 0x80,
    kMipMoveBl = 0x100,
    kMipStop = 0x200,
    kMipDelayReq = 0x400,
    kMipJogStop = 0x2000,
    kMipExternal = 0x8000,
};

int32_t nint(double x) {
    if (!std::isfinite(x)) return 0;
    if (x >= 2147483647.0) return 2147483647;
    if (x <= -2147483648.0) return int32_t(-2147483647 - 1);
    return int32_t(std::llround(x));
}

// What the record is doing.
enum class Phase : uint8_t {
    Idle,     // nothing; DMOV is 0 only while a target waits for SPMG=Go/Move
    Moving,   // positioning (the first leg when a backlash leg follows)
    Backlash, // final backlash approach
    Homing,
    Jogging,
    JogStopping, // jog released: backlash after it stops
    Stopping,    // STOP/SPMG=Stop/limit: targets follow the readback when stopped; `after_` next
    Pausing,     // SPMG=Pause: target kept, the move resumes on Go/Move
    External,    // the driver moves without a command from this record
    Settling,    // stopped, waiting DLY before the retry check or DMOV=1
};
enum class After : uint8_t { None, HomeF, HomeR, JogF, JogR }; // starts once a stop completes
enum class Then : uint8_t { Finish, RetryCheck };              // after DLY

class MotorRecordImpl final : public MotorRecord {
public:
    // --- fields (motorRecord.dbd types)
    double val = 0, dval = 0, rlv = 0, rbv = 0, drbv = 0, diff = 0;
    int32_t rval = 0, rrbv = 0, rdif = 0, rmp = 0, rep = 0;
    double off = 0;
    uint16_t dir = 0, foff = 0, set = 0;
    int16_t igset = 0;
    double mres = 0, eres = 0, rres = 0, urev = 0;
    int32_t srev = 200;
    uint16_t ueip = 0, urip = 0;
    int16_t prec = 0;
    char egu[16] = {};
    double velo = 0, vbas = 0, vmax = 0, accl = 0.2, bdst = 0, bvel = 0, bacc = 0.5, hvel = 0,
           jvel = 0, jar = 0;
    double hlm = 0, llm = 0, dhlm = 0, dllm = 0;
    int16_t hls = 0, lls = 0, rhls = 0, rlls = 0;
    uint16_t hlsv = 0;
    int16_t lvio = 1, dmov = 1, movn = 0, tdir = 0, cdir = 0, athm = 0, miss = 0, rcnt = 0,
            rtry = 10;
    double rdbd = 0, spdb = 0, dly = 0;
    int16_t stop = 0;
    // synApps fields kept for databases that set them: FOF/VOF and SSET/SUSE are buttons for
    // FOFF and SET; RHLM/RLLM are DHLM/DLLM in steps; SPAM (the ESS/PSI fork ecmccfg uses) is a
    // debug-print mask; the Soft Channel device support's links (STOO DINP RINP LOCK), CARD, LRLV,
    // RVEL, PP, MMAP/NMAP, ALST/MLST and the fork's MISV/MFLG/MINP are stored and do nothing here.
    int16_t fof = 0, vof = 0, sset = 0, suse = 0, card = -1, pp_field = 0, spam = 15;
    double rhlm = 0, rllm = 0, lrlv = 0, alst = 0, mlst = 0;
    int32_t rvel = 0;
    uint32_t mmap = 0, nmap = 0, mflg = 0;
    uint16_t lock = 0, misv = 0;
    Link stoo, dinp, rinp, minp;
    uint16_t spmg = kSpmgGo, lspg = kSpmgGo;
    int16_t homf = 0, homr = 0, jogf = 0, jogr = 0, twf = 0, twr = 0;
    double twv = 0;
    uint16_t cnen = 0;
    uint32_t msta = 0;
    uint16_t mip = 0;
    double lval = 0, ldvl = 0;
    int32_t lrvl = 0;
    uint16_t rstm = kRstmNearZero;
    // speeds in revolutions per second (UREV per revolution), acceleration in EGU/s^2
    double s = 0, sbas = 0, smax = 0, sbak = 0, accs = 0;
    uint16_t accu = 0;                 // ACCU: which of ACCL and ACCS was set last
    float frac = 1;                    // FRAC: fraction of the final (backlash) approach
    uint16_t rmod = kRmodDefault;      // RMOD: retry fractions
    uint16_t ntm = 1, ntmf = 2;        // NTM/NTMF (new targets retarget at once here)
    double hihi = 0, lolo = 0, high = 0, low = 0, hopr = 0, lopr = 0, mdel = 0, adel = 0;
    uint16_t hhsv = 0, llsv = 0, hsv = 0, lsv = 0;
    uint16_t stup = 0;                 // STUP: a status update on request
    int16_t sync_field = 0;            // SYNC: targets := readbacks
    double pcof = 0, icof = 0, dcof = 0; // PCOF/ICOF/DCOF: the driver's PID gains
    uint16_t omsl = 0;                 // OMSL closed_loop: VAL from DOL when processed
    Link dol, rdbl, rlnk;              // DOL; RDBL (URIP: readback, RRES per unit); RLNK (RBV out)
    char init_text[40] = {}, prem[40] = {}, post_text[40] = {};
    float vers = 7.3f;
    char out_text[64] = {};
    uint16_t scan_field = 0; // SCAN as clients see it (the record is polled by poll_tick)
    bool processing_ = false; // inside process()
    uint32_t sync_seen_ = 0, stop_seen_ = 0; // the driver's request counts acted on

    static std::vector<FieldDesc> fields();

    explicit MotorRecordImpl(const RecordType& t)
        : MotorRecord(t) {
        const auto& fs = type().fields();
        first_ = std::size_t(type().find("VAL")->index);
        fd_dmov_ = type().find("DMOV");
        snap_off_.resize(fs.size() + 1, 0);
        for (std::size_t i = 0; i < fs.size(); ++i)
            snap_off_[i + 1] = snap_off_[i] + (i >= first_ ? fs[i].size : 0);
        snap_.assign(snap_off_.back(), 0);
    }

    // --- MotorRecord
    void set_driver(std::shared_ptr<MotorDriver> d) override {
        if (!d)
            d = make_sim();
        else
            sim_ = nullptr;
        driver_ = std::move(d);
        if (!initialised_) return;
        resync();
        valid_seen_ = st_.valid;
        failed_ = false;
        publish();
        if (dmov) async_done();
    }
    const std::shared_ptr<MotorDriver>& driver() const override { return driver_; }
    void set_clock(MotorClock c) override {
        clock_ = c ? std::move(c) : MotorClock(steady_now);
        if (sim_) sim_->set_clock(clock_);
    }
    void poll() override {
        if (initialised_ && !pact) run(false);
    }
    std::string_view out() const override {
        return std::string_view(out_text, strnlen(out_text, sizeof out_text));
    }

    // --- Record
    void init() override;
    ProcessResult process() override {
        if (!initialised_) return ProcessResult::Done;
        if (omsl == 1 && dol.is_db() && read_link(dol, *type().find("VAL"))) // closed_loop: VAL from DOL
            failed_ = false;
        processing_ = true;
        run(true);
        processing_ = false;
        return ProcessResult::Async; // completion reported by run() through async_done()
    }
    // Every 0.1 s the database polls the record: status, motion, and what waits for it.
    double poll_period_s() const override { return 0.1; }
    void poll_tick() override {
        if (initialised_ && !pact) run(true);
    }
    PutStatus special(const FieldDesc& f) override;
    int16_t precision(const FieldDesc& f) const override {
        if (f.dbf != Dbf::Double && f.dbf != Dbf::Float) return 0;
        return (prec < 0 || prec > 15) ? 15 : prec;
    }
    void metadata(const FieldDesc& f, Metadata& md) const override;

private:
    std::shared_ptr<MotorDriver> driver_;
    SimMotorDriver* sim_ = nullptr; // driver_ when it is the built-in sim
    MotorClock clock_ = steady_now;
    MotorDriver::Status st_;
    bool initialised_ = false;

    Phase phase_ = Phase::Idle;
    After after_ = After::None;
    Then then_ = Then::Finish;
    double settle_until_ = 0;       // [s] on clock_
    bool backlash_pending_ = false; // Moving: the final backlash leg follows
    bool retrying_ = false;
    bool jog_req_ = false; // a jog button went to 1 and the jog has not started
    bool jog_fwd_ = true, home_fwd_ = true;
    bool pending_target_ = false; // a target written while homing or moving externally
    bool ls_hit_ = false;         // the last motion ended on the switch in its direction
    bool failed_ = false;         // the motion of the last drive-field write was refused or ended
                                  // short: its put-callback completes with a failure
    bool valid_seen_ = true;      // the driver's readback has been valid (VAL synced to it)
    bool lvio_refused_ = false;   // the last drive-field write was refused for a soft limit
                                  // (SOFT/MINOR alarm until the next write that moves)

    std::size_t first_ = 0; // index of the first motor field (after dbCommon)
    const FieldDesc* fd_dmov_ = nullptr;
    std::vector<uint32_t> snap_off_; // byte offset of each field in snap_
    std::vector<uint8_t> snap_;      // field values as last posted
    // Units strings handed out by metadata(); each stays valid until EGU changes.
    mutable char units_per_s_[24] = {}, units_per_s2_[24] = {}, units_per_rev_[24] = {};

    std::shared_ptr<MotorDriver> make_sim() {
        auto s = std::make_shared<SimMotorDriver>(clock_);
        sim_ = s.get();
        return s;
    }

    // --- helpers
    int dirs() const { return dir ? -1 : 1; }
    bool limits_on() const { return !(dhlm == 0 && dllm == 0); }
    bool set_mode() const { return set && !igset; }
    static double accel_for(double v, double t, double vb) { // accEGUfromVelo [EGU/s^2]
        if (!(t > 0)) return 0;
        return v > vb ? (v - vb) / t : v / t;
    }
    double move_accel() const { return accel_for(velo, accl, vbas); }
    static void range_check(double& v, double lo, double hi) {
        if (v < lo) v = lo;
        if (hi != 0 && v > hi) v = hi;
    }
    // FRAC: the final approach from `from` covers this much of the way to DVAL (the retries the
    // rest), as motorRecord's backlash leg.
    double final_approach(double from) const {
        double f = frac > 0 ? frac : 1;
        return from + f * (dval - from);
    }
    // RMOD: the part of the remaining distance a retry moves (retry RCNT of RTRY).
    double retry_fraction() const {
        if (rmod == kRmodArithmetic && rtry > 0) return double(rtry - rcnt + 1) / rtry;
        if (rmod == kRmodGeometric) return std::ldexp(1.0, -std::max(0, rcnt - 1));
        return 1;
    }
    // S/SBAS/SMAX/SBAK from VELO/VBAS/VMAX/BVEL, and ACCL/ACCS from each other (ACCU says which
    // was given), as motorRecord does after any speed or resolution change.
    void derived_speeds() {
        double u = std::fabs(urev);
        if (u > 0) {
            s = velo / u;
            sbas = vbas / u;
            smax = vmax / u;
            sbak = bvel / u;
        }
        double dv = velo - vbas > 0 ? velo - vbas : velo;
        if (accu == 1 && accs > 0 && dv > 0)
            accl = dv / accs;
        else if (accl > 0)
            accs = dv / accl;
    }
    void clamp_speeds() {
        range_check(velo, vbas, vmax);
        range_check(bvel, vbas, vmax);
        range_check(jvel, vbas, vmax);
        range_check(hvel, vbas, vmax);
    }
    void clear_buttons() { jogf = jogr = homf = homr = 0; }
    void remember_targets() {
        lval = val;
        ldvl = dval;
        lrvl = rval;
    }
    void restore_targets() {
        val = lval;
        dval = ldvl;
        rval = lrvl;
    }
    void sync_targets() { // targets := readback
        val = rbv;
        dval = drbv;
        rval = nint(dval / mres);
        remember_targets();
    }
    void set_userlimits() {
        if (dir == 0) {
            hlm = dhlm + off;
            llm = dllm + off;
        } else {
            hlm = -dllm + off;
            llm = -dhlm + off;
        }
    }
    void finish() {
        phase_ = Phase::Idle;
        after_ = After::None;
        backlash_pending_ = retrying_ = false;
        dmov = 1;
    }
    void halt(double acc) { driver_->stop(acc); }
    void drive(double target, double v, double a) { driver_->move(target, v, a); }

    // --- snapshot of posted values
    bool changed(const FieldDesc& f) const {
        return std::memcmp(f.addr(const_cast<MotorRecordImpl&>(*this)),
                           snap_.data() + snap_off_[std::size_t(f.index)], f.size) != 0;
    }
    void sync(const FieldDesc& f) {
        std::memcpy(snap_.data() + snap_off_[std::size_t(f.index)], f.addr(*this), f.size);
    }
    void post_now(const FieldDesc* f) {
        sync(*f);
        post(f, kDbeValue | kDbeLog);
    }

    void refresh();
    void track(double now);
    void on_stopped(double now);
    void settle(Then then, double now);
    void after_settle(Then then);
    void start_move(bool retry);
    void start_home(bool forward);
    void start_jog(bool forward);
    // A home or jog asked for while the motor moves: ramp down first and start `next` when the
    // stop is done (true); false when nothing moves (a settling move counts as done).
    bool stop_first(After next) {
        if (phase_ == Phase::Settling) phase_ = Phase::Idle;
        if (phase_ == Phase::Idle) return false;
        halt(move_accel());
        backlash_pending_ = false;
        after_ = next;
        phase_ = Phase::Stopping;
        dmov = 0;
        return true;
    }
    double jog_velocity() const { return jvel * dirs() * (jog_fwd_ ? 1 : -1); }
    void stop_all();
    void pause();
    void load_pos();
    void do_work();
    void resync();
    void publish();
    void run(bool work);
};

std::vector<FieldDesc> MotorRecordImpl::fields() {
    using R = MotorRecordImpl;
    auto v = common_fields();
    for (auto& f : v) {
        if (std::strcmp(f.name, "DTYP") == 0) f.menu = &kMenuMotorDtyp;
        if (std::strcmp(f.name, "SCAN") == 0)
            f.addr = [](Record& r) -> void* { return &static_cast<R&>(r).scan_field; };
    }
    constexpr uint16_t kDrive = kProcess | kAsl0;
    constexpr uint16_t kLimit = kProcess | kProp;
    auto add = {
        BEAMCTL_FIELD(R, VAL, val, Double, kDrive),
        BEAMCTL_FIELD(R, DVAL, dval, Double, kDrive),
        BEAMCTL_FIELD(R, RVAL, rval, Long, kDrive),
        BEAMCTL_FIELD(R, RLV, rlv, Double, kDrive),
        BEAMCTL_FIELD(R, RBV, rbv, Double, kReadOnly),
        BEAMCTL_FIELD(R, DRBV, drbv, Double, kReadOnly),
        BEAMCTL_FIELD(R, RRBV, rrbv, Long, kReadOnly),
        BEAMCTL_FIELD(R, DIFF, diff, Double, kReadOnly),
        BEAMCTL_FIELD(R, RDIF, rdif, Long, kReadOnly),
        BEAMCTL_FIELD(R, RMP, rmp, Long, kReadOnly),
        BEAMCTL_FIELD(R, REP, rep, Long, kReadOnly),
        BEAMCTL_FIELD(R, MSTA, msta, ULong, kReadOnly),
        BEAMCTL_FIELD(R, OFF, off, Double, kProcess | kAsl0),
        BEAMCTL_MENU(R, DIR, dir, kMenuMotorDir, kProcess),
        BEAMCTL_MENU(R, FOFF, foff, kMenuMotorFoff, kAsl0),
        BEAMCTL_MENU(R, SET, set, kMenuMotorSet, kAsl0),
        BEAMCTL_FIELD(R, IGSET, igset, Short, 0),
        BEAMCTL_FIELD(R, MRES, mres, Double, kProcess | kProp),
        BEAMCTL_FIELD(R, ERES, eres, Double, kProcess),
        BEAMCTL_FIELD(R, RRES, rres, Double, 0),
        BEAMCTL_FIELD(R, SREV, srev, Long, kProcess | kProp),
        BEAMCTL_FIELD(R, UREV, urev, Double, kProcess | kProp),
        BEAMCTL_MENU(R, UEIP, ueip, kMenuMotorUeip, kProcess),
        BEAMCTL_MENU(R, URIP, urip, kMenuMotorUeip, kProcess),
        BEAMCTL_FIELD(R, PREC, prec, Short, kProp),
        BEAMCTL_FIELD(R, EGU, egu, String, kProp),
        BEAMCTL_FIELD(R, VELO, velo, Double, 0),
        BEAMCTL_FIELD(R, VBAS, vbas, Double, kProp),
        BEAMCTL_FIELD(R, VMAX, vmax, Double, kProp),
        BEAMCTL_FIELD(R, ACCL, accl, Double, 0),
        BEAMCTL_FIELD(R, BDST, bdst, Double, kAsl0),
        BEAMCTL_FIELD(R, BVEL, bvel, Double, 0),
        BEAMCTL_FIELD(R, BACC, bacc, Double, 0),
        BEAMCTL_FIELD(R, HVEL, hvel, Double, 0),
        BEAMCTL_FIELD(R, JVEL, jvel, Double, 0),
        BEAMCTL_FIELD(R, JAR, jar, Double, 0),
        BEAMCTL_FIELD(R, HLM, hlm, Double, kLimit),
        BEAMCTL_FIELD(R, LLM, llm, Double, kLimit),
        BEAMCTL_FIELD(R, DHLM, dhlm, Double, kLimit),
        BEAMCTL_FIELD(R, DLLM, dllm, Double, kLimit),
        BEAMCTL_FIELD(R, HLS, hls, Short, kReadOnly),
        BEAMCTL_FIELD(R, LLS, lls, Short, kReadOnly),
        BEAMCTL_FIELD(R, RHLS, rhls, Short, kReadOnly),
        BEAMCTL_FIELD(R, RLLS, rlls, Short, kReadOnly),
        BEAMCTL_MENU(R, HLSV, hlsv, kMenuAlarmSevr, kProcess),
        BEAMCTL_FIELD(R, LVIO, lvio, Short, kReadOnly),
        BEAMCTL_FIELD(R, MOVN, movn, Short, kReadOnly),
        BEAMCTL_FIELD(R, TDIR, tdir, Short, kReadOnly),
        BEAMCTL_FIELD(R, CDIR, cdir, Short, kReadOnly),
        BEAMCTL_FIELD(R, ATHM, athm, Short, kReadOnly),
        BEAMCTL_FIELD(R, MISS, miss, Short, kReadOnly),
        BEAMCTL_FIELD(R, RCNT, rcnt, Short, kReadOnly),
        BEAMCTL_FIELD(R, RTRY, rtry, Short, 0),
        BEAMCTL_FIELD(R, RDBD, rdbd, Double, 0),
        BEAMCTL_FIELD(R, SPDB, spdb, Double, 0),
        BEAMCTL_FIELD(R, DLY, dly, Double, 0),
        BEAMCTL_FIELD(R, STOP, stop, Short, kProcess | kAsl0),
        BEAMCTL_MENU(R, SPMG, spmg, kMenuMotorSpmg, kProcess | kAsl0),
        BEAMCTL_MENU(R, LSPG, lspg, kMenuMotorSpmg, kReadOnly),
        BEAMCTL_FIELD(R, HOMF, homf, Short, kProcess),
        BEAMCTL_FIELD(R, HOMR, homr, Short, kProcess),
        BEAMCTL_FIELD(R, JOGF, jogf, Short, kProcess | kAsl0),
        BEAMCTL_FIELD(R, JOGR, jogr, Short, kProcess | kAsl0),
        BEAMCTL_FIELD(R, TWF, twf, Short, kProcess | kAsl0),
        BEAMCTL_FIELD(R, TWR, twr, Short, kProcess | kAsl0),
        BEAMCTL_FIELD(R, TWV, twv, Double, kAsl0),
        BEAMCTL_MENU(R, CNEN, cnen, kMenuMotorTorq, kProcess | kAsl0),
        BEAMCTL_FIELD(R, MIP, mip, UShort, kReadOnly),
        BEAMCTL_FIELD(R, LVAL, lval, Double, kReadOnly),
        BEAMCTL_FIELD(R, LDVL, ldvl, Double, kReadOnly),
        BEAMCTL_FIELD(R, LRVL, lrvl, Long, kReadOnly),
        BEAMCTL_MENU(R, RSTM, rstm, kMenuMotorRstm, 0),
        BEAMCTL_FIELD(R, OUT, out_text, String, kInitOnly),
        BEAMCTL_FIELD(R, S, s, Double, 0),
        BEAMCTL_FIELD(R, SBAS, sbas, Double, kProp),
        BEAMCTL_FIELD(R, SMAX, smax, Double, kProp),
        BEAMCTL_FIELD(R, SBAK, sbak, Double, 0),
        BEAMCTL_FIELD(R, ACCS, accs, Double, 0),
        BEAMCTL_MENU(R, ACCU, accu, kMenuMotorAccu, 0),
        BEAMCTL_FIELD(R, FRAC, frac, Float, 0),
        BEAMCTL_MENU(R, RMOD, rmod, kMenuMotorRmod, 0),
        BEAMCTL_MENU(R, NTM, ntm, kMenuYesNo, 0),
        BEAMCTL_FIELD(R, NTMF, ntmf, UShort, 0),
        BEAMCTL_FIELD(R, HIHI, hihi, Double, kProcess | kProp),
        BEAMCTL_FIELD(R, LOLO, lolo, Double, kProcess | kProp),
        BEAMCTL_FIELD(R, HIGH, high, Double, kProcess | kProp),
        BEAMCTL_FIELD(R, LOW, low, Double, kProcess | kProp),
        BEAMCTL_MENU(R, HHSV, hhsv, kMenuAlarmSevr, kProcess | kProp),
        BEAMCTL_MENU(R, LLSV, llsv, kMenuAlarmSevr, kProcess | kProp),
        BEAMCTL_MENU(R, HSV, hsv, kMenuAlarmSevr, kProcess | kProp),
        BEAMCTL_MENU(R, LSV, lsv, kMenuAlarmSevr, kProcess | kProp),
        BEAMCTL_FIELD(R, HOPR, hopr, Double, kProp),
        BEAMCTL_FIELD(R, LOPR, lopr, Double, kProp),
        BEAMCTL_FIELD(R, MDEL, mdel, Double, 0),
        BEAMCTL_FIELD(R, ADEL, adel, Double, 0),
        BEAMCTL_MENU(R, STUP, stup, kMenuMotorStup, kAsl0),
        BEAMCTL_FIELD(R, SYNC, sync_field, Short, kAsl0),
        BEAMCTL_FIELD(R, PCOF, pcof, Double, 0),
        BEAMCTL_FIELD(R, ICOF, icof, Double, 0),
        BEAMCTL_FIELD(R, DCOF, dcof, Double, 0),
        BEAMCTL_MENU(R, OMSL, omsl, kMenuOmsl, 0),
        BEAMCTL_FIELD(R, DOL, dol, InLink, 0),
        BEAMCTL_FIELD(R, RDBL, rdbl, InLink, 0),
        BEAMCTL_FIELD(R, RLNK, rlnk, OutLink, 0),
        BEAMCTL_FIELD(R, INIT, init_text, String, 0),
        BEAMCTL_FIELD(R, PREM, prem, String, 0),
        BEAMCTL_FIELD(R, POST, post_text, String, 0),
        BEAMCTL_FIELD(R, FOF, fof, Short, kAsl0),
        BEAMCTL_FIELD(R, VOF, vof, Short, kAsl0),
        BEAMCTL_FIELD(R, SSET, sset, Short, kAsl0),
        BEAMCTL_FIELD(R, SUSE, suse, Short, kAsl0),
        BEAMCTL_FIELD(R, RHLM, rhlm, Double, kReadOnly),
        BEAMCTL_FIELD(R, RLLM, rllm, Double, kReadOnly),
        BEAMCTL_FIELD(R, CARD, card, Short, kReadOnly),
        BEAMCTL_FIELD(R, LRLV, lrlv, Double, kReadOnly),
        BEAMCTL_FIELD(R, RVEL, rvel, Long, kReadOnly),
        BEAMCTL_FIELD(R, PP, pp_field, Short, kReadOnly),
        BEAMCTL_FIELD(R, MMAP, mmap, ULong, kReadOnly),
        BEAMCTL_FIELD(R, NMAP, nmap, ULong, kReadOnly),
        BEAMCTL_FIELD(R, ALST, alst, Double, kReadOnly),
        BEAMCTL_FIELD(R, MLST, mlst, Double, kReadOnly),
        BEAMCTL_FIELD(R, STOO, stoo, OutLink, 0),
        BEAMCTL_FIELD(R, DINP, dinp, InLink, 0),
        BEAMCTL_FIELD(R, RINP, rinp, InLink, 0),
        BEAMCTL_MENU(R, LOCK, lock, kMenuYesNo, 0),
        BEAMCTL_FIELD(R, SPAM, spam, Short, 0),
        BEAMCTL_MENU(R, MISV, misv, kMenuAlarmSevr, kProcess),
        BEAMCTL_FIELD(R, MFLG, mflg, ULong, kReadOnly),
        BEAMCTL_FIELD(R, MINP, minp, InLink, 0),
        BEAMCTL_FIELD(R, VERS, vers, Float, kReadOnly),
        BEAMCTL_FIELD(R, DMOV, dmov, Short, kReadOnly), // last: posted after all others
    };
    v.insert(v.end(), add.begin(), add.end());
    return v;
}

void MotorRecordImpl::init() {
    if (scan_field == 1 || scan_field == 2)
        throw Error(SB() << "SCAN \"" << kMenuScan.choices[scan_field]
                         << "\" is not supported for soft records (use Passive or a period)");
    // Reconcile speed and resolution (check_speed_and_resolution).
    if (srev <= 0) srev = 200;
    if (urev != 0) mres = urev / srev;
    if (mres == 0 || !std::isfinite(mres)) mres = 1;
    urev = mres * srev;
    if (vmax < 0) vmax = 0;
    range_check(vbas, 0, vmax);
    range_check(velo, vbas, vmax);
    range_check(bvel, vbas, vmax);
    if (!(accl > 0)) accl = 0.1;
    if (!(bacc > 0)) bacc = 0.1;
    if (jvel == 0)
        jvel = velo;
    else
        range_check(jvel, vbas, vmax);
    if (!(jar > 0)) jar = velo / accl;
    if (hvel == 0)
        hvel = vbas;
    else
        range_check(hvel, vbas, vmax);
    if (eres == 0) eres = mres;
    rdbd = std::max(rdbd, std::fabs(mres));
    if (urip && !rdbl.is_db()) {
        LOG_WARN(lg, "motor " << name() << ": URIP=Yes without an RDBL link; using No");
        urip = 0;
    }
    if (rres == 0) rres = 1;
    frac = std::clamp(frac > 0 ? frac : 1.0f, 0.1f, 1.5f);
    derived_speeds();
    spmg = lspg = kSpmgGo;
    udf = 0;
    if (!driver_) {
        if (dtyp != 0)
            LOG_WARN(lg, "motor " << name() << ": DTYP " << kMenuMotorDtyp.choices[dtyp]
                                  << " but no driver attached at init; using a simulated motor");
        driver_ = make_sim();
    }
    // Restore the saved dial position (autosave) into the controller, per RSTM.
    MotorDriver::Status s = driver_->status();
    bool near_zero = std::fabs(s.position) < rdbd && std::fabs(dval) > rdbd;
    bool use_rel = rtry != 0 && ueip;
    if (rstm == kRstmAlways || (rstm == kRstmNearZero && near_zero) ||
        (rstm == kRstmConditional && (near_zero || use_rel)))
        driver_->set_position(dval);
    resync();
    valid_seen_ = s.valid;
    initialised_ = true;
    scan = 0;  // Passive for the database (puts and links process it); polled by poll_tick()
    publish(); // alarms to NO_ALARM; nobody subscribes yet
}

// Forgets any motion: targets := readback, DMOV=1, LVIO from the position (init_record).
void MotorRecordImpl::resync() {
    refresh();
    sync_targets();
    set_userlimits();
    lvio = limits_on() &&
           (drbv > dhlm + std::fabs(mres) || drbv < dllm - std::fabs(mres) || dllm > dhlm);
    phase_ = Phase::Idle;
    after_ = After::None;
    backlash_pending_ = retrying_ = jog_req_ = pending_target_ = false;
    movn = 0;
    dmov = 1;
}

// Reads the driver status into the readback fields (process_motor_info).
void MotorRecordImpl::refresh() {
    const MotorDriver::Status s = driver_->status();
    st_ = s;
    rmp = nint(s.position / mres);
    rep = s.has_encoder ? nint(s.encoder / eres) : 0;
    if (ueip && !s.has_encoder) ueip = 0;
    double linked = 0;
    if (urip && rdbl.is_db() && read_link(rdbl, linked)) { // URIP: the readback link, RRES per unit
        drbv = linked * rres;
        rrbv = nint(drbv / mres);
    } else if (ueip) {
        rrbv = rep;
        drbv = rrbv * eres;
    } else {
        rrbv = rmp;
        drbv = rrbv * mres;
    }
    rbv = drbv * dirs() + off;
    bool neg = mres < 0;
    rhls = neg ? s.low_limit : s.high_limit; // raw + switch
    rlls = neg ? s.high_limit : s.low_limit;
    bool same = (dir == 0) == !neg; // user + is raw +
    hls = same ? rhls : rlls;
    lls = same ? rlls : rhls;
    tdir = s.direction_positive != neg;
    bool ls_active = (rhls && cdir) || (rlls && !cdir);
    movn = !(ls_active || s.done || s.problem);
    athm = s.home_switch;
    cnen = s.enabled;
    uint32_t m = kMstaGainSupport; // CNEN acts on the driver
    if (tdir) m |= kMstaDirection;
    if (s.done) m |= kMstaDone;
    if (rhls) m |= kMstaPlusLs;
    if (s.home_switch) m |= kMstaHome;
    if (s.enabled) m |= kMstaPosition;
    if (s.slip_stall) m |= kMstaSlipStall;
    if (s.has_encoder && s.home_switch) m |= kMstaEncHome;
    if (s.has_encoder) m |= kMstaEncPresent;
    if (s.problem) m |= kMstaProblem;
    if (s.moving) m |= kMstaMoving;
    if (s.comm_error) m |= kMstaCommErr;
    if (rlls) m |= kMstaMinusLs;
    if (s.homed) m |= kMstaHomed;
    msta = m;
}

// Advances the motion from the status just read.
void MotorRecordImpl::track(double now) {
    switch (phase_) {
    case Phase::Idle:
        if (dmov && movn) { // someone else moves the axis: DMOV follows it
            phase_ = Phase::External;
            dmov = 0;
        }
        return;
    case Phase::Settling:
        if (now >= settle_until_) after_settle(then_);
        return;
    case Phase::Homing:
        lvio = 0;
        break;
    case Phase::Jogging:
        if (limits_on()) {
            lvio = (jogf && rbv > hlm - jvel) || (jogr && rbv < llm + jvel) || dllm > dhlm;
            if (lvio && !set_mode()) { // about to cross a soft limit: stop the jog
                clear_buttons();
                jog_req_ = false;
                halt(jar);
                phase_ = Phase::Stopping;
                after_ = After::None;
                return;
            }
        }
        break;
    default:
        break;
    }
    if (st_.done || st_.problem) on_stopped(now);
}

void MotorRecordImpl::on_stopped(double now) {
    ls_hit_ = (rhls && cdir) || (rlls && !cdir);
    if (st_.failed || ((phase_ == Phase::Moving || phase_ == Phase::Backlash) && (ls_hit_ || st_.problem))) failed_ = true;
    if (st_.failed && st_.limit_violation) lvio = 1; // the controller refused it for a soft limit
    switch (phase_) {
    case Phase::Moving:
    case Phase::Backlash:
        if (ls_hit_ || st_.problem) { // hard limit or fault: targets := readback, no retries
            sync_targets();
            finish();
            return;
        }
        if (phase_ == Phase::Moving && backlash_pending_) {
            backlash_pending_ = false;
            cdir = nint((dval - drbv) / mres) >= 0;
            drive(final_approach(dval - bdst), bvel, accel_for(bvel, bacc, vbas));
            phase_ = Phase::Backlash;
            return;
        }
        settle(Then::RetryCheck, now);
        return;
    case Phase::Homing:
        homf = homr = 0;
        if (pending_target_) {
            pending_target_ = false;
            phase_ = Phase::Idle;
            start_move(false);
            return;
        }
        sync_targets();
        settle(Then::Finish, now);
        return;
    case Phase::Jogging: // stopped by itself (switch, fault)
        jogf = jogr = 0;
        jog_req_ = false;
        sync_targets();
        settle(Then::Finish, now);
        return;
    case Phase::JogStopping:
        sync_targets();
        if (std::fabs(bdst) >= std::fabs(mres)) { // approach the stop position from -BDST
            cdir = nint(-bdst / mres) >= 0;
            drive(dval - bdst, velo, move_accel());
            backlash_pending_ = true;
            retrying_ = false;
            phase_ = Phase::Moving;
            return;
        }
        settle(Then::Finish, now);
        return;
    case Phase::Stopping: {
        sync_targets();
        After next = after_;
        after_ = After::None;
        phase_ = Phase::Idle;
        if (next == After::HomeF || next == After::HomeR) return start_home(next == After::HomeF);
        if (next == After::JogF || next == After::JogR) return start_jog(next == After::JogF);
        settle(Then::Finish, now);
        return;
    }
    case Phase::Pausing:
        phase_ = Phase::Idle;
        return; // DMOV stays 0 until Go/Move
    case Phase::External:
        if (pending_target_) {
            pending_target_ = false;
            phase_ = Phase::Idle;
            start_move(false);
            return;
        }
        sync_targets();
        settle(Then::Finish, now);
        return;
    default:
        return;
    }
}

void MotorRecordImpl::settle(Then then, double now) {
    phase_ = Phase::Idle;
    if (dly > 0) {
        phase_ = Phase::Settling;
        then_ = then;
        settle_until_ = now + dly;
        return;
    }
    after_settle(then);
}

// After the motion and DLY: retry if not close enough (maybeRetry), else DMOV=1.
void MotorRecordImpl::after_settle(Then then) {
    phase_ = Phase::Idle;
    if (then == Then::Finish) return finish();
    if (std::fabs(dval - drbv) >= rdbd && !ls_hit_) {
        if (rtry <= 0 || rmod == kRmodInPosition) return finish(); // In-Position: the controller retries
        if (++rcnt > rtry) {
            miss = 1;
            return finish();
        }
        return start_move(true);
    }
    miss = 0;
    if (spmg == kSpmgMove) spmg = lspg = kSpmgPause;
    finish();
}

// Starts (or retargets) a move to DVAL: null moves, soft and hard limits, backlash.
void MotorRecordImpl::start_move(bool retry) {
    bool active = phase_ == Phase::Moving || phase_ == Phase::Backlash || phase_ == Phase::Pausing;
    if (phase_ == Phase::Settling) phase_ = Phase::Idle;
    val = dval * dirs() + off;
    rval = nint(dval / mres);
    int64_t steps = int64_t(nint(dval / mres)) - int64_t(nint(drbv / mres));
    if (!active) {
        bool small = retry ? std::llabs(steps) < nint(rdbd / std::fabs(mres))
                           : steps == 0 || (spdb > 0 && std::fabs(dval - drbv) < spdb);
        if (small) { // null move: DMOV back to 1, nothing moves
            remember_targets();
            finish();
            return;
        }
    }
    if (!retry) rcnt = 0;
    double prev = retry ? drbv : ldvl;
    bool preferred = (dval > prev) == (bdst > 0);
    // Soft limits.
    bool lv;
    if (!limits_on())
        lv = false;
    else if (dllm > dhlm)
        lv = true;
    else if ((dval > dhlm && dval < ldvl) || (dval < dllm && dval > ldvl))
        lv = false; // back in
    else {
        double p = preferred ? dval : dval - bdst;
        lv = p > dhlm || p < dllm;
    }
    lvio = lv;
    lvio_refused_ = lv;
    if (lv) {
        failed_ = true;
        restore_targets();
        if (!active) finish();
        return;
    }
    // Hard limits: no move further into an active switch.
    bool up = nint((dval - drbv) / mres) >= 0; // raw direction
    if ((up && rhls) || (!up && rlls)) {
        failed_ = true;
        if (active) {
            restore_targets();
        } else {
            sync_targets();
            finish();
        }
        return;
    }
    cdir = up;
    remember_targets();
    double a = move_accel(), ab = accel_for(bvel, bacc, vbas);
    bool need_backlash =
        std::fabs(bdst) >= std::fabs(mres) && !(preferred && bvel == velo && bacc == accl);
    backlash_pending_ = false;
    if (!need_backlash) {
        drive(retry ? drbv + retry_fraction() * (dval - drbv) : dval, velo, a);
    } else if (preferred && std::fabs(dval - prev) <= std::fabs(bdst) + std::fabs(mres)) {
        drive(final_approach(retry ? drbv : prev), bvel, ab); // within the backlash distance: approach slowly
    } else {
        drive(dval - bdst, velo, a);
        backlash_pending_ = true;
    }
    phase_ = Phase::Moving;
    retrying_ = retry;
    dmov = 0;
}

void MotorRecordImpl::start_home(bool forward) {
    double v = hvel > 0 ? hvel : velo;
    driver_->home(forward, v, accel_for(v, accl, vbas));
    home_fwd_ = forward;
    lvio_refused_ = false;
    phase_ = Phase::Homing;
    dmov = 0;
    rcnt = 0;
    lvio = 0;
    cdir = forward != (mres < 0);
}

void MotorRecordImpl::start_jog(bool forward) {
    jog_fwd_ = forward;
    lvio_refused_ = false;
    double v = jog_velocity();
    driver_->move_velocity(v, jar);
    phase_ = Phase::Jogging;
    dmov = 0;
    cdir = (v > 0) != (mres < 0);
}

// STOP, or SPMG to Stop: stop; targets := readback when stopped.
void MotorRecordImpl::stop_all() {
    jog_req_ = pending_target_ = false;
    after_ = After::None;
    clear_buttons();
    switch (phase_) {
    case Phase::Idle:
        halt(move_accel()); // just in case
        if (!dmov) {        // a target waiting for Go is cancelled
            sync_targets();
            dmov = 1;
        }
        break;
    case Phase::Settling:
        sync_targets();
        then_ = Then::Finish;
        break;
    default:
        halt(phase_ == Phase::Jogging ? jar : move_accel());
        backlash_pending_ = retrying_ = false;
        phase_ = Phase::Stopping;
        break;
    }
}

// SPMG to Pause: a positioning move stops and resumes on Go/Move; anything else stops.
void MotorRecordImpl::pause() {
    switch (phase_) {
    case Phase::Moving:
    case Phase::Backlash:
        halt(move_accel());
        backlash_pending_ = false;
        phase_ = Phase::Pausing;
        break;
    case Phase::Homing:
    case Phase::Jogging:
    case Phase::JogStopping:
    case Phase::External:
        stop_all();
        break;
    default:
        break;
    }
}

// SET=Set with a new dial target: redefine the position, no motion (load_pos).
void MotorRecordImpl::load_pos() {
    rval = nint(dval / mres);
    if (foff) {
        val = off + dval * dirs();
    } else {
        off = val - dval * dirs();
        set_userlimits();
    }
    remember_targets();
    driver_->set_position(dval);
    refresh();
    finish();
}

// Acts on what a client wrote (do_work in motorRecord.cc).
void MotorRecordImpl::do_work() {
    // Stop/Pause/Move/Go and STOP.
    if (spmg != lspg || stop) {
        bool pressed = stop != 0;
        lspg = spmg;
        stop = 0;
        if (pressed || spmg == kSpmgStop) return stop_all();
        if (spmg == kSpmgPause) return pause();
        if (spmg == kSpmgMove) rcnt = 0;
        if (phase_ == Phase::Idle && ((jogf && !hls) || (jogr && !lls))) jog_req_ = true;
    }
    bool held = spmg == kSpmgStop || spmg == kSpmgPause;

    // Home.
    bool homing_next =
        phase_ == Phase::Stopping && (after_ == After::HomeF || after_ == After::HomeR);
    if ((homf || homr) && phase_ != Phase::Homing && !homing_next) {
        bool fwd = homf != 0;
        if (fwd ? st_.high_limit : st_.low_limit) { // already on the switch: refused
            homf = homr = 0;
            if (dmov) { // a DMOV pulse so that ophyd's home() completes
                dmov = 0;
                post_now(fd_dmov_);
                dmov = 1;
            }
            return;
        }
        if (held) {
            dmov = 0; // starts on Go
            return;
        }
        if (stop_first(fwd ? After::HomeF : After::HomeR)) return;
        return start_home(fwd);
    }

    // Jog.
    if (jog_req_ && phase_ != Phase::Jogging && !held) {
        jog_req_ = false;
        if (jogf || jogr) {
            bool fwd = jogf != 0;
            if (limits_on() &&
                ((fwd && val > hlm - jvel) || (!fwd && val < llm + jvel) || dllm > dhlm)) {
                lvio = 1;
                jogf = jogr = 0;
                return;
            }
            if (stop_first(fwd ? After::JogF : After::JogR)) return;
            return start_jog(fwd);
        }
    }
    if (phase_ == Phase::Jogging && !jogf && !jogr) {
        halt(jar);
        phase_ = Phase::JogStopping;
        return;
    }
    if (phase_ == Phase::JogStopping) return;

    // Relative, raw and user targets.
    if (twf || twr) {
        val += twv * (twf ? 1 : -1);
        twf = twr = 0;
    }
    if (rlv != 0) {
        val += rlv;
        rlv = 0;
    }
    if (rval != lrvl) dval = rval * mres;
    if (val != lval) {
        if (set_mode() && foff == 0) { // calibrate the user position: OFF moves, nothing else
            off = val - dval * dirs();
            rbv = drbv * dirs() + off;
            set_userlimits();
            lval = val;
            if (phase_ == Phase::Idle) finish();
            return;
        }
        dval = (val - off) * dirs();
    }
    if (held) return; // the target waits for Go/Move (DMOV stays 0)

    bool waiting = phase_ == Phase::Idle && !dmov;
    if (dval != ldvl || waiting || phase_ == Phase::Pausing) {
        if (set_mode()) return load_pos();
        switch (phase_) {
        case Phase::Homing:
        case Phase::External: // moves once the present motion ends
            pending_target_ = true;
            val = dval * dirs() + off;
            rval = nint(dval / mres);
            return;
        case Phase::Stopping:
            return; // the stop wins
        default:
            return start_move(false);
        }
    }
}

// Alarms, monitors (changed fields, DMOV last), ctrl-limit property events.
void MotorRecordImpl::publish() {
    diff = dval - drbv;
    rdif = nint(diff / mres);
    uint16_t m = 0;
    switch (phase_) {
    case Phase::Moving:
        m = retrying_ ? kMipRetry : kMipMove;
        break;
    case Phase::Backlash:
        m = kMipMoveBl;
        break;
    case Phase::Homing:
        m = home_fwd_ ? kMipHomF : kMipHomR;
        break;
    case Phase::Jogging:
        m = jog_fwd_ ? kMipJogF : kMipJogR;
        break;
    case Phase::JogStopping:
        m = kMipJogStop;
        break;
    case Phase::Stopping:
    case Phase::Pausing:
        m = kMipStop;
        break;
    case Phase::External:
        m = kMipExternal;
        break;
    case Phase::Settling:
        m = kMipDelayReq;
        break;
    case Phase::Idle:
        break;
    }
    mip = m;

    // alarm_sub
    if (udf) {
        set_sevr(kStatUdf, kInvalid);
    } else if (hlsv && (hls || (limits_on() && dval > dhlm))) {
        set_sevr(kStatHigh, hlsv);
    } else if (hlsv && (lls || (limits_on() && dval < dllm))) {
        set_sevr(kStatLow, hlsv);
    } else {
        if (st_.comm_error) set_sevr(kStatComm, kInvalid);
        if (st_.slip_stall || st_.problem) set_sevr(kStatState, kMajor);
        if (lvio_refused_) set_sevr(kStatSoft, kMinor); // a move refused for a soft limit
        // HIHI/HIGH/LOW/LOLO on the readback, with their severities (none by default)
        if (hhsv && rbv >= hihi) set_sevr(kStatHihi, hhsv);
        else if (llsv && rbv <= lolo) set_sevr(kStatLolo, llsv);
        else if (hsv && rbv >= high) set_sevr(kStatHigh, hsv);
        else if (lsv && rbv <= low) set_sevr(kStatLow, lsv);
    }
    stamp_time();
    unsigned alarm = reset_alarms();

    bool prop = false;
    const auto& fs = type().fields();
    auto emit = [&](const FieldDesc& f) {
        unsigned mask = alarm;
        if (changed(f)) {
            sync(f);
            mask |= kDbeValue | kDbeLog;
            if (f.flags & kProp) prop = true;
        }
        if (mask) post(&f, mask);
    };
    for (std::size_t i = first_; i < fs.size(); ++i)
        if (&fs[i] != fd_dmov_) emit(fs[i]);
    emit(*fd_dmov_);
    if (prop) post(static_cast<const FieldDesc*>(nullptr), kDbeProperty);
}

void MotorRecordImpl::run(bool work) {
    bool was_done = dmov != 0;
    pact = 1;
    refresh();
    if (mres != 0) { // RHLM/RLLM: the dial limits in steps (swapped for a negative MRES)
        rhlm = (mres > 0 ? dhlm : dllm) / mres;
        rllm = (mres > 0 ? dllm : dhlm) / mres;
    }
    // the controller's requests (ECMC's SYNC / STOP from PLC code), counted since the first look
    if (!initialised_) {
        sync_seen_ = st_.sync_requests;
        stop_seen_ = st_.stop_requests;
    }
    if (st_.stop_requests != stop_seen_) {
        stop_seen_ = st_.stop_requests;
        stop = 1;
        work = true;
    }
    if (st_.sync_requests != sync_seen_) {
        sync_seen_ = st_.sync_requests;
        if (phase_ == Phase::Idle && dmov) resync();
    }
    if (st_.valid && !valid_seen_) { // the first real readback: the targets start there
        valid_seen_ = true;
        if (phase_ == Phase::Idle && dmov) resync();
    }
    track(clock_());
    if (work) do_work();
    if (rlnk.is_db()) (void)write_link(rlnk, rbv); // the readback out (motorRecord: every processing)
    publish();
    // the forward link when a motion ends, or a processing (a put, PROC) ends with nothing to move
    if (dmov && (!was_done || processing_)) fwd_link(flnk);
    pact = 0;
    // completes a put-callback waiting for the end of the motion, failed if the motion was
    // refused or ended short
    if (dmov) {
        async_done(failed_ ? PutStatus::Failed : PutStatus::Ok);
        failed_ = false; // reported; later put-callbacks (VELO, ...) are not about that motion
    }
}

PutStatus MotorRecordImpl::special(const FieldDesc& f) {
    if (!initialised_ || std::size_t(f.index) < first_) return PutStatus::Ok;
    std::string_view n = f.name;
    if (f.dbf == Dbf::Double && !std::isfinite(*static_cast<double*>(f.addr(*this))))
        return PutStatus::BadValue;
    // Refusals first: a refused put changes nothing.
    if ((n == "MRES" && mres == 0) || (n == "UREV" && urev == 0)) return PutStatus::BadValue;
    if ((n == "HOMF" || n == "HOMR") && phase_ == Phase::Homing) return PutStatus::Failed;
    if (n == "URIP" && urip && !rdbl.is_db()) return PutStatus::Failed; // no readback link
    if ((n == "PCOF" || n == "ICOF" || n == "DCOF") &&
        !driver_->set_gain(n == "PCOF" ? 0 : n == "ICOF" ? 1 : 2, *static_cast<double*>(f.addr(*this))))
        return PutStatus::BadValue; // the driver refused the gain (ECMC: 0..0.99)
    if (n == "S" || n == "SBAS" || n == "SMAX" || n == "SBAK") {
        double u = std::fabs(urev);
        if (u == 0) return PutStatus::BadValue;
        if (n == "S") velo = s * u;
        else if (n == "SBAS") vbas = std::max(0.0, sbas * u);
        else if (n == "SMAX") vmax = std::max(0.0, smax * u);
        else bvel = sbak * u;
        if (n == "SBAS" && vmax != 0 && vbas > vmax) vmax = vbas;
        if (n == "SMAX" && vmax != 0 && vmax < vbas) vbas = vmax;
    }
    if (n == "ACCL") accu = 0;
    if (n == "ACCS") {
        if (!(accs > 0)) return PutStatus::BadValue;
        accu = 1;
    }
    if (n == "FRAC") frac = std::clamp(frac, 0.1f, 1.5f);
    if (n == "FOF" || n == "VOF") { // motorRecord's special: a put to either sets FOFF
        foff = n == "FOF" ? 1 : 0;
        fof = vof = 0;
        post("FOFF", kDbeValue | kDbeLog);
    }
    if (n == "SSET" || n == "SUSE") { // ... and SET
        set = n == "SSET" ? 1 : 0;
        sset = suse = 0;
        post("SET", kDbeValue | kDbeLog);
    }
    if (n == "SYNC" && sync_field) { // the targets take the readbacks (when nothing moves)
        sync_field = 0;
        if (phase_ == Phase::Idle && dmov) resync();
    }
    if (n == "STUP" && stup == 1) { // one status update now
        refresh();
        stup = 0;
    }
    if (n == "JOGF" && jogf && (phase_ != Phase::Idle || jogr || hls)) return PutStatus::Failed;
    if (n == "JOGR" && jogr && (phase_ != Phase::Idle || jogf || lls)) return PutStatus::Failed;

    if (n == "VAL" || n == "DVAL" || n == "RVAL" || n == "RLV" || n == "TWF" || n == "TWR") {
        failed_ = false;
        if (dmov) { // the 1->0 edge, posted before anything moves
            dmov = 0;
            post_now(fd_dmov_);
        }
    } else if (n == "JOGF" || n == "JOGR") {
        jog_req_ = (jogf || jogr) && phase_ == Phase::Idle;
    } else if (n == "VELO" || n == "BVEL" || n == "HVEL") {
        clamp_speeds();
    } else if (n == "VBAS") {
        if (vbas < 0) vbas = 0;
        if (vmax != 0 && vbas > vmax) vmax = vbas;
        clamp_speeds();
    } else if (n == "VMAX") {
        if (vmax < 0) vmax = 0;
        if (vmax != 0 && vmax < vbas) vbas = vmax;
        clamp_speeds();
    } else if (n == "JVEL" || n == "JAR") {
        clamp_speeds();
        if (!(jar > 0)) jar = jvel / 0.1;
        if (phase_ == Phase::Jogging) driver_->move_velocity(jog_velocity(), jar);
    } else if (n == "ACCL") {
        if (!(accl > 0)) accl = 0.1;
    } else if (n == "BACC") {
        if (!(bacc > 0)) bacc = 0.1;
    } else if (n == "RDBD" || n == "BDST") {
        rdbd = std::max(rdbd, std::fabs(mres));
    } else if (n == "MRES" || n == "UREV" || n == "SREV") {
        if (n == "SREV" && srev <= 0) srev = 200;
        if (n == "MRES")
            urev = mres * srev;
        else if (urev != 0)
            mres = urev / srev;
        else
            urev = mres * srev;
        if (eres == 0) eres = mres;
        rdbd = std::max(rdbd, std::fabs(mres));
        rval = lrvl = nint(dval / mres); // same dial target in new steps: not a new raw target
    } else if (n == "ERES") {
        if (eres == 0) eres = mres;
    } else if (n == "UEIP") {
        if (ueip && !st_.has_encoder) ueip = 0;
    } else if (n == "DIR") {
        if (foff) {
            val = dval * dirs() + off;
        } else {
            off = val - dval * dirs();
        }
        lval = ldvl * dirs() + off;
        rbv = drbv * dirs() + off;
        set_userlimits();
    } else if (n == "OFF") {
        val = dval * dirs() + off;
        lval = ldvl * dirs() + off;
        rbv = drbv * dirs() + off;
        set_userlimits();
    } else if (n == "HLM") {
        if (dir == 0)
            dhlm = hlm - off;
        else
            dllm = -hlm + off;
    } else if (n == "LLM") {
        if (dir == 0)
            dllm = llm - off;
        else
            dhlm = -llm + off;
    } else if (n == "DHLM") {
        if (dir == 0)
            hlm = dhlm + off;
        else
            llm = -dhlm + off;
    } else if (n == "DLLM") {
        if (dir == 0)
            llm = dllm + off;
        else
            hlm = -dllm + off;
    } else if (n == "CNEN") {
        driver_->set_closed_loop(cnen != 0);
    } else if (n == "S" || n == "SBAS" || n == "SMAX" || n == "SBAK") {
        clamp_speeds();
    }
    if (n == "HLM" || n == "LLM" || n == "DHLM" || n == "DLLM") driver_->set_soft_limits(dllm, dhlm); // one value both ways
    derived_speeds();
    if (&f != type().find("VAL")) sync(f); // the database posts the written field itself
    if (!(f.flags & kProcess)) {           // no processing follows: post what changed now
        const auto& fs = type().fields();
        bool prop = false;
        for (std::size_t i = first_; i < fs.size(); ++i)
            if (changed(fs[i])) {
                if (fs[i].flags & kProp) prop = true;
                post_now(&fs[i]);
            }
        if (prop) post(static_cast<const FieldDesc*>(nullptr), kDbeProperty);
    }
    return PutStatus::Ok;
}

void MotorRecordImpl::metadata(const FieldDesc& f, Metadata& md) const {
    Record::metadata(f, md);
    std::string_view n = f.name;
    std::string e(egu, strnlen(egu, sizeof egu));
    auto with = [&](char* buf, std::size_t size, const char* suffix) {
        copy_string(buf, size, e + suffix);
        return buf;
    };
    if (n == "VELO" || n == "VMAX" || n == "BVEL" || n == "VBAS" || n == "JVEL" || n == "HVEL")
        md.units = with(units_per_s_, sizeof units_per_s_, "/sec"); // get_units
    else if (n == "JAR")
        md.units = with(units_per_s2_, sizeof units_per_s2_, "/s/s");
    else if (n == "UREV")
        md.units = with(units_per_rev_, sizeof units_per_rev_, "/rev");
    else if (n == "ACCL" || n == "BACC")
        md.units = "sec";
    else if (n == "SREV")
        md.units = "steps/rev";
    else
        md.units = egu;
    auto limits = [&](double hi, double lo) {
        md.disp_hi = md.ctrl_hi = hi;
        md.disp_lo = md.ctrl_lo = lo;
    };
    if (n == "VAL" || n == "RBV")
        limits(hlm, llm);
    else if (n == "DVAL" || n == "DRBV")
        limits(dhlm, dllm);
    else if (n == "RVAL" || n == "RRBV") {
        if (mres >= 0)
            limits(dhlm / mres, dllm / mres);
        else
            limits(dllm / mres, dhlm / mres);
    } else if (n == "VELO")
        limits(vmax, vbas);
    else if (n == "S")
        limits(smax, sbas);
    if (n == "VAL" || n == "RBV") { // get_alarm_double: the alarm limits of the user values
        md.alarm_hihi = hihi;
        md.alarm_high = high;
        md.alarm_low = low;
        md.alarm_lolo = lolo;
    }
    if (n == "S" || n == "SBAS" || n == "SMAX" || n == "SBAK") md.units = "rev/sec";
    else if (n == "ACCS") md.units = with(units_per_s2_, sizeof units_per_s2_, "/s/s");
}

} // namespace

MotorRecord* MotorRecord::from(Record* r) {
    return dynamic_cast<MotorRecord*>(r);
}

void register_motor_record(RecordTypes& types) {
    types.add(
        std::make_unique<RecordType>("motor", MotorRecordImpl::fields(), [](const RecordType& t) {
            return std::unique_ptr<Record>(new MotorRecordImpl(t));
        }));
}

void attach_motor_drivers(
    Database& db, const std::function<std::shared_ptr<MotorDriver>(MotorRecord&)>& factory) {
    for (Record* r : db.records())
        if (MotorRecord* m = MotorRecord::from(r))
            if (auto d = factory(*m)) m->set_driver(std::move(d));
}

} // namespace beamctl::pv
