// PLC source text: preprocessing as ecmccfg does it (msi macros, `include`/`substitute` lines,
// ECMC's `#` comments) and error messages pointing into the original files. Compile-time only.
#pragma once

#include "core/error.hpp"
#include "core/macros.hpp"

#include <string>
#include <string_view>
#include <vector>

namespace beamctl::plc::detail {

// Collects compile errors (already formatted); add() throws Abort once `max` errors are in.
class Diagnostics {
public:
    struct Abort {};
    explicit Diagnostics(int max)
        : max_(max < 1 ? 1 : max) {}
    void add(std::string message);
    bool empty() const { return messages_.empty(); }
    const std::vector<std::string>& messages() const { return messages_; }

private:
    int max_;
    std::vector<std::string> messages_;
};

struct SourceFile {
    std::string path;
    std::vector<std::string> raw; // original lines, without line ends
    int parent_line = -1;         // the `include` line in the including file (raw line, 1-based)
    int parent_file = -1;
    // A text inside another file (kinematics code in ioc.yaml): added to its line numbers, and
    // to the columns of its first line and of the others, when a place in it is named.
    int line_base = 0, first_col_base = 0, col_base = 0;
    std::string label; // what the text is, said after the place ("kinematics 'k' inverse")
    int file_line(int raw_line) const { return raw_line + line_base; }
    int file_col(int raw_line, int col) const { return col + (raw_line == 1 ? first_col_base : col_base); }
};

// Where a root text sits in the file that holds it (see SourceFile::line_base).
struct Embedding {
    int line_base = 0, first_col_base = 0, col_base = 0;
    std::string label;
};

// One line of preprocessed code.
struct SourceLine {
    int file = 0;          // index into Source::files
    int line = 0;          // 1-based line in that file
    bool expanded = false; // a macro was expanded on this line
    std::string text;      // after macro expansion, without comments
    std::vector<int> col;  // original 1-based column of each byte of text, and one past the end
};

class Source {
public:
    std::vector<SourceFile> files;
    std::vector<SourceLine> lines;

    // Location of byte `offset` of preprocessed line `line`.
    SourceLoc loc(int line, int offset) const;
    // "file:line:col: message", the original line and a caret under the column; for a line with
    // macros also the expanded line with its own caret; the include chain, if any.
    std::string diagnostic(int line, int offset, const std::string& message) const;
    // The same for a position in an original file (1-based raw line and column).
    std::string diagnostic_at(int file, int raw_line, int col, const std::string& message) const;
};

// Appends the preprocessed lines of one root text (the program or a library) to `src`.
// `macros` grows by `substitute` lines (msi keeps them for the rest of its input). Errors go to
// `diags`; the offending line is skipped.
void preprocess(Source& src, std::string_view text, const std::string& filename, MacroMap& macros,
                const std::vector<std::string>& include_path, Diagnostics& diags,
                const Embedding& embedding = {});

// Reads a whole file; throws beamctl::Error naming the path if it cannot be read.
std::string read_file(const std::string& path);

} // namespace beamctl::plc::detail
