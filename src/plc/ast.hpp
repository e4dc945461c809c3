// Syntax tree of a PLC program with every name resolved (locals, host storage, functions).
// Built by the parser, consumed by the compiler; compile-time only.
#pragma once

#include "plc/builtins.hpp"
#include "plc/program.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::plc::detail {

struct Pos {
    int line = -1; // preprocessed line (Source::lines)
    int offset = 0;
};

// Storage the code names: a `var` (scalar or vector), a `function` parameter, or host storage.
struct Variable {
    std::string name;
    int frame = -1; // owning `function` (-1: the program); unused for host storage
    int size = 1;   // elements
    bool vector = false;
    bool host = false;
    bool writable = true;
    double* address = nullptr; // host storage
    Pos pos;                   // declaration (or first use of host storage)
    int slot = -1;             // compiler: first memory slot of a local
};

enum class NK : unsigned char {
    num,         // num
    str,         // str (only as a print() argument)
    var,         // scalar variable: ref
    vec,         // whole vector: ref
    elem,        // vector element: ref, kids[0] = index
    neg,         // kids[0]
    lnot,        // not(kids[0])
    binary,      // op = BinOp, kids[0], kids[1]
    assign,      // op = Assign, kids[0] = target (var, elem or vec), kids[1] = value
    swap,        // kids[0] <=> kids[1]
    builtin,     // builtin, kids = arguments
    aggregate,   // op = Aggregate, kids = arguments (one vector or scalars)
    host_call,   // ref = Unit::host_functions index, kids = arguments
    call,        // ref = Unit::functions index, kids = arguments
    print,       // op = 1 for println, kids = arguments
    dot,         // kids = v0, v1 [, r0, r1]
    cond,        // if / ternary: kids[0] ? kids[1] : kids[2] (kids[2] may be null: NaN)
    loop_while,  // kids[0] = condition, kids[1] = body
    loop_repeat, // kids[0] = body, kids[1] = condition (until)
    loop_for,    // kids = init, condition, increment, body (any but the body may be null)
    brk,         // kids[0] = value or null
    cont,
    ret,      // kids = values
    block,    // kids = statements; value of the last
    var_decl, // ref, kids[0] = initial value or null (0); op = 1: `var x{}` (not initialised)
    vec_decl, // ref, op = VecInit, kids = initial values
    switch_,  // kids = case0, value0, case1, value1, ..., [default]; op = 1 with default
    mswitch,  // [*]: kids = case0, value0, ...
    null,     // NaN
};

enum class Assign : unsigned char { set, add, sub, mul, div, mod };
enum class VecInit : unsigned char { zero, list, single, vector, none };

struct Node {
    NK kind = NK::null;
    Pos pos;
    int op = 0;
    int ref = -1;
    double num = 0;
    bool from_var = false; // num: computed from a constant `var` (not a literal of the source)
    std::string str;
    const Builtin* builtin = nullptr;
    std::vector<std::unique_ptr<Node>> kids;
};
using NodePtr = std::unique_ptr<Node>;

// True when evaluating `n` can change anything (an assignment, a call, print, a declaration,
// a jump or a loop); pure expressions may be skipped when their value is unused.
inline bool has_side_effects(const Node& n) {
    switch (n.kind) {
    case NK::assign:
    case NK::swap:
    case NK::host_call:
    case NK::call:
    case NK::print:
    case NK::var_decl:
    case NK::vec_decl:
    case NK::brk:
    case NK::cont:
    case NK::ret:
    case NK::loop_while:
    case NK::loop_for:
    case NK::loop_repeat:
        return true;
    default:
        break;
    }
    for (const NodePtr& k : n.kids)
        if (k && has_side_effects(*k)) return true;
    return false;
}

struct Function {
    std::string name;
    Pos pos;
    std::vector<int> params; // Variable ids
    NodePtr body;            // null until parsed
    bool defined = false;
};

struct HostFunction {
    std::string name;
    Host::FunctionInfo info;
};

struct Unit {
    std::vector<Variable> vars;
    std::vector<Function> functions;
    std::vector<HostFunction> host_functions;
    NodePtr main; // block
};

} // namespace beamctl::plc::detail
