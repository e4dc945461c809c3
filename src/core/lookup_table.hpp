// ECMC's lookup table (ecmcLookupTable; ecmccfg loadLUTFile.cmd, encoder `lookuptable:`): rows of
// x and y, linear interpolation between them, clamped to the first/last y outside the table.
//
// File format, as ECMC: one row per line, x then y, separated by spaces, tabs or commas (further
// numbers on the line are ignored); `#` at the start of a line is a comment; `PREC=<n>` sets the
// print precision (default 10). At least 3 rows; x strictly increasing. Deliberately more lenient
// than ECMC: whitespace-only lines and a CR line end (CRLF files) are accepted, and so is a `#`
// after leading spaces.
// Threading: parsed before the cycle starts; value() is RT-safe (no allocation, O(log n)).
#pragma once

#include <string>
#include <vector>

namespace beamctl {

class LookupTable {
public:
    LookupTable() = default;
    // Throws Error "file:line: what" (ECMC's error id in the text: 0x1441A too few rows,
    // 0x1441B x not increasing, 0x1441C cannot be opened, 0x1441D not two numbers).
    static LookupTable parse(const std::string& text, const std::string& file);
    static LookupTable load(const std::string& path);

    double value(double x) const noexcept;
    std::size_t size() const noexcept { return x_.size(); }
    int precision() const noexcept { return prec_; }
    double x(std::size_t i) const { return x_.at(i); }
    double y(std::size_t i) const { return y_.at(i); }

private:
    std::vector<double> x_, y_;
    int prec_ = 10;
};

} // namespace beamctl
