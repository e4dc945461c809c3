// areaDetector's file-name template: C's printf conversions, checked before any is formatted.
#include "ioc/area_detector.hpp"

#include <gtest/gtest.h>

using beamctl::ioc::format_file_name;

TEST(AreaDetectorFileName, TheTemplatesUsersWrite) {
    std::string out, why;
    ASSERT_TRUE(format_file_name("%s%s_%3.3d.h5", "/data/", "spot", 7, out, why)) << why;
    EXPECT_EQ(out, "/data/spot_007.h5");
    ASSERT_TRUE(format_file_name("%s%s%d.h5", "/d/", "a", 12, out, why));
    EXPECT_EQ(out, "/d/a12.h5");
    ASSERT_TRUE(format_file_name("%s/%s_%05d_100%%.hdf", "/d", "a", 3, out, why));
    EXPECT_EQ(out, "/d/a_00003_100%.hdf");
    ASSERT_TRUE(format_file_name("fixed.h5", "/d/", "a", 3, out, why));
    EXPECT_EQ(out, "fixed.h5");
    ASSERT_TRUE(format_file_name("%s%s_%x.h5", "/d/", "a", 255, out, why));
    EXPECT_EQ(out, "/d/a_ff.h5");
}

TEST(AreaDetectorFileName, EverythingElseIsRefusedWithAReason) {
    std::string out, why;
    for (const char* bad : {"%s%s%n", "%s%s%s_%d", "%d%s", "%s%s_%d_%d", "%s%s_%f.h5", "%s%s_%p", "%s%s_%", "%s%s_%lld", "%*d"}) {
        why.clear();
        EXPECT_FALSE(format_file_name(bad, "/d/", "a", 1, out, why)) << bad;
        EXPECT_FALSE(why.empty()) << bad;
    }
    EXPECT_FALSE(format_file_name(std::string(300, 'a'), "", "", 1, out, why));
}
