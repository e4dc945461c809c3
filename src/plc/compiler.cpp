#include "plc/compiler.hpp"

#include "plc/parser.hpp"

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <string>

namespace beamctl::plc::detail {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::uint32_t kUnroll = 8; // element-wise vector code is unrolled up to this size

// An operand before memory is laid out.
struct Ref {
    enum Kind : std::uint8_t { none, mem, konst, host };
    Kind kind = none;
    std::uint32_t index = 0;  // memory slot, constant, or host variable id
    std::uint32_t offset = 0; // element of a host vector
    bool temp = false;        // a temporary (holds a value, never a variable)
    bool valid() const { return kind != none; }
    bool is_variable() const { return (kind == mem && !temp) || kind == host; }
    friend bool operator==(const Ref& x, const Ref& y) {
        return x.kind == y.kind && x.index == y.index && x.offset == y.offset;
    }
};

struct PInsn {
    Op op = Op::halt;
    std::uint32_t n = 0;
    Ref d, a, b, c, e;
    Fn1 f1 = nullptr;
    Fn2 f2 = nullptr;
    Fn3 f3 = nullptr;
    Host::Function host = nullptr;
    void* ctx = nullptr;
    int list = -1;
    Pos pos;
};

// An element index: a constant, or a slot holding it.
struct Index {
    Ref ref;
    bool constant = false;
    std::uint32_t value = 0;
};

// A place an assignment writes: fixed storage, or a vector element with a computed index.
struct Place {
    bool dynamic = false;
    Ref ref;   // fixed storage, or the vector's element 0
    Ref index; // dynamic
    std::uint32_t size = 1;
};

// Kinds whose code writes the destination only with their final instruction, so a value may be
// computed straight into the variable it is assigned to.
bool writes_once(const Node& n) {
    switch (n.kind) {
    case NK::num:
    case NK::var:
    case NK::vec:
    case NK::elem:
    case NK::neg:
    case NK::lnot:
    case NK::builtin:
    case NK::host_call:
    case NK::call:
    case NK::dot:
        return true;
    case NK::binary:
        return n.op != static_cast<int>(BinOp::scand) && n.op != static_cast<int>(BinOp::scor);
    case NK::aggregate:
        return n.op != static_cast<int>(Aggregate::mand) &&
               n.op != static_cast<int>(Aggregate::mor) && !is_vector_expr(*n.kids[0]);
    default:
        return false;
    }
}

Op binary_op(BinOp b) {
    switch (b) {
    case BinOp::add:
        return Op::add;
    case BinOp::sub:
        return Op::sub;
    case BinOp::mul:
        return Op::mul;
    case BinOp::div:
        return Op::div;
    case BinOp::mod:
        return Op::mod;
    case BinOp::pow:
        return Op::pow;
    case BinOp::lt:
        return Op::lt;
    case BinOp::le:
        return Op::le;
    case BinOp::gt:
        return Op::gt;
    case BinOp::ge:
        return Op::ge;
    case BinOp::eq:
        return Op::eq;
    case BinOp::ne:
        return Op::ne;
    case BinOp::land:
    case BinOp::scand:
        return Op::land;
    case BinOp::lor:
    case BinOp::scor:
        return Op::lor;
    case BinOp::lnand:
        return Op::lnand;
    case BinOp::lnor:
        return Op::lnor;
    case BinOp::lxor:
        return Op::lxor;
    case BinOp::lxnor:
        return Op::lxnor;
    }
    return Op::add;
}

Op assign_op(Assign a) {
    switch (a) {
    case Assign::add:
        return Op::add;
    case Assign::sub:
        return Op::sub;
    case Assign::mul:
        return Op::mul;
    case Assign::div:
        return Op::div;
    case Assign::mod:
        return Op::mod;
    case Assign::set:
        break;
    }
    return Op::mov;
}

class Compiler {
public:
    Compiler(const Unit& unit, const Source& src, const CompileOptions& options, Diagnostics& diags)
        : unit_(unit)
        , src_(src)
        , options_(options)
        , diags_(diags)
        , slot_(unit.vars.size(), -1) {}

    std::unique_ptr<Program::Impl> run(Host& host) {
        // The program's frame first, then one frame per function.
        frame_ = -1;
        gen(*unit_.main, {}, false);
        emit(Op::halt);
        struct FrameInfo {
            std::uint32_t entry, begin, end, result, params;
        };
        std::vector<FrameInfo> frames(unit_.functions.size());
        fn_result_slot_.assign(unit_.functions.size(), 0);
        for (std::size_t f = 0; f < unit_.functions.size(); ++f) {
            const Function& fn = unit_.functions[f];
            next_slot_ = high_;
            const std::uint32_t result = alloc(1);
            fn_result_slot_[f] = result;
            const std::uint32_t begin = next_slot_;
            for (int p : fn.params) slot_[p] = static_cast<int>(alloc(1));
            frame_ = static_cast<int>(f);
            returns_.clear();
            const std::uint32_t entry = here();
            if (fn.body) gen(*fn.body, Ref{Ref::mem, result}, true);
            for (std::size_t j : returns_) patch(j, here());
            emit(Op::ret).n = static_cast<std::uint32_t>(f);
            frames[f] = {entry, begin, high_, result, static_cast<std::uint32_t>(fn.params.size())};
        }

        auto impl = std::make_unique<Program::Impl>();
        impl->host = &host;
        const std::uint32_t const_base = high_;
        impl->memory.assign(static_cast<std::size_t>(high_) + consts_.size(), 0.0);
        for (std::size_t i = 0; i < consts_.size(); ++i) impl->memory[const_base + i] = consts_[i];
        double* mem = impl->memory.data();
        auto ptr = [&](const Ref& r) -> double* {
            switch (r.kind) {
            case Ref::mem:
                return mem + r.index;
            case Ref::konst:
                return mem + const_base + r.index;
            case Ref::host:
                return unit_.vars[r.index].address + r.offset;
            case Ref::none:
                break;
            }
            return nullptr;
        };
        std::vector<std::size_t> list_start;
        for (const auto& l : lists_) {
            list_start.push_back(impl->lists.size());
            for (const Ref& r : l) impl->lists.push_back(ptr(r));
        }
        impl->code.reserve(code_.size());
        impl->locations.reserve(code_.size());
        for (const PInsn& p : code_) {
            Insn in;
            in.op = p.op;
            in.n = p.n;
            in.d = ptr(p.d);
            in.a = ptr(p.a);
            in.b = ptr(p.b);
            in.c = ptr(p.c);
            in.e = ptr(p.e);
            if (p.f1) in.x.f1 = p.f1;
            if (p.f2) in.x.f2 = p.f2;
            if (p.f3) in.x.f3 = p.f3;
            if (p.host) in.x.host = p.host;
            if (p.list >= 0) in.x.list = impl->lists.data() + list_start[p.list];
            in.ctx = p.ctx;
            impl->code.push_back(in);
            impl->locations.push_back(src_.loc(p.pos.line, p.pos.offset).str());
        }
        std::uint32_t max_frame = 0;
        for (std::size_t f = 0; f < frames.size(); ++f) {
            FunctionCode fc;
            fc.entry = frames[f].entry;
            fc.frame = mem + frames[f].begin;
            fc.size = frames[f].end - frames[f].begin;
            fc.params = frames[f].params;
            fc.result = mem + frames[f].result;
            max_frame = std::max(max_frame, fc.size);
            impl->functions.push_back(fc);
        }
        const std::size_t depth = static_cast<std::size_t>(std::max(1, options_.max_call_depth));
        if (!frames.empty()) {
            impl->returns.resize(depth);
            impl->save.resize(depth * max_frame);
        }
        impl->strings = strings_;
        impl->print_buffer.resize(1024);
        impl->loop_budget = options_.max_loop_iterations;
        for (std::size_t v = 0; v < unit_.vars.size(); ++v)
            if (unit_.vars[v].host)
                impl->host_names.push_back(
                    {unit_.vars[v].address, unit_.vars[v].size, unit_.vars[v].name});
        impl->const_begin = const_base;
        return impl;
    }

private:
    // ---- emission and memory ------------------------------------------------------------------

    PInsn& emit(Op op) {
        PInsn p;
        p.op = op;
        p.pos = pos_;
        code_.push_back(p);
        return code_.back();
    }
    PInsn& emit(Op op, Ref d, Ref a, Ref b = {}) {
        PInsn& p = emit(op);
        p.d = d;
        p.a = a;
        p.b = b;
        return p;
    }
    std::uint32_t here() const { return static_cast<std::uint32_t>(code_.size()); }
    void patch(std::size_t insn, std::uint32_t target) { code_[insn].n = target; }
    std::size_t emit_jump(Op op, Ref cond = {}) {
        emit(op).a = cond;
        return code_.size() - 1;
    }
    // A jump taken when `cond` is false (0, or a comparison that does not hold): a scalar
    // comparison is tested by the jump itself (one instruction instead of two).
    std::size_t emit_jump_unless(const Node& cond) {
        if (cond.kind == NK::binary && !is_vector_expr(cond)) {
            Op op = Op::halt;
            switch (static_cast<BinOp>(cond.op)) {
            case BinOp::lt:
                op = Op::jf_lt;
                break;
            case BinOp::le:
                op = Op::jf_le;
                break;
            case BinOp::gt:
                op = Op::jf_gt;
                break;
            case BinOp::ge:
                op = Op::jf_ge;
                break;
            case BinOp::eq:
                op = Op::jf_eq;
                break;
            case BinOp::ne:
                op = Op::jf_ne;
                break;
            default:
                break;
            }
            if (op != Op::halt) {
                const std::vector<Ref> args = gen_args(cond.kids);
                PInsn& j = emit(op);
                j.a = args[0];
                j.b = args[1];
                return code_.size() - 1;
            }
        }
        return emit_jump(Op::jz, gen(cond));
    }

    std::uint32_t alloc(std::uint32_t n) {
        const std::uint32_t s = next_slot_;
        next_slot_ += n;
        high_ = std::max(high_, next_slot_);
        return s;
    }
    Ref temp() {
        Ref r{Ref::mem, alloc(1)};
        r.temp = true;
        return r;
    }
    Ref konst(double v) {
        std::uint64_t bits;
        std::memcpy(&bits, &v, sizeof bits);
        auto it = const_index_.find(bits);
        if (it == const_index_.end()) {
            it = const_index_.emplace(bits, static_cast<std::uint32_t>(consts_.size())).first;
            consts_.push_back(v);
        }
        return Ref{Ref::konst, it->second};
    }
    Ref var_ref(int id, std::uint32_t offset = 0) {
        const Variable& v = unit_.vars[id];
        if (v.host) return Ref{Ref::host, static_cast<std::uint32_t>(id), offset};
        if (slot_[id] < 0) { // cannot happen: declarations precede uses
            error(v.pos, SB() << "internal error: '" << v.name << "' has no storage");
            slot_[id] = static_cast<int>(alloc(static_cast<std::uint32_t>(v.size)));
        }
        return Ref{Ref::mem, static_cast<std::uint32_t>(slot_[id]) + offset};
    }
    Ref to(Ref dst) { return dst.valid() ? dst : temp(); }
    Ref finish(Ref value, Ref dst) {
        if (!dst.valid() || value == dst) return value;
        emit(Op::mov, dst, value);
        return dst;
    }
    void error(const Pos& at, const std::string& msg) {
        diags_.add(src_.diagnostic(at.line, at.offset, msg));
    }

    // ---- expressions --------------------------------------------------------------------------

    // Generates `n`. With `need`, returns where the value is (in `dst` when given); without,
    // only the side effects are generated.
    Ref gen(const Node& n, Ref dst = {}, bool need = true) {
        if (!need && !has_side_effects(n)) return {};
        const Pos saved = pos_;
        pos_ = n.pos;
        // A pure arithmetic expression computes each distinct subexpression once (kinematics
        // repeat sin(yaw / 1000) and the like); the values are bitwise the same.
        const bool memo_root = need && !memo_on_ && is_operation(n) && pure_arith(n);
        if (memo_root) {
            memo_on_ = true;
            memo_root_ = &n;
        }
        Ref r = gen_node(n, need ? dst : Ref{}, need);
        if (memo_root) {
            memo_on_ = false;
            memo_root_ = nullptr;
            memo_.clear();
        }
        if (need && dst.valid()) r = finish(r, dst);
        pos_ = saved;
        return r;
    }

    // ---- common subexpressions ---------------------------------------------------------------

    static bool is_operation(const Node& n) {
        return n.kind == NK::neg || n.kind == NK::binary || n.kind == NK::builtin;
    }
    // Numbers, scalar variables and arithmetic on them: no side effects, no control flow.
    static bool pure_arith(const Node& n) {
        switch (n.kind) {
        case NK::num:
        case NK::var:
            return true;
        case NK::binary:
            if (n.op == static_cast<int>(BinOp::scand) || n.op == static_cast<int>(BinOp::scor)) return false;
            [[fallthrough]];
        case NK::neg:
        case NK::builtin:
            for (const NodePtr& k : n.kids)
                if (!k || !pure_arith(*k)) return false;
            return true;
        default:
            return false;
        }
    }
    static void append_key(const Node& n, std::string& k) {
        k += static_cast<char>(n.kind);
        k += static_cast<char>(n.op);
        auto raw = [&k](const void* p, std::size_t size) { k.append(static_cast<const char*>(p), size); };
        if (n.kind == NK::num) raw(&n.num, sizeof n.num);
        if (n.kind == NK::var) raw(&n.ref, sizeof n.ref);
        if (n.kind == NK::builtin) raw(&n.builtin, sizeof n.builtin);
        k += '(';
        for (const NodePtr& c : n.kids) append_key(*c, k);
        k += ')';
    }
    // While generating a pure expression: the temporary already holding `n`'s value, or
    // generates it into a new one (the root may go straight to `dst`).
    template <typename Gen> Ref memoized(const Node& n, Ref dst, Gen generate) {
        if (!memo_on_) return generate(dst);
        if (&n == memo_root_) return generate(dst);
        std::string key;
        append_key(n, key);
        if (auto it = memo_.find(key); it != memo_.end()) return it->second;
        const Ref r = generate(Ref{});
        memo_.emplace(std::move(key), r);
        return r;
    }

    Ref gen_node(const Node& n, Ref dst, bool need) {
        if (memo_on_ && is_operation(n))
            return memoized(n, dst, [&](Ref d) { return gen_operation(n, d); });
        return gen_operation(n, dst, need);
    }

    Ref gen_operation(const Node& n, Ref dst, bool need = true) {
        switch (n.kind) {
        case NK::num:
            return konst(n.num);
        case NK::str:
            error(n.pos, "strings are only allowed as arguments of print() and println()");
            return konst(kNaN);
        case NK::var:
            return var_ref(n.ref);
        case NK::vec:
            return var_ref(n.ref); // a vector as a scalar: its first element
        case NK::elem:
            return load(place(n));
        case NK::neg:
        case NK::lnot: {
            const Ref a = gen(*n.kids[0]);
            const Ref d = to(dst);
            emit(n.kind == NK::neg ? Op::neg : Op::lnot, d, a);
            return d;
        }
        case NK::binary:
            return gen_binary(n, dst);
        case NK::assign:
            return gen_assign(n);
        case NK::swap:
            return gen_swap(n);
        case NK::builtin: {
            const std::vector<Ref> args = gen_args(n.kids);
            const Ref d = to(dst);
            if (n.builtin->f1 == builtin_abs() || n.builtin->f1 == builtin_sqrt()) { // inline
                emit(n.builtin->f1 == builtin_abs() ? Op::fabs : Op::fsqrt, d, args[0]);
                return d;
            }
            PInsn& p = emit(n.builtin->arity == 1   ? Op::fn1
                            : n.builtin->arity == 2 ? Op::fn2
                                                    : Op::fn3,
                            d, args[0], args.size() > 1 ? args[1] : Ref{});
            if (args.size() > 2) p.c = args[2];
            p.f1 = n.builtin->f1;
            p.f2 = n.builtin->f2;
            p.f3 = n.builtin->f3;
            return d;
        }
        case NK::aggregate:
            return gen_aggregate(n, dst);
        case NK::host_call: {
            const HostFunction& f = unit_.host_functions[n.ref];
            const Ref args = gen_arg_block(n.kids);
            const Ref d = to(dst);
            PInsn& p = emit(Op::host_call, d, args);
            p.n = static_cast<std::uint32_t>(n.kids.size());
            p.host = f.info.fn;
            p.ctx = f.info.ctx;
            return d;
        }
        case NK::call: {
            const Ref args = gen_arg_block(n.kids);
            const Ref d = to(dst);
            emit(Op::call, d, args).n = static_cast<std::uint32_t>(n.ref);
            return d;
        }
        case NK::print:
            return gen_print(n, dst, need);
        case NK::dot: {
            const Variable& v0 = unit_.vars[n.kids[0]->ref];
            const Variable& v1 = unit_.vars[n.kids[1]->ref];
            const Ref a = var_ref(n.kids[0]->ref), b = var_ref(n.kids[1]->ref);
            Ref r0, r1;
            if (n.kids.size() == 4) {
                const std::vector<Ref> r = gen_args(n.kids.begin() + 2, n.kids.end());
                r0 = r[0];
                r1 = r[1];
            }
            const Ref d = to(dst);
            PInsn& p = emit(n.kids.size() == 4 ? Op::dot_range : Op::dot, d, a, b);
            p.c = r0;
            p.e = r1;
            p.n = static_cast<std::uint32_t>(std::min(v0.size, v1.size));
            return d;
        }
        case NK::cond:
            return gen_cond(n, dst, need);
        case NK::loop_while:
        case NK::loop_repeat:
        case NK::loop_for:
            return gen_loop(n, dst, need);
        case NK::brk: {
            if (loops_.empty()) return {};
            Loop& l = loops_.back();
            if (n.kids[0]) {
                gen(*n.kids[0], l.need ? l.value : Ref{}, l.need);
            } else if (l.need) {
                emit(Op::mov, l.value, konst(kNaN));
            }
            l.breaks.push_back(emit_jump(Op::jmp));
            return need ? konst(kNaN) : Ref{};
        }
        case NK::cont:
            if (!loops_.empty()) loops_.back().continues.push_back(emit_jump(Op::jmp));
            return need ? konst(kNaN) : Ref{};
        case NK::ret: {
            if (frame_ < 0) {
                for (const NodePtr& k : n.kids) gen(*k, {}, false);
                emit(Op::halt);
            } else {
                // The first value is the function's result (NaN for `return [];`).
                const Ref result = fn_result();
                if (n.kids.empty() || n.kids[0]->kind == NK::str)
                    emit(Op::mov, result, konst(kNaN));
                else
                    gen(*n.kids[0], result);
                for (std::size_t i = 1; i < n.kids.size(); ++i) gen(*n.kids[i], {}, false);
                returns_.push_back(emit_jump(Op::jmp));
            }
            return need ? konst(kNaN) : Ref{};
        }
        case NK::block:
            return gen_block(n, dst, need);
        case NK::var_decl: {
            slot_[n.ref] = static_cast<int>(alloc(1));
            ++locals_;
            const Ref r = var_ref(n.ref);
            if (n.op == 1) return r;
            if (n.kids.empty() || !n.kids[0])
                emit(Op::mov, r, konst(0.0));
            else
                gen(*n.kids[0], r);
            return r;
        }
        case NK::vec_decl:
            return gen_vec_decl(n);
        case NK::switch_:
        case NK::mswitch:
            return gen_switch(n, dst, need);
        case NK::null:
            return konst(kNaN);
        }
        return konst(kNaN);
    }

    // Evaluates arguments left to right; a variable operand is copied first when a later
    // argument has side effects, so it is read where ExprTk reads it.
    std::vector<Ref> gen_args(const std::vector<NodePtr>& kids) {
        return gen_args(kids.begin(), kids.end());
    }
    std::vector<Ref> gen_args(std::vector<NodePtr>::const_iterator b,
                              std::vector<NodePtr>::const_iterator e) {
        std::vector<Ref> refs;
        for (auto it = b; it != e; ++it) {
            if (has_side_effects(**it)) {
                for (Ref& r : refs) {
                    if (r.is_variable()) {
                        const Ref t = temp();
                        emit(Op::mov, t, r);
                        r = t;
                    }
                }
            }
            refs.push_back(gen(**it));
        }
        return refs;
    }

    // Arguments evaluated into consecutive temporaries (host and `function` calls).
    Ref gen_arg_block(const std::vector<NodePtr>& kids) {
        if (kids.empty()) return {};
        const std::uint32_t base = alloc(static_cast<std::uint32_t>(kids.size()));
        for (std::size_t i = 0; i < kids.size(); ++i) {
            Ref slot{Ref::mem, base + static_cast<std::uint32_t>(i)};
            slot.temp = true;
            gen(*kids[i], slot);
        }
        Ref r{Ref::mem, base};
        r.temp = true;
        return r;
    }

    Ref gen_binary(const Node& n, Ref dst) {
        const auto op = static_cast<BinOp>(n.op);
        if (op == BinOp::scand || op == BinOp::scor) {
            // `&`: 0 without evaluating the right side when the left is false; `|` likewise.
            const Ref d = to(dst);
            const Ref a = gen(*n.kids[0]);
            const std::size_t skip = emit_jump(op == BinOp::scand ? Op::jz : Op::jnz, a);
            const Ref b = gen(*n.kids[1]);
            emit(Op::truth, d, b);
            const std::size_t end = emit_jump(Op::jmp);
            patch(skip, here());
            emit(Op::mov, d, konst(op == BinOp::scand ? 0.0 : 1.0));
            patch(end, here());
            return d;
        }
        const std::vector<Ref> args = gen_args(n.kids);
        const Ref d = to(dst);
        emit_binary(op, d, args[0], args[1], is_literal(*n.kids[1]));
        return d;
    }
    // A number written in the source (or computed from such numbers), not a constant `var`.
    static bool is_literal(const Node& n) { return n.kind == NK::num && !n.from_var; }

    // `a op b`; a power with a literal exponent is strength-reduced: integers as ExprTk does
    // (int_pow, bit for bit with ECMC), 0.5 to a square root (pow_half). ExprTk computes a
    // power of a `var` exponent with pow, so one from a constant `var` stays pow here too.
    void emit_binary(BinOp op, Ref d, Ref a, Ref b, bool literal_b) {
        if (op == BinOp::pow && literal_b && b.kind == Ref::konst) {
            const double c = consts_[b.index];
            if (is_int_pow_exponent(c)) {
                const auto p = static_cast<std::uint32_t>(std::fabs(c));
                if (p == 0)
                    emit(Op::mov, d, konst(1.0));
                else if (c < 0)
                    emit(Op::powi_inv, d, a).n = p;
                else if (p == 1)
                    emit(Op::mov, d, a);
                else if (p == 2)
                    emit(Op::sqr, d, a);
                else
                    emit(Op::powi, d, a).n = p;
                return;
            }
            if (c == 0.5) {
                emit(Op::pow_half, d, a);
                return;
            }
        }
        emit(binary_op(op), d, a, b);
    }

    // ---- places (assignment targets) ----------------------------------------------------------

    Place place(const Node& n) {
        Place p;
        if (n.kind == NK::var) {
            p.ref = var_ref(n.ref);
            return p;
        }
        // element
        const Variable& v = unit_.vars[n.ref];
        const Node& idx = *n.kids[0];
        // A constant index is checked by the parser when written as a number; one from a
        // constant `var` (plc/optimize) may be out of range: checked at run time, as before.
        if (idx.kind == NK::num && idx.num >= 0 && idx.num < v.size) {
            p.ref = var_ref(n.ref, static_cast<std::uint32_t>(idx.num));
            return p;
        }
        p.dynamic = true;
        p.ref = var_ref(n.ref);
        p.index = gen(idx);
        p.size = static_cast<std::uint32_t>(v.size);
        return p;
    }
    Ref load(const Place& p, Ref dst = {}) {
        if (!p.dynamic) return p.ref;
        const Ref d = to(dst);
        PInsn& i = emit(Op::load, d, p.ref, p.index);
        i.n = p.size;
        return d;
    }
    void store(const Place& p, Ref value) {
        if (!p.dynamic) {
            if (!(value == p.ref)) emit(Op::mov, p.ref, value);
            return;
        }
        PInsn& i = emit(Op::store, {}, p.ref, p.index);
        i.c = value;
        i.n = p.size;
    }
    Ref snapshot(Ref r) {
        if (!r.is_variable()) return r;
        const Ref t = temp();
        emit(Op::mov, t, r);
        return t;
    }

    Ref gen_assign(const Node& n) {
        const Node& target = *n.kids[0];
        const Node& value = *n.kids[1];
        const auto aop = static_cast<Assign>(n.op);
        if (target.kind == NK::vec) return gen_vector_assign(n);
        Place p = place(target);
        if (p.dynamic && has_side_effects(value)) p.index = snapshot(p.index);
        if (aop == Assign::set) {
            if (!p.dynamic && writes_once(value)) return gen(value, p.ref);
            const Ref v = gen(value);
            store(p, v);
            return p.dynamic ? v : p.ref;
        }
        const Ref v = gen(value);
        if (!p.dynamic) {
            emit(assign_op(aop), p.ref, p.ref, v);
            return p.ref;
        }
        const Ref t = load(p);
        emit(assign_op(aop), t, t, v);
        store(p, t);
        return t;
    }

    Ref gen_swap(const Node& n) {
        const Place x = place(*n.kids[0]);
        const Place y = place(*n.kids[1]);
        if (!x.dynamic && !y.dynamic) {
            emit(Op::swap, x.ref, y.ref);
            return y.ref;
        }
        const Ref tx = snapshot(load(x));
        const Ref ty = snapshot(load(y));
        store(x, ty);
        store(y, tx);
        return tx;
    }

    // ---- vectors ------------------------------------------------------------------------------

    // Scalar parts of a vector expression are evaluated once, before the element loop.
    void hoist(const Node& n, std::map<const Node*, Ref>& scalars) {
        if (!is_vector_expr(n)) {
            scalars[&n] = gen(n);
            return;
        }
        for (const NodePtr& k : n.kids) hoist(*k, scalars);
    }

    // Element `i` of a vector expression.
    Ref gen_elem(const Node& n, const Index& i, const std::map<const Node*, Ref>& scalars) {
        if (auto it = scalars.find(&n); it != scalars.end()) return it->second;
        switch (n.kind) {
        case NK::vec: {
            if (i.constant) return var_ref(n.ref, i.value);
            const Ref t = temp();
            emit(Op::load, t, var_ref(n.ref), i.ref).n =
                static_cast<std::uint32_t>(unit_.vars[n.ref].size);
            return t;
        }
        case NK::neg:
        case NK::lnot: {
            const Ref a = gen_elem(*n.kids[0], i, scalars);
            const Ref t = temp();
            emit(n.kind == NK::neg ? Op::neg : Op::lnot, t, a);
            return t;
        }
        case NK::binary: {
            const Ref a = gen_elem(*n.kids[0], i, scalars);
            const Ref b = gen_elem(*n.kids[1], i, scalars);
            const Ref t = temp();
            emit_binary(static_cast<BinOp>(n.op), t, a, b, is_literal(*n.kids[1]));
            return t;
        }
        case NK::builtin: {
            Ref args[3];
            for (std::size_t k = 0; k < n.kids.size(); ++k)
                args[k] = gen_elem(*n.kids[k], i, scalars);
            const Ref t = temp();
            PInsn& p = emit(n.builtin->arity == 1   ? Op::fn1
                            : n.builtin->arity == 2 ? Op::fn2
                                                    : Op::fn3,
                            t, args[0], args[1]);
            p.c = args[2];
            p.f1 = n.builtin->f1;
            p.f2 = n.builtin->f2;
            p.f3 = n.builtin->f3;
            return t;
        }
        default:
            return gen(n);
        }
    }

    // Calls body(i) for i in [first, count): unrolled for small vectors, else a counted loop.
    template <typename F>
    void for_each_element(std::uint32_t first, std::uint32_t count, F&& body) {
        if (count <= kUnroll) {
            for (std::uint32_t k = first; k < count; ++k) body(Index{konst(k), true, k});
            return;
        }
        const Ref i = temp();
        emit(Op::mov, i, konst(first));
        const std::uint32_t top = here();
        body(Index{i, false, 0});
        emit(Op::add, i, i, konst(1));
        const Ref more = temp();
        emit(Op::lt, more, i, konst(count));
        emit(Op::jnz).a = more;
        code_.back().n = top;
    }

    Ref gen_vector_assign(const Node& n) {
        const Node& target = *n.kids[0];
        const Node& value = *n.kids[1];
        const auto aop = static_cast<Assign>(n.op);
        const Variable& v = unit_.vars[target.ref];
        const Ref base = var_ref(target.ref);
        const std::uint32_t size = static_cast<std::uint32_t>(v.size);
        if (!is_vector_expr(value)) {
            const Ref s = snapshot(gen(value));
            if (aop == Assign::set) {
                emit(Op::fill, base, s).n = size;
            } else {
                for_each_element(0, size, [&](const Index& i) {
                    const Place p = element(target.ref, i);
                    const Ref t = load(p);
                    const Ref r = temp();
                    emit(assign_op(aop), r, t, s);
                    store(p, r);
                });
            }
            return base;
        }
        std::map<const Node*, Ref> scalars;
        hoist(value, scalars);
        const auto count =
            static_cast<std::uint32_t>(std::min<int>(v.size, vector_expr_size(value, unit_)));
        for_each_element(0, count, [&](const Index& i) {
            const Ref x = gen_elem(value, i, scalars);
            const Place p = element(target.ref, i);
            if (aop == Assign::set) {
                store(p, x);
            } else {
                const Ref t = load(p);
                const Ref r = temp();
                emit(assign_op(aop), r, t, x);
                store(p, r);
            }
        });
        return base;
    }

    Place element(int var, const Index& i) {
        Place p;
        if (i.constant) {
            p.ref = var_ref(var, i.value);
            return p;
        }
        p.dynamic = true;
        p.ref = var_ref(var);
        p.index = i.ref;
        p.size = static_cast<std::uint32_t>(unit_.vars[var].size);
        return p;
    }

    Ref gen_vec_decl(const Node& n) {
        const Variable& v = unit_.vars[n.ref];
        const auto size = static_cast<std::uint32_t>(v.size);
        slot_[n.ref] = static_cast<int>(alloc(size));
        ++locals_;
        const Ref base = var_ref(n.ref);
        std::uint32_t filled = 0;
        switch (static_cast<VecInit>(n.op)) {
        case VecInit::none:
            return base;
        case VecInit::zero:
            break;
        case VecInit::list:
            for (const NodePtr& k : n.kids) gen(*k, var_ref(n.ref, filled++));
            break;
        case VecInit::single: {
            const Ref s = gen(*n.kids[0]);
            emit(Op::fill, base, s).n = size;
            return base;
        }
        case VecInit::vector: {
            std::map<const Node*, Ref> scalars;
            hoist(*n.kids[0], scalars);
            filled = static_cast<std::uint32_t>(
                std::min<int>(v.size, vector_expr_size(*n.kids[0], unit_)));
            for_each_element(0, filled, [&](const Index& i) {
                store(element(n.ref, i), gen_elem(*n.kids[0], i, scalars));
            });
            break;
        }
        }
        if (filled < size) emit(Op::fill, var_ref(n.ref, filled), konst(0.0)).n = size - filled;
        return base;
    }

    Ref gen_aggregate(const Node& n, Ref dst) {
        const auto agg = static_cast<Aggregate>(n.op);
        if (agg == Aggregate::mand || agg == Aggregate::mor) {
            // Left to right; stops at the first false (mand) or true (mor) argument.
            const Ref d = to(dst);
            std::vector<std::size_t> exits;
            for (const NodePtr& k : n.kids)
                exits.push_back(emit_jump(agg == Aggregate::mand ? Op::jz : Op::jnz, gen(*k)));
            emit(Op::mov, d, konst(agg == Aggregate::mand ? 1.0 : 0.0));
            const std::size_t end = emit_jump(Op::jmp);
            for (std::size_t j : exits) patch(j, here());
            emit(Op::mov, d, konst(agg == Aggregate::mand ? 0.0 : 1.0));
            patch(end, here());
            return d;
        }
        if (n.kids.size() == 1 && is_vector_expr(*n.kids[0]))
            return gen_vector_aggregate(n, agg, dst);
        const std::vector<Ref> args = gen_args(n.kids);
        if (args.size() == 1) return args[0];
        const Ref d = to(dst);
        if (args.size() == 2 && (agg == Aggregate::min || agg == Aggregate::max)) {
            emit(agg == Aggregate::min ? Op::fmin2 : Op::fmax2, d, args[0], args[1]);
            return d;
        }
        Op op = Op::list_sum;
        switch (agg) {
        case Aggregate::mul:
            op = Op::list_mul;
            break;
        case Aggregate::min:
            op = Op::list_min;
            break;
        case Aggregate::max:
            op = Op::list_max;
            break;
        default:
            break;
        }
        PInsn& p = emit(op, d, {});
        p.n = static_cast<std::uint32_t>(args.size());
        p.list = static_cast<int>(lists_.size());
        lists_.push_back(args);
        if (agg == Aggregate::avg) emit(Op::div, d, d, konst(static_cast<double>(args.size())));
        return d;
    }

    Ref gen_vector_aggregate(const Node& n, Aggregate agg, Ref dst) {
        const Node& x = *n.kids[0];
        const Ref d = to(dst);
        const std::uint32_t size = static_cast<std::uint32_t>(vector_expr_size(x, unit_));
        if (x.kind == NK::vec) {
            Op op = Op::vec_sum;
            if (agg == Aggregate::mul) op = Op::vec_mul;
            if (agg == Aggregate::min) op = Op::vec_min;
            if (agg == Aggregate::max) op = Op::vec_max;
            emit(op, d, var_ref(x.ref)).n = size;
        } else {
            std::map<const Node*, Ref> scalars;
            hoist(x, scalars);
            const Ref acc = temp();
            emit(Op::mov, acc, gen_elem(x, Index{konst(0), true, 0}, scalars));
            for_each_element(1, size, [&](const Index& i) {
                const Ref e = gen_elem(x, i, scalars);
                switch (agg) {
                case Aggregate::mul:
                    emit(Op::mul, acc, acc, e);
                    break;
                case Aggregate::min:
                    emit(Op::fn2, acc, acc, e).f2 = min2;
                    break;
                case Aggregate::max:
                    emit(Op::fn2, acc, acc, e).f2 = max2;
                    break;
                default:
                    emit(Op::add, acc, acc, e);
                    break;
                }
            });
            emit(Op::mov, d, acc);
        }
        if (agg == Aggregate::avg) emit(Op::div, d, d, konst(static_cast<double>(size)));
        return d;
    }

    Ref gen_print(const Node& n, Ref dst, bool need) {
        // ExprTk evaluates every argument before printing any.
        std::vector<Ref> values;
        for (const NodePtr& k : n.kids)
            values.push_back(k->kind == NK::str || k->kind == NK::vec ? Ref{} : snapshot(gen(*k)));
        emit(Op::print_begin);
        for (std::size_t i = 0; i < n.kids.size(); ++i) {
            const Node& k = *n.kids[i];
            if (k.kind == NK::str) {
                emit(Op::print_str).n = static_cast<std::uint32_t>(strings_.size());
                strings_.push_back(k.str);
            } else if (k.kind == NK::vec) {
                emit(Op::print_vec, {}, var_ref(k.ref)).n =
                    static_cast<std::uint32_t>(unit_.vars[k.ref].size);
            } else {
                emit(Op::print_num, {}, values[i]);
            }
        }
        emit(Op::print_end).n = n.op;
        return need ? finish(konst(0.0), dst) : Ref{};
    }

    // ---- control flow -------------------------------------------------------------------------

    Ref gen_cond(const Node& n, Ref dst, bool need) {
        const Node* yes = n.kids[1].get();
        const Node* no = n.kids.size() > 2 ? n.kids[2].get() : nullptr;
        if (n.kids[0]->kind == NK::num) { // constant condition: only the branch taken
            const Node* taken = is_true(n.kids[0]->num) ? yes : no;
            if (taken) return gen(*taken, dst, need);
            return need ? konst(kNaN) : Ref{};
        }
        const std::size_t skip = emit_jump_unless(*n.kids[0]);
        const Ref d = need ? to(dst) : Ref{};
        gen(*yes, d, need);
        if (no || need) {
            const std::size_t end = emit_jump(Op::jmp);
            patch(skip, here());
            if (no)
                gen(*no, d, need);
            else
                emit(Op::mov, d, konst(kNaN));
            patch(end, here());
        } else {
            patch(skip, here());
        }
        return d;
    }

    Ref gen_loop(const Node& n, Ref dst, bool need) {
        const Ref d = need ? to(dst) : Ref{};
        if (need) emit(Op::mov, d, konst(kNaN));
        const Node* cond = nullptr;
        const Node* body = nullptr;
        const Node* inc = nullptr;
        if (n.kind == NK::loop_while) {
            cond = n.kids[0].get();
            body = n.kids[1].get();
        } else if (n.kind == NK::loop_for) {
            if (n.kids[0]) gen(*n.kids[0], {}, false);
            cond = n.kids[1].get();
            inc = n.kids[2].get();
            body = n.kids[3].get();
        } else {
            body = n.kids[0].get();
        }
        if (cond && cond->kind == NK::num && !is_true(cond->num)) return d; // never runs
        loops_.push_back(Loop{d, need, {}, {}});
        const std::uint32_t top = here();
        std::size_t exit = SIZE_MAX;
        if (cond && cond->kind != NK::num) exit = emit_jump_unless(*cond);
        gen(*body, d, need);
        const std::uint32_t cont = here();
        if (inc) gen(*inc, {}, false);
        if (n.kind == NK::loop_repeat) {
            const Node& until = *n.kids[1];
            if (until.kind == NK::num) {
                if (is_true(until.num)) exit = emit_jump(Op::jmp);
            } else {
                exit = emit_jump(Op::jnz, gen(until));
            }
        }
        emit(Op::loop).n = top;
        const std::uint32_t end = here();
        if (exit != SIZE_MAX) patch(exit, end);
        Loop l = std::move(loops_.back());
        loops_.pop_back();
        for (std::size_t j : l.breaks) patch(j, end);
        for (std::size_t j : l.continues) patch(j, cont);
        return d;
    }

    Ref gen_block(const Node& n, Ref dst, bool need) {
        if (n.kids.empty()) return need ? konst(kNaN) : Ref{};
        for (std::size_t i = 0; i < n.kids.size(); ++i) {
            const bool last = i + 1 == n.kids.size();
            const std::uint32_t mark = next_slot_;
            const int locals = locals_;
            if (last) return gen(*n.kids[i], dst, need);
            gen(*n.kids[i], {}, false);
            // Temporaries of a statement are reused by the next one (locals are kept).
            if (locals == locals_) next_slot_ = mark;
        }
        return {};
    }

    Ref gen_switch(const Node& n, Ref dst, bool need) {
        const bool multi = n.kind == NK::mswitch;
        const bool has_default = !multi && n.op == 1;
        const std::size_t cases = (n.kids.size() - (has_default ? 1 : 0)) / 2;
        const Ref d = need ? to(dst) : Ref{};
        if (need && multi) emit(Op::mov, d, konst(0.0));
        std::vector<std::size_t> ends;
        for (std::size_t c = 0; c < cases; ++c) {
            const std::size_t skip = emit_jump(Op::jz, gen(*n.kids[2 * c]));
            gen(*n.kids[2 * c + 1], d, need);
            if (!multi) ends.push_back(emit_jump(Op::jmp));
            patch(skip, here());
        }
        if (has_default)
            gen(*n.kids.back(), d, need);
        else if (need && !multi)
            emit(Op::mov, d, konst(kNaN));
        for (std::size_t j : ends) patch(j, here());
        return d;
    }

    Ref fn_result() { return Ref{Ref::mem, fn_result_slot_[frame_]}; }

    struct Loop {
        Ref value;
        bool need = false;
        std::vector<std::size_t> breaks, continues;
    };

    const Unit& unit_;
    const Source& src_;
    const CompileOptions& options_;
    Diagnostics& diags_;
    std::vector<int> slot_;
    std::vector<PInsn> code_;
    std::vector<double> consts_;
    std::map<std::uint64_t, std::uint32_t> const_index_;
    std::vector<std::vector<Ref>> lists_;
    std::vector<std::string> strings_;
    std::vector<Loop> loops_;
    std::vector<std::size_t> returns_;
    std::vector<std::uint32_t> fn_result_slot_;
    std::uint32_t next_slot_ = 0, high_ = 0;
    int locals_ = 0;
    bool memo_on_ = false;             // generating a pure expression (common subexpressions)
    const Node* memo_root_ = nullptr;
    std::map<std::string, Ref> memo_;  // structural key -> temporary holding its value
    int frame_ = -1;
    Pos pos_;
};

} // namespace

std::unique_ptr<Program::Impl> generate(const Unit& unit, const Source& src, Host& host,
                                        const CompileOptions& options, Diagnostics& diags) {
    Compiler c(unit, src, options, diags);
    return c.run(host);
}

} // namespace beamctl::plc::detail
