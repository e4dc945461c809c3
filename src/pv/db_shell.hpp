// The commands of `beamctl shell`: introspection of a running IOC as EPICS iocsh users know it
// (dbl, dbpr, dbgf, dbpf, dbtr, scanppl, casr, help; and signals, beamctl's registry), one line in, the command's text out. No
// sockets (pv/shell_server.hpp serves it on a UNIX socket); what is not in the PV database (the
// CA server's report for casr) comes in through DbShellHooks.
// Threading: a DbShell and its Database are used by the database's thread (the IOC loop).
#pragma once

#include <functional>
#include <map>
#include <vector>
#include <iosfwd>
#include <string>
#include <string_view>

namespace beamctl::pv {

class Database;

struct DbShellHooks {
    // casr [level]: the CA server's report (empty: "casr: no Channel Access server").
    std::function<void(int level, std::ostream& os)> casr;
    // signals [PATTERN]: the IOC's signal registry now, with what the RCP bridge has declared since
    // start (empty: "signals: this IOC has no signal registry" — a soft IOC). False: none matched.
    std::function<bool(const std::string& pattern, std::ostream& os)> signals;
    // Commands of the application (the IOC's `ethercat`, `sim`): argv[0] is the name; false: it
    // failed (an Error thrown is printed as "error: ..."). `usage` goes into help.
    struct Command {
        std::string usage; // "sim BUS FAULT ...  inject a fault into a simulated segment"
        std::function<bool(const std::vector<std::string>& argv, std::ostream& os)> run;
    };
    std::map<std::string, Command> commands;
};

class DbShell {
public:
    explicit DbShell(Database& db, DbShellHooks hooks = {});

    // Runs one command line (words split as iocsh does: blanks, "quotes", and ( ) , as in
    // dbpf("rec", "1")). Output and errors go to `os`; returns false when the command failed
    // (unknown command, bad arguments, unknown record, refused put). A blank line or a
    // '#' comment does nothing and succeeds.
    bool execute(std::string_view line, std::ostream& os);

private:
    Database& db_;
    DbShellHooks hooks_;
};

} // namespace beamctl::pv
