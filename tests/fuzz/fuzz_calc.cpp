// libFuzzer: arbitrary bytes as a calc expression (pv/calc.hpp, the CALC field of calc records);
// what compiles is performed on fixed args. Must never crash, hang or overrun: checks that an
// error points into the text, that compiling is deterministic and that arg usage stays in A..U.
#include "pv/calc.hpp"

#include <cmath>
#include <cstdint>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl::pv::calc;
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    Program p;
    CompileError err{};
    bool ok = compile(text, p, &err);
    // Longer texts too (as calc links may allow): the stack limit still bounds them.
    if (!ok && err.code == Errc::TooLong) ok = compile(text, p, &err, 4096);
    if (!ok) {
        if (err.position > size || err.message.empty()) __builtin_trap();
        return 0;
    }
    Program again;
    if (!compile(text, again, nullptr, 4096) || again.code != p.code) __builtin_trap();

    double args[kArgs];
    for (int i = 0; i < kArgs; ++i) args[i] = (i - 8) * 0.75;
    args[1] = NAN;
    args[2] = INFINITY;
    args[3] = -3e9;
    double value = 1.5;
    (void)perform(p, args, &value);

    uint32_t inputs = 0, stores = 0;
    arg_usage(p, &inputs, &stores);
    if ((inputs | stores) >> kArgs) __builtin_trap();
    return 0;
}
