// The command line's plan client (see plan_client.hpp).
#include "automation/plan_client.hpp"

#include "automation/number_text.hpp"
#include "automation/plan.hpp"
#include "ca/client.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"
#include "core/signals.hpp"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <memory>

namespace beamctl::automation {

namespace {

constexpr const char* kStatus[] = {"Idle", "Running", "Paused", "Done", "Aborted", "Failed"};

std::string text_of(const ca::Value& v) {
    std::string s;
    for (double c : v.as_doubles()) {
        if (c == 0) break;
        s += char(int(c));
    }
    return s;
}

const config::PlanEntry* find_plan(const config::IocConfig& cfg, const std::string& name) {
    for (const auto& p : cfg.plans)
        if (p.name == name) return &p;
    return nullptr;
}

const char* type_name(config::PlanEntry::Type t) {
    using T = config::PlanEntry::Type;
    return t == T::Scan ? "scan" : t == T::Grid ? "grid" : t == T::List ? "list" : t == T::Align ? "align" : "sequence";
}

} // namespace

int list_plans(const config::IocConfig& cfg, std::ostream& out) {
    if (cfg.plans.empty()) {
        out << cfg.path << ": no plans\n";
        return 1;
    }
    for (const auto& p : cfg.plans) {
        out << p.name << " (" << type_name(p.type) << ")" << (p.desc.empty() ? "" : ": " + p.desc) << "\n";
        if (!p.args.empty()) {
            out << "    args:";
            for (const auto& [n, v] : p.args) out << " " << n << "=" << number_text(v, 6);
            out << "\n";
        }
        out << "    PVs " << cfg.prefix << p.name << ":Start, :Args, :Status, :Message, ...\n";
    }
    return 0;
}

int run_plan_client(const config::IocConfig& cfg, const PlanRunOptions& o, std::ostream& out, std::ostream& err) {
    const config::PlanEntry* plan = find_plan(cfg, o.plan);
    if (!plan) {
        std::string known;
        for (const auto& p : cfg.plans) known += (known.empty() ? "" : ", ") + p.name;
        err << cfg.path << ": no plan '" << o.plan << "' (" << (known.empty() ? "the file has no plans:" : "its plans: " + known) << ")\n";
        return 2;
    }
    std::string args;
    for (const std::string& a : o.args) args += (args.empty() ? "" : " ") + a;
    std::vector<double> values;
    std::string why;
    if (!parse_plan_args(plan->args, args, values, why)) { // the IOC's own parser: a clear message before anything moves
        err << o.plan << ": " << why << "\n";
        return 2;
    }

    block_stop_signals();
    EventLoop loop;
    ca::ClientConfig cc = ca::ClientConfig::from_env();
    if (cfg.ca_port) cc.server_port = *cfg.ca_port; // the IOC file's own port
    ca::Client client(loop, cc);
    const std::string p = cfg.prefix + plan->name + ":";
    auto args_ch = client.channel(p + "Args"), start_ch = client.channel(p + "Start"), status_ch = client.channel(p + "Status"),
         message_ch = client.channel(p + "Message"), file_ch = client.channel(p + "File"), abort_ch = client.channel(p + "Abort"),
         runs_ch = client.channel(p + "Runs");
    const bool align = plan->type == config::PlanEntry::Type::Align;
    std::shared_ptr<ca::Channel> center_ch = align ? client.channel(p + "Center") : nullptr;
    std::shared_ptr<ca::Channel> width_ch = align ? client.channel(p + "Width") : nullptr;

    int rc = -1;          // the exit code, once known
    bool started = false; // the IOC counted a new run (Runs went up): else Start was refused
    double runs_before = 0;
    std::shared_ptr<ca::Monitor> messages;
    std::string last_message;
    double center = NAN, width = NAN;

    // The run ended (or was refused): what the PVs say, then leave.
    auto conclude = [&](bool put_ok, const std::string& put_message) {
        runs_ch->get([&, put_ok, put_message](const ca::Result& n) {
        started = n.ok() && n.value.as_double() > runs_before;
        status_ch->get([&, put_ok, put_message](const ca::Result& s) {
            const int st = s.ok() ? int(s.value.as_double()) : -1;
            message_ch->get([&, st, put_ok, put_message](const ca::Result& m) {
                const std::string msg = m.ok() ? text_of(m.value) : put_message;
                file_ch->get([&, st, msg, put_ok](const ca::Result& f) {
                    const std::string file = f.ok() ? text_of(f.value) : std::string();
                    const char* name = st >= 0 && st < 6 ? kStatus[st] : "unknown";
                    if (!started) {
                        out << o.plan << ": not started: " << msg << "\n";
                        rc = 1;
                    } else {
                        std::string lower = name;
                        for (char& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
                        out << o.plan << ": " << name << (msg == lower ? std::string() : ": " + msg) << "\n"; // "Done", "Failed: why"
                        if (align && st == 3 && std::isfinite(center))
                            out << o.plan << ": centre " << number_text(center, 8) << ", width " << number_text(width, 6) << "\n";
                        if (!file.empty()) out << o.plan << ": file " << file << "\n";
                        rc = put_ok && st == 3 ? 0 : 1;
                    }
                    loop.stop();
                });
            });
        });
        });
    };
    const double deadline = EventLoop::now_s() + o.connect_timeout_s;
    bool asked = false;
    loop.call_every(0.02, [&] {
        if (asked) return;
        const bool all = args_ch->connected() && start_ch->connected() && runs_ch->connected() && status_ch->connected() && message_ch->connected() &&
                         file_ch->connected() && abort_ch->connected() && (!align || (center_ch->connected() && width_ch->connected()));
        if (!all) {
            if (EventLoop::now_s() > deadline) {
                err << o.plan << ": cannot reach " << p << "Start within " << o.connect_timeout_s
                    << " s (is the IOC running? EPICS_CA_ADDR_LIST, EPICS_CA_SERVER_PORT)\n";
                rc = 2;
                loop.stop();
            }
            return;
        }
        asked = true;
        std::vector<char> chars(args.begin(), args.end());
        chars.push_back(0);
        runs_ch->get([&](const ca::Result& n) { runs_before = n.ok() ? n.value.as_double() : 0; });
        args_ch->put_raw(pv::Prim::Char, chars.data(), uint32_t(chars.size()), [&](const ca::Result& r) {
            if (!r.ok()) return conclude(false, r.message);
            if (!o.quiet)
                messages = message_ch->monitor(pv::kDbeValue, [&](const ca::Result& m) {
                    if (!m.ok()) return;
                    const std::string t = text_of(m.value);
                    if (!t.empty() && t != last_message && !last_message.empty()) out << o.plan << ": " << t << "\n" << std::flush;
                    last_message = t.empty() ? " " : t;
                });
            start_ch->put(1.0, [&](const ca::Result& s) {
                if (align) // the fitted centre and width the run ended with
                    center_ch->get([&, s](const ca::Result& c) {
                        center = c.ok() ? c.value.as_double() : NAN;
                        width_ch->get([&, s](const ca::Result& w) {
                            width = w.ok() ? w.value.as_double() : NAN;
                            conclude(s.ok(), s.message);
                        });
                    });
                else
                    conclude(s.ok(), s.message);
            });
        });
    });
    LoopSignals signals(loop, {});
    loop.run();
    if (rc < 0) { // a signal: abort the run, wait for its end
        err << o.plan << ": aborting (again to leave at once)\n";
        abort_ch->put(1.0);
        loop.run();
        if (rc < 0) return 130;
    }
    return rc;
}

} // namespace beamctl::automation
