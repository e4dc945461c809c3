// Motor record behaviour as pyepics, ophyd and bluesky see it: calibration, limits, the DMOV
// 1->0->1 pulse, put-callback completion, STOP/SPMG, home, jog, tweak, retries, backlash, MSTA,
// ctrl metadata; a fake driver the tests steer, and the SimMotorDriver in virtual time.
#include "pv/database.hpp"
#include "pv/motor_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

using namespace beamctl;
using namespace beamctl::pv;

namespace {

// A driver whose status the test sets. Commands are logged; move/home/jog report done=false at
// once (the MotorDriver contract) and the test decides when the motion ends.
struct FakeDriver : MotorDriver {
    struct Call {
        std::string what;
        double a = 0, b = 0, c = 0;
    };
    std::vector<Call> calls;
    Status st;
    void busy(bool positive) {
        st.done = false;
        st.moving = true;
        st.direction_positive = positive;
    }
    void move(double t, double v, double a) override {
        calls.push_back({"move", t, v, a});
        busy(t >= st.position);
    }
    void move_velocity(double v, double a) override {
        calls.push_back({"jog", v, a});
        busy(v >= 0);
    }
    void home(bool fwd, double v, double a) override {
        calls.push_back({"home", fwd ? 1.0 : 0.0, v, a});
        busy(fwd);
    }
    void stop(double a) override { calls.push_back({"stop", a}); }
    void set_position(double p) override {
        calls.push_back({"set", p});
        st.position = p;
    }
    void set_closed_loop(bool on) override {
        calls.push_back({"cnen", on ? 1.0 : 0.0});
        st.enabled = on;
    }
    Status status() override { return st; }
    // The motion ends at `p` (dial).
    void arrive(double p) {
        st.position = p;
        st.done = true;
        st.moving = false;
    }
    int count(const std::string& what) const {
        int n = 0;
        for (auto& c : calls) n += c.what == what;
        return n;
    }
    const Call& last(const std::string& what) const {
        for (auto it = calls.rbegin(); it != calls.rend(); ++it)
            if (it->what == what) return *it;
        static Call none{"none"};
        return none;
    }
};

// Logs "FIELD=value" for each monitor event, in posting order, into a shared log.
struct Watch : Subscription {
    Database* db = nullptr;
    std::string field;
    std::vector<std::string>* log = nullptr;
    std::vector<double> values;
    std::vector<unsigned> masks;
    void on_event(unsigned m) override {
        double v = 0;
        db->get(addr, Prim::Double, &v, 1);
        values.push_back(v);
        masks.push_back(m);
        if (log) {
            char buf[64];
            std::snprintf(buf, sizeof buf, "%s=%g", field.c_str(), v);
            log->push_back(buf);
        }
    }
};

struct MotorTest : ::testing::Test {
    Database db;
    std::shared_ptr<FakeDriver> drv = std::make_shared<FakeDriver>();
    double now = 100; // virtual time [s]
    MotorRecord* m = nullptr;
    std::vector<std::unique_ptr<Watch>> watches;
    std::vector<std::string> events;

    ~MotorTest() override {
        for (auto& w : watches) db.unsubscribe(*w);
    }
    // Loads record "m" with the given fields; with `fake`, the fake driver is attached first.
    // `others`: more records of the same file (link targets).
    void load(const std::string& fields, bool fake = true, const std::string& others = "") {
        db.load(parse_db(others + "record(motor, \"m\") {" + fields + "}", "m.db", {}));
        m = MotorRecord::from(db.find("m"));
        ASSERT_NE(m, nullptr);
        m->set_clock([this] { return now; });
        if (fake) m->set_driver(drv);
        db.init_records();
    }
    Address addr(const std::string& n) {
        Address a;
        EXPECT_TRUE(db.resolve(n, a)) << n;
        return a;
    }
    PutStatus put(const std::string& n, double v, PutCallback cb = {}) {
        return db.put(addr(n), Prim::Double, &v, 1, std::move(cb));
    }
    PutStatus put_str(const std::string& n, const char* s) {
        char buf[40] = {};
        std::strncpy(buf, s, 39);
        return db.put(addr(n), Prim::String, buf, 1);
    }
    double getd(const std::string& n) {
        double d = 0;
        db.get(addr(n), Prim::Double, &d, 1);
        return d;
    }
    std::string gets(const std::string& n) {
        char s[40] = {};
        db.get(addr(n), Prim::String, s, 1);
        return s;
    }
    Watch& watch(const std::string& n, unsigned mask = kDbeValue | kDbeAlarm) {
        auto w = std::make_unique<Watch>();
        w->db = &db;
        w->field = n.substr(n.find('.') + 1);
        w->log = &events;
        w->addr = addr(n);
        w->mask = mask;
        db.subscribe(*w);
        watches.push_back(std::move(w));
        return *watches.back();
    }
    Metadata meta(const std::string& n) {
        Address a = addr(n);
        Metadata md;
        a.rec->metadata(*a.field, md);
        return md;
    }
    // Ends the fake motion at dial `p` and polls.
    void arrive(double p) {
        drv->arrive(p);
        m->poll();
    }
};

constexpr const char* kBasic = R"(field(MRES, "0.001") field(VELO, "2") field(ACCL, "0.5")
                                   field(EGU, "mm") field(PREC, "3"))";

} // namespace

TEST_F(MotorTest, TypeFieldsAndDefaults) {
    load(kBasic);
    EXPECT_EQ(gets("m.RTYP"), "motor");
    EXPECT_EQ(addr("m.MSTA").native, Prim::Double); // ULONG reaches CA as DOUBLE
    EXPECT_EQ(addr("m.RVAL").native, Prim::Long);
    EXPECT_EQ(addr("m.RRBV").native, Prim::Long);
    EXPECT_EQ(addr("m.DMOV").native, Prim::Short);
    EXPECT_EQ(addr("m.VAL").native, Prim::Double);
    EXPECT_EQ(addr("m.SPMG").native, Prim::Enum);
    EXPECT_EQ(addr("m.EGU").native, Prim::String);
    EXPECT_EQ(gets("m.SPMG"), "Go");
    EXPECT_EQ(gets("m.DIR"), "Pos");
    EXPECT_EQ(gets("m.FOFF"), "Variable");
    EXPECT_EQ(gets("m.SET"), "Use");
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(getd("m.LVIO"), 0);
    EXPECT_EQ(getd("m.RTRY"), 10);
    EXPECT_DOUBLE_EQ(getd("m.BACC"), 0.5);
    EXPECT_DOUBLE_EQ(getd("m.UREV"), 0.2); // MRES * SREV(200)
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM");
    EXPECT_EQ(gets("m.SCAN"), "Passive"); // the polling does not show in SCAN
    EXPECT_FALSE(addr("m.RBV").writable());
    EXPECT_FALSE(addr("m.DMOV").writable());
    EXPECT_FALSE(addr("m.MSTA").writable());
    EXPECT_EQ(put("m.DMOV", 0), PutStatus::ReadOnly);
}

TEST_F(MotorTest, UserDialRawConversions) {
    load(std::string(kBasic) + R"(field(OFF, "2"))");
    ASSERT_EQ(put("m", 5), PutStatus::Ok);
    ASSERT_EQ(drv->count("move"), 1);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 3.0); // dial = user - OFF
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 3.0);
    EXPECT_EQ(getd("m.RVAL"), 3000);            // raw = dial / MRES
    EXPECT_DOUBLE_EQ(drv->last("move").b, 2.0); // VELO
    EXPECT_DOUBLE_EQ(drv->last("move").c, 4.0); // VELO / ACCL
    arrive(3.0);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 5.0);
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 3.0);
    EXPECT_EQ(getd("m.RRBV"), 3000);

    ASSERT_EQ(put_str("m.DIR", "Neg"), PutStatus::Ok); // FOFF Variable: OFF follows, VAL stays
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 5.0);
    EXPECT_DOUBLE_EQ(getd("m.OFF"), 8.0); // 5 = -3 + 8
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 5.0);
    ASSERT_EQ(put("m", 6), PutStatus::Ok); // user up = dial down
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.0);
    arrive(2.0);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 6.0);

    ASSERT_EQ(put("m.RVAL", 1500), PutStatus::Ok); // raw target
    EXPECT_DOUBLE_EQ(drv->last("move").a, 1.5);
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 1.5);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 6.5);
    arrive(1.5);
    ASSERT_EQ(put("m.DVAL", 1.0), PutStatus::Ok); // dial target
    EXPECT_DOUBLE_EQ(drv->last("move").a, 1.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 7.0);
    EXPECT_EQ(getd("m.RVAL"), 1000);
}

TEST_F(MotorTest, ReadbackIsQuantisedToSteps) {
    load(kBasic);
    drv->st.position = 1.23456;
    m->poll();
    EXPECT_EQ(getd("m.RRBV"), 1235);
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 1.235);
    EXPECT_DOUBLE_EQ(getd("m.RMP"), 1235);
}

TEST_F(MotorTest, SetVariableMovesTheOffsetOnly) {
    load(std::string(kBasic) + R"(field(DHLM, "10") field(DLLM, "-10"))");
    put("m", 1.0);
    arrive(1.0);
    Watch& dmov = watch("m.DMOV");
    ASSERT_EQ(put_str("m.SET", "Set"), PutStatus::Ok);
    ASSERT_EQ(put("m", 4.0), PutStatus::Ok);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_DOUBLE_EQ(getd("m.OFF"), 3.0);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 4.0);
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 1.0);
    EXPECT_DOUBLE_EQ(getd("m.HLM"), 13.0); // user limits move with the offset
    EXPECT_DOUBLE_EQ(getd("m.LLM"), -7.0);
    EXPECT_DOUBLE_EQ(getd("m.DHLM"), 10.0);
    EXPECT_EQ(drv->count("move"), 1); // the move there, nothing since
    EXPECT_EQ(drv->count("set"), 0);
}

TEST_F(MotorTest, SetFrozenRedefinesTheDialPosition) {
    load(std::string(kBasic) + R"(field(OFF, "1") field(FOFF, "Frozen"))");
    ASSERT_EQ(put_str("m.SET", "Set"), PutStatus::Ok);
    ASSERT_EQ(put("m", 4.0), PutStatus::Ok);
    ASSERT_EQ(drv->count("set"), 1);
    EXPECT_DOUBLE_EQ(drv->last("set").a, 3.0);
    EXPECT_DOUBLE_EQ(getd("m.OFF"), 1.0);
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 3.0);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 4.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(drv->count("move"), 0);
}

TEST_F(MotorTest, SetDvalReloadsTheHardwareAndKeepsVal) {
    load(kBasic);
    ASSERT_EQ(put_str("m.SET", "Set"), PutStatus::Ok);
    ASSERT_EQ(put("m.DVAL", 5.0), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("set").a, 5.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 0.0); // VAL as before (init took it from the readback 0)
    EXPECT_DOUBLE_EQ(getd("m.OFF"), -5.0);
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 5.0);
    ASSERT_EQ(put("m.RVAL", 7000), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("set").a, 7.0);
    EXPECT_EQ(drv->count("move"), 0);
}

TEST_F(MotorTest, PyepicsSetPositionPlainPutsInOrder) {
    load(kBasic);
    put("m", 1.5);
    arrive(1.5);
    ASSERT_EQ(put("m.SET", 1), PutStatus::Ok); // Motor.set_position(12.0): no wait, in order
    ASSERT_EQ(put("m.VAL", 12.0), PutStatus::Ok);
    ASSERT_EQ(put("m.SET", 0), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 12.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 12.0);
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 1.5);
    EXPECT_EQ(gets("m.SET"), "Use");
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(drv->count("move"), 1);
    ASSERT_EQ(put("m.VAL", 13.0), PutStatus::Ok); // after SET=0 a move is a move again
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.5);
}

TEST_F(MotorTest, OphydSetCurrentPositionWithCallbacks) {
    load(kBasic);
    std::vector<int> done;
    put("m.SET", 1, [&](PutStatus s) { done.push_back(1 + 10 * int(s)); });
    put("m.VAL", 3.0, [&](PutStatus s) { done.push_back(2 + 10 * int(s)); });
    put("m.SET", 0, [&](PutStatus s) { done.push_back(3 + 10 * int(s)); });
    EXPECT_EQ(done, (std::vector<int>{1, 2, 3}));
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 3.0);
}

TEST_F(MotorTest, UserAndDialLimitsThroughDirAndOff) {
    load(std::string(kBasic) + R"(field(DHLM, "10") field(DLLM, "-5") field(OFF, "1"))");
    EXPECT_DOUBLE_EQ(getd("m.HLM"), 11.0); // init derives user limits from dial limits
    EXPECT_DOUBLE_EQ(getd("m.LLM"), -4.0);
    ASSERT_EQ(put_str("m.DIR", "Neg"), PutStatus::Ok);
    double off = getd("m.OFF");
    EXPECT_DOUBLE_EQ(off, 1.0);                        // FOFF Variable: VAL 1 = DVAL 0 * -1 + OFF
    EXPECT_DOUBLE_EQ(getd("m.HLM"), 5.0 + off);        // -DLLM + OFF
    EXPECT_DOUBLE_EQ(getd("m.LLM"), -10.0 + off);      // -DHLM + OFF
    ASSERT_EQ(put("m.HLM", 3.0 + off), PutStatus::Ok); // user high = dial low when DIR=Neg
    EXPECT_DOUBLE_EQ(getd("m.DLLM"), -3.0);
    ASSERT_EQ(put("m.DHLM", 8.0), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.LLM"), -8.0 + off);
    ASSERT_EQ(put("m.OFF", off + 2), PutStatus::Ok); // limits and VAL follow the offset
    EXPECT_DOUBLE_EQ(getd("m.HLM"), 3.0 + off + 2);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), getd("m.RBV"));
    EXPECT_EQ(drv->count("move"), 0);
}

TEST_F(MotorTest, SoftLimitViolationRefusesAndPulsesDmov) {
    load(std::string(kBasic) + R"(field(DHLM, "10") field(DLLM, "-10"))");
    ASSERT_EQ(put("m", 2), PutStatus::Ok);
    arrive(2);
    Watch& dmov = watch("m.DMOV");
    bool completed = false;
    PutStatus how = PutStatus::Ok;
    ASSERT_EQ(put("m", 20, [&](PutStatus s) { completed = true, how = s; }), PutStatus::Ok);
    EXPECT_TRUE(completed); // nothing to wait for
    EXPECT_EQ(how, PutStatus::Failed); // a refused move is not a success
    EXPECT_EQ(getd("m.LVIO"), 1);
    EXPECT_EQ(getd("m.SEVR"), 1); // SOFT/MINOR until the next move
    EXPECT_EQ(gets("m.STAT"), "SOFT");
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 2.0); // target reverts
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 2.0);
    EXPECT_EQ(getd("m.RVAL"), 2000);
    EXPECT_EQ(drv->count("move"), 1);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    ASSERT_EQ(put("m", -3), PutStatus::Ok); // a valid move clears LVIO
    EXPECT_EQ(getd("m.LVIO"), 0);
    EXPECT_EQ(getd("m.SEVR"), 0);
    EXPECT_EQ(drv->count("move"), 2);
}

// The driver refuses a move, or its motion ends short (a limit, an interlock, a fault): the
// put-callback fails, MSTA has PROBLEM, the record alarms (RBV included: ophyd checks it), DMOV is
// 1 and the targets are back at the readback. A later put-callback on another field succeeds.
TEST_F(MotorTest, AMoveTheControllerRefusesOrEndsShortFailsItsPutCallbackAndAlarms) {
    load(kBasic);
    bool completed = false;
    PutStatus how = PutStatus::Ok;
    ASSERT_EQ(put("m", 5, [&](PutStatus s) { completed = true, how = s; }), PutStatus::Ok);
    EXPECT_FALSE(completed);
    drv->st.position = 1.25; // ended short
    drv->st.done = true;
    drv->st.moving = false;
    drv->st.failed = drv->st.problem = true;
    m->poll();
    EXPECT_TRUE(completed);
    EXPECT_EQ(how, PutStatus::Failed);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_TRUE(uint32_t(getd("m.MSTA")) & (1u << 9));
    EXPECT_EQ(getd("m.SEVR"), 2);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 1.25); // VAL takes the readback
    EXPECT_EQ(getd("m.LVIO"), 0);
    bool velo_ok = false;
    ASSERT_EQ(put("m.VELO", 1, [&](PutStatus s) { velo_ok = s == PutStatus::Ok; }), PutStatus::Ok);
    EXPECT_TRUE(velo_ok);
    // refused for a soft limit of the controller (a kinematics group): LVIO too
    drv->st.failed = drv->st.problem = false;
    completed = false;
    ASSERT_EQ(put("m", 3, [&](PutStatus s) { completed = true, how = s; }), PutStatus::Ok);
    drv->st.done = true;
    drv->st.moving = false;
    drv->st.failed = drv->st.problem = drv->st.limit_violation = true;
    m->poll();
    EXPECT_TRUE(completed);
    EXPECT_EQ(how, PutStatus::Failed);
    EXPECT_EQ(getd("m.LVIO"), 1);
    // the next good move succeeds and clears the alarm
    drv->st = MotorDriver::Status{};
    drv->st.position = 1.25;
    completed = false;
    ASSERT_EQ(put("m", 2, [&](PutStatus s) { completed = true, how = s; }), PutStatus::Ok);
    arrive(2);
    EXPECT_TRUE(completed);
    EXPECT_EQ(how, PutStatus::Ok);
    EXPECT_EQ(getd("m.SEVR"), 0);
}

// A driver that has not read its controller yet (valid = false): when the readback becomes valid
// with the record idle, VAL/DVAL/RVAL take it, so a tweak starts from where the axis is.
TEST_F(MotorTest, ValStartsAtTheFirstValidReadback) {
    drv->st.valid = false;
    drv->st.position = 0;
    load(kBasic);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 0.0);
    drv->st.valid = true;
    drv->st.position = 1.5; // the absolute encoder's position
    m->poll();
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 1.5);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 1.5);
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 1.5);
    EXPECT_EQ(getd("m.RVAL"), 1500);
    ASSERT_EQ(put("m.TWV", 0.5), PutStatus::Ok);
    ASSERT_EQ(put("m.TWF", 1), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.0); // forward from 1.5
}

TEST_F(MotorTest, LimitsOffWhenBothZeroAndAlwaysViolatedWhenInverted) {
    load(kBasic);
    ASSERT_EQ(put("m", 1000), PutStatus::Ok);
    EXPECT_EQ(drv->count("move"), 1);
    EXPECT_EQ(getd("m.LVIO"), 0);
    arrive(1000);
    ASSERT_EQ(put("m.DLLM", 5), PutStatus::Ok);
    ASSERT_EQ(put("m.DHLM", 1), PutStatus::Ok);
    ASSERT_EQ(put("m", 3), PutStatus::Ok);
    EXPECT_EQ(getd("m.LVIO"), 1);
    EXPECT_EQ(drv->count("move"), 1);
}

TEST_F(MotorTest, MovingBackIntoTheRangeIsAllowed) {
    load(std::string(kBasic) + R"(field(DHLM, "10") field(DLLM, "-10"))");
    ASSERT_EQ(put_str("m.SET", "Set"), PutStatus::Ok); // calibrate the motor outside its limits
    ASSERT_EQ(put("m.DVAL", 15), PutStatus::Ok);
    ASSERT_EQ(put_str("m.SET", "Use"), PutStatus::Ok);
    ASSERT_EQ(put("m.DVAL", 12), PutStatus::Ok); // still outside, but towards the range
    EXPECT_EQ(getd("m.LVIO"), 0);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 12.0);
    arrive(12);
    ASSERT_EQ(put("m.DVAL", 13), PutStatus::Ok); // further out: refused
    EXPECT_EQ(getd("m.LVIO"), 1);
    EXPECT_EQ(drv->count("move"), 1);
}

TEST_F(MotorTest, NullMovesStillPulseDmov) {
    load(std::string(kBasic) + R"(field(MRES, "0.1"))");
    Watch& dmov = watch("m.DMOV");
    bool completed = false;
    ASSERT_EQ(put("m", 0.04, [&](PutStatus) { completed = true; }), PutStatus::Ok); // < 1 step
    EXPECT_TRUE(completed);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_EQ(drv->count("move"), 0);
    ASSERT_EQ(put("m.SPDB", 0.5), PutStatus::Ok);
    ASSERT_EQ(put("m", 0.3), PutStatus::Ok); // 3 steps, inside SPDB
    EXPECT_EQ(drv->count("move"), 0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1, 0, 1}));
    ASSERT_EQ(put("m.TWF", 0), PutStatus::Ok); // even writing 0 to a button pulses
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1, 0, 1, 0, 1}));
    ASSERT_EQ(put("m", 0.6), PutStatus::Ok); // outside SPDB: moves
    EXPECT_EQ(drv->count("move"), 1);
}

TEST_F(MotorTest, DmovFallsBeforeTheMoveAndRisesWithTheCallbackAtDone) {
    load(kBasic);
    Watch& dmov = watch("m.DMOV");
    Watch& rbv = watch("m.RBV");
    std::vector<std::size_t> moves_at_dmov;
    int completed = 0;
    ASSERT_EQ(put("m", 1.0, [&](PutStatus s) { completed += s == PutStatus::Ok; }), PutStatus::Ok);
    ASSERT_EQ(dmov.values, (std::vector<double>{0}));
    EXPECT_EQ(drv->count("move"), 1);
    EXPECT_EQ(events.front(), "DMOV=0"); // posted in special(), before anything else
    for (int i = 0; i < 5; ++i) {
        drv->st.position = 0.2 * i;
        now += 0.1;
        m->poll();
    }
    EXPECT_EQ(completed, 0);
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_EQ(getd("m.MOVN"), 1);
    EXPECT_GE(rbv.values.size(), 4u); // readback monitors while moving
    arrive(1.0);
    EXPECT_EQ(completed, 1);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_EQ(events.back(), "DMOV=1"); // after RBV
    EXPECT_EQ(getd("m.MOVN"), 0);
    m->poll(); // nothing changed: nothing posted, nothing completed twice
    EXPECT_EQ(dmov.values.size(), 2u);
    EXPECT_EQ(completed, 1);
}

TEST_F(MotorTest, SecondPutCallbackWaitsBehindTheFirstMove) {
    load(kBasic);
    std::vector<int> done;
    put("m", 1.0, [&](PutStatus) { done.push_back(1); });
    put("m", 2.0, [&](PutStatus) { done.push_back(2); });
    EXPECT_EQ(drv->count("move"), 1); // the second waits (arrival order)
    arrive(1.0);
    EXPECT_EQ(done, (std::vector<int>{1}));
    EXPECT_EQ(drv->count("move"), 2);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.0);
    arrive(2.0);
    EXPECT_EQ(done, (std::vector<int>{1, 2}));
}

TEST_F(MotorTest, DlyHoldsDmovAfterTheMotion) {
    load(std::string(kBasic) + R"(field(DLY, "0.5"))");
    bool completed = false;
    put("m", 1.0, [&](PutStatus) { completed = true; });
    arrive(1.0);
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_EQ(getd("m.MOVN"), 0); // MOVN is not the inverse of DMOV
    now += 0.3;
    m->poll();
    EXPECT_FALSE(completed);
    now += 0.3;
    m->poll();
    EXPECT_TRUE(completed);
    EXPECT_EQ(getd("m.DMOV"), 1);
}

TEST_F(MotorTest, OphydMoveSeesTheDmovEdgeAndNoAlarmOnRbv) {
    load(std::string(kBasic) + R"(field(DHLM, "100") field(DLLM, "-100"))");
    Metadata md = meta("m.VAL");
    EXPECT_DOUBLE_EQ(md.ctrl_hi, 100); // ophyd checks the target against these first
    EXPECT_DOUBLE_EQ(md.ctrl_lo, -100);
    Watch& dmov = watch("m.DMOV");
    ASSERT_EQ(put("m", 5.0), PutStatus::Ok); // ophyd: VAL without a callback
    drv->st.position = 2.5;
    m->poll();
    arrive(5.0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_EQ(getd("m.TDIR"), 1);
    EXPECT_EQ(getd("m.HLS"), 0);
    EXPECT_EQ(getd("m.LLS"), 0);
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM"); // RBV's severity is the record's
}

TEST_F(MotorTest, StopHaltsAndThenTargetsFollowTheReadback) {
    load(kBasic);
    bool completed = false;
    put("m", 10.0, [&](PutStatus) { completed = true; });
    drv->st.position = 2.0;
    m->poll();
    ASSERT_EQ(put("m.STOP", 1), PutStatus::Ok);
    EXPECT_EQ(drv->count("stop"), 1);
    EXPECT_EQ(getd("m.STOP"), 0); // resets itself
    EXPECT_EQ(getd("m.DMOV"), 0); // until the motor has stopped
    EXPECT_FALSE(completed);
    arrive(2.5);
    EXPECT_TRUE(completed);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 2.5);
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 2.5);
    EXPECT_EQ(getd("m.RVAL"), 2500);
    EXPECT_EQ(drv->count("move"), 1); // no retry towards the old target
}

TEST_F(MotorTest, SpmgPauseResumesOnGo) {
    load(kBasic);
    put("m", 4.0);
    drv->st.position = 1.0;
    m->poll();
    ASSERT_EQ(put_str("m.SPMG", "Pause"), PutStatus::Ok);
    EXPECT_EQ(drv->count("stop"), 1);
    arrive(1.2);
    EXPECT_EQ(getd("m.DMOV"), 0); // still going to 4 later
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 4.0);
    ASSERT_EQ(put("m", 5.0), PutStatus::Ok); // a new target while paused waits too
    EXPECT_EQ(drv->count("move"), 1);
    ASSERT_EQ(put_str("m.SPMG", "Go"), PutStatus::Ok);
    EXPECT_EQ(drv->count("move"), 2);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 5.0);
    arrive(5.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
}

TEST_F(MotorTest, SpmgStopHaltsAndHoldsNewTargetsUntilGo) {
    load(kBasic);
    put("m", 4.0);
    drv->st.position = 1.0;
    m->poll();
    ASSERT_EQ(put_str("m.SPMG", "Stop"), PutStatus::Ok);
    EXPECT_EQ(drv->count("stop"), 1);
    arrive(1.1);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 1.1);
    bool completed = false;
    ASSERT_EQ(put("m", 3.0, [&](PutStatus) { completed = true; }), PutStatus::Ok);
    EXPECT_EQ(drv->count("move"), 1); // held
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_FALSE(completed);
    ASSERT_EQ(put_str("m.SPMG", "Go"), PutStatus::Ok);
    EXPECT_EQ(drv->count("move"), 2);
    arrive(3.0);
    EXPECT_TRUE(completed);
}

TEST_F(MotorTest, SpmgMoveFallsBackToPauseAfterOneMove) {
    load(kBasic);
    ASSERT_EQ(put_str("m.SPMG", "Move"), PutStatus::Ok);
    put("m", 1.0);
    arrive(1.0);
    EXPECT_EQ(gets("m.SPMG"), "Pause");
    put("m", 2.0);
    EXPECT_EQ(drv->count("move"), 1);
    EXPECT_EQ(getd("m.DMOV"), 0);
}

TEST_F(MotorTest, HomeForwardAndReverse) {
    load(std::string(kBasic) + R"(field(HVEL, "0.5") field(DIR, "Neg"))");
    Watch& dmov = watch("m.DMOV");
    bool completed = false;
    ASSERT_EQ(put("m.HOMF", 1, [&](PutStatus) { completed = true; }), PutStatus::Ok);
    ASSERT_EQ(drv->count("home"), 1);
    EXPECT_EQ(drv->last("home").a, 1.0); // HOMF is dial forward, whatever DIR says
    EXPECT_DOUBLE_EQ(drv->last("home").b, 0.5);
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_EQ(put("m.HOMF", 1), PutStatus::Failed); // not while homing
    EXPECT_EQ(put("m.HOMR", 1), PutStatus::Failed);
    drv->st.homed = true;
    arrive(0.25);
    EXPECT_TRUE(completed);
    EXPECT_EQ(getd("m.HOMF"), 0); // cleared when done
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_DOUBLE_EQ(getd("m.VAL"), -0.25);
    EXPECT_NE(int(getd("m.MSTA")) & (1 << 14), 0); // HOMED
    ASSERT_EQ(put("m.HOMR", 1), PutStatus::Ok);
    EXPECT_EQ(drv->last("home").a, 0.0);
    arrive(0);
    EXPECT_EQ(getd("m.HOMR"), 0);
}

TEST_F(MotorTest, HomeOnTheSwitchIsRefusedWithADmovPulse) {
    load(kBasic);
    drv->st.high_limit = true;
    m->poll();
    Watch& dmov = watch("m.DMOV");
    ASSERT_EQ(put("m.HOMF", 1), PutStatus::Ok);
    EXPECT_EQ(drv->count("home"), 0);
    EXPECT_EQ(getd("m.HOMF"), 0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
}

TEST_F(MotorTest, HomeWhileMovingStopsFirst) {
    load(kBasic);
    put("m", 3.0);
    ASSERT_EQ(put("m.HOMR", 1), PutStatus::Ok);
    EXPECT_EQ(drv->count("stop"), 1);
    EXPECT_EQ(drv->count("home"), 0);
    arrive(1.0);
    EXPECT_EQ(drv->count("home"), 1);
    EXPECT_EQ(getd("m.DMOV"), 0);
    arrive(0.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(getd("m.HOMR"), 0);
}

TEST_F(MotorTest, JogRunsWhileTheButtonIsHeld) {
    load(std::string(kBasic) + R"(field(JVEL, "0.5") field(JAR, "2") field(DIR, "Neg"))");
    ASSERT_EQ(put("m.JOGF", 1), PutStatus::Ok);
    ASSERT_EQ(drv->count("jog"), 1);
    EXPECT_DOUBLE_EQ(drv->last("jog").a, -0.5); // user forward = dial negative with DIR=Neg
    EXPECT_DOUBLE_EQ(drv->last("jog").b, 2.0);
    EXPECT_EQ(getd("m.DMOV"), 0);
    drv->st.position = -1.0;
    m->poll();
    EXPECT_EQ(put("m.JOGR", 1), PutStatus::Failed); // one jog at a time
    EXPECT_EQ(drv->count("stop"), 0);
    ASSERT_EQ(put("m.JOGF", 0), PutStatus::Ok);
    EXPECT_EQ(drv->count("stop"), 1);
    EXPECT_DOUBLE_EQ(drv->last("stop").a, 2.0); // JAR
    EXPECT_EQ(getd("m.DMOV"), 0);
    arrive(-1.2);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 1.2);
    EXPECT_EQ(drv->count("move"), 0); // BDST 0: no backlash leg
}

TEST_F(MotorTest, JogStopsBeforeTheSoftLimit) {
    load(std::string(kBasic) + R"(field(JVEL, "1") field(DHLM, "10") field(DLLM, "-10"))");
    ASSERT_EQ(put("m.JOGF", 1), PutStatus::Ok);
    drv->st.position = 8.0;
    m->poll();
    EXPECT_EQ(drv->count("stop"), 0);
    drv->st.position = 9.5; // within JVEL of HLM
    m->poll();
    EXPECT_EQ(drv->count("stop"), 1);
    EXPECT_EQ(getd("m.LVIO"), 1);
    EXPECT_EQ(getd("m.JOGF"), 0);
    arrive(9.8);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 9.8);
    ASSERT_EQ(put("m.JOGF", 1), PutStatus::Ok); // starting inside the margin: refused
    EXPECT_EQ(drv->count("jog"), 1);
    EXPECT_EQ(getd("m.JOGF"), 0);
}

TEST_F(MotorTest, JogWithBacklashApproachesFromBdst) {
    load(std::string(kBasic) + R"(field(BDST, "0.5") field(BVEL, "0.1"))");
    put("m.JOGF", 1);
    drv->st.position = 2.0;
    m->poll();
    put("m.JOGF", 0);
    arrive(2.2);
    ASSERT_EQ(drv->count("move"), 1);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 1.7); // stop position - BDST
    EXPECT_EQ(getd("m.DMOV"), 0);
    arrive(1.7);
    ASSERT_EQ(drv->count("move"), 2);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.2);
    EXPECT_DOUBLE_EQ(drv->last("move").b, 0.1); // BVEL
    arrive(2.2);
    EXPECT_EQ(getd("m.DMOV"), 1);
}

TEST_F(MotorTest, TweaksAndRelativeMoves) {
    load(std::string(kBasic) + R"(field(TWV, "0.25") field(OFF, "1"))");
    ASSERT_EQ(put("m.TWF", 1), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 0.25);
    EXPECT_EQ(getd("m.TWF"), 0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 1.25);
    arrive(0.25);
    ASSERT_EQ(put("m.TWR", 1), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 0.0);
    arrive(0.0);
    ASSERT_EQ(put("m.RLV", -2), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(drv->last("move").a, -2.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), -1.0);
    EXPECT_DOUBLE_EQ(getd("m.RLV"), 0.0);
    EXPECT_EQ(drv->count("move"), 3);
}

TEST_F(MotorTest, HardLimitRefusesOnlyMovesFurtherIntoTheSwitch) {
    load(kBasic);
    drv->st.position = 5.0;
    drv->st.high_limit = true;
    m->poll();
    EXPECT_EQ(getd("m.HLS"), 1);
    EXPECT_EQ(getd("m.RHLS"), 1);
    Watch& dmov = watch("m.DMOV");
    ASSERT_EQ(put("m", 6.0), PutStatus::Ok);
    EXPECT_EQ(drv->count("move"), 0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 5.0);    // VAL = RBV
    ASSERT_EQ(put("m", 4.0), PutStatus::Ok); // away from the switch
    EXPECT_EQ(drv->count("move"), 1);
    arrive(4.0);
    EXPECT_EQ(put("m.JOGF", 1), PutStatus::Failed); // no jog into it either
    EXPECT_EQ(drv->count("jog"), 0);
}

TEST_F(MotorTest, HardLimitSwitchesFollowDirAndMresSign) {
    load(std::string(kBasic) + R"(field(DIR, "Neg"))");
    drv->st.high_limit = true; // dial + switch
    m->poll();
    EXPECT_EQ(getd("m.LLS"), 1); // user - is dial + with DIR=Neg
    EXPECT_EQ(getd("m.HLS"), 0);
    EXPECT_EQ(getd("m.RHLS"), 1);
    ASSERT_EQ(put("m.MRES", -0.001), PutStatus::Ok); // raw + is dial -
    EXPECT_EQ(getd("m.RLLS"), 1);
    EXPECT_EQ(getd("m.LLS"), 1);
    unsigned msta = unsigned(getd("m.MSTA"));
    EXPECT_NE(msta & (1u << 13), 0u); // MINUS_LS is raw
    EXPECT_EQ(msta & (1u << 2), 0u);
}

TEST_F(MotorTest, HittingALimitSwitchEndsTheMoveWithAlarm) {
    load(std::string(kBasic) + R"(field(HLSV, "MAJOR"))");
    Watch& rbv_alarm = watch("m.RBV", kDbeAlarm); // what ophyd's RBV monitor sees
    bool completed = false;
    put("m", 10.0, [&](PutStatus) { completed = true; });
    drv->st.high_limit = true;
    arrive(4.0);
    EXPECT_TRUE(completed);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 4.0);
    EXPECT_EQ(drv->count("move"), 1); // no retries into the switch
    EXPECT_EQ(gets("m.SEVR"), "MAJOR");
    EXPECT_EQ(gets("m.STAT"), "HIGH");
    EXPECT_EQ(rbv_alarm.masks.size(), 1u);
    drv->st.high_limit = false;
    m->poll();
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM");
    EXPECT_EQ(rbv_alarm.masks.size(), 2u); // the clear is posted on RBV too
}

TEST_F(MotorTest, MstaBitsFromTheDriverStatus) {
    load(kBasic);
    EXPECT_EQ(unsigned(getd("m.MSTA")), (1u << 1) | (1u << 5) | (1u << 11) | (1u << 0));
    drv->st.done = false;
    drv->st.moving = true;
    drv->st.direction_positive = false;
    drv->st.home_switch = true;
    drv->st.has_encoder = true;
    drv->st.slip_stall = true;
    drv->st.low_limit = true;
    drv->st.enabled = false;
    m->poll();
    unsigned msta = unsigned(getd("m.MSTA"));
    EXPECT_EQ(msta,
              (1u << 3) | (1u << 6) | (1u << 7) | (1u << 8) | (1u << 10) | (1u << 11) | (1u << 13));
    EXPECT_EQ(getd("m.TDIR"), 0);
    EXPECT_EQ(getd("m.ATHM"), 1);
    EXPECT_EQ(gets("m.CNEN"), "Disable");
    EXPECT_EQ(gets("m.SEVR"), "MAJOR"); // slip/stall
    drv->st.slip_stall = false;
    drv->st.problem = true;
    drv->st.comm_error = true;
    m->poll();
    msta = unsigned(getd("m.MSTA"));
    EXPECT_NE(msta & (1u << 9), 0u);
    EXPECT_NE(msta & (1u << 12), 0u);
    EXPECT_EQ(gets("m.SEVR"), "INVALID");
}

TEST_F(MotorTest, ExternalMotionDrivesDmov) {
    load(kBasic);
    Watch& dmov = watch("m.DMOV");
    drv->busy(true); // moved by someone else
    drv->st.position = 0.5;
    m->poll();
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_EQ(getd("m.MOVN"), 1);
    arrive(2.0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 2.0);
    EXPECT_EQ(drv->count("move"), 0);
}

TEST_F(MotorTest, RetriesUntilCloseEnoughThenMiss) {
    load(std::string(kBasic) + R"(field(RTRY, "2") field(RDBD, "0.01"))");
    put("m", 1.0);
    arrive(0.9); // 0.1 short
    EXPECT_EQ(drv->count("move"), 2);
    EXPECT_EQ(getd("m.RCNT"), 1);
    EXPECT_EQ(getd("m.DMOV"), 0);
    arrive(0.995); // inside RDBD
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(getd("m.MISS"), 0);
    put("m", 2.0);
    EXPECT_EQ(getd("m.RCNT"), 0);
    arrive(1.5);
    arrive(1.5);
    arrive(1.5);
    EXPECT_EQ(drv->count("move"), 5); // 2 moves + 2 retries for this target
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(getd("m.MISS"), 1);
    EXPECT_EQ(getd("m.RCNT"), 3);
}

TEST_F(MotorTest, BacklashLegForMovesAgainstThePreferredDirection) {
    load(std::string(kBasic) + R"(field(BDST, "0.5") field(BVEL, "0.2") field(BACC, "0.4"))");
    put("m", -3.0); // against +BDST: first to -3.5 at VELO, then to -3 at BVEL
    EXPECT_DOUBLE_EQ(drv->last("move").a, -3.5);
    EXPECT_DOUBLE_EQ(drv->last("move").b, 2.0);
    arrive(-3.5);
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_DOUBLE_EQ(drv->last("move").a, -3.0);
    EXPECT_DOUBLE_EQ(drv->last("move").b, 0.2);
    EXPECT_DOUBLE_EQ(drv->last("move").c, 0.5); // BVEL / BACC
    arrive(-3.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
    put("m", 3.0); // preferred direction, far: one move at VELO (BVEL differs: backlash leg)
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.5);
    arrive(2.5);
    arrive(3.0);
    put("m", 3.2); // preferred, within BDST: one slow move
    EXPECT_DOUBLE_EQ(drv->last("move").a, 3.2);
    EXPECT_DOUBLE_EQ(drv->last("move").b, 0.2);
}

TEST_F(MotorTest, NewTargetWhileMovingRetargets) {
    load(kBasic);
    put("m", 5.0);
    drv->st.position = 1.0;
    m->poll();
    put("m", 2.0);
    EXPECT_EQ(drv->count("move"), 2);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.0);
    EXPECT_EQ(getd("m.DMOV"), 0);
    arrive(2.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(drv->count("move"), 2);
}

TEST_F(MotorTest, CtrlLimitsUnitsAndPrecision) {
    load(
        std::string(kBasic) +
        R"(field(DHLM, "10") field(DLLM, "-5") field(OFF, "1") field(VBAS, "0.1") field(VMAX, "4"))");
    Metadata v = meta("m.VAL"), r = meta("m.RBV"), d = meta("m.DVAL"), dr = meta("m.DRBV");
    EXPECT_DOUBLE_EQ(v.ctrl_hi, 11);
    EXPECT_DOUBLE_EQ(v.ctrl_lo, -4);
    EXPECT_DOUBLE_EQ(r.ctrl_hi, 11);
    EXPECT_DOUBLE_EQ(d.ctrl_hi, 10);
    EXPECT_DOUBLE_EQ(d.ctrl_lo, -5);
    EXPECT_DOUBLE_EQ(dr.disp_lo, -5);
    Metadata rv = meta("m.RVAL");
    EXPECT_DOUBLE_EQ(rv.ctrl_hi, 10000);
    Metadata ve = meta("m.VELO");
    EXPECT_DOUBLE_EQ(ve.ctrl_hi, 4);
    EXPECT_DOUBLE_EQ(ve.ctrl_lo, 0.1);
    EXPECT_STREQ(ve.units, "mm/sec");
    EXPECT_STREQ(v.units, "mm");
    EXPECT_EQ(v.precision, 3);
    EXPECT_EQ(meta("m.ACCL").units, std::string("sec"));
    EXPECT_EQ(gets("m.VAL"), "1.000");
    EXPECT_EQ(gets("m.RBV"), "1.000");
    Watch& prop = watch("m.VAL", kDbeProperty);
    ASSERT_EQ(put("m.DHLM", 20), PutStatus::Ok); // derived HLM changes: clients re-read ctrl
    EXPECT_GE(prop.masks.size(), 1u);
    std::size_t n = prop.masks.size();
    ASSERT_EQ(put("m.OFF", 2), PutStatus::Ok); // OFF moves HLM/LLM without touching them
    EXPECT_GT(prop.masks.size(), n);
    EXPECT_DOUBLE_EQ(meta("m.VAL").ctrl_hi, 22);
}

TEST_F(MotorTest, SpeedsClampedToVbasVmax) {
    load(std::string(kBasic) + R"(field(VBAS, "0.5") field(VMAX, "3"))");
    ASSERT_EQ(put("m.VELO", 10), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 3);
    ASSERT_EQ(put("m.VELO", 0.1), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 0.5);
    Watch& velo = watch("m.VELO");
    ASSERT_EQ(put("m.VBAS", 1), PutStatus::Ok); // VELO follows, and is posted
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 1);
    EXPECT_EQ(velo.values, (std::vector<double>{1}));
    ASSERT_EQ(put("m.VMAX", 0), PutStatus::Ok); // 0: no upper check
    ASSERT_EQ(put("m.VELO", 50), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 50);
    put("m", 1);
    EXPECT_DOUBLE_EQ(drv->last("move").b, 50);
    EXPECT_DOUBLE_EQ(drv->last("move").c, (50 - 1) / 0.5); // (VELO - VBAS) / ACCL
}

TEST_F(MotorTest, BadValuesAreRefusedAndChangeNothing) {
    load(kBasic);
    EXPECT_EQ(put("m.MRES", 0), PutStatus::BadValue);
    EXPECT_DOUBLE_EQ(getd("m.MRES"), 0.001);
    EXPECT_EQ(put("m", NAN), PutStatus::BadValue);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_EQ(drv->count("move"), 0);
    EXPECT_EQ(put_str("m.URIP", "Yes"), PutStatus::Failed);
    EXPECT_EQ(put_str("m.SPMG", "Sideways"), PutStatus::BadValue);
}

TEST_F(MotorTest, MresChangeKeepsTheDialTarget) {
    load(kBasic);
    put("m", 1.0);
    arrive(1.0);
    ASSERT_EQ(put("m.MRES", 0.01), PutStatus::Ok);
    EXPECT_EQ(getd("m.RVAL"), 100);
    EXPECT_EQ(getd("m.RRBV"), 100);
    EXPECT_DOUBLE_EQ(getd("m.UREV"), 2.0);
    EXPECT_EQ(drv->count("move"), 1); // not a new raw target
    EXPECT_EQ(getd("m.DMOV"), 1);
}

TEST_F(MotorTest, CnenSwitchesClosedLoop) {
    load(kBasic);
    ASSERT_EQ(put_str("m.CNEN", "Disable"), PutStatus::Ok);
    EXPECT_EQ(drv->last("cnen").a, 0.0);
    EXPECT_EQ(gets("m.CNEN"), "Disable");
    ASSERT_EQ(put_str("m.CNEN", "Enable"), PutStatus::Ok);
    EXPECT_EQ(drv->last("cnen").a, 1.0);
}

TEST_F(MotorTest, PeriodicScanPollsWithoutClientTraffic) {
    load(kBasic);
    bool completed = false;
    put("m", 1.0, [&](PutStatus) { completed = true; });
    drv->arrive(1.0);
    db.scan_periodic(now);
    EXPECT_TRUE(completed);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 1.0);
    EXPECT_EQ(gets("m.SCAN"), "Passive");
}

TEST_F(MotorTest, DriverAttachedAfterInitTakesOver) {
    load(kBasic, false);
    EXPECT_NE(dynamic_cast<SimMotorDriver*>(m->driver().get()), nullptr); // none given: the sim
    drv->st.position = 4.0;
    int offered = 0;
    attach_motor_drivers(db, [&](MotorRecord& r) {
        ++offered;
        EXPECT_EQ(r.name(), "m");
        return std::shared_ptr<MotorDriver>(drv);
    });
    EXPECT_EQ(offered, 1);
    EXPECT_EQ(m->driver(), drv);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 4.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 4.0);
}

TEST_F(MotorTest, OutTextIsKeptForWhoeverAttachesDrivers) {
    load(std::string(kBasic) + R"x(field(OUT, "@asyn(MCU1,3)") field(DTYP, "asynMotor"))x");
    EXPECT_EQ(m->out(), "@asyn(MCU1,3)");
    EXPECT_FALSE(addr("m.OUT").writable());
    EXPECT_EQ(gets("m.DTYP"), "asynMotor");
}

TEST_F(MotorTest, RestoreModeLoadsTheSavedDialPosition) {
    load(std::string(kBasic) + R"(field(DVAL, "3.5"))"); // autosave restored DVAL; driver at 0
    EXPECT_EQ(drv->count("set"), 1);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 3.5);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 3.5);
}

TEST_F(MotorTest, RestoreModeNeverKeepsTheControllerPosition) {
    load(std::string(kBasic) + R"(field(DVAL, "3.5") field(RSTM, "Never"))");
    EXPECT_EQ(drv->count("set"), 0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 0.0);
}

TEST_F(MotorTest, ExportAndReloadKeepsTheConfiguration) {
    load(std::string(kBasic) + R"(field(DHLM, "5") field(DESC, "slit"))");
    std::ostringstream os;
    db.write_db(os);
    EXPECT_NE(os.str().find("field(DHLM, \"5\")"), std::string::npos) << os.str();
    EXPECT_EQ(os.str().find("field(SCAN"), std::string::npos) << os.str();
    Database db2;
    db2.load(parse_db(os.str(), "export.db", {}));
    db2.init_records();
    EXPECT_NE(MotorRecord::from(db2.find("m")), nullptr);
}

// ---------------------------------------------------------------- SimMotorDriver

TEST(SimMotorDriver, TrapezoidAndTriangleProfiles) {
    double t = 0;
    SimMotorDriver sim([&] { return t; });
    sim.move(2.0, 1.0, 2.0); // accel 0.5 s (0.25), cruise 1.5 s, decel 0.5 s: 2.5 s
    EXPECT_FALSE(sim.status().done);
    t = 0.5;
    EXPECT_NEAR(sim.status().position, 0.25, 1e-12);
    EXPECT_NEAR(sim.status().velocity, 1.0, 1e-12);
    t = 1.25;
    EXPECT_NEAR(sim.status().position, 1.0, 1e-12);
    t = 2.49;
    EXPECT_FALSE(sim.status().done);
    EXPECT_TRUE(sim.status().direction_positive);
    t = 2.5;
    EXPECT_TRUE(sim.status().done);
    EXPECT_EQ(sim.status().position, 2.0);
    sim.move(1.0, 10.0, 4.0); // short: triangle, peak sqrt(4) = 2, 1 s total
    t = 3.0;
    EXPECT_NEAR(sim.status().position, 1.5, 1e-12);
    EXPECT_NEAR(sim.status().velocity, -2.0, 1e-12);
    EXPECT_FALSE(sim.status().direction_positive);
    t = 3.5;
    EXPECT_TRUE(sim.status().done);
    EXPECT_EQ(sim.status().position, 1.0);
}

TEST(SimMotorDriver, RetargetJogStopHomeAndSetPosition) {
    double t = 0;
    SimMotorDriver sim([&] { return t; });
    sim.move(10.0, 1.0, 1.0);
    t = 2.0;                 // at 1.5 with v = 1
    sim.move(0.0, 1.0, 1.0); // reverse: stop (0.5 further), then back
    t = 3.0;
    EXPECT_NEAR(sim.status().position, 2.0, 1e-12);
    EXPECT_NEAR(sim.status().velocity, 0.0, 1e-12);
    t = 20;
    EXPECT_TRUE(sim.status().done);
    EXPECT_EQ(sim.status().position, 0.0);
    sim.move_velocity(-2.0, 4.0); // jog: 0.5 s to -2 mm/s, then forever
    t = 21.5;
    EXPECT_NEAR(sim.status().position, -0.5 - 2.0, 1e-12);
    EXPECT_FALSE(sim.status().done);
    sim.stop(4.0);
    t = 30;
    EXPECT_TRUE(sim.status().done);
    EXPECT_NEAR(sim.status().position, -3.0, 1e-12);
    sim.set_position(7.0);
    EXPECT_EQ(sim.status().position, 7.0);
    EXPECT_FALSE(sim.status().homed);
    sim.set_home_position(1.0);
    sim.home(false, 3.0, 0); // no acceleration given: constant speed, 2 s
    t = 31.9;
    EXPECT_FALSE(sim.status().done);
    t = 32;
    EXPECT_TRUE(sim.status().done);
    EXPECT_EQ(sim.status().position, 1.0);
    EXPECT_TRUE(sim.status().homed);
    sim.set_closed_loop(false);
    EXPECT_FALSE(sim.status().enabled);
}

TEST_F(MotorTest, SimMotorEndToEndThroughThePeriodicScan) {
    now = 0;
    load(R"(field(DTYP, "Sim Motor") field(MRES, "0.001") field(VELO, "1") field(ACCL, "1")
            field(DHLM, "50") field(DLLM, "-50"))",
         false);
    Watch& dmov = watch("m.DMOV");
    double done_at = -1;
    ASSERT_EQ(put("m", 2.0, [&](PutStatus) { done_at = now; }), PutStatus::Ok);
    double mid = NAN;
    for (int i = 1; i <= 400 && done_at < 0; ++i) {
        now = i * 0.01;
        db.scan_periodic(now);
        if (i == 150) mid = getd("m.RBV");
    }
    EXPECT_NEAR(mid, 1.0, 0.11); // 1 mm/s with 1 s ramps: half way at 1.5 s, 0.1 s polling
    EXPECT_GE(done_at, 3.0);     // accel 1 s + cruise 1 s + decel 1 s
    EXPECT_LE(done_at, 3.11);
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 2.0);
    EXPECT_EQ(dmov.values, (std::vector<double>{0, 1}));
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM");
    // Jog forward for a while, release, and the readback stays where it stopped.
    ASSERT_EQ(put("m.JOGF", 1), PutStatus::Ok);
    for (int i = 1; i <= 200; ++i) db.scan_periodic(now += 0.01);
    ASSERT_EQ(put("m.JOGF", 0), PutStatus::Ok);
    for (int i = 1; i <= 200; ++i) db.scan_periodic(now += 0.01);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_GT(getd("m.RBV"), 3.0);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), getd("m.RBV"));
    // Home: the sim goes to 0 and reports HOMED.
    ASSERT_EQ(put("m.HOMR", 1), PutStatus::Ok);
    for (int i = 1; i <= 1000 && getd("m.DMOV") == 0; ++i) db.scan_periodic(now += 0.01);
    EXPECT_EQ(getd("m.RBV"), 0.0);
    EXPECT_NE(unsigned(getd("m.MSTA")) & (1u << 14), 0u);
}

TEST_F(MotorTest, EventScanIsRefusedAtInit) {
    db.load(parse_db(R"(record(motor, "m") { field(SCAN, "I/O Intr") })", "m.db", {}));
    try {
        db.init_records();
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("record m: SCAN \"I/O Intr\""), std::string::npos)
            << e.what();
    }
}

// The controller's requests (ECMC mc_mr_set_sync / mc_mr_set_stop from PLC code): a changed sync
// count makes an idle record take the readback as its target; a changed stop count stops a
// motion as STOP=1 does. Counts seen before the first look are not replayed.
TEST_F(MotorTest, ControllerSyncAndStopRequests) {
    drv->st.sync_requests = 4; // before the record looked: not a request to it
    load(kBasic);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 0);
    drv->st.position = 2.5; // something else moved the axis (a kinematics PLC)
    drv->st.sync_requests = 5;
    m->poll();
    EXPECT_DOUBLE_EQ(getd("m.RBV"), 2.5);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 2.5); // synced (an idle record follows the readback anyway)
    EXPECT_DOUBLE_EQ(getd("m.DVAL"), 2.5);
    ASSERT_EQ(put("m", 4), PutStatus::Ok);
    EXPECT_EQ(getd("m.DMOV"), 0);
    EXPECT_EQ(drv->count("stop"), 0);
    drv->st.stop_requests = 1;
    m->poll();
    EXPECT_EQ(drv->count("stop"), 1);
    arrive(3.0);
    EXPECT_EQ(getd("m.DMOV"), 1);
    EXPECT_DOUBLE_EQ(getd("m.VAL"), 3.0); // stopped where it was, as STOP
}

// FRAC: the final (backlash) approach covers that fraction of the way; retries do the rest.
TEST_F(MotorTest, FracShortensTheFinalApproach) {
    load(std::string(kBasic) + R"(field(BDST, "0.5") field(BVEL, "0.2") field(FRAC, "0.5") field(RDBD, "0.01"))");
    put("m", -3.0);
    EXPECT_DOUBLE_EQ(drv->last("move").a, -3.5);
    arrive(-3.5);
    EXPECT_DOUBLE_EQ(drv->last("move").a, -3.25); // half of the 0.5 approach
    arrive(-3.25);
    EXPECT_EQ(getd("m.DMOV"), 0); // a retry follows
    EXPECT_EQ(getd("m.RCNT"), 1);
    EXPECT_DOUBLE_EQ(drv->last("move").a, -3.125);
    EXPECT_FLOAT_EQ(float(getd("m.FRAC")), 0.5f);
    put("m.FRAC", 3);
    EXPECT_FLOAT_EQ(float(getd("m.FRAC")), 1.5f); // clamped to 0.1..1.5
}

// RMOD: Arithmetic retries move (RTRY-RCNT+1)/RTRY of what is left, Geometric 1/2^(RCNT-1);
// In-Position leaves retries to the controller (the record does none).
TEST_F(MotorTest, RetryModes) {
    load(std::string(kBasic) + R"(field(RTRY, "4") field(RDBD, "0.01") field(RMOD, "Arithmetic"))");
    put("m", 1.0);
    arrive(0.6);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 1.0); // retry 1 of 4: all of it
    arrive(0.8);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 0.8 + 0.75 * 0.2);
    arrive(1.0);
    put_str("m.RMOD", "Geometric");
    put("m", 2.0);
    arrive(1.2);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.0);
    arrive(1.6);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 1.6 + 0.5 * 0.4);
    arrive(2.0);
    put_str("m.RMOD", "In-Position");
    int moves = drv->count("move");
    put("m", 3.0);
    arrive(2.9);
    EXPECT_EQ(drv->count("move"), moves + 1); // no retry
    EXPECT_EQ(getd("m.DMOV"), 1);
}

// S/SBAS/SMAX/SBAK are VELO/VBAS/VMAX/BVEL in revolutions per second (UREV per revolution), and
// ACCS (EGU/s^2) and ACCL (s) follow each other, ACCU saying which was set.
TEST_F(MotorTest, SpeedsInRevolutionsAndAccelerationInUnits) {
    load(std::string(kBasic) + R"(field(UREV, "0.5") field(VMAX, "4"))"); // VELO 2, ACCL 0.5
    EXPECT_DOUBLE_EQ(getd("m.S"), 4.0);
    EXPECT_DOUBLE_EQ(getd("m.SMAX"), 8.0);
    EXPECT_DOUBLE_EQ(getd("m.ACCS"), 4.0); // 2 mm/s in 0.5 s
    EXPECT_EQ(gets("m.ACCU"), "Use ACCL");
    ASSERT_EQ(put("m.S", 6), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 3.0);
    ASSERT_EQ(put("m.S", 100), PutStatus::Ok); // beyond SMAX: VELO clamped to VMAX
    EXPECT_DOUBLE_EQ(getd("m.VELO"), 4.0);
    EXPECT_DOUBLE_EQ(getd("m.S"), 8.0);
    ASSERT_EQ(put("m.ACCS", 16), PutStatus::Ok);
    EXPECT_DOUBLE_EQ(getd("m.ACCL"), 0.25);
    EXPECT_EQ(gets("m.ACCU"), "Use ACCS");
    ASSERT_EQ(put("m.VELO", 2), PutStatus::Ok); // ACCS kept: ACCL follows
    EXPECT_DOUBLE_EQ(getd("m.ACCL"), 0.125);
    EXPECT_EQ(put("m.ACCS", 0), PutStatus::BadValue);
    put("m", 1.0);
    EXPECT_DOUBLE_EQ(drv->last("move").c, 16.0); // the driver gets EGU/s^2
}

// OMSL closed_loop: processing the record reads its target from DOL; RLNK: the readback goes out.
TEST_F(MotorTest, DolAndRlnkLinks) {
    load(std::string(kBasic) + R"(field(OMSL, "closed_loop") field(DOL, "target") field(RLNK, "copy PP"))", true,
         R"(record(ao, "target") { field(VAL, "2.5") } record(ao, "copy") {})");
    put("m.PROC", 1);
    EXPECT_DOUBLE_EQ(drv->last("move").a, 2.5);
    arrive(2.5);
    EXPECT_DOUBLE_EQ(getd("copy"), 2.5);
}

// URIP: the readback comes from RDBL (times RRES) instead of the driver.
TEST_F(MotorTest, UripReadsTheReadbackLink) {
    load(std::string(kBasic) + R"(field(URIP, "Yes") field(RDBL, "rb") field(RRES, "0.25"))", true,
         R"(record(ao, "rb") { field(VAL, "8") })");
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 2.0); // 8 x 0.25
    put("rb", 12);
    m->poll();
    EXPECT_DOUBLE_EQ(getd("m.DRBV"), 3.0);
}

// SYNC and STUP act once and return to 0; HIHI..LOLO with their severities alarm on RBV and are
// the VAL/RBV alarm limits clients see.
TEST_F(MotorTest, SyncStupAndAlarmLimits) {
    load(std::string(kBasic) + R"(field(HIGH, "1") field(HSV, "MINOR") field(HIHI, "2") field(HHSV, "MAJOR"))");
    ASSERT_EQ(put("m.SYNC", 1), PutStatus::Ok);
    EXPECT_EQ(getd("m.SYNC"), 0);
    ASSERT_EQ(put("m.STUP", 1), PutStatus::Ok);
    EXPECT_EQ(gets("m.STUP"), "OFF");
    EXPECT_EQ(gets("m.SEVR"), "NO_ALARM");
    put("m", 1.5);
    arrive(1.5);
    EXPECT_EQ(gets("m.SEVR"), "MINOR");
    EXPECT_EQ(gets("m.STAT"), "HIGH");
    put("m", 2.5);
    arrive(2.5);
    EXPECT_EQ(gets("m.SEVR"), "MAJOR");
    EXPECT_EQ(gets("m.STAT"), "HIHI");
    Metadata md = meta("m.RBV");
    EXPECT_DOUBLE_EQ(md.alarm_high, 1);
    EXPECT_DOUBLE_EQ(md.alarm_hihi, 2);
}

// synApps' fields that databases set (ecmccfg's motor template sets SPAM): stored, and the
// buttons FOF/VOF and SSET/SUSE set FOFF and SET; RHLM/RLLM are the dial limits in steps.
TEST_F(MotorTest, SynAppsButtonFieldsAndRawLimits) {
    load(R"(field(MRES, "0.001") field(DHLM, "5") field(DLLM, "-2") field(SPAM, "0"))");
    EXPECT_DOUBLE_EQ(getd("m.SPAM"), 0);
    EXPECT_EQ(put("m.FOF", 1), PutStatus::Ok);
    EXPECT_EQ(gets("m.FOFF"), "Frozen");
    EXPECT_EQ(put("m.VOF", 1), PutStatus::Ok);
    EXPECT_EQ(gets("m.FOFF"), "Variable");
    EXPECT_EQ(put("m.SSET", 1), PutStatus::Ok);
    EXPECT_EQ(gets("m.SET"), "Set");
    EXPECT_EQ(put("m.SUSE", 1), PutStatus::Ok);
    EXPECT_EQ(gets("m.SET"), "Use");
    put("m.PROC", 1);
    EXPECT_NEAR(getd("m.RHLM"), 5000, 1e-6);
    EXPECT_NEAR(getd("m.RLLM"), -2000, 1e-6);
    EXPECT_EQ(put("m.RHLM", 1), PutStatus::ReadOnly);
}
