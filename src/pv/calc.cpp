// The EPICS calc engine: the compiler (infix -> postfix, as base's postfix.c) and the stack
// machine (as calcPerform.c), written from base 7's documented and tested behaviour.
//
// The compiler is a shunting-yard over two element tables: one searched where an operand is
// expected, one where an operator is; the longest case-insensitive name wins ("NOT" before "N").
// Each element has a priority on the operator stack and one when it arrives (equal for the
// left-associative binary operators; unary operators and '(' arrive at 8 so they never pop
// anything), and its effect on the depth of the evaluation stack, which is counted to reject
// expressions that would leave other than one value.
// Threading: see calc.hpp.
#include "pv/calc.hpp"

#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <span>

#if defined(__GLIBC__)
#include <locale.h>
#endif

namespace beamctl::pv::calc {
namespace {

// Opcodes of the postfix code.
enum Op : unsigned char {
    kEnd = 0,
    kLiteral, // followed by the 8 bytes of a double
    kFetchVal,
    kFetchA,                   // kFetchA + i fetches arg i
    kStoreA = kFetchA + kArgs, // kStoreA + i assigns arg i
    kPi = kStoreA + kArgs,
    kD2R,
    kR2D,
    kRandom,
    kNeg,
    kAdd,
    kSub,
    kMul,
    kDiv,
    kMod,
    kPow,
    kAbs,
    kExp,
    kLog10,
    kLn,
    kMax, // kMax, kMin, kFinite, kIsnan are followed by a byte: the argument count
    kMin,
    kSqrt,
    kAcos,
    kAsin,
    kAtan,
    kAtan2,
    kCos,
    kCosh,
    kSin,
    kSinh,
    kTan,
    kTanh,
    kCeil,
    kFloor,
    kFmod,
    kFinite,
    kIsinf,
    kIsnan,
    kNint,
    kOr,
    kAnd,
    kNot,
    kBitOr,
    kBitAnd,
    kBitXor,
    kBitNot,
    kShiftRight,
    kShiftLeft,
    kShiftRightLogical,
    kNe,
    kLt,
    kLe,
    kEq,
    kGe,
    kGt,
    kIf,
    kElse,
    kEndIf,
    kOpCount,
    kNoOp = 255, // '(' and ',' generate no code
};
static_assert(kOpCount < kNoOp);

constexpr bool is_fetch(unsigned op) {
    return op >= kFetchA && op < kFetchA + kArgs;
}
constexpr bool is_store(unsigned op) {
    return op >= kStoreA && op < kStoreA + kArgs;
}
constexpr bool has_count(unsigned op) {
    return op == kMax || op == kMin || op == kFinite || op == kIsnan;
}

// ---------------------------------------------------------------------------------------------
// Compiler

enum class Kind : uint8_t {
    Operand,     // pushes a value: arg, VAL, constant, RNDM
    Literal,     // decimal number, INF, NAN
    HexLiteral,  // 0x...
    Store,       // :=
    Unary,       // prefix operator or function of fixed arity
    Vararg,      // MAX MIN FINITE ISNAN: as many arguments as commas + 1
    OpenParen,   // (
    Binary,      // infix operator
    Separator,   // ,
    CloseParen,  // )
    Conditional, // ? and :
    Terminator,  // ;
};

struct Element {
    std::string_view name; // upper case
    int8_t stack_pri;      // priority while on the operator stack
    int8_t arrive_pri;     // priority when it arrives: pops operators of >= stack priority
    int effect;            // change of the evaluation stack depth
    Kind kind;
    unsigned char op;
};

// Where an operand is expected. Args A..U are matched after these (see match_operand).
// clang-format off
constexpr Element kOperands[] = {
    {"!", 7, 8, 0, Kind::Unary, kNot},
    {"(", 0, 8, 0, Kind::OpenParen, kNoOp},
    {"-", 7, 8, 0, Kind::Unary, kNeg},
    {".", 0, 0, 1, Kind::Literal, kLiteral},
    {"0", 0, 0, 1, Kind::Literal, kLiteral},
    {"0X", 0, 0, 1, Kind::HexLiteral, kLiteral},
    {"1", 0, 0, 1, Kind::Literal, kLiteral},
    {"2", 0, 0, 1, Kind::Literal, kLiteral},
    {"3", 0, 0, 1, Kind::Literal, kLiteral},
    {"4", 0, 0, 1, Kind::Literal, kLiteral},
    {"5", 0, 0, 1, Kind::Literal, kLiteral},
    {"6", 0, 0, 1, Kind::Literal, kLiteral},
    {"7", 0, 0, 1, Kind::Literal, kLiteral},
    {"8", 0, 0, 1, Kind::Literal, kLiteral},
    {"9", 0, 0, 1, Kind::Literal, kLiteral},
    {"ABS", 7, 8, 0, Kind::Unary, kAbs},
    {"ACOS", 7, 8, 0, Kind::Unary, kAcos},
    {"ASIN", 7, 8, 0, Kind::Unary, kAsin},
    {"ATAN", 7, 8, 0, Kind::Unary, kAtan},
    {"ATAN2", 7, 8, -1, Kind::Unary, kAtan2},
    {"CEIL", 7, 8, 0, Kind::Unary, kCeil},
    {"COS", 7, 8, 0, Kind::Unary, kCos},
    {"COSH", 7, 8, 0, Kind::Unary, kCosh},
    {"D2R", 0, 0, 1, Kind::Operand, kD2R},
    {"EXP", 7, 8, 0, Kind::Unary, kExp},
    {"FINITE", 7, 8, 0, Kind::Vararg, kFinite},
    {"FLOOR", 7, 8, 0, Kind::Unary, kFloor},
    {"FMOD", 7, 8, -1, Kind::Unary, kFmod},
    {"INF", 0, 0, 1, Kind::Literal, kLiteral},
    {"ISINF", 7, 8, 0, Kind::Unary, kIsinf},
    {"ISNAN", 7, 8, 0, Kind::Vararg, kIsnan},
    {"LN", 7, 8, 0, Kind::Unary, kLn},
    {"LOG", 7, 8, 0, Kind::Unary, kLog10},
    {"LOGE", 7, 8, 0, Kind::Unary, kLn},
    {"MAX", 7, 8, 0, Kind::Vararg, kMax},
    {"MIN", 7, 8, 0, Kind::Vararg, kMin},
    {"NAN", 0, 0, 1, Kind::Literal, kLiteral},
    {"NINT", 7, 8, 0, Kind::Unary, kNint},
    {"NOT", 7, 8, 0, Kind::Unary, kBitNot},
    {"PI", 0, 0, 1, Kind::Operand, kPi},
    {"R2D", 0, 0, 1, Kind::Operand, kR2D},
    {"RNDM", 0, 0, 1, Kind::Operand, kRandom},
    {"SIN", 7, 8, 0, Kind::Unary, kSin},
    {"SINH", 7, 8, 0, Kind::Unary, kSinh},
    {"SQR", 7, 8, 0, Kind::Unary, kSqrt},
    {"SQRT", 7, 8, 0, Kind::Unary, kSqrt},
    {"TAN", 7, 8, 0, Kind::Unary, kTan},
    {"TANH", 7, 8, 0, Kind::Unary, kTanh},
    {"VAL", 0, 0, 1, Kind::Operand, kFetchVal},
    {"~", 7, 8, 0, Kind::Unary, kBitNot},
};
// clang-format on

constexpr char kArgLetters[] = "ABCDEFGHIJKLMNOPQRSTU";
static_assert(sizeof(kArgLetters) - 1 == kArgs);

constexpr std::array<Element, kArgs> make_arg_elements() {
    std::array<Element, kArgs> a{};
    for (int i = 0; i < kArgs; ++i)
        a[i] = {std::string_view(kArgLetters + i, 1),   0, 0, 1, Kind::Operand,
                static_cast<unsigned char>(kFetchA + i)};
    return a;
}
constexpr std::array<Element, kArgs> kArgElements = make_arg_elements();

// Where an operator is expected.
// clang-format off
constexpr Element kOperators[] = {
    {"!=", 3, 3, -1, Kind::Binary, kNe},
    {"#", 3, 3, -1, Kind::Binary, kNe},
    {"%", 5, 5, -1, Kind::Binary, kMod},
    {"&", 2, 2, -1, Kind::Binary, kBitAnd},
    {"&&", 2, 2, -1, Kind::Binary, kAnd},
    {")", 0, 0, 0, Kind::CloseParen, kNoOp},
    {"*", 5, 5, -1, Kind::Binary, kMul},
    {"**", 6, 6, -1, Kind::Binary, kPow},
    {"+", 4, 4, -1, Kind::Binary, kAdd},
    {",", 0, 0, 0, Kind::Separator, kNoOp},
    {"-", 4, 4, -1, Kind::Binary, kSub},
    {"/", 5, 5, -1, Kind::Binary, kDiv},
    {":", 0, 0, -1, Kind::Conditional, kElse},
    {":=", 0, 0, -1, Kind::Store, kStoreA},
    {";", 0, 0, 0, Kind::Terminator, kNoOp},
    {"<", 3, 3, -1, Kind::Binary, kLt},
    {"<<", 2, 2, -1, Kind::Binary, kShiftLeft},
    {"<=", 3, 3, -1, Kind::Binary, kLe},
    {"=", 3, 3, -1, Kind::Binary, kEq},
    {"==", 3, 3, -1, Kind::Binary, kEq},
    {">", 3, 3, -1, Kind::Binary, kGt},
    {">=", 3, 3, -1, Kind::Binary, kGe},
    {">>", 2, 2, -1, Kind::Binary, kShiftRight},
    {">>>", 2, 2, -1, Kind::Binary, kShiftRightLogical},
    {"?", 0, 0, -1, Kind::Conditional, kIf},
    {"AND", 2, 2, -1, Kind::Binary, kBitAnd},
    {"OR", 1, 1, -1, Kind::Binary, kBitOr},
    {"XOR", 1, 1, -1, Kind::Binary, kBitXor},
    {"^", 6, 6, -1, Kind::Binary, kPow},
    {"|", 1, 1, -1, Kind::Binary, kBitOr},
    {"||", 1, 1, -1, Kind::Binary, kOr},
};
// clang-format on

// What ':' leaves on the operator stack: the end of the conditional, emitted when popped.
constexpr Element kEndIfElement = {":", 0, 0, 0, Kind::Conditional, kEndIf};

constexpr char upper(char c) {
    return c >= 'a' && c <= 'z' ? char(c - 'a' + 'A') : c;
}
// isspace() in the C locale, as base skips blanks between elements.
constexpr bool is_blank(char c) {
    return c == ' ' || (c >= '\t' && c <= '\r');
}

const Element* longest_match(std::span<const Element> table, std::string_view rest) {
    const Element* best = nullptr;
    for (const Element& e : table) {
        if (e.name.size() > rest.size() || (best && e.name.size() <= best->name.size())) continue;
        bool same = true;
        for (std::size_t i = 0; i < e.name.size() && same; ++i) same = upper(rest[i]) == e.name[i];
        if (same) best = &e;
    }
    return best;
}

const Element* match_operand(std::string_view rest) {
    if (const Element* e = longest_match(kOperands, rest)) return e;
    char c = upper(rest[0]);
    if (c >= 'A' && c < 'A' + kArgs) return &kArgElements[c - 'A'];
    return nullptr;
}

const char* error_text(Errc e) {
    switch (e) {
    case Errc::None:
        return "No error";
    case Errc::TooMany:
        return "Too many results";
    case Errc::BadLiteral:
        return "Bad number";
    case Errc::BadAssignment:
        return "Bad assignment";
    case Errc::BadSeparator:
        return "',' outside the parentheses of a function";
    case Errc::ParenNotOpen:
        return "')' without '('";
    case Errc::ParenOpen:
        return "'(' not closed";
    case Errc::Conditional:
        return "Unpaired conditional";
    case Errc::Incomplete:
        return "Incomplete expression";
    case Errc::Underflow:
        return "Too few operands";
    case Errc::Overflow:
        return "Too many values at once";
    case Errc::Syntax:
        return "Syntax error";
    case Errc::Empty:
        return "Empty expression";
    case Errc::TooLong:
        return "Expression too long";
    }
    return "Unknown error";
}

// A decimal literal (or INF, NAN) as epicsParseDouble reads it: strtod in the C locale; a value
// that over- or underflows a double is an error, as is text that converts nothing (".").
bool parse_decimal(const char* s, double& value, const char*& end) {
    char* e = nullptr;
    errno = 0;
#if defined(__GLIBC__)
    static const locale_t c_locale = newlocale(LC_ALL_MASK, "C", locale_t(0));
    value = c_locale ? strtod_l(s, &e, c_locale) : std::strtod(s, &e);
#else
    value = std::strtod(s, &e);
#endif
    if (e == s || errno == ERANGE) return false;
    end = e;
    return true;
}

// A 0x literal as epicsParseUInt32 reads it (strtoul, base 0): 32 bits, which evaluate as a
// signed integer (0xffffffff is -1). "0x" without hex digits reads as 0 followed by "x...".
bool parse_hex(const char* s, double& value, const char*& end) {
    char* e = nullptr;
    errno = 0;
    unsigned long long u = std::strtoull(s, &e, 0);
    if (e == s || errno == ERANGE) return false;
    // epicsParseUInt32 on 64-bit longs lets values above ~0xffffffff pass as negative ones
    if (u > 0xffffffffULL && u <= ~0xffffffffULL) return false;
    value = static_cast<int32_t>(static_cast<uint32_t>(u));
    end = e;
    return true;
}

class Compiler {
public:
    Compiler(std::string_view infix, CompileError* err)
        : text_(infix)
        , err_(err) {}
    bool run(Program& out);

private:
    struct Pending {
        Element el;
        std::size_t pos; // where it was in the text
    };
    static constexpr std::size_t kNone = std::size_t(-1);

    bool fail(Errc code, std::size_t pos, std::string_view detail = {});
    std::string excerpt(std::size_t pos) const;
    void emit_value(unsigned char op, const double* literal = nullptr);
    void emit(const Pending& p);
    bool flush_statement(); // ';' or the end: every pending operator to the code

    std::string text_; // NUL-terminated for the number parsers
    CompileError* err_;
    std::vector<unsigned char> code_;
    std::vector<Pending> ops_;
    std::vector<std::size_t> open_ifs_; // positions of the '?' still waiting for their ':'
    std::size_t last_insn_ = kNone;     // offset of the last instruction in code_
    int depth_ = 0;                     // evaluation stack depth after the code so far
};

bool Compiler::fail(Errc code, std::size_t pos, std::string_view detail) {
    if (err_) {
        err_->code = code;
        err_->position = pos;
        err_->message = error_text(code);
        if (!detail.empty()) err_->message.append(": ").append(detail);
    }
    return false;
}

std::string Compiler::excerpt(std::size_t pos) const {
    constexpr std::size_t kShown = 12;
    std::string s(1, '\'');
    s.append(text_, pos, kShown);
    if (text_.size() - pos > kShown) s += "...";
    s += '\'';
    return s;
}

void Compiler::emit_value(unsigned char op, const double* literal) {
    last_insn_ = code_.size();
    code_.push_back(op);
    if (literal) {
        unsigned char bytes[sizeof(double)];
        std::memcpy(bytes, literal, sizeof bytes);
        code_.insert(code_.end(), bytes, bytes + sizeof bytes);
    }
    depth_ += 1;
}

void Compiler::emit(const Pending& p) {
    last_insn_ = code_.size();
    code_.push_back(p.el.op);
    // A vararg function's effect is 1 - its argument count (see the ')' case).
    if (p.el.kind == Kind::Vararg) code_.push_back(static_cast<unsigned char>(1 - p.el.effect));
    depth_ += p.el.effect;
}

bool Compiler::flush_statement() {
    while (!ops_.empty()) {
        if (ops_.back().el.kind == Kind::OpenParen) return fail(Errc::ParenOpen, ops_.back().pos);
        emit(ops_.back());
        ops_.pop_back();
    }
    if (!open_ifs_.empty()) return fail(Errc::Conditional, open_ifs_.back(), "'?' without its ':'");
    return true;
}

bool Compiler::run(Program& out) {
    const std::string_view text = text_;
    bool operand_needed = true;
    std::size_t pos = 0;
    for (;;) {
        while (pos < text.size() && is_blank(text[pos])) ++pos;
        if (pos == text.size()) break;
        const std::string_view rest = text.substr(pos);
        const Element* el = operand_needed ? match_operand(rest) : longest_match(kOperators, rest);
        if (!el)
            return fail(Errc::Syntax, pos,
                        (operand_needed ? "expected an operand at " : "expected an operator at ") +
                            excerpt(pos));
        const std::size_t at = pos;
        pos += el->name.size();

        switch (el->kind) {
        case Kind::Operand:
            emit_value(el->op);
            operand_needed = false;
            break;

        case Kind::Literal:
        case Kind::HexLiteral: {
            // The name only says a number starts here; the parser reads all of it.
            double value = 0;
            const char* end = nullptr;
            const char* start = text_.c_str() + at;
            if (!(el->kind == Kind::Literal ? parse_decimal(start, value, end)
                                            : parse_hex(start, value, end)))
                return fail(Errc::BadLiteral, at, excerpt(at) + " is malformed or out of range");
            pos = static_cast<std::size_t>(end - text_.c_str());
            emit_value(kLiteral, &value);
            operand_needed = false;
            break;
        }

        case Kind::Store: {
            // Only right after an arg, with nothing pending: "A:=", also "(A):=" as in base.
            if (!ops_.empty() || last_insn_ == kNone || !is_fetch(code_[last_insn_]))
                return fail(Errc::BadAssignment, at,
                            "':=' must follow one of A..U at the start of a statement");
            Pending store{*el, at};
            store.el.op = static_cast<unsigned char>(kStoreA + code_[last_insn_] - kFetchA);
            code_.resize(last_insn_); // the store replaces the fetch
            last_insn_ = kNone;
            ops_.push_back(store);
            depth_ -= 1;
            operand_needed = true;
            break;
        }

        case Kind::Unary:
        case Kind::Vararg:
        case Kind::OpenParen:
        case Kind::Binary:
            while (!ops_.empty() && ops_.back().el.stack_pri >= el->arrive_pri) {
                emit(ops_.back());
                ops_.pop_back();
            }
            ops_.push_back({*el, at});
            if (el->kind == Kind::Binary) operand_needed = true;
            break;

        case Kind::Separator:
            // Operators back to the '(' go out; the '(' counts one more argument.
            while (ops_.empty() || ops_.back().el.kind != Kind::OpenParen) {
                if (ops_.size() <= 1) return fail(Errc::BadSeparator, at);
                emit(ops_.back());
                ops_.pop_back();
            }
            if (--ops_.back().el.effect < -254) // the count must fit its byte
                return fail(Errc::Overflow, at, "too many arguments");
            operand_needed = true;
            break;

        case Kind::CloseParen: {
            while (ops_.empty() || ops_.back().el.kind != Kind::OpenParen) {
                if (ops_.size() <= 1) return fail(Errc::ParenNotOpen, at);
                emit(ops_.back());
                ops_.pop_back();
            }
            const int commas_effect = ops_.back().el.effect;
            ops_.pop_back();
            // A vararg function before the '(' takes as many arguments as there were.
            if (!ops_.empty() && ops_.back().el.kind == Kind::Vararg) {
                ops_.back().el.effect = commas_effect;
                if (commas_effect > 0) return fail(Errc::Incomplete, at);
            }
            break;
        }

        case Kind::Conditional:
            while (!ops_.empty() && ops_.back().el.stack_pri > el->arrive_pri) {
                emit(ops_.back());
                ops_.pop_back();
            }
            emit({*el, at});
            if (el->op == kElse) {
                if (open_ifs_.empty()) return fail(Errc::Conditional, at, "':' without '?'");
                open_ifs_.pop_back();
                ops_.push_back({kEndIfElement, at});
            } else {
                open_ifs_.push_back(at);
            }
            operand_needed = true;
            break;

        case Kind::Terminator:
            if (!flush_statement()) return false;
            if (depth_ > 1)
                return fail(Errc::TooMany, at,
                            "each statement but one must assign its value with ':='");
            operand_needed = true;
            break;
        }

        if (depth_ < 0)
            return fail(Errc::Underflow, at, "a function lacks arguments before " + excerpt(at));
        if (depth_ >= kStackSize)
            return fail(Errc::Overflow, at,
                        "at most " + std::to_string(kStackSize - 1) + " fit the stack");
    }

    if (!flush_statement()) return false;
    if (operand_needed) return fail(Errc::Incomplete, text.size(), "operand missing at the end");
    if (depth_ < 1)
        return fail(Errc::Incomplete, text.size(),
                    "no value is left: every statement assigns, or a function lacks arguments");
    if (depth_ > 1)
        return fail(Errc::Incomplete, text.size(),
                    std::to_string(depth_) + " values are left instead of one: too many "
                                             "arguments, or two statements without ':='");
    code_.push_back(kEnd);
    out.code = std::move(code_);
    return true;
}

// ---------------------------------------------------------------------------------------------
// Evaluation

// The casts of calcPerform as x86-64 computes them (C leaves out-of-range casts undefined):
// double -> int32 truncates, and gives INT32_MIN for NaN and values out of range.
int32_t to_int32(double x) {
    if (x > -2147483649.0 && x < 2147483648.0) return static_cast<int32_t>(x);
    return INT32_MIN;
}
// double >= 0 -> uint32 goes through a 64-bit truncation: the low 32 bits below 2^63, else 0
// (also for NaN, which base sends this way).
uint32_t to_uint32_nonneg(double x) {
    if (x < 9223372036854775808.0) return static_cast<uint32_t>(static_cast<int64_t>(x));
    return 0;
}
// Bitwise operands: negative values convert as signed, others as unsigned, so both
// -1431655766 and 2863311530 are 0xaaaaaaaa.
int32_t bits_signed(double x) {
    return x < 0 ? to_int32(x) : static_cast<int32_t>(to_uint32_nonneg(x));
}
uint32_t bits_unsigned(double x) {
    return x < 0 ? static_cast<uint32_t>(to_int32(x)) : to_uint32_nonneg(x);
}

// RNDM: uniform in [0, 1), splitmix64 on a per-thread state (base: a 16-bit LCG, in [0, 1]).
double random_unit() noexcept {
    thread_local uint64_t state = 0;
    if (state == 0) {
        static std::atomic<uint64_t> threads{0};
        state = (threads.fetch_add(1, std::memory_order_relaxed) + 1) * 0x9E3779B97F4A7C15u ^
                reinterpret_cast<uintptr_t>(&state);
        state |= 1;
    }
    uint64_t z = (state += 0x9E3779B97F4A7C15u);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9u;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBu;
    z ^= z >> 31;
    return static_cast<double>(z >> 11) * 0x1.0p-53;
}

// How each opcode uses the stack, checked before it runs so that no code can overrun it: whether
// it pops a value from below the top one, or pushes a new one (a vararg opcode checks its count
// itself). The top one may be stack[0]: base lets an operator that lacks an operand read that
// unused slot, so "ATAN2(1);2" compiles and gives 2 (see perform()).
enum StackUse : uint8_t { kKeeps = 0, kPops = 1, kPushes = 2 };
constexpr std::array<uint8_t, 256> make_stack_use() {
    std::array<uint8_t, 256> u{};
    u[kLiteral] = u[kFetchVal] = kPushes;
    for (int i = 0; i < kArgs; ++i) {
        u[kFetchA + i] = kPushes;
        u[kStoreA + i] = kPops;
    }
    u[kPi] = u[kD2R] = u[kR2D] = u[kRandom] = kPushes;
    u[kIf] = kPops; // the condition
    for (unsigned op :
         {kAdd, kSub, kMul,   kDiv,    kMod,    kPow,        kAtan2,     kFmod,
          kOr,  kAnd, kBitOr, kBitAnd, kBitXor, kShiftRight, kShiftLeft, kShiftRightLogical,
          kNe,  kLt,  kLe,    kEq,     kGe,     kGt})
        u[op] = kPops;
    return u;
}
constexpr std::array<uint8_t, 256> kStackUse = make_stack_use();

// Moves pc just past the `match` (kElse or kEndIf) of the conditional being executed, stepping
// over nested ones as base's cond_search does; nullptr if there is none.
const unsigned char* skip_to(const unsigned char* pc, const unsigned char* end, unsigned match) {
    int nesting = 1;
    while (pc != end && *pc != kEnd) {
        const unsigned op = *pc++;
        if (op == match && --nesting == 0) return pc;
        if (op == kLiteral)
            pc += end - pc < 8 ? end - pc : 8;
        else if (has_count(op))
            pc += pc != end;
        else if (op == kIf)
            ++nesting;
    }
    return nullptr;
}

constexpr double kPiValue = 3.14159265358979323; // base's PI

} // namespace

const char* errc_text(Errc e) {
    return error_text(e);
}

bool compile(std::string_view infix, Program& out, CompileError* err) {
    return compile(infix, out, err, kMaxInfix - 1);
}

bool compile(std::string_view infix, Program& out, CompileError* err, std::size_t max_chars) {
    infix = infix.substr(0, infix.find('\0')); // a C string ends at its NUL
    if (infix.empty()) {
        if (err) *err = {error_text(Errc::Empty), 0, Errc::Empty};
        return false;
    }
    if (infix.size() > max_chars) {
        if (err)
            *err = {"Expression too long: " + std::to_string(infix.size()) +
                        " characters, at most " + std::to_string(max_chars) + " fit",
                    max_chars, Errc::TooLong};
        return false;
    }
    return Compiler(infix, err).run(out);
}

bool perform(const Program& p, double* args, double* result) noexcept {
    // Code ends with kEnd, so the loop stops there: only instructions with bytes of their own
    // (literals, argument counts) check that they stay before it.
    if (p.code.empty() || p.code.back() != kEnd) return false;
    const unsigned char* pc = p.code.data();
    const unsigned char* const last = pc + p.code.size() - 1;
    // top == stack means empty. stack[0] holds no value, but an operator short of operands reads
    // and writes it as base's does (uninitialised there): a result that needs it is dropped, or
    // the stack does not end with one value. Nothing goes below it.
    double stack[kStackSize + 1];
    stack[0] = NAN;
    double* top = stack;
    double* const full = stack + kStackSize;

    for (;;) {
        const unsigned op = *pc++;
        if (const uint8_t use = kStackUse[op];
            use != kKeeps && top == (use == kPops ? stack : full))
            return false;
        double x; // the operand popped last (the right-hand one)
        switch (op) {
        case kEnd:
            if (top != stack + 1) return false;
            *result = *top;
            return true;
        case kLiteral:
            if (last - pc < 8) return false;
            std::memcpy(++top, pc, sizeof(double));
            pc += sizeof(double);
            break;
        case kFetchVal:
            *++top = *result;
            break;
        case kPi:
            *++top = kPiValue;
            break;
        case kD2R:
            *++top = kPiValue / 180.;
            break;
        case kR2D:
            *++top = 180. / kPiValue;
            break;
        case kRandom:
            *++top = random_unit();
            break;

        case kNeg:
            *top = -*top;
            break;
        case kAdd:
            x = *top--;
            *top += x;
            break;
        case kSub:
            x = *top--;
            *top -= x;
            break;
        case kMul:
            x = *top--;
            *top *= x;
            break;
        case kDiv:
            x = *top--;
            *top /= x;
            break;
        case kMod: {
            // Integer remainder of the truncated operands; NaN for a zero divisor. Base traps
            // (SIGFPE) on INT32_MIN % -1, which is 0 here.
            const int32_t divisor = to_int32(*top--);
            if (divisor == 0)
                *top = NAN;
            else
                *top = divisor == -1 ? 0 : to_int32(*top) % divisor;
            break;
        }
        case kPow:
            x = *top--;
            *top = std::pow(*top, x);
            break;

        case kAbs:
            *top = std::fabs(*top);
            break;
        case kExp:
            *top = std::exp(*top);
            break;
        case kLog10:
            *top = std::log10(*top);
            break;
        case kLn:
            *top = std::log(*top);
            break;
        case kSqrt:
            *top = std::sqrt(*top);
            break;
        case kMax:
        case kMin: {
            // Pairwise from the last argument back; a NaN anywhere wins.
            if (pc == last) return false;
            int n = *pc++;
            if (n < 1 || top - stack < n - 1) return false;
            while (--n) {
                x = *top--;
                if ((op == kMax ? *top < x : *top > x) || std::isnan(x)) *top = x;
            }
            break;
        }

        case kAcos:
            *top = std::acos(*top);
            break;
        case kAsin:
            *top = std::asin(*top);
            break;
        case kAtan:
            *top = std::atan(*top);
            break;
        case kAtan2:
            x = *top--;
            *top = std::atan2(x, *top);
            break; // ATAN2(a, b) = atan2(b, a)
        case kCos:
            *top = std::cos(*top);
            break;
        case kCosh:
            *top = std::cosh(*top);
            break;
        case kSin:
            *top = std::sin(*top);
            break;
        case kSinh:
            *top = std::sinh(*top);
            break;
        case kTan:
            *top = std::tan(*top);
            break;
        case kTanh:
            *top = std::tanh(*top);
            break;

        case kCeil:
            *top = std::ceil(*top);
            break;
        case kFloor:
            *top = std::floor(*top);
            break;
        case kFmod:
            x = *top--;
            *top = std::fmod(*top, x);
            break;
        case kFinite:
        case kIsnan: {
            if (pc == last) return false;
            int n = *pc++;
            if (n < 1 || top - stack < n - 1) return false;
            double* const first = top - (n - 1);
            bool any_nan = false, all_finite = true;
            for (const double* v = first; v <= top; ++v) {
                any_nan = any_nan || std::isnan(*v);
                all_finite = all_finite && std::isfinite(*v);
            }
            top = first;
            *top = op == kIsnan ? any_nan : all_finite;
            break;
        }
        case kIsinf:
            // glibc's isinf(), which base calls: -1 for -Inf
            *top = std::isinf(*top) ? (*top < 0 ? -1 : 1) : 0;
            break;
        case kNint:
            // Half away from zero through a 32-bit cast: NINT(NaN) and NINT(3e9) are INT32_MIN.
            *top = to_int32(*top >= 0 ? *top + 0.5 : *top - 0.5);
            break;

        case kOr:
            x = *top--;
            *top = *top != 0 || x != 0;
            break;
        case kAnd:
            x = *top--;
            *top = *top != 0 && x != 0;
            break;
        case kNot:
            *top = *top == 0;
            break;

        case kBitOr:
            x = *top--;
            *top = bits_signed(*top) | bits_signed(x);
            break;
        case kBitAnd:
            x = *top--;
            *top = bits_signed(*top) & bits_signed(x);
            break;
        case kBitXor:
            x = *top--;
            *top = bits_signed(*top) ^ bits_signed(x);
            break;
        case kBitNot:
            *top = ~bits_signed(*top);
            break;
        case kShiftRight:
            x = *top--;
            *top = bits_signed(*top) >> (bits_signed(x) & 31);
            break;
        case kShiftLeft:
            x = *top--;
            *top = static_cast<int32_t>(bits_unsigned(*top) << (bits_signed(x) & 31));
            break;
        case kShiftRightLogical:
            x = *top--;
            *top = bits_unsigned(*top) >> (bits_unsigned(x) & 31u);
            break;

        case kNe:
            x = *top--;
            *top = *top != x;
            break;
        case kLt:
            x = *top--;
            *top = *top < x;
            break;
        case kLe:
            x = *top--;
            *top = *top <= x;
            break;
        case kEq:
            x = *top--;
            *top = *top == x;
            break;
        case kGe:
            x = *top--;
            *top = *top >= x;
            break;
        case kGt:
            x = *top--;
            *top = *top > x;
            break;

        case kIf:
            // 0 takes the ':' branch; anything else (NaN too) the '?' branch.
            if (*top-- == 0.0 && !(pc = skip_to(pc, last, kElse))) return false;
            break;
        case kElse:
            if (!(pc = skip_to(pc, last, kEndIf))) return false;
            break;
        case kEndIf:
            break;

        default:
            if (is_fetch(op)) {
                *++top = args[op - kFetchA];
            } else if (is_store(op)) {
                args[op - kStoreA] = *top--;
            } else {
                return false; // not an opcode
            }
        }
    }
}

void arg_usage(const Program& p, uint32_t* inputs, uint32_t* stores) noexcept {
    uint32_t read = 0, assigned = 0;
    const unsigned char* pc = p.code.data();
    const unsigned char* const end = pc + p.code.size();
    while (pc != end && *pc != kEnd) {
        const unsigned op = *pc++;
        if (is_fetch(op))
            read |= (1u << (op - kFetchA)) & ~assigned; // read after an assignment: not an input
        else if (is_store(op))
            assigned |= 1u << (op - kStoreA);
        else if (op == kLiteral)
            pc += end - pc < 8 ? end - pc : 8;
        else if (has_count(op))
            pc += pc != end;
    }
    if (inputs) *inputs = read;
    if (stores) *stores = assigned;
}

} // namespace beamctl::pv::calc
