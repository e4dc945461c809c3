// The signal registry: declarations, one writer per output, names with a bit, binding through
// the owner, listing; and the process-image access every subsystem shares (registry/image.hpp).
#include "core/error.hpp"
#include "core/glob.hpp"
#include "registry/image.hpp"
#include "registry/registry.hpp"

#include <gtest/gtest.h>

#include <sstream>

using namespace beamctl;
using namespace beamctl::registry;

namespace {

Signal sig(std::string name, Direction d, std::string owner, std::string type = "UINT16") {
    Signal s;
    s.name = std::move(name);
    s.type = std::move(type);
    s.direction = d;
    s.owner = std::move(owner);
    return s;
}

std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(Registry, ANameIsDeclaredOnceAndNotAfterTheFreeze) {
    Registry r;
    r.declare(sig("ec0.s1.binaryInput01", Direction::Input, "ec0"));
    std::string e = error_of([&] { r.declare(sig("ec0.s1.binaryInput01", Direction::Input, "plc0")); });
    EXPECT_NE(e.find("'ec0.s1.binaryInput01' of plc0 is already declared by ec0"), std::string::npos) << e;
    r.freeze();
    e = error_of([&] { r.declare(sig("ax1.enc.actpos", Direction::Input, "axis 1 (X)")); });
    EXPECT_NE(e.find("after the registry was frozen"), std::string::npos) << e;
    EXPECT_EQ(r.size(), 1u);
}

TEST(Registry, AnOutputHasOneWriter) {
    Registry r;
    r.declare(sig("ec0.s2.binaryOutput01", Direction::Output, "ec0"));
    r.declare(sig("ec0.s1.binaryInput01", Direction::Input, "ec0"));
    std::string why;
    EXPECT_TRUE(r.claim("ec0.s2.binaryOutput01", "plc0", why));
    EXPECT_TRUE(r.claim("ec0.s2.binaryOutput01", "plc0", why)); // the same writer again
    EXPECT_FALSE(r.claim("ec0.s2.binaryOutput01", "axis 1 (X)", why));
    EXPECT_EQ(why, "'ec0.s2.binaryOutput01' is already written by plc0 (one writer per output)");
    EXPECT_EQ(r.find("ec0.s2.binaryOutput01")->writer, "plc0"); // unchanged by the refusal
    EXPECT_FALSE(r.claim("ec0.s1.binaryInput01", "plc0", why));
    EXPECT_NE(why.find("is an input of ec0"), std::string::npos) << why;
    EXPECT_FALSE(r.claim("ec0.s9.nothing", "plc0", why));
    EXPECT_EQ(why, "no signal 'ec0.s9.nothing'");
    r.release("ec0.s2.binaryOutput01", "someone else"); // only its writer releases it
    EXPECT_EQ(r.find("ec0.s2.binaryOutput01")->writer, "plc0");
    r.release("ec0.s2.binaryOutput01", "plc0");
    EXPECT_TRUE(r.claim("ec0.s2.binaryOutput01", "axis 1 (X)", why));
}

TEST(Registry, NamesWithABitAndBindingThroughTheOwner) {
    Registry r;
    r.declare(sig("ec0.s3.driveStatus01", Direction::Input, "ec0"));
    r.declare(sig("ax1.enc.actpos", Direction::Input, "axis 1 (X)", "LREAL"));
    int bit = -1;
    EXPECT_EQ(r.find_with_bit("ec0.s3.driveStatus01.12", bit)->name, "ec0.s3.driveStatus01");
    EXPECT_EQ(bit, 12);
    EXPECT_EQ(r.find_with_bit("ec0.s3.driveStatus01", bit)->name, "ec0.s3.driveStatus01");
    EXPECT_EQ(bit, -1);
    EXPECT_EQ(r.find_with_bit("ec0.s3.driveStatus01.x", bit), nullptr);
    EXPECT_EQ(r.find_with_bit("ec0.s3.other.1", bit), nullptr);

    uint8_t image[8] = {0x00, 0x10, 0, 0, 0, 0, 0, 0}; // bit 12 set
    r.set_binder("ec0.", [&](const Signal& s, int b, std::string&) {
        EXPECT_EQ(s.name, "ec0.s3.driveStatus01");
        return BoundSignal{image, 0, 16, false, b};
    });
    std::string why;
    BoundSignal b = r.bind("ec0.s3.driveStatus01.12", why);
    ASSERT_TRUE(b.bound()) << why;
    EXPECT_EQ(b.get(), 1);
    EXPECT_FALSE(r.bind("ec0.s3.driveStatus01.16", why).bound());
    EXPECT_EQ(why, "'ec0.s3.driveStatus01' has 16 bits, no bit 16");
    EXPECT_FALSE(r.bind("ax1.enc.actpos", why).bound()); // no binder for ax names
    EXPECT_NE(why.find("has no place in a process image"), std::string::npos) << why;
    EXPECT_FALSE(r.bind("ec0.s4.nothing", why).bound());
    EXPECT_EQ(why, "no signal 'ec0.s4.nothing'");
}

TEST(Registry, ListingByGlob) {
    Registry r;
    r.declare(sig("ec0.s2.binaryOutput01", Direction::Output, "ec0"));
    r.declare(sig("ec0.s1.binaryInput01", Direction::Input, "ec0"));
    r.declare(sig("ax1.enc.actpos", Direction::Input, "axis 1 (X)", "LREAL"));
    r.set_pv("ec0.s2.binaryOutput01", "T:m0s002-BO01");
    auto all = r.match("");
    ASSERT_EQ(all.size(), 3u);
    EXPECT_EQ(all[0]->name, "ax1.enc.actpos"); // by name
    EXPECT_EQ(r.match("ec0.s?.binary*").size(), 2u);
    EXPECT_EQ(r.match("*Output*").size(), 1u);
    EXPECT_TRUE(r.match("ec1.*").empty());
    std::ostringstream os;
    r.print(os, "ec0.*");
    std::string t = os.str();
    EXPECT_NE(t.find("NAME"), std::string::npos);
    EXPECT_NE(t.find("ec0.s2.binaryOutput01  UINT16  output    ec0    CA (its PV)  T:m0s002-BO01"), std::string::npos) << t;
    EXPECT_EQ(t.find("ax1"), std::string::npos) << t;
}

TEST(Glob, StarAndQuestionMark) {
    EXPECT_TRUE(beamctl::glob_match("", ""));
    EXPECT_TRUE(beamctl::glob_match("*", "anything"));
    EXPECT_TRUE(beamctl::glob_match("a*b*c", "aXXbYYc"));
    EXPECT_FALSE(beamctl::glob_match("a*b*c", "aXXbYY"));
    EXPECT_TRUE(beamctl::glob_match("a?c", "abc"));
    EXPECT_FALSE(beamctl::glob_match("a?c", "ac"));
    EXPECT_TRUE(beamctl::glob_match("**.x", "a.b.x"));
}

// The one reader/writer of process-image entries: aligned and unaligned, every width, signed.
TEST(ProcessImage, ReadWriteEveryWidthAndOffset) {
    for (uint8_t bits : {1, 3, 8, 12, 16, 24, 32, 33, 64})
        for (uint32_t off : {0u, 1u, 7u, 8u, 13u, 16u}) {
            uint8_t img[16];
            std::memset(img, 0xA5, sizeof img);
            uint8_t before[16];
            std::memcpy(before, img, sizeof img);
            uint64_t mask = bits == 64 ? ~uint64_t(0) : (uint64_t(1) << bits) - 1;
            uint64_t v = 0x0123456789ABCDEFull & mask;
            image_write(img, off, bits, v);
            EXPECT_EQ(image_read(img, off, bits), v) << int(bits) << "@" << off;
            for (uint32_t b = 0; b < 128; ++b) // the bits around the entry are kept
                if (b < off || b >= off + bits)
                    EXPECT_EQ(img[b >> 3] >> (b & 7) & 1, before[b >> 3] >> (b & 7) & 1) << int(bits) << "@" << off << " bit " << b;
        }
}

TEST(ProcessImage, SignedEntriesAndOutputsOfNegativeValues) {
    EXPECT_EQ(sign_extend(0xFFFF, 16), -1);
    EXPECT_EQ(sign_extend(0x7FFF, 16), 32767);
    EXPECT_EQ(sign_extend(0x8000, 16), -32768);
    EXPECT_EQ(sign_extend(0x4, 3), -4);
    EXPECT_EQ(raw_to_double(0xFFFE, ImageEntry{0, 16, true}), -2.0);
    EXPECT_EQ(raw_to_double(0xFFFE, ImageEntry{0, 16, false}), 65534.0);
    EXPECT_EQ(double_to_raw(-2, 16), 0xFFFEu);
    EXPECT_EQ(double_to_raw(70000, 16), 70000u & 0xFFFF);
    EXPECT_TRUE(datatype_is_signed("INT16"));
    EXPECT_TRUE(datatype_is_signed("DINT"));
    EXPECT_TRUE(datatype_is_signed("SINT"));
    EXPECT_FALSE(datatype_is_signed("UINT16"));
    EXPECT_FALSE(datatype_is_signed("UDINT"));
    EXPECT_FALSE(datatype_is_signed("BOOL"));
}
