// Bus outages are logged when they begin (with what is wrong), at most every few seconds while
// they last, and when they end (with their duration): the monitor in virtual time, then a master
// over a simulated segment whose link goes down or whose slave is unplugged.
#include "ethercat/master.hpp"
#include "ethercat/outage.hpp"
#include "sim_bus.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::ethercat;

namespace {

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// Feeds the monitor one sample per 0.1 s health pass and keeps every line it asks to log.
struct Passes {
    OutageMonitor mon{"ec0"};
    BusSample s;
    int passes = 0;
    std::vector<std::pair<double, OutageMonitor::Report>> lines;
    Passes() {
        s.wkc = s.expected_wkc = 3;
    }
    // n passes, each after `lost`/`wkc_err` more errors.
    void run(int n, uint64_t lost = 0, uint64_t wkc_err = 0) {
        for (int i = 0; i < n; ++i) {
            double t = 100.0 + 0.1 * ++passes; // [s]
            s.frames_lost += lost;
            s.wkc_errors += wkc_err;
            if (auto r = mon.update(s, t)) lines.emplace_back(t, *r);
        }
    }
};

} // namespace

TEST(BusOutage, LinkDownIsLoggedAtOnceThenEveryFiveSecondsThenItsEndWithTheDuration) {
    Passes p;
    p.run(10);
    EXPECT_TRUE(p.lines.empty());
    p.s.frames_back = false; // every cycle's frame is lost from now on (100 per pass at 1 kHz)
    p.run(1, 100);
    ASSERT_EQ(p.lines.size(), 1u);
    EXPECT_EQ(p.lines[0].second.level, log::Level::err);
    EXPECT_EQ(p.lines[0].second.text, "ec0: bus outage: no cyclic frame comes back");
    p.run(120, 100); // 12 s more: one line per 5 s, not per pass
    ASSERT_EQ(p.lines.size(), 3u);
    EXPECT_NEAR(p.lines[1].first - p.lines[0].first, 5.0, 1e-6);
    EXPECT_NEAR(p.lines[2].first - p.lines[1].first, 5.0, 1e-6);
    EXPECT_TRUE(has(p.lines[1].second.text, "ec0: bus outage for 5.0 s: no cyclic frame comes back")) << p.lines[1].second.text;
    EXPECT_TRUE(has(p.lines[1].second.text, "5100 cyclic frame(s) lost, 0 cycle(s) with a wrong working counter so far")) << p.lines[1].second.text;
    p.s.frames_back = true; // the link is back
    p.run(20);
    ASSERT_EQ(p.lines.size(), 4u);
    const auto& [t_end, end] = p.lines[3];
    EXPECT_EQ(end.level, log::Level::info);
    // Down from the pass at +0.1 s through 12.1 s; seen good again 12.1 s after it began.
    EXPECT_EQ(end.text, "ec0: bus outage ended after 12.1 s (12100 cyclic frame(s) lost, 0 cycle(s) with a wrong working counter)");
    EXPECT_FALSE(p.mon.in_outage());
    (void)t_end;
}

TEST(BusOutage, AWrongWorkingCounterNamesTheCountsAndTheSlaves) {
    Passes p;
    p.run(2);
    p.s.wkc = 2;
    p.s.slaves = "slave 2 (EL7041) not answering";
    p.run(1, 0, 100);
    ASSERT_EQ(p.lines.size(), 1u);
    EXPECT_EQ(p.lines[0].second.text, "ec0: bus outage: working counter 2, expected 3; slave 2 (EL7041) not answering");
    p.s.wkc = 3;
    p.s.slaves.clear();
    p.run(10);
    ASSERT_EQ(p.lines.size(), 2u);
    EXPECT_TRUE(has(p.lines[1].second.text, "ended after 0.1 s (0 cyclic frame(s) lost, 100 cycle(s) with a wrong working counter)"))
        << p.lines[1].second.text;
}

TEST(BusOutage, AFlappingLinkIsOneOutageNotALineEveryPass) {
    Passes p;
    p.run(1);
    for (int i = 0; i < 60; ++i) { // 6 s of a link that drops every other pass
        p.s.frames_back = i % 2 == 1;
        p.run(1, 50);
    }
    p.s.frames_back = true;
    p.run(10);
    ASSERT_EQ(p.lines.size(), 3u); // began, once more after 5 s, ended
    EXPECT_TRUE(has(p.lines[0].second.text, "bus outage: "));
    EXPECT_TRUE(has(p.lines[1].second.text, "bus outage for 5.0 s"));
    EXPECT_TRUE(has(p.lines[2].second.text, "bus outage ended after"));
}

TEST(BusOutage, ErrorsBetweenGoodPassesAreSummedAtMostEveryFiveSeconds) {
    Passes p;
    p.run(1);
    p.run(1, 1); // one frame lost between two passes that both saw a good cycle
    ASSERT_EQ(p.lines.size(), 1u);
    EXPECT_EQ(p.lines[0].second.level, log::Level::warn);
    EXPECT_EQ(p.lines[0].second.text,
              "ec0: brief bus errors, the bus is OK: 1 cyclic frame(s) lost, 0 cycle(s) with a wrong working counter since the previous check");
    p.run(10, 1, 1); // one second of more
    EXPECT_EQ(p.lines.size(), 1u);
    p.run(40); // quiet: the sum comes when 5 s have passed since the last line
    ASSERT_EQ(p.lines.size(), 2u);
    EXPECT_TRUE(has(p.lines[1].second.text, "10 cyclic frame(s) lost, 10 cycle(s) with a wrong working counter in the last"))
        << p.lines[1].second.text;
    p.run(100);
    EXPECT_EQ(p.lines.size(), 2u);
}

TEST(BusOutage, MasterLogsALinkOutageWhenItBeginsAndWhenItEnds) {
    simbus::Bus b({"EK1100", "EL2008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    auto cycles = [&](int n) {
        for (int i = 0; i < n; ++i) {
            m.send_process_data();
            (void)m.receive_process_data(0);
        }
    };
    cycles(10);
    EXPECT_EQ(m.check_outage(10.0), "");
    b.seg.set_frame_loss(1.0); // nothing comes back
    cycles(100);
    EXPECT_EQ(m.check_outage(10.1), "ec0: bus outage: no cyclic frame comes back");
    cycles(100);
    EXPECT_EQ(m.check_outage(10.2), "");
    b.seg.set_frame_loss(0.0);
    cycles(100);
    EXPECT_EQ(m.check_outage(10.3), "");
    std::string end = m.check_outage(10.8);
    EXPECT_TRUE(has(end, "ec0: bus outage ended after 0.2 s (200 cyclic frame(s) lost")) << end;
}

TEST(BusOutage, MasterNamesTheUnpluggedSlave) {
    simbus::Bus b({"EK1100", "EL2008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    auto cycles = [&](int n) {
        for (int i = 0; i < n; ++i) {
            m.send_process_data();
            (void)m.receive_process_data(0);
        }
    };
    cycles(10);
    EXPECT_EQ(m.check_outage(1.0), "");
    b.seg.unplug(2);
    cycles(10);
    // A slave gone is not a bus outage: the cycle is consistent without it (the health pass
    // reports the slave lost).
    EXPECT_EQ(m.check_outage(1.1), "");
    // A working counter the slaves taking part do not explain is one, naming the slave missing.
    b.seg.slave(1).memory()[0x0600 + 12] = 0; // EL2008's output FMMU off
    cycles(10);
    std::string line = m.check_outage(1.2);
    EXPECT_TRUE(has(line, "ec0: bus outage: working counter ")) << line;
    EXPECT_TRUE(has(line, "slave 2 (EL1008) not answering")) << line;
}

// Through the health pass the bus thread runs (real clock), on stderr where operators see it.
TEST(BusOutage, TheHealthPassLogsAnOutageOnStderr) {
    simbus::Bus b({"EK1100", "EL2008", "EL1008"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    for (int i = 0; i < 10; ++i) {
        m.send_process_data();
        (void)m.receive_process_data(0);
    }
    m.check_and_recover();
    b.seg.set_frame_loss(1.0);
    for (int i = 0; i < 10; ++i) {
        m.send_process_data();
        (void)m.receive_process_data(0);
    }
    log::configure("info"); // whatever BEAMCTL_LOG says
    testing::internal::CaptureStderr();
    m.check_and_recover();
    std::string err = testing::internal::GetCapturedStderr();
    log::configure(); // back to BEAMCTL_LOG
    EXPECT_TRUE(has(err, "error ethercat.master: ec0: bus outage: no cyclic frame comes back")) << err;
}

TEST(BusOutage, BriefErrorsNotLoggedYetAreNamedWhenAnOutageBegins) {
    Passes p;
    p.run(1);
    p.run(1, 1); // logged at once
    p.run(10, 2); // within 5 s of that line: held back
    ASSERT_EQ(p.lines.size(), 1u);
    p.s.frames_back = false;
    p.run(1, 100);
    ASSERT_EQ(p.lines.size(), 2u);
    EXPECT_EQ(p.lines[1].second.text, "ec0: bus outage: no cyclic frame comes back (before it, in the last 1.0 s: "
                                      "20 cyclic frame(s) lost, 0 cycle(s) with a wrong working counter)");
    p.s.frames_back = true;
    p.run(100);
    ASSERT_EQ(p.lines.size(), 3u); // the end; the brief errors are not told again
    EXPECT_TRUE(has(p.lines[2].second.text, "ended after 0.1 s (100 cyclic frame(s) lost")) << p.lines[2].second.text;
}
