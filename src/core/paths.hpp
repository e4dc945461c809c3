// Where a file named in a configuration file is: ECMC resolves relative names against the IOC's
// working directory, beamctl against the naming file's directory. Both are tried, the naming
// file's directory first.
#pragma once

#include <filesystem>
#include <string>

namespace beamctl {

// `name` as written in a file of directory `dir`: dir/name if it exists, else name relative to
// the working directory if that exists (ECMC's rule), else dir/name (for the error message).
inline std::string resolve_beside(const std::filesystem::path& dir, const std::string& name) {
    std::filesystem::path f = name;
    if (f.is_absolute()) return name;
    std::filesystem::path beside = dir / f;
    std::error_code ec;
    if (!std::filesystem::exists(beside, ec) && std::filesystem::exists(f, ec)) return f.string();
    return beside.string();
}

} // namespace beamctl
