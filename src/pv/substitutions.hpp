// EPICS substitution files (x.substitutions, as read by dbLoadTemplate and msi): which template
// files to load, and with which macros. A pure function of the text (load_substitutions_file only
// reads the file); safe to call from any non-RT thread.
//
// Grammar (dbLoadTemplate's):
//   file     := { global | template }
//   global   := "global" "{" [ defs ] "}"
//   template := "file" NAME "{" [ pattern | { set } ] "}"
//   pattern  := "pattern" "{" { WORD [","] } "}" { "{" { VALUE [","] } "}" | global }
//   set      := "{" [ defs ] "}" | global
//   defs     := { WORD "=" VALUE [","] }
// NAME and VALUE are a WORD or a quoted string. A WORD is a run of [a-zA-Z0-9_-+:./\[]<>;] and
// macro references $(...) / ${...}; a string is "..." or '...' on one line, a backslash keeping
// the next character in it. '#' starts a comment to the end of the line. As in dbLoadTemplate, a
// word before an instance's "{" (`name { ... }`, deprecated) is allowed and ignored.
//
// Macros of one instance: those given to dbLoadTemplate, then every global definition seen so
// far in the file (globals last to the end of the file, also those inside a file block), then
// the instance's own values; a later definition of a name wins. A pattern row gives its values to
// the pattern's names in order; fewer values leave the last names undefined, more are an error.
// Values are kept as written (macro references in them are expanded when the template is,
// `"$(P)x"` works); a quoted value is a macro definition NAME="VALUE" (core/macros.hpp).
// Template file names have macro references expanded with the macros known at that point
// (dbLoadTemplate's and the globals so far).
//
// Errors are "file:line:col: what was expected, found what"; parsing stops at the first.
#pragma once

#include "core/error.hpp"
#include "core/macros.hpp"
#include "pv/db_file.hpp"

#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv {

// One dbLoadRecords(file, macros) that a substitution file asks for.
struct TemplateInstance {
    std::string file;   // template (.db / .template) file name as written, macros expanded
    SourceLoc file_loc; // of the file name after `file`
    SourceLoc loc;      // of the instance's "{"
    MacroMap macros;    // dbLoadTemplate's, the globals so far, then the instance's own
};

// Parses substitution-file text; `filename` names it in messages. `macros` are dbLoadTemplate's
// second argument (the command's macros), overridden by the file's definitions.
std::vector<TemplateInstance> parse_substitutions(std::string_view text,
                                                  const std::string& filename,
                                                  const MacroMap& macros = {});

// Reads and parses the substitution file at `path`.
std::vector<TemplateInstance> load_substitutions_file(const std::string& path,
                                                      const MacroMap& macros = {});

// True for a substitution file's name (.substitutions, .substitution, .subs, .substs).
bool is_substitutions_file(std::string_view path);

// The records of `path` as dbLoadRecords or dbLoadTemplate reads them, by its extension: a .db /
// .template file parsed with `macros`, or each template of a substitution file with its
// instance's macros (a relative template name is found beside the substitution file, then in
// `include_path`, then from the working directory). Every error of every instance is thrown
// (MultiError), each with the instance it came from.
std::vector<DbFile> load_records_file(const std::string& path, const MacroMap& macros,
                                      const std::vector<std::string>& include_path = {});

} // namespace beamctl::pv
