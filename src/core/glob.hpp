// Glob matching of names (`*` any run, `?` one character), as dbl, `beamctl signals` and the
// shell's filters take them.
#pragma once

#include <string_view>

namespace beamctl {

inline bool glob_match(std::string_view pattern, std::string_view text) noexcept {
    std::size_t pi = 0, ti = 0, star = std::string_view::npos, mark = 0;
    while (ti < text.size()) {
        if (pi < pattern.size() && (pattern[pi] == '?' || pattern[pi] == text[ti])) {
            ++pi;
            ++ti;
        } else if (pi < pattern.size() && pattern[pi] == '*') {
            star = pi++;
            mark = ti;
        } else if (star != std::string_view::npos) {
            pi = star + 1;
            ti = ++mark;
        } else {
            return false;
        }
    }
    while (pi < pattern.size() && pattern[pi] == '*') ++pi;
    return pi == pattern.size();
}

} // namespace beamctl
