// The bridge against the rcp-sim model of examples/rcp/model.yaml, packets passed in memory in
// virtual time: the demo's PVs, a setpoint driving the plant, the motor record moving, homing
// and refused by the model's soft limit, the model falling silent, and, while it is silent,
// nothing reaching it; restarted, its values become the setpoints.
#include "rcp_harness.hpp"

#include "bridge/rcp/model.hpp"
#include "pv/motor_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

using namespace beamctl;
using namespace beamctl::bridge::rcp;
using namespace beamctl::bridge::rcp::test;

namespace {

const std::filesystem::path kExample = std::filesystem::path(__FILE__).parent_path() / ".." / ".." /
                                       ".." / "examples" / "rcp" / "model.yaml";

struct Loop : ::testing::Test {
    Harness h;
    Model m{ModelConfig::load(kExample.string())};
    const Endpoint rcp{0x7F000001, 18066}; // the model's listen address
    double dt = 1.0 / m.config().rate_hz;
    double next_beacon = 0;
    std::size_t delivered = 0;
    std::vector<Packet> packets;
    DataPacket rx;
    bool running = true;

    // One model period: writes reach the model, it steps, its packets reach the bridge.
    void period() {
        for (; delivered < h.sent.size(); ++delivered) {
            const Sent& s = h.sent[delivered];
            ASSERT_EQ(s.to, rcp);
            ASSERT_TRUE(parse_data(std::span<const uint8_t>(s.bytes), rx).ok());
            for (const DataEntry& e : rx.view()) ASSERT_EQ(m.check_write(e), Malformed::None);
            for (const DataEntry& e : rx.view()) m.apply_write(e);
        }
        h.t += dt;
        if (running) {
            m.step(dt);
            if (h.t >= next_beacon) {
                for (const Packet& p : m.beacon_packets()) h.feed(p, rcp);
                next_beacon = h.t + m.config().beacon_period_s;
            }
            m.data_packets(packets);
            for (const Packet& p : packets) h.feed(p, rcp);
        }
        h.core->tick(h.t);
        h.db.scan_periodic(h.t);
    }
    void run(double seconds) {
        for (int i = 0, n = int(std::lround(seconds / dt)); i < n; ++i) period();
    }
    void SetUp() override {
        next_beacon = h.t;
        run(0.5);
    }
};

} // namespace

TEST_F(Loop, TheDemoModelBecomesPvs) {
    for (const ObjectSpec& o : m.config().objects)
        EXPECT_TRUE(h.exists("T:sgDemo:" + o.name)) << o.name;
    EXPECT_EQ(h.type("T:sgDemo:Spectrum"), "waveform");
    EXPECT_EQ(h.get("T:sgDemo:Spectrum.NELM"), 16);
    EXPECT_EQ(h.type("T:sgDemo:Gains"), "waveform");
    EXPECT_EQ(h.type("T:sgDemo:Gains_RBV"), "waveform");
    EXPECT_EQ(h.type("T:sgDemo:Stage"), "motor");
    EXPECT_EQ(h.alarm("T:sgDemo:Counter"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.get("T:sgDemo:Counter"), m.value("Counter"));
    EXPECT_EQ(h.get("T:sgDemo:Offset"), 0.5) << "setpoints start at the model's values";
    EXPECT_EQ(h.get("T:sgDemo:PlantEnable"), 1);
    EXPECT_EQ(h.core->totals().malformed[0], 0u);
    auto app = h.core->applications().at(0);
    EXPECT_EQ(app.objects, 17u);
    for (uint64_t n : app.counters.malformed) EXPECT_EQ(n, 0u);
}

TEST_F(Loop, ASetpointDrivesThePlant) {
    ASSERT_EQ(h.put("T:sgDemo:Setpoint", 2.0), pv::PutStatus::Ok);
    run(0.5); // one time constant
    EXPECT_NEAR(h.get("T:sgDemo:PlantOut"), 2.0 * (1 - std::exp(-1.0)), 0.05);
    EXPECT_EQ(h.get("T:sgDemo:InTolerance"), 0);
    run(4);
    EXPECT_NEAR(h.get("T:sgDemo:PlantOut"), 2.0, 0.01);
    EXPECT_EQ(h.get("T:sgDemo:InTolerance"), 1);
    EXPECT_EQ(h.get("T:sgDemo:Setpoint_RBV"), 2.0);
    // The model clamps: the readback shows what it took.
    ASSERT_EQ(h.put("T:sgDemo:Mode", 7), pv::PutStatus::Ok);
    run(0.05);
    EXPECT_EQ(h.get("T:sgDemo:Mode_RBV"), 3);
    double gains[4] = {1, 2, 3, 4};
    ASSERT_EQ(h.db.put(h.addr("T:sgDemo:Gains"), pv::Prim::Double, gains, 4), pv::PutStatus::Ok);
    run(0.05);
    EXPECT_EQ(h.get_array("T:sgDemo:Gains_RBV"), (std::vector<double>{1, 2, 3, 4}));
}

TEST_F(Loop, TheMotorRecordMovesHomesAndIsRefused) {
    int done = 0;
    ASSERT_EQ(h.put("T:sgDemo:Stage.VELO", 5), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:sgDemo:Stage", 10, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    run(1);
    EXPECT_EQ(h.get("T:sgDemo:Stage.DMOV"), 0);
    EXPECT_GT(h.get("T:sgDemo:Stage.RBV"), 1);
    EXPECT_EQ(done, 0);
    run(3);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(h.get("T:sgDemo:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:sgDemo:Stage.RBV"), 10, 1e-4);
    // Home: the model searches forward, reverses at its +50 switch, ends on 0 and is homed.
    ASSERT_EQ(h.put("T:sgDemo:Stage.HVEL", 8), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:sgDemo:Stage.HOMF", 1), pv::PutStatus::Ok);
    run(30);
    EXPECT_EQ(h.get("T:sgDemo:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:sgDemo:Stage.RBV"), 0, 1e-4);
    EXPECT_NE(uint32_t(h.get("T:sgDemo:Stage.MSTA")) & (1u << 14), 0u) << "homed";
    // Beyond the model's soft limit: refused there, the record ends the move with a problem.
    done = 0;
    ASSERT_EQ(h.put("T:sgDemo:Stage", 60, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    run(1);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(h.get("T:sgDemo:Stage_ErrCode"), 1);
    EXPECT_EQ(h.alarm("T:sgDemo:Stage"), "MAJOR/STATE");
    EXPECT_NEAR(h.get("T:sgDemo:Stage.RBV"), 0, 1e-4);
}

TEST_F(Loop, ASilentModelTurnsItsPvsInvalidAndComesBack) {
    running = false;
    run(2.9);
    EXPECT_EQ(h.alarm("T:sgDemo:Sine"), "NO_ALARM/NO_ALARM");
    run(0.2);
    EXPECT_EQ(h.alarm("T:sgDemo:Sine"), "INVALID/COMM");
    EXPECT_EQ(h.alarm("T:sgDemo:Stage"), "INVALID/COMM");
    EXPECT_EQ(h.alarm("T:sgDemo:Spectrum"), "INVALID/COMM");
    running = true;
    run(0.05);
    EXPECT_EQ(h.alarm("T:sgDemo:Sine"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.alarm("T:sgDemo:Stage"), "NO_ALARM/NO_ALARM");
}

TEST_F(Loop, OfflineNothingReachesTheModelAndARestartedModelsValuesBecomeTheSetpoints) {
    ASSERT_EQ(h.put("T:sgDemo:Setpoint", 2.0), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:sgDemo:Stage.VELO", 5), pv::PutStatus::Ok);
    ASSERT_EQ(h.put("T:sgDemo:Stage", 5), pv::PutStatus::Ok);
    run(3);
    ASSERT_EQ(h.get("T:sgDemo:Setpoint_RBV"), 2.0);
    ASSERT_NEAR(h.get("T:sgDemo:Stage.RBV"), 5, 1e-4);
    ASSERT_EQ(h.get("T:sgDemo:Stage.DMOV"), 1);

    running = false; // its data stops; anything sent would still reach it
    run(3.1);
    ASSERT_EQ(h.alarm("T:sgDemo:Setpoint"), "INVALID/COMM");
    EXPECT_EQ(h.put("T:sgDemo:Setpoint", 3.0), pv::PutStatus::Failed);
    EXPECT_EQ(h.get("T:sgDemo:Setpoint"), 2.0);
    int done = 0;
    ASSERT_EQ(h.put("T:sgDemo:Stage", 20, [&](pv::PutStatus) { ++done; }), pv::PutStatus::Ok);
    run(0.1);
    EXPECT_EQ(done, 1);
    EXPECT_EQ(h.get("T:sgDemo:Stage.DMOV"), 1);
    EXPECT_NEAR(h.get("T:sgDemo:Stage.VAL"), 5, 1e-4);
    EXPECT_EQ(h.alarm("T:sgDemo:Stage"), "INVALID/COMM");
    run(1);
    EXPECT_EQ(m.value("Setpoint"), 2.0) << "no write reached the model";
    EXPECT_NEAR(m.value("Stage"), 5, 1e-9) << "no move reached the model";

    // The model restarts with its initial values (Setpoint 0, Offset 0.5, Stage at 0).
    m = Model(ModelConfig::load(kExample.string()));
    running = true;
    run(0.5);
    EXPECT_EQ(h.alarm("T:sgDemo:Setpoint"), "NO_ALARM/NO_ALARM");
    EXPECT_EQ(h.get("T:sgDemo:Setpoint"), 0);
    EXPECT_EQ(h.get("T:sgDemo:Setpoint_RBV"), 0);
    EXPECT_EQ(h.get("T:sgDemo:Offset"), h.get("T:sgDemo:Offset_RBV"));
    EXPECT_NEAR(h.get("T:sgDemo:Stage.VAL"), 0, 1e-4);
    EXPECT_NEAR(h.get("T:sgDemo:Stage.RBV"), 0, 1e-4);
    EXPECT_EQ(h.alarm("T:sgDemo:Stage"), "NO_ALARM/NO_ALARM");
    run(2);
    EXPECT_EQ(m.value("Setpoint"), 0) << "nothing is replayed";
    EXPECT_NEAR(m.value("Stage"), 0, 1e-9);
    EXPECT_EQ(h.get("T:sgDemo:Stage.DMOV"), 1);
}
