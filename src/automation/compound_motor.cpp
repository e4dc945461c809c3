// Compound motors (see compound_motor.hpp).
#include "automation/compound_motor.hpp"

#include "automation/expression_names.hpp"
#include "automation/motor_port.hpp"
#include "automation/number_text.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "plc/program.hpp"
#include "pv/db_file.hpp"
#include "pv/motor_record.hpp"

#include <cmath>
#include <cstdio>
#include <optional>

namespace beamctl::automation {

namespace {

log::Logger lg("compound");

std::string fmt(double v) { return number_text(v, 9); }

plc::Program compile(const std::string& code, const std::string& where, const std::string& what, ExpressionNames& host) {
    plc::CompileOptions o;
    o.max_loop_iterations = 100000; // expressions, not programs: a runaway loop is a fault
    try {
        return plc::Program::compile(code, what, host, o);
    } catch (const plc::CompileError& e) {
        throw Error(where + ": " + what + ": " + e.what());
    }
}

class VirtualDriver;

} // namespace

struct CompoundMotors::Group {
    struct Virtual {
        std::string record;
        double position = NAN; // forward of the readbacks
        bool valid = false;    // known at least once
        double request = NAN;  // the target asked for
        bool pending = false;  // asked for, not started
        bool busy = false;     // asked for, not finished (what the driver reports as !done)
        bool failed = false, lvio = false;
        double hlm = NAN, llm = NAN; // the limits last written into the record
        pv::Address hlm_a, llm_a;
        double mres = 0;
        // The reals moved by someone else while idle: the record takes the readback as its VAL
        // (a sync request, as ECMC's mc_mr_set_sync), so that VAL never lies about where it is.
        uint32_t syncs = 0;
        double synced = NAN;
        std::shared_ptr<pv::MotorDriver> driver;
    };

    config::CompoundMotorEntry cfg;
    pv::Database& db;
    std::vector<double> rbv, input, vout, vin, target; // the expressions' storage (never resized)
    ExpressionNames fhost, ihost;
    std::vector<plc::Program> forward, inverse;
    std::vector<bool> driven;                       // per real: an inverse expression moves it
    std::vector<std::unique_ptr<MotorPort>> reals;  // null while a remote one is not made yet
    std::vector<std::unique_ptr<PvReader>> inputs;
    std::vector<bool> remote_real, remote_input;
    std::vector<MotorPort::State> st;
    std::vector<Virtual> v;
    bool connected = false;
    std::string not_connected; // which, for messages
    // the move under way
    bool moving = false, stop_asked = false, limits_due = true;
    std::vector<double> seen_limits; // the reals' HLM, LLM when the virtuals' limits were derived
    int mover = -1, outstanding = 0, polls = 0;
    double move_target = 0;
    std::vector<std::string> failures;

    Group(const config::CompoundMotorEntry& c, pv::Database& d)
        : cfg(c), db(d), rbv(c.reals.size()), input(c.inputs.size()), vout(c.virtuals.size()), vin(c.virtuals.size()),
          target(c.reals.size()), fhost("compound motor group '" + c.name + "'"), ihost("compound motor group '" + c.name + "'"), driven(c.reals.size()), reals(c.reals.size()),
          inputs(c.inputs.size()), remote_real(c.reals.size()), remote_input(c.inputs.size()), st(c.reals.size()),
          v(c.virtuals.size()) {
        for (std::size_t j = 0; j < c.reals.size(); ++j) fhost.bind(c.reals[j].name, &rbv[j], false), ihost.bind(c.reals[j].name, &target[j], true);
        for (std::size_t k = 0; k < c.inputs.size(); ++k) fhost.bind(c.inputs[k].name, &input[k], false), ihost.bind(c.inputs[k].name, &input[k], false);
        for (std::size_t i = 0; i < c.virtuals.size(); ++i) fhost.bind(c.virtuals[i].name, &vout[i], true), ihost.bind(c.virtuals[i].name, &vin[i], false);
        for (const auto& x : c.virtuals)
            forward.push_back(compile(x.name + " := (" + x.forward + ");", x.where, "forward of " + x.name, fhost));
        for (std::size_t e = 0; e < c.inverse.size(); ++e)
            inverse.push_back(compile(c.inverse[e].first + " := (" + c.inverse[e].second + ");", c.inverse_where[e],
                                      "inverse of " + c.inverse[e].first, ihost));
        for (const std::string& n : ihost.assigned_names())
            for (std::size_t j = 0; j < c.reals.size(); ++j)
                if (c.reals[j].name == n) driven[j] = true;
    }

    // forward at the readbacks in `rbv` (and `input`): into `out`. False when an expression faults
    // or gives a non-number.
    bool eval_forward(std::vector<double>& out) {
        for (std::size_t i = 0; i < forward.size(); ++i) {
            vout[i] = NAN;
            if (forward[i].run() != 0) return false;
        }
        out = vout;
        for (double x : out)
            if (!std::isfinite(x)) return false;
        return true;
    }
    // inverse at virtuals `vals`: into `target` (reals not driven keep their readback).
    bool eval_inverse(const std::vector<double>& vals) {
        vin = vals;
        target = rbv;
        for (plc::Program& p : inverse)
            if (p.run() != 0) return false;
        return true;
    }

    void read_ports() {
        connected = true;
        not_connected.clear();
        for (std::size_t j = 0; j < reals.size(); ++j) {
            st[j] = reals[j] ? reals[j]->state() : MotorPort::State{};
            if (!st[j].connected) connected = false, not_connected += (not_connected.empty() ? "" : ", ") + cfg.reals[j].pv;
            rbv[j] = st[j].rbv;
        }
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            double x = 0;
            if (inputs[k] && inputs[k]->read(x)) input[k] = x;
            else connected = false, not_connected += (not_connected.empty() ? "" : ", ") + cfg.inputs[k].pv;
        }
    }

    // Why real j cannot go to target[j] ("" when it can).
    std::string real_refuses(std::size_t j) const {
        const double t = target[j];
        const MotorPort::State& s = st[j];
        if (!std::isfinite(t)) return cfg.reals[j].name + " (" + cfg.reals[j].pv + ") would go to " + fmt(t) + " (not a number)";
        if (s.hlm != s.llm && (t > s.hlm || t < s.llm))
            return cfg.reals[j].name + " (" + cfg.reals[j].pv + ") would go to " + fmt(t) + ", outside its soft limits [" +
                   fmt(s.llm) + ", " + fmt(s.hlm) + "]";
        return {};
    }
    bool feasible(std::size_t i, double x) {
        std::vector<double> vals(vout.size());
        for (std::size_t k = 0; k < v.size(); ++k) vals[k] = v[k].position;
        vals[i] = x;
        if (!eval_inverse(vals)) return false;
        for (std::size_t j = 0; j < reals.size(); ++j)
            if (driven[j] && !real_refuses(j).empty()) return false;
        return true;
    }

    // The largest step from x0 in direction `dir` that keeps every driven real within its limits
    // (doubling, then bisection); nullopt when none is found within 2^50 steps.
    std::optional<double> limit(std::size_t i, double x0, int dir) {
        const double s = std::max(v[i].mres, 1e-9 * (1 + std::fabs(x0)));
        double d = s;
        for (int k = 0; k < 50 && feasible(i, x0 + dir * d); ++k) d *= 2;
        if (feasible(i, x0 + dir * d)) return std::nullopt;
        double lo = d / 2 > s ? d / 2 : 0, hi = d;
        for (int k = 0; k < 60 && hi - lo > 0.01 * s; ++k) {
            const double mid = 0.5 * (lo + hi);
            (feasible(i, x0 + dir * mid) ? lo : hi) = mid;
        }
        return x0 + dir * lo;
    }

    void update_limits() {
        limits_due = false;
        if (!connected) return;
        const std::vector<double> keep = rbv;
        for (std::size_t i = 0; i < v.size(); ++i) {
            Virtual& vv = v[i];
            if (!vv.valid || !feasible(i, vv.position)) continue; // here already outside: no limits to derive
            std::optional<double> hi = limit(i, vv.position, +1), lo = limit(i, vv.position, -1);
            double h = 0, l = 0; // none
            if (hi || lo) h = hi.value_or(1e300), l = lo.value_or(-1e300);
            auto differs = [](double a, double b) { return !(std::fabs(a - b) <= 1e-12 * (1 + std::fabs(a))); };
            if (differs(h, vv.hlm) || differs(l, vv.llm)) {
                vv.hlm = h, vv.llm = l;
                // LLM first when lowering, HLM first when raising: never HLM < LLM on the way
                if (l > h) continue;
                db.put(vv.llm_a, pv::Prim::Double, &l, 1);
                db.put(vv.hlm_a, pv::Prim::Double, &h, 1);
            }
        }
        rbv = keep;
    }

    void fail(std::size_t i, const std::string& why, bool lvio) {
        Virtual& vv = v[i];
        vv.busy = false, vv.failed = true, vv.lvio = lvio;
        LOG_WARN(lg, vv.record << ": move to " << fmt(vv.request) << " refused: " << why);
    }

    void start_move(std::size_t i) {
        Virtual& vv = v[i];
        vv.pending = false;
        if (!connected) return fail(i, "not connected: " + not_connected, false);
        std::vector<double> vals(v.size());
        for (std::size_t k = 0; k < v.size(); ++k) vals[k] = v[k].position;
        vals[i] = vv.request;
        if (!eval_inverse(vals)) return fail(i, "the inverse expressions faulted", false);
        for (std::size_t j = 0; j < reals.size(); ++j)
            if (std::string why = driven[j] ? real_refuses(j) : ""; !why.empty()) return fail(i, why, true);
        moving = true, stop_asked = false, mover = int(i), move_target = vv.request;
        failures.clear();
        outstanding = 1; // held until every real's move is issued
        const std::vector<double> targets = target;
        for (std::size_t j = 0; j < reals.size(); ++j)
            if (driven[j]) {
                ++outstanding;
                reals[j]->move(targets[j], [this](bool ok, const std::string& why) { real_done(ok, why); });
            }
        real_done(true, {});
    }

    void real_done(bool ok, const std::string& why) {
        if (!ok) failures.push_back(why);
        if (--outstanding > 0) return;
        finish();
    }

    // The reals are all done: judge the virtual's move by where it ended.
    void finish() {
        moving = false, limits_due = true;
        Virtual& vv = v[std::size_t(mover)];
        read_ports();
        std::vector<double> pos;
        std::string why;
        for (const std::string& f : failures) why += (why.empty() ? "" : "; ") + f;
        if (stop_asked) why = "stopped" + (why.empty() ? std::string() : ": " + why);
        if (!eval_forward(pos)) {
            if (why.empty()) why = "the forward expressions faulted at the end of the move";
        } else {
            // the reals' deadbands through `forward`: how far the virtual may be from its target
            double tol = 1e-12 * (1 + std::fabs(move_target));
            const std::vector<double> keep = rbv;
            for (std::size_t j = 0; j < reals.size(); ++j) {
                if (!driven[j]) continue;
                rbv[j] = keep[j] + std::max(st[j].deadband, 1e-12);
                std::vector<double> moved;
                if (eval_forward(moved)) tol += std::fabs(moved[std::size_t(mover)] - pos[std::size_t(mover)]);
                rbv[j] = keep[j];
            }
            const double end = pos[std::size_t(mover)];
            if (why.empty() && !(std::fabs(end - move_target) <= tol))
                why = "ended short at " + fmt(end) + " (target " + fmt(move_target) + ", tolerance " + fmt(tol) + ")";
            for (std::size_t k = 0; k < v.size(); ++k) v[k].position = pos[k];
        }
        if (vv.pending) return; // a newer target: that move decides what the record sees
        vv.busy = false;
        vv.failed = !why.empty();
        if (vv.failed) LOG_WARN(lg, vv.record << ": move to " << fmt(move_target) << " failed: " << why);
    }

    void poll() {
        read_ports();
        std::vector<double> pos;
        if (connected && eval_forward(pos))
            for (std::size_t i = 0; i < v.size(); ++i) {
                Virtual& vv = v[i];
                vv.position = pos[i], vv.valid = true;
                if (moving || vv.busy) vv.synced = NAN;
                else if (!(std::fabs(vv.position - vv.synced) <= vv.mres)) ++vv.syncs, vv.synced = vv.position;
            }
        if (!moving)
            for (std::size_t i = 0; i < v.size(); ++i)
                if (v[i].pending) {
                    start_move(i);
                    if (moving) break;
                }
        // the virtuals' limits: when a real's limits changed, after a move, else every 0.5 s
        std::vector<double> lims;
        for (const auto& s : st) lims.push_back(s.hlm), lims.push_back(s.llm);
        if (lims != seen_limits) limits_due = true, seen_limits = lims;
        if (!moving && (limits_due || ++polls % 50 == 0)) update_limits();
    }

    // --- what the virtual motors' drivers ask
    void request(std::size_t i, double x) {
        Virtual& vv = v[i];
        vv.request = x, vv.pending = true, vv.busy = true, vv.failed = false, vv.lvio = false;
    }
    void refuse(std::size_t i, const char* what) {
        v[i].request = v[i].position;
        fail(i, std::string(what) + " is not available on a compound motor", false);
    }
    void stop() {
        for (Virtual& vv : v)
            if (vv.pending) vv.pending = false, vv.busy = false, vv.failed = true;
        if (!moving) return;
        stop_asked = true;
        for (std::size_t j = 0; j < reals.size(); ++j)
            if (driven[j] && reals[j]) reals[j]->stop();
    }
    pv::MotorDriver::Status status(std::size_t i) const {
        const Virtual& vv = v[i];
        pv::MotorDriver::Status s;
        s.position = std::isfinite(vv.position) ? vv.position : 0;
        s.valid = vv.valid;
        s.done = !vv.busy;
        s.moving = moving && mover == int(i);
        s.direction_positive = !(vv.request < vv.position);
        s.failed = vv.failed, s.limit_violation = vv.lvio;
        s.comm_error = s.problem = !connected;
        s.homed = true;
        s.sync_requests = vv.syncs;
        return s;
    }
};

namespace {

// The motor record's driver of one virtual motor: everything goes to the group.
class VirtualDriver final : public pv::MotorDriver {
public:
    VirtualDriver(CompoundMotors::Group& g, std::size_t i) : g_(g), i_(i) {}
    void move(double dial_target, double, double) override { g_.request(i_, dial_target); }
    void move_velocity(double, double) override { g_.refuse(i_, "jogging"); }
    void home(bool, double, double) override { g_.refuse(i_, "homing"); }
    void stop(double) override { g_.stop(); }
    void set_position(double) override {} // the reals define where a compound motor is
    void set_closed_loop(bool) override {}
    Status status() override { return g_.status(i_); }

private:
    CompoundMotors::Group& g_;
    std::size_t i_;
};

} // namespace

CompoundMotors::CompoundMotors(const std::vector<config::CompoundMotorEntry>& cfg, const std::string& prefix, pv::Database& db)
    : db_(db) {
    pv::DbFile f;
    for (const auto& c : cfg) {
        auto g = std::make_unique<Group>(c, db);
        for (std::size_t i = 0; i < c.virtuals.size(); ++i) {
            const auto& x = c.virtuals[i];
            Group::Virtual& vv = g->v[i];
            vv.record = prefix + x.name;
            vv.mres = x.mres > 0 ? x.mres : std::pow(10.0, -x.prec);
            f.records.push_back(pv::generated_record("motor", vv.record,
                                                     {{"DTYP", "Compound Motor"},
                                                      {"OUT", "@compound(" + c.name + "," + x.name + ")"},
                                                      {"DESC", (x.desc.empty() ? "compound motor " + c.name : x.desc).substr(0, 40)},
                                                      {"EGU", x.egu},
                                                      {"PREC", std::to_string(x.prec)},
                                                      {"MRES", fmt(vv.mres)},
                                                      {"RDBD", fmt(vv.mres)},
                                                      {"VELO", fmt(x.velocity)},
                                                      {"RTRY", "0"}}));
        }
        groups_.push_back(std::move(g));
    }
    db_.load(f);
    // drivers before init: the records start at the compound position once it is known
    for (auto& g : groups_)
        for (std::size_t i = 0; i < g->v.size(); ++i) {
            Group::Virtual& vv = g->v[i];
            vv.driver = std::make_shared<VirtualDriver>(*g, i);
            pv::MotorRecord::from(db_.find(vv.record))->set_driver(vv.driver);
        }
}

CompoundMotors::~CompoundMotors() = default;

void CompoundMotors::start() {
    for (auto& g : groups_) {
        const auto& c = g->cfg;
        for (std::size_t j = 0; j < c.reals.size(); ++j) {
            const auto& r = c.reals[j];
            if (!db_.find(r.pv.substr(0, r.pv.find('.')))) {
                g->remote_real[j] = true; // another IOC's: through Channel Access (connect())
                continue;
            }
            try {
                g->reals[j] = make_local_motor(db_, r.pv);
            } catch (const Error& e) {
                throw Error(r.where + ": compound motor group '" + c.name + "': real '" + r.name + "': " + e.what());
            }
        }
        for (std::size_t k = 0; k < c.inputs.size(); ++k)
            if (!(g->inputs[k] = make_local_reader(db_, c.inputs[k].pv))) g->remote_input[k] = true;
        for (std::size_t i = 0; i < g->v.size(); ++i) {
            Group::Virtual& vv = g->v[i];
            db_.resolve(vv.record + ".HLM", vv.hlm_a);
            db_.resolve(vv.record + ".LLM", vv.llm_a);
        }
        std::size_t moved = 0, remote = 0;
        for (bool d : g->driven) moved += d;
        for (bool r : g->remote_real) remote += r;
        for (bool r : g->remote_input) remote += r;
        LOG_INFO(lg, "group '" << c.name << "': " << g->v.size() << " virtual motor(s) over " << moved << " driven real motor(s)"
                               << (remote ? ", " + std::to_string(remote) + " PV(s) of other IOCs (Channel Access)" : std::string()));
    }
    poll();
}

bool CompoundMotors::needs_client() const {
    for (const auto& g : groups_)
        for (std::size_t j = 0; j < g->reals.size(); ++j)
            if (g->remote_real[j] && !g->reals[j]) return true;
    for (const auto& g : groups_)
        for (std::size_t k = 0; k < g->inputs.size(); ++k)
            if (g->remote_input[k] && !g->inputs[k]) return true;
    return false;
}

void CompoundMotors::connect(ca::Client& client) {
    for (auto& g : groups_) {
        for (std::size_t j = 0; j < g->reals.size(); ++j)
            if (g->remote_real[j] && !g->reals[j]) g->reals[j] = make_ca_motor(client, g->cfg.reals[j].pv);
        for (std::size_t k = 0; k < g->inputs.size(); ++k)
            if (g->remote_input[k] && !g->inputs[k]) g->inputs[k] = make_ca_reader(client, g->cfg.inputs[k].pv);
    }
}

void CompoundMotors::poll() {
    for (auto& g : groups_) g->poll();
}

std::size_t CompoundMotors::groups() const { return groups_.size(); }

std::size_t CompoundMotors::virtual_count() const {
    std::size_t n = 0;
    for (const auto& g : groups_) n += g->v.size();
    return n;
}

double CompoundMotors::evaluate_forward(std::size_t g) {
    std::vector<double> out;
    groups_.at(g)->eval_forward(out);
    return out.empty() ? NAN : out[0];
}

} // namespace beamctl::automation
