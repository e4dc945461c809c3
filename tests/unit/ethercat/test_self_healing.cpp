// The self-healing bus (issue 20): a start with slaves missing or of another identity, hot connect,
// a power cycle with its start-up SDOs written again, a line break and repair, a return with
// another identity, injected refusals, and a cycle the other slaves never notice. Health passes
// run without the RT thread (transactions go straight to the segment) so these are exact; the
// last tests run a real cycling thread beside the health pass.
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/faults.hpp"
#include "ethercat/sim/segment.hpp"

#include "sim_bus.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

using namespace beamctl;
using namespace beamctl::ethercat;
using beamctl::ethercat::simbus::Bus;

namespace {

void cycle(Master& m, int n = 1) {
    for (int i = 0; i < n; ++i) {
        m.send_process_data();
        m.receive_process_data();
    }
}

void fault(Bus& b, const std::string& text) {
    b.seg.apply(sim::parse_fault(text, Catalog::builtin(), b.seg.size()));
}

uint32_t coe_u16(sim::Esc& esc, uint16_t index, uint8_t sub) {
    std::vector<uint8_t> v;
    if (esc.coe()->upload(index, sub, v) != 0 || v.size() < 2) return 0xFFFFFFFF;
    return uint32_t(v[0] | v[1] << 8);
}

} // namespace

TEST(SelfHealing, MissingLastSlaveStartsWithoutItThenJoinsWhenPluggedIn) {
    Bus b({"EK1100", "EL2008", "EL1008"});
    b.cfg.push_back({3, "EL1008"}); // configured, not on the bus
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(m.slave_state(3), SlaveState::Missing);
    EXPECT_EQ(m.slave_health(3).error_id, slave_error::kNotOnline);
    EXPECT_NE(m.slave_last_error(3).find("ec0 position 3: missing (expected EL1008, vendor 0x00000002, product "
                                         "0x03f03052"),
              std::string::npos)
        << m.slave_last_error(3);
    EXPECT_NE(m.slave_last_error(3).find("3 slave(s) answer"), std::string::npos);
    for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(m.slave_state(i), SlaveState::Op);
    // its region is reserved: the names bind now and will not move
    const SignalInfo* in3 = m.find_signal("ec0.s3.binaryInput01");
    ASSERT_NE(in3, nullptr);
    uint32_t at = in3->bit_offset;
    cycle(m);
    EXPECT_TRUE(m.cycle_ok());
    EXPECT_TRUE(m.slave_valid(1) && m.slave_valid(2));
    EXPECT_FALSE(m.slave_valid(3));
    EXPECT_LT(m.wkc(), m.expected_wkc());
    EXPECT_EQ(m.responding(), 3);
    EXPECT_EQ(m.check_and_recover(), 0); // nothing there yet
    // plugged in at the end of the line
    b.seg.add(*Catalog::builtin().find("EL1008"));
    cycle(m);
    EXPECT_EQ(m.responding(), 4);
    EXPECT_TRUE(m.health_due());
    EXPECT_EQ(m.check_and_recover(), 1);
    EXPECT_EQ(m.slave_state(3), SlaveState::Op);
    EXPECT_EQ(m.slave_health(3).reconfigured, 1u);
    EXPECT_EQ(m.slave_health(3).error_id, 0u);
    EXPECT_EQ(b.seg.slave(3).al_state(), 8);
    *b.seg.slave(3).sm_buffer(0) = 0x01;
    cycle(m, 2);
    EXPECT_TRUE(m.slave_valid(3));
    EXPECT_EQ(m.wkc(), m.expected_wkc());
    EXPECT_EQ(m.find_signal("ec0.s3.binaryInput01")->bit_offset, at);
    EXPECT_EQ(m.get(*in3), 1u);
}

TEST(SelfHealing, MissingMiddleSlaveLeavesTheShiftedOneAloneAndBothJoin) {
    // A powered-off slave is bypassed: the one behind it answers at its position.
    Bus b({"EK1100", "EL2008", "EL7041", "EL1008"});
    fault(b, "power 2 off");
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(m.slave_state(2), SlaveState::WrongId);
    EXPECT_EQ(m.slave_health(2).error_id, slave_error::kVerificationFail);
    EXPECT_NE(m.slave_last_error(2).find("expected EL7041"), std::string::npos) << m.slave_last_error(2);
    EXPECT_NE(m.slave_last_error(2).find("found EL1008"), std::string::npos) << m.slave_last_error(2);
    EXPECT_EQ(m.slave_state(3), SlaveState::Missing);
    // nothing configured in the device that answered at position 2: INIT, no station address
    EXPECT_EQ(b.seg.slave(3).al_state(), 1);
    EXPECT_EQ(le16(b.seg.slave(3).memory() + 0x0010), 0);
    EXPECT_EQ(b.seg.slave(3).memory()[0x0600 + 12], 0); // FMMU 0 not enabled
    cycle(m);
    EXPECT_TRUE(m.cycle_ok());
    EXPECT_TRUE(m.slave_valid(1));
    fault(b, "power 2 on");
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 2);
    cycle(m, 2);
    for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_EQ(m.slave_state(i), SlaveState::Op) << i;
        EXPECT_TRUE(m.slave_valid(i)) << i;
    }
    EXPECT_EQ(m.wkc(), m.expected_wkc());
}

TEST(SelfHealing, PowerCycleWritesTheStartupSdosAgain) {
    Bus b({"EK1100", "EL1008", "EL7041"});
    b.cfg[2].sdos = {{0x8010, 1, 1500, 2}}; // max current [mA]
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(coe_u16(b.seg.slave(2), 0x8010, 1), 1500u);
    cycle(m);
    fault(b, "power 2 off");
    cycle(m);
    EXPECT_FALSE(m.slave_valid(2));
    EXPECT_TRUE(m.slave_valid(1)); // the others' data stays valid in the very cycle of the loss
    EXPECT_TRUE(m.cycle_ok());
    EXPECT_TRUE(m.health_due());
    EXPECT_EQ(m.check_and_recover(), 0);
    EXPECT_EQ(m.slave_state(2), SlaveState::Lost);
    EXPECT_EQ(m.slave_health(2).lost, 1u);
    EXPECT_EQ(m.slave_health(2).error_id, slave_error::kNotOnline);
    fault(b, "power 2 on"); // back with a fresh dictionary
    EXPECT_NE(coe_u16(b.seg.slave(2), 0x8010, 1), 1500u);
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 1);
    EXPECT_EQ(m.slave_state(2), SlaveState::Op);
    EXPECT_EQ(m.slave_health(2).reconfigured, 1u);
    EXPECT_EQ(coe_u16(b.seg.slave(2), 0x8010, 1), 1500u);
    std::vector<uint8_t> v = m.sdo_upload(2, 0x8010, 1); // read back through CoE
    ASSERT_EQ(v.size(), 2u);
    EXPECT_EQ(v[0] | v[1] << 8, 1500);
    cycle(m, 2);
    EXPECT_TRUE(m.slave_valid(2));
    EXPECT_EQ(m.wkc(), m.expected_wkc());
}

TEST(SelfHealing, ADcSlaveGetsItsSync0AgainAfterAPowerCycle) {
    Bus b({"EK1100", "EL1008", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.set_cycle_time_ns(500'000);
    m.bring_up();
    auto reg32 = [&](uint16_t a) { return le32(b.seg.slave(2).memory() + a); };
    uint16_t active = le16(b.seg.slave(2).memory() + 0x0980);
    EXPECT_NE(active, 0);
    fault(b, "power 2 off");
    cycle(m);
    m.check_and_recover();
    fault(b, "power 2 on");
    EXPECT_EQ(le16(b.seg.slave(2).memory() + 0x0980), 0);
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 1);
    EXPECT_EQ(le16(b.seg.slave(2).memory() + 0x0980), active);
    EXPECT_EQ(reg32(0x09A0), 500'000u);
    EXPECT_EQ(b.seg.slave(2).al_state(), 8);
}

TEST(SelfHealing, ReturnWithAnotherIdentityStaysOut) {
    Bus b({"EK1100", "EL1008", "EL2008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    cycle(m);
    fault(b, "replace 1 EL1252");
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 0);
    EXPECT_EQ(m.slave_state(1), SlaveState::WrongId);
    EXPECT_EQ(m.slave_health(1).error_id, slave_error::kVerificationFail);
    EXPECT_EQ(m.slave_health(1).lost, 1u);
    EXPECT_NE(m.slave_last_error(1).find("found EL1252"), std::string::npos) << m.slave_last_error(1);
    EXPECT_EQ(b.seg.slave(1).al_state(), 1);                       // left in INIT
    EXPECT_EQ(le16(b.seg.slave(1).memory() + 0x0010), 0);          // its station address taken back
    cycle(m);
    EXPECT_FALSE(m.slave_valid(1));
    EXPECT_TRUE(m.slave_valid(2));
    EXPECT_TRUE(m.cycle_ok());
    // a pass later (back-off not over): not tried again, nothing logged again
    uint32_t refused = m.slave_health(1).refused;
    m.check_and_recover();
    EXPECT_EQ(m.slave_health(1).refused, refused);
}

TEST(SelfHealing, LineBreakAndRepair) {
    Bus b({"EK1100", "EL1008", "EL2008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    cycle(m);
    fault(b, "break 1");
    cycle(m);
    EXPECT_TRUE(m.cycle_ok());
    EXPECT_TRUE(m.slave_valid(1));
    EXPECT_FALSE(m.slave_valid(2));
    EXPECT_FALSE(m.slave_valid(3));
    EXPECT_EQ(m.responding(), 2);
    m.check_and_recover();
    EXPECT_EQ(m.slave_state(2), SlaveState::Lost);
    EXPECT_EQ(m.slave_state(3), SlaveState::Lost);
    fault(b, "repair");
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 2);
    cycle(m, 2);
    for (std::size_t i = 1; i < 4; ++i) EXPECT_TRUE(m.slave_valid(i)) << i;
    EXPECT_EQ(m.slave_health(2).reconfigured, 1u);
    EXPECT_EQ(m.wkc(), m.expected_wkc());
}

TEST(SelfHealing, InjectedRefusalsLeaveTheSlaveOutUntilCleared) {
    Bus b({"EK1100", "EL1008", "EL7041"});
    b.cfg[2].sdos = {{0x8010, 1, 1500, 2}};
    fault(b, "refuse-state 2 SAFEOP 0x001D");
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(m.slave_state(1), SlaveState::Op);
    EXPECT_EQ(m.slave_state(2), SlaveState::Error);
    EXPECT_NE(m.slave_last_error(2).find("refused SAFEOP: AL status code 0x001D invalid output configuration"),
              std::string::npos)
        << m.slave_last_error(2);
    cycle(m);
    EXPECT_TRUE(m.cycle_ok()); // its FMMUs answer (present, not trusted): in the tolerated range
    EXPECT_TRUE(m.slave_valid(1));
    EXPECT_FALSE(m.slave_valid(2));
    // the SDO refused next: another error, the slave still out
    fault(b, "clear");
    fault(b, "refuse-sdo 2 0x8010:01 0x06090030");
    EXPECT_EQ(m.check_and_recover(), 0);
    EXPECT_EQ(m.slave_state(2), SlaveState::Error);
    EXPECT_NE(m.slave_last_error(2).find("SDO download 0x8010:01 aborted: 0x06090030"), std::string::npos)
        << m.slave_last_error(2);
    fault(b, "clear");
    cycle(m);
    // retried after its back-off (1 s, then 2 s, ...): a change of the bus lets it go at once
    fault(b, "power 2 off");
    cycle(m);
    m.check_and_recover();
    fault(b, "power 2 on");
    cycle(m);
    EXPECT_EQ(m.check_and_recover(), 1);
    EXPECT_EQ(m.slave_state(2), SlaveState::Op);
    EXPECT_EQ(coe_u16(b.seg.slave(2), 0x8010, 1), 1500u);
}

TEST(SelfHealing, OnePercentFrameLossInvalidatesOnlyTheLostCycles) {
    Bus b({"EK1100", "EL2008", "EL1008", "EL7041"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    cycle(m);
    b.seg.set_frame_loss(0.01, 7);
    int lost = 0, invalid = 0, inconsistent = 0;
    for (int c = 0; c < 60000; ++c) { // a minute at 1 kHz
        m.send_process_data();
        CycleStatus st = m.receive_process_data(0);
        bool all_valid = m.slave_valid(1) && m.slave_valid(2) && m.slave_valid(3);
        if (st == CycleStatus::FrameLost) ++lost;
        if (!all_valid) ++invalid;
        if (st == CycleStatus::WkcMismatch) ++inconsistent;
        EXPECT_EQ(all_valid, st == CycleStatus::Ok) << "cycle " << c;
        if (c % 100 == 99) { // a health pass every 100 ms; with the loss off so its own frames pass
            b.seg.set_frame_loss(0);
            m.check_and_recover();
            b.seg.set_frame_loss(0.01, uint64_t(8 + c));
        }
    }
    EXPECT_GT(lost, 300);
    EXPECT_LT(lost, 900);
    EXPECT_EQ(invalid, lost);
    EXPECT_EQ(inconsistent, 0);
    for (std::size_t i = 0; i < 4; ++i) {
        EXPECT_EQ(m.slave_state(i), SlaveState::Op) << i;
        EXPECT_EQ(m.slave_health(i).lost, 0u) << i;
    }
}

TEST(SelfHealing, LateAnswersAreCountedAndLoseNoSlave) {
    Bus b({"EK1100", "EL1008", "EL2008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    cycle(m, 2);
    fault(b, "delay 1.5"); // [ms]: beyond the 1 ms receive time-out of each cycle
    int lost = 0;
    for (int c = 0; c < 100; ++c) {
        m.send_process_data();
        if (m.receive_process_data(1000) == CycleStatus::FrameLost) ++lost;
        EXPECT_FALSE(m.slave_valid(1));
    }
    EXPECT_EQ(lost, 100);
    EXPECT_GE(m.frames_late(), 99u); // each came back one wait late: dropped as too old
    m.check_and_recover();
    for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(m.slave_state(i), SlaveState::Op) << i;
    fault(b, "delay 0.5"); // within the time-out: on time again
    for (int c = 0; c < 3; ++c) {
        m.send_process_data();
        m.receive_process_data(1000);
    }
    EXPECT_TRUE(m.slave_valid(1) && m.slave_valid(2));
    EXPECT_EQ(m.slave_health(1).lost, 0u);
}

TEST(SelfHealing, ACleanStopLeavesTheMissingSlaveAlone) {
    Bus b({"EK1100", "EL2008", "EL1008"});
    b.cfg.push_back({3, "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    cycle(m);
    EXPECT_NO_THROW(m.to_safe_op()); // not "no answer to the SAFEOP request" for the missing one
    EXPECT_EQ(b.seg.slave(1).al_state(), 4);
    EXPECT_EQ(b.seg.slave(2).al_state(), 4);
}

TEST(SelfHealing, StrictKeepsTheRefusalOfAMissingSlave) {
    Bus b({"EK1100", "EL1008"});
    b.cfg.push_back({2, "EL2008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.set_strict(true);
    EXPECT_THROW(m.bring_up(), Error);
}

// A real cycling thread (the RT thread's part) beside the health pass (the health thread's): a
// drive power-cycled and brought back while the other slaves' data is valid in every cycle.
TEST(SelfHealing, PowerCycleWhileCyclingNeverDisturbsTheOthers) {
    Bus b({"EK1100", "EL1008", "EL7041", "EL1008"});
    b.cfg[2].sdos = {{0x8010, 1, 1500, 2}};
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    m.start_cycling();
    std::atomic<bool> stop{false};
    std::atomic<uint64_t> cycles{0}, others_invalid{0}, inconsistent{0};
    std::thread rt([&] {
        while (!stop.load()) {
            m.send_process_data();
            m.receive_process_data(2000);
            cycles++;
            if (!m.slave_valid(1) || !m.slave_valid(3)) others_invalid++;
            if (!m.cycle_ok()) inconsistent++;
            std::this_thread::sleep_for(std::chrono::microseconds(20));
        }
    });
    auto until = [&](auto pred) {
        for (int i = 0; i < 400 && !pred(); ++i) {
            m.check_and_recover();
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        return pred();
    };
    ASSERT_TRUE(until([&] { return m.slave_valid(2); }));
    b.seg.post(sim::parse_fault("power 2 off", Catalog::builtin(), b.seg.size()));
    EXPECT_TRUE(until([&] { return m.slave_state(2) == SlaveState::Lost; }));
    b.seg.post(sim::parse_fault("power 2 on", Catalog::builtin(), b.seg.size()));
    uint64_t from = cycles.load();
    EXPECT_TRUE(until([&] { return m.slave_state(2) == SlaveState::Op && m.slave_valid(2); }));
    uint64_t to_op = cycles.load() - from;
    stop = true;
    rt.join();
    EXPECT_EQ(others_invalid.load(), 0u);
    EXPECT_EQ(inconsistent.load(), 0u);
    EXPECT_EQ(m.slave_health(2).lost, 1u);
    EXPECT_EQ(m.slave_health(2).reconfigured, 1u);
    EXPECT_EQ(coe_u16(b.seg.slave(2), 0x8010, 1), 1500u);
    RecordProperty("cycles_to_op", std::to_string(to_op));
}

TEST(SelfHealing, FaultCommandsParseAndRefuseBadInput) {
    const Catalog& cat = Catalog::builtin();
    EXPECT_EQ(sim::describe(sim::parse_fault("power 3 off", cat, 5)), "power 3 off");
    EXPECT_EQ(sim::describe(sim::parse_fault("  refuse-sdo 2 0x8010:01 0x06090030 ", cat, 5)),
              "refuse-sdo 2 0x8010:01 0x06090030");
    EXPECT_EQ(sim::describe(sim::parse_fault("refuse-state 1 OP 0x1D", cat, 5)), "refuse-state 1 OP 0x001D");
    EXPECT_EQ(sim::describe(sim::parse_fault("glitch 4 -500", cat, 5)), "glitch 4 -500");
    EXPECT_EQ(sim::describe(sim::parse_fault("replace 1 EL2008", cat, 5)), "replace 1 EL2008");
    EXPECT_EQ(sim::describe(sim::parse_fault("delay 2.5", cat, 5)), "delay 2.5");
    auto error = [&](const std::string& t) {
        try {
            sim::parse_fault(t, cat, 5);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(accepted)");
    };
    EXPECT_NE(error("power 5 off").find("'5' is not a slave position (0..4)"), std::string::npos);
    EXPECT_NE(error("power 1 maybe").find("power takes off or on"), std::string::npos);
    EXPECT_NE(error("loss 1.5").find("'1.5' is not a fraction 0..1"), std::string::npos);
    EXPECT_NE(error("replace 1 EL9999").find("'EL9999' is not a device type"), std::string::npos);
    EXPECT_NE(error("refuse-sdo 1 0x8010 5").find("is not an object INDEX:SUB"), std::string::npos);
    EXPECT_NE(error("explode 1").find("unknown fault 'explode'"), std::string::npos);
    EXPECT_NE(error("").find("empty"), std::string::npos);
    EXPECT_NE(error("delay -1").find("is not a delay of 0..1000 ms"), std::string::npos);
    // random words and bytes: an error or a fault, never a crash
    std::mt19937 rng(3);
    const char* vocab[] = {"power", "break", "loss", "refuse-sdo", "refuse-state", "glitch", "0x", "-1", "1e9", "OP",
                           "::", "0x8010:zz", "nan", "on", "off", "\xff", "replace", "EL1008", "clear", "99999999999999999999"};
    for (int i = 0; i < 20000; ++i) {
        std::string t;
        for (int w = int(rng() % 5); w >= 0; --w) t += std::string(vocab[rng() % 20]) + (rng() % 3 ? " " : "");
        try {
            sim::parse_fault(t, cat, 5);
        } catch (const Error&) {
        }
    }
}
