// The soft PLC language: ECMC's ExprTk dialect, compiled once (non-RT) into a flat instruction
// list that one scan executes without allocating, locking or throwing.
//
// Threading: compile() runs on a non-RT thread and is the only time Host::resolve and
// Host::function are called; run() runs on one thread at a time (the RT thread) and calls only
// host functions and Host::print. The Host and every bound address must outlive the Program.
//
// Language (ExprTk semantics, as exprtk-ecmc compiles them): statements separated by ';';
// `:=`, `+= -= *= /= %=`, `<=>`; `= ==`, `!= <>`, `< <= > >=`; `and or xor nand nor xnor not()`
// (`&`/`|` short-circuit, `and`/`or` evaluate both sides); `+ - * / % ^` with ExprTk's
// precedence (`^` right-associative, `-x^2 == -(x^2)`); implicit multiplication (`2x`, `) x`);
// `if (c) {..} else if (c) {..} else {..};`, `if (c, a, b)`, `c ? a : b`, `switch`, `[*]`;
// `for`, `while`, `repeat .. until (c)`, `break`, `break[v]`, `continue`; `var x := 1;`,
// `var v[3] := {1, 2};`, `v[i]`, `v[]`; `return [..];` ends the scan; `~{a; b}`; `println`,
// `print`; ExprTk's math functions, `dot()`; keywords and built-ins are case-insensitive.
// Preprocessing as ecmccfg does it: msi macros `${NAME}`/`$(NAME=default)` (not inside '...'),
// `include "file"` and `substitute "A=1"` lines, then ECMC's `#` comments (to the end of the
// line, also inside strings), `VAR name : address; END_VAR` aliases, and `function f(a, b) {..}`
// definitions (in the code or in CompileOptions::libraries).
#pragma once

#include "core/error.hpp"
#include "core/macros.hpp"

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::plc {

// Storage behind a name the code uses. `size` > 1 makes the name a vector of that many doubles
// (indexable as name[i], usable in dot(), sum(), println()).
struct Binding {
    double* address = nullptr;
    bool writable = false;
    int size = 1;
};

// What the PLC's names mean: the host (the IOC) resolves every name once, at compile time.
class Host {
public:
    virtual ~Host() = default;
    // A name the code uses ("ax1.enc.actpos", "static.step", "ec0.s3.binaryInput01.0"): its
    // storage, or nullopt if unknown (a compile error naming it). Called only while compiling.
    virtual std::optional<Binding> resolve(std::string_view name) = 0;
    // Why `name` is unknown ("no axis 7; the IOC has axes 1-4"), added to the compile error;
    // "" for a plain "unknown name". Called only while compiling, after resolve() failed.
    virtual std::string why_unknown(std::string_view /*name*/) { return {}; }
    // The code assigns to host storage `name` (compile time: who writes what).
    virtual void assigned(std::string_view /*name*/) {}
    // Host functions (ECMC's mc_*, ec_*, ds_*, plugins): looked up by name while compiling;
    // called in RT with the evaluated arguments.
    using Function = double (*)(void* ctx, const double* args, int nargs) noexcept;
    struct FunctionInfo {
        Function fn = nullptr;
        void* ctx = nullptr;
        int min_args = 0, max_args = 0;
    };
    virtual std::optional<FunctionInfo> function(std::string_view /*name*/) { return std::nullopt; }
    // Output of print()/println() (RT: must not block; the host queues it). println's text ends
    // with '\n', print's does not; at most 1023 characters. Numbers are formatted as ExprTk
    // does ("%10.5f"), vector elements separated by a space.
    virtual void print(std::string_view /*text*/) noexcept {}
};

struct CompileOptions {
    MacroMap macros;                       // ${NAME} values (SELF, SELF_ID, M, M_ID, PLC macros)
    std::vector<std::string> include_path; // searched by `include` after the including file's dir
    std::vector<std::string> libraries;    // files of `function f(..) {..}` definitions (plc_lib)
    std::uint64_t max_loop_iterations = 0; // loop iterations per scan before a fault; 0 = no limit
    int max_call_depth = 64;               // nested calls of `function`s per scan
    int max_errors = 50;                   // compile errors collected before giving up
    bool strict = false; // also an error: each construct beamctl accepts and ECMC's ExprTk refuses
    // compile() of a text inside another file (kinematics code in ioc.yaml): errors name
    // origin.file and the lines there. The text's first character is at origin; with
    // origin_block (a YAML `|` block) every line keeps origin's column, else only the first does.
    SourceLoc origin;
    bool origin_block = false;
    std::string origin_label; // said after the place in errors ("kinematics 'k' inverse")
};

// Result of one scan. Anything but ok means the scan stopped at the faulting instruction: values
// written before it stay written, nothing after it ran; the next run() starts afresh.
enum class RunStatus : int {
    ok = 0,
    index_out_of_range = 1,   // v[i] with i outside 0..size-1 (or NaN)
    loop_budget_exceeded = 2, // more than max_loop_iterations loop iterations in one scan
    call_depth_exceeded = 3,  // `function` calls nested deeper than max_call_depth
};
const char* to_string(RunStatus status) noexcept;

// Thrown by compile(): what() is the first error ("file:line:col: message\n<line>\n   ^"),
// errors() every error found (up to CompileOptions::max_errors).
class CompileError : public Error {
public:
    explicit CompileError(std::vector<std::string> errors);
    const std::vector<std::string>& errors() const { return errors_; }

private:
    std::vector<std::string> errors_;
};

class Program {
public:
    // Preprocesses and compiles `text` (reported as `filename`; includes are searched next to
    // it). Throws CompileError on errors, beamctl::Error if a library file cannot be read.
    static Program compile(std::string_view text, const std::string& filename, Host& host,
                           const CompileOptions& options = {});
    static Program compile_file(const std::string& path, Host& host,
                                const CompileOptions& options = {});

    Program(Program&&) noexcept;
    Program& operator=(Program&&) noexcept;
    ~Program();

    // One scan (RT): returns 0 or a RunStatus value. Allocation-free; bounded by the code, and
    // by the loop budget when one is set.
    int run() noexcept;
    // Loop iterations allowed per scan (0 = no limit); RT-safe.
    void set_loop_budget(std::uint64_t iterations) noexcept;

    // Where the last failing run() stopped: "file:line:col: <what>" (non-RT), "" after success.
    std::string fault_location() const;
    // The same split for another thread: the faulting instruction (RT: read right after run(),
    // -1 after success), and the "file:line:col" of an instruction (any thread; immutable).
    int fault_index() const noexcept;
    std::string location(int index) const;
    // Number of instructions (diagnostics, benchmarks).
    std::size_t size() const noexcept;
    // The compiled code as text, one instruction per line (debugging).
    std::string disassemble() const;

    struct Impl; // internal (plc/code.hpp)

private:
    explicit Program(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

} // namespace beamctl::plc
