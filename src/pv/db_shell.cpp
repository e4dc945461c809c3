#include "pv/db_shell.hpp"

#include "core/error.hpp"
#include "pv/convert.hpp"
#include "pv/database.hpp"
#include "pv/iocsh.hpp"

#include <cctype>
#include <cstring>
#include <ostream>
#include <vector>

namespace beamctl::pv {

namespace {

// Words as iocsh splits them: blanks and ( ) , separate, "..." and '...' group.
bool split(std::string_view line, std::vector<std::string>& argv, std::string& why) {
    std::string word;
    bool in = false;
    char quote = 0;
    for (char c : line) {
        if (quote) {
            if (c == quote)
                quote = 0;
            else
                word += c;
            continue;
        }
        if (c == '"' || c == '\'') {
            quote = c;
            in = true;
        } else if (std::strchr(" \t(),\r\n", c)) {
            if (in) argv.push_back(word);
            word.clear();
            in = false;
        } else {
            word += c;
            in = true;
        }
    }
    if (quote) {
        why = "Unbalanced quote.";
        return false;
    }
    if (in) argv.push_back(word);
    return true;
}

int level_arg(const std::vector<std::string>& argv, std::size_t i, const char* cmd) {
    if (i >= argv.size()) return 0;
    int64_t v = 0;
    if (!parse_int(argv[i], v) || v < 0 || v > 10)
        throw Error(SB() << cmd << ": level '" << argv[i] << "' should be a number from 0 to 10");
    return int(v);
}

const char* kHelp =
    "Commands (as EPICS iocsh):\n"
    "  dbl [RECORDTYPE|PATTERN] [\"FIELD ...\"]  list records (of a type, or names matching a glob)\n"
    "  dbpr NAME [LEVEL]                      print a record's fields (level 0: the main ones)\n"
    "  dbgf NAME[.FIELD]                      print a field\n"
    "  dbpf NAME[.FIELD] VALUE                put a value as a CA client would, print the field\n"
    "  dbtr NAME                              process a record, then print it as dbpr\n"
    "  scanppl [PERIOD]                       records of the periodic scan lists\n"
    "  casr [LEVEL]                           Channel Access server clients (1: channels too)\n"
    "  signals [PATTERN]                      the IOC's signals now (as `beamctl signals`, with RCP objects)\n"
    "  help                                   this text\n";

} // namespace

DbShell::DbShell(Database& db, DbShellHooks hooks)
    : db_(db), hooks_(std::move(hooks)) {}

bool DbShell::execute(std::string_view line, std::ostream& os) {
    std::vector<std::string> argv;
    std::string why;
    std::size_t i = 0;
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i == line.size() || line[i] == '#') return true;
    if (!split(line, argv, why)) {
        os << "error: " << why << "\n";
        return false;
    }
    if (argv.empty()) return true;
    auto arg = [&](std::size_t k) -> const std::string& {
        static const std::string none;
        return k < argv.size() ? argv[k] : none;
    };
    const std::string& cmd = argv[0];
    try {
        if (cmd == "help" || cmd == "?") {
            os << kHelp;
            for (const auto& [name, c] : hooks_.commands) os << "  " << c.usage << "\n";
        } else if (cmd == "dbl") {
            std::string first = arg(1) == "*" ? "" : arg(1);
            if (!first.empty() && RecordTypes::global().find(first))
                print_record_list(db_, first, "", arg(2), os);
            else
                print_record_list(db_, "", first, arg(2), os);
        } else if (cmd == "dbpr") {
            if (arg(1).empty()) throw Error("dbpr: missing the record name (usage: dbpr NAME [LEVEL])");
            return print_record(db_, arg(1), level_arg(argv, 2, "dbpr"), os);
        } else if (cmd == "dbgf") {
            if (arg(1).empty()) throw Error("dbgf: missing the PV name (usage: dbgf NAME.FIELD)");
            return print_field(db_, arg(1), os);
        } else if (cmd == "dbpf") {
            if (arg(1).empty() || argv.size() < 3)
                throw Error("dbpf: missing arguments (usage: dbpf NAME.FIELD VALUE)");
            put_field_text(db_, arg(1), arg(2), os);
        } else if (cmd == "dbtr") {
            if (arg(1).empty()) throw Error("dbtr: missing the record name (usage: dbtr NAME)");
            Record* r = db_.find(arg(1));
            if (!r) {
                os << "Record '" << arg(1) << "' not found\n";
                return false;
            }
            if (r->busy()) throw Error(SB() << "dbtr: " << arg(1) << " is active (PACT): not processed");
            db_.process(*r);
            print_record(db_, arg(1), 0, os);
        } else if (cmd == "scanppl") {
            print_scan_lists(db_, arg(1), os);
        } else if (cmd == "casr") {
            int level = level_arg(argv, 1, "casr");
            if (!hooks_.casr) throw Error("casr: this IOC has no Channel Access server");
            hooks_.casr(level, os);
        } else if (cmd == "signals") {
            if (!hooks_.signals) throw Error("signals: this IOC has no signal registry (a soft IOC)");
            if (!hooks_.signals(arg(1), os)) {
                os << "no signal matches '" << arg(1) << "'\n";
                return false;
            }
        } else if (auto c = hooks_.commands.find(cmd); c != hooks_.commands.end()) {
            return c->second.run(argv, os);
        } else {
            throw Error(SB() << "unknown command '" << cmd << "' (help lists the commands)");
        }
    } catch (const Error& e) {
        os << "error: " << e.what() << "\n";
        return false;
    }
    return true;
}

} // namespace beamctl::pv
