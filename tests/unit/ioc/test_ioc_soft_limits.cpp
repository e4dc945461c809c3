// The motor record's soft limits and the axis's are one value both ways (issue 41, item 7, as
// ECMC's driver with CfgSyncSftLim): a put to DHLM/DLLM/HLM/LLM moves the axis's soft limits
// (DLLM = DHLM = 0 turns them off), and a write of ecmccfg's $(P)$(M)-CfgDHLM / -CfgDLLM /
// -CfgDHLM-En moves the axis's and, through it, the record's. Demo IOC in virtual time.
#include "virtual_ioc.hpp"

#include "pv/database.hpp"

#include <gtest/gtest.h>

using namespace beamctl;

namespace {

const std::string kDemo = std::string(BEAMCTL_SOURCE_DIR) + "/examples/demo/ioc.yaml";

struct SoftLimits : ::testing::Test {
    test::VirtualIoc v{kDemo};
    void SetUp() override { v.run(100); } // the PLCs enable what they enable
    void put(const std::string& channel, double x) {
        pv::Address a;
        ASSERT_TRUE(v.ioc->database().resolve(channel, a)) << channel;
        ASSERT_EQ(v.ioc->database().put(a, pv::Prim::Double, &x, 1), pv::PutStatus::Ok) << channel;
    }
    double get(const std::string& channel) {
        pv::Address a;
        EXPECT_TRUE(v.ioc->database().resolve(channel, a)) << channel;
        double x = 0;
        v.ioc->database().get(a, pv::Prim::Double, &x, 1);
        return x;
    }
    const motion::AxisStatus& st() { return v.axis("SampleX").status(); }
    // An axis move (not through the record): what the axis itself allows.
    void move_axis(double to) {
        motion::AxisCommand on{motion::CommandType::Power};
        on.on = true;
        v.send("SampleX", on);
        v.run(200);
        v.send("SampleX", motion::AxisCommand{motion::CommandType::MoveAbsolute, to});
        v.run(8000);
    }
};

} // namespace

TEST_F(SoftLimits, RecordDialLimitsBecomeTheAxisLimits) {
    ASSERT_DOUBLE_EQ(st().soft_fwd, 24); // the axis file's
    ASSERT_DOUBLE_EQ(get("DEMO:SampleX.DHLM"), 24);
    put("DEMO:SampleX.DHLM", 20);
    v.run(20);
    EXPECT_DOUBLE_EQ(st().soft_fwd, 20);
    EXPECT_TRUE(st().soft_fwd_enabled);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-CfgDHLM-RB"), 20);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DHLM"), 20); // the axis's status did not put the old one back
    move_axis(22); // the axis refuses what the record refuses
    EXPECT_LT(st().act_pos, 20.01);
    EXPECT_EQ(st().warning_id, motion::error_id::kSoftLimitFwd);
    // raised past the axis file's 24: a move to 24.3 is the axis's to make now
    put("DEMO:SampleX.HLM", 24.5); // DIR Pos, OFF 0: HLM is DHLM
    v.run(20);
    EXPECT_DOUBLE_EQ(st().soft_fwd, 24.5);
    move_axis(24.3);
    EXPECT_NEAR(st().act_pos, 24.3, 0.01);
    EXPECT_EQ(st().warning_id, 0u);
    put("DEMO:SampleX.DLLM", -3);
    v.run(20);
    EXPECT_DOUBLE_EQ(st().soft_bwd, -3);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-CfgDLLM-RB"), -3);
}

TEST_F(SoftLimits, NoRecordLimitsTurnTheAxisLimitsOff) {
    put("DEMO:SampleX.DHLM", 0);
    put("DEMO:SampleX.DLLM", 0);
    v.run(20);
    EXPECT_FALSE(st().soft_fwd_enabled);
    EXPECT_FALSE(st().soft_bwd_enabled);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-CfgDHLM-En-RB"), 0);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-SftLimFwdEna-RB"), 0);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DHLM"), 0);
}

TEST_F(SoftLimits, EcmccfgLimitPvsMoveTheAxisAndTheRecord) {
    put("DEMO:SampleX-CfgDHLM", 21);
    v.run(20);
    EXPECT_DOUBLE_EQ(st().soft_fwd, 21);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DHLM"), 21);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.HLM"), 21);
    put("DEMO:SampleX-CfgDLLM", -5);
    v.run(20);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DLLM"), -5);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-CfgDLLM"), -5); // its read-back follows too
    put("DEMO:SampleX-CfgDHLM-En", 0);
    v.run(20);
    EXPECT_FALSE(st().soft_fwd_enabled);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX-SftLimFwdEna-RB"), 0);
    EXPECT_TRUE(st().soft_bwd_enabled);
}

TEST_F(SoftLimits, PlcCodeMovingTheAxisLimitsMovesTheRecordsAndNothingComesBack) {
    motion::Axis& ax = v.axis("SampleX");
    ax.variables().mon.highsoftlim = 22; // as ecmccfg's slit include moves a blade's limits
    ax.variables().mon.lowsoftlim = -21;
    v.run(20);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DHLM"), 22);
    EXPECT_DOUBLE_EQ(get("DEMO:SampleX.DLLM"), -21);
    v.run(20);
    EXPECT_DOUBLE_EQ(st().soft_fwd, 22); // the record's follow-up puts did not send the pair back
    EXPECT_DOUBLE_EQ(st().soft_bwd, -21);
    EXPECT_EQ(v.axis("SampleX").variables().mon.highsoftlim, 22);
}
