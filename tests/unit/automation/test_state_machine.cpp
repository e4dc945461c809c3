// State machines with an error latch (automation/state_machine.hpp) in virtual time, on records of
// one database: a transition's steps (put with put-callback, wait_for, delay) run in order and the
// state changes only when they are done; a false guard, a step that fails or times out, and an
// invariant that turns false latch the machine; a latched machine refuses every request until Ack,
// whose author is logged; auxiliary machines are guards on other machines' states.
#include "automation/state_machine.hpp"

#include "db_rig.hpp"

#include "core/error.hpp"
#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <gtest/gtest.h>

using namespace beamctl;
using namespace beamctl::automation;
using Step = config::StateMachineEntry::Step;

namespace {

const char* kDb = R"(
record(bo, "P:n2") { field(ZNAM, "Closed") field(ONAM, "Open") }
record(bo, "P:vac") { field(ZNAM, "Off") field(ONAM, "On") field(VAL, "1") }
record(calc, "P:floating") { field(INPA, "P:n2 CP") field(INPB, "P:vac CP") field(CALC, "A&&!B") }
record(ao, "P:x") { }
)";

Step put(const std::string& pv, double v, double timeout = 0) {
    Step s;
    s.kind = Step::Kind::Put, s.pv = pv, s.value = v, s.seconds = timeout, s.where = "t.yaml:" + pv;
    return s;
}
Step wait_for(const std::string& e, double timeout) {
    Step s;
    s.kind = Step::Kind::WaitFor, s.expr = e, s.seconds = timeout, s.where = "t.yaml:wait";
    return s;
}
Step delay(double t) {
    Step s;
    s.kind = Step::Kind::Delay, s.seconds = t, s.where = "t.yaml:delay";
    return s;
}

config::StateMachineEntry bearing() {
    config::StateMachineEntry e;
    e.name = "bearing", e.where = "t.yaml:1:1";
    e.states = {{"locked", "", "", {}, {}, ""}, {"landed", "", "", {}, {}, ""}, {"flying", "", "floating == 1", {}, {}, ""}};
    e.initial = "locked";
    e.names = {{"vac", "P:vac"}, {"floating", "P:floating"}};
    e.names_where = {"", ""};
    config::StateMachineEntry::Transition t;
    t.from = "locked", t.to = "landed", t.name = "release", t.steps = {put("P:vac", 0), wait_for("vac == 0", 2)};
    e.transitions.push_back(t);
    t.from = "landed", t.to = "flying", t.name = "fly", t.steps = {put("P:n2", 1), delay(0.5), wait_for("floating == 1", 2)};
    e.transitions.push_back(t);
    t.from = "flying", t.to = "landed", t.name = "land", t.steps = {put("P:n2", 0), wait_for("floating == 0", 2)};
    e.transitions.push_back(t);
    return e;
}

config::StateMachineEntry primary() {
    config::StateMachineEntry e;
    e.name = "main", e.where = "t.yaml:10:1";
    e.states = {{"parked", "", "", {}, {}, ""},          {"access", "parked", "", {}, {}, ""},
                {"normal", "", "floating == 1", {}, {}, ""}, {"error_latch", "", "", {}, {}, ""}};
    e.initial = "parked", e.latch = "error_latch", e.after_ack = "parked";
    e.names = {{"floating", "P:floating"}, {"x", "P:x"}};
    e.names_where = {"", ""};
    config::StateMachineEntry::Transition t;
    t.from = "parked", t.to = "normal", t.name = "unpark", t.guard = "bearing == bearing.flying";
    e.transitions.push_back(t);
    t = {};
    t.from = "parked", t.to = "access", t.name = "enter";
    e.transitions.push_back(t);
    t = {};
    t.from = "parked", t.to = "parked", t.name = "noop";
    e.transitions.push_back(t);
    t = {};
    t.from = "normal", t.to = "parked", t.name = "park", t.steps = {wait_for("x > 5", 3)}; // someone must set x
    e.transitions.push_back(t);
    return e;
}

struct Rig : test::DbRig {
    std::unique_ptr<StateMachines> sm;
    std::vector<std::string> latches;
    explicit Rig(std::vector<config::StateMachineEntry> cfg = {bearing(), primary()}) {
        db.load(pv::parse_db(kDb, "t.db", {}));
        sm = std::make_unique<StateMachines>(cfg, "S:", db, [this] { return now; });
        db.init_records();
        sm->start();
        sm->on_latch([this](const std::string& m, const std::string& why) { latches.push_back(m + ": " + why); });
        poll = [this] { sm->poll(); };
        run(0.1);
    }
    std::string text(const std::string& n) { return pv::get_text(*db.find(n)); }
    // The bearing landed, then flying; the main machine in normal operation.
    void fly_and_operate() {
        put("S:bearing:Request", 1);
        run(0.1);
        put("S:bearing:Request", 2);
        run(1.0);
        put("S:main:Request", 2);
        run(0.1);
    }
    std::string str(const std::string& n) {
        pv::Address a;
        db.resolve(n, a);
        char s[40] = {};
        db.get(a, pv::Prim::String, s, 1);
        return s;
    }
};

} // namespace

TEST(StateMachine, StartsInTheInitialStateAndServesItsPvs) {
    Rig r;
    EXPECT_EQ(r.sm->state_name("main"), "parked");
    EXPECT_EQ(r.get("S:main:State"), 0);
    EXPECT_EQ(r.str("S:main:State"), "parked");
    EXPECT_EQ(r.str("S:main:Request"), "parked");
    EXPECT_EQ(r.text("S:main:Allowed"), "normal, access, parked");
    EXPECT_EQ(r.get("S:main:Busy"), 0);
    EXPECT_EQ(r.get("S:main:Latched"), 0);
    EXPECT_EQ(r.str("S:bearing:State"), "locked");
}

TEST(StateMachine, ATransitionRunsItsStepsInOrderAndChangesStateWhenTheyAreDone) {
    Rig r;
    ASSERT_EQ(r.put("S:bearing:Request", 1), pv::PutStatus::Ok); // landed
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("bearing"), "landed");
    EXPECT_EQ(r.get("P:vac"), 0);
    ASSERT_EQ(r.put("S:bearing:Request", 2), pv::PutStatus::Ok); // flying: n2, a 0.5 s delay, floating
    r.run(0.2);
    EXPECT_TRUE(r.sm->busy("bearing"));
    EXPECT_EQ(r.get("S:bearing:Busy"), 1);
    EXPECT_EQ(r.str("S:bearing:Transition"), "fly");
    EXPECT_EQ(r.str("S:bearing:Step"), "2/3 delay 0.5 s");
    EXPECT_EQ(r.sm->state_name("bearing"), "landed"); // not before the steps are done
    EXPECT_EQ(r.put("S:bearing:Request", 0), pv::PutStatus::Failed); // one at a time
    r.run(0.5);
    EXPECT_FALSE(r.sm->busy("bearing"));
    EXPECT_EQ(r.sm->state_name("bearing"), "flying");
    EXPECT_EQ(r.get("P:floating"), 1);
    EXPECT_TRUE(r.latches.empty());
}

TEST(StateMachine, ARequestWithoutATransitionIsRefusedAndChangesNothing) {
    Rig r;
    EXPECT_EQ(r.put("S:bearing:Request", 2), pv::PutStatus::Failed); // locked -> flying: no such transition
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("bearing"), "locked");
    EXPECT_EQ(r.get("S:bearing:Request"), 0); // the refused value is not kept
    EXPECT_FALSE(r.sm->latched("main"));
}

TEST(StateMachine, AFalseGuardLatchesAndTheLatchRefusesEverythingUntilAcknowledged) {
    Rig r;
    EXPECT_EQ(r.put("S:main:Request", 2), pv::PutStatus::Failed); // unpark: the bearing is not flying
    EXPECT_TRUE(r.sm->latched("main"));
    EXPECT_EQ(r.str("S:main:State"), "error_latch");
    EXPECT_EQ(r.get("S:main:Latched"), 1);
    EXPECT_EQ(r.text("S:main:Error"), "guard of transition unpark does not hold: bearing == bearing.flying");
    ASSERT_EQ(r.latches.size(), 1u);
    EXPECT_EQ(r.text("S:main:Allowed"), "");
    EXPECT_EQ(r.put("S:main:Request", 1), pv::PutStatus::Failed); // refused while latched
    EXPECT_EQ(r.sm->state_name("main"), "error_latch");
    r.db.set_put_origin("alice@beamline");
    EXPECT_EQ(r.put("S:main:Ack", 1), pv::PutStatus::Ok);
    r.db.set_put_origin({});
    EXPECT_EQ(r.sm->state_name("main"), "parked");
    EXPECT_EQ(r.str("S:main:AckBy"), "alice@beamline");
    EXPECT_EQ(r.str("S:main:AckTime").size(), 20u); // 2026-11-28T21:01:27Z
    EXPECT_EQ(r.put("S:main:Ack", 1), pv::PutStatus::Failed); // nothing to acknowledge
    // the auxiliary machine flies: the guard holds
    r.put("S:bearing:Request", 1);
    r.run(0.1);
    r.put("S:bearing:Request", 2);
    r.run(1.0);
    ASSERT_EQ(r.sm->state_name("bearing"), "flying");
    EXPECT_EQ(r.put("S:main:Request", 2), pv::PutStatus::Ok);
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("main"), "normal");
}

TEST(StateMachine, AnInvariantThatTurnsFalseLatchesOnceAndAMachineWithoutALatchStaysAndSaysSo) {
    Rig r;
    r.fly_and_operate();
    ASSERT_EQ(r.sm->state_name("main"), "normal");
    r.put("P:n2", 0); // the tower lands on its own
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("main"), "error_latch");
    EXPECT_EQ(r.sm->error("main"), "the invariant of normal no longer holds: floating == 1");
    // the bearing machine has no latch: it stays in flying with the error, reported once
    EXPECT_EQ(r.sm->state_name("bearing"), "flying");
    EXPECT_EQ(r.sm->error("bearing"), "the invariant of flying no longer holds: floating == 1");
    r.run(1.0);
    EXPECT_EQ(r.latches.size(), 1u); // main's only (a machine without a latch does not notify)
}

TEST(StateMachine, AStepThatTimesOutLatchesNamingTheStep) {
    Rig r;
    r.fly_and_operate();
    ASSERT_EQ(r.put("S:main:Request", 0), pv::PutStatus::Ok); // park: waits for x > 5
    r.run(2.0);
    EXPECT_TRUE(r.sm->busy("main"));
    EXPECT_EQ(r.str("S:main:Step"), "1/1 wait for x > 5");
    r.run(1.5);
    EXPECT_EQ(r.sm->state_name("main"), "error_latch");
    EXPECT_EQ(r.sm->error("main"), "transition park failed at step 1/1 (t.yaml:wait): x > 5 did not hold within 3 s");
}

TEST(StateMachine, AStepWhoseConditionComesTrueEndsTheTransition) {
    Rig r;
    r.fly_and_operate();
    r.put("S:main:Request", 0);
    r.run(1.0);
    r.put("P:x", 6);
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("main"), "parked");
    EXPECT_FALSE(r.sm->latched("main"));
}

TEST(StateMachine, AFailedPutLatches) {
    auto m = primary();
    m.transitions[1].steps = {put("P:nonexistent", 1)};
    Rig r({bearing(), m});
    ASSERT_EQ(r.put("S:main:Request", 1), pv::PutStatus::Ok); // enter access: its put has no PV
    r.run(0.1);
    EXPECT_EQ(r.sm->state_name("main"), "error_latch");
    EXPECT_EQ(r.sm->error("main"), "transition enter failed at step 1/1 (t.yaml:P:nonexistent): P:nonexistent is not reachable");
}

TEST(StateMachine, BadExpressionsAreRefusedNamingWhere) {
    auto m = primary();
    m.transitions[0].guard = "bearing == bearing.hovering";
    m.transitions[0].where = "t.yaml:12:7";
    pv::Database db;
    db.load(pv::parse_db(kDb, "t.db", {}));
    try {
        StateMachines sm({bearing(), m}, "S:", db, [] { return 0.0; });
        FAIL() << "accepted an unknown state";
    } catch (const Error& e) {
        const std::string w = e.what();
        EXPECT_NE(w.find("t.yaml:12:7: state machine 'main': guard of unpark"), std::string::npos) << w;
        EXPECT_NE(w.find("bearing.hovering"), std::string::npos) << w;
        EXPECT_NE(w.find("bearing.flying"), std::string::npos) << w; // the names it knows
    }
}
