// Startup scripts (st.cmd) of a soft IOC, run as EPICS iocsh runs them, into a Database: the
// commands soft IOCs use (epicsEnvSet, dbLoadRecords, dbLoadTemplate, iocInit, dbpf, dbl, `<`
// includes, cd, ...), with iocsh's line handling. No sockets: serving starts in the init hook.
// Threading: an IocShell and its Database are used by one thread, the one that runs the IOC loop
// afterwards (scripts run before the loop does).
//
// Lines, as iocsh reads them: leading blanks are skipped; a line starting with '#' is a comment
// (echoed, unless it starts with "#-"); $(NAME) and ${NAME} are expanded from the environment
// and the macros of iocshLoad (core/macros.hpp syntax; an undefined name without a default is an
// error); each line is echoed after expansion. Words are separated by blanks and ( ) , so that
// `dbLoadRecords("x.db", "P=A:")` and `dbLoadRecords x.db P=A:` are the same; "..." and '...'
// group (the quotes are removed, nothing is escaped inside them), a backslash outside quotes
// makes the next character literal. Unquoted `< file` runs another script (also as a line of its
// own), `> file`, `>> file` and `1>` send the command's output to a file. Extra arguments are
// ignored, as iocsh does. Relative paths are taken from the current directory, which `cd`
// changes for the whole process (as iocsh does).
//
// Commands: see docs/softioc.md. A command that fails, and an unknown command, is an Error
// "file:line: what" (errors of loaded files keep their own file:line:col, followed by the line
// that loaded them); the script stops there, as after iocsh's `on error break`. After
// `on error continue` errors are printed to the error stream and the script goes on.
#pragma once

#include "pv/types.hpp"

#include <functional>
#include <iosfwd>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv {

class Database;

struct IocShellOptions {
    std::vector<std::string> include_path; // .db `include` search path; also where template
                                           // files of substitution files are looked for (-I)
    std::ostream* out = nullptr;           // echo and command output (nullptr: std::cout)
    std::ostream* err = nullptr;           // notes and continued errors (nullptr: std::cerr)
    bool echo = true;                      // echo script lines, as iocsh does
};

struct IocShellHooks {
    // At iocInit, after the records are initialised: start serving (read the access-security
    // file, start the CA server). An Error it throws fails iocInit.
    std::function<void()> init;
    // A put processed the exit record of load_exit_records(): stop the IOC with this status.
    std::function<void(int status)> exit;
};

class IocShell {
public:
    IocShell(Database& db, IocShellOptions options = {}, IocShellHooks hooks = {});
    ~IocShell();
    IocShell(const IocShell&) = delete;
    IocShell& operator=(const IocShell&) = delete;

    // Runs a script file, as iocshLoad(path, macros) (`macros` as "A=1,B=2").
    void run_file(const std::string& path, const std::string& macros = "");
    // Runs script text; `name` stands for its file in messages.
    void run_text(std::string_view text, const std::string& name, const std::string& macros = "");

    // The commands behind -d, -x, -a and iocInit, also for the command line (`macros` as
    // "A=1,B=2"; a bad one is an error naming `macros_origin`, e.g. "-m").
    void load_records(const std::string& path, const std::string& macros,
                      const std::string& macros_origin = "macros");
    void load_template(const std::string& path, const std::string& macros,
                       const std::string& macros_origin = "macros");
    // softIoc's -x PREFIX: "PREFIX:exit" (bo; a put of any value makes the IOC exit with status 0
    // through hooks.exit) and "PREFIX:BaseVersion" (stringin holding `version`).
    void load_exit_records(const std::string& prefix, const std::string& version);
    // asSetFilename + asSetSubstitutions: the ACF read at iocInit (by hooks.init).
    void set_access_security(const std::string& path, const std::string& substitutions);
    // iocInit: initialises the records loaded so far, then calls hooks.init. Once only.
    void ioc_init();

    // Adds a command to those of scripts (autosave's set_savefile_path, ...): `fn` gets the
    // words (argv[0] is the name) and the stream the command's output goes to; an Error it
    // throws is the error of the script line. `usage` is shown in messages.
    using CommandFn = std::function<void(const std::vector<std::string>& argv, std::ostream& out)>;
    void add_command(std::string name, std::string usage, CommandFn fn);

    bool initialised() const;
    std::size_t records_loaded() const; // by dbLoadRecords, dbLoadTemplate and -x
    // The access-security file ("" for none; as given, or absolute when `cd` moved away from where
    // it was given) and its substitutions ("A=1,B=2").
    const std::string& acf_file() const;
    const std::string& acf_substitutions() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Prints a field's value as EPICS dbgf does ("DBF_DOUBLE:         3.5", columns of 10); for
// dbpf/dbgf and tests. Returns false (printing "PV 'name' not found") if the name resolves to
// nothing.
bool print_field(const Database& db, std::string_view channel, std::ostream& os);

// The introspection commands of iocsh (dbl, dbpf, dbpr, dbtr, scanppl) as functions, shared by
// startup scripts and `beamctl shell` (pv/db_shell.hpp); output as EPICS prints it. Database
// thread only.

// dbl: the records of record type `type` ("" for all) whose names match the glob `pattern` ("" for
// all), one a line in load order within record types in name order, each followed by the values
// of `fields` (blank-separated; "recordType" is the type) as `, "value"`.
void print_record_list(const Database& db, std::string_view type, std::string_view pattern,
                       std::string_view fields, std::ostream& os);
// dbpf: writes `value` (text; an array as [1, 2, "a"] or one value) through Database::put as a CA
// put does (read-only fields refused, pp fields process the record), then prints the field as
// dbgf. Throws Error "dbpf NAME "VALUE": why" when the name is unknown or the put refused.
void put_field_text(Database& db, const std::string& channel, const std::string& value,
                    std::ostream& os);
// dbpr: the fields of a record as "NAME: value" in columns of 20, in name order; level 0 the
// fields dbpr shows at interest level 0 (ASG DESC DISA DISP DISV NAME SEVR STAT TPRO VAL),
// 1 and up every field. Returns false (printing "Record 'x' not found") for an unknown name.
bool print_record(const Database& db, std::string_view name, int level, std::ostream& os);
// scanppl: the records of each periodic scan list ("Scan list for 1 second:" and the names), or
// only those of `period` ("1 second", "1", ".5 second", ...) when given.
void print_scan_lists(const Database& db, std::string_view period, std::ostream& os);
// What a refused put's status means ("the field is read-only", ...).
const char* put_status_text(PutStatus st);

} // namespace beamctl::pv
