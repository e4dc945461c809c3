// ECMC's lookup table files (core/lookup_table.hpp): the format, its errors with file:line and
// ECMC's ids, interpolation and clamping; and the encoder correction that uses one.
#include "core/error.hpp"
#include "core/lookup_table.hpp"

#include <gtest/gtest.h>

using beamctl::Error;
using beamctl::LookupTable;

namespace {
std::string error_of(const std::string& text) {
    try {
        LookupTable::parse(text, "t.lut");
    } catch (const Error& e) {
        return e.what();
    }
    return "<none>";
}
} // namespace

TEST(LookupTable, EcmcFormat) {
    // ecmccfg's enc.corr example: comments, PREC lines anywhere, spaces
    LookupTable t = LookupTable::parse("######\n# comment\nPREC=5\n-10 -10.123456789\n0 0.123456789\n"
                                       "10 10.123456789\nPREC=6\n12.67898 12.3456789\n",
                                       "enc.corr");
    EXPECT_EQ(t.size(), 4u);
    EXPECT_EQ(t.precision(), 6);
    EXPECT_DOUBLE_EQ(t.x(3), 12.67898);
    // commas, tabs, extra columns, CRLF, blank lines (the last two ECMC refuses; beamctl takes)
    LookupTable u = LookupTable::parse("1,10\r\n\n2\t20 7 8\r\n   \n3 , 30\r\n", "u.lut");
    EXPECT_EQ(u.size(), 3u);
    EXPECT_DOUBLE_EQ(u.y(2), 30);
}

TEST(LookupTable, InterpolatesAndClamps) {
    LookupTable t = LookupTable::parse("0 0\n1 10\n3 30\n4 0\n", "t.lut");
    EXPECT_DOUBLE_EQ(t.value(0.5), 5);
    EXPECT_DOUBLE_EQ(t.value(1), 10);
    EXPECT_DOUBLE_EQ(t.value(2), 20);
    EXPECT_DOUBLE_EQ(t.value(3.5), 15);
    EXPECT_DOUBLE_EQ(t.value(-7), 0);  // first y below the table
    EXPECT_DOUBLE_EQ(t.value(99), 0);  // last y above it: no extrapolation
    EXPECT_DOUBLE_EQ(t.value(3.999999), 30 - 30 * 0.999999);
}

TEST(LookupTable, ErrorsNameTheLineAndEcmcsId) {
    EXPECT_EQ(error_of("0 0\n1 1\n"), "t.lut: 2 rows; a lookup table needs at least 3 (0x1441A)");
    EXPECT_EQ(error_of("0 0\n2 1\n1 1\n"), "t.lut:3: x 1 should be greater than the row before's 2 (x strictly increasing, 0x1441B)");
    EXPECT_EQ(error_of("0 0\n1 x\n2 2\n"), "t.lut:2: '1 x' is not a row of two numbers, x and y (0x1441D)");
    EXPECT_EQ(error_of("PREC=a\n"), "t.lut:1: 'PREC=a' should be PREC=<0..17> (0x1441D)");
    try {
        LookupTable::load("/nonexistent/t.lut");
        FAIL();
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "/nonexistent/t.lut: cannot open the lookup table (0x1441C)");
    }
}
