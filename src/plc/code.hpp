// The executable form of a PLC program: a flat list of three-address instructions whose
// operands are addresses fixed at compile time (program memory or host storage). Everything
// run() touches is allocated here, before the first scan.
#pragma once

#include "plc/builtins.hpp"
#include "plc/program.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::plc::detail {

enum class Op : std::uint8_t {
    halt,  // end of scan
    mov,   // *d = *a
    neg,   // *d = -*a
    lnot,  // *d = !*a
    truth, // *d = *a != 0
    add,
    sub,
    mul,
    div,
    mod,
    pow,
    sqr,      // *d = *a * *a            (x ^ 2)
    powi,     // *d = int_pow(*a, n)     (x ^ n, n a literal integer 3..60)
    powi_inv, // *d = 1 / int_pow(*a, n) (x ^ -n)
    pow_half, // *d = pow_half(*a)       (x ^ 0.5)
    fabs,     // *d = |*a| as ExprTk's abs (-0 stays -0)
    fsqrt,    // *d = sqrt(*a)
    fmin2,    // *d = min2(*a, *b)       (min of two scalars)
    fmax2,    // *d = max2(*a, *b)
    lt,
    le,
    gt,
    ge,
    eq,
    ne,
    land,
    lor,
    lnand,
    lnor,
    lxor,
    lxnor,
    fn1,      // *d = f1(*a)
    fn2,      // *d = f2(*a, *b)
    fn3,      // *d = f3(*a, *b, *c)
    jmp,      // pc = n
    jz,       // if *a == 0: pc = n
    jnz,      // if *a != 0: pc = n
    jf_lt,    // unless *a < *b: pc = n (an `if`/loop condition that is a comparison)
    jf_le,
    jf_gt,
    jf_ge,
    jf_eq,
    jf_ne,
    loop,     // pc = n, counted against the loop budget
    load,     // *d = a[*b]      (vector at a, size n)
    store,    // a[*b] = *c      (vector at a, size n)
    fill,     // d[0..n) = *a
    list_sum, // *d = sum of *list[0..n)
    list_mul,
    list_min,
    list_max,
    vec_sum, // *d = sum of a[0..n)
    vec_mul,
    vec_min,
    vec_max,
    dot,       // *d = sum a[i] * b[i], i < n
    dot_range, // the same over [*c, *e] (NaN if not a valid range of n)
    host_call, // *d = host(ctx, a, n)
    call,      // `function` n with arguments at a; result to *d
    ret,       // return from `function` n
    print_begin,
    print_str, // strings[n]
    print_num, // *a as "%10.5f"
    print_vec, // a[0..n)
    print_end, // n = 1: newline; hands the text to Host::print
    swap,      // *d <=> *a
};

const char* to_string(Op op);

struct Insn {
    Op op = Op::halt;
    std::uint32_t n = 0;
    double* d = nullptr;
    double* a = nullptr;
    double* b = nullptr;
    double* c = nullptr;
    double* e = nullptr;
    union {
        Fn1 f1;
        Fn2 f2;
        Fn3 f3;
        Host::Function host;
        double* const* list;
    } x{};
    void* ctx = nullptr;
};

struct FunctionCode {
    std::uint32_t entry = 0;
    double* frame = nullptr; // parameters, locals and temporaries
    std::uint32_t size = 0;
    std::uint32_t params = 0; // the first `params` slots of the frame
    double* result = nullptr;
    int active = 0; // calls in progress (run time)
};

struct ReturnRecord {
    std::uint32_t call_pc;
    bool saved; // the callee's frame was pushed to the save stack
};

} // namespace beamctl::plc::detail

namespace beamctl::plc {

struct Program::Impl {
    Host* host = nullptr;
    std::vector<detail::Insn> code;
    std::vector<double> memory;       // locals, temporaries, constants, frames
    std::vector<std::string> strings; // print() texts
    std::vector<double*> lists;       // operand lists of list_* instructions
    std::vector<detail::FunctionCode> functions;
    std::vector<double> save; // frames of recursive calls
    std::size_t save_top = 0;
    std::vector<detail::ReturnRecord> returns; // capacity = max call depth
    std::size_t return_top = 0;
    std::uint64_t loop_budget = 0;
    std::vector<std::string> locations; // "file:line:col" of each instruction (faults)
    std::vector<char> print_buffer;     // sized at compile time
    std::size_t print_length = 0;
    struct HostName {
        const double* address;
        int size;
        std::string name;
    };
    std::vector<HostName> host_names; // disassembly
    std::uint32_t const_begin = 0;    // memory[const_begin..]: constants
    int fault_pc = -1;
    RunStatus fault = RunStatus::ok;

    int run() noexcept;
    void reset_calls() noexcept;
};

} // namespace beamctl::plc
