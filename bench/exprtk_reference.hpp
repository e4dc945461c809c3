// ExprTk as ECMC runs a PLC (issue 18's reference): the text compiled once, every symbol it
// names bound by reference to a double of the caller's, `expression.value()` per scan. Built
// only when CMake's BEAMCTL_EXPRTK_DIR names a directory holding ExprTk's single header
// (exprtk.hpp, taken in at development time: never in the repository, never needed by CI).
#pragma once

#include <map>
#include <memory>
#include <string>

namespace exprtk_reference {

class Expression {
public:
    // Compiles `text`; a symbol it names that is not an ExprTk word or a `var` it declares is
    // bound to vars[symbol] (created at 0). Returns null and sets `error` if ExprTk refuses it.
    static std::unique_ptr<Expression> compile(const std::string& text,
                                               std::map<std::string, double>& vars, std::string& error);
    ~Expression();
    double value();

    struct Impl;

private:
    explicit Expression(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

} // namespace exprtk_reference
