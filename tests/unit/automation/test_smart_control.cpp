// smartControl (src/automation): the line protocol's parser and the setup table's coordinate
// conversion as pure functions, then the protocol against examples/goniometer's IOC in virtual
// time: moves through the motor records (wrapped into the cut window, refused beyond the soft
// limits before anything moves, an interrupted move answered ERR), the oscillation scan with the
// shutter and the trigger, counting, the setup table changed through its PVs, and bad lines.
#include "automation/smart_command.hpp"
#include "automation/line_server.hpp"
#include "automation/smart_control.hpp"

#include "../ioc/virtual_ioc.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>

using namespace beamctl;
using namespace beamctl::automation;

TEST(SmartCommand, ParsesEveryCommandAndSaysWhatIsWrong) {
    SmartCommand c;
    std::string why;
    ASSERT_TRUE(parse_smart_command("move omega 140 Phi -30.5", c, why)) << why;
    EXPECT_EQ(c.kind, SmartCommand::Kind::Move);
    EXPECT_EQ(c.keyword, "MOVE");
    ASSERT_EQ(c.targets.size(), 2u);
    EXPECT_EQ(c.targets[0], std::make_pair(std::string("OMEGA"), 140.0));
    EXPECT_EQ(c.targets[1], std::make_pair(std::string("PHI"), -30.5));
    ASSERT_TRUE(parse_smart_command("  SCAN\tomega 0 5 1.5 ", c, why)) << why;
    EXPECT_EQ(c.kind, SmartCommand::Kind::Scan);
    EXPECT_EQ(c.axis, "OMEGA");
    EXPECT_EQ(c.start, 0);
    EXPECT_EQ(c.end, 5);
    EXPECT_EQ(c.seconds, 1.5);
    ASSERT_TRUE(parse_smart_command("POS 2theta", c, why));
    EXPECT_EQ(c.axis, "TWOTHETA");
    ASSERT_TRUE(parse_smart_command("SHUTTER open", c, why));
    EXPECT_TRUE(c.has_value && c.open);
    ASSERT_TRUE(parse_smart_command("VELO KAPPA 2.5", c, why));
    EXPECT_TRUE(c.has_value);
    EXPECT_EQ(c.value, 2.5);
    ASSERT_TRUE(parse_smart_command("COUNT 0.5", c, why));
    EXPECT_EQ(c.value, 0.5);
    for (const char* ok : {"ID", "HELP", "STATUS", "STOP", "POS", "LIMITS", "LIMITS PHI", "SHUTTER", "VELO OMEGA"})
        EXPECT_TRUE(parse_smart_command(ok, c, why)) << ok << ": " << why;
    const std::pair<const char*, const char*> bad[] = {
        {"", "empty line"},
        {"JUMP 3", "unknown command 'JUMP'"},
        {"MOVE OMEGA", "usage: MOVE axis position"},
        {"MOVE CHI 3", "'CHI' is not an axis"},
        {"MOVE OMEGA 1e999", "'1e999' is not a number"},
        {"MOVE OMEGA nan", "'nan' is not a number"},
        {"MOVE OMEGA 3x", "'3x' is not a number"},
        {"MOVE OMEGA 1 OMEGA 2", "OMEGA is given twice"},
        {"SCAN OMEGA 0 5", "usage: SCAN axis start end seconds"},
        {"SCAN OMEGA 5 5 1", "start and end are the same"},
        {"SCAN OMEGA 0 5 0", "the exposure should be above 0"},
        {"COUNT -1", "the counting time should be above 0"},
        {"VELO OMEGA 0", "the velocity should be above 0"},
        {"SHUTTER AJAR", "should be OPEN or CLOSE"},
        {"STOP NOW", "usage: STOP"},
        {"MOVE OMEGA\x01 3", "byte 0x01 at column 11 is not printable ASCII"},
        {"POS \xc3\xa9", "byte 0xc3 at column 5"},
    };
    for (const auto& [line, expected] : bad) {
        EXPECT_FALSE(parse_smart_command(line, c, why)) << line;
        EXPECT_NE(why.find(expected), std::string::npos) << line << ": " << why;
    }
    // a long word is shortened in the message
    EXPECT_FALSE(parse_smart_command("MOVE " + std::string(200, 'X') + " 1", c, why));
    EXPECT_LT(why.size(), 120u);
}

TEST(SmartCommand, TheSetupTableConvertsAndWrapsIntoTheCutWindow) {
    SmartAxisSetup omega{0, 1, -230, 130};
    double m = 0;
    std::string why;
    ASSERT_TRUE(smart_to_motor(omega, 140, m, why));
    EXPECT_DOUBLE_EQ(m, -220); // the seed's example
    EXPECT_DOUBLE_EQ(motor_to_smart(omega, -220), 140);
    ASSERT_TRUE(smart_to_motor(omega, -100, m, why));
    EXPECT_DOUBLE_EQ(m, -100);
    ASSERT_TRUE(smart_to_motor(omega, 500, m, why));
    EXPECT_DOUBLE_EQ(m, -220);
    ASSERT_TRUE(smart_to_motor(omega, 130, m, why));
    EXPECT_DOUBLE_EQ(m, -230); // the window's two ends are the same angle: the lower one
    EXPECT_DOUBLE_EQ(motor_to_smart(omega, -230), 130);
    EXPECT_DOUBLE_EQ(motor_to_smart(omega, -180), 180); // (-180, 180]
    SmartAxisSetup phi{90, -1, 0, 0}; // no window: sign and offset only
    ASSERT_TRUE(smart_to_motor(phi, 30, m, why));
    EXPECT_DOUBLE_EQ(m, 60);
    EXPECT_DOUBLE_EQ(motor_to_smart(phi, 60), 30);
    ASSERT_TRUE(smart_to_motor(phi, 500, m, why));
    EXPECT_DOUBLE_EQ(m, -410); // not wrapped: the motor's limits decide
    for (double s = -720; s <= 720; s += 7.25) { // every angle has its place, and comes back
        ASSERT_TRUE(smart_to_motor(omega, s, m, why)) << s;
        EXPECT_GE(m, -230);
        EXPECT_LE(m, 130);
        EXPECT_NEAR(std::remainder(motor_to_smart(omega, m) - s, 360.0), 0, 1e-9) << s;
    }
}

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;

struct Gonio {
    test::VirtualIoc v{kSource + "/examples/goniometer/ioc.yaml"};
    SmartControl& sc() { return *v.ioc->smart_control(); }
    Gonio() {
        // the database's delays and periodic scans (the motor record's) on the virtual clock, as
        // the running IOC's loop does every 10 ms on the real one
        v.ioc->database().set_clock([this] { return now(); });
        run(300); // the bus in OP
    }
    double now() { return double(v.clock.now_ns()) * 1e-9; }
    void run(int cycles) {
        for (int k = 0; k < cycles; k += 10) {
            v.run(10);
            v.ioc->database().scan_periodic(now());
        }
    }
    // Sends a line; runs the engine until it is answered (at most `cycles`).
    std::string send(const std::string& line, int cycles = 60000) {
        std::optional<std::string> got;
        sc().command(line, [&](const std::string& r) { got = r; });
        for (int k = 0; k < cycles && !got; k += 10) run(10);
        return got.value_or("(no reply)");
    }
    double motor(const std::string& axis) { return pv("GON:" + axis + ".RBV"); }
    double pv(const std::string& name) { // a field's value
        pv::Address a;
        if (!v.ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        double x = 0;
        v.ioc->database().get(a, pv::Prim::Double, &x, 1);
        return x;
    }
    pv::PutStatus put(const std::string& name, double x) {
        pv::Address a;
        if (!v.ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        return v.ioc->database().put(a, pv::Prim::Double, &x, 1);
    }
};

// The value after "NAME=" in a reply.
double field(const std::string& reply, const std::string& name) {
    const std::size_t at = reply.find(name + "=");
    if (at == std::string::npos) return NAN;
    return std::stod(reply.substr(at + name.size() + 1));
}

} // namespace

TEST(SmartControl, MovesGoThroughTheMotorRecordsIntoTheCutWindow) {
    Gonio g;
    EXPECT_EQ(g.send("ID"), "ID OK beamctl smartControl OMEGA PHI");
    EXPECT_EQ(g.send("POS"), "POS OK OMEGA=0.000 PHI=90.000"); // phi: the motor's 0 is SMART's 90
    const std::string r = g.send("MOVE OMEGA 140 PHI 30");
    ASSERT_EQ(r.rfind("MOVE OK", 0), 0u) << r;
    EXPECT_NEAR(field(r, "OMEGA"), 140, 0.02);
    EXPECT_NEAR(field(r, "PHI"), 30, 0.02);
    EXPECT_NEAR(g.motor("Omega"), -220, 0.02); // wrapped into -230 .. 130
    EXPECT_NEAR(g.motor("Phi"), 60, 0.02);     // 90 - 30
    EXPECT_EQ(g.pv("GON:Omega.DMOV"), 1);
    // the table's read-backs, in the client's coordinates
    g.run(200);
    EXPECT_NEAR(g.v.get("GON:smart:OmegaPosition"), 140, 0.02);
    EXPECT_EQ(g.v.get("GON:smart:KappaExists"), 0);
    EXPECT_EQ(g.v.get("GON:smart:OmegaExists"), 1);
    EXPECT_DOUBLE_EQ(g.v.get("GON:smart:PhiLowLimit"), -310);  // 90 - 400
    EXPECT_DOUBLE_EQ(g.v.get("GON:smart:PhiHighLimit"), 490);  // 90 + 400
    EXPECT_EQ(g.send("LIMITS OMEGA"), "LIMITS OK OMEGA=-230.000..130.000");
    // the setup table through its PVs: an offset of 10 moves the client's zero
    ASSERT_EQ(g.put("GON:smart:PhiOffset", 100), pv::PutStatus::Ok);
    EXPECT_NEAR(field(g.send("POS PHI"), "PHI"), 40, 0.02);
}

TEST(SmartControl, AMoveBeyondTheSoftLimitsIsRefusedBeforeAnythingMoves) {
    Gonio g;
    ASSERT_EQ(g.put("GON:smart:OmegaLowCut", 0), pv::PutStatus::Ok); // no window: 500 stays 500
    ASSERT_EQ(g.put("GON:smart:OmegaHighCut", 0), pv::PutStatus::Ok);
    const std::string r = g.send("MOVE PHI 10 OMEGA 500");
    EXPECT_EQ(r.rfind("MOVE ERR OMEGA: 500.000 (motor) is beyond the motor's soft limits -400.000 .. 400.000", 0), 0u) << r;
    g.run(500);
    EXPECT_NEAR(g.motor("Phi"), 0, 1e-9); // PHI did not move either
    EXPECT_EQ(g.v.get("GON:smart:Errors"), 1);
    EXPECT_EQ(g.send("MOVE KAPPA 1"), "MOVE ERR KAPPA is not configured (smart_control.axes)");
}

TEST(SmartControl, AStoppedMoveIsAnsweredErrNeverOk) {
    Gonio g;
    std::optional<std::string> move;
    g.sc().command("MOVE OMEGA -100", [&](const std::string& r) { move = r; });
    g.run(2000);
    ASSERT_FALSE(move) << *move;
    EXPECT_EQ(g.send("STATUS").rfind("STATUS OK MOVING", 0), 0u);
    EXPECT_EQ(g.send("MOVE PHI 3"), "MOVE ERR busy: MOVE is under way (STOP ends it)");
    EXPECT_EQ(g.send("STOP"), "STOP OK");
    for (int k = 0; k < 3000 && !move; k += 10) g.run(10);
    ASSERT_TRUE(move);
    // the motor record completes a stopped move's put-callback normally (its target becomes the
    // stop position): the position says it ended short
    EXPECT_EQ(move->rfind("MOVE ERR OMEGA ended short at ", 0), 0u) << *move;
    EXPECT_NE(move->find("(target -100.000)"), std::string::npos) << *move;
    EXPECT_GT(g.motor("Omega"), -99);
    EXPECT_LT(g.motor("Omega"), -1);
}

TEST(SmartControl, AScanOpensTheShutterAndTriggersForTheExposure) {
    Gonio g;
    const double velo = g.pv("GON:Omega.VELO");
    std::optional<std::string> scan;
    g.sc().command("SCAN OMEGA 10 12 0.5", [&](const std::string& r) { scan = r; });
    // to the start first, shutter closed
    double opened_at = NAN, closed_at = NAN;
    bool exposure_velocity = false;
    for (int k = 0; k < 60000 && !scan; k += 10) {
        g.run(10);
        const bool open = g.v.get("GON:Shutter") != 0;
        if (open && std::isnan(opened_at)) {
            opened_at = g.motor("Omega");
            EXPECT_EQ(g.v.get("GON:DetTrigger"), 1);
        }
        if (open) exposure_velocity = exposure_velocity || g.pv("GON:Omega.VELO") == 4.0; // 2 deg in 0.5 s
        if (!open && !std::isnan(opened_at) && std::isnan(closed_at)) closed_at = g.motor("Omega");
    }
    ASSERT_TRUE(scan);
    EXPECT_EQ(scan->rfind("SCAN OK OMEGA=", 0), 0u) << *scan;
    EXPECT_NEAR(opened_at, 10, 0.02);
    EXPECT_NEAR(field(*scan, "OMEGA"), 12, 0.02);
    EXPECT_TRUE(exposure_velocity);
    EXPECT_EQ(g.v.get("GON:Shutter"), 0);
    EXPECT_EQ(g.v.get("GON:DetTrigger"), 0);
    EXPECT_EQ(g.pv("GON:Omega.VELO"), velo); // given back
    EXPECT_GT(field(*scan, "SECONDS"), 0);
    EXPECT_GE(field(*scan, "COUNTS"), 0);
    // a scan that leaves the cut window is refused
    EXPECT_EQ(g.send("SCAN OMEGA 120 140 1"), "SCAN ERR OMEGA: the scan to 140.000 leaves the cut window");
}

TEST(SmartControl, CountIntegratesTheScaler) {
    Gonio g;
    g.run(500);
    const double rate = g.v.get("GON:IonChamber"); // 2 V x 1e5 counts/s per V
    EXPECT_NEAR(rate, 2e5, 3e3);
    const std::string r = g.send("COUNT 0.05");
    ASSERT_EQ(r.rfind("COUNT OK ", 0), 0u) << r;
    EXPECT_NEAR(std::stod(r.substr(9)), rate * 0.05, rate * 0.05 * 0.05);
}

TEST(SmartControl, BadLinesAreCountedAndChangeNothing) {
    Gonio g;
    EXPECT_EQ(g.send("FLY AWAY"), "FLY ERR unknown command 'FLY' (ID, HELP, STATUS, POS, LIMITS, VELO, MOVE, STOP, SHUTTER, COUNT, SCAN)");
    EXPECT_EQ(g.send("MOVE OMEGA x"), "MOVE ERR 'x' is not a number (position)");
    EXPECT_EQ(g.send("SHUTTER OPEN"), "SHUTTER OK OPEN");
    EXPECT_EQ(g.v.get("GON:Shutter"), 1);
    g.run(200);
    EXPECT_EQ(g.v.get("GON:smart:Errors"), 2);
    EXPECT_EQ(g.v.get("GON:smart:Commands"), 3);
    EXPECT_EQ(g.v.get("GON:smart:Shutter"), 1);
    EXPECT_EQ(g.sc().errors(), 2u);
}

TEST(LineFraming, LinesBlanksAndLinesTooLong) {
    std::string in = "ID\r\n\r\nPOS omega\nSTATUS\rHAL", line;
    bool dropping = false;
    const std::size_t max = 16;
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line);
    EXPECT_EQ(line, "ID");
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line); // the blank \n of \r\n skipped
    EXPECT_EQ(line, "POS omega");
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line);
    EXPECT_EQ(line, "STATUS");
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::None); // "HAL": wait for the rest
    in += "T\n";
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line);
    EXPECT_EQ(line, "HALT");
    // too long with its terminator: one event, then the next line
    in = std::string(40, 'x') + "\nID\n";
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::TooLong);
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line);
    EXPECT_EQ(line, "ID");
    // too long before its terminator arrives: one event, the rest dropped up to it
    in = std::string(20, 'y');
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::TooLong);
    EXPECT_TRUE(dropping);
    in += std::string(50, 'y');
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::None);
    in += "yy\nPOS\n";
    EXPECT_EQ(next_line(in, dropping, line, max), LineEvent::Line);
    EXPECT_EQ(line, "POS");
    EXPECT_FALSE(dropping);
}
