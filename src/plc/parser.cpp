#include "plc/parser.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <set>

namespace beamctl::plc::detail {

bool is_vector_expr(const Node& n) {
    switch (n.kind) {
    case NK::vec:
        return true;
    case NK::neg:
    case NK::lnot:
    case NK::builtin:
    case NK::binary:
        if (n.kind == NK::binary &&
            (n.op == static_cast<int>(BinOp::scand) || n.op == static_cast<int>(BinOp::scor)))
            return false;
        for (const NodePtr& k : n.kids)
            if (k && is_vector_expr(*k)) return true;
        return false;
    default:
        return false;
    }
}

int vector_expr_size(const Node& n, const Unit& unit) {
    if (n.kind == NK::vec) return unit.vars[n.ref].size;
    int size = std::numeric_limits<int>::max();
    for (const NodePtr& k : n.kids)
        if (k && is_vector_expr(*k)) size = std::min(size, vector_expr_size(*k, unit));
    return size;
}

namespace {

struct Syntax {}; // unwinds to the statement level after a diagnostic

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Words with a meaning of their own (ExprTk's reserved words plus the ones this dialect adds).
const std::set<std::string>& reserved_words() {
    static const std::set<std::string> words = {
        "assert", "break",    "case",  "continue", "const",  "default", "else",    "false",
        "for",    "if",       "ilike", "in",       "like",   "and",     "nand",    "nor",
        "not",    "null",     "or",    "repeat",   "return", "swap",    "switch",  "true",
        "until",  "var",      "while", "xnor",     "xor",    "&",       "|",       "~",
        "[*]",    "function", "print", "println",  "dot",    "pi",      "epsilon", "inf"};
    return words;
}

bool is_reserved_name(const std::string& lname) {
    Aggregate a;
    return reserved_words().count(lname) != 0 || find_builtin(lname) != nullptr ||
           find_aggregate(lname, a);
}

bool valid_local_name(const std::string& s) {
    if (s.empty() || !std::isalpha(static_cast<unsigned char>(s[0]))) return false;
    for (char c : s)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.')) return false;
    return true;
}

bool is_pure_constant(const Node& n) {
    return n.kind == NK::num;
}

class Parser {
public:
    Parser(const Source& src, Host& host, Diagnostics& diags, Unit& unit)
        : src_(src)
        , host_(host)
        , diags_(diags)
        , unit_(unit) {}

    void strict(bool on) { strict_ = on; }

    // Registers the `function` signatures of a token stream (so calls may precede definitions).
    void declare_functions(const std::vector<Token>& toks) {
        int depth = 0;
        for (std::size_t i = 0; i + 2 < toks.size(); ++i) {
            const Tok t = toks[i].type;
            if (t == Tok::lparen || t == Tok::lbracket || t == Tok::lbrace) ++depth;
            if (t == Tok::rparen || t == Tok::rbracket || t == Tok::rbrace) --depth;
            if (depth != 0 || !(t == Tok::symbol && lower(toks[i].text) == "function")) continue;
            const Token& name = toks[i + 1];
            if (name.type != Tok::symbol || toks[i + 2].type != Tok::lparen) continue;
            const std::string lname = lower(name.text);
            if (is_reserved_name(lname) || name.text.find('.') != std::string::npos) {
                error(name, SB() << "'" << name.text << "' cannot be used as a function name");
                continue;
            }
            if (functions_.count(lname)) {
                const Function& prev = unit_.functions[functions_[lname]];
                error(name, SB() << "function '" << name.text << "' is defined twice (first at "
                                 << src_.loc(prev.pos.line, prev.pos.offset).str() << ")");
                continue;
            }
            Function f;
            f.name = name.text;
            f.pos = {name.line, name.offset};
            const int id = static_cast<int>(unit_.functions.size());
            std::set<std::string> seen;
            std::size_t j = i + 3;
            bool ok = true;
            while (j < toks.size() && toks[j].type != Tok::rparen) {
                const Token& p = toks[j];
                if (p.type != Tok::symbol || !valid_local_name(p.text) ||
                    is_reserved_name(lower(p.text))) {
                    error(p, SB() << "expected a parameter name in the definition of '" << name.text
                                  << "', found " << describe(p));
                    ok = false;
                    break;
                }
                if (!seen.insert(lower(p.text)).second) {
                    error(p, SB() << "parameter '" << p.text << "' appears twice");
                    ok = false;
                    break;
                }
                Variable v;
                v.name = p.text;
                v.frame = id;
                v.pos = {p.line, p.offset};
                f.params.push_back(static_cast<int>(unit_.vars.size()));
                unit_.vars.push_back(std::move(v));
                ++j;
                if (j < toks.size() && toks[j].type == Tok::comma) ++j;
            }
            if (!ok) continue;
            functions_[lname] = id;
            unit_.functions.push_back(std::move(f));
        }
    }

    NodePtr parse_file(const std::vector<Token>& toks, bool library) {
        toks_ = &toks;
        pos_ = 0;
        auto block = make(NK::block, cur());
        if (auto bad = check_brackets()) {
            // The statements before the mismatch are parsed as a file of their own (their errors
            // come too); nothing after it can be told apart reliably.
            std::vector<Token> head(toks.begin(), toks.begin() + std::ptrdiff_t(bad->cut));
            head.push_back(toks.back()); // the end token
            if (bad->cut > 0) block = parse_file(head, library);
            toks_ = &toks;
            error(toks[bad->at], bad->message);
            return block;
        }
        bool ended = true; // the last statement has its ';' (or there is none yet)
        while (!is(Tok::end)) {
            if (is(Tok::semicolon)) {
                if (ended) empty_statement(cur());
                ended = true;
                next();
                continue;
            }
            const std::size_t start = pos_;
            try {
                if (is_word(cur(), "function")) {
                    if (!library)
                        ecmc_refuses(cur(), "a 'function' definition in PLC code",
                                     "define it in a library file (ecmccfg loadPLCLib.cmd; "
                                     "'libraries:' of the PLC here)");
                    parse_function_def();
                    ended = true;
                    continue;
                }
                if (!ended) juxtaposed_numbers();
                ended = false;
                if (library)
                    fail(cur(), SB() << "expected a function definition in a library, found "
                                     << describe(cur()));
                block->kids.push_back(parse_expression(0));
                if (is(Tok::rparen) || is(Tok::rbracket) || is(Tok::rbrace))
                    fail(cur(), SB() << "unexpected " << describe(cur()));
                if (pos_ == start) fail(cur(), SB() << "unexpected " << describe(cur()));
            } catch (const Syntax&) {
                recover();
            }
        }
        return block;
    }

private:
    // ---- tokens ------------------------------------------------------------------------------

    const Token& cur() const { return (*toks_)[pos_]; }
    const Token& peek(std::size_t k = 1) const {
        return (*toks_)[std::min(pos_ + k, toks_->size() - 1)];
    }
    void next() {
        if (pos_ + 1 < toks_->size()) ++pos_;
    }
    bool is(Tok t) const { return cur().type == t; }
    static bool is_word(const Token& t, const char* w) {
        return t.type == Tok::symbol && lower(t.text) == w;
    }

    static std::string describe(const Token& t) {
        switch (t.type) {
        case Tok::end:
            return "end of code";
        case Tok::symbol:
            return "'" + t.text + "'";
        case Tok::number:
            return "number '" + t.text + "'";
        case Tok::string:
            return "string '" + t.text + "'";
        default:
            if (t.inserted) return "an implicit '*' (a missing ';' or operator?)";
            return to_string(t.type);
        }
    }

    void error(const Token& at, const std::string& msg) {
        diags_.add(src_.diagnostic(at.line, at.offset, msg));
    }
    void error(const Pos& at, const std::string& msg) {
        diags_.add(src_.diagnostic(at.line, at.offset, msg));
    }
    [[noreturn]] void fail(const Token& at, const std::string& msg) {
        error(at, msg);
        throw Syntax{};
    }
    void expect(Tok t, const char* context) {
        if (!is(t))
            fail(cur(), SB() << "expected " << to_string(t) << " " << context << ", found "
                             << describe(cur()));
        next();
    }

    static NodePtr make(NK k, const Token& at) {
        auto n = std::make_unique<Node>();
        n->kind = k;
        n->pos = {at.line, at.offset};
        return n;
    }
    static NodePtr number(double v, const Pos& at) {
        auto n = std::make_unique<Node>();
        n->kind = NK::num;
        n->num = v;
        n->pos = at;
        return n;
    }

    // ExprTk's bracket check: every bracket matched, before anything is parsed. On a mismatch,
    // `cut` is where the statements before it end (after the last top-level ';' ahead of the first
    // bracket involved), so those can still be parsed and their errors reported.
    struct BracketError {
        std::size_t at;
        std::string message;
        std::size_t cut;
    };
    std::optional<BracketError> check_brackets() {
        std::vector<std::size_t> stack;
        depth_.assign(toks_->size(), 0);
        std::optional<BracketError> bad;
        std::size_t i = 0;
        for (; i < toks_->size() && !bad; ++i) {
            const Token& t = (*toks_)[i];
            depth_[i] = static_cast<int>(stack.size());
            if (t.type == Tok::lparen || t.type == Tok::lbracket || t.type == Tok::lbrace) {
                stack.push_back(i);
            } else if (t.type == Tok::rparen || t.type == Tok::rbracket || t.type == Tok::rbrace) {
                const Tok open = t.type == Tok::rparen     ? Tok::lparen
                                 : t.type == Tok::rbracket ? Tok::lbracket
                                                           : Tok::lbrace;
                if (stack.empty()) {
                    bad = BracketError{i, SB() << "unmatched " << to_string(t.type), i};
                    break;
                }
                const Token& o = (*toks_)[stack.back()];
                if (o.type != open) {
                    bad = BracketError{i, SB() << to_string(t.type) << " does not match " << to_string(o.type)
                                                << " at " << src_.loc(o.line, o.offset).str(), i};
                    break;
                }
                stack.pop_back();
                depth_[i] = static_cast<int>(stack.size());
            }
        }
        if (!bad && !stack.empty())
            bad = BracketError{stack.back(), SB() << to_string((*toks_)[stack.back()].type) << " is never closed", 0};
        if (!bad) return bad;
        std::size_t first = stack.empty() ? bad->at : std::min(bad->at, stack.front());
        bad->cut = 0;
        for (std::size_t k = first; k-- > 0;)
            if (depth_[k] == 0 && (*toks_)[k].type == Tok::semicolon) {
                bad->cut = k + 1;
                break;
            }
        return bad;
    }

    // After a syntax error: skip to the end of the statement (a ';' or a closing '}' at the top
    // level) or to the next `function` definition.
    // Scopes, frame and loop depth were restored by the guards while unwinding.
    void recover() {
        while (!is(Tok::end)) {
            if (depth_[pos_] == 0) {
                if (is(Tok::semicolon)) {
                    next();
                    return;
                }
                if (is(Tok::rbrace)) {
                    next();
                    if (is(Tok::semicolon)) next();
                    return;
                }
                if (is_word(cur(), "function")) return;
            }
            next();
        }
    }

    // ---- scopes ------------------------------------------------------------------------------

    struct ScopeGuard {
        Parser& p;
        explicit ScopeGuard(Parser& parser)
            : p(parser) {
            p.scopes_.emplace_back();
        }
        ~ScopeGuard() {
            if (!p.scopes_.empty()) p.scopes_.pop_back();
        }
    };
    struct LoopGuard {
        Parser& p;
        explicit LoopGuard(Parser& parser)
            : p(parser) {
            ++p.loop_depth_;
        }
        ~LoopGuard() { --p.loop_depth_; }
    };

    int find_local(const std::string& lname) const {
        for (auto s = scopes_.rbegin(); s != scopes_.rend(); ++s) {
            auto it = s->find(lname);
            if (it != s->end()) return it->second;
        }
        return -1;
    }

    int declare(const Token& name, bool vector, int size) {
        const std::string lname = lower(name.text);
        if (!valid_local_name(name.text) || is_reserved_name(lname) || functions_.count(lname))
            fail(name, SB() << "'" << name.text << "' cannot be used as a variable name");
        if (const int prev = find_local(lname); prev >= 0) {
            const Variable& v = unit_.vars[prev];
            fail(name, SB() << "'" << name.text << "' is already defined (at "
                            << src_.loc(v.pos.line, v.pos.offset).str()
                            << "); ExprTk does not allow redefinition or shadowing");
        }
        Variable v;
        v.name = name.text;
        v.frame = frame_;
        v.vector = vector;
        v.size = size;
        v.pos = {name.line, name.offset};
        const int id = static_cast<int>(unit_.vars.size());
        unit_.vars.push_back(std::move(v));
        if (scopes_.empty()) scopes_.emplace_back();
        scopes_.back()[lname] = id;
        return id;
    }

    // ---- top level ---------------------------------------------------------------------------

    void parse_function_def() {
        next(); // function
        const Token name = cur();
        const auto it = functions_.find(lower(name.text));
        if (name.type == Tok::symbol && peek().type == Tok::lparen && it == functions_.end())
            throw Syntax{}; // a bad head, reported by declare_functions
        if (name.type != Tok::symbol || peek().type != Tok::lparen)
            fail(name, SB() << "expected a function name and '(' after 'function', found "
                            << describe(name));
        const int id = it->second;
        next();
        while (!is(Tok::rparen)) next(); // parameters were read by declare_functions
        next();
        if (!is(Tok::lbrace))
            fail(cur(), SB() << "expected '{' to start the body of function '" << name.text
                             << "', found " << describe(cur()));
        struct FrameGuard {
            Parser& p;
            int frame;
            std::vector<std::map<std::string, int>> scopes;
            int loops;
            FrameGuard(Parser& parser, int f)
                : p(parser)
                , frame(parser.frame_)
                , scopes(std::move(parser.scopes_))
                , loops(parser.loop_depth_) {
                p.frame_ = f;
                p.scopes_.clear();
                p.loop_depth_ = 0;
            }
            ~FrameGuard() {
                p.frame_ = frame;
                p.scopes_ = std::move(scopes);
                p.loop_depth_ = loops;
            }
        } guard(*this, id);
        ScopeGuard params(*this);
        for (int v : unit_.functions[id].params) scopes_.back()[lower(unit_.vars[v].name)] = v;
        NodePtr body = parse_braces();
        if (is(Tok::mul) && cur().inserted) next(); // `}` then a statement on the next line
        if (is(Tok::semicolon)) next();
        unit_.functions[id].body = std::move(body);
        unit_.functions[id].defined = true;
    }

    // `{ a; b; ... }` with its own scope; the value is the last statement's. `bare`: not the
    // body of a statement, where ExprTk reads `{` as a bracket around one expression.
    NodePtr parse_braces(bool bare = false) {
        const Token open = cur();
        expect(Tok::lbrace, "");
        auto block = make(NK::block, open);
        ScopeGuard scope(*this);
        bool statements = false; // a ';' inside: a sequence, not one bracketed expression
        bool ended = true;       // the last statement has its ';'
        while (!is(Tok::rbrace)) {
            if (is(Tok::semicolon)) {
                empty_statement(cur());
                next();
                continue;
            }
            if (is(Tok::end)) fail(open, "'{' is never closed");
            if (!ended) juxtaposed_numbers();
            block->kids.push_back(parse_expression(0));
            ended = false;
            if (is(Tok::semicolon)) {
                statements = ended = true;
                next();
            } else if (is(Tok::rparen) || is(Tok::rbracket)) {
                fail(cur(), SB() << "unexpected " << describe(cur()) << " (expected ';' or '}')");
            }
        }
        next();
        if (bare && (statements || block->kids.empty()))
            ecmc_refuses(open,
                         block->kids.empty() ? "an empty '{}' block"
                                             : "a bare '{ ...; }' block of statements (ExprTk reads "
                                               "a bare '{' as a bracket around one expression)",
                         "'~{ ... }'");
        return block;
    }

    // ---- strict ECMC mode: what beamctl accepts and ECMC's ExprTk refuses ---------------------

    void ecmc_refuses(const Token& at, const std::string& what, const std::string& spelling) {
        if (strict_)
            error(at, SB() << "strict ECMC: ExprTk refuses " << what << "; ECMC spelling: "
                           << spelling);
    }
    // A number right after a number (`x := 1 2`) starts a new statement here; ExprTk refuses
    // the token pair.
    void juxtaposed_numbers() {
        if (pos_ > 0 && is(Tok::number) && (*toks_)[pos_ - 1].type == Tok::number)
            ecmc_refuses(cur(), "two numbers side by side", "an operator or ';' between them");
    }
    void empty_statement(const Token& at) {
        ecmc_refuses(at, "an empty statement (a ';' with no statement before it)",
                     "remove the ';'");
    }

    // ExprTk's multi-sequence: `{a; b}` or `(a, b)`.
    NodePtr parse_sequence(const char* what) {
        if (is(Tok::lbrace)) return parse_braces();
        if (!is(Tok::lparen))
            fail(cur(),
                 SB() << "expected '{' to start the " << what << ", found " << describe(cur()));
        const Token open = cur();
        next();
        auto block = make(NK::block, open);
        ScopeGuard scope(*this);
        if (is(Tok::rparen)) {
            next();
            return block;
        }
        for (;;) {
            block->kids.push_back(parse_expression(0));
            if (is(Tok::rparen)) {
                next();
                break;
            }
            expect(Tok::comma, SB() << "between the parts of the " << what);
        }
        return block;
    }
    void expect(Tok t, const SB& context) { expect(t, std::string(context).c_str()); }

    // ---- expressions -------------------------------------------------------------------------

    struct OpInfo {
        int left = 0, right = 0;
        bool assign = false;
        Assign assign_op = Assign::set;
        bool swap = false;
        BinOp bin = BinOp::add;
    };

    // ExprTk's precedence levels (left, right): assignments and '<=>' 0/0, or nor xor xnor |
    // 1/2, and nand & 3/4, comparisons 5/6, + - 7/8, * / % 10/11, ^ 12/12 (right-associative).
    static bool binary_op(const Token& t, OpInfo& op) {
        static const struct {
            Tok tok;
            Assign assign;
        } assigns[] = {{Tok::assign, Assign::set},     {Tok::add_assign, Assign::add},
                       {Tok::sub_assign, Assign::sub}, {Tok::mul_assign, Assign::mul},
                       {Tok::div_assign, Assign::div}, {Tok::mod_assign, Assign::mod}};
        static const struct {
            Tok tok;
            int left, right;
            BinOp bin;
        } ops[] = {{Tok::lt, 5, 6, BinOp::lt},     {Tok::le, 5, 6, BinOp::le},
                   {Tok::gt, 5, 6, BinOp::gt},     {Tok::ge, 5, 6, BinOp::ge},
                   {Tok::eq, 5, 6, BinOp::eq},     {Tok::ne, 5, 6, BinOp::ne},
                   {Tok::add, 7, 8, BinOp::add},   {Tok::sub, 7, 8, BinOp::sub},
                   {Tok::mul, 10, 11, BinOp::mul}, {Tok::div, 10, 11, BinOp::div},
                   {Tok::mod, 10, 11, BinOp::mod}, {Tok::pow, 12, 12, BinOp::pow}};
        static const struct {
            const char* word;
            int left, right;
            BinOp bin;
        } words[] = {{"and", 3, 4, BinOp::land},   {"&", 3, 4, BinOp::scand},
                     {"nand", 3, 4, BinOp::lnand}, {"or", 1, 2, BinOp::lor},
                     {"|", 1, 2, BinOp::scor},     {"nor", 1, 2, BinOp::lnor},
                     {"xor", 1, 2, BinOp::lxor},   {"xnor", 1, 2, BinOp::lxnor}};
        op = OpInfo{};
        if (t.type == Tok::swap) {
            op.swap = true;
            return true;
        }
        for (const auto& a : assigns) {
            if (t.type == a.tok) {
                op.assign = true;
                op.assign_op = a.assign;
                return true;
            }
        }
        for (const auto& o : ops) {
            if (t.type == o.tok) {
                op.left = o.left;
                op.right = o.right;
                op.bin = o.bin;
                return true;
            }
        }
        if (t.type != Tok::symbol) return false;
        const std::string w = lower(t.text);
        for (const auto& o : words) {
            if (w == o.word) {
                op.left = o.left;
                op.right = o.right;
                op.bin = o.bin;
                return true;
            }
        }
        return false;
    }

    // Precedence climbing exactly as ExprTk's parse_expression: an operator binds when its left
    // precedence is at least `prec`, its right operand is parsed at its right precedence.
    NodePtr parse_expression(int prec) {
        // Bounded recursion (ExprTk limits its parser stack too).
        struct Depth {
            int& d;
            explicit Depth(int& depth)
                : d(++depth) {}
            ~Depth() { --d; }
        } depth(nesting_);
        if (nesting_ > kMaxNesting)
            fail(cur(), SB() << "expression nested more than " << kMaxNesting << " levels deep");
        NodePtr left = parse_branch(prec);
        for (;;) {
            OpInfo op;
            if (!binary_op(cur(), op)) {
                const std::string w = is(Tok::symbol) ? lower(cur().text) : "";
                if (w == "in" || w == "like" || w == "ilike")
                    fail(cur(), SB() << "string operator '" << cur().text << "' is not supported");
                break;
            }
            if (op.left < prec) break;
            const Token optok = cur();
            next();
            NodePtr right = parse_expression(op.right);
            left = combine(optok, op, std::move(left), std::move(right));
            if (prec == 0 && is(Tok::question)) left = parse_ternary(std::move(left));
        }
        return left;
    }

    void no_string(const Node& n) {
        if (n.kind == NK::str)
            fail_at(n.pos, "strings are only allowed as arguments of print() and println()");
    }
    [[noreturn]] void fail_at(const Pos& at, const std::string& msg) {
        error(at, msg);
        throw Syntax{};
    }

    // The storage an assignment may write: a writable variable, vector element or vector.
    void check_target(const Node& n, const Token& op) {
        if (n.kind == NK::var || n.kind == NK::vec || n.kind == NK::elem) {
            const Variable& v = unit_.vars[n.ref];
            if (!v.writable) error(n.pos, SB() << "'" << v.name << "' is read-only");
            else if (v.host) host_.assigned(v.name);
            return;
        }
        if (n.kind == NK::num && n.str.size())
            fail_at(n.pos, SB() << "cannot assign to the constant '" << n.str << "'");
        if (n.kind == NK::binary && n.str == "implicit")
            fail_at(n.pos, SB() << "the left side of " << to_string(op.type)
                                << " is not a variable: a missing ';' before it? (ExprTk reads "
                                << "'a b' as 'a*b')");
        fail_at(n.pos, SB() << "the left side of " << to_string(op.type)
                            << " is not a variable or vector element");
    }

    NodePtr combine(const Token& optok, const OpInfo& op, NodePtr left, NodePtr right) {
        no_string(*left);
        no_string(*right);
        if (op.assign) {
            check_target(*left, optok); // a vector value assigned to a scalar: its element 0
            auto n = std::make_unique<Node>();
            n->kind = NK::assign;
            n->pos = {optok.line, optok.offset};
            n->op = static_cast<int>(op.assign_op);
            n->kids.push_back(std::move(left));
            n->kids.push_back(std::move(right));
            return n;
        }
        if (op.swap) {
            for (const Node* side : {left.get(), right.get()}) {
                check_target(*side, optok);
                if (side->kind == NK::vec)
                    fail_at(side->pos, "'<=>' swaps scalars and vector elements only");
            }
            auto n = std::make_unique<Node>();
            n->kind = NK::swap;
            n->pos = {optok.line, optok.offset};
            n->kids.push_back(std::move(left));
            n->kids.push_back(std::move(right));
            return n;
        }
        if (is_pure_constant(*left) && is_pure_constant(*right))
            return number(apply(op.bin, left->num, right->num), left->pos);
        if (NodePtr s = simplify(op.bin, left, right)) return s;
        auto n = std::make_unique<Node>();
        n->kind = NK::binary;
        n->pos = {optok.line, optok.offset};
        n->op = static_cast<int>(op.bin);
        if (optok.inserted) n->str = "implicit";
        n->kids.push_back(std::move(left));
        n->kids.push_back(std::move(right));
        return n;
    }

    // ExprTk's compile-time rewrites of an operation with one literal operand, which decide the
    // value: 0*e, e*0 and 0/e are 0, e/0 is NaN, 0+e, e+0, 1*e, e*1 and e/1 are e. (ExprTk
    // skips them for a few operand shapes it compiles into special nodes, such as (x*y)/0, and
    // drops the side effects of the discarded operand; here they always apply and the side
    // effects are kept.)
    NodePtr simplify(BinOp op, NodePtr& left, NodePtr& right) {
        const bool lc = left->kind == NK::num, rc = right->kind == NK::num;
        if (lc == rc) return nullptr;
        if (is_vector_expr(*left) || is_vector_expr(*right)) return nullptr;
        const double c = lc ? left->num : right->num;
        NodePtr& other = lc ? right : left;
        const Pos at = left->pos;
        auto constant = [&](double v) {
            if (!has_side_effects(*other)) return number(v, at);
            auto block = std::make_unique<Node>();
            block->kind = NK::block;
            block->pos = at;
            block->kids.push_back(std::move(other));
            block->kids.push_back(number(v, at));
            return block;
        };
        if (c == 0 && op == BinOp::mul) return constant(0.0);
        if (c == 0 && op == BinOp::div) return constant(lc ? 0.0 : kNaN);
        if ((c == 0 && op == BinOp::add) || (c == 1 && op == BinOp::mul) ||
            (rc && c == 1 && op == BinOp::div))
            return std::move(other);
        return nullptr;
    }
    NodePtr parse_ternary(NodePtr condition) {
        const Token q = cur();
        next(); // ?
        no_string(*condition);
        NodePtr yes = parse_expression(0);
        expect(Tok::colon, "between the two values of '?:'");
        NodePtr no = parse_expression(0);
        no_string(*yes);
        no_string(*no);
        auto n = make(NK::cond, q);
        n->kids.push_back(std::move(condition));
        n->kids.push_back(std::move(yes));
        n->kids.push_back(std::move(no));
        return fold_condition(std::move(n));
    }

    // A condition that is a constant leaves only the branch taken (as ExprTk's compiler does).
    static NodePtr fold_condition(NodePtr n) {
        if (n->kids[0]->kind != NK::num) return n;
        NodePtr& taken = is_true(n->kids[0]->num) ? n->kids[1] : n->kids[2];
        if (taken) return std::move(taken);
        auto null = std::make_unique<Node>();
        null->kind = NK::null;
        null->pos = n->pos;
        return null;
    }

    NodePtr parse_branch(int prec) {
        const Token t = cur();
        NodePtr n;
        switch (t.type) {
        case Tok::number:
            n = number(t.value, {t.line, t.offset});
            next();
            break;
        case Tok::string:
            n = make(NK::str, t);
            n->str = t.text;
            next();
            break;
        case Tok::symbol:
            n = parse_symbol();
            break;
        case Tok::lparen:
            next();
            n = parse_expression(0);
            expect(Tok::rparen, "to close '('");
            break;
        case Tok::lbracket:
            next();
            n = parse_expression(0);
            expect(Tok::rbracket, "to close '['");
            break;
        case Tok::lbrace:
            n = parse_braces(true);
            break;
        case Tok::sub: {
            next();
            NodePtr k = parse_expression(11); // -x^2 is -(x^2); -x*y is (-x)*y
            no_string(*k);
            if (k->kind == NK::num) {
                k->num = -k->num;
                k->str.clear();
                n = std::move(k);
            } else {
                n = make(NK::neg, t);
                n->kids.push_back(std::move(k));
            }
            break;
        }
        case Tok::add:
            next();
            n = parse_expression(13);
            no_string(*n);
            break;
        case Tok::end:
            fail(t, "expected a value, found end of code (a missing value after an operator?)");
        default:
            fail(t, SB() << "expected a value, found " << describe(t));
        }
        if (prec == 0 && is(Tok::question)) n = parse_ternary(std::move(n));
        return n;
    }

    // ---- names -------------------------------------------------------------------------------

    NodePtr parse_symbol() {
        const Token t = cur();
        const std::string w = lower(t.text);
        if (w == "if") return parse_if();
        if (w == "while") return parse_while();
        if (w == "repeat") return parse_repeat();
        if (w == "for") return parse_for();
        if (w == "switch") return parse_switch(false);
        if (w == "[*]") return parse_switch(true);
        if (w == "var") return parse_var();
        if (w == "return") return parse_return();
        if (w == "swap") return parse_swap();
        if (w == "~") return parse_tilde();
        if (w == "null") {
            next();
            return make(NK::null, t);
        }
        if (w == "break") return parse_break();
        if (w == "continue") {
            if (loop_depth_ == 0) fail(t, "'continue' outside a loop");
            next();
            return make(NK::cont, t);
        }
        if (w == "not") {
            next();
            expect(Tok::lparen, "after 'not'");
            NodePtr k = parse_expression(0);
            expect(Tok::rparen, "to close 'not('");
            no_string(*k);
            if (k->kind == NK::num) return number(logical_not(k->num), {t.line, t.offset});
            auto n = make(NK::lnot, t);
            n->kids.push_back(std::move(k));
            return n;
        }
        if (w == "print" || w == "println") return parse_print(w == "println");
        if (w == "dot") return parse_dot();
        if (w == "function") fail(t, "a function can only be defined at the top level of a file");
        if (w == "else") fail(t, "'else' without a matching 'if' (a ';' between '}' and 'else'?)");
        if (reserved_words().count(w) && w != "pi" && w != "epsilon" && w != "inf")
            fail(t, SB() << "unexpected '" << t.text << "'");
        Aggregate agg;
        if (find_aggregate(w, agg)) return parse_aggregate(agg);
        if (const Builtin* b = find_builtin(w)) return parse_builtin(*b);
        if (w == "pi" || w == "epsilon" || w == "inf") {
            next();
            const double v = w == "pi"        ? std::numbers::pi
                             : w == "epsilon" ? 1e-10 // ExprTk's epsilon constant
                                              : std::numeric_limits<double>::infinity();
            NodePtr n = number(v, {t.line, t.offset});
            n->str = t.text; // remembered for "cannot assign to the constant"
            return n;
        }
        if (const int local = find_local(w); local >= 0) return variable_use(local);
        if (auto it = functions_.find(w); it != functions_.end()) return parse_call(it->second);
        if (const int hf = host_function(t.text); hf >= 0) return parse_host_call(hf);
        if (const int hv = host_variable(t); hv >= 0) return variable_use(hv);
        // Reported without unwinding, so the rest of the statement is checked too.
        const std::string why = host_.why_unknown(t.text);
        error(t, SB() << "unknown name '" << t.text << "'" << (why.empty() ? "" : ": ") << why);
        next();
        if (is(Tok::lparen)) arguments(t, true);
        return placeholder(t);
    }

    // Stands for something that was reported as an error (the code is never generated).
    NodePtr placeholder(const Token& t) {
        if (placeholder_var_ < 0) {
            Variable v;
            v.name = "<error>";
            placeholder_var_ = static_cast<int>(unit_.vars.size());
            unit_.vars.push_back(std::move(v));
        }
        auto n = make(NK::var, t);
        n->ref = placeholder_var_;
        return n;
    }

    int host_function(const std::string& name) {
        if (auto it = host_functions_.find(name); it != host_functions_.end()) return it->second;
        std::optional<Host::FunctionInfo> info = host_.function(name);
        if (!info || !info->fn) return -1;
        const int id = static_cast<int>(unit_.host_functions.size());
        unit_.host_functions.push_back(HostFunction{name, *info});
        host_functions_[name] = id;
        return id;
    }

    int host_variable(const Token& t) {
        if (auto it = host_vars_.find(t.text); it != host_vars_.end()) return it->second;
        std::optional<Binding> b = host_.resolve(t.text);
        if (!b) return -1;
        if (!b->address || b->size < 1)
            fail(t, SB() << "the host bound '" << t.text << "' to no storage");
        Variable v;
        v.name = t.text;
        v.host = true;
        v.writable = b->writable;
        v.address = b->address;
        v.size = b->size;
        v.vector = b->size > 1;
        v.pos = {t.line, t.offset};
        const int id = static_cast<int>(unit_.vars.size());
        unit_.vars.push_back(std::move(v));
        host_vars_[t.text] = id;
        return id;
    }

    NodePtr variable_use(int id) {
        const Token t = cur();
        next();
        const Variable v = unit_.vars[id]; // a copy: parsing the index may add variables
        if (!v.vector) {
            if (is(Tok::lbracket)) fail(cur(), SB() << "'" << v.name << "' is not a vector");
            auto n = make(NK::var, t);
            n->ref = id;
            return n;
        }
        if (!is(Tok::lbracket)) {
            auto n = make(NK::vec, t);
            n->ref = id;
            return n;
        }
        next();
        if (is(Tok::rbracket)) { // v[]: the size
            next();
            return number(v.size, {t.line, t.offset});
        }
        NodePtr index = parse_expression(0);
        expect(Tok::rbracket, "to close the index");
        no_string(*index);
        if (is_vector_expr(*index)) fail_at(index->pos, "a vector index must be a scalar");
        if (index->kind == NK::num && !(index->num >= 0 && index->num < v.size))
            fail_at(index->pos, SB() << "index " << index->num << " is out of range for '" << v.name
                                     << "' (size " << v.size << ")");
        auto n = make(NK::elem, t);
        n->ref = id;
        n->kids.push_back(std::move(index));
        return n;
    }

    // Arguments in parentheses; `(` may be omitted for no arguments when `optional_parens`.
    std::vector<NodePtr> arguments(const Token& name, bool optional_parens) {
        std::vector<NodePtr> args;
        if (!is(Tok::lparen)) {
            if (optional_parens) return args;
            fail(cur(),
                 SB() << "expected '(' after '" << name.text << "', found " << describe(cur()));
        }
        next();
        if (is(Tok::rparen)) {
            next();
            return args;
        }
        for (;;) {
            args.push_back(parse_expression(0));
            if (is(Tok::rparen)) {
                next();
                return args;
            }
            expect(Tok::comma, SB() << "between the arguments of '" << name.text << "'");
        }
    }

    void scalar_args(const Token& name, const std::vector<NodePtr>& args) {
        for (const NodePtr& a : args) {
            no_string(*a);
            if (is_vector_expr(*a))
                fail_at(a->pos, SB() << "'" << name.text << "' takes scalar arguments");
        }
    }

    NodePtr parse_builtin(const Builtin& b) {
        const Token t = cur();
        next();
        std::vector<NodePtr> args = arguments(t, false);
        if (static_cast<int>(args.size()) != b.arity)
            fail(t, SB() << "'" << t.text << "' takes " << b.arity << " argument"
                         << (b.arity == 1 ? "" : "s") << ", got " << args.size());
        bool constant = true;
        for (const NodePtr& a : args) {
            no_string(*a);
            constant = constant && a->kind == NK::num;
        }
        if (constant) {
            double v[3] = {0, 0, 0};
            for (std::size_t i = 0; i < args.size(); ++i) v[i] = args[i]->num;
            return number(call(b, v), {t.line, t.offset});
        }
        auto n = make(NK::builtin, t);
        n->builtin = &b;
        n->kids = std::move(args);
        return n;
    }

    NodePtr parse_aggregate(Aggregate agg) {
        const Token t = cur();
        next();
        std::vector<NodePtr> args = arguments(t, false);
        if (args.empty()) fail(t, SB() << "'" << t.text << "' needs at least one argument");
        for (const NodePtr& a : args) no_string(*a);
        const bool vector = args.size() == 1 && is_vector_expr(*args[0]);
        if (!vector) scalar_args(t, args);
        if (vector && (agg == Aggregate::mand || agg == Aggregate::mor))
            fail(t, SB() << "'" << t.text << "' takes scalar arguments");
        if (std::all_of(args.begin(), args.end(),
                        [](const NodePtr& a) { return a->kind == NK::num; }))
            return number(fold(agg, args), {t.line, t.offset});
        auto n = make(NK::aggregate, t);
        n->op = static_cast<int>(agg);
        n->kids = std::move(args);
        return n;
    }

    // Value of an aggregate of constants, computed as the evaluator does.
    static double fold(Aggregate agg, const std::vector<NodePtr>& args) {
        double r = args[0]->num;
        switch (agg) {
        case Aggregate::mand:
        case Aggregate::mor:
            for (const NodePtr& a : args)
                if (is_true(a->num) != (agg == Aggregate::mand))
                    return agg == Aggregate::mand ? 0 : 1;
            return agg == Aggregate::mand ? 1 : 0;
        default:
            break;
        }
        if (agg == Aggregate::min || agg == Aggregate::max)
            return min_max(agg == Aggregate::max, args.size(),
                           [&](std::size_t i) { return args[i]->num; });
        for (std::size_t i = 1; i < args.size(); ++i)
            r = agg == Aggregate::mul ? r * args[i]->num : r + args[i]->num;
        return agg == Aggregate::avg ? r / static_cast<double>(args.size()) : r;
    }

    NodePtr parse_print(bool newline) {
        const Token t = cur();
        next();
        auto n = make(NK::print, t);
        n->op = newline ? 1 : 0;
        n->kids = arguments(t, true);
        for (const NodePtr& a : n->kids)
            if (a->kind != NK::str && a->kind != NK::vec && is_vector_expr(*a))
                fail_at(a->pos, "print() takes vectors, not vector expressions");
        return n;
    }

    NodePtr parse_dot() {
        const Token t = cur();
        next();
        auto n = make(NK::dot, t);
        n->kids = arguments(t, false);
        if (n->kids.size() != 2 && n->kids.size() != 4)
            fail(t, SB() << "dot() takes 2 vectors and optionally a range r0, r1, got "
                         << n->kids.size() << " arguments");
        for (std::size_t i = 0; i < n->kids.size(); ++i) {
            const Node& a = *n->kids[i];
            no_string(a);
            if (i < 2 && a.kind != NK::vec) fail_at(a.pos, "dot() takes vectors (by name)");
            if (i >= 2 && is_vector_expr(a)) fail_at(a.pos, "a dot() range bound must be a scalar");
        }
        return n;
    }

    NodePtr parse_call(int id) {
        const Token t = cur();
        next();
        const Function& f = unit_.functions[id]; // (functions are all declared before parsing)
        std::vector<NodePtr> args = arguments(t, f.params.empty());
        if (args.size() != f.params.size())
            fail(t, SB() << "function '" << f.name << "' takes " << f.params.size() << " argument"
                         << (f.params.size() == 1 ? "" : "s") << ", got " << args.size());
        scalar_args(t, args);
        auto n = make(NK::call, t);
        n->ref = id;
        n->kids = std::move(args);
        return n;
    }

    NodePtr parse_host_call(int id) {
        const Token t = cur();
        next();
        const HostFunction f = unit_.host_functions[id]; // a copy: arguments may add functions
        std::vector<NodePtr> args = arguments(t, f.info.min_args == 0);
        const int n_args = static_cast<int>(args.size());
        if (n_args < f.info.min_args || n_args > f.info.max_args) {
            SB msg;
            msg << "'" << f.name << "' takes ";
            if (f.info.min_args == f.info.max_args)
                msg << f.info.min_args;
            else
                msg << f.info.min_args << " to " << f.info.max_args;
            msg << " arguments, got " << n_args;
            fail(t, msg);
        }
        for (const NodePtr& a : args)
            if (a->kind == NK::str)
                fail_at(a->pos, SB() << "string arguments to '" << f.name << "' are not supported");
        scalar_args(t, args);
        auto n = make(NK::host_call, t);
        n->ref = id;
        n->kids = std::move(args);
        return n;
    }

    // ---- statements --------------------------------------------------------------------------

    NodePtr parse_if() {
        const Token t = cur();
        next();
        expect(Tok::lparen, "after 'if'");
        NodePtr condition = parse_expression(0);
        no_string(*condition);
        auto n = make(NK::cond, t);
        n->kids.push_back(std::move(condition));
        if (is(Tok::comma)) { // if (c, a, b)
            next();
            n->kids.push_back(parse_expression(0));
            expect(Tok::comma, "between the values of 'if(c, a, b)'");
            n->kids.push_back(parse_expression(0));
            expect(Tok::rparen, "to close 'if(c, a, b)'");
            no_string(*n->kids[1]);
            no_string(*n->kids[2]);
            return fold_condition(std::move(n));
        }
        expect(Tok::rparen, "after the condition of 'if'");
        if (is(Tok::mul) && cur().inserted) next(); // `if (c) x := 1;`: ExprTk skips the '*'
        if (is(Tok::lbrace)) {
            n->kids.push_back(parse_braces());
        } else {
            n->kids.push_back(parse_expression(0));
            if (!is(Tok::semicolon))
                fail(cur(),
                     SB() << "expected ';' after the statement of 'if', found " << describe(cur()));
        }
        no_string(*n->kids[1]);
        if (is_word(cur(), "else") || (is(Tok::semicolon) && is_word(peek(), "else"))) {
            if (is(Tok::semicolon)) next();
            next(); // else
            if (is(Tok::lbrace)) {
                n->kids.push_back(parse_braces());
            } else if (is_word(cur(), "if")) {
                n->kids.push_back(parse_if());
            } else {
                n->kids.push_back(parse_expression(0));
                if (is(Tok::semicolon))
                    next();
                else if (!is(Tok::rbrace) && !is(Tok::question))
                    fail(cur(), SB() << "expected ';' after the statement of 'else', found "
                                     << describe(cur()));
            }
            no_string(*n->kids[2]);
        } else {
            n->kids.push_back(nullptr);
        }
        return fold_condition(std::move(n));
    }

    NodePtr parse_while() {
        const Token t = cur();
        next();
        expect(Tok::lparen, "after 'while'");
        NodePtr condition = parse_expression(0);
        no_string(*condition);
        expect(Tok::rparen, "after the condition of 'while'");
        LoopGuard loop(*this);
        auto n = make(NK::loop_while, t);
        n->kids.push_back(std::move(condition));
        n->kids.push_back(parse_sequence("body of 'while'"));
        return n;
    }

    NodePtr parse_repeat() {
        const Token t = cur();
        next();
        auto body = make(NK::block, t);
        {
            LoopGuard loop(*this);
            ScopeGuard scope(*this);
            while (!is_word(cur(), "until")) {
                if (is(Tok::end)) fail(t, "'repeat' without 'until'");
                if (is(Tok::semicolon)) {
                    next();
                    continue;
                }
                body->kids.push_back(parse_expression(0));
            }
        }
        next(); // until
        expect(Tok::lparen, "after 'until'");
        NodePtr condition = parse_expression(0);
        no_string(*condition);
        expect(Tok::rparen, "after the condition of 'until'");
        auto n = make(NK::loop_repeat, t);
        n->kids.push_back(std::move(body));
        n->kids.push_back(std::move(condition));
        return n;
    }

    NodePtr parse_for() {
        const Token t = cur();
        next();
        ScopeGuard scope(*this);
        expect(Tok::lparen, "after 'for'");
        NodePtr init, condition, increment;
        if (is(Tok::semicolon))
            ecmc_refuses(cur(), "'for' without an initialiser",
                         "'for (var i := 0; ...)', or 'while (condition) { ... }'");
        if (!is(Tok::semicolon)) {
            if (is_word(cur(), "var")) {
                next();
                const Token name = cur();
                if (name.type != Tok::symbol || peek().type != Tok::assign)
                    fail(name, "expected 'var name := value' in the initialiser of 'for'");
                const int id = declare(name, false, 1);
                auto decl = make(NK::var_decl, name);
                decl->ref = id;
                decl->op = 1; // the assignment below initialises it
                auto block = make(NK::block, name);
                block->kids.push_back(std::move(decl));
                block->kids.push_back(parse_expression(0));
                init = std::move(block);
            } else {
                init = parse_expression(0);
            }
        }
        expect(Tok::semicolon, "after the initialiser of 'for'");
        if (!is(Tok::semicolon)) condition = parse_expression(0);
        expect(Tok::semicolon, "after the condition of 'for'");
        if (!is(Tok::rparen)) increment = parse_expression(0);
        expect(Tok::rparen, "after the increment of 'for'");
        LoopGuard loop(*this);
        auto n = make(NK::loop_for, t);
        n->kids.push_back(std::move(init));
        n->kids.push_back(std::move(condition));
        n->kids.push_back(std::move(increment));
        n->kids.push_back(parse_sequence("body of 'for'"));
        return n;
    }

    NodePtr parse_switch(bool multi) {
        const Token t = cur();
        next();
        expect(Tok::lbrace, multi ? "after '[*]'" : "after 'switch'");
        auto n = make(multi ? NK::mswitch : NK::switch_, t);
        bool has_default = false;
        while (!is(Tok::rbrace)) {
            if (is(Tok::semicolon)) {
                empty_statement(cur());
                next();
                continue;
            }
            const bool is_case = is_word(cur(), "case");
            if (!is_case && !(is_word(cur(), "default") && !multi && !has_default))
                fail(cur(), SB() << "expected 'case'"
                                 << (multi || has_default ? "" : " or 'default'") << ", found "
                                 << describe(cur()));
            next();
            if (is_case) {
                n->kids.push_back(parse_expression(0));
                no_string(*n->kids.back());
            } else {
                has_default = true;
            }
            expect(Tok::colon, is_case ? "after the case condition" : "after 'default'");
            n->kids.push_back(is(Tok::lbrace) ? parse_braces() : parse_expression(0));
            no_string(*n->kids.back());
            if (is(Tok::semicolon))
                next();
            else
                ecmc_refuses(cur(), SB() << "a '" << (is_case ? "case" : "default")
                                         << "' without ';' after its statement",
                             SB() << "'" << (is_case ? "case c : ...;" : "default : ...;")
                                  << "' (a ';' also after a '{ }' body)");
        }
        next();
        n->op = has_default ? 1 : 0;
        return n;
    }

    NodePtr parse_var() {
        const Token t = cur();
        next();
        const Token name = cur();
        if (name.type != Tok::symbol)
            fail(name, SB() << "expected a name after 'var', found " << describe(name));
        next();
        if (is(Tok::lbracket)) return parse_vector_def(t, name);
        auto n = make(NK::var_decl, t);
        if (is(Tok::lbrace)) { // var x{}: not initialised
            next();
            expect(Tok::rbrace, "in 'var x{}'");
            n->op = 1;
        } else if (is(Tok::assign)) {
            next();
            NodePtr init = parse_expression(0);
            if (init->kind == NK::str) fail_at(init->pos, "string variables are not supported");
            if (is_vector_expr(*init))
                fail_at(init->pos, SB() << "'" << name.text << "' is a scalar; define a vector "
                                        << "with 'var " << name.text << "[n] := ...'");
            n->kids.push_back(std::move(init));
        }
        end_of_definition(name);
        n->ref = declare(name, false, 1);
        return n;
    }

    void end_of_definition(const Token& name) {
        if (!(is(Tok::semicolon) || is(Tok::rparen) || is(Tok::rbrace) || is(Tok::rbracket) ||
              is(Tok::end)))
            fail(cur(), SB() << "expected ';' after the definition of '" << name.text << "', found "
                             << describe(cur()));
    }

    NodePtr parse_vector_def(const Token& t, const Token& name) {
        next(); // [
        NodePtr size_expr = parse_expression(0);
        expect(Tok::rbracket, "after the vector size");
        if (size_expr->kind != NK::num)
            fail_at(size_expr->pos,
                    SB() << "the size of vector '" << name.text << "' must be a constant");
        const double size = size_expr->num;
        if (!(size >= 1 && size <= 1e6 && size == std::trunc(size)))
            fail_at(size_expr->pos, SB() << "the size of vector '" << name.text
                                         << "' must be an integer from 1 to 1000000, got " << size);
        auto n = make(NK::vec_decl, t);
        n->op = static_cast<int>(VecInit::zero);
        if (is(Tok::assign)) {
            next();
            if (is(Tok::lbracket)) { // [x]: every element
                next();
                n->kids.push_back(parse_expression(0));
                expect(Tok::rbracket, "after the initial value");
                n->op = static_cast<int>(VecInit::single);
            } else if (is(Tok::lbrace)) {
                next();
                n->op = static_cast<int>(VecInit::list);
                while (!is(Tok::rbrace)) {
                    n->kids.push_back(parse_expression(0));
                    if (is(Tok::rbrace)) break;
                    expect(Tok::comma, "between initial values");
                }
                next();
                if (n->kids.size() > static_cast<std::size_t>(size))
                    fail(name, SB() << "vector '" << name.text << "' has " << size
                                    << " elements but " << n->kids.size() << " initial values");
            } else if (is_word(cur(), "null")) {
                next();
                n->op = static_cast<int>(VecInit::none);
            } else {
                NodePtr from = parse_expression(0);
                if (!is_vector_expr(*from))
                    fail_at(from->pos, SB() << "expected '{...}', '[value]' or a vector to "
                                            << "initialise '" << name.text << "'");
                n->kids.push_back(std::move(from));
                n->op = static_cast<int>(VecInit::vector);
            }
            for (const NodePtr& k : n->kids) {
                no_string(*k);
                if (n->op != static_cast<int>(VecInit::vector) && is_vector_expr(*k))
                    fail_at(k->pos, "an initial value must be a scalar");
            }
        }
        end_of_definition(name);
        n->ref = declare(name, true, static_cast<int>(size));
        return n;
    }

    NodePtr parse_break() {
        const Token t = cur();
        if (loop_depth_ == 0) fail(t, "'break' outside a loop");
        next();
        auto n = make(NK::brk, t);
        if (is(Tok::lbracket)) {
            next();
            n->kids.push_back(parse_expression(0));
            no_string(*n->kids[0]);
            expect(Tok::rbracket, "after the value of 'break['");
        } else {
            n->kids.push_back(nullptr);
        }
        return n;
    }

    NodePtr parse_return() {
        const Token t = cur();
        next();
        expect(Tok::lbracket, "after 'return' (ExprTk writes 'return [];')");
        auto n = make(NK::ret, t);
        while (!is(Tok::rbracket)) {
            n->kids.push_back(parse_expression(0));
            if (is(Tok::rbracket)) break;
            expect(Tok::comma, "between return values");
        }
        next();
        return n;
    }

    NodePtr parse_swap() {
        const Token t = cur();
        next();
        std::vector<NodePtr> args = arguments(t, false);
        if (args.size() != 2) fail(t, "swap() takes 2 arguments");
        OpInfo op;
        op.swap = true;
        Token optok = t;
        optok.type = Tok::swap;
        return combine(optok, op, std::move(args[0]), std::move(args[1]));
    }

    NodePtr parse_tilde() {
        const Token t = cur();
        next();
        if (!is(Tok::lbrace) && !is(Tok::lparen))
            fail(cur(), SB() << "expected '{' or '(' after '~', found " << describe(cur()));
        return parse_sequence("'~' sequence");
    }

    const Source& src_;
    Host& host_;
    Diagnostics& diags_;
    Unit& unit_;
    const std::vector<Token>* toks_ = nullptr;
    std::size_t pos_ = 0;
    std::vector<int> depth_; // bracket depth before each token
    std::vector<std::map<std::string, int>> scopes_;
    int frame_ = -1;
    int loop_depth_ = 0;
    int placeholder_var_ = -1;
    int nesting_ = 0;
    bool strict_ = false; // report what ECMC's ExprTk refuses (CompileOptions::strict)
    static constexpr int kMaxNesting = 400;
    std::map<std::string, int> functions_; // lower-case name -> Unit::functions
    std::map<std::string, int> host_functions_;
    std::map<std::string, int> host_vars_;
};

} // namespace

Unit parse(const Source& src, const std::vector<Token>& program,
           const std::vector<std::vector<Token>>& libraries, Host& host, Diagnostics& diags,
           bool strict) {
    Unit unit;
    Parser p(src, host, diags, unit);
    p.strict(strict);
    for (const auto& lib : libraries) p.declare_functions(lib);
    p.declare_functions(program);
    for (const auto& lib : libraries) p.parse_file(lib, true);
    unit.main = p.parse_file(program, false);
    return unit;
}

} // namespace beamctl::plc::detail
