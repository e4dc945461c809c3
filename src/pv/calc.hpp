// The EPICS calc expression engine, as libCom's postfix() and calcPerform() of EPICS base 7:
// infix text ("A:=A+1;B*SIN(A*D2R)") is compiled once into postfix code, which a small stack
// machine then evaluates on the arguments A..U. Same language, precedences, error cases and
// results as base (bit operations convert as base does on x86-64); see docs in calc.cpp.
// Threading: compile() and perform() are reentrant; a compiled Program is read-only and may be
// performed by any number of threads at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv::calc {

constexpr int kArgs = 21;      // A..U: CALCPERFORM_NARGS of base 7.0 since 2025 (A..L before)
constexpr int kMaxInfix = 80;  // calc record CALC field size: at most kMaxInfix - 1 characters
constexpr int kStackSize = 80; // values on the evaluation stack (CALCPERFORM_STACK)

// A compiled expression (EPICS "postfix" form). Default-constructed = empty, evaluates to error.
struct Program {
    std::vector<unsigned char> code; // opcodes; a literal is followed by its 8-byte double
    bool empty() const { return code.empty(); }
};

// Why an expression did not compile: base's CALC_ERR_* codes (same values), then what beamctl
// adds.
enum class Errc : uint8_t {
    None,
    TooMany,       // a statement other than the one result is not an assignment
    BadLiteral,    // badly formed or out of range numeric literal ("1e999", ".")
    BadAssignment, // ':=' not after A..U at the start of a statement
    BadSeparator,  // ',' outside the parentheses of a function
    ParenNotOpen,  // ')' without '('
    ParenOpen,     // '(' still open at ';' or the end
    Conditional,   // '?' without ':' or ':' without '?'
    Incomplete,    // operand missing, or no statement gives the result
    Underflow,     // a function got fewer arguments than it takes
    Overflow,      // kStackSize values or more would be on the stack at once
    Syntax,        // unknown operator or operand
    Empty,         // empty text (CALC_ERR_NULL_ARG)
    TooLong = 100, // more characters than the CALC field holds
};
// The text of a code, e.g. "Unpaired conditional" (what calcErrorStr gives in base).
const char* errc_text(Errc e);

struct CompileError {
    std::string message;  // what is wrong, e.g. "Syntax error: expected an operand at 'x+1'"
    std::size_t position; // 0-based char index in the infix text where the error was found
    Errc code = Errc::None;
};

// Compiles infix text (EPICS postfix()); text ends at its first NUL as in C. Returns false and
// fills *err on a bad expression, leaving `out` unchanged. Allocates; call outside RT paths.
[[nodiscard]] bool compile(std::string_view infix, Program& out, CompileError* err = nullptr);
// As above with another length limit than the CALC field's (e.g. for calc links); the stack
// limit (kStackSize) still applies.
[[nodiscard]] bool compile(std::string_view infix, Program& out, CompileError* err,
                           std::size_t max_chars);

// Evaluates (EPICS calcPerform): args[kArgs] are A..U and may be changed by ':=' assignments.
// *result is read first as VAL (the previous value) and then holds the new value. Returns false
// on an evaluation error (as calcPerform returns -1): *result is unchanged, but assignments made
// before the error stay, as in base. Never allocates or throws.
[[nodiscard]] bool perform(const Program& p, double* args, double* result) noexcept;

// calcArgUsage: bit i of *inputs set if arg i is read before any assignment to it, of *stores if
// arg i is assigned. Either pointer may be null.
void arg_usage(const Program& p, uint32_t* inputs, uint32_t* stores) noexcept;

} // namespace beamctl::pv::calc
