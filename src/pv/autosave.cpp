#include "pv/autosave.hpp"

#include "core/error.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

namespace beamctl::pv {

namespace {

namespace fs = std::filesystem;

constexpr const char* kVersion = "save/restore V5.11";
constexpr const char* kArrayMarker = "@array@";
constexpr const char* kEnumMarker = "@ENUM@";
constexpr double kCheckInterval_s = 0.5; // how often a set looks for changed values

std::string trim(std::string_view s) {
    std::size_t b = 0, e = s.size();
    while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
    while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
    return std::string(s.substr(b, e - b));
}

std::string read_file(const std::string& path, bool* missing = nullptr) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        if (missing) *missing = errno == ENOENT;
        throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    }
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

// The shortest %g text that reads back as the same double.
std::string format_number(double v) {
    char buf[64];
    for (int prec = 6; prec <= 17; ++prec) {
        std::snprintf(buf, sizeof buf, "%.*g", prec, v);
        if (std::strtod(buf, nullptr) == v || std::isnan(v)) break;
    }
    return buf;
}

std::string now_stamp() {
    std::time_t t = std::time(nullptr);
    std::tm tm{};
    localtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%y%m%d-%H%M%S", &tm);
    return buf;
}

std::string join(const std::string& dir, const std::string& name) {
    if (dir.empty() || fs::path(name).is_absolute()) return name;
    return (fs::path(dir) / name).string();
}

// The value of one channel now, or false if the name resolves to nothing.
bool capture(const Database& db, const std::string& name, SavedValue& out) {
    Address a;
    if (!db.resolve(name, a) || a.kind == Address::Kind::RecordType) return false;
    Record& r = *a.rec;
    const FieldDesc& f = *a.field;
    out.name = name;
    out.values.clear();
    if (a.kind == Address::Kind::StringHead) { // a long string (lsi VAL): its text whole
        Elements e = r.elements(f);
        const char* s = static_cast<const char*>(e.data);
        out.array = false;
        out.values.emplace_back(s, strnlen(s, e.capacity));
        return true;
    }
    if (!(f.flags & kArray)) {
        out.array = false;
        out.values.push_back(format_field(r, f));
        return true;
    }
    out.array = true;
    Elements e = r.elements(f);
    for (uint32_t i = 0; i < e.count; ++i) {
        if (e.type == Dbf::String) {
            char s[kStringSize] = {};
            get_element(r, f, e, i, Prim::String, s);
            out.values.emplace_back(s, strnlen(s, sizeof s));
        } else {
            double v = 0;
            get_element(r, f, e, i, Prim::Double, &v);
            out.values.push_back(format_number(v));
        }
    }
    return true;
}

} // namespace

// --- the file format ----------------------------------------------------------------------------

std::string format_save_file(const std::vector<SavedValue>& values, std::string_view stamp) {
    std::string out = SB() << "# " << kVersion << "\tAutomatically generated - DO NOT MODIFY - "
                           << stamp << "\n";
    for (const auto& v : values) {
        out += v.name;
        out += ' ';
        if (!v.array) {
            if (!v.values.empty()) out += v.values[0];
        } else {
            out += kArrayMarker;
            out += " {";
            for (const auto& item : v.values) {
                out += " \"";
                for (char c : item) {
                    if (c == '"' || c == '\\') out += '\\';
                    out += c;
                }
                out += '"';
            }
            out += " }";
        }
        out += '\n';
    }
    out += "<END>\n";
    return out;
}

std::vector<SavedValue> parse_save_file(std::string_view text, const std::string& path) {
    std::vector<SavedValue> out;
    bool end = false;
    int lineno = 0;
    std::size_t pos = 0;
    while (pos < text.size()) {
        std::size_t nl = text.find('\n', pos);
        std::string_view line = text.substr(pos, nl == std::string_view::npos ? text.npos : nl - pos);
        pos = nl == std::string_view::npos ? text.size() : nl + 1;
        ++lineno;
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        auto fail = [&](const std::string& what) -> Error {
            return Error(SB() << path << ":" << lineno << ": " << what);
        };
        if (end) {
            if (!trim(line).empty()) throw fail("text after the <END> line");
            continue;
        }
        if (line.empty()) continue;
        if (line[0] == '#' || line[0] == '!') continue; // header, unsaved channels, comments
        if (line.starts_with("<END>")) {
            end = true;
            continue;
        }
        if (std::isspace(static_cast<unsigned char>(line[0])) || line.find('\0') != line.npos)
            throw fail("not a 'NAME VALUE' line");
        std::size_t sp = line.find_first_of(" \t");
        SavedValue v;
        v.line = lineno;
        v.name = std::string(line.substr(0, sp));
        std::string_view rest = sp == line.npos ? std::string_view() : line.substr(sp + 1);
        std::string t = trim(rest);
        if (t.starts_with(kArrayMarker)) {
            v.array = true;
            std::size_t i = t.find('{', std::strlen(kArrayMarker));
            if (i == t.npos || trim(std::string_view(t).substr(std::strlen(kArrayMarker), i - std::strlen(kArrayMarker))) != "")
                throw fail(SB() << v.name << ": array value without '{'");
            ++i;
            bool closed = false;
            while (i < t.size()) {
                char c = t[i];
                if (std::isspace(static_cast<unsigned char>(c))) {
                    ++i;
                } else if (c == '}') {
                    closed = true;
                    ++i;
                    break;
                } else if (c == '"') {
                    std::string item;
                    ++i;
                    bool done = false;
                    while (i < t.size()) {
                        if (t[i] == '\\' && i + 1 < t.size()) {
                            item += t[i + 1];
                            i += 2;
                        } else if (t[i] == '"') {
                            done = true;
                            ++i;
                            break;
                        } else {
                            item += t[i++];
                        }
                    }
                    if (!done) throw fail(SB() << v.name << ": unterminated \"...\" in the array");
                    v.values.push_back(std::move(item));
                } else {
                    throw fail(SB() << v.name << ": expected \"element\" or '}' in the array at '"
                                    << t.substr(i, 10) << "'");
                }
            }
            if (!closed) throw fail(SB() << v.name << ": array without its closing '}'");
            if (!trim(std::string_view(t).substr(i)).empty())
                throw fail(SB() << v.name << ": text after the array's '}'");
        } else if (t.starts_with(kEnumMarker)) { // "@ENUM@ 2 "State"": the number counts
            std::istringstream is(t.substr(std::strlen(kEnumMarker)));
            long n;
            if (!(is >> n)) throw fail(SB() << v.name << ": " << kEnumMarker << " without a number");
            v.values.push_back(std::to_string(n));
        } else {
            v.values.emplace_back(rest); // the rest of the line, as synApps reads it
        }
        out.push_back(std::move(v));
    }
    if (!end)
        throw Error(SB() << path << ":" << lineno
                         << ": no <END> line: the file is incomplete (truncated)");
    return out;
}

// --- request files ------------------------------------------------------------------------------

namespace {

void read_request(const std::string& name, const MacroMap& macros,
                  const std::vector<std::string>& search_path, std::vector<std::string>& out,
                  int depth, const std::string& from) {
    if (depth > 16) throw Error(SB() << from << ": request files nested more than 16 deep");
    std::string path = name;
    std::error_code ec;
    if (!fs::path(name).is_absolute())
        for (const auto& dir : search_path) {
            fs::path p = fs::path(dir) / name;
            if (fs::is_regular_file(p, ec)) {
                path = p.string();
                break;
            }
        }
    std::string text;
    try {
        text = read_file(path);
    } catch (const Error& e) {
        throw Error(SB() << (from.empty() ? "" : from + ": ") << e.what());
    }
    std::istringstream in(text);
    int lineno = 0;
    for (std::string raw; std::getline(in, raw);) {
        ++lineno;
        const std::string where = SB() << path << ":" << lineno;
        std::string line = trim(raw);
        if (line.empty() || line[0] == '#') continue;
        line = expand_macros(line, macros, SourceLoc{path, lineno, 1});
        std::istringstream words(line);
        std::string first;
        words >> first;
        if (first == "file") {
            std::string file;
            words >> file;
            if (file.size() >= 2 && (file.front() == '"' || file.front() == '\''))
                file = file.substr(1, file.size() - 2);
            if (file.empty()) throw Error(SB() << where << ": 'file' without a file name");
            std::string defs;
            std::getline(words, defs);
            MacroMap m = macros;
            defs = trim(defs);
            if (defs.size() >= 2 && defs.front() == '"' && defs.back() == '"')
                defs = defs.substr(1, defs.size() - 2);
            for (auto& [k, v] : parse_macro_defs(defs, SourceLoc{path, lineno, 1})) m[k] = v;
            read_request(file, m, search_path, out, depth + 1, where);
            continue;
        }
        out.push_back(first);
    }
}

} // namespace

std::vector<std::string> read_request_file(const std::string& name, const MacroMap& macros,
                                           const std::vector<std::string>& search_path) {
    std::vector<std::string> out;
    read_request(name, macros, search_path, out, 0, "");
    return out;
}

std::vector<std::string> channels_from_info(const Database& db, std::string_view tag) {
    std::vector<std::string> out;
    for (Record* r : db.records())
        for (const auto& [k, v] : r->infos()) {
            if (k != tag) continue;
            std::istringstream fields(v);
            for (std::string f; fields >> f;) out.push_back(std::string(r->name()) + "." + f);
        }
    return out;
}

// --- atomic write -------------------------------------------------------------------------------

void write_file_atomically(const std::string& path, std::string_view text, bool keep_backup) {
    fs::path p(path);
    std::string dir = p.has_parent_path() ? p.parent_path().string() : ".";
    std::string tmpl = path + ".tmpXXXXXX";
    std::vector<char> tmp(tmpl.begin(), tmpl.end());
    tmp.push_back('\0');
    int fd = ::mkstemp(tmp.data());
    if (fd < 0)
        throw Error(SB() << path << ": cannot create a temporary file in " << dir << ": "
                         << std::strerror(errno));
    auto fail = [&](const char* what) {
        int e = errno;
        if (fd >= 0) ::close(fd);
        ::unlink(tmp.data());
        return Error(SB() << path << ": " << what << ": " << std::strerror(e) << " (the previous "
                          << "file is unchanged)");
    };
    ::fchmod(fd, 0644);
    const char* d = text.data();
    std::size_t left = text.size();
    while (left > 0) {
        ssize_t n = ::write(fd, d, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            if (n == 0) errno = EIO;
            throw fail("write failed");
        }
        d += n;
        left -= std::size_t(n);
    }
    if (::fsync(fd) != 0) throw fail("fsync failed");
    if (::close(fd) != 0) {
        fd = -1;
        throw fail("close failed");
    }
    fd = -1;
    if (keep_backup) {
        const std::string backup = path + "B";
        struct stat st {};
        if (::stat(path.c_str(), &st) == 0) {
            ::unlink(backup.c_str());
            if (::link(path.c_str(), backup.c_str()) != 0) {
                // No hard links here: copy the old file instead.
                std::error_code ec;
                fs::copy_file(path, backup, fs::copy_options::overwrite_existing, ec);
            }
        }
    }
    if (::rename(tmp.data(), path.c_str()) != 0) throw fail("rename failed");
    int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
        ::fsync(dfd);
        ::close(dfd);
    }
}

// --- the engine ---------------------------------------------------------------------------------

struct Autosave::Impl {
    Database& db;
    Report report;
    std::string save_dir;
    std::vector<std::string> request_dirs;
    std::vector<std::pair<int, std::string>> restore_files; // (pass, name)
    struct Set {
        std::string sav_name;
        std::vector<std::string> channels;
        double period_s;
        std::string last_body;  // the values of the last write ("" before the first)
        double last_write_s = -1e300;
        double next_check_s = -1e300;
        bool wrote = false;
        std::vector<std::string> missing_reported;
    };
    std::vector<Set> sets;
    uint64_t writes = 0, write_failures = 0;
    std::size_t restored = 0;
    bool restore_done = false;

    void note(const std::string& m) const {
        if (report) report(m);
    }

    // The values of a set as file lines (without header and <END>), and how many are missing.
    std::string body(Set& s, std::vector<SavedValue>& vals) {
        vals.clear();
        std::string missing;
        int not_found = 0;
        for (const auto& ch : s.channels) {
            SavedValue v;
            if (capture(db, ch, v)) {
                vals.push_back(std::move(v));
            } else {
                ++not_found;
                if (std::find(s.missing_reported.begin(), s.missing_reported.end(), ch) ==
                    s.missing_reported.end()) {
                    s.missing_reported.push_back(ch);
                    note(SB() << "autosave: " << s.sav_name << ": '" << ch
                              << "' is not in the database: not saved");
                }
            }
        }
        std::string text = format_save_file(vals, "");
        return text.substr(text.find('\n') + 1);
    }

    // Whether an existing file is a whole save file (worth keeping as .savB).
    static bool good_file(const std::string& path) {
        try {
            parse_save_file(read_file(path), path);
            return true;
        } catch (const Error&) {
            return false;
        }
    }

    void write(Set& s, const std::vector<SavedValue>& vals, const std::string& b, double now) {
        const std::string path = join(save_dir, s.sav_name);
        bool keep = s.wrote || good_file(path); // a bad .sav must not replace a good .savB
        try {
            write_file_atomically(path, format_save_file(vals, now_stamp()), keep);
            s.wrote = true;
            s.last_body = b;
            ++writes;
        } catch (const Error& e) {
            ++write_failures;
            note(SB() << "autosave: " << e.what());
        }
        s.last_write_s = now; // a failed write is retried after a period too
    }

    void tick(double now, bool force) {
        for (Set& s : sets) {
            if (!force && now < s.next_check_s) continue;
            s.next_check_s = now + std::min(s.period_s, kCheckInterval_s);
            std::vector<SavedValue> vals;
            std::string b = body(s, vals);
            if (s.wrote && b == s.last_body) continue;
            if (!force && now < s.last_write_s + s.period_s) {
                s.next_check_s = s.last_write_s + s.period_s;
                continue;
            }
            write(s, vals, b, now);
        }
    }

    // Restores one file; false if it could not be read or parsed (nothing restored then).
    bool restore_file(const std::string& path, bool quiet_missing) {
        std::string text;
        bool missing = false;
        try {
            text = read_file(path, &missing);
        } catch (const Error& e) {
            if (!(missing && quiet_missing))
                note(SB() << "autosave: " << (missing ? path + ": not found (nothing restored)" : e.what()));
            return false;
        }
        std::vector<SavedValue> vals;
        try {
            vals = parse_save_file(text, path);
        } catch (const Error& e) {
            note(SB() << "autosave: " << e.what() << ": file ignored");
            return false;
        }
        std::size_t n = 0;
        for (const auto& v : vals) {
            std::string why;
            if (put(v, why))
                ++n;
            else
                note(SB() << "autosave: " << path << ":" << v.line << ": " << v.name << ": " << why
                          << ": skipped");
        }
        restored += n;
        note(SB() << "autosave: restored " << n << " value(s) from " << path);
        return true;
    }

    // dbPut of a saved value: stored without processing.
    bool put(const SavedValue& v, std::string& why) {
        Address a;
        if (!db.resolve(v.name, a, &why) || a.kind == Address::Kind::RecordType) {
            if (why.empty()) why = "not a field";
            why = "not in the database (" + why + ")";
            return false;
        }
        if (a.field->flags & kReadOnly) {
            why = "the field is read-only";
            return false;
        }
        PutStatus st;
        // A text stored whole through a char-array address ("rec.FIELD$"): its characters and NUL.
        auto store_text = [&](const Address& chars, std::string z) {
            z.push_back('\0');
            return db.store_value(chars, Prim::Char, z.data(), uint32_t(std::min<std::size_t>(z.size(), chars.count)));
        };
        Address whole;
        if (a.kind == Address::Kind::StringHead && !v.array && db.resolve(v.name + "$", whole)) {
            st = store_text(whole, v.values.empty() ? std::string() : v.values[0]);
        } else if (v.array || (a.field->flags & kArray)) {
            if (v.values.empty()) return true;
            std::vector<char> buf(v.values.size() * kStringSize, '\0');
            for (std::size_t k = 0; k < v.values.size(); ++k)
                copy_string(&buf[k * kStringSize], kStringSize, v.values[k]);
            st = db.store_value(a, Prim::String, buf.data(), uint32_t(std::min<std::size_t>(v.values.size(), a.count)));
        } else {
            const std::string& s = v.values.empty() ? std::string() : v.values[0];
            Address la;
            if (a.kind == Address::Kind::LongString) { // saved as "rec.FIELD$": the text whole
                st = store_text(a, s);
            } else if (a.field->dbf == Dbf::String && s.size() >= std::size_t(kStringSize) &&
                       db.resolve(v.name + "$", la)) {
                st = store_text(la, s);
            } else {
                char buf[kStringSize];
                copy_string(buf, sizeof buf, s);
                st = db.store_value(a, Prim::String, buf, 1);
            }
        }
        if (st == PutStatus::Ok) return true;
        why = st == PutStatus::BadValue ? "the value does not fit the field" : "the record refused the value";
        return false;
    }
};

Autosave::Autosave(Database& db, Report report)
    : impl_(std::make_unique<Impl>(Impl{db, std::move(report), {}, {}, {}, {}, 0, 0, 0, false})) {}
Autosave::~Autosave() = default;

void Autosave::set_save_dir(std::string dir) { impl_->save_dir = std::move(dir); }
const std::string& Autosave::save_dir() const { return impl_->save_dir; }
void Autosave::add_request_dir(std::string dir) { impl_->request_dirs.push_back(std::move(dir)); }
void Autosave::add_restore_file(std::string sav_name, int pass) {
    impl_->restore_files.emplace_back(pass, std::move(sav_name));
}

void Autosave::add_request_set(const std::string& req_name, double period_s,
                               const std::string& macros) {
    MacroMap m = parse_macro_defs(macros, SourceLoc{"create_monitor_set macros", 1, 1});
    std::vector<std::string> channels = read_request_file(req_name, m, impl_->request_dirs);
    std::string base = fs::path(req_name).filename().string();
    if (base.ends_with(".req")) base.resize(base.size() - 4);
    add_set(base + ".sav", std::move(channels), period_s);
}

void Autosave::add_set(std::string sav_name, std::vector<std::string> channels, double period_s) {
    if (!(period_s > 0)) period_s = 5;
    for (auto& s : impl_->sets)
        if (s.sav_name == sav_name)
            throw Error(SB() << "autosave: " << sav_name << " is already saved by another set");
    Impl::Set s;
    s.sav_name = std::move(sav_name);
    s.channels = std::move(channels);
    s.period_s = period_s;
    impl_->sets.push_back(std::move(s));
}

void Autosave::write_request_from_info(const std::string& req_path, std::string_view tag) const {
    std::string text;
    for (const auto& ch : channels_from_info(impl_->db, tag)) text += ch + "\n";
    write_file_atomically(req_path, text, false);
}

void Autosave::restore() {
    Impl& i = *impl_;
    // Once, at the IOC's start: records added later (an RCP application's) must not get every
    // saved value put back over the running ones.
    if (i.restore_done) return;
    i.restore_done = true;
    for (int pass : {0, 1})
        for (const auto& [p, name] : i.restore_files) {
            if (p != pass) continue;
            const std::string path = join(i.save_dir, name);
            if (i.restore_file(path, false)) continue;
            std::error_code ec;
            if (!fs::exists(path, ec)) continue; // nothing to fall back from
            const std::string backup = path + "B";
            if (fs::exists(backup, ec)) {
                i.note(SB() << "autosave: trying the backup file " << backup);
                i.restore_file(backup, false);
            }
        }
}

void Autosave::tick(double now_s) { impl_->tick(now_s, false); }
void Autosave::flush() { impl_->tick(impl_->sets.empty() ? 0 : impl_->sets[0].last_write_s, true); }
std::size_t Autosave::set_count() const { return impl_->sets.size(); }
uint64_t Autosave::writes() const { return impl_->writes; }
uint64_t Autosave::write_failures() const { return impl_->write_failures; }
std::size_t Autosave::restored() const { return impl_->restored; }

} // namespace beamctl::pv
