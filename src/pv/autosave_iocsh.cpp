// The autosave commands of st.cmd scripts (autosave.hpp: add_autosave_commands) and the defaults
// for IOCs with info tags only.
#include "core/error.hpp"
#include "pv/autosave.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"
#include "pv/iocsh.hpp"

#include <filesystem>
#include <ostream>

namespace beamctl::pv {

namespace {

namespace fs = std::filesystem;

const std::string& arg(const std::vector<std::string>& argv, std::size_t i) {
    static const std::string none;
    return i < argv.size() ? argv[i] : none;
}

// synApps' (path, subdirectory) pairs: "path/subdir", or path alone.
std::string path_arg(const std::vector<std::string>& argv, const char* usage) {
    if (arg(argv, 1).empty()) throw Error(SB() << argv[0] << ": missing the path (usage: " << usage << ")");
    if (arg(argv, 2).empty()) return arg(argv, 1);
    return (fs::path(arg(argv, 1)) / arg(argv, 2)).string();
}

} // namespace

void add_autosave_commands(IocShell& sh, Autosave& as, std::function<void(const std::string&)> note) {
    sh.add_command("set_savefile_path", "set_savefile_path PATH [SUBDIR]",
                   [&as](const std::vector<std::string>& a, std::ostream&) {
                       as.set_save_dir(path_arg(a, "set_savefile_path PATH [SUBDIR]"));
                   });
    sh.add_command("set_requestfile_path", "set_requestfile_path PATH [SUBDIR]",
                   [&as](const std::vector<std::string>& a, std::ostream&) {
                       as.add_request_dir(path_arg(a, "set_requestfile_path PATH [SUBDIR]"));
                   });
    for (int pass : {0, 1}) {
        const std::string name = SB() << "set_pass" << pass << "_restoreFile";
        sh.add_command(name, name + " FILE.sav", [&as, &sh, pass, name](const std::vector<std::string>& a, std::ostream&) {
            if (arg(a, 1).empty()) throw Error(SB() << name << ": missing the file (usage: " << name << " FILE.sav)");
            if (sh.initialised())
                throw Error(SB() << name << " must come before iocInit (files are restored at iocInit)");
            as.add_restore_file(arg(a, 1), pass);
        });
    }
    for (const char* name : {"create_monitor_set", "create_periodic_set"}) {
        const std::string usage = SB() << name << " FILE.req [PERIOD_S] [MACROS]";
        sh.add_command(name, usage, [&as, usage, name](const std::vector<std::string>& a, std::ostream&) {
            if (arg(a, 1).empty()) throw Error(SB() << name << ": missing the request file (usage: " << usage << ")");
            double period = 5;
            if (!arg(a, 2).empty() && (!parse_double(arg(a, 2), period) || !(period > 0)))
                throw Error(SB() << name << ": period '" << arg(a, 2) << "' should be a number of seconds > 0");
            as.add_request_set(arg(a, 1), period, arg(a, 3));
        });
    }
    sh.add_command("makeAutosaveFileFromDbInfo", "makeAutosaveFileFromDbInfo FILE.req INFO_NAME",
                   [&as](const std::vector<std::string>& a, std::ostream&) {
                       if (arg(a, 1).empty() || arg(a, 2).empty())
                           throw Error("makeAutosaveFileFromDbInfo: usage: makeAutosaveFileFromDbInfo FILE.req INFO_NAME");
                       std::string file = arg(a, 1);
                       if (!file.ends_with(".req")) file += ".req";
                       as.write_request_from_info(file, arg(a, 2));
                   });
    for (const char* name : {"save_restoreSet_Debug", "save_restoreSet_NumSeqFiles", "save_restoreSet_SeqPeriodInSeconds",
                             "save_restoreSet_DatedBackupFiles", "save_restoreSet_IncompleteSetsOk",
                             "save_restoreSet_status_prefix", "save_restoreSet_CAReconnect",
                             "save_restoreSet_CallbackTimeout", "save_restoreSet_UseStatusPVs",
                             "save_restoreSet_periodicDatedBackups", "save_restoreSet_NFSHost"}) {
        sh.add_command(name, name, [note](const std::vector<std::string>& a, std::ostream&) {
            if (note) note(SB() << "note: " << a[0] << " ignored: beamctl's autosave keeps one backup (.savB), "
                                << "writes atomically and restores whatever is valid");
        });
    }
}

void autosave_defaults_before_init(Autosave& as, const std::string& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw Error(SB() << "autosave: cannot create the directory " << dir << ": " << ec.message());
    as.set_save_dir(dir);
    as.add_restore_file("info_positions.sav", 0);
    as.add_restore_file("info_settings.sav", 1);
}

void autosave_defaults_after_init(Autosave& as, const Database& db, double period_s) {
    auto positions = channels_from_info(db, "autosaveFields_pass0");
    auto settings = channels_from_info(db, "autosaveFields");
    if (!positions.empty()) as.add_set("info_positions.sav", std::move(positions), period_s);
    if (!settings.empty()) as.add_set("info_settings.sav", std::move(settings), period_s);
}

} // namespace beamctl::pv
