// Runs the strict-mode table (tests/unit/plc/strict_ecmc_table.hpp) through ExprTk and reports
// every case whose recorded verdict ExprTk contradicts; exit 1 if any. Built with bench_plc's
// ExprTk reference (BEAMCTL_EXPRTK_DIR); the unit test checks beamctl against the same table.
#include "exprtk_reference.hpp"
#include "strict_ecmc_table.hpp"

#include <cstdio>

int main() {
    int wrong = 0, n = 0;
    for (const auto& c : beamctl::plc::test::kStrictCases) {
        std::map<std::string, double> vars;
        std::string error;
        const bool accepts = exprtk_reference::Expression::compile(c.code, vars, error) != nullptr;
        ++n;
        if (accepts != c.exprtk_accepts) {
            ++wrong;
            std::printf("WRONG: ExprTk %s \"%s\"%s%s\n", accepts ? "accepts" : "refuses", c.code,
                        accepts ? "" : ": ", error.substr(0, error.find('\n')).c_str());
        }
    }
    std::printf("%d of %d verdicts confirmed by ExprTk\n", n - wrong, n);
    return wrong ? 1 : 0;
}
