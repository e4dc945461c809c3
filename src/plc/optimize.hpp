// Compile-time rewrites of the syntax tree that keep every value bit for bit. Between parsing and
// code generation; compile-time only.
#pragma once

#include "plc/ast.hpp"

namespace beamctl::plc::detail {

// Constant `var`s: a scalar `var` initialised with a number and never written afterwards is
// that number wherever it is read, and every operation whose operands are all numbers is
// computed once, here, with the evaluator's own arithmetic (so the shipped kinematics'
// geometry - `var dz := 800; ... dz / 2` - costs nothing per scan). Conditions that become
// numbers keep only the branch taken. Repeated until nothing changes (a `var` initialised from
// constant `var`s becomes one too). Rules that are not exact in IEEE arithmetic (x*0 -> 0) are
// not applied: they stay for literals in the source only, as ExprTk applies them; the exact
// ones (x - 0, x * 1, x / 1) are.
void propagate_constants(Unit& unit);

} // namespace beamctl::plc::detail
