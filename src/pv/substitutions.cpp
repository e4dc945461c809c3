#include "pv/substitutions.hpp"

#include "core/error_list.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace beamctl::pv {

namespace {

[[noreturn]] void fail(const SourceLoc& loc, const std::string& msg) {
    throw Error(SB() << loc.str() << ": " << msg);
}

bool is_word_char(char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           std::strchr("_-+:./\\[]<>;", c) != nullptr;
}

std::string char_desc(char c) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u >= 0x7f) {
        static const char* hex = "0123456789abcdef";
        return SB() << "character 0x" << hex[u >> 4] << hex[u & 15];
    }
    return SB() << "'" << c << "'";
}

struct Token {
    enum Kind { End, Word, Quoted, LBrace, RBrace, Comma, Equals } kind = End;
    std::string text; // a word, or a string's contents without its quotes (escapes kept)
    char quote = 0;   // '"' or '\'' for Quoted
    SourceLoc loc;
};

std::string describe(const Token& t) {
    switch (t.kind) {
    case Token::End:
        return "end of file";
    case Token::Word:
        return SB() << "'" << t.text << "'";
    case Token::Quoted:
        return SB() << t.quote << t.text << t.quote;
    case Token::LBrace:
        return "'{'";
    case Token::RBrace:
        return "'}'";
    case Token::Comma:
        return "','";
    case Token::Equals:
        return "'='";
    }
    return "?";
}

class Lexer {
public:
    Lexer(std::string_view text, const std::string& file)
        : text_(text) {
        loc_.file = file;
        loc_.line = 1;
        loc_.col = 1;
    }

    Token next() {
        skip_space_and_comments();
        Token t;
        t.loc = loc_;
        if (pos_ >= text_.size()) return t;
        const char c = text_[pos_];
        switch (c) {
        case '{':
            advance();
            t.kind = Token::LBrace;
            return t;
        case '}':
            advance();
            t.kind = Token::RBrace;
            return t;
        case ',':
            advance();
            t.kind = Token::Comma;
            return t;
        case '=':
            advance();
            t.kind = Token::Equals;
            return t;
        case '"':
        case '\'':
            return quoted(t, c);
        default:
            break;
        }
        if (is_word_char(c) || is_macro_ref(text_, pos_)) return word(t);
        fail(loc_, SB() << "invalid " << char_desc(c));
    }

private:
    void advance() {
        advance_loc(loc_, text_[pos_]);
        ++pos_;
    }

    void skip_space_and_comments() {
        while (pos_ < text_.size()) {
            const char c = text_[pos_];
            if (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v') {
                advance();
            } else if (c == '#') {
                while (pos_ < text_.size() && text_[pos_] != '\n') advance();
            } else {
                break;
            }
        }
    }

    Token& quoted(Token& t, char q) {
        t.kind = Token::Quoted;
        t.quote = q;
        advance();
        while (true) {
            if (pos_ >= text_.size() || text_[pos_] == '\n')
                fail(t.loc, SB() << "string starting here has no closing " << q << " on its line");
            const char c = text_[pos_];
            if (c == q) {
                advance();
                return t;
            }
            if (c == '\\' && pos_ + 1 < text_.size() && text_[pos_ + 1] != '\n') {
                t.text += c;
                advance();
            }
            t.text += text_[pos_];
            advance();
        }
    }

    // A bare word: word characters and whole macro references (which may hold other characters).
    Token& word(Token& t) {
        t.kind = Token::Word;
        while (pos_ < text_.size()) {
            if (is_macro_ref(text_, pos_)) {
                const SourceLoc start = loc_;
                const char close = text_[pos_ + 1] == '(' ? ')' : '}';
                int depth = 0;
                while (true) {
                    if (pos_ >= text_.size() || text_[pos_] == '\n')
                        fail(start, SB() << "macro reference has no closing '" << close
                                         << "' on its line");
                    const char c = text_[pos_];
                    t.text += c;
                    advance();
                    if (c == '(' || c == '{') ++depth;
                    if ((c == ')' || c == '}') && --depth == 0) break;
                }
            } else if (is_word_char(text_[pos_])) {
                t.text += text_[pos_];
                advance();
            } else {
                break;
            }
        }
        return t;
    }

    std::string_view text_;
    std::size_t pos_ = 0;
    SourceLoc loc_;
};

// `\c` -> c (a quoted file name).
std::string unescape(std::string_view s) {
    std::string out;
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (s[i] == '\\' && i + 1 < s.size()) ++i;
        out += s[i];
    }
    return out;
}

class Parser {
public:
    Parser(std::string_view text, const std::string& file, const MacroMap& macros)
        : lex_(text, file)
        , macros_(macros) {
        tok_ = lex_.next();
    }

    std::vector<TemplateInstance> parse() {
        while (tok_.kind != Token::End) {
            if (is_word("global")) {
                global();
            } else if (is_word("file")) {
                template_block();
            } else {
                fail(tok_.loc, SB() << "expected 'file' or 'global', found " << describe(tok_));
            }
        }
        return std::move(out_);
    }

private:
    bool is_word(const char* w) const { return tok_.kind == Token::Word && tok_.text == w; }
    void next() { tok_ = lex_.next(); }
    Token expect(Token::Kind k, const std::string& what) {
        if (tok_.kind != k)
            fail(tok_.loc, SB() << "expected " << what << ", found " << describe(tok_));
        Token t = tok_;
        next();
        return t;
    }

    // NAME=VALUE as macro definition text, parsed as -m / dbLoadRecords macros are.
    void define(MacroMap& into, const Token& name, const Token& value) {
        std::string def = name.text + "=";
        if (value.kind == Token::Quoted)
            def += value.quote + value.text + value.quote;
        else
            def += value.text;
        for (auto& [k, v] : parse_macro_defs(def, value.loc)) into[k] = v;
    }

    // { WORD "=" VALUE [","] } up to and including "}".
    void definitions(MacroMap& into) {
        while (true) {
            if (tok_.kind == Token::RBrace) {
                next();
                return;
            }
            if (tok_.kind == Token::Comma) {
                next();
                continue;
            }
            if (tok_.kind != Token::Word)
                fail(tok_.loc, SB() << "expected a macro name or '}', found " << describe(tok_));
            const Token name = tok_;
            next();
            expect(Token::Equals, SB() << "'=' after " << name.text);
            if (tok_.kind != Token::Word && tok_.kind != Token::Quoted)
                fail(tok_.loc,
                     SB() << "expected the value of " << name.text << ", found " << describe(tok_));
            define(into, name, tok_);
            next();
        }
    }

    void global() {
        next(); // "global"
        expect(Token::LBrace, "'{' after 'global'");
        definitions(globals_);
    }

    MacroMap known() const {
        MacroMap m = macros_;
        for (const auto& [k, v] : globals_) m[k] = v;
        return m;
    }

    void emit(const std::string& file, const SourceLoc& file_loc, const SourceLoc& at,
              const MacroMap& locals) {
        TemplateInstance inst;
        inst.file = file;
        inst.file_loc = file_loc;
        inst.loc = at;
        inst.macros = known();
        for (const auto& [k, v] : locals) inst.macros[k] = v;
        out_.push_back(std::move(inst));
    }

    // An instance may be written `name { ... }` (deprecated syntax): the word is ignored.
    bool at_instance() {
        if (tok_.kind == Token::LBrace) return true;
        if (tok_.kind == Token::Word && !is_word("global")) {
            Token word = tok_;
            next();
            if (tok_.kind != Token::LBrace)
                fail(tok_.loc, SB() << "expected '{' after " << describe(word) << ", found "
                                    << describe(tok_));
            return true;
        }
        return false;
    }

    void template_block() {
        next(); // "file"
        if (tok_.kind != Token::Word && tok_.kind != Token::Quoted)
            fail(tok_.loc,
                 SB() << "expected a template file name after 'file', found " << describe(tok_));
        const SourceLoc file_loc = tok_.loc;
        std::string file = tok_.kind == Token::Quoted ? unescape(tok_.text) : tok_.text;
        file = expand_macros(file, known(), file_loc, MacroEscapes::unescape);
        if (file.empty()) fail(file_loc, "empty template file name");
        next();
        expect(Token::LBrace, "'{' after the template file name");
        if (is_word("pattern")) {
            pattern(file, file_loc);
        } else {
            while (tok_.kind != Token::RBrace) {
                if (is_word("global")) {
                    global();
                    continue;
                }
                if (!at_instance())
                    fail(tok_.loc,
                         SB() << "expected '{' (a set of NAME=VALUE), 'global' or '}', found "
                              << describe(tok_));
                const SourceLoc at = tok_.loc;
                next();
                MacroMap locals;
                definitions(locals);
                emit(file, file_loc, at, locals);
            }
        }
        expect(Token::RBrace, "'}' closing the file block");
    }

    void pattern(const std::string& file, const SourceLoc& file_loc) {
        next(); // "pattern"
        expect(Token::LBrace, "'{' after 'pattern'");
        std::vector<Token> names;
        while (tok_.kind != Token::RBrace) {
            if (tok_.kind == Token::Comma) {
                next();
                continue;
            }
            if (tok_.kind != Token::Word)
                fail(tok_.loc, SB() << "expected a macro name or '}', found " << describe(tok_));
            names.push_back(tok_);
            next();
        }
        next(); // "}"
        while (tok_.kind != Token::RBrace) {
            if (is_word("global")) {
                global();
                continue;
            }
            if (!at_instance())
                fail(tok_.loc, SB() << "expected '{' (a row of values), 'global' or '}', found "
                                    << describe(tok_));
            const SourceLoc at = tok_.loc;
            next();
            MacroMap locals;
            std::size_t n = 0;
            while (tok_.kind != Token::RBrace) {
                if (tok_.kind == Token::Comma) {
                    next();
                    continue;
                }
                if (tok_.kind != Token::Word && tok_.kind != Token::Quoted)
                    fail(tok_.loc, SB() << "expected a value or '}', found " << describe(tok_));
                if (n >= names.size())
                    fail(tok_.loc, SB() << "value " << (n + 1) << " (" << describe(tok_)
                                        << ") has no name: the pattern has " << names.size()
                                        << " name" << (names.size() == 1 ? "" : "s"));
                define(locals, names[n++], tok_);
                next();
            }
            next(); // "}"
            emit(file, file_loc, at, locals);
        }
    }

    Lexer lex_;
    Token tok_;
    const MacroMap& macros_;
    MacroMap globals_;
    std::vector<TemplateInstance> out_;
};

} // namespace

std::vector<TemplateInstance>
parse_substitutions(std::string_view text, const std::string& filename, const MacroMap& macros) {
    return Parser(text, filename, macros).parse();
}

std::vector<TemplateInstance> load_substitutions_file(const std::string& path,
                                                      const MacroMap& macros) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw Error(SB() << path << ": cannot open: Is a directory");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw Error(SB() << path << ": read error: " << std::strerror(errno));
    return parse_substitutions(ss.str(), path, macros);
}

bool is_substitutions_file(std::string_view path) {
    for (std::string_view ext : {".substitutions", ".substitution", ".subs", ".substs"})
        if (path.size() > ext.size() && path.ends_with(ext)) return true;
    return false;
}

std::vector<DbFile> load_records_file(const std::string& path, const MacroMap& macros,
                                      const std::vector<std::string>& include_path) {
    if (!is_substitutions_file(path)) return {load_db_file(path, macros, include_path)};
    namespace fs = std::filesystem;
    std::vector<DbFile> files;
    ErrorList errors;
    const fs::path dir = fs::path(path).parent_path();
    for (const TemplateInstance& inst : load_substitutions_file(path, macros)) {
        std::error_code ec;
        std::string found = inst.file;
        if (!fs::path(inst.file).is_absolute()) {
            std::vector<fs::path> where{dir / inst.file};
            for (const auto& d : include_path) where.push_back(fs::path(d) / inst.file);
            for (const auto& w : where)
                if (fs::exists(w, ec)) {
                    found = w.string();
                    break;
                }
        }
        std::vector<std::string> inc{dir.string()};
        inc.insert(inc.end(), include_path.begin(), include_path.end());
        errors.capture([&] { files.push_back(load_db_file(found, inst.macros, inc)); },
                       std::string(SB() << inst.loc.str() << ": instance of " << inst.file));
    }
    errors.throw_if_any();
    return files;
}

} // namespace beamctl::pv
