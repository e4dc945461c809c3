// EPICS-style macro definitions ("P=DEMO:,R=m1") and macro expansion ("$(P)$(R=m1)"), as in
// EPICS macLib. Pure functions without global state; safe to call from any non-RT thread.
//
// Reference syntax: $(NAME) or ${NAME}; $(NAME=default) uses `default` when NAME is undefined;
// $(NAME,A=1,B=2) expands NAME with A and B defined (scoped) while it is expanded. Names,
// defaults and scoped values may themselves contain references: $(A$(B)), $(X=$(Y)).
// Inside a reference (as in macLib) a backslash makes the next character literal and quotes
// ' or " group characters (so `$(D="a,b")` works) and are removed; single quotes also stop
// expansion. A reference ends at the first unquoted ')' or '}' matching its opener (plain
// parentheses are not counted) and may not span lines.
//
// Escapes outside references depend on the text (MacroEscapes):
//   keep      macLib for file text: a backslash and the character after it are copied
//             unchanged, and that character never starts a reference: `\$(P)` -> `\$(P)`.
//             For text whose own grammar translates escapes afterwards (.db strings).
//   unescape  `\$` -> `$` and `\\` -> `\`; any other backslash is copied as is. For text with no
//             escape grammar of its own (YAML values, PLC code).
// MacroMap values are expanded with `unescape` rules: they may reference other macros, `\$`
// gives a literal '$' and `\\` a backslash; quotes in values are ordinary characters.
// Deviation from macLib: quotes outside references do not stop expansion in any mode.
//
// An undefined macro without default, a recursive macro (A=$(A), or A=$(B),B=$(A)), an empty
// name and an unterminated reference are errors; the message starts with "file:line:col: " of
// the '$' in the original text, also when the fault is deep inside macro values.
#pragma once

#include "core/error.hpp"

#include <cstddef>
#include <map>
#include <string>
#include <string_view>

namespace beamctl {

// Macro name -> value (value in the form described above: `\$`, `\\` and references special).
using MacroMap = std::map<std::string, std::string>;

enum class MacroEscapes { keep, unescape };

// Parses EPICS macro definitions `NAME=VALUE,NAME2="a, b",E=` (macParseDefns). Whitespace around
// names and values is dropped unless quoted; values may be quoted (partly or wholly) with ' or ",
// the quotes are removed; `\c` makes c literal. A later definition of a name replaces an earlier
// one; empty entries (",,") are skipped. Errors (no '=', empty name, quote in a name, unterminated
// quote, trailing backslash) name the position, counted from `start` (default <input>:1:1).
MacroMap parse_macro_defs(std::string_view defs, const SourceLoc& start = {});

// Expands every reference in `text`. Error locations are counted from `start` (line and column
// of text[0], default <input>:1:1); newlines in `text` advance the line.
std::string expand_macros(std::string_view text, const MacroMap& macros,
                          MacroEscapes escapes = MacroEscapes::keep);
std::string expand_macros(std::string_view text, const MacroMap& macros, const SourceLoc& start,
                          MacroEscapes escapes = MacroEscapes::keep);

// True when text[pos] starts a reference: '$' followed by '(' or '{'.
bool is_macro_ref(std::string_view text, std::size_t pos);

// Building block for lexers: expands the one reference that starts at text[pos] (see
// is_macro_ref). `loc` is the location of text[pos]; on return `pos` and `loc` point just past
// the reference's closing bracket.
std::string expand_macro_ref(std::string_view text, std::size_t& pos, SourceLoc& loc,
                             const MacroMap& macros);

// Advances `loc` over one character of original text (newline: next line, column 1; UTF-8
// continuation bytes do not count, so columns count characters).
void advance_loc(SourceLoc& loc, char c);

} // namespace beamctl
