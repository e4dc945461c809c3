// EPICS database files (.db, as read by dbLoadRecords): parsed into plain structs, with macros
// expanded and every item located in its original file. Pure functions (they only read files);
// safe to call from any non-RT thread.
//
// Grammar:
//   file   := { record | alias | include }
//   record := ("record" | "grecord") "(" TYPE "," NAME ")" [ "{" { item } "}" ]
//   item   := "field" "(" NAME "," VALUE ")" | "info" "(" NAME "," VALUE ")"
//           | "alias" "(" NAME ")" | include
//   alias  := "alias" "(" RECORD "," ALIAS ")"
//   include:= "include" STRING
// A STRING is a bare word of [a-zA-Z0-9_-+:.[]<>;] and macro references, or a "quoted string".
// A field or info VALUE may also be JSON ({...} or [...], EPICS 7 links and info tags): it is
// kept as written, with macros expanded and '#' comments removed, for the consumer to parse.
// '#' starts a comment to the end of the line (outside strings).
//
// Quoted strings: no newline inside; escapes \n \t \r \a \b \f \v \\ \" \' \? \$, \ooo (octal,
// 1-3 digits) and \xhh (hex, 1-2 digits); any other \c gives c (EPICS dbTranslateEscape). Macro
// references (core/macros.hpp) are expanded in quoted strings, bare words and JSON values, not in
// comments; `\$(P)` in a quoted string is a literal "$(P)". Macro values are inserted literally
// (their characters are not escape-translated again).
//
// Record names and aliases may not contain space, tab, control characters, " ' . or $.
// Redefinitions (as EPICS): a record defined again with the same type, or with type "*", merges
// into the first definition: a field or info given again takes the later value and location but
// keeps its place; new ones are appended. A different type is an error. record("*", NAME) must
// name an existing record; if NAME is not defined earlier in the same parse it is kept as its own
// record of type "*", and whoever installs the records must merge it into the existing record
// or report "<loc>: record 'NAME' not found". An alias equal to another alias or a record name
// from the same parse is an error. Includes are resolved against the including file's directory,
// then `include_path` in order; include cycles are errors.
//
// Errors are "file:line:col: what was expected, found what"; an error inside an included file
// continues with lines "\n  included from file:line:col". After an error the parser goes on at
// the next line that starts with `record`/`grecord`, so one MultiError (core/error_list.hpp)
// reports every error of the file and its includes, in the order found (at most 100; then
// "<file>: too many errors (100); the rest is not read").
#pragma once

#include "core/error.hpp"
#include "core/macros.hpp"

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::pv {

struct DbField {
    std::string name;
    std::string value;
    SourceLoc loc; // of the field name
};

struct DbInfo {
    std::string name;
    std::string value;
    SourceLoc loc; // of the info name
};

struct DbRecord {
    std::string type; // record type, or "*" (modify an existing record)
    std::string name;
    SourceLoc loc;               // of the 'record' keyword of the first definition
    std::vector<DbField> fields; // in order of first appearance
    std::vector<DbInfo> infos;   // in order of first appearance
    std::vector<std::string> aliases;
};

struct DbAlias {
    std::string record;
    std::string alias;
    SourceLoc loc; // of the 'alias' keyword
};

struct DbFile {
    std::vector<DbRecord> records; // in order of first definition
    std::vector<DbAlias> aliases;  // top-level alias("record", "alias"), in order
};

// Parses .db text; `filename` is used for locations and as the base of relative includes.
DbFile parse_db(std::string_view text, const std::string& filename, const MacroMap& macros,
                const std::vector<std::string>& include_path = {});

// Reads and parses the .db file at `path`.
DbFile load_db_file(const std::string& path, const MacroMap& macros,
                    const std::vector<std::string>& include_path = {});

// Appends `more` (e.g. the next file loaded) to `into` with the redefinition rules above.
void merge_db(DbFile& into, const DbFile& more);

// A record definition made by code (an IOC's generated PVs), located at "<generated>".
inline DbRecord generated_record(const std::string& type, const std::string& name,
                                 const std::vector<std::pair<std::string, std::string>>& fields) {
    DbRecord r;
    r.type = type;
    r.name = name;
    r.loc = SourceLoc{"<generated>", 1, 1};
    for (const auto& [k, v] : fields) r.fields.push_back(DbField{k, v, r.loc});
    return r;
}

} // namespace beamctl::pv
