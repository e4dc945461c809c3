// ioc.yaml `autosave:` (config/ioc_config.hpp): its keys, defaults and errors.
#include "config/ioc_config.hpp"

#include "core/error.hpp"

#include <gtest/gtest.h>

namespace beamctl::config {
namespace {

TEST(AutosaveConfig, DirRelativeToTheFileAndPeriod) {
    IocConfig c = IocConfig::parse("ioc: {name: T}\nautosave: {dir: sav, period_s: 2.5}\n", "/x/ioc.yaml");
    ASSERT_TRUE(c.autosave);
    EXPECT_EQ(c.autosave->dir, "/x/sav");
    EXPECT_EQ(c.autosave->period_s, 2.5);
    EXPECT_FALSE(IocConfig::parse("ioc: {name: T}\n", "/x/ioc.yaml").autosave);
    IocConfig d = IocConfig::parse("ioc: {name: T}\nautosave: {dir: /abs}\n", "/x/ioc.yaml");
    EXPECT_EQ(d.autosave->dir, "/abs");
    EXPECT_EQ(d.autosave->period_s, 5);
}

TEST(AutosaveConfig, UnknownKeysMissingDirAndBadPeriodAreErrors) {
    auto error = [](const char* text) {
        try {
            IocConfig::parse(text, "ioc.yaml");
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(no error)");
    };
    EXPECT_NE(error("ioc: {name: T}\nautosave: {dir: a, perod_s: 1}\n").find("ioc.yaml:2"), std::string::npos);
    EXPECT_NE(error("ioc: {name: T}\nautosave: {dir: a, perod_s: 1}\n").find("perod_s"), std::string::npos);
    EXPECT_NE(error("ioc: {name: T}\nautosave: {period_s: 1}\n").find("dir"), std::string::npos);
    EXPECT_NE(error("ioc: {name: T}\nautosave: {dir: a, period_s: 0}\n").find("period_s"), std::string::npos);
}

} // namespace
} // namespace beamctl::config
