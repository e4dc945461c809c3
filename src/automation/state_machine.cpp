// State machines with an error latch (see state_machine.hpp).
#include "automation/state_machine.hpp"

#include "automation/expression_names.hpp"
#include "automation/motor_port.hpp"
#include "automation/number_text.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "plc/program.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <optional>

namespace beamctl::automation {

namespace {

log::Logger lg("fsm");

constexpr const char* kResult = "fsm_result_"; // where an expression's value goes
constexpr const char* kMbbStrings[16] = {"ZRST", "ONST", "TWST", "THST", "FRST", "FVST", "SXST", "SVST",
                                         "EIST", "NIST", "TEST", "ELST", "TVST", "TTST", "FTST", "FFST"};

std::string fmt(double v) { return number_text(v, 9); }

std::string utc_now() {
    const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&t, &tm);
    char b[32];
    std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return b;
}

} // namespace

struct StateMachines::Machine {
    struct Step {
        const config::StateMachineEntry::Step* cfg = nullptr;
        std::optional<plc::Program> expr;     // wait_for
        std::unique_ptr<PvWriter> writer;     // put (null until connected, for another IOC's PV)
        bool remote = false;
    };
    config::StateMachineEntry cfg;
    std::size_t index = 0;
    std::string p; // $(P)<name>:
    std::size_t name_base = 0;
    std::vector<std::unique_ptr<PvReader>> readers;
    std::vector<bool> remote_reader;
    bool names_ok = false, names_seen = false;
    std::string missing; // names not readable, for messages
    double result = 0;
    ExpressionNames host;
    std::vector<std::optional<plc::Program>> invariants, guards; // per state, per transition
    std::vector<std::vector<Step>> entry, exits, steps;           // per state, state, transition
    std::vector<int> parent;
    int state = 0, latch = -1, after_ack = 0;
    // the transition under way
    bool busy = false;
    int transition = -1, target = -1;
    std::vector<Step*> plan;
    std::size_t step = 0;
    double t_start = 0, t_step = 0;
    bool waiting = false, step_done = false, step_ok = false;
    std::string step_why, step_text;
    uint64_t step_id = 0;
    std::string error, ack_by, ack_time;
    bool violating = false; // an invariant's violation reported (a machine without a latch stays)
    pv::Record *state_r = nullptr, *busy_r = nullptr, *transition_r = nullptr, *step_r = nullptr, *allowed_r = nullptr,
               *error_r = nullptr, *latched_r = nullptr, *ackby_r = nullptr, *acktime_r = nullptr;

    int state_index(const std::string& n) const {
        for (std::size_t i = 0; i < cfg.states.size(); ++i)
            if (cfg.states[i].name == n) return int(i);
        return -1;
    }
    bool within(int s, int ancestor) const { // s is `ancestor` or one of its sub-states
        for (int k = s; k >= 0; k = parent[std::size_t(k)])
            if (k == ancestor) return true;
        return false;
    }
    bool latched() const { return latch >= 0 && state == latch; }
    bool eval(plc::Program& prog) {
        if (!names_ok) return false;
        result = 0;
        return prog.run() == 0 && result != 0 && std::isfinite(result);
    }
    plc::Program compile(const std::string& expr, const std::string& where, const std::string& what) {
        plc::CompileOptions o;
        o.max_loop_iterations = 100000;
        try {
            return plc::Program::compile(std::string(kResult) + " := (" + expr + ");", what, host, o);
        } catch (const plc::CompileError& e) {
            throw Error(where + ": state machine '" + cfg.name + "': " + what + ": " + e.what());
        }
    }
    std::string allowed() const {
        std::string s;
        if (busy || latched()) return s;
        for (const auto& t : cfg.transitions) {
            const int from = state_index(t.from);
            if (within(state, from) && s.find(t.to) == std::string::npos) s += (s.empty() ? "" : ", ") + t.to;
        }
        return s;
    }
};

StateMachines::StateMachines(const std::vector<config::StateMachineEntry>& cfg, const std::string& prefix, pv::Database& db,
                             std::function<double()> clock)
    : db_(db), clock_(std::move(clock)) {
    std::size_t n_names = 0, n_states = 0;
    for (const auto& c : cfg) n_names += c.names.size(), n_states += c.states.size();
    state_values_.assign(cfg.size(), 0);
    constants_.assign(n_states, 0);
    names_.assign(n_names, 0);
    std::size_t name_base = 0;
    for (std::size_t i = 0; i < cfg.size(); ++i) {
        auto m = std::make_unique<Machine>();
        m->cfg = cfg[i];
        m->index = i;
        m->p = prefix + cfg[i].name + ":";
        m->name_base = name_base;
        name_base += cfg[i].names.size();
        machines_.push_back(std::move(m));
    }
    // every machine's expressions see its own names, every machine's state and state constants
    std::size_t k = 0;
    for (auto& mp : machines_)
        for (std::size_t s = 0; s < mp->cfg.states.size(); ++s) constants_[k++] = double(s);
    pv::DbFile f;
    for (auto& mp : machines_) {
        Machine& m = *mp;
        const auto& c = m.cfg;
        for (std::size_t j = 0; j < c.names.size(); ++j) m.host.bind(c.names[j].first, &names_[m.name_base + j], false);
        std::size_t ck = 0;
        for (auto& other : machines_) {
            m.host.bind(other->cfg.name, &state_values_[other->index], false);
            for (const auto& st : other->cfg.states) m.host.bind(other->cfg.name + "." + st.name, &constants_[ck++], false);
        }
        m.host.bind(kResult, &m.result, true);
        m.parent.assign(c.states.size(), -1);
        for (std::size_t s = 0; s < c.states.size(); ++s) m.parent[s] = m.state_index(c.states[s].parent);
        m.state = std::max(0, m.state_index(c.initial));
        m.latch = m.state_index(c.latch);
        m.after_ack = std::max(0, m.state_index(c.after_ack));
        auto compile_steps = [&](const std::vector<config::StateMachineEntry::Step>& in, const std::string& what) {
            std::vector<Machine::Step> out(in.size());
            for (std::size_t j = 0; j < in.size(); ++j) {
                out[j].cfg = &in[j];
                if (in[j].kind == config::StateMachineEntry::Step::Kind::WaitFor)
                    out[j].expr = m.compile(in[j].expr, in[j].where, what + " step " + std::to_string(j + 1));
            }
            return out;
        };
        for (const auto& st : m.cfg.states) {
            m.invariants.push_back(st.invariant.empty() ? std::nullopt
                                                        : std::optional(m.compile(st.invariant, st.where, "invariant of " + st.name)));
            m.entry.push_back(compile_steps(st.entry, "entry of " + st.name));
            m.exits.push_back(compile_steps(st.exit, "exit of " + st.name));
        }
        for (const auto& t : m.cfg.transitions) {
            m.guards.push_back(t.guard.empty() ? std::nullopt : std::optional(m.compile(t.guard, t.where, "guard of " + t.name)));
            m.steps.push_back(compile_steps(t.steps, "transition " + t.name));
        }
        std::vector<std::pair<std::string, std::string>> mbb;
        for (std::size_t s = 0; s < c.states.size(); ++s) mbb.emplace_back(kMbbStrings[s], c.states[s].name);
        auto with = [](std::vector<std::pair<std::string, std::string>> a, std::vector<std::pair<std::string, std::string>> b) {
            a.insert(a.end(), b.begin(), b.end());
            return a;
        };
        f.records.push_back(pv::generated_record("mbbi", m.p + "State", with(mbb, {{"VAL", std::to_string(m.state)}})));
        f.records.push_back(pv::generated_record("mbbo", m.p + "Request", with(mbb, {{"VAL", std::to_string(m.state)}})));
        f.records.push_back(pv::generated_record("bi", m.p + "Busy", {{"ZNAM", "Idle"}, {"ONAM", "Busy"}}));
        f.records.push_back(pv::generated_record("bi", m.p + "Latched", {{"ZNAM", "No"}, {"ONAM", "Latched"}, {"OSV", "MAJOR"}}));
        f.records.push_back(pv::generated_record("bo", m.p + "Ack", {{"ZNAM", "Done"}, {"ONAM", "Ack"}}));
        for (const char* r : {"Transition", "Step", "AckBy", "AckTime"}) f.records.push_back(pv::generated_record("stringin", m.p + r, {}));
        for (const char* r : {"Allowed", "Error"})
            f.records.push_back(pv::generated_record("waveform", m.p + r, {{"FTVL", "CHAR"}, {"NELM", "512"}}));
    }
    db_.load(f);
}

StateMachines::~StateMachines() = default;

void StateMachines::start() {
    for (auto& mp : machines_) {
        Machine& m = *mp;
        const auto& c = m.cfg;
        for (std::size_t j = 0; j < c.names.size(); ++j) {
            m.readers.push_back(make_local_reader(db_, c.names[j].second));
            m.remote_reader.push_back(!m.readers.back());
        }
        for (auto* list : {&m.entry, &m.exits, &m.steps})
            for (auto& steps : *list)
                for (auto& s : steps)
                    if (s.cfg->kind == config::StateMachineEntry::Step::Kind::Put && !(s.writer = make_local_writer(db_, s.cfg->pv)))
                        s.remote = true;
        auto rec = [&](const char* n) { return db_.find(m.p + n); };
        m.state_r = rec("State"), m.busy_r = rec("Busy"), m.transition_r = rec("Transition"), m.step_r = rec("Step");
        m.allowed_r = rec("Allowed"), m.error_r = rec("Error"), m.latched_r = rec("Latched");
        m.ackby_r = rec("AckBy"), m.acktime_r = rec("AckTime");
        Machine* mm = &m;
        rec("Request")->put_hook = [this, mm](pv::Record& r, const pv::FieldDesc&) { return request(*mm, int(pv::get_value(r))); };
        rec("Ack")->put_hook = [this, mm](pv::Record& r, const pv::FieldDesc&) {
            return pv::get_value(r) != 0 ? acknowledge(*mm) : pv::PutStatus::Ok;
        };
        state_values_[m.index] = m.state;
        LOG_INFO(lg, m.cfg.name << ": " << c.states.size() << " states, " << c.transitions.size() << " transitions, in "
                                << c.states[std::size_t(m.state)].name);
    }
    for (auto& mp : machines_) publish(*mp);
}

bool StateMachines::needs_client() const {
    for (const auto& mp : machines_) {
        for (std::size_t j = 0; j < mp->readers.size(); ++j)
            if (mp->remote_reader[j] && !mp->readers[j]) return true;
        for (auto* list : {&mp->entry, &mp->exits, &mp->steps})
            for (const auto& steps : *list)
                for (const auto& s : steps)
                    if (s.remote && !s.writer) return true;
    }
    return false;
}

void StateMachines::connect(ca::Client& client) {
    for (auto& mp : machines_) {
        for (std::size_t j = 0; j < mp->readers.size(); ++j)
            if (mp->remote_reader[j] && !mp->readers[j]) mp->readers[j] = make_ca_reader(client, mp->cfg.names[j].second);
        for (auto* list : {&mp->entry, &mp->exits, &mp->steps})
            for (auto& steps : *list)
                for (auto& s : steps)
                    if (s.remote && !s.writer) s.writer = make_ca_writer(client, s.cfg->pv);
    }
}

void StateMachines::on_latch(LatchHook hook) { latch_hook_ = std::move(hook); }

StateMachines::Machine* StateMachines::find(const std::string& name) const {
    for (const auto& m : machines_)
        if (m->cfg.name == name) return m.get();
    return nullptr;
}

int StateMachines::state(const std::string& machine) const {
    const Machine* m = find(machine);
    return m ? m->state : -1;
}
std::string StateMachines::state_name(const std::string& machine) const {
    const Machine* m = find(machine);
    return m ? m->cfg.states[std::size_t(m->state)].name : std::string();
}
bool StateMachines::latched(const std::string& machine) const {
    const Machine* m = find(machine);
    return m && m->latched();
}
bool StateMachines::busy(const std::string& machine) const {
    const Machine* m = find(machine);
    return m && m->busy;
}
std::string StateMachines::error(const std::string& machine) const {
    const Machine* m = find(machine);
    return m ? m->error : std::string();
}

void StateMachines::publish(Machine& m) {
    state_values_[m.index] = m.state;
    pv::set_value(db_, *m.state_r, m.state, false);
    pv::set_value(db_, *m.busy_r, m.busy, false);
    pv::set_value(db_, *m.latched_r, m.latched(), false);
    pv::set_string(db_, *m.transition_r, m.busy ? m.cfg.transitions[std::size_t(m.transition)].name : "");
    pv::set_string(db_, *m.step_r, m.busy ? m.step_text : "");
    pv::set_text(db_, *m.allowed_r, m.allowed());
    pv::set_text(db_, *m.error_r, m.error);
    pv::set_string(db_, *m.ackby_r, m.ack_by);
    pv::set_string(db_, *m.acktime_r, m.ack_time);
}

void StateMachines::latch(Machine& m, const std::string& why) {
    m.busy = false;
    m.error = why;
    if (m.latch >= 0) m.state = m.latch;
    LOG_ERR(lg, m.cfg.name << ": " << (m.latch >= 0 ? "latched in " + m.cfg.states[std::size_t(m.latch)].name + ": " : std::string()) << why);
    publish(m);
    if (latch_hook_ && m.latch >= 0) latch_hook_(m.cfg.name, why);
}

bool StateMachines::latch(const std::string& machine, const std::string& why) {
    Machine* m = find(machine);
    if (!m || m->latch < 0) return false;
    if (!m->latched()) latch(*m, why); // already latched: the first error stands
    return true;
}

pv::PutStatus StateMachines::request(Machine& m, int to) {
    const auto& c = m.cfg;
    auto refuse = [&](const std::string& why) {
        LOG_WARN(lg, m.cfg.name << ": request refused: " << why);
        return pv::PutStatus::Failed;
    };
    if (to < 0 || std::size_t(to) >= c.states.size()) return refuse("no state " + std::to_string(to));
    const std::string& name = c.states[std::size_t(to)].name;
    if (m.latched()) return refuse("latched (" + m.error + "); write 1 to " + m.p + "Ack first");
    if (m.busy) return refuse("transition " + c.transitions[std::size_t(m.transition)].name + " is under way");
    if (to == m.state) return pv::PutStatus::Ok;
    int t = -1;
    for (std::size_t i = 0; i < c.transitions.size() && t < 0; ++i)
        if (c.transitions[i].to == name && m.within(m.state, m.state_index(c.transitions[i].from))) t = int(i);
    if (t < 0)
        return refuse("no transition from " + c.states[std::size_t(m.state)].name + " to " + name + " (allowed: " +
                      (m.allowed().empty() ? "none" : m.allowed()) + ")");
    const auto& tr = c.transitions[std::size_t(t)];
    if (m.guards[std::size_t(t)] && !m.eval(*m.guards[std::size_t(t)])) {
        latch(m, "guard of transition " + tr.name + " does not hold: " + tr.guard +
                     (m.names_ok ? std::string() : " (not readable: " + m.missing + ")"));
        return pv::PutStatus::Failed;
    }
    m.busy = true, m.transition = t, m.target = to, m.violating = false;
    m.plan.clear();
    for (auto& s : m.exits[std::size_t(m.state)]) m.plan.push_back(&s);
    for (auto& s : m.steps[std::size_t(t)]) m.plan.push_back(&s);
    for (auto& s : m.entry[std::size_t(to)]) m.plan.push_back(&s);
    m.step = 0, m.waiting = false, m.t_start = clock_(), m.step_text.clear();
    LOG_INFO(lg, m.cfg.name << ": " << tr.name << " (" << c.states[std::size_t(m.state)].name << " -> " << name << ", "
                            << m.plan.size() << " steps)");
    publish(m); // the steps run from the next poll, outside this put
    return pv::PutStatus::Ok;
}

pv::PutStatus StateMachines::acknowledge(Machine& m) {
    if (!m.latched()) {
        LOG_WARN(lg, m.cfg.name << ": Ack refused: not latched");
        return pv::PutStatus::Failed;
    }
    const std::string who = db_.put_origin().empty() ? std::string("the IOC") : std::string(db_.put_origin());
    m.ack_by = who, m.ack_time = utc_now();
    m.state = m.after_ack, m.violating = false;
    LOG_WARN(lg, m.cfg.name << ": latch acknowledged by " << who << " at " << m.ack_time << " (error: " << m.error << "); now in "
                            << m.cfg.states[std::size_t(m.state)].name);
    publish(m);
    return pv::PutStatus::Ok;
}

void StateMachines::run(Machine& m, double now) {
    using Kind = config::StateMachineEntry::Step::Kind;
    const auto& tr = m.cfg.transitions[std::size_t(m.transition)];
    auto fail = [&](const std::string& why) {
        const std::string at = m.step < m.plan.size() ? " at step " + std::to_string(m.step + 1) + "/" + std::to_string(m.plan.size()) +
                                                            " (" + m.plan[m.step]->cfg->where + ")"
                                                      : std::string();
        latch(m, "transition " + tr.name + " failed" + at + ": " + why);
    };
    if (now - m.t_start > tr.timeout) return fail("timed out after " + fmt(tr.timeout) + " s");
    while (m.step < m.plan.size()) {
        Machine::Step& s = *m.plan[m.step];
        const auto& sc = *s.cfg;
        if (!m.waiting) {
            m.waiting = true, m.step_done = false, m.t_step = now;
            const std::string n = std::to_string(m.step + 1) + "/" + std::to_string(m.plan.size()) + " ";
            m.step_text = sc.kind == Kind::Put ? n + "put " + sc.pv + " = " + fmt(sc.value)
                          : sc.kind == Kind::WaitFor ? n + "wait for " + sc.expr
                                                     : n + "delay " + fmt(sc.seconds) + " s";
            pv::set_string(db_, *m.step_r, m.step_text);
            if (sc.kind == Kind::Put) {
                if (!s.writer) return fail(sc.pv + " is not reachable");
                const uint64_t id = ++m.step_id;
                Machine* mm = &m;
                s.writer->put(sc.value, sc.wait, [mm, id](bool ok, const std::string& why) {
                    if (mm->step_id != id) return; // a step of an abandoned transition
                    mm->step_done = true, mm->step_ok = ok, mm->step_why = why;
                });
            }
        }
        const bool timed_out = sc.seconds > 0 && sc.kind != Kind::Delay && now - m.t_step > sc.seconds;
        if (sc.kind == Kind::Put) {
            if (!m.step_done) return timed_out ? fail("the put to " + sc.pv + " did not complete within " + fmt(sc.seconds) + " s") : void();
            if (!m.step_ok) return fail(m.step_why);
        } else if (sc.kind == Kind::WaitFor) {
            if (!m.eval(*s.expr))
                return timed_out ? fail(sc.expr + " did not hold within " + fmt(sc.seconds) + " s" +
                                        (m.names_ok ? std::string() : " (not readable: " + m.missing + ")"))
                                 : void();
        } else if (now - m.t_step < sc.seconds) {
            return;
        }
        m.waiting = false;
        ++m.step;
    }
    m.busy = false;
    m.state = m.target;
    LOG_INFO(lg, m.cfg.name << ": " << tr.name << " done: in " << m.cfg.states[std::size_t(m.state)].name);
    publish(m);
}

void StateMachines::poll() {
    const double now = clock_();
    for (auto& mp : machines_) {
        Machine& m = *mp;
        m.names_ok = true;
        m.missing.clear();
        for (std::size_t j = 0; j < m.readers.size(); ++j) {
            double v = 0;
            if (m.readers[j] && m.readers[j]->read(v)) names_[m.name_base + j] = v;
            else m.names_ok = false, m.missing += (m.missing.empty() ? "" : ", ") + m.cfg.names[j].second;
        }
        m.names_seen = m.names_seen || m.names_ok;
    }
    for (auto& mp : machines_) {
        Machine& m = *mp;
        if (m.busy) {
            run(m, now);
            continue;
        }
        if (m.latched() || !m.names_seen) continue; // invariants: once every name has been read
        bool holds = true;
        for (int s = m.state; s >= 0 && holds; s = m.parent[std::size_t(s)])
            if (auto& inv = m.invariants[std::size_t(s)]; inv && !m.eval(*inv)) {
                holds = false;
                if (m.violating) break; // reported once (a machine without a latch stays where it is)
                m.violating = true;
                const auto& st = m.cfg.states[std::size_t(s)];
                latch(m, "the invariant of " + st.name + " no longer holds: " + st.invariant +
                             (m.names_ok ? std::string() : " (not readable: " + m.missing + ")"));
            }
        if (holds) m.violating = false;
    }
}

} // namespace beamctl::automation
