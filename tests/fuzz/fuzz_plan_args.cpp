// libFuzzer: arbitrary bytes as a plan's Args text, as a CA client's put to $(P)<plan>:Args or the
// command line brings them (src/automation/plan.cpp). Crashes, UB, an accepted text whose values
// are not the plan's arguments (one finite value each), or a refusal without a reason, are bugs.
#include "automation/plan.hpp"

#include <cmath>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl::automation;
    static const std::vector<std::pair<std::string, double>> declared = {{"dwell", 0.05}, {"width", 0.1}, {"n", 41}, {"E1", 8}};
    const std::string text(reinterpret_cast<const char*>(data), size);
    std::vector<double> out = {1, 2, 3};
    std::string why;
    if (parse_plan_args(declared, text, out, why)) {
        if (out.size() != declared.size()) __builtin_trap();
        for (double v : out)
            if (!std::isfinite(v)) __builtin_trap();
    } else {
        if (why.empty() || why.size() > size + 200) __builtin_trap();
        if (out.size() != 3) __builtin_trap(); // a refused text changes nothing
    }
    std::vector<double> none;
    if (parse_plan_args({}, text, none, why) && !none.empty()) __builtin_trap();
    return 0;
}
