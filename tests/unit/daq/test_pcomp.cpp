// PCOMP against PandA's rules (specs/records.md §7): each scenario is a table of evaluations (one
// engine cycle each) written from PandA's semantics: what is set before the evaluation, then what
// OUT, PRODUCED, ACTIVE, HEALTH (and, where given, STATE) are after it. Outputs a row does not name
// must not change (as in PandA's timing tables).
#include "daq/pcomp.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace beamctl::daq {
namespace {

struct Scenario {
    const char* name;
    const char* params; // "START=4 STEP=3 WIDTH=2 PULSES=3 RELATIVE=0 DIR=0 PRE_START=0"
    std::vector<const char*> rows; // "INP=2 ENABLE=1 -> ACTIVE=1 STATE=3"
};

std::map<std::string, double> assignments(const std::string& text) {
    std::map<std::string, double> m;
    std::istringstream in(text);
    std::string kv;
    while (in >> kv) {
        auto eq = kv.find('=');
        if (eq == std::string::npos) ADD_FAILURE() << "bad token '" << kv << "'";
        else m[kv.substr(0, eq)] = std::stod(kv.substr(eq + 1));
    }
    return m;
}

void run(const Scenario& s) {
    SCOPED_TRACE(s.name);
    Pcomp pc;
    for (auto& [k, v] : assignments(s.params)) {
        if (k == "START") pc.params.start = v;
        else if (k == "STEP") pc.params.step = v;
        else if (k == "WIDTH") pc.params.width = v;
        else if (k == "PULSES") pc.params.pulses = uint32_t(v);
        else if (k == "PRE_START") pc.params.pre_start = v;
        else if (k == "RELATIVE") pc.params.relative = v != 0;
        else if (k == "DIR") pc.params.dir = PcompDir(int(v));
        else ADD_FAILURE() << "unknown parameter " << k;
    }
    bool enable = false;
    double inp = 0;
    std::map<std::string, double> have{{"OUT", 0}, {"PRODUCED", 0}, {"ACTIVE", 0}, {"HEALTH", 0}};
    int line = 0;
    for (const char* row : s.rows) {
        ++line;
        std::string text = row, set = text, expect;
        if (auto arrow = text.find("->"); arrow != std::string::npos) {
            set = text.substr(0, arrow);
            expect = text.substr(arrow + 2);
        }
        for (auto& [k, v] : assignments(set)) {
            if (k == "INP") inp = v;
            else if (k == "ENABLE") enable = v != 0;
            else ADD_FAILURE() << "row " << line << ": unknown input " << k;
        }
        pc.step(enable, inp);
        std::map<std::string, double> want = have;
        int state = -1;
        for (auto& [k, v] : assignments(expect)) {
            if (k == "STATE") state = int(v);
            else if (want.count(k)) want[k] = v;
            else ADD_FAILURE() << "row " << line << ": unknown output " << k;
        }
        have = {{"OUT", pc.out()}, {"PRODUCED", pc.produced()}, {"ACTIVE", pc.active()}, {"HEALTH", int(pc.health())}};
        for (auto& [k, v] : want) EXPECT_EQ(have[k], v) << "row " << line << " '" << row << "': " << k;
        if (state >= 0) EXPECT_EQ(int(pc.state()), state) << "row " << line << " '" << row << "': STATE";
        have = {{"OUT", pc.out()}, {"PRODUCED", pc.produced()}, {"ACTIVE", pc.active()}, {"HEALTH", int(pc.health())}};
    }
}

// STATE: 0 WAIT_ENABLE, 1 WAIT_DIR, 2 WAIT_PRE_START, 3 WAIT_RISING, 4 WAIT_FALLING.
// DIR: 0 Positive, 1 Negative, 2 Either.
const std::vector<Scenario> kScenarios = {
    {"three pulses forward", "START=4 STEP=3 WIDTH=2 PULSES=3",
     {"INP=2", "ENABLE=1 -> ACTIVE=1 STATE=3", "INP=3", "INP=4 -> OUT=1 PRODUCED=1 STATE=4", "INP=5",
      "INP=6 -> OUT=0 STATE=3", "INP=7 -> OUT=1 PRODUCED=2", "INP=8", "INP=9 -> OUT=0", "INP=10 -> OUT=1 PRODUCED=3",
      "INP=11", "INP=12 -> OUT=0 ACTIVE=0 STATE=0", "INP=13", "INP=16"}},
    {"enabled beyond START: waits to come from below", "START=4 STEP=3 WIDTH=2 PULSES=2",
     {"INP=5", "ENABLE=1 -> ACTIVE=1 STATE=2", "INP=4 -> STATE=2", "INP=3 -> STATE=3", "INP=4 -> OUT=1 PRODUCED=1",
      "INP=5", "INP=6 -> OUT=0", "INP=7 -> OUT=1 PRODUCED=2", "INP=8", "INP=9 -> OUT=0 ACTIVE=0 STATE=0"}},
    {"two pulses backward", "START=2 STEP=3 WIDTH=2 PULSES=2 DIR=1",
     {"INP=3", "ENABLE=1 -> ACTIVE=1 STATE=3", "INP=2 -> OUT=1 PRODUCED=1", "INP=1", "INP=0 -> OUT=0",
      "INP=-1 -> OUT=1 PRODUCED=2", "INP=-2", "INP=-3 -> OUT=0 ACTIVE=0", "INP=-4"}},
    {"a pulse only once per point, moving back and forth", "START=4 STEP=3 WIDTH=1 PULSES=2",
     {"INP=2", "ENABLE=1 -> ACTIVE=1", "INP=4 -> OUT=1 PRODUCED=1", "INP=5 -> OUT=0", "INP=6", "INP=5", "INP=4",
      "INP=3", "INP=4", "INP=5", "INP=6", "INP=7 -> OUT=1 PRODUCED=2", "INP=8 -> OUT=0 ACTIVE=0"}},
    {"jitter over START without PRE_START: the pulse stays up until WIDTH", "START=4 STEP=3 WIDTH=2 PULSES=2",
     {"INP=5", "ENABLE=1 -> ACTIVE=1", "INP=4", "INP=3 -> STATE=3", "INP=4 -> OUT=1 PRODUCED=1", "INP=3", "INP=2",
      "INP=0", "INP=3", "INP=5", "INP=6 -> OUT=0", "INP=7 -> OUT=1 PRODUCED=2", "INP=9 -> OUT=0 ACTIVE=0"}},
    {"PRE_START ignores jitter near START", "START=4 STEP=3 WIDTH=2 PULSES=2 PRE_START=2",
     {"INP=5", "ENABLE=1 -> ACTIVE=1 STATE=2", "INP=4", "INP=3", "INP=4", "INP=3", "INP=2 -> STATE=2",
      "INP=1 -> STATE=3", "INP=0", "INP=3", "INP=4 -> OUT=1 PRODUCED=1", "INP=6 -> OUT=0",
      "INP=7 -> OUT=1 PRODUCED=2", "INP=9 -> OUT=0 ACTIVE=0"}},
    {"DIR Either, absolute: guessed backward", "START=2 STEP=3 WIDTH=2 PULSES=2 DIR=2",
     {"INP=3", "ENABLE=1 -> ACTIVE=1 STATE=3", "INP=2 -> OUT=1 PRODUCED=1", "INP=1", "INP=0 -> OUT=0",
      "INP=-1 -> OUT=1 PRODUCED=2", "INP=-3 -> OUT=0 ACTIVE=0"}},
    {"DIR Either, absolute: guessed forward", "START=4 STEP=3 WIDTH=2 PULSES=3 DIR=2",
     {"INP=2", "ENABLE=1 -> ACTIVE=1 STATE=3", "INP=4 -> OUT=1 PRODUCED=1", "INP=3", "INP=1", "INP=-1", "INP=1",
      "INP=5", "INP=6 -> OUT=0", "INP=7 -> OUT=1 PRODUCED=2", "INP=9 -> OUT=0", "INP=10 -> OUT=1 PRODUCED=3",
      "INP=12 -> OUT=0 ACTIVE=0"}},
    {"DIR Either, absolute, enabled on START: waits until INP leaves it", "START=4 STEP=3 WIDTH=2 DIR=2",
     {"INP=4", "ENABLE=1 -> ACTIVE=1 STATE=1", "INP=4 -> STATE=1", "INP=3 -> STATE=3", "INP=4 -> OUT=1 PRODUCED=1"}},
    {"disabled while high: OUT and ACTIVE drop", "START=5 STEP=10 WIDTH=7 PULSES=3 DIR=1",
     {"INP=10", "ENABLE=1 -> ACTIVE=1", "INP=9", "INP=6", "INP=5 -> OUT=1 PRODUCED=1",
      "INP=4 ENABLE=0 -> OUT=0 ACTIVE=0 STATE=0", "INP=-20", "INP=10", "INP=5"}},
    {"disabled before the first point: nothing", "START=5 STEP=10 WIDTH=7 DIR=1",
     {"INP=10", "ENABLE=1 -> ACTIVE=1", "INP=6", "INP=5 ENABLE=0 -> ACTIVE=0 STATE=0", "INP=4", "INP=3"}},
    {"enabled again: PRODUCED and HEALTH start over", "START=4 STEP=5 WIDTH=2",
     {"INP=1", "ENABLE=1 -> ACTIVE=1", "INP=5 -> OUT=1 PRODUCED=1", "INP=10 -> OUT=0 ACTIVE=0 HEALTH=1",
      "ENABLE=0", "INP=0", "ENABLE=1 -> ACTIVE=1 HEALTH=0 PRODUCED=0 STATE=3", "INP=4 -> OUT=1 PRODUCED=1"}},
    {"absolute pulses forward, big steps", "START=4 STEP=5 WIDTH=2 PULSES=2",
     {"INP=9", "ENABLE=1 -> ACTIVE=1 STATE=2", "INP=1 -> STATE=3", "INP=5 -> OUT=1 PRODUCED=1", "INP=7 -> OUT=0",
      "INP=8", "INP=9 -> OUT=1 PRODUCED=2", "INP=15 -> OUT=0 ACTIVE=0"}},
    {"jump error while low: past the next rise and a whole STEP", "START=4 STEP=5 WIDTH=2",
     {"INP=9", "ENABLE=1 -> ACTIVE=1", "INP=1", "INP=5 -> OUT=1 PRODUCED=1", "INP=7 -> OUT=0", "INP=8",
      "INP=11 -> ACTIVE=0 HEALTH=1 STATE=0", "INP=14", "INP=20"}},
    {"jump error while high: past the next rise before falling", "START=4 STEP=5 WIDTH=2",
     {"INP=9", "ENABLE=1 -> ACTIVE=1", "INP=1", "INP=5 -> OUT=1 PRODUCED=1",
      "INP=9 -> OUT=0 ACTIVE=0 HEALTH=1 STATE=0"}},
    {"jump error far away", "START=4 STEP=5 WIDTH=2",
     {"INP=1", "ENABLE=1 -> ACTIVE=1", "INP=5 -> OUT=1 PRODUCED=1", "INP=7 -> OUT=0", "INP=80 -> ACTIVE=0 HEALTH=1"}},
    {"first point skipped entirely: jump error, not a pulse", "START=4 STEP=5 WIDTH=2",
     {"INP=1", "ENABLE=1 -> ACTIVE=1 STATE=3", "INP=9.5 -> ACTIVE=0 HEALTH=1 STATE=0"}},
    {"first point passed by less than STEP: a pulse", "START=4 STEP=5 WIDTH=2",
     {"INP=1", "ENABLE=1 -> ACTIVE=1", "INP=8.5 -> OUT=1 PRODUCED=1", "INP=8.8 -> OUT=0", "INP=9.5 -> OUT=1 PRODUCED=2"}},
    {"still high when INP reaches the next point: jump error", "START=4 STEP=5 WIDTH=2",
     {"INP=1", "ENABLE=1 -> ACTIVE=1", "INP=8.5 -> OUT=1 PRODUCED=1", "INP=9 -> OUT=0 ACTIVE=0 HEALTH=1"}},
    {"relative, backward", "START=3 STEP=4 WIDTH=2 PULSES=2 RELATIVE=1 DIR=1",
     {"INP=1", "INP=2 ENABLE=1 -> ACTIVE=1 STATE=3", "INP=3", "INP=1", "INP=0", "INP=-1 -> OUT=1 PRODUCED=1",
      "INP=-2", "INP=-3 -> OUT=0", "INP=-5 -> OUT=1 PRODUCED=2", "INP=-6", "INP=-7 -> OUT=0 ACTIVE=0"}},
    {"relative without START: the first pulse at enable", "STEP=4 WIDTH=2 PULSES=2 RELATIVE=1",
     {"INP=1", "INP=2 ENABLE=1 -> ACTIVE=1 OUT=1 PRODUCED=1 STATE=4", "INP=4 -> OUT=0 STATE=3",
      "INP=6 -> OUT=1 PRODUCED=2", "INP=8 -> OUT=0 ACTIVE=0", "ENABLE=0"}},
    {"relative, DIR Either: guessed forward", "START=3 STEP=4 WIDTH=2 PULSES=2 RELATIVE=1 DIR=2",
     {"INP=1", "INP=2 ENABLE=1 -> ACTIVE=1 STATE=1", "INP=3", "INP=4", "INP=5 -> OUT=1 PRODUCED=1 STATE=4", "INP=6",
      "INP=7 -> OUT=0", "INP=8", "INP=9 -> OUT=1 PRODUCED=2", "INP=10", "INP=11 -> OUT=0 ACTIVE=0"}},
    {"relative, DIR Either: guessed backward", "START=3 STEP=4 WIDTH=2 PULSES=2 RELATIVE=1 DIR=2",
     {"INP=1", "INP=2 ENABLE=1 -> ACTIVE=1 STATE=1", "INP=3", "INP=1", "INP=0", "INP=-1 -> OUT=1 PRODUCED=1",
      "INP=-3 -> OUT=0", "INP=-5 -> OUT=1 PRODUCED=2", "INP=-7 -> OUT=0 ACTIVE=0"}},
    {"relative, DIR Either with PRE_START: the run-up gives the direction", "PRE_START=2 STEP=4 WIDTH=2 PULSES=2 RELATIVE=1 DIR=2",
     {"INP=5", "INP=4 ENABLE=1 -> ACTIVE=1 STATE=1", "INP=3", "INP=2 -> STATE=2", "INP=1 -> STATE=3", "INP=2",
      "INP=3", "INP=4 -> OUT=1 PRODUCED=1", "INP=5", "INP=6 -> OUT=0", "INP=7", "INP=8 -> OUT=1 PRODUCED=2",
      "INP=10 -> OUT=0 ACTIVE=0"}},
    {"relative, DIR Either without START and PRE_START: HEALTH 2", "STEP=4 WIDTH=2 PULSES=2 RELATIVE=1 DIR=2",
     {"INP=1", "INP=2 ENABLE=1 -> ACTIVE=0 HEALTH=2 STATE=0", "INP=10"}},
    {"negative WIDTH: a Schmitt trigger", "START=4 WIDTH=-2 PULSES=2",
     {"INP=2", "ENABLE=1 -> ACTIVE=1", "INP=3", "INP=4 -> OUT=1 PRODUCED=1", "INP=3", "INP=2 -> OUT=0", "INP=3",
      "INP=4 -> OUT=1 PRODUCED=2", "INP=5", "INP=6", "INP=4", "INP=3", "INP=2 -> OUT=0 ACTIVE=0"}},
    {"STEP 0: a repeating comparator", "START=3 WIDTH=2 PULSES=2",
     {"INP=2", "ENABLE=1 -> ACTIVE=1", "INP=3 -> OUT=1 PRODUCED=1", "INP=4", "INP=5 -> OUT=0", "INP=6", "INP=5",
      "INP=4", "INP=3 -> OUT=1 PRODUCED=2", "INP=2", "INP=3", "INP=4", "INP=5 -> OUT=0 ACTIVE=0", "INP=6"}},
    {"one edge per cycle: a pulse narrower than a cycle's move still shows", "START=1 STEP=10 WIDTH=0.1",
     {"INP=0", "ENABLE=1 -> ACTIVE=1", "INP=1.5 -> OUT=1 PRODUCED=1", "INP=3 -> OUT=0", "INP=11.05 -> OUT=1 PRODUCED=2",
      "INP=11.3 -> OUT=0"}},
};

TEST(Pcomp, PandaRuleTable) {
    for (const Scenario& s : kScenarios) run(s);
}

// The spiral example's distance train: a pulse every 0.8 mm from 1 mm while the input moves
// 1 µm per cycle (1 mm/s at 1 kHz); every rise within one cycle of its ideal position.
TEST(Pcomp, DistanceTrainRisesWithinOneCycleOfEachPoint) {
    Pcomp pc;
    pc.params.start = 1.0;
    pc.params.step = 0.8;
    pc.params.width = 0.4;
    pc.params.pulses = 40;
    pc.step(false, 0);
    std::vector<double> rises;
    for (int k = 0; k < 40000; ++k) {
        double x = k * 1e-3;
        pc.step(true, x);
        if (pc.rose()) {
            rises.push_back(x);
            double ideal = 1.0 + 0.8 * double(rises.size() - 1);
            EXPECT_GE(x, ideal - 1e-9);
            EXPECT_LT(x - ideal, 1e-3 + 1e-9) << "pulse " << rises.size();
            EXPECT_NEAR(pc.edge_position(), ideal, 1e-12);
        }
    }
    EXPECT_EQ(rises.size(), 40u);
    EXPECT_EQ(pc.produced(), 40u);
    EXPECT_FALSE(pc.active());
    EXPECT_EQ(pc.health(), PcompHealth::Ok);
}

// The edge's place between two inputs: linear interpolation of the compare point.
TEST(Pcomp, EdgeFractionInterpolatesTheCrossing) {
    Pcomp pc;
    pc.params.start = 1.0;
    pc.params.step = 1.0;
    pc.params.width = 0.5;
    pc.step(true, 0.6);
    pc.step(true, 0.9);
    EXPECT_FALSE(pc.out());
    pc.step(true, 1.2);
    ASSERT_TRUE(pc.rose());
    EXPECT_NEAR(pc.edge_fraction(), 1.0 / 3.0, 1e-12);
    EXPECT_DOUBLE_EQ(pc.edge_position(), 1.0);
    pc.step(true, 1.5);
    ASSERT_TRUE(pc.fell());
    EXPECT_NEAR(pc.edge_fraction(), 1.0, 1e-12);
    EXPECT_DOUBLE_EQ(pc.edge_position(), 1.5);
}

// Relative: the compare points are offsets from INP at enable; edge_position() is absolute.
TEST(Pcomp, RelativeEdgePositionIsAbsolute) {
    Pcomp pc;
    pc.params.start = 2;
    pc.params.step = 3;
    pc.params.width = 1;
    pc.params.relative = true;
    pc.step(true, 10);
    for (double x = 10; x < 13; x += 0.25) pc.step(true, x);
    EXPECT_EQ(pc.produced(), 1u);
    EXPECT_DOUBLE_EQ(pc.edge_position(), 12);
}

TEST(Pcomp, NamesOfStatesAndHealth) {
    EXPECT_STREQ(to_string(PcompState::WaitPreStart), "WAIT_PRE_START");
    EXPECT_STREQ(to_string(PcompHealth::JumpError), "Error: Position jumped by more than STEP");
}

} // namespace
} // namespace beamctl::daq
