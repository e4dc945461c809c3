#include "plc/program.hpp"

#include "plc/code.hpp"
#include "plc/compiler.hpp"
#include "plc/lexer.hpp"
#include "plc/optimize.hpp"
#include "plc/parser.hpp"
#include "plc/source.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace beamctl::plc {

using detail::Op;

const char* to_string(RunStatus status) noexcept {
    switch (status) {
    case RunStatus::ok:
        return "ok";
    case RunStatus::index_out_of_range:
        return "vector index out of range";
    case RunStatus::loop_budget_exceeded:
        return "loop iteration budget exceeded";
    case RunStatus::call_depth_exceeded:
        return "function calls nested too deep";
    }
    return "unknown run status";
}

CompileError::CompileError(std::vector<std::string> errors)
    : Error(errors.empty() ? std::string("compile error") : errors.front())
    , errors_(std::move(errors)) {}

namespace detail {

const char* to_string(Op op) {
    switch (op) {
    case Op::halt:
        return "halt";
    case Op::mov:
        return "mov";
    case Op::neg:
        return "neg";
    case Op::lnot:
        return "not";
    case Op::truth:
        return "truth";
    case Op::add:
        return "add";
    case Op::sub:
        return "sub";
    case Op::mul:
        return "mul";
    case Op::div:
        return "div";
    case Op::mod:
        return "mod";
    case Op::pow:
        return "pow";
    case Op::sqr:
        return "sqr";
    case Op::powi:
        return "powi";
    case Op::powi_inv:
        return "powi_inv";
    case Op::pow_half:
        return "pow_half";
    case Op::fabs:
        return "abs";
    case Op::fsqrt:
        return "sqrt";
    case Op::fmin2:
        return "min2";
    case Op::fmax2:
        return "max2";
    case Op::jf_lt:
        return "jf_lt";
    case Op::jf_le:
        return "jf_le";
    case Op::jf_gt:
        return "jf_gt";
    case Op::jf_ge:
        return "jf_ge";
    case Op::jf_eq:
        return "jf_eq";
    case Op::jf_ne:
        return "jf_ne";
    case Op::lt:
        return "lt";
    case Op::le:
        return "le";
    case Op::gt:
        return "gt";
    case Op::ge:
        return "ge";
    case Op::eq:
        return "eq";
    case Op::ne:
        return "ne";
    case Op::land:
        return "and";
    case Op::lor:
        return "or";
    case Op::lnand:
        return "nand";
    case Op::lnor:
        return "nor";
    case Op::lxor:
        return "xor";
    case Op::lxnor:
        return "xnor";
    case Op::fn1:
        return "fn1";
    case Op::fn2:
        return "fn2";
    case Op::fn3:
        return "fn3";
    case Op::jmp:
        return "jmp";
    case Op::jz:
        return "jz";
    case Op::jnz:
        return "jnz";
    case Op::loop:
        return "loop";
    case Op::load:
        return "load";
    case Op::store:
        return "store";
    case Op::fill:
        return "fill";
    case Op::list_sum:
        return "list_sum";
    case Op::list_mul:
        return "list_mul";
    case Op::list_min:
        return "list_min";
    case Op::list_max:
        return "list_max";
    case Op::vec_sum:
        return "vec_sum";
    case Op::vec_mul:
        return "vec_mul";
    case Op::vec_min:
        return "vec_min";
    case Op::vec_max:
        return "vec_max";
    case Op::dot:
        return "dot";
    case Op::dot_range:
        return "dot_range";
    case Op::host_call:
        return "host_call";
    case Op::call:
        return "call";
    case Op::ret:
        return "ret";
    case Op::print_begin:
        return "print_begin";
    case Op::print_str:
        return "print_str";
    case Op::print_num:
        return "print_num";
    case Op::print_vec:
        return "print_vec";
    case Op::print_end:
        return "print_end";
    case Op::swap:
        return "swap";
    }
    return "?";
}

} // namespace detail

// ---- compile --------------------------------------------------------------------------------

Program::Program(std::unique_ptr<Impl> impl)
    : impl_(std::move(impl)) {}
Program::Program(Program&&) noexcept = default;
Program& Program::operator=(Program&&) noexcept = default;
Program::~Program() = default;

Program Program::compile(std::string_view text, const std::string& filename, Host& host,
                         const CompileOptions& options) {
    detail::Diagnostics diags(options.max_errors);
    detail::Source src;
    std::unique_ptr<Impl> impl;
    try {
        std::vector<std::pair<int, int>> lib_lines;
        for (const std::string& lib : options.libraries) {
            const std::string lib_text = detail::read_file(lib);
            MacroMap macros = options.macros;
            const int first = static_cast<int>(src.lines.size());
            detail::preprocess(src, lib_text, lib, macros, options.include_path, diags);
            lib_lines.emplace_back(first, static_cast<int>(src.lines.size()));
        }
        MacroMap macros = options.macros;
        const int first = static_cast<int>(src.lines.size());
        detail::Embedding at;
        const SourceLoc& o = options.origin;
        if (o.line > 0) {
            at.line_base = o.line - 1;
            at.first_col_base = o.col - 1;
            at.col_base = options.origin_block ? o.col - 1 : 0;
            at.label = options.origin_label;
        }
        detail::preprocess(src, text, o.line > 0 ? o.file : filename, macros, options.include_path, diags, at);
        const int last = static_cast<int>(src.lines.size());
        if (diags.empty()) {
            std::vector<std::vector<detail::Token>> libs;
            for (const auto& [b, e] : lib_lines)
                libs.push_back(detail::lex(src, b, e, false, diags));
            const std::vector<detail::Token> program = detail::lex(src, first, last, true, diags);
            detail::Unit unit = detail::parse(src, program, libs, host, diags, options.strict);
            if (diags.empty()) {
                detail::propagate_constants(unit);
                impl = detail::generate(unit, src, host, options, diags);
            }
        }
    } catch (const detail::Diagnostics::Abort&) {
    }
    if (!diags.empty()) throw CompileError(diags.messages());
    return Program(std::move(impl));
}

Program Program::compile_file(const std::string& path, Host& host, const CompileOptions& options) {
    const std::string text = detail::read_file(path);
    return compile(text, path, host, options);
}

// ---- run ------------------------------------------------------------------------------------

int Program::run() noexcept {
    return impl_->run();
}

void Program::set_loop_budget(std::uint64_t iterations) noexcept {
    impl_->loop_budget = iterations;
}

std::size_t Program::size() const noexcept {
    return impl_->code.size();
}

std::string Program::fault_location() const {
    if (impl_->fault_pc < 0) return {};
    return impl_->locations[static_cast<std::size_t>(impl_->fault_pc)] + ": " +
           to_string(impl_->fault);
}

int Program::fault_index() const noexcept {
    return impl_->fault_pc;
}

std::string Program::location(int index) const {
    if (index < 0 || static_cast<std::size_t>(index) >= impl_->locations.size()) return {};
    return impl_->locations[static_cast<std::size_t>(index)];
}

void Program::Impl::reset_calls() noexcept {
    for (detail::FunctionCode& f : functions) f.active = 0;
    save_top = 0;
    return_top = 0;
}

namespace {

// Appends to the print buffer, keeping one byte for println's newline.
struct PrintSink {
    char* buf;
    std::size_t cap; // usable bytes (buffer size - 1)
    std::size_t& len;

    void text(const std::string& s) noexcept {
        const std::size_t n = std::min(s.size(), cap - len);
        std::copy(s.data(), s.data() + n, buf + len);
        len += n;
    }
    void number(double v) noexcept {
        if (len >= cap) return;
        const int k = std::snprintf(buf + len, cap - len + 1, "%10.5f", v);
        if (k > 0) len = std::min(len + static_cast<std::size_t>(k), cap);
    }
};

} // namespace

int Program::Impl::run() noexcept {
    using namespace detail;
    const Insn* const prog = code.data();
    std::uint32_t pc = 0;
    std::uint64_t budget =
        loop_budget != 0 ? loop_budget : std::numeric_limits<std::uint64_t>::max();
    fault_pc = -1;
    fault = RunStatus::ok;
    auto stop = [&](RunStatus s) noexcept {
        fault_pc = static_cast<int>(pc);
        fault = s;
        reset_calls();
        return static_cast<int>(s);
    };
    auto index_ok = [](double i, std::uint32_t n) noexcept { return i >= 0 && i < n; };

    for (;;) {
        const Insn& in = prog[pc];
        switch (in.op) {
        case Op::halt:
            return 0;
        case Op::mov:
            *in.d = *in.a;
            break;
        case Op::neg:
            *in.d = -*in.a;
            break;
        case Op::lnot:
            *in.d = logical_not(*in.a);
            break;
        case Op::truth:
            *in.d = from_bool(is_true(*in.a));
            break;
        case Op::add:
            *in.d = *in.a + *in.b;
            break;
        case Op::sub:
            *in.d = *in.a - *in.b;
            break;
        case Op::mul:
            *in.d = *in.a * *in.b;
            break;
        case Op::div:
            *in.d = *in.a / *in.b;
            break;
        case Op::mod:
            *in.d = std::fmod(*in.a, *in.b);
            break;
        case Op::pow:
            *in.d = std::pow(*in.a, *in.b);
            break;
        case Op::sqr:
            *in.d = *in.a * *in.a;
            break;
        case Op::powi:
            *in.d = int_pow(*in.a, in.n);
            break;
        case Op::powi_inv:
            *in.d = 1.0 / int_pow(*in.a, in.n);
            break;
        case Op::pow_half:
            *in.d = pow_half(*in.a);
            break;
        case Op::fabs:
            *in.d = *in.a < 0 ? -*in.a : *in.a;
            break;
        case Op::fsqrt:
            *in.d = std::sqrt(*in.a);
            break;
        case Op::fmin2:
            *in.d = min2(*in.a, *in.b);
            break;
        case Op::fmax2:
            *in.d = max2(*in.a, *in.b);
            break;
        // a comparison that is false (NaN included) jumps
        case Op::jf_lt:
            if (!(*in.a < *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jf_le:
            if (!(*in.a <= *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jf_gt:
            if (!(*in.a > *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jf_ge:
            if (!(*in.a >= *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jf_eq:
            if (!(*in.a == *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jf_ne:
            if (!(*in.a != *in.b)) {
                pc = in.n;
                continue;
            }
            break;
        case Op::lt:
            *in.d = from_bool(*in.a < *in.b);
            break;
        case Op::le:
            *in.d = from_bool(*in.a <= *in.b);
            break;
        case Op::gt:
            *in.d = from_bool(*in.a > *in.b);
            break;
        case Op::ge:
            *in.d = from_bool(*in.a >= *in.b);
            break;
        case Op::eq:
            *in.d = from_bool(*in.a == *in.b);
            break;
        case Op::ne:
            *in.d = from_bool(*in.a != *in.b);
            break;
        case Op::land:
            *in.d = from_bool(is_true(*in.a) && is_true(*in.b));
            break;
        case Op::lor:
            *in.d = from_bool(is_true(*in.a) || is_true(*in.b));
            break;
        case Op::lnand:
            *in.d = from_bool(!(is_true(*in.a) && is_true(*in.b)));
            break;
        case Op::lnor:
            *in.d = from_bool(!(is_true(*in.a) || is_true(*in.b)));
            break;
        case Op::lxor:
            *in.d = from_bool(is_true(*in.a) != is_true(*in.b));
            break;
        case Op::lxnor:
            *in.d = from_bool(is_true(*in.a) == is_true(*in.b));
            break;
        case Op::fn1:
            *in.d = in.x.f1(*in.a);
            break;
        case Op::fn2:
            *in.d = in.x.f2(*in.a, *in.b);
            break;
        case Op::fn3:
            *in.d = in.x.f3(*in.a, *in.b, *in.c);
            break;
        case Op::jmp:
            pc = in.n;
            continue;
        case Op::jz:
            if (*in.a == 0.0) {
                pc = in.n;
                continue;
            }
            break;
        case Op::jnz:
            if (*in.a != 0.0) {
                pc = in.n;
                continue;
            }
            break;
        case Op::loop:
            if (budget-- == 0) return stop(RunStatus::loop_budget_exceeded);
            pc = in.n;
            continue;
        case Op::load: {
            const double i = *in.b;
            if (!index_ok(i, in.n)) return stop(RunStatus::index_out_of_range);
            *in.d = in.a[static_cast<std::size_t>(i)];
            break;
        }
        case Op::store: {
            const double i = *in.b;
            if (!index_ok(i, in.n)) return stop(RunStatus::index_out_of_range);
            in.a[static_cast<std::size_t>(i)] = *in.c;
            break;
        }
        case Op::fill: {
            const double v = *in.a;
            for (std::uint32_t k = 0; k < in.n; ++k) in.d[k] = v;
            break;
        }
        case Op::list_sum: {
            double s = *in.x.list[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s += *in.x.list[k];
            *in.d = s;
            break;
        }
        case Op::list_mul: {
            double s = *in.x.list[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s *= *in.x.list[k];
            *in.d = s;
            break;
        }
        case Op::list_min:
        case Op::list_max:
            *in.d = min_max(in.op == Op::list_max, in.n,
                            [&](std::size_t k) noexcept { return *in.x.list[k]; });
            break;
        case Op::vec_sum: {
            double s = in.a[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s += in.a[k];
            *in.d = s;
            break;
        }
        case Op::vec_mul: {
            double s = in.a[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s *= in.a[k];
            *in.d = s;
            break;
        }
        case Op::vec_min: {
            double s = in.a[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s = min2(s, in.a[k]);
            *in.d = s;
            break;
        }
        case Op::vec_max: {
            double s = in.a[0];
            for (std::uint32_t k = 1; k < in.n; ++k) s = max2(s, in.a[k]);
            *in.d = s;
            break;
        }
        case Op::dot: {
            double s = 0;
            for (std::uint32_t k = 0; k < in.n; ++k) s += in.a[k] * in.b[k];
            *in.d = s;
            break;
        }
        case Op::dot_range: {
            const double r0 = std::trunc(*in.c), r1 = std::trunc(*in.e);
            if (!(r0 >= 0 && r0 <= r1 && r1 < in.n)) {
                *in.d = std::numeric_limits<double>::quiet_NaN();
                break;
            }
            double s = 0;
            for (auto k = static_cast<std::uint32_t>(r0); k <= static_cast<std::uint32_t>(r1); ++k)
                s += in.a[k] * in.b[k];
            *in.d = s;
            break;
        }
        case Op::host_call:
            *in.d = in.x.host(in.ctx, in.a, static_cast<int>(in.n));
            break;
        case Op::call: {
            FunctionCode& f = functions[in.n];
            if (return_top == returns.size()) return stop(RunStatus::call_depth_exceeded);
            bool saved = false;
            if (f.active > 0) { // recursion: keep the running call's frame
                if (save_top + f.size > save.size()) return stop(RunStatus::call_depth_exceeded);
                std::copy(f.frame, f.frame + f.size, save.data() + save_top);
                save_top += f.size;
                saved = true;
            }
            for (std::uint32_t k = 0; k < f.params; ++k) f.frame[k] = in.a[k];
            returns[return_top++] = ReturnRecord{pc, saved};
            ++f.active;
            pc = f.entry;
            continue;
        }
        case Op::ret: {
            FunctionCode& f = functions[in.n];
            const ReturnRecord r = returns[--return_top];
            --f.active;
            const double result = *f.result;
            if (r.saved) {
                save_top -= f.size;
                std::copy(save.data() + save_top, save.data() + save_top + f.size, f.frame);
            }
            *prog[r.call_pc].d = result;
            pc = r.call_pc + 1;
            continue;
        }
        case Op::print_begin:
            print_length = 0;
            break;
        case Op::print_str:
            PrintSink{print_buffer.data(), print_buffer.size() - 1, print_length}.text(
                strings[in.n]);
            break;
        case Op::print_num:
            PrintSink{print_buffer.data(), print_buffer.size() - 1, print_length}.number(*in.a);
            break;
        case Op::print_vec: {
            PrintSink sink{print_buffer.data(), print_buffer.size() - 1, print_length};
            for (std::uint32_t k = 0; k < in.n; ++k) {
                sink.number(in.a[k]);
                if (k + 1 < in.n && print_length < sink.cap) print_buffer[print_length++] = ' ';
            }
            break;
        }
        case Op::print_end:
            if (in.n != 0) print_buffer[print_length++] = '\n';
            host->print(std::string_view(print_buffer.data(), print_length));
            break;
        case Op::swap:
            std::swap(*in.d, *in.a);
            break;
        }
        ++pc;
    }
}

// ---- disassembly ----------------------------------------------------------------------------

std::string Program::disassemble() const {
    const Impl& m = *impl_;
    auto name = [&](const double* p) -> std::string {
        if (!p) return "-";
        const double* mem = m.memory.data();
        if (p >= mem && p < mem + m.memory.size()) {
            const auto i = static_cast<std::size_t>(p - mem);
            if (i >= m.const_begin) return SB() << "#" << *p;
            return SB() << "m" << i;
        }
        for (const auto& h : m.host_names) {
            if (p == h.address) return h.name;
            if (p > h.address && p < h.address + h.size)
                return SB() << h.name << "[" << (p - h.address) << "]";
        }
        return "host";
    };
    SB out;
    for (std::size_t pc = 0; pc < m.code.size(); ++pc) {
        const detail::Insn& in = m.code[pc];
        out << pc << ": " << detail::to_string(in.op);
        if (in.d) out << " " << name(in.d) << " <-";
        for (const double* p : {in.a, in.b, in.c, in.e})
            if (p) out << " " << name(p);
        switch (in.op) {
        case Op::jmp:
        case Op::jz:
        case Op::jnz:
        case Op::loop:
            out << " -> " << in.n;
            break;
        case Op::print_str:
            out << " '" << m.strings[in.n] << "'";
            break;
        case Op::halt:
        case Op::mov:
        case Op::print_begin:
            break;
        default:
            if (in.n) out << " n=" << in.n;
            break;
        }
        out << "\n";
    }
    return out.str();
}

} // namespace beamctl::plc
