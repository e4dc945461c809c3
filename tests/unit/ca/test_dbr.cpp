// DBR type table (sizes and value offsets as libca's dbr_size/dbr_value_offset, spec §5) and
// payload encoding of values and metadata.
#include "ca/dbr.hpp"
#include "ca/protocol.hpp"
#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

using namespace beamctl;
using namespace beamctl::ca;

namespace {

struct Expect {
    uint16_t size, offset;
};

// From ca-protocol.md §5 (measured with libca dbr_size / dbr_value_offset).
const Expect kSpec[39] = {
    {40, 0},   {2, 0},    {4, 0},    {2, 0},     {1, 0},   {4, 0},   {8, 0},   // plain
    {44, 4},   {6, 4},    {8, 4},    {6, 4},     {6, 5},   {8, 4},   {16, 8},  // STS
    {52, 12},  {16, 14},  {16, 12},  {16, 14},   {16, 15}, {16, 12}, {24, 16}, // TIME
    {44, 4},   {26, 24},  {44, 40},  {424, 422}, {20, 19}, {40, 36}, {72, 64}, // GR
    {44, 4},   {30, 28},  {52, 48},  {424, 422}, {22, 21}, {48, 44}, {88, 80}, // CTRL
    {2, 0},    {2, 0},    {48, 8},   {40, 0}};

pv::Database& db() {
    static pv::Database* d = [] {
        auto* x = new pv::Database;
        x->load(pv::parse_db(R"(
record(ai, "t:ai") { field(VAL, "1.5") field(PREC, "2") field(EGU, "mm") field(HOPR, "10")
  field(LOPR, "-10") field(HIHI, "8") field(HHSV, "MAJOR") field(LOW, "-3") field(LSV, "MINOR") }
record(ao, "t:ao") { field(DRVH, "5") field(DRVL, "-5") field(HOPR, "9") field(LOPR, "-9") }
record(mbbi, "t:mbbi") { field(ZRST, "zero") field(ONST, "one") field(TWST, "two") field(VAL, "1") }
record(waveform, "t:wf") { field(FTVL, "SHORT") field(NELM, "8") }
record(longin, "t:li") { field(VAL, "-7") field(HOPR, "100") field(HIGH, "50") field(HSV, "MINOR") }
)",
                             "t.db", {}));
        x->init_records();
        return x;
    }();
    return *d;
}

pv::Address addr(const char* name) {
    pv::Address a;
    EXPECT_TRUE(db().resolve(name, a)) << name;
    return a;
}

} // namespace

TEST(Dbr, SizesAndOffsetsMatchLibca) {
    for (uint16_t t = 0; t <= kLastDbr; ++t) {
        EXPECT_EQ(dbr_info(t).size, kSpec[t].size) << "dbr type " << t;
        EXPECT_EQ(dbr_info(t).value_offset, kSpec[t].offset) << "dbr type " << t;
    }
    EXPECT_FALSE(dbr_valid(39));
}

TEST(Dbr, PayloadSizeGrowsByElementSize) {
    EXPECT_EQ(dbr_payload_size(20, 1), 24u);
    EXPECT_EQ(dbr_payload_size(20, 10), 24u + 9 * 8);
    EXPECT_EQ(dbr_payload_size(0, 3), 120u);
    EXPECT_EQ(dbr_payload_size(18, 5), 16u + 4);
}

TEST(Dbr, TimeDoubleCarriesAlarmTimeAndValue) {
    std::vector<uint8_t> out(24);
    pv::Address a = addr("t:ai");
    a.rec->time = pv::EpicsTime{123456, 789};
    encode_dbr(db(), a, 20, 1, out.data());
    EXPECT_EQ(get16(&out[0]), a.rec->stat);
    EXPECT_EQ(get16(&out[2]), a.rec->sevr);
    EXPECT_EQ(get32(&out[4]), 123456u);
    EXPECT_EQ(get32(&out[8]), 789u);
    EXPECT_EQ(getf64(&out[16]), 1.5);
}

TEST(Dbr, CtrlDoubleMetadataWithNanForUnusedAlarmLimits) {
    std::vector<uint8_t> out(88);
    encode_dbr(db(), addr("t:ai"), 34, 1, out.data());
    EXPECT_EQ(get16(&out[4]), 2);                                  // precision
    EXPECT_STREQ(reinterpret_cast<char*>(&out[8]), "mm");           // units
    EXPECT_EQ(getf64(&out[16]), 10.0);                              // upper display
    EXPECT_EQ(getf64(&out[24]), -10.0);                             // lower display
    EXPECT_EQ(getf64(&out[32]), 8.0);                               // upper alarm (HHSV set)
    EXPECT_TRUE(std::isnan(getf64(&out[40])));                      // upper warning: HSV=NO_ALARM
    EXPECT_EQ(getf64(&out[48]), -3.0);                              // lower warning (LSV set)
    EXPECT_TRUE(std::isnan(getf64(&out[56])));                      // lower alarm: LLSV=NO_ALARM
    EXPECT_EQ(getf64(&out[64]), 10.0);                              // ai ctrl = HOPR/LOPR
    EXPECT_EQ(getf64(&out[72]), -10.0);
    EXPECT_EQ(getf64(&out[80]), 1.5);
}

TEST(Dbr, AoControlLimitsAreDrvhDrvl) {
    std::vector<uint8_t> out(88);
    encode_dbr(db(), addr("t:ao"), 34, 1, out.data());
    EXPECT_EQ(getf64(&out[16]), 9.0);
    EXPECT_EQ(getf64(&out[64]), 5.0);
    EXPECT_EQ(getf64(&out[72]), -5.0);
}

TEST(Dbr, CtrlLongUsesZeroForNanAlarmLimits) {
    std::vector<uint8_t> out(48);
    encode_dbr(db(), addr("t:li"), 33, 1, out.data());
    EXPECT_EQ(int32_t(get32(&out[12])), 100); // upper display
    EXPECT_EQ(int32_t(get32(&out[20])), 0);   // upper alarm: NaN -> 0
    EXPECT_EQ(int32_t(get32(&out[24])), 50);  // upper warning
    EXPECT_EQ(int32_t(get32(&out[44])), -7);
}

TEST(Dbr, CtrlEnumHasStateStrings) {
    std::vector<uint8_t> out(424);
    encode_dbr(db(), addr("t:mbbi"), 31, 1, out.data());
    EXPECT_EQ(get16(&out[4]), 3);
    EXPECT_STREQ(reinterpret_cast<char*>(&out[6]), "zero");
    EXPECT_STREQ(reinterpret_cast<char*>(&out[6 + 26]), "one");
    EXPECT_STREQ(reinterpret_cast<char*>(&out[6 + 52]), "two");
    EXPECT_EQ(get16(&out[422]), 1);
}

TEST(Dbr, EnumReadAsStringGivesStateName) {
    std::vector<uint8_t> out(40);
    encode_dbr(db(), addr("t:mbbi"), 0, 1, out.data());
    EXPECT_STREQ(reinterpret_cast<char*>(out.data()), "one");
}

TEST(Dbr, DoubleAsStringUsesPrec) {
    std::vector<uint8_t> out(40);
    encode_dbr(db(), addr("t:ai"), 0, 1, out.data());
    EXPECT_STREQ(reinterpret_cast<char*>(out.data()), "1.50");
}

TEST(Dbr, ArrayReadPastCurrentCountIsZeroFilled) {
    pv::Address a = addr("t:wf");
    int16_t v[3] = {7, -8, 9};
    ASSERT_EQ(db().put(a, pv::Prim::Short, v, 3), pv::PutStatus::Ok);
    EXPECT_EQ(db().current_count(a), 3u);
    std::vector<uint8_t> out(dbr_payload_size(5, 6));
    uint32_t valid = encode_dbr(db(), a, 5, 6, out.data()); // as DBR_LONG
    EXPECT_EQ(valid, 3u);
    EXPECT_EQ(int32_t(get32(&out[0])), 7);
    EXPECT_EQ(int32_t(get32(&out[4])), -8);
    EXPECT_EQ(int32_t(get32(&out[8])), 9);
    EXPECT_EQ(get32(&out[12]), 0u);
    EXPECT_EQ(get32(&out[20]), 0u);
}

TEST(Dbr, ClassNameIsRecordType) {
    std::vector<uint8_t> out(40);
    encode_dbr(db(), addr("t:ao"), 38, 1, out.data());
    EXPECT_STREQ(reinterpret_cast<char*>(out.data()), "ao");
}

TEST(Dbr, DecodePutSwapsBytesAndTerminatesStrings) {
    uint8_t p[16];
    putf64(p, 2.25);
    putf64(p + 8, -1);
    std::vector<char> host;
    ASSERT_TRUE(decode_put(6, p, 16, 2, host));
    double d[2];
    std::memcpy(d, host.data(), 16);
    EXPECT_EQ(d[0], 2.25);
    EXPECT_EQ(d[1], -1.0);
    EXPECT_FALSE(decode_put(6, p, 16, 3, host)); // payload too short for 3 doubles
    uint8_t s[40];
    std::memset(s, 'x', 40);
    ASSERT_TRUE(decode_put(0, s, 40, 1, host));
    EXPECT_EQ(std::strlen(host.data()), 39u);
}

TEST(Protocol, ExtendedHeaderOnlyForLargeMessages) {
    uint8_t h[24];
    EXPECT_EQ(encode_header(h, kEventAdd, 0xFFF8, 6, 10, 1, 2), 16u);
    EXPECT_EQ(encode_header(h, kEventAdd, 0x10000, 6, 0x2000, 1, 2), 24u);
    EXPECT_EQ(get16(h + 2), 0xFFFF);
    EXPECT_EQ(get16(h + 6), 0);
    EXPECT_EQ(get32(h + 16), 0x10000u);
    EXPECT_EQ(get32(h + 20), 0x2000u);
    Header d;
    EXPECT_EQ(decode_header(h, 24, true, d), 24u);
    EXPECT_EQ(d.payload_size, 0x10000u);
    EXPECT_EQ(d.count, 0x2000u);
    EXPECT_EQ(decode_header(h, 20, true, d), 0u);          // incomplete extended header
    EXPECT_EQ(decode_header(h, 16, false, d), 16u);        // old peers: 0xFFFF is a size
    EXPECT_EQ(d.payload_size, 0xFFFFu);
}

TEST(Protocol, MessagesArePaddedToEightBytes) {
    std::string out;
    append_message(out, kEcho, 0, 0, 0, 0, "abc", 3);
    EXPECT_EQ(out.size(), 24u);
    EXPECT_EQ(get16(reinterpret_cast<const uint8_t*>(out.data()) + 2), 8);
}
