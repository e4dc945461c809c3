// beamctl: the command-line program. Subcommands:
//   run      run an IOC from its configuration (buses, RT engine, PVs, CA server)
//   check    load a configuration and report every error
//   signals  list an IOC's signals (the registry): name, type, direction, owner, writer, PV
//   softioc  serve EPICS databases over Channel Access: softIoc's command line, st.cmd scripts
//   db       print the loaded database as .db text
//   sim      run a simulated EtherCAT segment behind a UDP socket or on a network interface
//   plc check    compile PLC files and report every error
//   rcp-sim  stand in for a rapid-control-prototyping machine
//   ca-repeater  the Channel Access repeater (also when invoked as `caRepeater`, EPICS's name)
//   esi import   turn vendor ESI XML into catalog entries (catalog/*.yaml)
#include "automation/plan_client.hpp"
#include "ca/access_security.hpp"
#include "ca/ca_link.hpp"
#include "ca/repeater.hpp"
#include "ca/server.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"
#include "core/log.hpp"
#include "core/macros.hpp"
#include "core/signals.hpp"
#include "detector/mca_record.hpp"
#include "feedback/epid_record.hpp"
#include "pv/autosave.hpp"
#include "pv/database.hpp"
#include "pv/dbd_file.hpp"
#include "pv/ioc_stats.hpp"
#include "pv/substitutions.hpp"
#include "core/error_list.hpp"
#include "pv/db_shell.hpp"
#include "pv/shell_server.hpp"
#include "pv/db_file.hpp"
#include "pv/iocsh.hpp"
#include "pv/sub_routines.hpp"
#include "config/ioc_config.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/esi_import.hpp"
#include "bridge/rcp/rcp_sim.hpp"
#include "ioc/check.hpp"
#include "ioc/ioc.hpp"
#include "plc/runtime.hpp"
#include "rt/engine.hpp"
#include "scanner/client.hpp"
#include "scanner/scanner.hpp"
#include "ethercat/sim/fault_server.hpp"
#include "ethercat/sim/raw_server.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
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

// Every error of every file in one run: each file's errors, then those of resolving the links.
void load_databases(pv::Database& db, const DbOptions& o) {
    MacroMap macros = macro_options(o.macros);
    ErrorList errs;
    for (auto& f : o.files) // .db / .template files, and substitution files (dbLoadTemplate)
        errs.capture([&] {
            for (const pv::DbFile& d : pv::load_records_file(f, macros, o.include_path)) db.load(d);
        });
    errs.capture([&] { db.init_records(); });
    errs.throw_if_any();
}

// `beamctl plc check`: compiles PLC files and reports every error; with --ioc, against that
// IOC's buses, axes and plugins, else accepting every well-formed name of the known namespaces.
struct PlcCheckOptions {
    std::vector<std::string> macros, include_path, files;
    std::string ioc_file;
    double rate_ms = -1;
    bool strict = false; // --strict: also report what ECMC's ExprTk would refuse
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
        src.strict = o.strict;
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

// `beamctl softioc`: softIoc's command line. Steps in command-line order (-m, -d, -x, -a and
// positional files); -m applies to the -d / -a after it, each -m replacing the one before.
struct SoftIocStep {
    enum Kind { Macros, Db, Exit, Stats, Acf, File } kind;
    std::string value;
};

struct SoftIocOptions {
    std::vector<std::string> macros, dbs, exits, stats, acfs, files, include_path;
    std::vector<std::string> routine_libs; // -P: libraries of sub/aSub routines (as dlload)
    std::string dbd;                                           // -D: accepted, not needed
    bool no_shell = false, old_shell = false, verbose = false; // -S, -s, -v
    std::string autosave_dir;     // --autosave DIR: info-tag defaults (autosave.hpp)
    std::string shell_socket;     // --shell-socket PATH ("none": no `beamctl shell`)
    double autosave_period_s = 5; // --autosave-period
    std::vector<SoftIocStep> steps;
};

// A positional file is a database when it ends in .db, .vdb or .template, else a startup script.
bool is_database_file(const std::string& f) {
    for (const char* ext : {".db", ".vdb", ".template"})
        if (f.size() > std::strlen(ext) && f.ends_with(ext)) return true;
    return false;
}

// The access-security file, with asSetSubstitutions' macros (if any) expanded in its text.
ca::AccessSecurity load_acf(const std::string& path, const std::string& substitutions) {
    if (substitutions.empty()) return ca::AccessSecurity::load_file(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::stringstream ss;
    ss << in.rdbuf();
    MacroMap m = parse_macro_defs(substitutions, SourceLoc{"asSetSubstitutions", 1, 1});
    return ca::AccessSecurity::parse(expand_macros(ss.str(), m, SourceLoc{path, 1, 1}), path);
}

int run_softioc(const SoftIocOptions& o) {
    pv::Database db;
    db.set_clock(EventLoop::now_s); // delays (calcout ODLY, seq DLYn) on the scan clock
    EventLoop loop;
    // CA links to records of other servers, searched as EPICS_CA_ADDR_LIST etc. say (dbCa).
    ca::CaLinks ca_links(db);
    ca_links.start(loop);
    std::unique_ptr<ca::Server> server;
    int exit_status = 0;
    pv::IocShell* shell_ptr = nullptr;
    pv::IocShellHooks hooks;
    hooks.init = [&] { // iocInit: access security and the CA server (EPICS_CAS_* read now)
        ca::AccessSecurity acf;
        if (!shell_ptr->acf_file().empty())
            acf = load_acf(shell_ptr->acf_file(), shell_ptr->acf_substitutions());
        server = std::make_unique<ca::Server>(loop, db, ca::ServerConfig::from_env());
        server->set_access_security(acf);
        server->start();
        db.ioc_stats().set_ca_counts([&server] { // --ioc-stats: $(IOC):CA_CLNT_CNT, CA_CONN_CNT
            return pv::IocStats::CaCounts{unsigned(server->client_count()), unsigned(server->channel_count())};
        });
    };
    hooks.exit = [&](int status) { // a put to PREFIX:exit (-x): answer it, then stop
        exit_status = status;
        loop.call_after(0.05, [&loop] { loop.stop(); });
    };
    pv::IocShellOptions so;
    so.include_path = o.include_path;
    pv::IocShell shell(db, so, hooks);
    shell_ptr = &shell;
    // Autosave: st.cmd's synApps commands and/or --autosave DIR; restored before PINI.
    auto autosave_note = [](const std::string& m) {
        std::fprintf(stderr, "%s\n", m.c_str());
        std::fflush(stderr);
    };
    pv::Autosave autosave(db, autosave_note);
    pv::add_autosave_commands(shell, autosave, autosave_note);
    if (!o.autosave_dir.empty()) pv::autosave_defaults_before_init(autosave, o.autosave_dir);
    db.set_restore_hook([&autosave] { autosave.restore(); });

    for (const auto& lib : o.routine_libs) pv::RecordRoutines::global().load(lib);
    std::string macros, all_macros; // the -m in effect; every -m joined (for positional .db files)
    for (const auto& m : o.macros) all_macros += (all_macros.empty() ? "" : ",") + m;
    std::vector<std::string> scripts;
    bool loaded = false;
    auto verbose = [&](const std::string& line) {
        if (o.verbose) std::printf("%s\n", line.c_str());
    };
    for (const auto& step : o.steps) {
        switch (step.kind) {
        case SoftIocStep::Macros: macros = step.value; break;
        case SoftIocStep::Db:
            verbose(SB() << "dbLoadRecords(\"" << step.value << "\""
                         << (macros.empty() ? "" : ", \"" + macros + "\"") << ")");
            shell.load_records(step.value, macros, "-m");
            loaded = true;
            break;
        case SoftIocStep::Exit:
            verbose(SB() << "dbLoadRecords(\"softIocExit.db\", \"IOC=" << step.value << "\")");
            shell.load_exit_records(step.value, "beamctl " BEAMCTL_VERSION);
            loaded = true;
            break;
        case SoftIocStep::Stats:
            verbose(SB() << "dbLoadRecords(\"iocAdminSoft.db\", \"IOC=" << step.value << "\")");
            db.load(pv::parse_db(pv::IocStats::database_text(), "iocAdminSoft.db (beamctl's devIocStats records)",
                                 {{"IOC", step.value}}));
            loaded = true;
            break;
        case SoftIocStep::Acf:
            if (!macros.empty()) verbose(SB() << "asSetSubstitutions(\"" << macros << "\")");
            verbose(SB() << "asSetFilename(\"" << step.value << "\")");
            shell.set_access_security(step.value, macros);
            break;
        case SoftIocStep::File:
            if (is_database_file(step.value)) {
                verbose(SB() << "dbLoadRecords(\"" << step.value << "\""
                             << (all_macros.empty() ? "" : ", \"" + all_macros + "\"") << ")");
                shell.load_records(step.value, all_macros, "-m");
                loaded = true;
            } else {
                scripts.push_back(step.value);
            }
            break;
        }
    }
    if (!loaded && scripts.empty()) {
        std::fprintf(stderr, "beamctl softioc: nothing to do: give database files (-d FILE.db, FILE.db, "
                             "-x PREFIX) or a startup script (st.cmd)\n"
                             "Run 'beamctl softioc --help' for its options.\n");
        return 2;
    }
    std::fflush(stdout);
    for (const auto& script : scripts) {
        verbose(SB() << "# Begin " << script);
        shell.run_file(script);
        verbose(SB() << "# End " << script);
    }
    if (!shell.initialised()) {
        verbose("iocInit()");
        shell.ioc_init();
    }

    // Signals: TERM/INT stop cleanly, HUP reloads the access-security file.
    const std::string acf_path = shell.acf_file(), acf_subs = shell.acf_substitutions();
    std::function<bool()> reload; // true: reloaded
    if (!acf_path.empty()) {
        reload = [&, acf_path, acf_subs] {
            if (acf_subs.empty()) return server->reload_access_security(acf_path);
            try {
                server->set_access_security(load_acf(acf_path, acf_subs));
                LOG_INFO(lg, "access security reloaded from " << acf_path);
                return true;
            } catch (const Error& e) {
                LOG_ERR(lg, "access security reload failed, keeping the previous rules: " << e.what());
                return false;
            }
        };
    }
    LoopSignals signals(loop, reload ? std::function<void()>([&reload] { (void)reload(); }) : std::function<void()>());
    // devIocStats's READACF re-reads the ACF as SIGHUP does; SYSRESET stops as SIGTERM does
    pv::IocStats::set_admin_hooks(reload, [&loop] { loop.call_after(0, [&loop] { loop.stop(); }); });
    if (!db.records().empty()) loop.call_every(0.01, [&db] { db.scan_periodic(EventLoop::now_s()); });
    if (!o.autosave_dir.empty()) pv::autosave_defaults_after_init(autosave, db, o.autosave_period_s);
    if (autosave.set_count() > 0) {
        autosave.tick(EventLoop::now_s());
        loop.call_every(0.1, [&autosave] { autosave.tick(EventLoop::now_s()); });
    }

    // `beamctl shell`: introspection on a local UNIX socket, served on this loop.
    pv::DbShell db_shell(db, {[&server](int level, std::ostream& os) { server->report(level, os); }});
    auto shell_server = pv::start_shell_server(loop, db_shell, SB() << "softioc-" << ::getpid(), o.shell_socket);
    std::printf("ready: CA on %s, %zu PVs\n", server->listen_description().c_str(), db.size());
    std::printf("  try: EPICS_CA_ADDR_LIST=127.0.0.1:%u EPICS_CA_AUTO_ADDR_LIST=NO caget <pv>\n",
                unsigned(server->udp_port()));
    std::fflush(stdout);
    loop.run();
    pv::IocStats::set_admin_hooks({}, {});
    autosave.flush(); // a clean stop saves what changed since the last save
    return exit_status;
}

volatile bool g_sim_stop = false;

int run_sim(const std::string& file, const std::string& bind, int port, const std::string& iface, bool busy_poll,
            const std::string& control) {
    const ethercat::Catalog& cat = ethercat::Catalog::builtin();
    ethercat::sim::SimConfig cfg = ethercat::sim::SimConfig::load(file, cat);
    if (cfg.slaves.empty()) throw Error(SB() << file << ": slaves: is required for beamctl sim");
    ethercat::sim::Segment seg;
    cfg.build(seg, cat);
    std::unique_ptr<ethercat::sim::FaultServer> faults;
    if (!control.empty()) {
        faults = std::make_unique<ethercat::sim::FaultServer>(seg, cat, control);
        std::printf("control: %s (beamctl sim fault %s FAULT...)\n", control.c_str(), control.c_str());
    }
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

// `beamctl scanner SCANNER.yaml`: run the buses of the file and serve IOCs until SIGTERM/SIGINT.
int run_scanner(const std::string& file) {
    scanner::ScannerConfig cfg = scanner::ScannerConfig::load(file);
    rt::MonotonicClock clock;
    scanner::Scanner sc(cfg, ethercat::Catalog::builtin(), clock);
    EventLoop loop;
    LoopSignals sig(loop, [] {});
    sc.start();
    sc.serve(loop);
    std::printf("ready: scanner '%s', %zu bus(es), socket %s\n", cfg.name.c_str(), sc.bus_count(), cfg.socket.c_str());
    std::fflush(stdout);
    loop.run();
    sc.stop("the scanner is stopping");
    LOG_INFO(lg, "scanner stopped");
    return 0;
}

// `beamctl scanner status SOCKET|SCANNER.yaml`: the scanner's cycle, counters and clients.
int scanner_status(const std::string& where) {
    std::string socket = where;
    if (where.ends_with(".yaml") || where.ends_with(".yml")) socket = scanner::ScannerConfig::load(where).socket;
    scanner::Channel ch;
    ch.connect(socket);
    scanner::proto::Message r = ch.call(scanner::proto::StatusRequest{}, 5);
    const auto* st = std::get_if<scanner::proto::Status>(&r.body);
    if (!st) throw Error(SB() << "scanner " << socket << ": unexpected answer " << scanner::proto::to_string(r.type()));
    std::printf("cycle %llu, frames lost %llu, WKC errors %llu, %zu client(s)\n", (unsigned long long)st->cycle,
                (unsigned long long)st->frames_lost, (unsigned long long)st->wkc_errors, st->clients.size());
    for (const auto& c : st->clients)
        std::printf("  %s (pid %u): %u slave(s), %u claim(s), drops %llu, late %llu\n", c.name.c_str(), c.pid, unsigned(c.slaves),
                    unsigned(c.claims), (unsigned long long)c.drops, (unsigned long long)c.late);
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
    // Record types beyond pv's own (synApps' epid and mca): every command that loads a .db sees them.
    feedback::register_feedback_records(pv::RecordTypes::global());
    pv::IocStats::set_release("beamctl " BEAMCTL_VERSION ", EPICS 7.0.8 records"); // $(IOC):EPICS_VERS
    detector::register_detector_records(pv::RecordTypes::global());
    CLI::App app{"beamctl: beamline control engine (EPICS Channel Access server, PV database)"};
    app.set_version_flag("--version", std::string("beamctl ") + BEAMCTL_VERSION);
    app.require_subcommand(1);

    SoftIocOptions soft;
    auto* softioc = app.add_subcommand(
        "softioc",
        "Serve EPICS database files over Channel Access, with EPICS softIoc's command line:\n"
        "  beamctl softioc [-D dbd] [-S] [-s] [-v] [-a FILE.acf] [-m MACROS] [-d FILE.db]\n"
        "                  [-x PREFIX] [-I DIR] [-P LIB.so] [st.cmd | FILE.db ...]\n"
        "Options act in command-line order: -m sets the macros of the -d and -a after it (each -m\n"
        "replaces the one before). Positional FILE.db / .vdb / .template files are loaded with\n"
        "every -m; other positional files are startup scripts (st.cmd), run in order after the\n"
        "options; iocInit follows unless a script ran it.");
    auto take_each = [](CLI::Option* o) {
        return o->allow_extra_args(false)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    };
    auto* soft_m = take_each(softioc->add_option(
        "-m,--macros", soft.macros,
        "Macros for the -d/-a after it (and every positional .db), e.g. \"P=DEMO:,R=x\""));
    auto* soft_d = take_each(softioc->add_option(
        "-d,--db", soft.dbs, "Load a database file (dbLoadRecords) with the -m macros before it"));
    auto* soft_x = take_each(softioc->add_option(
        "-x", soft.exits, "Load PREFIX:exit (a put stops the IOC) and PREFIX:BaseVersion"));
    auto* soft_s = take_each(softioc->add_option(
        "--ioc-stats", soft.stats,
        "Load the IOC health records of devIocStats (iocAdminSoft.db) as IOC:HEARTBEAT, IOC:UPTIME, IOC:IOC_CPU_LOAD, ..."));
    auto* soft_a = take_each(softioc->add_option(
        "-a,--acf", soft.acfs,
        "EPICS access-security file, with the -m macros before it (reloaded on SIGHUP)"));
    take_each(softioc->add_option(
        "-I,--include", soft.include_path,
        "Search path for include \"file\" (and for the template files of substitution files)"));
    take_each(softioc->add_option(
        "-P,--plugin", soft.routine_libs,
        "Load a library of sub/aSub routines (include/beamctl/record_routines.h), as dlload LIB.so"));
    softioc->add_option("-D", soft.dbd, "softIoc.dbd: accepted and ignored (record types are built in)");
    softioc->add_flag("-S", soft.no_shell, "No interactive shell: accepted (beamctl never starts one)");
    softioc->add_flag("-s", soft.old_shell, "Accepted and ignored (as softIoc)");
    softioc->add_flag("-v", soft.verbose, "Print the steps taken during startup");
    softioc->add_option("--autosave", soft.autosave_dir,
                        "Autosave with synApps' defaults: restore DIR/info_positions.sav and info_settings.sav before PINI, "
                        "save the info(autosaveFields_pass0/autosaveFields) fields there on change");
    softioc->add_option("--autosave-period", soft.autosave_period_s,
                        "Seconds between saves of a changed autosave file (default 5)")
        ->check(CLI::Range(0.1, 86400.0));
    softioc->add_option("--shell-socket", soft.shell_socket,
                        "UNIX socket of 'beamctl shell' (default $XDG_RUNTIME_DIR/beamctl/softioc-PID.sock, "
                        "else /tmp/beamctl-UID/...; $BEAMCTL_SHELL_SOCKET; 'none': no shell)");
    auto* soft_files = softioc->add_option(
        "files", soft.files, "Startup scripts (st.cmd) and database files (.db, .vdb, .template)");

    DbOptions dbo;
    auto* dbcmd = app.add_subcommand("db", "Print the loaded database as .db text");
    dbcmd->add_option("-m,--macros", dbo.macros, "Macro definitions, e.g. \"P=DEMO:,R=x\" (for an ioc.yaml: its $(NAME) references)")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    dbcmd->add_option("-I,--include", dbo.include_path, "Search path for include \"file\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    bool dbd = false;
    dbcmd->add_flag("--dbd", dbd,
                    "Print the record types beamctl serves as a .dbd (every field, its type, menu, access and initial value)");
    // FILES are required, unless --dbd asks for the record types alone
    bool dbd_asked = false;
    for (int i = 1; i < argc; ++i)
        if (std::string_view(argv[i]) == "--dbd") dbd_asked = true;
    dbcmd->add_option("files", dbo.files, "Database files (.db), or one ioc.yaml")->required(!dbd_asked);

    IocOptions runo, checko;
    auto* runcmd = app.add_subcommand("run", "Run an IOC: buses, RT engine, PVs and CA server (ioc.yaml)");
    add_ioc_options(*runcmd, runo);
    std::string run_shell_socket;
    runcmd->add_option("--shell-socket", run_shell_socket,
                       "UNIX socket of 'beamctl shell' (default $XDG_RUNTIME_DIR/beamctl/NAME.sock, else "
                       "/tmp/beamctl-UID/NAME.sock; $BEAMCTL_SHELL_SOCKET; 'none': no shell)");
    std::string scanner_file, scanner_where;
    auto* scannercmd = app.add_subcommand("scanner", "Run an EtherCAT bus scanner that several IOCs share (SCANNER.yaml)");
    scannercmd->add_option("file", scanner_file, "Scanner configuration (scanner:, engine:, buses:)");
    auto* scanstatus = scannercmd->add_subcommand("status", "Show a running scanner's cycle, counters and clients");
    scanstatus->add_option("socket", scanner_where, "The scanner's socket, or its SCANNER.yaml")->required();
    auto* checkcmd = app.add_subcommand("check", "Load an IOC configuration and report errors (exit 1 on any)");
    add_ioc_options(*checkcmd, checko);
    IocOptions sigo;
    std::string sig_pattern;
    auto* sigcmd = app.add_subcommand(
        "signals", "List the signals of an IOC: name, type, direction, owner, writer, PV (ioc.yaml [PATTERN])");
    add_ioc_options(*sigcmd, sigo);
    sigcmd->add_option("pattern", sig_pattern, "Glob of signal names, e.g. 'ec0.s3.*' or 'ax1.traj.*'");

    PlcCheckOptions plco;
    auto* plancmd = app.add_subcommand("plan", "Plans of a running IOC: scans, alignments, sequences (docs/automation.md)");
    plancmd->require_subcommand(1);
    IocOptions plano;
    automation::PlanRunOptions planrun;
    auto* planruncmd = plancmd->add_subcommand(
        "run", "Start PLAN of the IOC of ioc.yaml with NAME=VALUE arguments, follow it, exit 0 when it is Done (Ctrl-C aborts it)");
    planruncmd->add_option("-m,--macros", plano.macros, "Macros for the IOC file's $(NAME) references")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    planruncmd->add_option("--timeout", planrun.connect_timeout_s, "Seconds to wait for the IOC's PVs")->check(CLI::Range(0.1, 3600.0));
    planruncmd->add_flag("-q,--quiet", planrun.quiet, "Print only the result");
    planruncmd->add_option("file", plano.file, "IOC configuration (ioc.yaml)")->required();
    planruncmd->add_option("plan", planrun.plan, "The plan (beamctl plan list ioc.yaml)")->required();
    planruncmd->add_option("args", planrun.args, "The plan's arguments, NAME=VALUE");
    IocOptions planlisto;
    auto* planlistcmd = plancmd->add_subcommand("list", "List the plans of an IOC file with their arguments");
    planlistcmd->add_option("file", planlisto.file, "IOC configuration (ioc.yaml)")->required();
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
    plccheck->add_flag("--strict", plco.strict,
                       "Also report every construct beamctl accepts but ECMC's ExprTk refuses, with its ECMC spelling");
    plccheck->add_option("files", plco.files, "PLC files")->required();

    std::vector<std::string> axis_macros, axis_encoders;
    std::string axis_file;
    auto* axiscmd = app.add_subcommand("axis", "ECMC axis files");
    axiscmd->require_subcommand(1);
    auto* axischeck = axiscmd->add_subcommand(
        "check", "Check an ECMC axis YAML file on its own (as loadYamlAxis.cmd) and compile its axis PLC (exit 1 on any error)");
    axischeck->add_option("-m,--macros", axis_macros, "Macro definitions, e.g. \"AX_ID=1,DRV_SLAVE=3\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    axischeck->add_option("-e,--encoder", axis_encoders, "An encoder file added after the axis (loadYamlEnc.cmd)")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    axischeck->add_option("file", axis_file, "The axis file")->required();

    std::string rcp_model;
    bridge::rcp::RcpSimOptions rcpo;
    auto* rcpcmd = app.add_subcommand("rcp-sim", "Stand in for a rapid-control-prototyping machine: run MODEL.yaml, send beacons and data, take writes");
    rcpcmd->add_option("model", rcp_model, "Model file (examples/rcp/model.yaml)")->required();
    rcpcmd->add_option("--ioc-host", rcpo.ioc_host, "IPv4 address of the IOC's bridge (overrides ioc.host)");
    rcpcmd->add_option("--ioc-port", rcpo.ioc_port, "UDP port of the IOC's bridge (overrides ioc.port)")->check(CLI::Range(1, 65535));
    rcpcmd->add_option("--port", rcpo.listen_port, "UDP port this machine takes writes on (0: any free port)")->check(CLI::Range(0, 65535));
    rcpcmd->add_option("--rate", rcpo.rate_hz, "Model rate [Hz] (overrides rate_hz)")->check(CLI::Range(1.0, 100000.0));
    rcpcmd->add_option("--duration", rcpo.duration_s, "Stop after this many seconds (default: until SIGINT/SIGTERM)");

    std::string sim_file, sim_bind = "127.0.0.1", sim_iface, sim_control;
    int sim_port = 0x88A4;
    bool sim_busy_poll = false;
    auto* simcmd = app.add_subcommand("sim", "Run a simulated EtherCAT segment (SIM.yaml) behind UDP or on an interface");
    simcmd->add_option("file", sim_file, "Simulator configuration (slaves:, wiring:)");
    simcmd->add_option("--control", sim_control,
                       "Local socket taking fault commands at run time (beamctl sim fault SOCKET FAULT...)");
    std::string fault_socket;
    std::vector<std::string> fault_words;
    auto* faultcmd = simcmd->add_subcommand(
        "fault", "Inject a fault into a running `beamctl sim --control SOCKET`: power K off|on, break K, repair, loss F, "
                 "corrupt F, delay MS, refuse-state K STATE CODE, refuse-sdo K INDEX:SUB ABORT, replace K TYPE, glitch K COUNTS, "
                 "drive-fault K, clear");
    faultcmd->add_option("socket", fault_socket, "The simulator's control socket")->required();
    faultcmd->add_option("fault", fault_words, "The fault, e.g. power 3 off")->required();
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

    pv::ShellClientOptions shello;
    auto* shellcmd = app.add_subcommand(
        "shell", "Run iocsh commands (dbl, dbpr, dbgf, dbpf, dbtr, scanppl, casr, help) in a running IOC "
                 "through its local socket: -c CMD, or lines from stdin (a prompt on a terminal)");
    shellcmd->add_option("--socket", shello.socket, "The IOC's socket (printed as 'shell: PATH' at its start)");
    shellcmd->add_option("-c,--command", shello.commands, "A command to run (repeatable), e.g. -c 'dbgf rec.VAL'")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    shellcmd->add_option("name", shello.name,
                         "IOC name (ioc: name of ioc.yaml, softioc-PID) or socket path; default: the only IOC running");

    int repeater_port = 0;
    auto* repcmd = app.add_subcommand(
        "ca-repeater", "Run the Channel Access repeater (EPICS caRepeater): fan CA server beacons out to this host's clients");
    repcmd->add_option("--port", repeater_port, "UDP port (default: EPICS_CA_REPEATER_PORT, else 5065)")
        ->check(CLI::Range(1, 65535));

    ethercat::EsiImportOptions esio;
    auto* esicmd = app.add_subcommand("esi", "EtherCAT Slave Information (vendor ESI XML) tools");
    esicmd->require_subcommand(1);
    auto* esiimport = esicmd->add_subcommand(
        "import", "Write catalog entries (one YAML file per device and revision) from ESI XML files; "
                  "without --out, print them (exit 1 on any error)");
    esiimport->add_option("files", esio.files, "ESI XML files (EtherCATInfo)")->required();
    esiimport->add_option("--out", esio.out, "Catalog directory to write to, e.g. catalog/ (created if missing)");
    esiimport->add_flag("--force", esio.force, "Replace existing files that beamctl esi import did not write");

    try {
        app.parse(argc, argv);
    } catch (const CLI::Success& e) { // --help, --version
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        return report_usage_error(app, e);
    }
    try {
        log::validate(); // BEAMCTL_LOG, against the loggers registered during static initialisation
        if (*softioc) {
            // The steps in command-line order: parse_order() names one option per value.
            struct Source {
                const CLI::Option* opt;
                SoftIocStep::Kind kind;
                const std::vector<std::string>& values;
                std::size_t next = 0;
            };
            Source sources[] = {{soft_m, SoftIocStep::Macros, soft.macros},
                                {soft_d, SoftIocStep::Db, soft.dbs},
                                {soft_x, SoftIocStep::Exit, soft.exits},
                                {soft_s, SoftIocStep::Stats, soft.stats},
                                {soft_a, SoftIocStep::Acf, soft.acfs},
                                {soft_files, SoftIocStep::File, soft.files}};
            for (const CLI::Option* opt : softioc->parse_order())
                for (Source& src : sources)
                    if (src.opt == opt && src.next < src.values.size())
                        soft.steps.push_back({src.kind, src.values[src.next++]});
            return run_softioc(soft);
        }
        if (*plccheck) return run_plc_check(plco);
        if (*planruncmd) return automation::run_plan_client(plano.load(), planrun, std::cout, std::cerr);
        if (*planlistcmd) return automation::list_plans(planlisto.load(), std::cout);
        if (*esiimport) return ethercat::run_esi_import(esio, std::cout, std::cerr);
        if (*axischeck) return ioc::run_axis_check(axis_file, axis_encoders, macro_options(axis_macros));
        if (*shellcmd) return pv::run_shell_client(shello);
        if (*rcpcmd) return bridge::rcp::run_rcp_sim(rcp_model, rcpo);
        if (*repcmd)
            return ca::run_ca_repeater(repeater_port ? uint16_t(repeater_port) : ca::repeater_port_from_env());
        if (*faultcmd) {
            std::string text;
            for (const auto& w : fault_words) text += (text.empty() ? "" : " ") + w;
            std::string reply = ethercat::sim::send_fault(fault_socket, text);
            std::printf("%s\n", reply.c_str());
            return reply.rfind("ok:", 0) == 0 ? 0 : 1;
        }
        if (*simcmd) {
            if (sim_file.empty()) throw Error("beamctl sim: the simulator configuration file is required (beamctl sim SIM.yaml)");
            return run_sim(sim_file, sim_bind, sim_port, sim_iface, sim_busy_poll, sim_control);
        }
        if (*scanstatus) return scanner_status(scanner_where);
        if (*scannercmd) {
            if (scanner_file.empty()) throw Error("beamctl scanner: the scanner configuration file is required (beamctl scanner SCANNER.yaml)");
            return run_scanner(scanner_file);
        }
        if (*runcmd) {
            rt::MonotonicClock clock;
            std::unique_ptr<ioc::Ioc> ioc;
            try {
                ioc = std::make_unique<ioc::Ioc>(runo.load(), clock);
            } catch (const Error&) {
                // every error of every file, the set `beamctl check` reports, not only the build's
                ioc::CheckReport r = ioc::check_ioc(runo.file, macro_options(runo.macros));
                if (r.ok()) throw;
                for (const auto& m : r.errors) std::fprintf(stderr, "%s\n", m.c_str());
                std::fprintf(stderr, "%s: %zu error%s\n", runo.file.c_str(), r.errors.size(), r.errors.size() == 1 ? "" : "s");
                return 1;
            }
            ioc->set_shell_socket(run_shell_socket);
            return ioc->run();
        }
        if (*checkcmd) return ioc::run_check(checko.file, macro_options(checko.macros)); // every error
        if (*sigcmd) { // configured, not brought up: nothing touches a bus
            rt::MonotonicClock clock;
            ioc::Ioc ioc(sigo.load(), clock);
            ioc.signals().print(std::cout, sig_pattern);
            return ioc.signals().match(sig_pattern).empty() ? 1 : 0;
        }
        if (*dbcmd && dbd) {
            pv::write_dbd(std::cout, pv::RecordTypes::global());
            return 0;
        }
        if (*dbcmd) {
            if (dbo.files.size() == 1 && dbo.files[0].size() > 5 &&
                (dbo.files[0].ends_with(".yaml") || dbo.files[0].ends_with(".yml"))) {
                rt::MonotonicClock clock;
                ioc::Ioc ioc(config::IocConfig::load(dbo.files[0], macro_options(dbo.macros)), clock);
                ioc.database().write_db(std::cout);
                return 0;
            }
            pv::Database db;
            db.set_offline_devices(true); // device addresses are the IOC's to bind: printed as written
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
