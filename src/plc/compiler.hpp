// Compiler: syntax tree -> Program::Impl (instructions, memory layout, constants). Compile-time
// only; errors go to the Diagnostics.
#pragma once

#include "plc/ast.hpp"
#include "plc/code.hpp"
#include "plc/source.hpp"

#include <memory>

namespace beamctl::plc::detail {

std::unique_ptr<Program::Impl> generate(const Unit& unit, const Source& src, Host& host,
                                        const CompileOptions& options, Diagnostics& diags);

} // namespace beamctl::plc::detail
