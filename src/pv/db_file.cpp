#include "pv/db_file.hpp"

#include "core/error_list.hpp"

#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

namespace beamctl::pv {

namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const SourceLoc& loc, const std::string& msg) {
    throw Error(SB() << loc.str() << ": " << msg);
}

bool is_bare_char(char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           std::strchr("_-+:.[]<>;", c) != nullptr;
}

bool is_space(char c) {
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

std::string char_desc(char c) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) {
        static const char* hex = "0123456789abcdef";
        return SB() << "character 0x" << hex[u >> 4] << hex[u & 15];
    }
    return SB() << "'" << c << "'";
}

// ---------------------------------------------------------------------------------------------
// Lexer

enum class Tok { end, punct, word, string, json };

struct Token {
    Tok kind = Tok::end;
    std::string text; // punct: the character; otherwise the value, macros expanded
    SourceLoc loc;    // first character in the original file
};

std::string describe(const Token& t) {
    switch (t.kind) {
    case Tok::end:
        return "end of file";
    case Tok::punct:
    case Tok::word:
        return SB() << "'" << t.text << "'";
    case Tok::string: {
        if (t.text.size() > 40) return SB() << "string \"" << t.text.substr(0, 37) << "...\"";
        return SB() << "string \"" << t.text << "\"";
    }
    case Tok::json:
        return "JSON value";
    }
    return "?";
}

class Lexer {
public:
    Lexer(std::string_view text, const std::string& file, const MacroMap& macros)
        : text_(text)
        , macros_(macros) {
        loc_.file = file;
        loc_.line = 1;
        loc_.col = 1;
        if (text_.substr(0, 3) == "\xEF\xBB\xBF") pos_ = 3; // UTF-8 byte order mark
    }

    // Next token; '{' and '[' are punctuation.
    Token next() {
        skip_space();
        Token t;
        t.loc = loc_;
        if (at_end()) return t;
        const char c = peek();
        if (std::strchr("(){},", c) != nullptr) {
            t.kind = Tok::punct;
            t.text = std::string(1, c);
            advance();
            return t;
        }
        if (c == '"') return read_string();
        if (is_bare_char(c) || is_macro_ref(text_, pos_)) return read_word();
        if (c == '\'') fail(loc_, "invalid character '\\'': strings are quoted with \"");
        fail(loc_, SB() << "invalid " << char_desc(c));
    }

    // Next token where a field or info value is expected: '{' and '[' start a JSON value.
    Token next_value() {
        skip_space();
        if (!at_end() && (peek() == '{' || peek() == '[')) return read_json();
        return next();
    }

    // After an error: moves to the start of the next line that begins (after blanks) with
    // `record` or `grecord` and then '(' or a blank. False when there is none.
    bool skip_to_next_record() {
        while (!at_end()) {
            while (!at_end() && peek() != '\n') advance();
            if (at_end()) return false;
            advance(); // the newline
            std::size_t p = pos_;
            while (p < text_.size() && (text_[p] == ' ' || text_[p] == '\t')) ++p;
            for (std::string_view kw : {"record", "grecord"}) {
                if (text_.substr(p, kw.size()) != kw) continue;
                const char c = p + kw.size() < text_.size() ? text_[p + kw.size()] : '\0';
                if (c == '(' || c == ' ' || c == '\t') return true;
            }
        }
        return false;
    }

private:
    bool at_end() const { return pos_ >= text_.size(); }
    char peek(std::size_t k = 0) const { return pos_ + k < text_.size() ? text_[pos_ + k] : '\0'; }
    void advance() {
        advance_loc(loc_, text_[pos_]);
        ++pos_;
    }
    void expand_into(std::string& out) { out += expand_macro_ref(text_, pos_, loc_, macros_); }

    void skip_space() {
        while (!at_end()) {
            if (is_space(peek())) {
                advance();
            } else if (peek() == '#') {
                while (!at_end() && peek() != '\n') advance();
            } else {
                break;
            }
        }
    }

    Token read_word() {
        Token t;
        t.kind = Tok::word;
        t.loc = loc_;
        while (!at_end()) {
            if (is_bare_char(peek())) {
                t.text += peek();
                advance();
            } else if (is_macro_ref(text_, pos_)) {
                expand_into(t.text);
            } else {
                break;
            }
        }
        return t;
    }

    [[noreturn]] void unterminated_string(const SourceLoc& start) const {
        fail(start, SB() << "unterminated string: missing closing '\"' before "
                         << (at_end() ? "end of file" : "end of line"));
    }

    Token read_string() {
        Token t;
        t.kind = Tok::string;
        t.loc = loc_;
        advance(); // opening quote
        while (true) {
            if (at_end() || peek() == '\n') unterminated_string(t.loc);
            const char c = peek();
            if (c == '"') {
                advance();
                return t;
            }
            if (c == '\\') {
                advance();
                if (at_end() || peek() == '\n') unterminated_string(t.loc);
                read_escape(t.text);
            } else if (is_macro_ref(text_, pos_)) {
                expand_into(t.text);
            } else {
                t.text += c;
                advance();
            }
        }
    }

    // After a backslash: translates the escape sequence at pos_.
    void read_escape(std::string& out) {
        const char c = peek();
        advance();
        switch (c) {
        case 'n':
            out += '\n';
            return;
        case 't':
            out += '\t';
            return;
        case 'r':
            out += '\r';
            return;
        case 'a':
            out += '\a';
            return;
        case 'b':
            out += '\b';
            return;
        case 'f':
            out += '\f';
            return;
        case 'v':
            out += '\v';
            return;
        case 'x': {
            int value = 0;
            int digits = 0;
            while (digits < 2 && std::isxdigit(static_cast<unsigned char>(peek())) != 0) {
                const char h = peek();
                value = value * 16 + (h <= '9' ? h - '0' : (h | 0x20) - 'a' + 10);
                ++digits;
                advance();
            }
            out += digits == 0 ? 'x' : static_cast<char>(value);
            return;
        }
        default:
            if (c >= '0' && c <= '7') {
                int value = c - '0';
                for (int digits = 1; digits < 3 && peek() >= '0' && peek() <= '7'; ++digits) {
                    value = value * 8 + (peek() - '0');
                    advance();
                }
                out += static_cast<char>(value);
                return;
            }
            out += c; // \\ \" \' \? \$ and any other character stand for themselves
        }
    }

    Token read_json() {
        Token t;
        t.kind = Tok::json;
        t.loc = loc_;
        std::string closers;
        while (true) {
            if (at_end()) {
                fail(t.loc, SB() << "unterminated JSON value: expected '" << closers.back()
                                 << "' before end of file");
            }
            const char c = peek();
            if (c == '"') {
                const SourceLoc start = loc_;
                t.text += c;
                advance();
                while (true) {
                    if (at_end() || peek() == '\n') unterminated_string(start);
                    const char s = peek();
                    if (s == '\\' && pos_ + 1 < text_.size() && peek(1) != '\n') {
                        t.text += s;
                        advance();
                        t.text += peek();
                        advance();
                    } else if (is_macro_ref(text_, pos_)) {
                        expand_into(t.text);
                    } else {
                        t.text += s;
                        advance();
                        if (s == '"') break;
                    }
                }
            } else if (c == '#') {
                while (!at_end() && peek() != '\n') advance();
            } else if (c == '{' || c == '[') {
                closers += c == '{' ? '}' : ']';
                t.text += c;
                advance();
            } else if (c == '}' || c == ']') {
                if (c != closers.back()) {
                    fail(loc_, SB() << "mismatched '" << c << "' in JSON value: expected '"
                                    << closers.back() << "'");
                }
                closers.pop_back();
                t.text += c;
                advance();
                if (closers.empty()) return t;
            } else if (is_macro_ref(text_, pos_)) {
                expand_into(t.text);
            } else {
                t.text += c;
                advance();
            }
        }
    }

    std::string_view text_;
    std::size_t pos_ = 0;
    SourceLoc loc_; // of text_[pos_]
    const MacroMap& macros_;
};

// ---------------------------------------------------------------------------------------------
// Redefinition rules

void check_name(const std::string& name, const SourceLoc& loc, const char* what) {
    if (name.empty()) fail(loc, SB() << "empty " << what);
    for (char c : name) {
        const auto u = static_cast<unsigned char>(c);
        if (u < 0x20 || u == 0x7f || std::strchr(" \"'.$", c) != nullptr) {
            fail(loc, SB() << "invalid " << char_desc(c) << " in " << what << " '" << name << "'");
        }
    }
}

class Builder {
public:
    explicit Builder(DbFile& file)
        : file_(file) {
        for (std::size_t i = 0; i < file_.records.size(); ++i) {
            const DbRecord& r = file_.records[i];
            records_[r.name] = i;
            for (const auto& a : r.aliases) aliases_[a] = r.loc;
        }
        for (const auto& a : file_.aliases) aliases_[a.alias] = a.loc;
    }

    // Returns the index of the record that the definition `type`/`name` goes into.
    std::size_t begin_record(const std::string& type, const std::string& name, const SourceLoc& loc,
                             const SourceLoc& type_loc, const SourceLoc& name_loc) {
        if (const auto a = aliases_.find(name); a != aliases_.end()) {
            fail(name_loc, SB() << "record name '" << name << "' is already an alias (defined at "
                                << a->second.str() << ")");
        }
        const auto it = records_.find(name);
        if (it != records_.end()) {
            const DbRecord& existing = file_.records[it->second];
            if (type == "*" || type == existing.type) return it->second;
            if (existing.type != "*") {
                fail(type_loc, SB() << "record '" << name << "' redefined with type '" << type
                                    << "', but it has type '" << existing.type << "' (defined at "
                                    << existing.loc.str() << ")");
            }
            // A concrete definition after an unresolved record("*", ...): the "*" entry must be
            // resolved first, against records defined elsewhere; later ones merge into this one.
        }
        DbRecord r;
        r.type = type;
        r.name = name;
        r.loc = loc;
        file_.records.push_back(std::move(r));
        records_[name] = file_.records.size() - 1;
        return file_.records.size() - 1;
    }

    void add_field(std::size_t rec, const DbField& f) { upsert(file_.records[rec].fields, f); }
    void add_info(std::size_t rec, const DbInfo& i) { upsert(file_.records[rec].infos, i); }

    void add_record_alias(std::size_t rec, const std::string& alias, const SourceLoc& loc) {
        check_alias(alias, loc);
        file_.records[rec].aliases.push_back(alias);
        aliases_[alias] = loc;
    }

    void add_alias(const DbAlias& a, const SourceLoc& alias_loc) {
        check_alias(a.alias, alias_loc);
        file_.aliases.push_back(a);
        aliases_[a.alias] = a.loc;
    }

private:
    template <typename T> static void upsert(std::vector<T>& items, const T& item) {
        for (auto& existing : items) {
            if (existing.name == item.name) {
                existing.value = item.value;
                existing.loc = item.loc;
                return;
            }
        }
        items.push_back(item);
    }

    void check_alias(const std::string& alias, const SourceLoc& loc) const {
        if (const auto r = records_.find(alias); r != records_.end()) {
            fail(loc, SB() << "alias '" << alias << "' has the name of record '" << alias
                           << "' (defined at " << file_.records[r->second].loc.str() << ")");
        }
        if (const auto a = aliases_.find(alias); a != aliases_.end()) {
            fail(loc, SB() << "alias '" << alias << "' is already defined (at " << a->second.str()
                           << ")");
        }
    }

    DbFile& file_;
    std::map<std::string, std::size_t> records_; // name -> record later definitions merge into
    std::map<std::string, SourceLoc> aliases_;   // alias name -> where defined
};

// ---------------------------------------------------------------------------------------------
// Parser

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw Error(SB() << path << ": read error: " << std::strerror(errno));
    return ss.str();
}

struct Context {
    Builder& builder;
    const MacroMap& macros;
    const std::vector<std::string>& include_path;
    std::vector<std::string> open_files; // include chain, canonical paths, outermost first
    ErrorList errors;                    // every error of every file, in the order found
    bool stopped = false;                // too many errors: nothing more is read
};

constexpr std::size_t kMaxErrors = 100;

std::string canonical_name(const std::string& path) {
    std::error_code ec;
    const fs::path p = fs::weakly_canonical(fs::path(path), ec);
    return ec ? path : p.string();
}

class FileParser {
public:
    // `trail` follows every error of this file: "\n  included from file:line:col" for each
    // include on the way to it, innermost first.
    FileParser(Context& ctx, std::string_view text, const std::string& filename,
               std::string trail = {})
        : ctx_(ctx)
        , lex_(text, filename, ctx.macros)
        , filename_(filename)
        , trail_(std::move(trail)) {}

    // A whole .db file: records, aliases, includes. An error is recorded and parsing goes on
    // at the next record.
    void parse_top() {
        while (!ctx_.stopped) {
            try {
                if (!parse_top_item()) return;
            } catch (const Error& e) {
                if (!recover(e)) return;
            }
        }
    }

    // An included file inside a record body: body items up to the end of the file.
    void parse_body_items(std::size_t rec, const std::string& rec_name) {
        while (!ctx_.stopped) {
            try {
                Token t = take();
                if (t.kind == Tok::end) return;
                if (!parse_body_item(t, rec, rec_name)) {
                    fail(t.loc, SB() << "expected 'field', 'info', 'alias' or 'include' for record '"
                                     << rec_name << "', found " << describe(t));
                }
            } catch (const Error& e) {
                if (!recover(e)) return;
            }
        }
    }

private:
    // Records the error; true when parsing can go on (at the next record).
    bool recover(const Error& e) {
        ctx_.errors.add(SB() << e.what() << trail_);
        if (ctx_.errors.size() >= kMaxErrors) {
            ctx_.errors.add(SB() << filename_ << ": too many errors (" << kMaxErrors
                                 << "); the rest is not read" << trail_);
            ctx_.stopped = true;
            return false;
        }
        ahead_.reset();
        try {
            return lex_.skip_to_next_record();
        } catch (const Error&) {
            return false;
        }
    }

    // One top-level item; false at the end of the file.
    bool parse_top_item() {
        {
            Token t = take();
            if (t.kind == Tok::end) return false;
            if (t.kind == Tok::word) {
                if (t.text == "record" || t.text == "grecord") {
                    parse_record(t);
                    return true;
                }
                if (t.text == "alias") {
                    parse_top_alias(t);
                    return true;
                }
                if (t.text == "include") {
                    parse_include(t, std::nullopt);
                    return true;
                }
                if (t.text == "path" || t.text == "addpath") {
                    fail(t.loc, SB() << "'" << t.text << "' is not supported in .db files; "
                                     << "give include directories to the loader instead");
                }
                static const char* const dbd_keywords[] = {
                    "menu", "choice",    "recordtype", "device",   "driver",
                    "link", "registrar", "function",   "variable", "breaktable"};
                for (const char* k : dbd_keywords) {
                    if (t.text == k) {
                        fail(t.loc, SB() << "'" << t.text << "' is a .dbd keyword, not allowed "
                                         << "in a .db file");
                    }
                }
            }
            fail(t.loc, SB() << "expected 'record', 'grecord', 'alias' or 'include', found "
                             << describe(t));
        }
    }

    Token& peek() {
        if (!ahead_) ahead_ = lex_.next();
        return *ahead_;
    }
    Token take() {
        if (ahead_) {
            Token t = std::move(*ahead_);
            ahead_.reset();
            return t;
        }
        return lex_.next();
    }
    // A field or info value (may be JSON); nothing may be looked ahead before it.
    Token take_value() { return ahead_ ? take() : lex_.next_value(); }

    void expect_punct(char c, const std::string& where) {
        Token t = take();
        if (t.kind != Tok::punct || t.text[0] != c) {
            fail(t.loc, SB() << "expected '" << c << "' " << where << ", found " << describe(t));
        }
    }

    // A bare word or quoted string.
    Token expect_string(const std::string& what) {
        Token t = take();
        if (t.kind != Tok::word && t.kind != Tok::string) {
            fail(t.loc, SB() << "expected " << what << ", found " << describe(t));
        }
        return t;
    }

    // record(TYPE, NAME) [{ items }]
    void parse_record(const Token& kw) {
        expect_punct('(', SB() << "after '" << kw.text << "'");
        const Token type = expect_string("record type");
        if (type.text.empty()) fail(type.loc, "empty record type");
        expect_punct(',', SB() << "after record type '" << type.text << "'");
        const Token name = expect_string("record name");
        check_name(name.text, name.loc, "record name");
        expect_punct(')', SB() << "after record name '" << name.text << "'");
        const std::size_t rec =
            ctx_.builder.begin_record(type.text, name.text, kw.loc, type.loc, name.loc);

        if (peek().kind != Tok::punct || peek().text != "{") return; // no body
        const Token open = take();
        while (true) {
            Token t = take();
            if (t.kind == Tok::punct && t.text == "}") return;
            if (parse_body_item(t, rec, name.text)) continue;
            SB msg;
            msg << "expected 'field', 'info', 'alias', 'include' or '}' in record '" << name.text
                << "', found " << describe(t);
            if (t.kind == Tok::end) msg << " (record body opened at " << open.loc.str() << ")";
            fail(t.loc, msg);
        }
    }

    // One field/info/alias/include of a record body; false if `t` starts none of them.
    bool parse_body_item(const Token& t, std::size_t rec, const std::string& rec_name) {
        if (t.kind != Tok::word) return false;
        if (t.text == "field" || t.text == "info") {
            const std::string kind = t.text;
            expect_punct('(', SB() << "after '" << kind << "'");
            const Token name = expect_string(kind + " name");
            if (name.text.empty()) fail(name.loc, SB() << "empty " << kind << " name");
            expect_punct(',', SB() << "after " << kind << " name '" << name.text << "'");
            const Token value = take_value();
            if (value.kind != Tok::word && value.kind != Tok::string && value.kind != Tok::json) {
                fail(value.loc, SB() << "expected value of " << kind << " '" << name.text
                                     << "', found " << describe(value));
            }
            expect_punct(')', SB() << "after value of " << kind << " '" << name.text << "'");
            if (kind == "field") {
                ctx_.builder.add_field(rec, DbField{name.text, value.text, name.loc});
            } else {
                ctx_.builder.add_info(rec, DbInfo{name.text, value.text, name.loc});
            }
            return true;
        }
        if (t.text == "alias") {
            expect_punct('(', "after 'alias'");
            const Token alias = expect_string(SB() << "alias name for record '" << rec_name << "'");
            check_name(alias.text, alias.loc, "alias name");
            expect_punct(')', SB() << "after alias name '" << alias.text << "'");
            ctx_.builder.add_record_alias(rec, alias.text, alias.loc);
            return true;
        }
        if (t.text == "include") {
            parse_include(t, std::make_pair(rec, rec_name));
            return true;
        }
        return false;
    }

    // alias(RECORD, ALIAS)
    void parse_top_alias(const Token& kw) {
        expect_punct('(', "after 'alias'");
        const Token rec = expect_string("record name");
        check_name(rec.text, rec.loc, "record name");
        expect_punct(',', SB() << "after record name '" << rec.text << "' in alias");
        const Token alias = expect_string("alias name");
        check_name(alias.text, alias.loc, "alias name");
        expect_punct(')', SB() << "after alias name '" << alias.text << "'");
        ctx_.builder.add_alias(DbAlias{rec.text, alias.text, kw.loc}, alias.loc);
    }

    // include "FILE"; inside a record body when `body` is set.
    void parse_include(const Token& kw,
                       const std::optional<std::pair<std::size_t, std::string>>& body) {
        const Token file = expect_string("file name after 'include'");
        if (file.text.empty()) fail(file.loc, "empty file name after 'include'");
        const std::string path = resolve_include(file);
        const std::string canonical = canonical_name(path);
        for (const auto& open : ctx_.open_files) {
            if (open == canonical) {
                fail(file.loc, SB() << "include cycle: '" << path << "' is already being read");
            }
        }
        const std::string text = read_file(path);
        ctx_.open_files.push_back(canonical);
        FileParser sub(ctx_, text, path, SB() << "\n  included from " << kw.loc.str() << trail_);
        if (body) {
            sub.parse_body_items(body->first, body->second);
        } else {
            sub.parse_top();
        }
        ctx_.open_files.pop_back();
    }

    std::string resolve_include(const Token& file) const {
        const fs::path name(file.text);
        std::vector<fs::path> candidates;
        if (name.is_absolute()) {
            candidates.push_back(name);
        } else {
            candidates.push_back(fs::path(filename_).parent_path() / name);
            for (const auto& dir : ctx_.include_path) candidates.push_back(fs::path(dir) / name);
        }
        SB searched;
        for (std::size_t i = 0; i < candidates.size(); ++i) {
            const fs::path p = candidates[i].lexically_normal();
            std::error_code ec;
            if (fs::is_regular_file(p, ec)) return p.string();
            searched << (i == 0 ? "" : ", ") << p.string();
        }
        fail(file.loc, SB() << "include file '" << file.text << "' not found (searched "
                            << searched.str() << ")");
    }

    Context& ctx_;
    Lexer lex_;
    std::string filename_;
    std::string trail_;
    std::optional<Token> ahead_;
};

} // namespace

DbFile parse_db(std::string_view text, const std::string& filename, const MacroMap& macros,
                const std::vector<std::string>& include_path) {
    DbFile out;
    Builder builder(out);
    Context ctx{builder, macros, include_path, {}, {}, false};
    if (!filename.empty()) ctx.open_files.push_back(canonical_name(filename));
    FileParser(ctx, text, filename).parse_top();
    ctx.errors.throw_if_any();
    return out;
}

DbFile load_db_file(const std::string& path, const MacroMap& macros,
                    const std::vector<std::string>& include_path) {
    return parse_db(read_file(path), path, macros, include_path);
}

void merge_db(DbFile& into, const DbFile& more) {
    Builder builder(into);
    for (const DbRecord& r : more.records) {
        const std::size_t rec = builder.begin_record(r.type, r.name, r.loc, r.loc, r.loc);
        for (const auto& f : r.fields) builder.add_field(rec, f);
        for (const auto& i : r.infos) builder.add_info(rec, i);
        for (const auto& a : r.aliases) builder.add_record_alias(rec, a, r.loc);
    }
    for (const auto& a : more.aliases) builder.add_alias(a, a.loc);
}

} // namespace beamctl::pv
