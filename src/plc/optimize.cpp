#include "plc/optimize.hpp"

#include "plc/parser.hpp"

#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <utility>

namespace beamctl::plc::detail {

namespace {

// Every variable an assignment, a swap or a declaration without a value writes.
void collect_written(const Node& n, std::set<int>& written) {
    switch (n.kind) {
    case NK::assign:
    case NK::swap:
        for (const NodePtr& k : n.kids)
            if (k && (k->kind == NK::var || k->kind == NK::vec || k->kind == NK::elem)) written.insert(k->ref);
        break;
    case NK::var_decl:
        if (n.op == 1) written.insert(n.ref); // `var x{}`, a for initialiser: assigned later
        break;
    default:
        break;
    }
    for (const NodePtr& k : n.kids)
        if (k) collect_written(*k, written);
}

// Scalar `var`s initialised with a number (or nothing: 0) and never written: their values.
void collect_constants(const Node& n, const Unit& unit, const std::set<int>& written,
                       std::map<int, double>& constants) {
    if (n.kind == NK::var_decl && n.op != 1 && !written.count(n.ref) && !unit.vars[n.ref].vector &&
        !unit.vars[n.ref].host) {
        const Node* init = n.kids.empty() ? nullptr : n.kids[0].get();
        if (!init)
            constants[n.ref] = 0.0;
        else if (init->kind == NK::num)
            constants[n.ref] = init->num;
    }
    for (const NodePtr& k : n.kids)
        if (k) collect_constants(*k, unit, written, constants);
}

NodePtr number_like(const Node& at, double v, bool from_var) {
    auto n = std::make_unique<Node>();
    n->kind = NK::num;
    n->pos = at.pos;
    n->num = v;
    n->from_var = from_var;
    return n;
}

bool is_num(const NodePtr& n) {
    return n && n->kind == NK::num;
}

// Rewrites `slot` in place; true when anything changed.
bool rewrite(NodePtr& slot, const std::map<int, double>& constants) {
    if (!slot) return false;
    Node& n = *slot;
    bool changed = false;
    for (NodePtr& k : n.kids) changed |= rewrite(k, constants);
    switch (n.kind) {
    case NK::var:
        if (auto it = constants.find(n.ref); it != constants.end()) {
            slot = number_like(n, it->second, true);
            return true;
        }
        return changed;
    case NK::var_decl:
        // The declaration of a constant: nothing to store any more; its value if used.
        if (auto it = constants.find(n.ref); it != constants.end()) {
            slot = number_like(n, it->second, true);
            return true;
        }
        return changed;
    case NK::neg:
        if (is_num(n.kids[0])) {
            slot = number_like(n, -n.kids[0]->num, n.kids[0]->from_var);
            return true;
        }
        return changed;
    case NK::lnot:
        if (is_num(n.kids[0])) {
            slot = number_like(n, logical_not(n.kids[0]->num), n.kids[0]->from_var);
            return true;
        }
        return changed;
    case NK::binary: {
        if (is_num(n.kids[0]) != is_num(n.kids[1]) && !is_vector_expr(n)) {
            // Identities exact for every double (NaN, infinities and -0 included): x - 0,
            // x * 1, 1 * x, x / 1 are x.
            const bool left = is_num(n.kids[0]);
            const double c = left ? n.kids[0]->num : n.kids[1]->num;
            const auto op = static_cast<BinOp>(n.op);
            const bool positive_zero = c == 0 && !std::signbit(c);
            if ((!left && op == BinOp::sub && positive_zero) || (op == BinOp::mul && c == 1) ||
                (!left && op == BinOp::div && c == 1)) {
                NodePtr keep = std::move(left ? n.kids[1] : n.kids[0]);
                slot = std::move(keep);
                return true;
            }
            return changed;
        }
        if (!is_num(n.kids[0]) || !is_num(n.kids[1])) return changed;
        const auto op = static_cast<BinOp>(n.op);
        const double a = n.kids[0]->num, b = n.kids[1]->num;
        double v;
        if (op == BinOp::pow && !n.kids[1]->from_var) {
            // `var ^ literal`: as the code generator reduces it (and ExprTk computes it)
            v = is_int_pow_exponent(b) ? (b < 0 ? 1.0 / int_pow(a, std::uint32_t(-b)) : int_pow(a, std::uint32_t(b)))
                : b == 0.5                ? pow_half(a)
                                          : apply(op, a, b);
        } else {
            v = apply(op, a, b);
        }
        slot = number_like(n, v, n.kids[0]->from_var || n.kids[1]->from_var);
        return true;
    }
    case NK::builtin: {
        double args[3] = {0, 0, 0};
        bool from_var = false;
        for (std::size_t i = 0; i < n.kids.size(); ++i) {
            if (!is_num(n.kids[i])) return changed;
            args[i] = n.kids[i]->num;
            from_var |= n.kids[i]->from_var;
        }
        slot = number_like(n, call(*n.builtin, args), from_var);
        return true;
    }
    case NK::cond:
        if (is_num(n.kids[0])) {
            NodePtr& taken = is_true(n.kids[0]->num) ? n.kids[1] : n.kids[2];
            if (taken) {
                NodePtr keep = std::move(taken);
                slot = std::move(keep);
            } else {
                auto null = std::make_unique<Node>();
                null->kind = NK::null;
                null->pos = n.pos;
                slot = std::move(null);
            }
            return true;
        }
        return changed;
    default:
        return changed;
    }
}

} // namespace

void propagate_constants(Unit& unit) {
    std::set<int> written;
    if (unit.main) collect_written(*unit.main, written);
    for (const Function& f : unit.functions)
        if (f.body) collect_written(*f.body, written);
    for (int round = 0; round < 16; ++round) {
        std::map<int, double> constants;
        if (unit.main) collect_constants(*unit.main, unit, written, constants);
        for (const Function& f : unit.functions)
            if (f.body) collect_constants(*f.body, unit, written, constants);
        if (constants.empty()) return;
        bool changed = rewrite(unit.main, constants);
        for (Function& f : unit.functions) changed |= rewrite(f.body, constants);
        if (!changed) return;
    }
}

} // namespace beamctl::plc::detail
