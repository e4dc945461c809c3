// A number as automation's messages and generated fields print it: %g with `significant` digits
// ("53.8158" at 6, "40.2180793" at 9).
#pragma once

#include <cstdio>
#include <string>

namespace beamctl::automation {

inline std::string number_text(double v, int significant) {
    char b[40];
    std::snprintf(b, sizeof b, "%.*g", significant, v);
    return b;
}

} // namespace beamctl::automation
