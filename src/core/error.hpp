// beamctl::Error and the SB string builder: configuration, file and network code throws Error
// with the full context inline, e.g. `throw Error(SB() << path << ":" << line << ": bad value")`.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace beamctl {

// Builds a message inline: SB() << "what " << value.
class SB {
public:
    template <typename T> SB& operator<<(const T& v) {
        os_ << v;
        return *this;
    }
    std::string str() const { return os_.str(); }
    operator std::string() const { return os_.str(); }

private:
    std::ostringstream os_;
};

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& msg) : std::runtime_error(msg) {}
    explicit Error(const SB& sb) : std::runtime_error(sb.str()) {}
};

// A position in a text file, for error messages ("file:line:col").
struct SourceLoc {
    std::string file;
    int line = 0; // 1-based
    int col = 0;  // 1-based
    std::string str() const;
};

} // namespace beamctl
