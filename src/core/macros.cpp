#include "core/macros.hpp"

#include <algorithm>
#include <cctype>
#include <optional>
#include <utility>
#include <vector>

namespace beamctl {

namespace {

SourceLoc normalized(SourceLoc loc) {
    if (loc.line <= 0) loc.line = 1;
    if (loc.col <= 0) loc.col = 1;
    return loc;
}

[[noreturn]] void fail(const SourceLoc& loc, const std::string& msg) {
    throw Error(SB() << loc.str() << ": " << msg);
}

bool is_space(char c) {
    return std::isspace(static_cast<unsigned char>(c)) != 0;
}

// Walks a text; `loc` is the location of text[pos]. Text that is not in a file (a macro value)
// has track == false and a fixed `loc`: the reference in the file that led to it.
struct Scanner {
    std::string_view text;
    std::size_t pos = 0;
    SourceLoc loc;
    bool track = true;

    bool at_end() const { return pos >= text.size(); }
    char peek(std::size_t k = 0) const { return pos + k < text.size() ? text[pos + k] : '\0'; }
    bool at_ref() const { return is_macro_ref(text, pos); }
    void advance() {
        if (track) advance_loc(loc, text[pos]);
        ++pos;
    }
};

// Makes `s` literal for value-mode expansion.
std::string escape_literal(std::string_view s) {
    std::string out;
    for (char c : s) {
        if (c == '\\' || c == '$') out += '\\';
        out += c;
    }
    return out;
}

std::string describe_stop(const Scanner& s) {
    if (s.at_end()) return s.track ? "end of text" : "end of value";
    if (s.peek() == '\n') return "end of line";
    return SB() << "'" << s.peek() << "'";
}

class Expander {
public:
    explicit Expander(const MacroMap& macros)
        : macros_(macros) {}

    // Expands all of `s` (top-level text or a macro value).
    void expand_text(Scanner& s, MacroEscapes mode, std::string& out) {
        while (!s.at_end()) {
            const char c = s.peek();
            if (c == '\\' && s.pos + 1 < s.text.size()) {
                const char n = s.peek(1);
                if (mode == MacroEscapes::keep) {
                    out += c;
                    out += n;
                    s.advance();
                    s.advance();
                    continue;
                }
                if (n == '$' || n == '\\') {
                    out += n;
                    s.advance();
                    s.advance();
                    continue;
                }
            } else if (s.at_ref()) {
                expand_ref(s, true, out);
                continue;
            }
            out += c;
            s.advance();
        }
    }

    // Parses the reference at s.pos ("$(" or "${"); appends its expansion when `evaluate`,
    // otherwise only skips it (unused defaults are not expanded, as in macLib).
    void expand_ref(Scanner& s, bool evaluate, std::string& out) {
        const SourceLoc ref_loc = s.loc;
        s.advance(); // '$'
        const char close = s.peek() == '(' ? ')' : '}';
        s.advance(); // '(' or '{'
        const std::string name_end = std::string("=,") + close;
        const std::string value_end = std::string(",") + close;

        std::string name;
        read_part(s, name_end, evaluate, name);

        std::optional<Scanner> default_start;
        if (!s.at_end() && s.peek() == '=') {
            s.advance();
            default_start = s;
            std::string skipped;
            read_part(s, value_end, false, skipped);
        }

        MacroMap scope;
        while (!s.at_end() && s.peek() == ',') {
            s.advance();
            std::string sub_name;
            read_part(s, name_end, evaluate, sub_name);
            if (!s.at_end() && s.peek() == '=') {
                s.advance();
                std::string sub_value;
                read_part(s, value_end, evaluate, sub_value);
                if (evaluate && !sub_name.empty()) scope[sub_name] = escape_literal(sub_value);
            }
        }

        if (s.at_end() || s.peek() != close) {
            fail(ref_loc, SB() << "unterminated macro reference '$" << (close == ')' ? '(' : '{')
                               << name << "': expected '" << close << "', found "
                               << describe_stop(s) << context());
        }
        s.advance(); // close
        if (!evaluate) return;

        if (name.empty()) fail(ref_loc, SB() << "empty macro name in reference" << context());

        const bool scoped = !scope.empty();
        if (scoped) scopes_.push_back(std::move(scope));
        struct PopScope {
            Expander& e;
            bool active;
            ~PopScope() {
                if (active) e.scopes_.pop_back();
            }
        } pop_scope{*this, scoped};

        if (const std::string* value = lookup(name)) {
            const auto it = std::find(stack_.begin(), stack_.end(), name);
            if (it != stack_.end()) {
                SB chain;
                for (auto p = it; p != stack_.end(); ++p) chain << *p << " -> ";
                chain << name;
                fail(ref_loc, SB() << "recursive macro '" << name << "' (" << chain.str() << ")");
            }
            stack_.push_back(name);
            Scanner vs{*value, 0, ref_loc, false};
            expand_text(vs, MacroEscapes::unescape, out);
            stack_.pop_back();
        } else if (default_start) {
            Scanner ds = *default_start;
            read_part(ds, value_end, true, out);
        } else {
            fail(ref_loc, SB() << "undefined macro '" << name << "'" << context());
        }
    }

private:
    // Reads a name, default or scoped value up to an unquoted character of `terms`, a newline or
    // the end (macLib rules: backslash escapes, quotes removed, no expansion in single quotes).
    void read_part(Scanner& s, std::string_view terms, bool evaluate, std::string& out) {
        char quote = 0;
        SourceLoc quote_loc;
        while (!s.at_end()) {
            const char c = s.peek();
            if (c == '\n') break;
            if (quote != 0) {
                if (c == quote) {
                    quote = 0;
                    s.advance();
                    continue;
                }
            } else if (c == '"' || c == '\'') {
                quote = c;
                quote_loc = s.loc;
                s.advance();
                continue;
            } else if (terms.find(c) != std::string_view::npos) {
                break;
            }
            if (c == '\\' && s.pos + 1 < s.text.size() && s.peek(1) != '\n') {
                s.advance();
                out += s.peek();
                s.advance();
            } else if (quote != '\'' && s.at_ref()) {
                expand_ref(s, evaluate, out);
            } else {
                out += c;
                s.advance();
            }
        }
        if (quote != 0) {
            fail(quote_loc,
                 SB() << "unterminated quote " << quote << " in macro reference" << context());
        }
    }

    const std::string* lookup(const std::string& name) const {
        for (auto it = scopes_.rbegin(); it != scopes_.rend(); ++it) {
            const auto found = it->find(name);
            if (found != it->end()) return &found->second;
        }
        const auto found = macros_.find(name);
        return found == macros_.end() ? nullptr : &found->second;
    }

    std::string context() const {
        if (stack_.empty()) return {};
        return SB() << " in the value of macro '" << stack_.back() << "'";
    }

    const MacroMap& macros_;
    std::vector<std::string> stack_; // macros being expanded, outermost first
    std::vector<MacroMap> scopes_;   // $(NAME,A=1) definitions, innermost last
};

} // namespace

void advance_loc(SourceLoc& loc, char c) {
    if (c == '\n') {
        ++loc.line;
        loc.col = 1;
    } else if ((static_cast<unsigned char>(c) & 0xC0) != 0x80) {
        ++loc.col;
    }
}

bool is_macro_ref(std::string_view text, std::size_t pos) {
    return pos + 1 < text.size() && text[pos] == '$' &&
           (text[pos + 1] == '(' || text[pos + 1] == '{');
}

std::string expand_macros(std::string_view text, const MacroMap& macros, MacroEscapes escapes) {
    return expand_macros(text, macros, SourceLoc{}, escapes);
}

std::string expand_macros(std::string_view text, const MacroMap& macros, const SourceLoc& start,
                          MacroEscapes escapes) {
    Expander e(macros);
    Scanner s{text, 0, normalized(start), true};
    std::string out;
    e.expand_text(s, escapes, out);
    return out;
}

std::string expand_macro_ref(std::string_view text, std::size_t& pos, SourceLoc& loc,
                             const MacroMap& macros) {
    if (!is_macro_ref(text, pos)) fail(loc, "expected a macro reference '$(' or '${'");
    Expander e(macros);
    Scanner s{text, pos, loc, true};
    std::string out;
    e.expand_ref(s, true, out);
    pos = s.pos;
    loc = s.loc;
    return out;
}

MacroMap parse_macro_defs(std::string_view defs, const SourceLoc& start) {
    const auto err = [](const SourceLoc& loc, const std::string& msg) {
        fail(loc, SB() << "in macro definitions: " << msg);
    };
    MacroMap out;
    Scanner s{defs, 0, normalized(start), true};
    while (true) {
        while (!s.at_end() && (is_space(s.peek()) || s.peek() == ',')) s.advance();
        if (s.at_end()) break;

        // Name: up to '=', trailing whitespace dropped.
        const SourceLoc name_loc = s.loc;
        std::string name;
        while (!s.at_end() && s.peek() != '=' && s.peek() != ',' && !is_space(s.peek())) {
            const char c = s.peek();
            if (c == '"' || c == '\'' || c == '\\' || c == '$' || c == '(' || c == ')' ||
                c == '{' || c == '}') {
                err(s.loc, SB() << "character '" << c << "' is not allowed in a macro name");
            }
            name += c;
            s.advance();
        }
        while (!s.at_end() && is_space(s.peek())) s.advance();
        if (name.empty()) err(name_loc, "empty macro name before '='");
        if (s.at_end() || s.peek() != '=') {
            err(s.loc, SB() << "expected '=' after macro name '" << name << "', found "
                            << (s.at_end() ? std::string("end of input")
                                           : std::string(SB() << "'" << s.peek() << "'")));
        }
        s.advance(); // '='

        // Value: up to an unquoted ',' outside references; quotes removed; whitespace trimmed
        // unless quoted or escaped. `keep` is the length that trailing-whitespace trimming keeps.
        while (!s.at_end() && is_space(s.peek())) s.advance();
        std::string value;
        std::size_t keep = 0;
        char quote = 0;
        SourceLoc quote_loc;
        std::vector<char> ref_close; // closers of the references we are inside
        char ref_quote = 0;          // quote open inside a reference
        while (!s.at_end()) {
            const char c = s.peek();
            if (!ref_close.empty()) {
                // Inside a reference: copy raw, expand_macros applies the reference rules.
                if (ref_quote != 0) {
                    if (c == ref_quote) ref_quote = 0;
                } else if (c == '"' || c == '\'') {
                    ref_quote = c;
                } else if (c == '\\' && s.pos + 1 < defs.size()) {
                    value += c;
                    s.advance();
                } else if (s.at_ref()) {
                    ref_close.push_back(s.peek(1) == '(' ? ')' : '}');
                    value += c;
                    s.advance();
                } else if (c == ref_close.back()) {
                    ref_close.pop_back();
                }
                value += s.peek();
                keep = value.size();
                s.advance();
                continue;
            }
            if (quote != 0 && c == quote) {
                quote = 0;
                s.advance();
                continue;
            }
            if (quote == 0 && (c == '"' || c == '\'')) {
                quote = c;
                quote_loc = s.loc;
                s.advance();
                continue;
            }
            if (quote == 0 && c == ',') break;
            if (c == '\\') {
                if (s.pos + 1 >= defs.size()) err(s.loc, "backslash at end of input");
                s.advance();
                const char n = s.peek();
                if (n == '\\' || n == '$') value += '\\';
                value += n;
                keep = value.size();
                s.advance();
                continue;
            }
            if (c == '$' && quote == '\'') {
                value += "\\$";
                keep = value.size();
                s.advance();
                continue;
            }
            if (s.at_ref()) {
                ref_close.push_back(s.peek(1) == '(' ? ')' : '}');
                value += c;
                keep = value.size();
                s.advance();
                continue; // the opener is copied by the reference branch above
            }
            value += c;
            if (quote != 0 || !is_space(c)) keep = value.size();
            s.advance();
        }
        if (quote != 0)
            err(quote_loc,
                SB() << "unterminated quote " << quote << " in value of '" << name << "'");
        value.resize(keep);
        out[name] = std::move(value);
    }
    return out;
}

} // namespace beamctl
