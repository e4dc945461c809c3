// beamctl: the command-line program. Subcommands:
//   run      run an IOC from its configuration (buses, RT engine, PVs, CA server)
//   check    load a configuration and report every error
//   softioc  serve EPICS database files over Channel Access (like EPICS softIoc)
//   db       print the loaded database as .db text
//   sim      run a simulated EtherCAT segment behind a UDP socket or on a network interface
//   plc check    compile PLC files and report every error
//   rcp-sim  stand in for a rapid-control-prototyping machine
//   ca-repeater  the Channel Access repeater (also when invoked as `caRepeater`, EPICS's name)
#include "ca/access_security.hpp"
#include "ca/repeater.hpp"
#include "ca/server.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"
#include "core/log.hpp"
#include "core/macros.hpp"
#include "core/signals.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"
#include "config/ioc_config.hpp"
#include "ethercat/catalog.hpp"
#include "bridge/rcp/rcp_sim.hpp"
#include "ioc/check.hpp"
#include "ioc/ioc.hpp"
#include "plc/runtime.hpp"
#include "rt/engine.hpp"
#include "ethercat/sim/raw_server.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <cstdio>
#include <iostream>
#include <unistd.h>

#ifndef BEAMCTL_VERSION
#define BEAMCTL_VERSION "0.1.0"
#endif

namespace {

using namespace beamctl;
log::Logger lg("beamctl");

struct DbOptions {
    std::vector<std::string> macros; // -m "P=X:,R=y" (repeatable)
    std::vector<std::string> files;
    std::vector<std::string> include_path;
};

// -m "A=x,B=y" options (repeatable; a later definition wins) as one map; errors name "-m".
MacroMap macro_options(const std::vector<std::string>& defs) {
    MacroMap macros;
    for (const auto& d : defs)
        for (auto& [k, v] : parse_macro_defs(d, SourceLoc{"-m", 1, 1})) macros[k] = v;
    return macros;
}

void load_databases(pv::Database& db, const DbOptions& o) {
    MacroMap macros = macro_options(o.macros);
    for (auto& f : o.files) db.load(pv::load_db_file(f, macros, o.include_path));
    db.init_records();
}

// `beamctl plc check`: compiles PLC files and reports every error; with --ioc, against that
// IOC's buses, axes and plugins, else accepting every well-formed name of the known namespaces.
struct PlcCheckOptions {
    std::vector<std::string> macros, include_path, files;
    std::string ioc_file;
    double rate_ms = -1;
};

int run_plc_check(const PlcCheckOptions& o) {
    std::unique_ptr<rt::MonotonicClock> clock;
    std::unique_ptr<ioc::Ioc> ioc;
    plc::PlcRuntime::Options opt;
    opt.check_only = true;
    std::vector<std::string> include_path = o.include_path;
    if (!o.ioc_file.empty()) {
        config::IocConfig cfg = config::IocConfig::load(o.ioc_file);
        // FILE is compiled as the IOC's PLCs are: with their include directories after -I's.
        for (const auto& plc : cfg.plcs)
            for (const auto& dir : plc.include)
                if (std::find(include_path.begin(), include_path.end(), dir) == include_path.end())
                    include_path.push_back(dir);
        clock = std::make_unique<rt::MonotonicClock>();
        ioc = std::make_unique<ioc::Ioc>(std::move(cfg), *clock);
        opt = ioc->plcs().check_options();
    }
    MacroMap macros = macro_options(o.macros);
    plc::PlcRuntime check(opt);
    int failed = 0, id = 0;
    for (const auto& f : o.files) {
        std::ifstream in(f, std::ios::binary);
        if (!in) {
            std::fprintf(stderr, "%s: cannot open: %s\n", f.c_str(), std::strerror(errno));
            ++failed;
            continue;
        }
        std::stringstream ss;
        ss << in.rdbuf();
        plc::PlcSource src;
        src.id = id++;
        src.file = f;
        src.text = ss.str();
        src.macros = macros;
        src.include_path = include_path;
        src.rate_ms = o.rate_ms;
        try {
            check.add(src);
            std::printf("%s: OK\n", f.c_str());
        } catch (const plc::CompileError& e) {
            for (const auto& err : e.errors()) std::fprintf(stderr, "%s\n", err.c_str());
            ++failed;
        } catch (const Error& e) {
            std::fprintf(stderr, "%s\n", e.what());
            ++failed;
        }
    }
    return failed ? 1 : 0;
}

int run_softioc(const DbOptions& o, const std::string& acf_path) {
    pv::Database db;
    load_databases(db, o);
    ca::AccessSecurity acf;
    if (!acf_path.empty()) acf = ca::AccessSecurity::load_file(acf_path);

    EventLoop loop;
    ca::Server server(loop, db, ca::ServerConfig::from_env());
    server.set_access_security(acf);
    server.start();

    // Signals: TERM/INT stop cleanly, HUP reloads the access-security file.
    LoopSignals signals(loop, acf_path.empty() ? std::function<void()>()
                                               : [&] { server.reload_access_security(acf_path); });
    if (!db.records().empty()) loop.call_every(0.01, [&db] { db.scan_periodic(EventLoop::now_s()); });

    std::printf("ready: CA on %s, %zu PVs\n", server.listen_description().c_str(), db.size());
    std::printf("  try: EPICS_CA_ADDR_LIST=127.0.0.1:%u EPICS_CA_AUTO_ADDR_LIST=NO caget <pv>\n",
                unsigned(server.udp_port()));
    std::fflush(stdout);
    loop.run();
    return 0;
}

volatile bool g_sim_stop = false;

int run_sim(const std::string& file, const std::string& bind, int port, const std::string& iface, bool busy_poll) {
    const ethercat::Catalog& cat = ethercat::Catalog::builtin();
    ethercat::sim::SimConfig cfg = ethercat::sim::SimConfig::load(file, cat);
    if (cfg.slaves.empty()) throw Error(SB() << file << ": slaves: is required for beamctl sim");
    ethercat::sim::Segment seg;
    cfg.build(seg, cat);
    struct sigaction sa {};
    sa.sa_handler = [](int) { g_sim_stop = true; };
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    if (!iface.empty()) {
        ethercat::sim::RawServer server(seg, iface, busy_poll);
        std::printf("ready: simulated segment of %zu slaves on interface %s\n", seg.size(), iface.c_str());
        std::fflush(stdout);
        server.run(g_sim_stop);
        LOG_INFO(lg, "sim: served " << server.frames << " frames on " << iface << " (" << server.ignored
                                    << " ignored, " << server.send_errors << " send errors)");
        return 0;
    }
    ethercat::sim::UdpServer server(seg, bind, uint16_t(port));
    std::printf("ready: simulated segment of %zu slaves on udp %s:%u\n", seg.size(), bind.c_str(),
                unsigned(server.port()));
    std::fflush(stdout);
    server.run(g_sim_stop);
    LOG_INFO(lg, "sim: served " << server.frames << " frames");
    return 0;
}

// `beamctl run` / `check` options: the IOC file, -m macros for its text, --ca-port.
struct IocOptions {
    std::string file;
    std::vector<std::string> macros;
    int ca_port = 0; // 0: ioc.yaml's ca: port, else EPICS_CAS_SERVER_PORT, else 5064
    config::IocConfig load() const {
        config::IocConfig cfg = config::IocConfig::load(file, macro_options(macros));
        if (ca_port) cfg.ca_port = uint16_t(ca_port);
        return cfg;
    }
};

void add_ioc_options(CLI::App& cmd, IocOptions& o) {
    cmd.add_option("-m,--macros", o.macros,
                   "Macros for the IOC file's $(NAME) / ${NAME} references, e.g. \"P=LAB:,PORT=5070\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    cmd.add_option("--ca-port", o.ca_port,
                   "Channel Access server port (overrides ca: port in the IOC file and EPICS_CAS_SERVER_PORT)")
        ->check(CLI::Range(1, 65535));
    cmd.add_option("file", o.file, "IOC configuration (ioc.yaml)")->required();
}

// Levenshtein distance, for "did you mean" on a mistyped subcommand or option.
std::size_t edit_distance(const std::string& a, const std::string& b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diag = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diag = up;
        }
    }
    return row[b.size()];
}

// " (did you mean 'check'?)" when one of `names` is close to `word`, else "".
std::string did_you_mean(const std::string& word, const std::vector<std::string>& names) {
    std::string best;
    std::size_t best_d = std::max<std::size_t>(1, word.size() / 3) + 1; // a third of it may differ
    if (word.size() < 3) return best;
    for (const auto& n : names) {
        std::size_t d = edit_distance(word, n);
        if (d < best_d) best_d = d, best = n;
    }
    return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}

std::vector<std::string> subcommand_names(const CLI::App& cmd) {
    std::vector<std::string> names;
    for (const CLI::App* sub : cmd.get_subcommands([](const CLI::App*) { return true; }))
        if (!sub->get_name().empty()) names.push_back(sub->get_name());
    return names;
}

std::vector<std::string> option_names(const CLI::App& cmd) {
    std::vector<std::string> names{"--help"};
    for (const CLI::Option* opt : cmd.get_options()) {
        for (const auto& l : opt->get_lnames()) names.push_back("--" + l);
        for (const auto& s : opt->get_snames()) names.push_back("-" + s);
    }
    return names;
}

// A command-line error, reported on stderr with the command it belongs to: every unknown
// subcommand, option or surplus argument by name (with the closest known one), then CLI11's own
// complaint unless the unknown words explain it, then where help is. Returns exit code 2.
int report_usage_error(const CLI::App& app, const CLI::ParseError& e) {
    // The chain of subcommands that were recognised: beamctl, beamctl plc, beamctl plc check.
    std::vector<const CLI::App*> chain{&app};
    while (!chain.back()->get_subcommands().empty()) chain.push_back(chain.back()->get_subcommands().front());
    auto path = [&](std::size_t upto) {
        std::string p = "beamctl";
        for (std::size_t i = 1; i <= upto; ++i) p += " " + chain[i]->get_name();
        return p;
    };
    bool unknown_subcommand = false;
    std::size_t help_at = chain.size() - 1;
    for (std::size_t i = 0; i < chain.size(); ++i) {
        const CLI::App& cmd = *chain[i];
        for (const std::string& word : cmd.remaining(false)) {
            const std::vector<std::string> subs = subcommand_names(cmd);
            if (word.size() > 1 && word[0] == '-') {
                std::string name = word.substr(0, word.find('='));
                std::fprintf(stderr, "%s: unknown option '%s'%s\n", path(i).c_str(), name.c_str(),
                             did_you_mean(name, option_names(cmd)).c_str());
            } else if (!subs.empty() && cmd.get_subcommands().empty()) {
                std::string list;
                for (const auto& s : subs) list += " " + s;
                std::fprintf(stderr, "%s: unknown subcommand '%s'%s; subcommands:%s\n", path(i).c_str(),
                             word.c_str(), did_you_mean(word, subs).c_str(), list.c_str());
                unknown_subcommand = true;
                help_at = std::min(help_at, i);
                break; // the words after it were meant for that subcommand
            } else {
                std::fprintf(stderr, "%s: unexpected argument '%s'\n", path(i).c_str(), word.c_str());
            }
            help_at = std::min(help_at, i);
        }
    }
    const bool explained = dynamic_cast<const CLI::ExtrasError*>(&e) ||
                           (unknown_subcommand && dynamic_cast<const CLI::RequiredError*>(&e));
    if (!explained) {
        std::string what = e.what();
        if (what == "A subcommand is required") {
            std::string list;
            for (const auto& s : subcommand_names(*chain.back())) list += " " + s;
            what = "a subcommand is required:" + list;
        }
        std::fprintf(stderr, "%s: %s\n", path(chain.size() - 1).c_str(), what.c_str());
        help_at = chain.size() - 1;
    }
    std::fprintf(stderr, "Run '%s --help' for %s.\n", path(help_at).c_str(),
                 chain[help_at]->get_subcommands([](const CLI::App*) { return true; }).empty()
                     ? "its options" : "the subcommands and options");
    return 2;
}

} // namespace

int main(int argc, char** argv) {
    // libca spawns `caRepeater` from PATH; a symlink of that name to beamctl serves it.
    if (argc > 0 && std::filesystem::path(argv[0]).filename() == "caRepeater")
        return ca::ca_repeater_main(argc, argv);
    CLI::App app{"beamctl: beamline control engine (EPICS Channel Access server, PV database)"};
    app.set_version_flag("--version", std::string("beamctl ") + BEAMCTL_VERSION);
    app.require_subcommand(1);

    DbOptions soft;
    std::string acf;
    auto* softioc = app.add_subcommand("softioc", "Serve EPICS database files over Channel Access");
    softioc->add_option("-m,--macros", soft.macros, "Macro definitions, e.g. \"P=DEMO:,R=x\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    softioc->add_option("-I,--include", soft.include_path, "Search path for include \"file\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    softioc->add_option("--acf", acf, "EPICS access-security file (reloaded on SIGHUP)");
    softioc->add_option("files", soft.files, "Database files (.db)")->required();

    DbOptions dbo;
    auto* dbcmd = app.add_subcommand("db", "Print the loaded database as .db text");
    dbcmd->add_option("-m,--macros", dbo.macros, "Macro definitions, e.g. \"P=DEMO:,R=x\" (for an ioc.yaml: its $(NAME) references)")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    dbcmd->add_option("-I,--include", dbo.include_path, "Search path for include \"file\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    dbcmd->add_option("files", dbo.files, "Database files (.db)")->required();

    IocOptions runo, checko;
    auto* runcmd = app.add_subcommand("run", "Run an IOC: buses, RT engine, PVs and CA server (ioc.yaml)");
    add_ioc_options(*runcmd, runo);
    auto* checkcmd = app.add_subcommand("check", "Load an IOC configuration and report errors (exit 1 on any)");
    add_ioc_options(*checkcmd, checko);

    PlcCheckOptions plco;
    auto* plccmd = app.add_subcommand("plc", "Soft PLC tools");
    plccmd->require_subcommand(1);
    auto* plccheck = plccmd->add_subcommand("check", "Compile PLC files and report every error (exit 1 on any)");
    plccheck->add_option("-m,--macros", plco.macros, "Macro definitions, e.g. \"AX=1,M=ec0\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    plccheck->add_option("-I,--include", plco.include_path, "Search path for include \"file\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    plccheck->add_option("--ioc", plco.ioc_file, "Bind names against this IOC configuration (buses, axes, plugins)");
    plccheck->add_option("files", plco.files, "PLC files")->required();

    std::string rcp_model;
    bridge::rcp::RcpSimOptions rcpo;
    auto* rcpcmd = app.add_subcommand("rcp-sim", "Stand in for a rapid-control-prototyping machine: run MODEL.yaml, send beacons and data, take writes");
    rcpcmd->add_option("model", rcp_model, "Model file (examples/rcp/model.yaml)")->required();
    rcpcmd->add_option("--ioc-host", rcpo.ioc_host, "IPv4 address of the IOC's bridge (overrides ioc.host)");
    rcpcmd->add_option("--ioc-port", rcpo.ioc_port, "UDP port of the IOC's bridge (overrides ioc.port)")->check(CLI::Range(1, 65535));
    rcpcmd->add_option("--port", rcpo.listen_port, "UDP port this machine takes writes on (0: any free port)")->check(CLI::Range(0, 65535));
    rcpcmd->add_option("--rate", rcpo.rate_hz, "Model rate [Hz] (overrides rate_hz)")->check(CLI::Range(1.0, 100000.0));
    rcpcmd->add_option("--duration", rcpo.duration_s, "Stop after this many seconds (default: until SIGINT/SIGTERM)");

    std::string sim_file, sim_bind = "127.0.0.1", sim_iface;
    int sim_port = 0x88A4;
    bool sim_busy_poll = false;
    auto* simcmd = app.add_subcommand("sim", "Run a simulated EtherCAT segment (SIM.yaml) behind UDP or on an interface");
    simcmd->add_option("file", sim_file, "Simulator configuration (slaves:, wiring:)")->required();
    auto* sim_udp = simcmd->add_option("--udp", sim_port, "UDP port for EtherCAT frames (0: any free port)")
                        ->check(CLI::Range(0, 65535));
    auto* sim_bind_opt = simcmd->add_option("--bind", sim_bind, "Address to bind (default 127.0.0.1)");
    auto* sim_iface_opt =
        simcmd->add_option("--iface", sim_iface,
                           "Serve raw EtherCAT frames on this network interface instead of UDP (root or CAP_NET_RAW)")
            ->excludes(sim_udp)
            ->excludes(sim_bind_opt);
    simcmd->add_flag("--busy-poll", sim_busy_poll,
                     "With --iface: spin on the socket instead of sleeping (answers at once like hardware; keeps a CPU busy)")
        ->needs(sim_iface_opt);

    int repeater_port = 0;
    auto* repcmd = app.add_subcommand(
        "ca-repeater", "Run the Channel Access repeater (EPICS caRepeater): fan CA server beacons out to this host's clients");
    repcmd->add_option("--port", repeater_port, "UDP port (default: EPICS_CA_REPEATER_PORT, else 5065)")
        ->check(CLI::Range(1, 65535));

    try {
        app.parse(argc, argv);
    } catch (const CLI::Success& e) { // --help, --version
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        return report_usage_error(app, e);
    }
    try {
        log::validate(); // BEAMCTL_LOG, against the loggers registered during static initialisation
        if (*softioc) return run_softioc(soft, acf);
        if (*plccheck) return run_plc_check(plco);
        if (*rcpcmd) return bridge::rcp::run_rcp_sim(rcp_model, rcpo);
        if (*repcmd)
            return ca::run_ca_repeater(repeater_port ? uint16_t(repeater_port) : ca::repeater_port_from_env());
        if (*simcmd) return run_sim(sim_file, sim_bind, sim_port, sim_iface, sim_busy_poll);
        if (*runcmd) {
            rt::MonotonicClock clock;
            ioc::Ioc ioc(runo.load(), clock);
            return ioc.run();
        }
        if (*checkcmd) return ioc::run_check(checko.file, macro_options(checko.macros)); // every error
        if (*dbcmd) {
            if (dbo.files.size() == 1 && dbo.files[0].size() > 5 &&
                (dbo.files[0].ends_with(".yaml") || dbo.files[0].ends_with(".yml"))) {
                rt::MonotonicClock clock;
                ioc::Ioc ioc(config::IocConfig::load(dbo.files[0], macro_options(dbo.macros)), clock);
                ioc.database().write_db(std::cout);
                return 0;
            }
            pv::Database db;
            load_databases(db, dbo);
            db.write_db(std::cout);
            return 0;
        }
    } catch (const plc::CompileError& e) {
        for (const auto& err : e.errors()) std::fprintf(stderr, "%s\n", err.c_str());
        return 1;
    } catch (const Error& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "beamctl: %s\n", e.what());
        return 1;
    }
    return 0;
}
