#include "core/lookup_table.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace beamctl {

LookupTable LookupTable::parse(const std::string& text, const std::string& file) {
    LookupTable t;
    std::istringstream in(text);
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
        ++n;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        std::size_t first = line.find_first_not_of(" \t");
        if (first == std::string::npos || line[first] == '#') continue;
        std::string_view rest(line.c_str() + first);
        if (rest.rfind("PREC=", 0) == 0) {
            char* end = nullptr;
            long p = std::strtol(line.c_str() + first + 5, &end, 10);
            if (end == line.c_str() + first + 5 || *end != '\0' || p < 0 || p > 17)
                throw Error(SB() << file << ":" << n << ": '" << rest << "' should be PREC=<0..17> (0x1441D)");
            t.prec_ = int(p);
            continue;
        }
        std::replace(line.begin(), line.end(), ',', ' ');
        const char* p = line.c_str();
        char* end = nullptr;
        double x = std::strtod(p, &end);
        bool ok = end != p;
        const char* q = end;
        double y = ok ? std::strtod(q, &end) : 0;
        ok = ok && end != q && std::isfinite(x) && std::isfinite(y);
        if (!ok) throw Error(SB() << file << ":" << n << ": '" << rest << "' is not a row of two numbers, x and y (0x1441D)");
        if (!t.x_.empty() && !(x > t.x_.back()))
            throw Error(SB() << file << ":" << n << ": x " << x << " should be greater than the row before's " << t.x_.back()
                             << " (x strictly increasing, 0x1441B)");
        t.x_.push_back(x);
        t.y_.push_back(y);
    }
    if (t.x_.size() < 3) throw Error(SB() << file << ": " << t.x_.size() << " rows; a lookup table needs at least 3 (0x1441A)");
    return t;
}

LookupTable LookupTable::load(const std::string& path) {
    std::ifstream f(path);
    if (!f) throw Error(SB() << path << ": cannot open the lookup table (0x1441C)");
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), path);
}

double LookupTable::value(double x) const noexcept {
    if (x_.empty() || std::isnan(x)) return 0;
    if (x <= x_.front()) return y_.front();
    if (x >= x_.back()) return y_.back();
    std::size_t i = std::size_t(std::lower_bound(x_.begin(), x_.end(), x) - x_.begin()); // first x_i >= x
    double x0 = x_[i - 1], x1 = x_[i];
    return y_[i - 1] + (y_[i] - y_[i - 1]) * (x - x0) / (x1 - x0);
}

} // namespace beamctl
