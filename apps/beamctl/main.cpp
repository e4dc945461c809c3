// beamctl: the command-line program. Subcommands:
//   softioc  serve EPICS database files over Channel Access (like EPICS softIoc)
//   db       print the loaded database as .db text
#include "ca/access_security.hpp"
#include "ca/server.hpp"
#include "core/error.hpp"
#include "core/event_loop.hpp"
#include "core/log.hpp"
#include "core/macros.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"

#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>
#include <iostream>
#include <sys/signalfd.h>
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

void load_databases(pv::Database& db, const DbOptions& o) {
    MacroMap macros;
    for (auto& m : o.macros) {
        MacroMap more = parse_macro_defs(m, SourceLoc{"-m", 1, 1});
        for (auto& [k, v] : more) macros[k] = v;
    }
    for (auto& f : o.files) db.load(pv::load_db_file(f, macros, o.include_path));
    db.init_records();
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
    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGTERM);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGHUP);
    sigprocmask(SIG_BLOCK, &mask, nullptr);
    int sfd = signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC);
    loop.add_fd(sfd, 1 /*EPOLLIN*/, [&](uint32_t) {
        signalfd_siginfo si;
        while (::read(sfd, &si, sizeof si) == sizeof si) {
            if (si.ssi_signo == SIGHUP) {
                if (acf_path.empty()) {
                    LOG_WARN(lg, "SIGHUP: no access-security file to reload (use --acf)");
                    continue;
                }
                try {
                    server.set_access_security(ca::AccessSecurity::load_file(acf_path));
                    LOG_INFO(lg, "access security reloaded from " << acf_path);
                } catch (const Error& e) {
                    LOG_ERR(lg, "access security reload failed, keeping the previous rules: " << e.what());
                }
            } else {
                LOG_INFO(lg, "signal " << si.ssi_signo << ": stopping");
                loop.stop();
            }
        }
    });
    if (!db.records().empty()) loop.call_every(0.01, [&db] { db.scan_periodic(EventLoop::now_s()); });

    std::printf("ready: CA on %s, %zu PVs\n", server.listen_description().c_str(), db.size());
    std::printf("  try: EPICS_CA_ADDR_LIST=127.0.0.1:%u EPICS_CA_AUTO_ADDR_LIST=NO caget <pv>\n",
                unsigned(server.udp_port()));
    std::fflush(stdout);
    loop.run();
    loop.remove_fd(sfd);
    ::close(sfd);
    return 0;
}

} // namespace

int main(int argc, char** argv) {
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
    dbcmd->add_option("-m,--macros", dbo.macros, "Macro definitions, e.g. \"P=DEMO:,R=x\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    dbcmd->add_option("-I,--include", dbo.include_path, "Search path for include \"file\"")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    dbcmd->add_option("files", dbo.files, "Database files (.db)")->required();

    CLI11_PARSE(app, argc, argv);
    try {
        if (*softioc) return run_softioc(soft, acf);
        if (*dbcmd) {
            pv::Database db;
            load_databases(db, dbo);
            db.write_db(std::cout);
            return 0;
        }
    } catch (const Error& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "beamctl: %s\n", e.what());
        return 1;
    }
    return 0;
}
