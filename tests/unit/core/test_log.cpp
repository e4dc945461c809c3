// BEAMCTL_LOG is checked against the level names and the loggers registered at static
// initialisation: an unknown level or logger is an error naming it and listing the valid ones.
#include "core/error.hpp"
#include "core/log.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>

using beamctl::Error;
namespace blog = beamctl::log;

namespace {

blog::Logger test_logger("test.log.validate");

std::string error_of(const char* spec) {
    try {
        blog::validate(spec);
    } catch (const Error& e) {
        return e.what();
    }
    return {};
}

} // namespace

TEST(LogSpec, DocumentedFormsAreValid) {
    for (const char* spec : {"", "info", "warn,ca=debug,ca.circuit=trace", "err", "error", "off",
                             "trace,test.log.validate=off", "test=debug", "test.log=warn", ",info,"})
        EXPECT_EQ(error_of(spec), "") << spec;
}

TEST(LogSpec, UnknownLevelIsNamedWithTheValidOnes) {
    std::string e = error_of("bogus");
    EXPECT_NE(e.find("unknown level 'bogus'"), std::string::npos) << e;
    EXPECT_NE(e.find("trace debug info warn error off"), std::string::npos) << e;
    e = error_of("warn,ca=loud");
    EXPECT_NE(e.find("unknown level 'loud' in 'ca=loud'"), std::string::npos) << e;
    EXPECT_NE(error_of("ca=").find("unknown level ''"), std::string::npos);
}

TEST(LogSpec, UnknownLoggerIsNamedWithTheKnownOnes) {
    std::string e = error_of("info,nosuch.logger=debug");
    EXPECT_NE(e.find("unknown logger 'nosuch.logger'"), std::string::npos) << e;
    EXPECT_NE(e.find("test.log.validate"), std::string::npos) << e; // the list of known loggers
    EXPECT_NE(e.find("ca.server"), std::string::npos) << e;
    // A prefix must end at a dot: "test.lo" is not a logger nor a dotted prefix of one.
    EXPECT_NE(error_of("test.lo=debug").find("unknown logger 'test.lo'"), std::string::npos);
    EXPECT_NE(error_of("=debug").find("no logger name"), std::string::npos);
}

TEST(LogSpec, KnownLoggersAreSortedAndIncludeStaticOnes) {
    auto names = blog::logger_names();
    EXPECT_TRUE(std::is_sorted(names.begin(), names.end()));
    EXPECT_NE(std::find(names.begin(), names.end(), "test.log.validate"), names.end());
    EXPECT_NE(std::find(names.begin(), names.end(), "rt.engine"), names.end());
}
