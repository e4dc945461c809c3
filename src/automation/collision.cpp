// Collision zones (see collision.hpp).
#include "automation/collision.hpp"

#include "automation/expression_names.hpp"
#include "automation/number_text.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "plc/program.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>

namespace beamctl::automation {

namespace {

log::Logger lg("collision");

constexpr double kRecordPollS = 0.1; // how old a motor record's RBV may be (it polls its driver at 10 Hz)
constexpr int kPathSamples = 200;    // points checked along a move's path

std::string fmt(double v) { return number_text(v, 6); }

} // namespace

struct CollisionZones::Zone {
    struct Axis {
        std::string name, pv;
        pv::Record* rec = nullptr;
        pv::Address val, rbv, stop, dmov, movn, tdir, velo, rlv, twv;
    };
    config::CollisionZoneEntry cfg;
    std::string p;
    std::vector<double> pos;
    double result = 0;
    ExpressionNames host{"a collision zone"};
    std::optional<plc::Program> forbidden;
    std::vector<Axis> axes;
    uint64_t refused = 0, stopped = 0;
    bool stopping = false, inside_shown = false;
    pv::Record *refused_r = nullptr, *stopped_r = nullptr, *inside_r = nullptr, *message_r = nullptr;

    bool inside(const std::vector<double>& x) {
        pos = x;
        result = 0;
        return forbidden->run() != 0 || result != 0 || !std::isfinite(result); // a faulting expression: forbidden
    }
    std::string where(const std::vector<double>& x) const {
        std::string s;
        for (std::size_t k = 0; k < axes.size(); ++k) s += (k ? ", " : "") + axes[k].name + " " + fmt(x[k]);
        return s;
    }
};

CollisionZones::CollisionZones(const std::vector<config::CollisionZoneEntry>& cfg, const std::string& prefix, pv::Database& db,
                               std::function<double()> clock)
    : db_(db), clock_(std::move(clock)) {
    pv::DbFile f;
    for (const auto& c : cfg) {
        auto z = std::make_unique<Zone>();
        z->cfg = c;
        z->p = prefix + c.name + ":";
        z->pos.assign(c.axes.size(), 0);
        for (std::size_t k = 0; k < c.axes.size(); ++k) {
            z->host.bind(c.axes[k].first, &z->pos[k], false);
            z->axes.push_back({c.axes[k].first, c.axes[k].second});
        }
        z->host.bind("zone_result_", &z->result, true);
        try {
            z->forbidden = plc::Program::compile("zone_result_ := (" + c.forbidden + ");", "forbidden", z->host);
        } catch (const plc::CompileError& e) {
            throw Error(c.where + ": collision zone '" + c.name + "': " + e.what());
        }
        f.records.push_back(pv::generated_record("longin", z->p + "Refused", {}));
        f.records.push_back(pv::generated_record("longin", z->p + "Stopped", {}));
        f.records.push_back(pv::generated_record("bi", z->p + "Inside", {{"ZNAM", "Outside"}, {"ONAM", "Inside"}, {"OSV", "MAJOR"}}));
        f.records.push_back(pv::generated_record("waveform", z->p + "Message", {{"FTVL", "CHAR"}, {"NELM", "256"}}));
        zones_.push_back(std::move(z));
    }
    db_.load(f);
}

CollisionZones::~CollisionZones() = default;

void CollisionZones::start() {
    for (auto& zp : zones_) {
        Zone& z = *zp;
        for (std::size_t k = 0; k < z.axes.size(); ++k) {
            Zone::Axis& a = z.axes[k];
            a.rec = db_.find(a.pv);
            if (!a.rec || std::string_view(a.rec->type().name()) != "motor")
                throw Error(z.cfg.where + ": collision zone '" + z.cfg.name + "': axis '" + a.name + "': '" + a.pv +
                            "' is not a motor record of this IOC");
            for (auto [field, addr] : {std::pair{"VAL", &a.val}, {"RBV", &a.rbv}, {"STOP", &a.stop}, {"DMOV", &a.dmov},
                                       {"MOVN", &a.movn}, {"TDIR", &a.tdir}, {"VELO", &a.velo}, {"RLV", &a.rlv}, {"TWV", &a.twv}})
                db_.resolve(a.pv + "." + field, *addr);
            // Every put that sets a target is checked along its path before the motor starts.
            Zone* zz = &z;
            auto before = a.rec->put_hook;
            a.rec->put_hook = [this, zz, k, before](pv::Record& r, const pv::FieldDesc& fd) {
                auto get = [&](const pv::Address& ad) {
                    double v = 0;
                    db_.get(ad, pv::Prim::Double, &v, 1);
                    return v;
                };
                Zone::Axis& ax = zz->axes[k];
                double target = NAN;
                if (std::strcmp(fd.name, "VAL") == 0) target = get(ax.val);
                else if (std::strcmp(fd.name, "RLV") == 0) target = get(ax.val) + get(ax.rlv);
                else if (std::strcmp(fd.name, "TWF") == 0) target = get(ax.val) + get(ax.twv);
                else if (std::strcmp(fd.name, "TWR") == 0) target = get(ax.val) - get(ax.twv);
                if (std::isfinite(target)) {
                    std::vector<double> from(zz->axes.size()), to(zz->axes.size());
                    for (std::size_t j = 0; j < zz->axes.size(); ++j) {
                        from[j] = get(zz->axes[j].rbv);
                        to[j] = get(zz->axes[j].dmov) == 0 ? get(zz->axes[j].val) : from[j]; // a moving one: where it goes
                    }
                    to[k] = target;
                    const bool start_inside = zz->inside(from);
                    std::vector<double> x(from.size());
                    for (int i = start_inside ? kPathSamples : 1; i <= kPathSamples; ++i) { // from inside: only the end counts
                        for (std::size_t j = 0; j < x.size(); ++j) x[j] = from[j] + (to[j] - from[j]) * i / kPathSamples;
                        if (!zz->inside(x)) continue;
                        ++zz->refused;
                        const std::string msg = "move of " + ax.pv + " to " + fmt(target) + " refused: it would enter collision zone '" +
                                                zz->cfg.name + "' (" + zz->cfg.forbidden + ") at " + zz->where(x);
                        LOG_WARN(lg, msg);
                        pv::set_text(db_, *zz->message_r, msg.substr(0, 255));
                        pv::set_value(db_, *zz->refused_r, double(zz->refused), false);
                        return pv::PutStatus::Failed;
                    }
                }
                return before ? before(r, fd) : pv::PutStatus::Ok;
            };
        }
        z.refused_r = db_.find(z.p + "Refused"), z.stopped_r = db_.find(z.p + "Stopped");
        z.inside_r = db_.find(z.p + "Inside"), z.message_r = db_.find(z.p + "Message");
        LOG_INFO(lg, "zone '" << z.cfg.name << "': " << z.axes.size() << " axes, forbidden where " << z.cfg.forbidden);
    }
}

void CollisionZones::poll() {
    for (auto& zp : zones_) {
        Zone& z = *zp;
        const std::size_t n = z.axes.size();
        std::vector<double> now(n), ahead(n);
        bool moving = false;
        for (std::size_t k = 0; k < n; ++k) {
            Zone::Axis& a = z.axes[k];
            double rbv = 0, movn = 0, tdir = 0, velo = 0, dmov = 1, val = 0;
            db_.get(a.rbv, pv::Prim::Double, &rbv, 1);
            db_.get(a.val, pv::Prim::Double, &val, 1);
            db_.get(a.movn, pv::Prim::Double, &movn, 1);
            db_.get(a.tdir, pv::Prim::Double, &tdir, 1);
            db_.get(a.velo, pv::Prim::Double, &velo, 1);
            db_.get(a.dmov, pv::Prim::Double, &dmov, 1);
            const double v = (movn != 0 || dmov == 0) ? (tdir != 0 ? velo : -velo) : 0;
            moving = moving || v != 0;
            now[k] = rbv;
            ahead[k] = rbv + v * (z.cfg.lookahead_s + kRecordPollS);
            // a move ends at its target (checked when it was put): not beyond it. A jog's VAL is
            // behind it, so a jog is extrapolated in full.
            if ((v > 0 && val >= rbv && val < ahead[k]) || (v < 0 && val <= rbv && val > ahead[k])) ahead[k] = val;
        }
        const bool inside_now = z.inside(now);
        if (inside_now != z.inside_shown) {
            z.inside_shown = inside_now;
            pv::set_value(db_, *z.inside_r, inside_now, false);
            if (inside_now) LOG_ERR(lg, "zone '" << z.cfg.name << "': the axes are inside the forbidden region at " << z.where(now));
        }
        if (moving && !inside_now && z.inside(ahead)) {
            if (z.stopping) continue;
            z.stopping = true;
            ++z.stopped;
            const double one = 1;
            std::string which;
            for (std::size_t k = 0; k < n; ++k) {
                double dmov = 1;
                db_.get(z.axes[k].dmov, pv::Prim::Double, &dmov, 1);
                if (dmov != 0) continue;
                db_.put(z.axes[k].stop, pv::Prim::Double, &one, 1);
                which += (which.empty() ? "" : ", ") + z.axes[k].pv;
            }
            const std::string msg = "stopped " + which + ": about to enter collision zone '" + z.cfg.name + "' (" + z.cfg.forbidden +
                                    ") at " + z.where(ahead);
            LOG_WARN(lg, msg);
            pv::set_text(db_, *z.message_r, msg.substr(0, 255));
            pv::set_value(db_, *z.stopped_r, double(z.stopped), false);
        } else {
            z.stopping = false;
        }
    }
}

uint64_t CollisionZones::refused() const {
    uint64_t n = 0;
    for (const auto& z : zones_) n += z->refused;
    return n;
}

uint64_t CollisionZones::stopped() const {
    uint64_t n = 0;
    for (const auto& z : zones_) n += z->stopped;
    return n;
}

} // namespace beamctl::automation
