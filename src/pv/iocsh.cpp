#include "pv/iocsh.hpp"

#include "core/glob.hpp"

#include "core/error_list.hpp"
#include "core/macros.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"
#include "pv/substitutions.hpp"
#include "pv/sub_routines.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>
#include <unistd.h>

extern char** environ;

namespace beamctl::pv {

namespace {

namespace fs = std::filesystem;

// An error whose messages already say where they are (a .db file's "x.db:3:5: ..."); the script
// that ran the command adds the line that did, instead of putting it in front.
class Located : public MultiError {
public:
    using MultiError::MultiError;
};

// Each message of e (one, or every one of a MultiError), with `suffix` appended.
std::vector<std::string> messages_of(const Error& e, const std::string& suffix = "") {
    std::vector<std::string> out;
    if (const auto* m = dynamic_cast<const MultiError*>(&e))
        for (const auto& s : m->errors()) out.push_back(s + suffix);
    else
        out.push_back(e.what() + suffix);
    return out;
}

std::string read_text_file(const std::string& path) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw Error(SB() << path << ": cannot open: Is a directory");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw Error(SB() << path << ": read error: " << std::strerror(errno));
    return ss.str();
}

// "A=1,B=2" as a MacroMap; a bad definition is an Error naming `origin` and the column.
MacroMap parse_macros(const std::string& defs, const std::string& origin) {
    try {
        return parse_macro_defs(defs, SourceLoc{"", 1, 1});
    } catch (const Error& e) {
        std::string msg = e.what();
        const std::string lead = "<input>:1:";
        std::string col;
        if (msg.rfind(lead, 0) == 0) {
            std::size_t end = msg.find(": ", lead.size());
            if (end != std::string::npos) {
                col = msg.substr(lead.size(), end - lead.size());
                msg = msg.substr(end + 2);
            }
        }
        throw Error(SB() << origin << " \"" << defs << "\""
                         << (col.empty() ? "" : ", column " + col) << ": " << msg);
    }
}

// Every environment variable as a macro.
MacroMap environment_macros() {
    MacroMap m;
    for (char** e = environ; e && *e; ++e) {
        const char* eq = std::strchr(*e, '=');
        if (!eq) continue;
        m[std::string(*e, std::size_t(eq - *e))] = eq + 1;
    }
    return m;
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
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

// EPICS dbTranslateEscape: C escapes of `echo`.
std::string translate_escapes(std::string_view s) {
    std::string out;
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (s[i] != '\\' || i + 1 >= s.size()) {
            out += s[i];
            continue;
        }
        char c = s[++i];
        switch (c) {
        case 'a':
            out += '\a';
            break;
        case 'b':
            out += '\b';
            break;
        case 'f':
            out += '\f';
            break;
        case 'n':
            out += '\n';
            break;
        case 'r':
            out += '\r';
            break;
        case 't':
            out += '\t';
            break;
        case 'v':
            out += '\v';
            break;
        case 'x': {
            int v = 0, n = 0;
            while (n < 2 && i + 1 < s.size() &&
                   std::isxdigit(static_cast<unsigned char>(s[i + 1]))) {
                char h = s[++i];
                v = v * 16 + (std::isdigit(static_cast<unsigned char>(h))
                                  ? h - '0'
                                  : (std::tolower(h) - 'a' + 10));
                ++n;
            }
            out += char(v);
            break;
        }
        default:
            if (c >= '0' && c <= '7') {
                int v = c - '0', n = 1;
                while (n < 3 && i + 1 < s.size() && s[i + 1] >= '0' && s[i + 1] <= '7')
                    v = v * 8 + (s[++i] - '0'), ++n;
                out += char(v);
            } else {
                out += c; // \\ \' \" \? and any other character: itself
            }
        }
    }
    return out;
}

// --- iocsh's line splitting -------------------------------------------------------------------

struct Words {
    std::vector<std::string> argv;
    std::string input;   // `< file`
    std::string output;  // `> file`, `>> file`
    bool append = false; // `>>`
    int output_fd = 1;   // `2> file`
    bool has_input = false, has_output = false;
};

// Splits a line as iocsh does. Returns "" or what is wrong ("Unbalanced quote.", ...).
std::string split_words(std::string_view line, Words& w) {
    enum class Target { Arg, In, Out };
    Target pending = Target::Arg; // where the next word goes
    Target current = Target::Arg; // where the word being read goes
    std::string word;
    bool inword = false, backslash = false;
    char quote = 0;
    auto end_word = [&] {
        if (current == Target::Arg)
            w.argv.push_back(word);
        else if (current == Target::In)
            w.input = word;
        else
            w.output = word;
        word.clear();
        inword = false;
    };
    for (std::size_t i = 0; i < line.size(); ++i) {
        char c = line[i];
        bool sep = !quote && !backslash && std::strchr(" \t(),\r\n", c) != nullptr;
        if (!quote && !backslash) {
            if (c == '\\') {
                backslash = true;
                continue;
            }
            if (c == '<') {
                if (pending != Target::Arg || w.has_input) return "Illegal redirection.";
                pending = Target::In;
                w.has_input = true;
                sep = true;
            }
            int fd = 1;
            if (c >= '1' && c <= '9' && i + 1 < line.size() && line[i + 1] == '>') {
                fd = c - '0';
                c = '>';
                ++i;
            }
            if (c == '>') {
                if (pending != Target::Arg || w.has_output) return "Illegal redirection.";
                pending = Target::Out;
                w.has_output = true;
                w.output_fd = fd;
                if (i + 1 < line.size() && line[i + 1] == '>') {
                    w.append = true;
                    ++i;
                }
                sep = true;
            }
        }
        if (inword) {
            if (c == quote) {
                quote = 0;
            } else if (!quote && !backslash) {
                if (sep)
                    end_word();
                else if (c == '"' || c == '\'')
                    quote = c;
                else
                    word += c;
            } else {
                word += c;
            }
        } else if (!sep) {
            if ((c == '"' || c == '\'') && !backslash) quote = c;
            current = pending;
            pending = Target::Arg;
            if (!quote) word += c;
            inword = true;
        }
        backslash = false;
    }
    if (inword) end_word();
    if (pending != Target::Arg) return "Illegal redirection.";
    if (quote) return "Unbalanced quote.";
    if (backslash) return "Trailing backslash.";
    return "";
}

} // namespace

// --- the shell ----------------------------------------------------------------------------------

struct IocShell::Impl {
    Database& db;
    IocShellOptions opt;
    IocShellHooks hooks;
    std::ostream* out;
    std::ostream* err;
    bool initialised = false;
    std::size_t records = 0;
    std::string acf_given; // asSetFilename's file, as given
    std::string acf_dir;   // the current directory then
    std::string acf_file;  // as usable now (acf_file())
    std::string acf_subs;  // asSetSubstitutions

    // One running script (iocshBody): its macros and its error policy.
    struct Scope {
        MacroMap macros;
        bool continue_on_error = false;
    };
    std::vector<Scope*> scopes;
    int depth = 0;
    std::map<std::string, std::pair<std::string, CommandFn>, std::less<>> added; // add_command

    // A command: its words, where it is, and the stream its output goes to.
    struct Call {
        const std::vector<std::string>& argv;
        std::string where; // "st.cmd:12"
        std::ostream& out;
        Scope& scope;
        const std::string& arg(std::size_t i) const {
            static const std::string none;
            return i < argv.size() ? argv[i] : none;
        }
        bool has(std::size_t i) const { return i < argv.size(); }
    };
    using Handler = void (Impl::*)(const Call&);
    struct Command {
        Handler fn;
        const char* usage;
    };

    Impl(Database& d, IocShellOptions o, IocShellHooks h)
        : db(d)
        , opt(std::move(o))
        , hooks(std::move(h)) {
        out = opt.out ? opt.out : &std::cout;
        err = opt.err ? opt.err : &std::cerr;
        // `cd` must not move the -I directories.
        for (auto& dir : opt.include_path) {
            std::error_code ec;
            fs::path abs = fs::absolute(dir, ec);
            if (!ec) dir = abs.lexically_normal().string();
        }
    }

    static const std::map<std::string, Command, std::less<>>& commands() {
        static const std::map<std::string, Command, std::less<>> table = {
            {"epicsEnvSet", {&Impl::cmd_env_set, "epicsEnvSet NAME VALUE"}},
            {"epicsEnvUnset", {&Impl::cmd_env_unset, "epicsEnvUnset NAME"}},
            {"epicsEnvShow", {&Impl::cmd_env_show, "epicsEnvShow [NAME]"}},
            {"dbLoadRecords", {&Impl::cmd_load_records, "dbLoadRecords FILE [MACROS]"}},
            {"dbLoadTemplate", {&Impl::cmd_load_template, "dbLoadTemplate FILE [MACROS]"}},
            {"dlload", {&Impl::cmd_dlload, "dlload LIBRARY.so"}},
            {"dbLoadDatabase", {&Impl::cmd_ignored, "dbLoadDatabase FILE [PATH] [SUBSTITUTIONS]"}},
            {"iocInit", {&Impl::cmd_ioc_init, "iocInit"}},
            {"dbpf", {&Impl::cmd_dbpf, "dbpf PV VALUE"}},
            {"dbgf", {&Impl::cmd_dbgf, "dbgf PV"}},
            {"dbl", {&Impl::cmd_dbl, "dbl [RECORDTYPE] [\"FIELD FIELD ...\"]"}},
            {"asSetFilename", {&Impl::cmd_as_set_filename, "asSetFilename FILE.acf"}},
            {"asSetSubstitutions", {&Impl::cmd_as_set_substitutions, "asSetSubstitutions MACROS"}},
            {"cd", {&Impl::cmd_cd, "cd DIRECTORY"}},
            {"pwd", {&Impl::cmd_pwd, "pwd"}},
            {"echo", {&Impl::cmd_echo, "echo TEXT"}},
            {"iocshLoad", {&Impl::cmd_iocsh_load, "iocshLoad FILE [MACROS]"}},
            {"on", {&Impl::cmd_on, "on error continue|break"}},
            {"epicsThreadSleep", {&Impl::cmd_sleep, "epicsThreadSleep SECONDS"}},
            {"iocLogInit", {&Impl::cmd_ignored, "iocLogInit"}},
            {"errlogInit", {&Impl::cmd_ignored, "errlogInit [BUFSIZE]"}},
            {"errlogInit2", {&Impl::cmd_ignored, "errlogInit2 [BUFSIZE] [MAXMSG]"}},
        };
        return table;
    }

    // --- script running ---

    void run_text(std::string_view text, const std::string& name, const MacroMap& macros) {
        if (depth >= 32)
            throw Error(SB() << name << ": scripts nested more than 32 deep (a '<' loop?)");
        Scope scope;
        scope.macros = macros;
        scopes.push_back(&scope);
        ++depth;
        struct Pop {
            Impl& s;
            ~Pop() {
                s.scopes.pop_back();
                --s.depth;
            }
        } pop{*this};
        int lineno = 0;
        std::size_t pos = 0;
        while (pos < text.size()) {
            std::size_t nl = text.find('\n', pos);
            std::string_view raw =
                text.substr(pos, nl == std::string_view::npos ? std::string_view::npos : nl - pos);
            pos = nl == std::string_view::npos ? text.size() : nl + 1;
            ++lineno;
            if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
            try {
                if (!run_line(raw, name, lineno, scope)) break;
            } catch (const Error& e) {
                if (!scope.continue_on_error) throw;
                for (const auto& m : messages_of(e)) *err << m << "\n";
                err->flush();
            }
        }
    }

    // Runs one line; returns false at `exit`.
    bool run_line(std::string_view raw, const std::string& file, int lineno, Scope& scope) {
        const std::string where = SB() << file << ":" << lineno;
        std::size_t i = 0;
        while (i < raw.size() && std::isspace(static_cast<unsigned char>(raw[i]))) ++i;
        if (i == raw.size()) return true;
        if (raw[i] == '#') {
            if (opt.echo && (i + 1 >= raw.size() || raw[i + 1] != '-')) *out << raw << "\n";
            return true;
        }
        std::string line(raw);
        if (line.find('$') != std::string::npos) {
            MacroMap m = environment_macros();
            for (Scope* s : scopes)
                for (const auto& [k, v] : s->macros) m[k] = v;
            try {
                line = expand_macros(line, m, SourceLoc{file, lineno, 1}, MacroEscapes::keep);
            } catch (const Error& e) {
                throw Located(messages_of(e));
            }
        }
        i = 0;
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        if (opt.echo && !line.empty() &&
            !(line[i] == '#' && i + 1 < line.size() && line[i + 1] == '-'))
            *out << line << "\n";
        if (i == line.size() || line[i] == '#') return true;

        Words w;
        std::string bad = split_words(std::string_view(line).substr(i), w);
        if (!bad.empty()) throw Located({SB() << where << ": " << bad});
        if (w.argv.empty() && !w.has_input) return true;
        if (w.argv.empty()) { // `< file`: run it
            nested(w.input, scope.macros, where, "included from");
            return true;
        }
        if (w.argv[0] == "exit") return false;
        if (w.has_input)
            throw Located({SB() << where << ": " << w.argv[0]
                                << ": '<' (input from a file) works only on a line of its own"});
        std::ofstream file_out;
        if (w.has_output) {
            if (w.output_fd != 1)
                throw Located({SB() << where << ": " << w.output_fd
                                    << "> is not supported (only the command's output, '>' or "
                                       "'>>', can be redirected)"});
            file_out.open(w.output, w.append ? std::ios::app : std::ios::trunc);
            if (!file_out)
                throw Located({SB() << where << ": cannot open \"" << w.output
                                    << "\": " << std::strerror(errno)});
        }
        Call call{w.argv, where, w.has_output ? static_cast<std::ostream&>(file_out) : *out, scope};
        try {
            dispatch(call);
        } catch (const Located& e) {
            throw Located(
                messages_of(e, SB() << "\n  loaded by " << where << " (" << w.argv[0] << ")"));
        } catch (const Error& e) {
            throw Located({SB() << where << ": " << e.what()});
        }
        return true;
    }

    void nested(const std::string& path, const MacroMap& macros, const std::string& where,
                const char* how) {
        std::string text;
        try {
            text = read_text_file(path);
        } catch (const Error& e) {
            throw Located({SB() << where << ": " << e.what()});
        }
        try {
            run_text(text, path, macros);
        } catch (const Error& e) {
            throw Located(messages_of(e, SB() << "\n  " << how << " " << where));
        }
    }

    void dispatch(const Call& c) {
        const std::string& name = c.argv[0];
        const auto& table = commands();
        auto it = table.find(name);
        if (it != table.end()) {
            (this->*(it->second.fn))(c);
            return;
        }
        if (auto ad = added.find(name); ad != added.end()) {
            ad->second.second(c.argv, c.out);
            return;
        }
        if (name.size() > 27 && name.ends_with("_registerRecordDeviceDriver")) {
            cmd_ignored(c);
            return;
        }
        std::string best;
        std::size_t best_d = std::max<std::size_t>(1, name.size() / 3) + 1;
        for (const auto& [known, cmd] : table) {
            std::size_t d = edit_distance(name, known);
            if (d < best_d) best_d = d, best = known;
        }
        for (const auto& [known, cmd] : added) {
            std::size_t d = edit_distance(name, known);
            if (d < best_d) best_d = d, best = known;
        }
        throw Error(SB() << "unknown command '" << name << "'"
                         << (best.empty() ? "" : " (did you mean '" + best + "'?)"));
    }

    static void need(const Call& c, std::size_t n) {
        if (c.argv.size() > n && !c.argv[n].empty()) return;
        throw Error(SB() << c.argv[0] << ": missing argument " << n
                         << " (usage: " << commands().find(c.argv[0])->second.usage << ")");
    }

    // --- commands ---

    void cmd_env_set(const Call& c) {
        need(c, 1);
        if (!c.has(2))
            throw Error(SB() << "epicsEnvSet: missing the value of " << c.arg(1)
                             << " (usage: epicsEnvSet NAME VALUE)");
        if (c.arg(1).find('=') != std::string::npos)
            throw Error(SB() << "epicsEnvSet: name '" << c.arg(1) << "' contains '='");
        ::setenv(c.arg(1).c_str(), c.arg(2).c_str(), 1);
        // Later lines see the environment's value (iocshEnvClear), not an iocshLoad macro.
        for (Scope* s : scopes) s->macros.erase(c.arg(1));
    }

    void cmd_env_unset(const Call& c) {
        need(c, 1);
        ::unsetenv(c.arg(1).c_str());
        for (Scope* s : scopes) s->macros.erase(c.arg(1));
    }

    void cmd_env_show(const Call& c) {
        for (char** e = environ; e && *e; ++e) {
            std::string_view kv(*e);
            std::size_t eq = kv.find('=');
            if (eq == std::string_view::npos) continue;
            if (c.arg(1).empty() || beamctl::glob_match(c.arg(1), kv.substr(0, eq))) c.out << kv << "\n";
        }
    }

    void cmd_load_records(const Call& c) {
        need(c, 1);
        load_records(c.arg(1), c.arg(2), "dbLoadRecords: macros");
    }

    // A library of sub/aSub routines (include/beamctl/record_routines.h), as EPICS's dlload.
    void cmd_dlload(const Call& c) {
        need(c, 1);
        RecordRoutines::global().load(c.arg(1));
    }

    void cmd_load_template(const Call& c) {
        need(c, 1);
        load_template(c.arg(1), c.arg(2), "dbLoadTemplate: macros");
    }

    void cmd_ignored(const Call& c) {
        const std::string& n = c.argv[0];
        const char* why =
            n == "dbLoadDatabase" || n.ends_with("_registerRecordDeviceDriver")
                ? "beamctl has its record types and device support built in; no .dbd is needed"
                : "beamctl logs to stderr (BEAMCTL_LOG sets its levels)";
        *err << c.where << ": note: " << n << " ignored: " << why << "\n";
        err->flush();
    }

    void cmd_ioc_init(const Call&) { ioc_init(); }

    void cmd_dbpf(const Call& c) {
        need(c, 1);
        if (!c.has(2)) throw Error("dbpf: missing the value (usage: dbpf PV VALUE)");
        if (!initialised) throw Error("dbpf only works after iocInit");
        put_field_text(db, c.arg(1), c.arg(2), c.out);
    }

    void cmd_dbgf(const Call& c) {
        need(c, 1);
        if (!initialised) throw Error("dbgf only works after iocInit");
        if (!print_field(db, c.arg(1), c.out))
            throw Error(SB() << "dbgf: PV '" << c.arg(1) << "' not found");
    }

    void cmd_dbl(const Call& c) {
        std::string type = c.arg(1);
        if (type == "*") type.clear();
        if (!type.empty() && !RecordTypes::global().find(type)) {
            c.out << "No record type\n";
            return;
        }
        print_record_list(db, type, "", c.arg(2), c.out);
    }

    void cmd_as_set_filename(const Call& c) {
        need(c, 1);
        set_access_security(c.arg(1), acf_subs);
    }

    void cmd_as_set_substitutions(const Call& c) {
        parse_macros(c.arg(1), "asSetSubstitutions");
        if (initialised) throw Error("asSetSubstitutions must come before iocInit");
        acf_subs = c.arg(1);
    }

    void cmd_cd(const Call& c) {
        need(c, 1);
        if (::chdir(c.arg(1).c_str()) != 0)
            throw Error(SB() << "cd: cannot change to \"" << c.arg(1)
                             << "\": " << std::strerror(errno));
        std::error_code ec;
        fs::path now = fs::current_path(ec);
        if (!ec) ::setenv("PWD", now.c_str(), 1);
    }

    void cmd_pwd(const Call& c) {
        std::error_code ec;
        c.out << fs::current_path(ec).string() << "\n";
    }

    void cmd_echo(const Call& c) { c.out << translate_escapes(c.arg(1)) << "\n"; }

    void cmd_iocsh_load(const Call& c) {
        need(c, 1);
        MacroMap m = parse_macros(c.arg(2), "iocshLoad: macros");
        run_text(read_text_file(c.arg(1)), c.arg(1), m); // errors: "loaded by" this line
    }

    void cmd_on(const Call& c) {
        if (c.arg(1) != "error" || !c.has(2)) throw Error("usage: on error continue|break");
        if (c.arg(2) == "continue")
            c.scope.continue_on_error = true;
        else if (c.arg(2) == "break")
            c.scope.continue_on_error = false;
        else
            throw Error(SB() << "on error " << c.arg(2) << ": not supported (continue or break)");
    }

    void cmd_sleep(const Call& c) {
        need(c, 1);
        double s = 0;
        if (!parse_double(c.arg(1), s) || !(s >= 0) || s > 3600)
            throw Error(SB() << "epicsThreadSleep: '" << c.arg(1)
                             << "' should be a number of seconds from 0 to 3600");
        c.out.flush();
        std::this_thread::sleep_for(std::chrono::duration<double>(s));
    }

    // --- the operations ---

    // A template file of a substitution file: as written (from the current directory), else in
    // the include path.
    std::string find_template(const std::string& name) const {
        std::error_code ec;
        if (fs::path(name).is_absolute() || fs::exists(name, ec)) return name;
        for (const auto& dir : opt.include_path) {
            fs::path p = fs::path(dir) / name;
            if (fs::exists(p, ec)) return p.string();
        }
        return name;
    }

    void refuse_after_init(const char* what) const {
        if (initialised) throw Error(SB() << what << ": records cannot be loaded after iocInit");
    }

    void load_records(const std::string& path, const std::string& macros,
                      const std::string& origin) {
        refuse_after_init("dbLoadRecords");
        MacroMap m = parse_macros(macros, origin);
        try {
            DbFile f = load_db_file(path, m, opt.include_path);
            db.load(f);
            records += f.records.size();
        } catch (const Error& e) {
            throw Located(messages_of(e));
        }
    }

    void load_template(const std::string& path, const std::string& macros,
                       const std::string& origin) {
        refuse_after_init("dbLoadTemplate");
        MacroMap m = parse_macros(macros, origin);
        std::vector<TemplateInstance> instances;
        try {
            instances = load_substitutions_file(path, m);
        } catch (const Error& e) {
            throw Located(messages_of(e));
        }
        ErrorList errors;
        for (const auto& inst : instances) {
            try {
                DbFile f = load_db_file(find_template(inst.file), inst.macros, opt.include_path);
                db.load(f);
                records += f.records.size();
            } catch (const Error& e) {
                for (auto& msg : messages_of(e, SB() << "\n  instance at " << inst.loc.str()))
                    errors.add(msg);
            }
        }
        if (!errors.empty()) throw Located(errors.messages());
    }

    void load_exit_records(const std::string& prefix, const std::string& version) {
        refuse_after_init("-x");
        static const char* kText = R"DB(
record(bo, "$(IOC):exit") {
    field(DESC, "Put any value to exit the IOC")
    field(ZNAM, "Run")
    field(ONAM, "Exit")
}
record(stringin, "$(IOC):BaseVersion") {
    field(DESC, "Version of the IOC program")
    field(VAL, "$(VERSION)")
    field(PINI, "YES")
}
)DB";
        MacroMap m{{"IOC", prefix}, {"VERSION", version}};
        try {
            DbFile f = parse_db(kText, "softIocExit.db", m);
            db.load(f);
            records += f.records.size();
        } catch (const Error& e) {
            throw Error(SB() << "-x " << prefix << ": " << e.what());
        }
        Record* r = db.find(prefix + ":exit");
        if (!r) return;
        r->put_hook = [exit = hooks.exit](Record&, const FieldDesc& f) {
            if (exit && (std::strcmp(f.name, "VAL") == 0 || std::strcmp(f.name, "PROC") == 0))
                exit(0);
            return PutStatus::Ok;
        };
    }

    void set_access_security(const std::string& path, const std::string& subs) {
        if (initialised) throw Error("asSetFilename must come before iocInit");
        parse_macros(subs, "asSetSubstitutions");
        std::error_code ec;
        acf_given = path;
        acf_dir = fs::current_path(ec).string();
        acf_subs = subs;
    }

    void ioc_init() {
        if (initialised) throw Error("iocInit: the IOC is already initialised (iocInit runs once)");
        try {
            db.init_records();
        } catch (const MultiError& e) {
            throw Located(e.errors());
        }
        initialised = true;
        if (hooks.init) hooks.init();
    }
};

IocShell::IocShell(Database& db, IocShellOptions options, IocShellHooks hooks)
    : impl_(std::make_unique<Impl>(db, std::move(options), std::move(hooks))) {}

IocShell::~IocShell() = default;

void IocShell::run_file(const std::string& path, const std::string& macros) {
    MacroMap m = parse_macros(macros, "macros");
    const std::string text = read_text_file(path);
    ::setenv("IOCSH_STARTUP_SCRIPT", path.c_str(), 1);
    impl_->run_text(text, path, m);
    impl_->out->flush();
}

void IocShell::run_text(std::string_view text, const std::string& name, const std::string& macros) {
    impl_->run_text(text, name, parse_macros(macros, "macros"));
    impl_->out->flush();
}

void IocShell::load_records(const std::string& path, const std::string& macros,
                            const std::string& origin) {
    impl_->load_records(path, macros, origin);
}

void IocShell::load_template(const std::string& path, const std::string& macros,
                             const std::string& origin) {
    impl_->load_template(path, macros, origin);
}

void IocShell::load_exit_records(const std::string& prefix, const std::string& version) {
    impl_->load_exit_records(prefix, version);
}

void IocShell::set_access_security(const std::string& path, const std::string& substitutions) {
    impl_->set_access_security(path, substitutions);
}

void IocShell::ioc_init() {
    impl_->ioc_init();
}

void IocShell::add_command(std::string name, std::string usage, CommandFn fn) {
    impl_->added[std::move(name)] = {std::move(usage), std::move(fn)};
}

bool IocShell::initialised() const {
    return impl_->initialised;
}
std::size_t IocShell::records_loaded() const {
    return impl_->records;
}
const std::string& IocShell::acf_file() const {
    // As given while the current directory is the one it was given in, else absolute (after cd).
    Impl& i = *impl_;
    std::error_code ec;
    const fs::path now = fs::current_path(ec);
    if (i.acf_given.empty() || fs::path(i.acf_given).is_absolute() ||
        (!ec && now == fs::path(i.acf_dir)))
        i.acf_file = i.acf_given;
    else
        i.acf_file = (fs::path(i.acf_dir) / i.acf_given).lexically_normal().string();
    return i.acf_file;
}
const std::string& IocShell::acf_substitutions() const {
    return impl_->acf_subs;
}

} // namespace beamctl::pv
