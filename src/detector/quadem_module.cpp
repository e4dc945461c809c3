#include "detector/quadem_module.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "module/pv_util.hpp"
#include "pv/db_file.hpp"

#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

namespace beamctl::detector {
using module::get_value;
using module::record;
using module::set_array;
using module::set_value;
using module::clamp_long;
namespace {

log::Logger lg("quadem");

std::string num(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

std::string lower(std::string s) {
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// quadEM.template's averaged-value records, in the order of the 11 values.
const char* const kAveNames[kQuadEmValues] = {"Current1Ave", "Current2Ave", "Current3Ave", "Current4Ave", "SumXAve", "SumYAve",
                                                        "SumAllAve",   "DiffXAve",    "DiffYAve",    "PositionXAve", "PositionYAve"};
const char* const kStats[4] = {"MeanValue_RBV", "SigmaValue_RBV", "MinValue_RBV", "MaxValue_RBV"};

enum Mode { kContinuous = 0, kMultiple = 1, kSingle = 2 };

} // namespace

struct QuadEmModule::Unit {
    config::QuadEmEntry cfg;
    std::string p; // $(P)<name>:
    std::unique_ptr<QuadEm> qe;
    module::ValueSource in[4];
    registry::BoundSignal ok[4]; // the inputs' buses' masterstatus (unbound: always good)
    // records
    pv::Record *acquire = nullptr, *mode = nullptr, *mode_rbv = nullptr, *num_acquire = nullptr, *num_acquire_rbv = nullptr,
               *num_acquired = nullptr, *avg_time = nullptr, *avg_time_rbv = nullptr, *num_average = nullptr, *num_averaged = nullptr,
               *sample_time = nullptr, *geometry = nullptr, *geometry_rbv = nullptr, *overflows = nullptr, *range = nullptr,
               *range_rbv = nullptr;
    pv::Record *cur_offset[4] = {}, *cur_scale[4] = {}, *pos_offset[2] = {}, *pos_scale[2] = {};
    pv::Record* ave[kQuadEmValues] = {};
    pv::Record* stats[kQuadEmValues][4] = {};
    bool acquiring = false;
    int acquired = 0;
    uint64_t seen_dropped = 0;
    // the time series (TS:): records, then the points so far
    pv::Record *ts_acquire = nullptr, *ts_acquiring = nullptr, *ts_read = nullptr, *ts_num_points = nullptr, *ts_current = nullptr,
               *ts_time_per_point = nullptr, *ts_time_per_point_rbv = nullptr, *ts_avg_time = nullptr, *ts_avg_time_rbv = nullptr,
               *ts_num_average = nullptr, *ts_elapsed = nullptr, *ts_mode = nullptr, *ts_mode_rbv = nullptr, *ts_timestamp = nullptr,
               *ts_time_axis = nullptr;
    pv::Record* ts_series[kQuadEmValues] = {};
    bool ts_on = false, ts_dirty = false;
    bool ts_circular = false;
    int ts_points = 1, ts_avg = 1;  // as started
    long ts_n = 0;                  // points taken (beyond ts_points in a circular buffer)
    int ts_acc_n = 0;
    double ts_acc[kQuadEmValues] = {};
    std::vector<double> ts_data[kQuadEmValues];
    double ts_t0 = 0, ts_last_read = 0;
};

// The Triggers stage's quadEM part: every electrometer takes one sample of its four currents.
class QuadEmModule::Stage : public rt::Stage {
public:
    explicit Stage(QuadEmModule& q) : q_(q) {}
    const char* name() const noexcept override { return "quadem"; }
    void run(const rt::CycleInfo& c) noexcept override {
        for (auto& up : q_.units_) {
            Unit& u = *up;
            double raw[4];
            bool valid = true;
            for (int i = 0; i < 4; ++i) {
                raw[i] = u.in[i].read(c.t_ns);
                if (u.ok[i].bound() && u.ok[i].get() == 0) valid = false;
            }
            u.qe->sample(raw, valid, c.cycle);
        }
    }

private:
    QuadEmModule& q_;
};

QuadEmModule::QuadEmModule(std::vector<config::QuadEmEntry> section, module::BuildContext& ctx) : reg_(ctx.signals), db_(ctx.db) {
    pv::DbFile f;
    for (const config::QuadEmEntry& e : section) {
        for (std::size_t i = 0; i < e.currents.size(); ++i) { // each exists (bind() then resolves them in the cycle)
            int bit = -1;
            if (e.currents[i] != "time" && !reg_.find_with_bit(e.currents[i], bit))
                throw Error(SB() << e.currents_where << ": quadem " << e.name << " current " << (i + 1) << ": no signal '" << e.currents[i]
                                 << "' in this IOC (`beamctl signals` lists them)");
        }
        auto u = std::make_unique<Unit>();
        u->cfg = e;
        u->p = ctx.prefix + e.name + ":";
        QuadEmParams prm;
        for (int i = 0; i < 4; ++i) prm.current_scale[i] = e.current_scale[i], prm.current_offset[i] = e.current_offset[i];
        for (int i = 0; i < 2; ++i) prm.position_scale[i] = e.position_scale[i], prm.position_offset[i] = e.position_offset[i];
        prm.geometry = e.geometry == "Diamond" ? QuadEmGeometry::Diamond
                       : e.geometry == "SquareCC" ? QuadEmGeometry::SquareCC
                                                  : QuadEmGeometry::Square;
        prm.full_scale = e.ranges.empty() ? 0 : e.ranges[std::size_t(e.range)].full_scale;
        u->qe = std::make_unique<QuadEm>(prm);
        // the cycle's values as engine signals, read through a binder onto the electrometer's cells
        const std::string owner = lower(e.name);
        for (int k = 0; k < kQuadEmValues; ++k) {
            registry::Signal s;
            s.name = owner + "." + lower(kQuadEmValueNames[k]);
            s.type = "LREAL";
            s.direction = registry::Direction::Input;
            s.owner_kind = registry::OwnerKind::Engine;
            s.owner = "quadem " + e.name;
            reg_.declare(std::move(s));
        }
        const QuadEm* qe = u->qe.get();
        reg_.set_binder(owner + ".", [qe, owner](const registry::Signal& s, int bit, std::string& why) {
            registry::BoundSignal b;
            if (bit >= 0) {
                why = s.name + " is a number, not bits";
                return b;
            }
            for (int k = 0; k < kQuadEmValues; ++k)
                if (s.name == owner + "." + lower(kQuadEmValueNames[k])) {
                    b.image = reinterpret_cast<uint8_t*>(const_cast<double*>(qe->values() + k));
                    b.bits = 64;
                    return b;
                }
            why = "no value " + s.name;
            return b;
        });
        // quadEM.template's PVs (their names)
        const std::string& p = u->p;
        const std::string prec = std::to_string(e.prec), egu = e.egu.substr(0, 15);
        f.records.push_back(record("busy", p + "Acquire", {{"ZNAM", "Done"}, {"ONAM", "Acquire"}, {"VAL", "1"}}));
        const std::vector<std::pair<std::string, std::string>> modes = {{"ZRST", "Continuous"}, {"ONST", "Multiple"}, {"TWST", "Single"}};
        f.records.push_back(record("mbbo", p + "AcquireMode", modes));
        f.records.push_back(record("mbbi", p + "AcquireMode_RBV", modes));
        f.records.push_back(record("longout", p + "NumAcquire", {{"VAL", "1"}, {"DRVL", "1"}, {"DRVH", "2147483647"}}));
        f.records.push_back(record("longin", p + "NumAcquire_RBV", {}));
        f.records.push_back(record("longin", p + "NumAcquired", {{"DESC", "Number of acquisitions complete"}}));
        f.records.push_back(record("ao", p + "AveragingTime", {{"DESC", "Averaging time"}, {"PREC", "4"}, {"EGU", "s"}, {"VAL", num(e.averaging_time)}}));
        f.records.push_back(record("ai", p + "AveragingTime_RBV", {{"DESC", "Averaging time"}, {"PREC", "4"}, {"EGU", "s"}}));
        f.records.push_back(record("longin", p + "NumAverage_RBV", {{"DESC", "Number of samples to average"}}));
        f.records.push_back(record("longin", p + "NumAveraged_RBV", {{"DESC", "Number of samples actually averaged"}}));
        f.records.push_back(record("ai", p + "SampleTime_RBV", {{"DESC", "Sampling time (sec)"}, {"PREC", "6"}, {"EGU", "s"}}));
        const std::vector<std::pair<std::string, std::string>> geo = {{"ZRST", "Diamond"}, {"ONST", "Square"}, {"TWST", "SquareCC"}};
        auto g = geo;
        g.push_back({"VAL", std::to_string(int(prm.geometry))});
        f.records.push_back(record("mbbo", p + "Geometry", g));
        f.records.push_back(record("mbbi", p + "Geometry_RBV", geo));
        {
            static const char* kSt[] = {"ZR", "ON", "TW", "TH", "FR", "FV", "SX", "SV", "EI", "NI", "TE", "EL", "TV", "TT", "FT", "FF"};
            std::vector<std::pair<std::string, std::string>> st;
            if (e.ranges.empty()) st.push_back({"ZRST", "Full"});
            for (std::size_t i = 0; i < e.ranges.size(); ++i) st.push_back({std::string(kSt[i]) + "ST", e.ranges[i].name});
            auto r = st;
            r.push_back({"DESC", "Range"});
            r.push_back({"VAL", std::to_string(e.range)});
            f.records.push_back(record("mbbo", p + "Range", r));
            st.push_back({"DESC", "Range"});
            f.records.push_back(record("mbbi", p + "Range_RBV", st));
        }
        for (int i = 0; i < 4; ++i) {
            const std::string n = std::to_string(i + 1);
            f.records.push_back(record("ao", p + "CurrentOffset" + n, {{"DESC", "Offset"}, {"PREC", prec}, {"VAL", num(e.current_offset[i])}}));
            f.records.push_back(record("ao", p + "CurrentScale" + n, {{"DESC", "Scale " + n}, {"PREC", "3"}, {"VAL", num(e.current_scale[i])}}));
        }
        for (int i = 0; i < 2; ++i) {
            const std::string n = i ? "Y" : "X";
            f.records.push_back(record("ao", p + "PositionOffset" + n, {{"DESC", "Offset " + n}, {"PREC", prec}, {"EGU", egu}, {"VAL", num(e.position_offset[i])}}));
            f.records.push_back(record("ao", p + "PositionScale" + n, {{"DESC", "Scale " + n}, {"PREC", "3"}, {"VAL", num(e.position_scale[i])}}));
        }
        f.records.push_back(record("longin", p + "RingOverflows", {{"DESC", "Readings the IOC did not take"}}));
        for (int k = 0; k < kQuadEmValues; ++k) {
            const bool pos = k >= kPosX;
            std::vector<std::pair<std::string, std::string>> flds = {{"PREC", prec}};
            if (pos) flds.push_back({"EGU", egu});
            f.records.push_back(record("ai", p + kAveNames[k], flds));
            for (const char* st : kStats) f.records.push_back(record("ai", p + kQuadEmValueNames[k] + ":" + st, flds));
        }
        // the time-series plugin (NDTimeSeries with R=<name>:TS:, NDTimeSeriesN with R=<name>:TS:<value>:)
        const std::string ts = p + "TS:", pts = std::to_string(e.ts_points);
        f.records.push_back(record("busy", ts + "TSAcquire", {{"ZNAM", "Done"}, {"ONAM", "Acquire"}}));
        f.records.push_back(record("bi", ts + "TSAcquiring", {{"ZNAM", "Done"}, {"ONAM", "Acquiring"}}));
        f.records.push_back(record("bo", ts + "TSRead", {{"ZNAM", "Done"}, {"ONAM", "Read"}, {"VAL", "1"}, {"SCAN", "1 second"}}));
        f.records.push_back(record("longout", ts + "TSNumPoints", {{"VAL", pts}, {"DRVL", "1"}, {"DRVH", pts}}));
        f.records.push_back(record("longin", ts + "TSCurrentPoint", {}));
        f.records.push_back(record("ao", ts + "TSTimePerPoint", {{"PREC", "6"}, {"EGU", "s"}}));
        f.records.push_back(record("ai", ts + "TSTimePerPoint_RBV", {{"PREC", "6"}, {"EGU", "s"}}));
        f.records.push_back(record("ao", ts + "TSAveragingTime", {{"PREC", "6"}, {"EGU", "s"}, {"VAL", "0"}}));
        f.records.push_back(record("ai", ts + "TSAveragingTime_RBV", {{"PREC", "6"}, {"EGU", "s"}}));
        f.records.push_back(record("longin", ts + "TSNumAverage", {}));
        f.records.push_back(record("ai", ts + "TSElapsedTime", {{"PREC", "3"}, {"EGU", "s"}}));
        const std::vector<std::pair<std::string, std::string>> ts_modes = {{"ZRST", "Fixed length"}, {"ONST", "Circ. buffer"}};
        f.records.push_back(record("mbbo", ts + "TSAcquireMode", ts_modes));
        f.records.push_back(record("mbbi", ts + "TSAcquireMode_RBV", ts_modes));
        f.records.push_back(record("waveform", ts + "TSTimestamp", {{"FTVL", "DOUBLE"}, {"NELM", pts}}));
        f.records.push_back(record("waveform", ts + "TSTimeAxis", {{"FTVL", "DOUBLE"}, {"NELM", pts}}));
        for (int k = 0; k < kQuadEmValues; ++k) {
            const std::string q = ts + kQuadEmValueNames[k] + ":";
            f.records.push_back(record("stringout", q + "Name", {{"VAL", kQuadEmValueNames[k]}}));
            f.records.push_back(record("waveform", q + "TimeSeries", {{"FTVL", "DOUBLE"}, {"NELM", pts}}));
        }
        units_.push_back(std::move(u));
    }
    if (f.records.empty()) return;
    db_.load(f);
    for (auto& up : units_) {
        Unit& u = *up;
        auto find = [&](const std::string& n) {
            pv::Record* r = db_.find(u.p + n);
            if (!r) throw Error(SB() << "quadem " << u.cfg.name << ": record " << u.p << n << " missing");
            return r;
        };
        u.acquire = find("Acquire");
        u.mode = find("AcquireMode");
        u.mode_rbv = find("AcquireMode_RBV");
        u.num_acquire = find("NumAcquire");
        u.num_acquire_rbv = find("NumAcquire_RBV");
        u.num_acquired = find("NumAcquired");
        u.avg_time = find("AveragingTime");
        u.avg_time_rbv = find("AveragingTime_RBV");
        u.num_average = find("NumAverage_RBV");
        u.num_averaged = find("NumAveraged_RBV");
        u.sample_time = find("SampleTime_RBV");
        u.geometry = find("Geometry");
        u.geometry_rbv = find("Geometry_RBV");
        u.range = find("Range");
        u.range_rbv = find("Range_RBV");
        u.overflows = find("RingOverflows");
        for (int i = 0; i < 4; ++i) {
            u.cur_offset[i] = find("CurrentOffset" + std::to_string(i + 1));
            u.cur_scale[i] = find("CurrentScale" + std::to_string(i + 1));
        }
        for (int i = 0; i < 2; ++i) {
            u.pos_offset[i] = find(std::string("PositionOffset") + (i ? "Y" : "X"));
            u.pos_scale[i] = find(std::string("PositionScale") + (i ? "Y" : "X"));
        }
        for (int k = 0; k < kQuadEmValues; ++k) {
            u.ave[k] = find(kAveNames[k]);
            for (int s = 0; s < 4; ++s) u.stats[k][s] = find(std::string(kQuadEmValueNames[k]) + ":" + kStats[s]);
        }
        u.ts_acquire = find("TS:TSAcquire");
        u.ts_acquiring = find("TS:TSAcquiring");
        u.ts_read = find("TS:TSRead");
        u.ts_num_points = find("TS:TSNumPoints");
        u.ts_current = find("TS:TSCurrentPoint");
        u.ts_time_per_point = find("TS:TSTimePerPoint");
        u.ts_time_per_point_rbv = find("TS:TSTimePerPoint_RBV");
        u.ts_avg_time = find("TS:TSAveragingTime");
        u.ts_avg_time_rbv = find("TS:TSAveragingTime_RBV");
        u.ts_num_average = find("TS:TSNumAverage");
        u.ts_elapsed = find("TS:TSElapsedTime");
        u.ts_mode = find("TS:TSAcquireMode");
        u.ts_mode_rbv = find("TS:TSAcquireMode_RBV");
        u.ts_timestamp = find("TS:TSTimestamp");
        u.ts_time_axis = find("TS:TSTimeAxis");
        for (int k = 0; k < kQuadEmValues; ++k) u.ts_series[k] = find(std::string("TS:") + kQuadEmValueNames[k] + ":TimeSeries");
        for (pv::Record* r : {u.mode_rbv, u.num_acquire_rbv, u.num_acquired, u.avg_time_rbv, u.num_average, u.num_averaged, u.sample_time,
                              u.geometry_rbv, u.range_rbv, u.overflows, u.ts_acquiring, u.ts_current, u.ts_time_per_point, u.ts_time_per_point_rbv,
                              u.ts_avg_time_rbv, u.ts_num_average, u.ts_elapsed, u.ts_mode_rbv, u.ts_timestamp, u.ts_time_axis})
            r->val_read_only = true;
        for (pv::Record* r : u.ts_series) r->val_read_only = true;
        for (int k = 0; k < kQuadEmValues; ++k) {
            u.ave[k]->val_read_only = true;
            for (pv::Record* r : u.stats[k]) r->val_read_only = true;
        }
        Unit* self = &u;
        auto param = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            if (&r == self->avg_time && !(get_value(r) >= 0)) {
                LOG_WARN(lg, r.name() << ": " << get_value(r) << " refused: the averaging time is >= 0 s");
                return pv::PutStatus::Failed;
            }
            if ((&r == self->cur_scale[0] || &r == self->cur_scale[1] || &r == self->cur_scale[2] || &r == self->cur_scale[3] ||
                 &r == self->pos_scale[0] || &r == self->pos_scale[1]) && !std::isfinite(get_value(r))) {
                LOG_WARN(lg, r.name() << ": refused: a scale is a finite number");
                return pv::PutStatus::Failed;
            }
            if ((&r == self->geometry || &r == self->mode) && !(get_value(r) >= 0 && get_value(r) <= 2)) {
                LOG_WARN(lg, r.name() << ": " << get_value(r) << " refused: not one of the record's three choices");
                return pv::PutStatus::Failed;
            }
            const double ranges = double(std::max<std::size_t>(self->cfg.ranges.size(), 1));
            if (&r == self->range && !(get_value(r) >= 0 && get_value(r) < ranges)) {
                LOG_WARN(lg, r.name() << ": " << get_value(r) << " refused: not one of the " << ranges << " ranges");
                return pv::PutStatus::Failed;
            }
            apply(*self);
            return pv::PutStatus::Ok;
        };
        for (pv::Record* r : {u.mode, u.num_acquire, u.avg_time, u.geometry, u.range, u.cur_offset[0], u.cur_offset[1], u.cur_offset[2], u.cur_offset[3],
                              u.cur_scale[0], u.cur_scale[1], u.cur_scale[2], u.cur_scale[3], u.pos_offset[0], u.pos_offset[1], u.pos_scale[0],
                              u.pos_scale[1]})
            r->put_hook = param;
        u.acquire->put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) == "VAL") set_acquire(*self, get_value(r) != 0);
            return pv::PutStatus::Ok;
        };
        // the time series: its settings wait while it acquires
        auto ts_param = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            if (self->ts_on) {
                LOG_WARN(lg, r.name() << ": refused while the time series acquires (TSAcquire 0 first)");
                return pv::PutStatus::Failed;
            }
            if (&r == self->ts_avg_time && !(get_value(r) >= 0)) {
                LOG_WARN(lg, r.name() << ": " << get_value(r) << " refused: the averaging time is >= 0 s");
                return pv::PutStatus::Failed;
            }
            if (&r == self->ts_mode && !(get_value(r) == 0 || get_value(r) == 1)) {
                LOG_WARN(lg, r.name() << ": refused: Fixed length (0) or Circ. buffer (1)");
                return pv::PutStatus::Failed;
            }
            ts_settings(*self);
            return pv::PutStatus::Ok;
        };
        for (pv::Record* r : {u.ts_num_points, u.ts_avg_time, u.ts_mode}) r->put_hook = ts_param;
        u.ts_acquire->put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            if (get_value(r) != 0 && !self->ts_on) ts_start(*self);
            else if (get_value(r) == 0 && self->ts_on) {
                ts_take(*self); // what the cycle already queued
                if (self->ts_on) ts_stop(*self);
            }
            return pv::PutStatus::Ok;
        };
        u.ts_read->put_hook = [this, self](pv::Record&, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) == "VAL" || std::string_view(fd.name) == "PROC") ts_publish(*self);
            return pv::PutStatus::Ok;
        };
    }
}

QuadEmModule::~QuadEmModule() = default;

const QuadEm& QuadEmModule::unit(std::size_t i) const { return *units_.at(i)->qe; }

void QuadEmModule::apply(Unit& u) {
    QuadEmParams p;
    for (int i = 0; i < 4; ++i) p.current_offset[i] = get_value(*u.cur_offset[i]), p.current_scale[i] = get_value(*u.cur_scale[i]);
    for (int i = 0; i < 2; ++i) p.position_offset[i] = get_value(*u.pos_offset[i]), p.position_scale[i] = get_value(*u.pos_scale[i]);
    const int g = int(get_value(*u.geometry));
    p.geometry = QuadEmGeometry(g >= 0 && g <= 2 ? g : 1);
    const std::size_t range = std::size_t(std::max(0.0, get_value(*u.range)));
    p.full_scale = range < u.cfg.ranges.size() ? u.cfg.ranges[range].full_scale : 0;
    // quadEM: NumAverage = int(AveragingTime / SampleTime + 0.5), at least 1
    const double n = std::floor(get_value(*u.avg_time) / cycle_s_ + 0.5);
    p.num_average = int(std::max(1.0, std::min(n, 1e7)));
    u.qe->set_params(p);
    set_value(db_, *u.mode_rbv, get_value(*u.mode), false);
    set_value(db_, *u.num_acquire_rbv, get_value(*u.num_acquire), false);
    set_value(db_, *u.num_average, p.num_average, false);
    set_value(db_, *u.avg_time_rbv, p.num_average * cycle_s_, false);
    set_value(db_, *u.sample_time, cycle_s_, false);
    set_value(db_, *u.geometry_rbv, double(int(p.geometry)), false);
    set_value(db_, *u.range_rbv, double(range), false);
}

void QuadEmModule::set_acquire(Unit& u, bool on) {
    if (on && !u.acquiring) {
        u.acquired = 0;
        set_value(db_, *u.num_acquired, 0, false);
    }
    u.acquiring = on;
}

void QuadEmModule::ts_settings(Unit& u) {
    const double avg = get_value(*u.ts_avg_time);
    const int n = int(std::max(1.0, std::min(std::floor(avg / cycle_s_ + 0.5), 1e7))); // whole samples a point
    set_value(db_, *u.ts_num_average, n, false);
    set_value(db_, *u.ts_avg_time_rbv, n * cycle_s_, false);
    set_value(db_, *u.ts_time_per_point, cycle_s_, false); // the samples' (quadEM: TIME_LINK = SampleTime_RBV)
    set_value(db_, *u.ts_time_per_point_rbv, cycle_s_, false);
    set_value(db_, *u.ts_mode_rbv, get_value(*u.ts_mode), false);
}

void QuadEmModule::ts_start(Unit& u) {
    ts_settings(u);
    QuadEmSample s;
    while (u.qe->pop_sample(s)) {
    } // a previous run's leftovers
    u.ts_points = std::max(1, int(get_value(*u.ts_num_points)));
    u.ts_avg = std::max(1, int(get_value(*u.ts_num_average)));
    u.ts_circular = get_value(*u.ts_mode) == 1;
    u.ts_n = 0, u.ts_acc_n = 0;
    for (auto& d : u.ts_data) d.assign(std::size_t(u.ts_points), 0.0);
    u.ts_t0 = double(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count()) * 1e-9 -
              631152000; // EPICS epoch
    u.ts_last_read = 0;
    u.ts_on = true, u.ts_dirty = true;
    set_value(db_, *u.ts_acquiring, 1, false);
    set_value(db_, *u.ts_current, 0, false);
    set_value(db_, *u.ts_elapsed, 0, false);
    std::vector<double> axis(std::size_t(u.ts_points));
    for (std::size_t i = 0; i < axis.size(); ++i) axis[i] = double(i) * u.ts_avg * cycle_s_;
    set_array(db_, *u.ts_time_axis, axis.data(), uint32_t(axis.size()));
    u.qe->stream_samples(true);
}

void QuadEmModule::ts_stop(Unit& u) {
    u.qe->stream_samples(false);
    u.ts_on = false;
    ts_publish(u);
    set_value(db_, *u.ts_acquiring, 0, false);
    if (get_value(*u.ts_acquire) != 0) set_value(db_, *u.ts_acquire, 0, false); // a put-callback completes
}

// The samples the cycle queued: TSNumAverage of them a point.
void QuadEmModule::ts_take(Unit& u) {
    QuadEmSample s;
    bool stop = false;
    uint64_t last_cycle = 0;
    auto full = [&u] { return !u.ts_circular && u.ts_n >= u.ts_points; };
    while (u.ts_on && !full() && u.qe->pop_sample(s)) {
        last_cycle = s.cycle;
        for (int k = 0; k < kQuadEmValues; ++k) u.ts_acc[k] = (u.ts_acc_n ? u.ts_acc[k] : 0) + s.v[k];
        if (++u.ts_acc_n < u.ts_avg) continue;
        const std::size_t at = std::size_t(u.ts_n % u.ts_points);
        for (int k = 0; k < kQuadEmValues; ++k) u.ts_data[k][at] = u.ts_acc[k] / u.ts_acc_n;
        u.ts_acc_n = 0;
        ++u.ts_n;
        u.ts_dirty = true;
    }
    stop = u.ts_on && full();
    if (!u.ts_on) return;
    set_value(db_, *u.ts_current, double(std::min<long>(u.ts_n, u.ts_points)), false);
    set_value(db_, *u.ts_elapsed, double(u.ts_n) * u.ts_avg * cycle_s_, false);
    if (stop) {
        ts_stop(u);
        return;
    }
    // TSRead's scan period: the arrays while acquiring (quadEM's TSRead, SCAN "1 second")
    static const double kPeriods[] = {0, 0, 0, 10, 5, 2, 1, 0.5, 0.2, 0.1};
    const double period = u.ts_read->scan < 10 ? kPeriods[u.ts_read->scan] : 0;
    const double now = double(u.ts_n) * u.ts_avg * cycle_s_;
    if (last_cycle && period > 0 && now - u.ts_last_read >= period) {
        u.ts_last_read = now;
        ts_publish(u);
    }
}

// The points so far into the arrays, oldest first (a circular buffer's latest point is its last).
void QuadEmModule::ts_publish(Unit& u) {
    if (!u.ts_dirty || u.ts_data[0].empty()) return;
    const std::size_t n = std::size_t(std::min<long>(u.ts_n, u.ts_points));
    const std::size_t first = u.ts_n > u.ts_points ? std::size_t(u.ts_n % u.ts_points) : 0;
    std::vector<double> v(n);
    for (int k = 0; k < kQuadEmValues; ++k) {
        for (std::size_t i = 0; i < n; ++i) v[i] = u.ts_data[k][(first + i) % std::size_t(u.ts_points)];
        set_array(db_, *u.ts_series[k], v.data(), uint32_t(n));
    }
    const long first_point = u.ts_n > u.ts_points ? u.ts_n - u.ts_points : 0;
    for (std::size_t i = 0; i < n; ++i) v[i] = u.ts_t0 + double(first_point + long(i) + 1) * u.ts_avg * cycle_s_;
    set_array(db_, *u.ts_timestamp, v.data(), uint32_t(n));
    u.ts_dirty = false;
}

void QuadEmModule::bind(module::BindContext& ctx) {
    rt::Engine& engine = ctx.cycle;
    motion::AxisGroup* axes = ctx.axes;
    if (units_.empty()) return;
    cycle_s_ = double(engine.period_ns()) * 1e-9;
    for (auto& up : units_) {
        Unit& u = *up;
        for (int i = 0; i < 4; ++i) {
            std::string why;
            u.in[i] = module::resolve_value(reg_, axes, u.cfg.currents[i], why);
            if (u.in[i].kind == module::ValueSource::Kind::None || u.in[i].kind == module::ValueSource::Kind::Time)
                throw Error(SB() << u.cfg.currents_where << ": quadem " << u.cfg.name << " current " << (i + 1) << ": "
                                 << (why.empty() ? std::string("'time' is not a current") : why));
            if (u.in[i].bus >= 0) u.ok[i] = reg_.bind(std::string(SB() << "ec" << u.in[i].bus << ".masterstatus"), why);
        }
        apply(u);
        ts_settings(u);
        set_acquire(u, get_value(*u.acquire) != 0);
    }
    stage_ = std::make_unique<Stage>(*this);
    engine.add_stage(rt::StageOrder::Triggers, *stage_);
}

void QuadEmModule::publish(double) {
    for (auto& up : units_) {
        Unit& u = *up;
        QuadEmReading r;
        bool got = false;
        while (u.qe->pop(r)) {
            if (!u.acquiring) continue; // Acquire off: the readings are not taken
            got = true;
            ++u.acquired;
            const int mode = int(get_value(*u.mode));
            const int want = int(get_value(*u.num_acquire));
            if (mode == kSingle || (mode == kMultiple && u.acquired >= std::max(1, want))) {
                u.acquiring = false;
                break; // this reading is the last one
            }
        }
        if (got) {
            for (int k = 0; k < kQuadEmValues; ++k) {
                set_value(db_, *u.ave[k], r.mean[k], false);
                set_value(db_, *u.stats[k][0], r.mean[k], false);
                set_value(db_, *u.stats[k][1], r.sigma[k], false);
                set_value(db_, *u.stats[k][2], r.min[k], false);
                set_value(db_, *u.stats[k][3], r.max[k], false);
            }
            set_value(db_, *u.num_averaged, r.n, false);
            set_value(db_, *u.num_acquired, u.acquired, false);
            if (!u.acquiring) set_value(db_, *u.acquire, 0, false); // Multiple/Single done
        }
        ts_take(u);
        if (u.qe->dropped() != u.seen_dropped) {
            u.seen_dropped = u.qe->dropped();
            set_value(db_, *u.overflows, clamp_long(u.seen_dropped), false);
        }
    }
}

} // namespace beamctl::detector
