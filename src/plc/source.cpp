#include "plc/source.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace beamctl::plc::detail {

namespace fs = std::filesystem;

void Diagnostics::add(std::string message) {
    messages_.push_back(std::move(message));
    if (static_cast<int>(messages_.size()) >= max_) throw Abort{};
}

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open file");
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw Error(SB() << path << ": read error");
    return ss.str();
}

namespace {

bool is_utf8_continuation(char c) {
    return (static_cast<unsigned char>(c) & 0xC0) == 0x80;
}

// 1-based column of each byte of `line` (continuation bytes share their character's column),
// plus one past the end.
std::vector<int> columns_of(std::string_view line) {
    std::vector<int> cols(line.size() + 1);
    int col = 0;
    for (std::size_t i = 0; i < line.size(); ++i) {
        if (!is_utf8_continuation(line[i])) ++col;
        cols[i] = col;
    }
    cols[line.size()] = col + 1;
    return cols;
}

// The part of `line` before column `col`, with every character but a tab turned into a space.
std::string caret_line(std::string_view line, int col) {
    std::string out;
    int c = 1;
    for (std::size_t i = 0; i < line.size() && c < col; ++i) {
        if (is_utf8_continuation(line[i])) continue;
        out += line[i] == '\t' ? '\t' : ' ';
        ++c;
    }
    while (c++ < col) out += ' ';
    out += '^';
    return out;
}

std::string include_chain(const Source& src, int file) {
    std::string out;
    for (int f = file; f >= 0 && src.files[f].parent_file >= 0; f = src.files[f].parent_file) {
        const SourceFile& parent = src.files[src.files[f].parent_file];
        out += SB() << "\n  included from " << parent.path << ":" << parent.file_line(src.files[f].parent_line);
    }
    return out;
}

// Comment removal, fed one character at a time over the whole preprocessed stream (a block
// comment may continue into the next line or file). As ECMC strips everything from a '#' to
// the end of the line before ExprTk sees the code, '#' ends the line in every state (also
// inside strings and block comments); ExprTk then drops `// ...` and `/* ... */`.
class CommentFilter {
public:
    void begin_line(SourceLine* out) {
        out_ = out;
        dropped_ = false;
        star_ = false;
        pending_slash_ = false;
        if (mode_ == Mode::string) mode_ = Mode::code; // strings do not span lines
    }
    void end_line() { flush_slash(); }
    bool in_comment() const { return dropped_ || mode_ == Mode::block; }
    bool in_block() const { return mode_ == Mode::block; }
    // Where the open block comment started (file, raw line, column).
    int block_file = -1, block_line = 0, block_col = 0;

    void put(char c, int col) {
        if (dropped_) return;
        if (c == '#') {
            flush_slash();
            dropped_ = true;
            return;
        }
        switch (mode_) {
        case Mode::code:
            if (pending_slash_) {
                pending_slash_ = false;
                if (c == '/') {
                    dropped_ = true;
                    return;
                }
                if (c == '*') {
                    mode_ = Mode::block;
                    star_ = false;
                    block_file = out_->file;
                    block_line = out_->line;
                    block_col = slash_col_;
                    return;
                }
                append('/', slash_col_);
            }
            if (c == '/') {
                pending_slash_ = true;
                slash_col_ = col;
                return;
            }
            if (c == '\'') {
                mode_ = Mode::string;
                escape_ = false;
            }
            append(c, col);
            return;
        case Mode::string:
            append(c, col);
            if (escape_) {
                escape_ = false;
            } else if (c == '\\') {
                escape_ = true;
            } else if (c == '\'') {
                mode_ = Mode::code;
            }
            return;
        case Mode::block:
            if (star_ && c == '/') {
                mode_ = Mode::code;
                star_ = false;
                return;
            }
            star_ = c == '*';
            return;
        }
    }

private:
    enum class Mode { code, string, block };
    void append(char c, int col) {
        out_->text += c;
        out_->col.push_back(col);
    }
    void flush_slash() {
        if (pending_slash_) append('/', slash_col_);
        pending_slash_ = false;
    }

    SourceLine* out_ = nullptr;
    Mode mode_ = Mode::code;
    bool dropped_ = false, star_ = false, escape_ = false, pending_slash_ = false;
    int slash_col_ = 0;
};

// An msi command line: `include "file"` or `substitute "A=1,B=2"` (keyword first on the line,
// the argument quoted, nothing after it).
struct MsiCommand {
    enum Kind { none, include, substitute } kind = none;
    std::string arg;
    std::size_t arg_pos = 0; // byte offset of the opening quote
};

MsiCommand msi_command(std::string_view line) {
    MsiCommand cmd;
    std::size_t p = 0;
    while (p < line.size() && std::isspace(static_cast<unsigned char>(line[p]))) ++p;
    std::string_view rest = line.substr(p);
    MsiCommand::Kind kind = MsiCommand::none;
    if (rest.substr(0, 7) == "include") {
        kind = MsiCommand::include;
        p += 7;
    } else if (rest.substr(0, 10) == "substitute") {
        kind = MsiCommand::substitute;
        p += 10;
    } else {
        return cmd;
    }
    while (p < line.size() && std::isspace(static_cast<unsigned char>(line[p]))) ++p;
    if (p >= line.size() || line[p] != '"') return cmd;
    const std::size_t quote = p++;
    const std::size_t start = p;
    while (p < line.size() && line[p] != '"') {
        if (line[p] == '\\' && p + 1 < line.size() && line[p + 1] == '"') ++p;
        ++p;
    }
    if (p >= line.size()) return cmd;
    const std::size_t end = p++;
    while (p < line.size() && (line[p] == ' ' || line[p] == '\t')) ++p;
    if (p != line.size()) return cmd;
    cmd.kind = kind;
    cmd.arg = std::string(line.substr(start, end - start));
    cmd.arg_pos = quote;
    return cmd;
}

class Preprocessor {
public:
    Preprocessor(Source& src, MacroMap& macros, const std::vector<std::string>& include_path,
                 Diagnostics& diags)
        : src_(src)
        , macros_(macros)
        , include_path_(include_path)
        , diags_(diags) {}

    void run(std::string_view text, const std::string& path, const Embedding& embedding) {
        embedding_ = embedding;
        process(text, path, -1, 0);
        if (filter_.in_block())
            diags_.add(src_.diagnostic_at(filter_.block_file, filter_.block_line, filter_.block_col,
                                          "'/*' comment is never closed"));
    }

private:
    void process(std::string_view text, const std::string& path, int parent_file, int parent_line) {
        const int file = static_cast<int>(src_.files.size());
        SourceFile sf;
        sf.path = path;
        sf.parent_file = parent_file;
        sf.parent_line = parent_line;
        if (parent_file < 0) {
            sf.line_base = embedding_.line_base;
            sf.first_col_base = embedding_.first_col_base;
            sf.col_base = embedding_.col_base;
            sf.label = embedding_.label;
        }
        std::size_t start = 0;
        while (start < text.size()) {
            std::size_t end = text.find('\n', start);
            if (end == std::string_view::npos) end = text.size();
            std::string_view l = text.substr(start, end - start);
            if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
            sf.raw.emplace_back(l);
            start = end + 1;
        }
        src_.files.push_back(std::move(sf));
        stack_.push_back(fs::weakly_canonical(fs::absolute(path)).string());

        const std::size_t nlines = src_.files[file].raw.size();
        for (std::size_t i = 0; i < nlines; ++i) {
            // Copy: including a file appends to src_.files and may move the raw lines.
            const std::string raw = src_.files[file].raw[i];
            const int lineno = static_cast<int>(i) + 1;
            const MsiCommand cmd = msi_command(raw);
            if (cmd.kind == MsiCommand::include) {
                include(file, lineno, raw, cmd);
                continue;
            }
            if (cmd.kind == MsiCommand::substitute) {
                substitute(file, lineno, raw, cmd);
                continue;
            }
            expand_line(file, lineno, raw);
        }
        stack_.pop_back();
    }

    std::string path_of(int file) const { return src_.files[file].path; }

    void include(int file, int lineno, const std::string& raw, const MsiCommand& cmd) {
        const int col = columns_of(raw)[cmd.arg_pos];
        std::vector<std::string> tried;
        std::string found;
        const fs::path name(cmd.arg);
        if (cmd.arg.empty()) {
            diags_.add(src_.diagnostic_at(file, lineno, col, "empty include file name"));
            return;
        }
        if (name.is_absolute()) {
            tried.push_back(cmd.arg);
            if (fs::is_regular_file(name)) found = cmd.arg;
        } else {
            std::vector<fs::path> dirs;
            fs::path own = fs::path(path_of(file)).parent_path();
            dirs.push_back(own.empty() ? fs::path(".") : own);
            for (const std::string& d : include_path_) dirs.emplace_back(d.empty() ? "." : d);
            for (const fs::path& d : dirs) {
                const fs::path candidate = d / name;
                tried.push_back(candidate.string());
                std::error_code ec;
                if (fs::is_regular_file(candidate, ec)) {
                    found = candidate.string();
                    break;
                }
            }
        }
        if (found.empty()) {
            SB msg;
            msg << "include file '" << cmd.arg << "' not found (searched:";
            for (const std::string& t : tried) msg << " " << t;
            msg << ")";
            diags_.add(src_.diagnostic_at(file, lineno, col, msg.str()));
            return;
        }
        const std::string canonical = fs::weakly_canonical(fs::absolute(found)).string();
        if (std::find(stack_.begin(), stack_.end(), canonical) != stack_.end() ||
            stack_.size() > 32) {
            diags_.add(src_.diagnostic_at(
                file, lineno, col,
                std::string(SB() << "recursive include of '" << cmd.arg << "'")));
            return;
        }
        std::string text;
        try {
            text = read_file(found);
        } catch (const Error& e) {
            diags_.add(src_.diagnostic_at(file, lineno, col, e.what()));
            return;
        }
        process(text, found, file, lineno);
    }

    void substitute(int file, int lineno, const std::string& raw, const MsiCommand& cmd) {
        const std::vector<int> cols = columns_of(raw);
        try {
            const MacroMap defs =
                parse_macro_defs(cmd.arg, SourceLoc{path_of(file), lineno, cols[cmd.arg_pos] + 1});
            for (const auto& [k, v] : defs) macros_[k] = v;
        } catch (const Error& e) {
            report_macro_error(file, lineno, cols[cmd.arg_pos], e.what());
        }
    }

    // Turns "path:line:col: message" from the macro code into a diagnostic with a caret.
    void report_macro_error(int file, int lineno, int fallback_col, const std::string& what) {
        const std::string prefix = SB() << path_of(file) << ":" << lineno << ":";
        int col = fallback_col;
        std::string message = what;
        if (what.compare(0, prefix.size(), prefix) == 0) {
            std::size_t p = prefix.size();
            int c = 0;
            while (p < what.size() && std::isdigit(static_cast<unsigned char>(what[p])))
                c = c * 10 + (what[p++] - '0');
            if (p + 1 < what.size() && what[p] == ':' && what[p + 1] == ' ' && c > 0) {
                col = c;
                message = what.substr(p + 2);
            }
        }
        diags_.add(src_.diagnostic_at(file, lineno, col, message));
    }

    // Expands macros as msi (macLib) does: not inside single quotes, `\c` copied as is; then
    // removes comments.
    void expand_line(int file, int lineno, const std::string& raw) {
        SourceLine line;
        line.file = file;
        line.line = lineno;
        const std::vector<int> cols = columns_of(raw);
        filter_.begin_line(&line);
        char quote = 0;
        std::size_t i = 0;
        while (i < raw.size()) {
            const char c = raw[i];
            if (c == '\\' && i + 1 < raw.size()) {
                filter_.put(c, cols[i]);
                filter_.put(raw[i + 1], cols[i + 1]);
                i += 2;
                continue;
            }
            if (quote != 0) {
                if (c == quote) quote = 0;
            } else if (c == '"' || c == '\'') {
                quote = c;
            }
            if (is_macro_ref(raw, i) && quote != '\'' && !filter_.in_comment()) {
                SourceLoc loc{path_of(file), lineno, cols[i]};
                std::size_t pos = i;
                std::string value;
                try {
                    value = expand_macro_ref(raw, pos, loc, macros_);
                } catch (const Error& e) {
                    report_macro_error(file, lineno, cols[i], e.what());
                    return; // the line is dropped
                }
                for (char v : value) filter_.put(v, cols[i]);
                line.expanded = true;
                i = pos;
                continue;
            }
            filter_.put(c, cols[i]);
            ++i;
        }
        filter_.end_line();
        line.col.push_back(cols[raw.size()]);
        src_.lines.push_back(std::move(line));
    }

    Source& src_;
    MacroMap& macros_;
    const std::vector<std::string>& include_path_;
    Diagnostics& diags_;
    Embedding embedding_; // of the root text
    CommentFilter filter_;
    std::vector<std::string> stack_; // canonical paths of the files being read
};

} // namespace

SourceLoc Source::loc(int line, int offset) const {
    if (line < 0 || line >= static_cast<int>(lines.size())) return SourceLoc{};
    const SourceLine& l = lines[line];
    const int off = std::clamp(offset, 0, static_cast<int>(l.col.size()) - 1);
    const SourceFile& f = files[l.file];
    return SourceLoc{f.path, f.file_line(l.line), f.file_col(l.line, l.col[off])};
}

std::string Source::diagnostic(int line, int offset, const std::string& message) const {
    if (line < 0 || line >= static_cast<int>(lines.size())) {
        const std::string file = files.empty() ? std::string("<input>") : files.back().path;
        return SB() << file << ": " << message;
    }
    const SourceLine& l = lines[line];
    const int off = std::clamp(offset, 0, static_cast<int>(l.col.size()) - 1);
    std::string out = diagnostic_at(l.file, l.line, l.col[off], message);
    if (l.expanded) {
        // Insert the expanded line before the include chain.
        const std::string chain = include_chain(*this, l.file);
        out.resize(out.size() - chain.size());
        int ecol = 1;
        for (int i = 0; i < off && i < static_cast<int>(l.text.size()); ++i)
            if (!is_utf8_continuation(l.text[i])) ++ecol;
        out += SB() << "\nafter macro expansion:\n" << l.text << "\n" << caret_line(l.text, ecol);
        out += chain;
    }
    return out;
}

std::string Source::diagnostic_at(int file, int raw_line, int col,
                                  const std::string& message) const {
    const SourceFile& f = files[file];
    SB out;
    out << f.path << ":" << f.file_line(raw_line) << ":" << f.file_col(raw_line, col) << ": ";
    if (!f.label.empty()) out << f.label << ": ";
    out << message;
    if (raw_line >= 1 && raw_line <= static_cast<int>(f.raw.size())) {
        const std::string& text = f.raw[raw_line - 1];
        out << "\n" << text << "\n" << caret_line(text, col);
    }
    return out.str() + include_chain(*this, file);
}

void preprocess(Source& src, std::string_view text, const std::string& filename, MacroMap& macros,
                const std::vector<std::string>& include_path, Diagnostics& diags, const Embedding& embedding) {
    Preprocessor(src, macros, include_path, diags).run(text, filename, embedding);
}

} // namespace beamctl::plc::detail
