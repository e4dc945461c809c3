#include "plc/lexer.hpp"

#include <cctype>
#include <cstdlib>
#include <map>
#include <set>

namespace beamctl::plc::detail {

const char* to_string(Tok t) {
    switch (t) {
    case Tok::end:
        return "end of code";
    case Tok::number:
        return "number";
    case Tok::symbol:
        return "name";
    case Tok::string:
        return "string";
    case Tok::assign:
        return "':='";
    case Tok::add_assign:
        return "'+='";
    case Tok::sub_assign:
        return "'-='";
    case Tok::mul_assign:
        return "'*='";
    case Tok::div_assign:
        return "'/='";
    case Tok::mod_assign:
        return "'%='";
    case Tok::swap:
        return "'<=>'";
    case Tok::lt:
        return "'<'";
    case Tok::le:
        return "'<='";
    case Tok::gt:
        return "'>'";
    case Tok::ge:
        return "'>='";
    case Tok::eq:
        return "'=='";
    case Tok::ne:
        return "'!='";
    case Tok::add:
        return "'+'";
    case Tok::sub:
        return "'-'";
    case Tok::mul:
        return "'*'";
    case Tok::div:
        return "'/'";
    case Tok::mod:
        return "'%'";
    case Tok::pow:
        return "'^'";
    case Tok::comma:
        return "','";
    case Tok::semicolon:
        return "';'";
    case Tok::lparen:
        return "'('";
    case Tok::rparen:
        return "')'";
    case Tok::lbracket:
        return "'['";
    case Tok::rbracket:
        return "']'";
    case Tok::lbrace:
        return "'{'";
    case Tok::rbrace:
        return "'}'";
    case Tok::question:
        return "'?'";
    case Tok::colon:
        return "':'";
    case Tok::bang:
        return "'!'";
    }
    return "?";
}

std::string lower(std::string_view s) {
    std::string out(s);
    for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return out;
}

namespace {

bool is_letter(char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
}
bool is_digit(char c) {
    return c >= '0' && c <= '9';
}
bool is_name_char(char c) {
    return is_letter(c) || is_digit(c) || c == '_';
}

class Lexer {
public:
    Lexer(const Source& src, Diagnostics& diags)
        : src_(src)
        , diags_(diags) {}

    void line(int index, std::vector<Token>& out) {
        const std::string& s = src_.lines[index].text;
        std::size_t i = 0;
        while (i < s.size()) {
            const char c = s[i];
            if (std::isspace(static_cast<unsigned char>(c))) {
                ++i;
            } else if (is_letter(c)) {
                i = symbol(s, i, index, out);
            } else if (is_digit(c) || (c == '.' && i + 1 < s.size() && is_digit(s[i + 1]))) {
                i = number(s, i, index, out);
            } else if (c == '\'') {
                i = string(s, i, index, out);
            } else {
                i = op(s, i, index, out);
            }
        }
    }

private:
    void error(int line, std::size_t off, const std::string& msg) {
        diags_.add(src_.diagnostic(line, static_cast<int>(off), msg));
    }

    static Token make(Tok t, std::string text, int line, std::size_t off) {
        Token k;
        k.type = t;
        k.text = std::move(text);
        k.line = line;
        k.offset = static_cast<int>(off);
        return k;
    }

    // ExprTk symbols: a letter, then letters, digits, '_' and '.' when a letter, digit or '_'
    // follows the dot (ax1.enc.actpos, ec0.s3.binaryInput01.0).
    std::size_t symbol(const std::string& s, std::size_t i, int line, std::vector<Token>& out) {
        const std::size_t start = i;
        while (i < s.size()) {
            if (is_name_char(s[i])) {
                ++i;
            } else if (s[i] == '.' && i + 1 < s.size() && is_name_char(s[i + 1])) {
                ++i;
            } else {
                break;
            }
        }
        out.push_back(make(Tok::symbol, s.substr(start, i - start), line, start));
        return i;
    }

    std::size_t number(const std::string& s, std::size_t i, int line, std::vector<Token>& out) {
        const std::size_t start = i;
        bool dot = false, exp = false, exp_sign = false, exp_digit = false;
        while (i < s.size()) {
            const char c = s[i];
            if (c == '.') {
                if (dot || exp) {
                    error(line, start,
                          SB() << "malformed number '" << s.substr(start, i - start + 1) << "'");
                    return skip_number(s, i);
                }
                dot = true;
            } else if (c == 'e' || c == 'E') {
                if (exp) break;
                const char n = i + 1 < s.size() ? s[i + 1] : '\0';
                if (n != '+' && n != '-' && !is_digit(n)) {
                    error(line, start,
                          SB() << "malformed number '" << s.substr(start, i - start + 1)
                               << "': exponent without digits");
                    return skip_number(s, i);
                }
                exp = true;
            } else if (exp && (c == '+' || c == '-') && !exp_digit) {
                if (exp_sign) break;
                exp_sign = true;
            } else if (is_digit(c)) {
                if (exp) exp_digit = true;
            } else {
                break;
            }
            ++i;
        }
        const std::string text = s.substr(start, i - start);
        if (exp && !exp_digit) {
            error(line, start,
                  SB() << "malformed number '" << text << "': exponent without digits");
            return i;
        }
        Token t = make(Tok::number, text, line, start);
        t.value = std::strtod(text.c_str(), nullptr);
        out.push_back(std::move(t));
        return i;
    }

    static std::size_t skip_number(const std::string& s, std::size_t i) {
        while (i < s.size() && (is_name_char(s[i]) || s[i] == '.')) ++i;
        return i;
    }

    // '...' with ExprTk's escapes: \n \r \t, \0xHH, \\ and \' (any other \c gives c).
    std::size_t string(const std::string& s, std::size_t i, int line, std::vector<Token>& out) {
        const std::size_t start = i++;
        std::string value;
        while (i < s.size() && s[i] != '\'') {
            if (s[i] == '\\' && i + 1 < s.size()) {
                const char e = s[i + 1];
                i += 2;
                switch (e) {
                case 'n':
                    value += '\n';
                    break;
                case 'r':
                    value += '\r';
                    break;
                case 't':
                    value += '\t';
                    break;
                case '0':
                    if (i + 2 < s.size() && (s[i] == 'x' || s[i] == 'X') &&
                        std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
                        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
                        value +=
                            static_cast<char>(std::strtol(s.substr(i + 1, 2).c_str(), nullptr, 16));
                        i += 3;
                    } else {
                        error(line, i - 2, "malformed escape in string: expected \\0xHH");
                    }
                    break;
                default:
                    value += e;
                    break;
                }
                continue;
            }
            value += s[i++];
        }
        if (i >= s.size()) {
            error(line, start, "string not terminated (a '#' ends the line, also inside a string)");
            return s.size();
        }
        out.push_back(make(Tok::string, value, line, start));
        return i + 1;
    }

    std::size_t op(const std::string& s, std::size_t i, int line, std::vector<Token>& out) {
        const char c0 = s[i];
        const char c1 = i + 1 < s.size() ? s[i + 1] : '\0';
        const char c2 = i + 2 < s.size() ? s[i + 2] : '\0';
        if (c0 == '<' && c1 == '=' && c2 == '>') {
            out.push_back(make(Tok::swap, "<=>", line, i));
            return i + 3;
        }
        struct Two {
            char a, b;
            Tok t;
        };
        static const Two two[] = {
            {'<', '=', Tok::le},         {'>', '=', Tok::ge},         {'<', '>', Tok::ne},
            {'!', '=', Tok::ne},         {'=', '=', Tok::eq},         {':', '=', Tok::assign},
            {'+', '=', Tok::add_assign}, {'-', '=', Tok::sub_assign}, {'*', '=', Tok::mul_assign},
            {'/', '=', Tok::div_assign}, {'%', '=', Tok::mod_assign},
        };
        for (const Two& t : two) {
            if (c0 == t.a && c1 == t.b) {
                out.push_back(make(t.t, std::string{c0, c1}, line, i));
                return i + 2;
            }
        }
        Tok t;
        switch (c0) {
        case '<':
            t = Tok::lt;
            break;
        case '>':
            t = Tok::gt;
            break;
        case '=':
            t = Tok::eq;
            break;
        case '+':
            t = Tok::add;
            break;
        case '-':
            t = Tok::sub;
            break;
        case '*':
            t = Tok::mul;
            break;
        case '/':
            t = Tok::div;
            break;
        case '%':
            t = Tok::mod;
            break;
        case '^':
            t = Tok::pow;
            break;
        case ',':
            t = Tok::comma;
            break;
        case ';':
            t = Tok::semicolon;
            break;
        case '(':
            t = Tok::lparen;
            break;
        case ')':
            t = Tok::rparen;
            break;
        case '[':
            t = Tok::lbracket;
            break;
        case ']':
            t = Tok::rbracket;
            break;
        case '{':
            t = Tok::lbrace;
            break;
        case '}':
            t = Tok::rbrace;
            break;
        case '?':
            t = Tok::question;
            break;
        case ':':
            t = Tok::colon;
            break;
        case '!':
            t = Tok::bang;
            break;
        case '&':
        case '|':
        case '~':
            t = Tok::symbol;
            break;
        default:
            if (c0 == '"')
                error(line, i, "unexpected '\"': strings are written in single quotes");
            else if (c0 == '$')
                error(line, i, "unexpected '$' (a macro reference that was not expanded?)");
            else if (c0 == '.')
                error(line, i, "unexpected '.'");
            else
                error(line, i, SB() << "unexpected character '" << c0 << "'");
            return i + 1;
        }
        out.push_back(make(t, std::string(1, c0), line, i));
        return i + 1;
    }

    const Source& src_;
    Diagnostics& diags_;
};

// ---- VAR ... END_VAR aliases (ECMC) ----------------------------------------------------------

struct Alias {
    std::vector<Token> value;
    Token decl;
};

bool plain_identifier(const std::string& s) {
    if (s.empty() || !(is_letter(s[0]) || s[0] == '_')) return false;
    for (char c : s)
        if (!is_name_char(c)) return false;
    return true;
}

// ECMC reads a VAR block line by line (ecmcPLCMain::parseVarBlock): an entry is `name : address;`
// on one line, and a line without its ';' is skipped, so that name is no alias (the manual's own
// example ends its block with such a line). The same here; a later use of a skipped name is an
// error that says so.
void apply_aliases(const Source& src, std::vector<Token>& toks, Diagnostics& diags) {
    std::map<std::string, Alias> aliases;
    std::map<std::string, Token> skipped; // entries without ';' on their line
    std::vector<Token> rest;
    rest.reserve(toks.size());
    for (std::size_t i = 0; i < toks.size(); ++i) {
        if (!(toks[i].type == Tok::symbol && toks[i].text == "VAR")) {
            rest.push_back(std::move(toks[i]));
            continue;
        }
        std::size_t end = i + 1;
        while (end < toks.size() && !(toks[end].type == Tok::symbol && toks[end].text == "END_VAR"))
            ++end;
        if (end >= toks.size()) { // no END_VAR: ExprTk's `var` keyword
            rest.push_back(std::move(toks[i]));
            continue;
        }
        std::size_t j = i + 1;
        while (j < end) {
            const Token& name = toks[j];
            if (name.type != Tok::symbol || !plain_identifier(name.text)) {
                diags.add(src.diagnostic(name.line, name.offset,
                                         SB() << "expected 'name : address;' in VAR block, found "
                                              << (name.type == Tok::symbol
                                                      ? "'" + name.text + "'"
                                                      : std::string(to_string(name.type)))));
                while (j < end && toks[j].type != Tok::semicolon) ++j;
                ++j;
                continue;
            }
            if (j + 1 >= end || toks[j + 1].type != Tok::colon) {
                const Token& at = j + 1 < end ? toks[j + 1] : toks[end];
                diags.add(src.diagnostic(at.line, at.offset,
                                         SB() << "expected ':' after '" << name.text
                                              << "' in VAR block"));
                while (j < end && toks[j].type != Tok::semicolon) ++j;
                ++j;
                continue;
            }
            std::size_t k = j + 2;
            Alias alias;
            alias.decl = name;
            while (k < end && toks[k].type != Tok::semicolon && toks[k].line == name.line)
                alias.value.push_back(toks[k++]);
            if (k >= end || toks[k].type != Tok::semicolon) { // no ';' on its line: ECMC skips it
                if (!aliases.count(name.text)) skipped.insert_or_assign(name.text, name);
                j = k; // the next line's entry
                continue;
            } else if (alias.value.empty()) {
                diags.add(src.diagnostic(toks[k].line, toks[k].offset,
                                         SB() << "VAR entry '" << name.text << "' has no address"));
            } else if (auto it = aliases.find(name.text); it != aliases.end()) {
                const SourceLoc prev = src.loc(it->second.decl.line, it->second.decl.offset);
                diags.add(src.diagnostic(name.line, name.offset,
                                         SB() << "'" << name.text << "' is declared twice in VAR "
                                              << "blocks (first at " << prev.str() << ")"));
            } else {
                skipped.erase(name.text);
                aliases.emplace(name.text, std::move(alias));
            }
            j = k + 1;
        }
        i = end; // skip the block and END_VAR
    }
    toks.clear();
    for (Token& t : rest) {
        if (t.type != Tok::symbol) {
            toks.push_back(std::move(t));
            continue;
        }
        const std::size_t dot = t.text.find('.');
        const std::string head = t.text.substr(0, dot);
        const auto it = aliases.find(head);
        if (it == aliases.end()) {
            const auto sk = skipped.find(head);
            if (sk != skipped.end() && !toks.empty() && toks.back().type == Tok::symbol && lower(toks.back().text) == "var") {
                skipped.erase(sk); // a local of that name from here on
            } else if (sk != skipped.end()) {
                const SourceLoc at = src.loc(sk->second.line, sk->second.offset);
                diags.add(src.diagnostic(t.line, t.offset,
                                         SB() << "'" << head << "' is no alias: its VAR entry (" << at.str()
                                              << ") has no ';' on its line, and ECMC skips such a line"));
            }
            toks.push_back(std::move(t));
            continue;
        }
        const std::vector<Token>& value = it->second.value;
        const std::string suffix = dot == std::string::npos ? "" : t.text.substr(dot);
        if (value.size() == 1 && value[0].type == Tok::symbol) {
            t.text = value[0].text + suffix;
            toks.push_back(std::move(t));
        } else if (!suffix.empty()) {
            diags.add(src.diagnostic(t.line, t.offset,
                                     SB() << "'" << head << "' is an alias of a constant and "
                                          << "cannot be followed by '" << suffix << "'"));
        } else {
            for (Token v : value) {
                v.line = t.line;
                v.offset = t.offset;
                toks.push_back(std::move(v));
            }
        }
    }
}

// ---- ExprTk's token passes -------------------------------------------------------------------

void replace_true_false(std::vector<Token>& toks) {
    for (Token& t : toks) {
        if (t.type != Tok::symbol) continue;
        const std::string l = lower(t.text);
        if (l == "true" || l == "false") {
            t.type = Tok::number;
            t.value = l == "true" ? 1.0 : 0.0;
        }
    }
}

// Joins adjacent operator tokens as ExprTk's operator_joiner does (`: =` is `:=`, `- -` is
// `+`, ...), whatever whitespace separates them.
void join_operators(std::vector<Token>& toks) {
    std::vector<Token> out;
    out.reserve(toks.size());
    for (std::size_t i = 0; i < toks.size(); ++i) {
        if (i + 1 < toks.size()) {
            const Tok a = toks[i].type, b = toks[i + 1].type;
            Tok j = Tok::end;
            if (b == Tok::eq) {
                switch (a) {
                case Tok::colon:
                    j = Tok::assign;
                    break;
                case Tok::add:
                    j = Tok::add_assign;
                    break;
                case Tok::sub:
                    j = Tok::sub_assign;
                    break;
                case Tok::mul:
                    j = Tok::mul_assign;
                    break;
                case Tok::div:
                    j = Tok::div_assign;
                    break;
                case Tok::mod:
                    j = Tok::mod_assign;
                    break;
                case Tok::gt:
                    j = Tok::ge;
                    break;
                case Tok::lt:
                    j = Tok::le;
                    break;
                case Tok::eq:
                    j = Tok::eq;
                    break;
                case Tok::bang:
                    j = Tok::ne;
                    break;
                default:
                    break;
                }
            } else if (a == Tok::lt && b == Tok::gt) {
                j = Tok::ne;
            } else if (a == Tok::le && b == Tok::gt) {
                j = Tok::swap;
            } else if ((a == Tok::add && b == Tok::sub) || (a == Tok::sub && b == Tok::add)) {
                j = Tok::sub;
            } else if (a == Tok::sub && b == Tok::sub) {
                j = Tok::add;
            }
            if (j != Tok::end) {
                Token t = toks[i];
                t.type = j;
                t.text = toks[i].text + toks[i + 1].text;
                out.push_back(std::move(t));
                ++i;
                continue;
            }
        }
        if (i + 2 < toks.size() && toks[i].type == Tok::lbracket && toks[i + 1].type == Tok::mul &&
            toks[i + 2].type == Tok::rbracket) {
            Token t = toks[i];
            t.type = Tok::symbol;
            t.text = "[*]";
            out.push_back(std::move(t));
            i += 2;
            continue;
        }
        out.push_back(std::move(toks[i]));
    }
    toks = std::move(out);
}

bool no_implicit_mul(const Token& t) {
    // ExprTk's reserved words, plus `function` (library definitions) and the `~`/`[*]` forms.
    static const std::set<std::string> words = {
        "assert", "break",  "case",   "continue", "const", "default", "false",  "for",  "if",
        "else",   "ilike",  "in",     "like",     "and",   "nand",    "nor",    "not",  "null",
        "or",     "repeat", "return", "shl",      "shr",   "swap",    "switch", "true", "until",
        "var",    "while",  "xnor",   "xor",      "&",     "|",       "~",      "[*]",  "function"};
    return t.type == Tok::symbol && words.count(lower(t.text)) != 0;
}

// ExprTk's commutative inserter: `2x`, `2(x)`, `x 2`, `(a)(b)`... get an implicit '*'.
void insert_implicit_mul(std::vector<Token>& toks) {
    std::vector<Token> out;
    out.reserve(toks.size());
    for (std::size_t i = 0; i < toks.size(); ++i) {
        if (!out.empty()) {
            const Token& t0 = out.back(); // toks[i - 1], already moved to `out`
            const Token& t1 = toks[i];
            bool mul = false;
            if (!no_implicit_mul(t0) && !no_implicit_mul(t1)) {
                const Tok a = t0.type, b = t1.type;
                const bool close = a == Tok::rparen || a == Tok::rbrace || a == Tok::rbracket;
                mul = (a == Tok::number && (b == Tok::symbol || b == Tok::lparen ||
                                            b == Tok::lbrace || b == Tok::lbracket)) ||
                      (a == Tok::symbol && b == Tok::number) ||
                      (close && (b == Tok::number || b == Tok::symbol)) ||
                      (a == Tok::symbol && b == Tok::symbol);
            }
            if (mul) {
                Token m;
                m.type = Tok::mul;
                m.text = "*";
                m.line = t1.line;
                m.offset = t1.offset;
                m.inserted = true;
                out.push_back(std::move(m));
            }
        }
        out.push_back(std::move(toks[i]));
    }
    toks = std::move(out);
}

} // namespace

std::vector<Token> lex(const Source& src, int first, int last, bool aliases, Diagnostics& diags) {
    Lexer lexer(src, diags);
    std::vector<Token> toks;
    for (int i = first; i < last; ++i) lexer.line(i, toks);
    if (aliases) apply_aliases(src, toks, diags);
    replace_true_false(toks);
    join_operators(toks);
    insert_implicit_mul(toks);
    Token end;
    end.type = Tok::end;
    end.text = "";
    if (last > first) {
        end.line = last - 1;
        end.offset = static_cast<int>(src.lines[last - 1].text.size());
    }
    toks.push_back(std::move(end));
    return toks;
}

} // namespace beamctl::plc::detail
