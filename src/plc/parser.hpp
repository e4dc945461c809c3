// Parser: tokens -> syntax tree, with ExprTk's grammar and precedence and every name resolved
// through scopes, built-ins, `function`s and the Host. Compile-time only.
#pragma once

#include "plc/ast.hpp"
#include "plc/lexer.hpp"
#include "plc/program.hpp"
#include "plc/source.hpp"

#include <vector>

namespace beamctl::plc::detail {

// Parses the program and the libraries (files of `function` definitions) into one Unit.
// Errors go to `diags`; after a syntax error parsing resumes at the next top-level statement.
// `strict`: also an error for each construct beamctl accepts but ECMC's ExprTk refuses.
Unit parse(const Source& src, const std::vector<Token>& program,
           const std::vector<std::vector<Token>>& libraries, Host& host, Diagnostics& diags,
           bool strict = false);

// True when the expression's value is a vector (a vector, or element-wise arithmetic on one).
bool is_vector_expr(const Node& n);
// Elements of a vector expression: the smallest vector in it.
int vector_expr_size(const Node& n, const Unit& unit);

} // namespace beamctl::plc::detail
