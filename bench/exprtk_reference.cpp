// See exprtk_reference.hpp. ExprTk's default parser settings, as ECMC's exprtkWrap compiles a
// PLC, with ExprTk's vector package (dot, ...) and println/print as no-op functions taking any
// arguments (ExprTk's own print functions, minus the output).
#include "exprtk_reference.hpp"

#include <exprtk.hpp>

namespace exprtk_reference {

using symbol_table_t = exprtk::symbol_table<double>;
using expression_t = exprtk::expression<double>;
using parser_t = exprtk::parser<double>;

namespace {

// Any unknown name becomes a variable of the caller's map.
struct Resolver : parser_t::unknown_symbol_resolver {
    std::map<std::string, double>* vars = nullptr;
    Resolver()
        : parser_t::unknown_symbol_resolver(parser_t::unknown_symbol_resolver::e_usrmode_extended) {}
    bool process(const std::string& name, symbol_table_t& table, std::string&) override {
        return table.add_variable(name, (*vars)[name]);
    }
};

// ECMC's print/println: variadic, strings and numbers; nothing printed in a benchmark.
struct Print : exprtk::igeneric_function<double> {
    Print()
        : exprtk::igeneric_function<double>("") {
        exprtk::enable_zero_parameters(*this);
    }
    double operator()(parameter_list_t) override { return 0; }
};

} // namespace

struct Expression::Impl {
    symbol_table_t table;
    exprtk::rtl::vecops::package<double> vecops;
    expression_t expression;
    Print print;
};

std::unique_ptr<Expression> Expression::compile(const std::string& text,
                                                std::map<std::string, double>& vars,
                                                std::string& error) {
    auto impl = std::make_unique<Impl>();
    impl->table.add_constants();
    impl->table.add_package(impl->vecops);
    impl->table.add_function("println", impl->print);
    impl->table.add_function("print", impl->print);
    impl->expression.register_symbol_table(impl->table);
    parser_t parser;
    Resolver resolver;
    resolver.vars = &vars;
    parser.enable_unknown_symbol_resolver(&resolver);
    if (!parser.compile(text, impl->expression)) {
        error = parser.error();
        for (std::size_t i = 0; i < parser.error_count(); ++i) {
            const auto e = parser.get_error(i);
            error += "\n  at " + std::to_string(e.token.position) + ": " + e.diagnostic;
        }
        return nullptr;
    }
    return std::unique_ptr<Expression>(new Expression(std::move(impl)));
}

Expression::Expression(std::unique_ptr<Impl> impl)
    : impl_(std::move(impl)) {}
Expression::~Expression() = default;

double Expression::value() {
    return impl_->expression.value();
}

} // namespace exprtk_reference
