// Fast feedback in the cycle (src/ioc/feedback.cpp, src/feedback/fast_epid.cpp) in virtual time:
// an EL4134 output wired to an EL3104 input (the plant: the input follows the output a frame
// later), the loop $(P)epidFast1 holding the input at its setpoint; step response, anti-windup at
// the drive limit, bumpless FBON, averaging over DT, the record as the interface.
#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "virtual_ioc.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

constexpr double kVoltsPerDigit = 10.0 / 32767;

std::string ioc_yaml(const std::string& loop_extra = "") {
    return "ioc: {name: FB}\n"
           "engine: {rate_hz: 1000}\n"
           "buses:\n"
           "  - id: 0\n"
           "    link: {type: sim, plant: plant.yaml}\n"
           "    slaves:\n"
           "      - {position: 0, type: EK1100}\n"
           "      - {position: 1, type: EL3104}\n"
           "      - {position: 2, type: EL4134}\n"
           "feedback:\n"
           "  - {name: epidFast1, input: ec0.s1.analogInput01, input_scale: " + std::to_string(kVoltsPerDigit) +
           ", output: ec0.s2.analogOutput01, output_scale: " + std::to_string(kVoltsPerDigit) +
           ", kp: 0.3, ki: 100, drvh: 5, drvl: -5, egu: V, scan: Passive" + loop_extra + "}\n";
}

struct FeedbackIoc {
    TempDir dir;
    std::unique_ptr<VirtualIoc> v;
    explicit FeedbackIoc(const std::string& extra = "") {
        dir.write("plant.yaml", "wiring:\n  - {from: s2.analogOutput01, to: s1.analogInput01}\n");
        v = std::make_unique<VirtualIoc>(dir.write("ioc.yaml", ioc_yaml(extra)));
        v->cycles(300); // the bus in OP
    }
    pv::PutStatus put(const std::string& name, double x) {
        pv::Address a;
        if (!v->ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        return v->ioc->database().put(a, pv::Prim::Double, &x, 1);
    }
    double field(const std::string& name) {
        pv::Address a;
        if (!v->ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        double x = 0;
        v->ioc->database().get(a, pv::Prim::Double, &x, 1);
        return x;
    }
    // The record's scan: one exchange with the loop.
    void exchange() { v->ioc->database().process(*v->ioc->database().find("FB:epidFast1")); }
    double input() const { return v->ioc->feedback().loop(0).terms().cval; }
    double output() const { return v->ioc->feedback().output_value(0); }
};

} // namespace

TEST(IocFeedback, TheLoopHoldsTheInputAtTheSetpoint) {
    FeedbackIoc f;
    ASSERT_EQ(f.put("FB:epidFast1", 2.0), pv::PutStatus::Ok);
    ASSERT_EQ(f.put("FB:epidFast1.FBON", 1), pv::PutStatus::Ok);
    f.exchange();
    double peak = 0;
    for (int k = 0; k < 100; ++k) {
        f.v->cycles(10);
        peak = std::max(peak, f.input());
    }
    EXPECT_NEAR(f.input(), 2.0, 2 * kVoltsPerDigit);
    EXPECT_LT(peak, 2.0 * 1.25); // a damped step response
    f.exchange();
    EXPECT_NEAR(f.field("FB:epidFast1.CVAL"), 2.0, 2 * kVoltsPerDigit);
    EXPECT_NEAR(f.field("FB:epidFast1.OVAL"), 2.0, 3 * kVoltsPerDigit);
    EXPECT_DOUBLE_EQ(f.field("FB:epidFast1.DT"), 0.001);
    EXPECT_EQ(f.field("FB:epidFast1.SEVR"), 0);
    // A new setpoint through the record.
    ASSERT_EQ(f.put("FB:epidFast1", -1.5), pv::PutStatus::Ok); // VAL processes the record: exchanged
    f.v->cycles(1000);
    EXPECT_NEAR(f.input(), -1.5, 2 * kVoltsPerDigit);
    EXPECT_GT(f.v->ioc->feedback().loop(0).steps(), 1900u);
}

TEST(IocFeedback, TheIntegralDoesNotWindUpAtTheDriveLimit) {
    FeedbackIoc f;
    ASSERT_EQ(f.put("FB:epidFast1.DRVH", 1.0), pv::PutStatus::Ok);
    ASSERT_EQ(f.put("FB:epidFast1.FBON", 1), pv::PutStatus::Ok);
    ASSERT_EQ(f.put("FB:epidFast1", 3.0), pv::PutStatus::Ok); // out of reach: the output sits at DRVH
    f.v->cycles(5000); // 5 s against the limit (an unchecked integral would reach 0.3*100*2*5 = 300 V)
    EXPECT_NEAR(f.output(), 1.0, kVoltsPerDigit);
    f.exchange();
    EXPECT_LE(f.field("FB:epidFast1.I"), 1.0);
    // The setpoint comes back into reach: the output leaves the limit within a few steps.
    ASSERT_EQ(f.put("FB:epidFast1", 0.5), pv::PutStatus::Ok);
    f.v->cycles(5);
    EXPECT_LT(f.output(), 1.0);
    f.v->cycles(500);
    EXPECT_NEAR(f.input(), 0.5, 2 * kVoltsPerDigit);
}

TEST(IocFeedback, FeedbackOnStartsFromTheOutputWithoutABump) {
    FeedbackIoc f;
    ASSERT_EQ(f.put("FB:epidFast1", 2.0), pv::PutStatus::Ok);
    ASSERT_EQ(f.put("FB:epidFast1.FBON", 1), pv::PutStatus::Ok);
    f.exchange();
    f.v->cycles(1000);
    ASSERT_EQ(f.put("FB:epidFast1.FBON", 0), pv::PutStatus::Ok);
    f.exchange();
    ASSERT_EQ(f.put("FB:epidFast1.KI", 0), pv::PutStatus::Ok); // KI 0 clears I while the loop runs off
    f.exchange();
    f.v->cycles(200);
    f.exchange();
    EXPECT_EQ(f.field("FB:epidFast1.I"), 0);
    const double held = f.output();
    EXPECT_NEAR(held, 2.0, 3 * kVoltsPerDigit); // feedback off: the output is left where it was
    // On again with KI: without the bumpless start OVAL would be P + 0, a 2 V jump.
    ASSERT_EQ(f.put("FB:epidFast1.KI", 20), pv::PutStatus::Ok);
    ASSERT_EQ(f.put("FB:epidFast1.FBON", 1), pv::PutStatus::Ok);
    f.exchange();
    double worst = 0;
    for (int k = 0; k < 50; ++k) {
        f.v->cycles(1);
        worst = std::max(worst, std::fabs(f.output() - held));
    }
    EXPECT_LE(worst, 2 * kVoltsPerDigit);
}

TEST(IocFeedback, DtAveragesTheSamplesOfAStep) {
    FeedbackIoc f;
    ASSERT_EQ(f.put("FB:epidFast1.DT", 0.0049), pv::PutStatus::Ok);
    f.exchange();
    EXPECT_DOUBLE_EQ(f.field("FB:epidFast1.DT"), 0.005); // 5 cycles of 1 ms
    const uint64_t before = f.v->ioc->feedback().loop(0).steps();
    f.v->cycles(1000);
    const uint64_t steps = f.v->ioc->feedback().loop(0).steps() - before;
    EXPECT_GE(steps, 199u);
    EXPECT_LE(steps, 201u);
    EXPECT_EQ(f.v->ioc->feedback().loop(0).samples_per_step(), 5);
}

TEST(IocFeedback, ConfigurationErrorsNameTheLoopAndWhere) {
    TempDir dir;
    dir.write("plant.yaml", "{}\n");
    auto err = [&](const std::string& yaml) {
        try {
            VirtualIoc v(dir.write("ioc.yaml", yaml));
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(no error)");
    };
    std::string y = ioc_yaml();
    std::string bad_out = y;
    bad_out.replace(bad_out.find("output: ec0.s2.analogOutput01"), 29, "output: ec0.s1.analogInput02");
    EXPECT_NE(err(bad_out).find("feedback epidFast1 output: 'ec0.s1.analogInput02' is not an analog output entry"), std::string::npos)
        << err(bad_out);
    std::string bad_in = y;
    bad_in.replace(bad_in.find("input: ec0.s1.analogInput01"), 27, "input: ec0.s1.analogInput09");
    EXPECT_NE(err(bad_in).find("ioc.yaml:11:"), std::string::npos) << err(bad_in);
    EXPECT_NE(err(bad_in).find("no signal 'ec0.s1.analogInput09'"), std::string::npos) << err(bad_in);
    std::string no_limits = y;
    no_limits.replace(no_limits.find("drvh: 5, drvl: -5, "), 19, "");
    EXPECT_NE(err(no_limits).find("needs drvh and drvl"), std::string::npos) << err(no_limits);
}
