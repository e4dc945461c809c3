// Autosave as synApps users know it: fields named by info(autosaveFields, "...") tags and .req
// request files are saved to .sav files in synApps' format, written atomically when a value
// changed (at most once per period), and restored after record init and before PINI. No sockets,
// no clock: the owner calls tick(now_s) (tests drive it in virtual time).
// Threading: an Autosave and its Database are used by one thread (the IOC loop).
//
// The .sav format (synApps save_restore): a header line "# save/restore V5.11\tAutomatically
// generated - DO NOT MODIFY - <time>", then "NAME VALUE" lines (the value is the rest of the
// line), arrays as "NAME @array@ { "1" "2" }" (\" and \\ escaped), and a last line "<END>" that
// says the file is whole. A save keeps the previous file as NAME.savB, as synApps does.
#pragma once

#include "core/macros.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv {

class Database;

// One saved channel ("rec.FIELD" or "rec") with its value(s) as text.
struct SavedValue {
    std::string name;
    bool array = false;
    std::vector<std::string> values; // a scalar: one value
    int line = 0;                    // where it was read (parse_save_file)
};

// The text of a .sav file; `stamp` is the header's time ("251125-193000").
std::string format_save_file(const std::vector<SavedValue>& values, std::string_view stamp);
// Parses a .sav file. Throws Error("path:line: what") on a malformed line, and for a file with no
// <END> line (truncated: a crash while it was written).
std::vector<SavedValue> parse_save_file(std::string_view text, const std::string& path);

// Reads a request file: one channel per line ("$(P)rec.FIELD", or "rec" for VAL), '#' comments,
// `file other.req MACROS` includes (searched in `search_path`, then as given); `macros` expand
// $(NAME). Throws Error("path:line: what"), e.g. for an undefined macro or a missing include.
std::vector<std::string> read_request_file(const std::string& name, const MacroMap& macros,
                                           const std::vector<std::string>& search_path);

// The channels info tags name: for every record with info(tag, "F1 F2 ..."), "rec.F1", ...
std::vector<std::string> channels_from_info(const Database& db, std::string_view tag);

// Writes `text` to `path` atomically: a temporary file in the same directory, fsync, rename over
// `path`, fsync of the directory. With keep_backup the file it replaces becomes `path`B first
// (a hard link, so `path` never goes missing). Throws Error naming the file and the errno text;
// `path` is then unchanged.
void write_file_atomically(const std::string& path, std::string_view text, bool keep_backup);

class Autosave {
public:
    using Report = std::function<void(const std::string& message)>;
    // `report` receives notes and errors (a missing or bad save file, a name no longer in the
    // database, a failed write); none of them is fatal.
    Autosave(Database& db, Report report);
    ~Autosave();
    Autosave(const Autosave&) = delete;
    Autosave& operator=(const Autosave&) = delete;

    // set_savefile_path: where .sav files are read and written (default: the current directory).
    void set_save_dir(std::string dir);
    const std::string& save_dir() const;
    // set_requestfile_path: one more directory request files are searched in.
    void add_request_dir(std::string dir);
    // set_pass0_restoreFile / set_pass1_restoreFile: a .sav file to restore at restore(). Both
    // passes run at the same point (after init, before PINI), pass 0 first.
    void add_restore_file(std::string sav_name, int pass);
    // create_monitor_set: saves the channels of a request file (with macros "P=...") to the .sav
    // file of the same base name, at most once per period_s. Throws Error for a bad request file.
    void add_request_set(const std::string& req_name, double period_s, const std::string& macros);
    // Saves `channels` to `sav_name` (e.g. the channels of info tags), at most once per period_s.
    void add_set(std::string sav_name, std::vector<std::string> channels, double period_s);
    // makeAutosaveFileFromDbInfo: writes a request file of the fields the info tag names.
    void write_request_from_info(const std::string& req_path, std::string_view tag) const;

    // Restores every restore file (the hook Database::init_records calls before PINI), once: later
    // calls (records added while the IOC runs) do nothing. A missing
    // file is noted; a bad or truncated one is reported and its .savB used if that is good; a
    // name that is not in the database (or a value it refuses) is reported and skipped.
    void restore();
    // Saves the sets whose values changed, each at most once per its period; `now_s` is
    // monotonic time. Cheap when nothing is due.
    void tick(double now_s);
    // Saves every set whose values changed since its last write (clean shutdown).
    void flush();

    std::size_t set_count() const;
    uint64_t writes() const;        // .sav files written
    uint64_t write_failures() const;
    std::size_t restored() const;   // values restored by restore()

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

class IocShell;

// The st.cmd commands of synApps autosave, added to a soft IOC's shell: set_savefile_path,
// set_requestfile_path, set_pass0_restoreFile, set_pass1_restoreFile, create_monitor_set (and
// create_periodic_set, which saves the same way), makeAutosaveFileFromDbInfo; the
// save_restoreSet_* tuning commands are accepted with a note. `note` gets those notes.
void add_autosave_commands(IocShell& shell, Autosave& autosave,
                           std::function<void(const std::string&)> note);

// The defaults for an IOC whose databases carry info tags and nothing else (`beamctl softioc
// --autosave DIR`, `autosave:` in ioc.yaml): before init, restore DIR/info_positions.sav (pass 0)
// and DIR/info_settings.sav (pass 1); creates DIR if needed. Throws Error if it cannot.
void autosave_defaults_before_init(Autosave& autosave, const std::string& dir);
// After init: save the fields of info(autosaveFields_pass0) to info_positions.sav and those of
// info(autosaveFields) to info_settings.sav, each at most once per period_s.
void autosave_defaults_after_init(Autosave& autosave, const Database& db, double period_s);

} // namespace beamctl::pv
