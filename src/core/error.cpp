#include "core/error.hpp"

namespace beamctl {

std::string SourceLoc::str() const {
    return SB() << (file.empty() ? "<input>" : file) << ":" << line << ":" << col;
}

} // namespace beamctl
