// Plugins through the C ABI: the example plugin loads, is constructed with its configuration,
// exposes its functions and constants, and gets its RT callbacks; a plugin built for another ABI
// version, a library without the entry point and a missing file are refused with clear errors.
#include "core/error.hpp"
#include "plc/plugin.hpp"

#include <gtest/gtest.h>

using namespace beamctl;

#ifndef BEAMCTL_TEST_PLUGIN
#error "BEAMCTL_TEST_PLUGIN (path of the example plugin) must be defined by the build"
#endif

namespace {
std::string load_error(const std::string& path, const std::string& config = "") {
    try {
        plc::Plugin::load(path, config);
    } catch (const Error& e) {
        return e.what();
    }
    return "(loaded)";
}
} // namespace

TEST(Plugin, ExampleLoadsWithConfigurationFunctionsAndConstants) {
    auto p = plc::Plugin::load(BEAMCTL_TEST_PLUGIN, "GAIN=2.5");
    EXPECT_EQ(p->name(), "example");
    EXPECT_EQ(p->version(), 1u);
    ASSERT_EQ(p->functions().size(), 4u);
    const plc::Plugin::Function* scale = p->function("ex_scale");
    ASSERT_NE(scale, nullptr);
    EXPECT_EQ(scale->nargs, 1);
    double a[] = {4.0};
    EXPECT_DOUBLE_EQ(scale->fn(a), 10.0); // GAIN from the configuration
    double c[] = {7, 0, 5};
    EXPECT_DOUBLE_EQ(p->function("ex_clamp")->fn(c), 5.0);
    EXPECT_EQ(p->function("nope"), nullptr);
    EXPECT_DOUBLE_EQ(p->constant("ex_pi").value(), 3.14159265358979323846);
    EXPECT_FALSE(p->constant("nope").has_value());
    // RT callbacks
    EXPECT_EQ(p->rt_enter(), 0);
    EXPECT_DOUBLE_EQ(p->function("ex_entered")->fn(nullptr), 1.0);
    for (int i = 0; i < 10; ++i) EXPECT_EQ(p->realtime(0), 0);
    EXPECT_DOUBLE_EQ(p->function("ex_cycles")->fn(nullptr), 10.0);
    EXPECT_EQ(p->rt_exit(), 0);
    EXPECT_DOUBLE_EQ(p->function("ex_entered")->fn(nullptr), 0.0);
}

TEST(Plugin, RefusalsSayWhatAndWhere) {
    std::string e = load_error(BEAMCTL_TEST_BAD_ABI_PLUGIN);
    EXPECT_NE(e.find("ABI version 42"), std::string::npos) << e;
    EXPECT_NE(e.find("this beamctl has version 1"), std::string::npos) << e;
    EXPECT_NE(e.find(BEAMCTL_TEST_BAD_ABI_PLUGIN), std::string::npos) << e;
    e = load_error("/nonexistent/plugin.so");
    EXPECT_NE(e.find("/nonexistent/plugin.so: cannot load plugin"), std::string::npos) << e;
    e = load_error("libm.so.6"); // a library, but not a plugin
    EXPECT_NE(e.find("exports no beamctl_plugin_get()"), std::string::npos) << e;
    e = load_error(BEAMCTL_TEST_PLUGIN, "GAIN=nan");
    EXPECT_NE(e.find("refused its configuration 'GAIN=nan'"), std::string::npos) << e;
}
