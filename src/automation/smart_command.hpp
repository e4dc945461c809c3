// smartControl's line protocol (docs/goniometer.md): one command per line, parsed into a
// SmartCommand, and the conversion between the client's (SMART's) axis coordinates and a motor's
// (sign, offset, and a cut window a rotation is wrapped into, as smartControl's setup table).
// Pure functions: the parser faces the network (fuzzed: tests/fuzz/fuzz_smart_command.cpp).
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::automation {

// The protocol's axes, in its order.
constexpr const char* kSmartAxes[] = {"TWOTHETA", "OMEGA", "PHI", "KAPPA"};

struct SmartCommand {
    enum class Kind { Id, Help, Pos, Limits, Velo, Move, Stop, Shutter, Count, Scan, Status };
    Kind kind = Kind::Id;
    std::string keyword;                                  // upper case: the reply starts with it
    std::vector<std::pair<std::string, double>> targets;  // MOVE: (axis, position)...
    std::string axis;                                     // POS/LIMITS/VELO (optional), SCAN
    bool has_value = false;                               // VELO <axis> <v>, SHUTTER OPEN|CLOSE
    double value = 0;                                     // VELO's velocity, COUNT's seconds
    bool open = false;                                    // SHUTTER OPEN
    double start = 0, end = 0, seconds = 0;               // SCAN <axis> <start> <end> <seconds>
};

// A line (without its terminator; keywords and axes case-insensitive, separated by blanks).
// false with `why` naming the word that is wrong.
bool parse_smart_command(std::string_view line, SmartCommand& out, std::string& why);

// One axis of the setup table: motor = sign x smart + offset, then moved by multiples of 360
// into [low_cut, high_cut] when the window is not empty (low_cut < high_cut).
struct SmartAxisSetup {
    double offset = 0;
    int sign = 1;
    double low_cut = 0, high_cut = 0;
};
// The motor position for a client's position; false with `why` if it has no place in the window.
bool smart_to_motor(const SmartAxisSetup& a, double smart, double& motor, std::string& why);
// The client's position of a motor position (with a cut window: in (-180, 180]).
double motor_to_smart(const SmartAxisSetup& a, double motor);

} // namespace beamctl::automation
