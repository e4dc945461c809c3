#include "automation/smart_command.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace beamctl::automation {
namespace {

std::vector<std::string> words_of(std::string_view line) {
    std::vector<std::string> w;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
        std::size_t j = i;
        while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
        if (j > i) w.emplace_back(line.substr(i, j - i));
        i = j;
    }
    return w;
}

std::string upper(std::string s) {
    for (char& c : s) c = char(std::toupper(static_cast<unsigned char>(c)));
    return s;
}

bool number(const std::string& w, double& v) {
    if (w.empty() || w.size() > 64) return false;
    char* end = nullptr;
    v = std::strtod(w.c_str(), &end);
    return end == w.c_str() + w.size() && std::isfinite(v);
}

bool axis_name(const std::string& w, std::string& out) {
    const std::string u = upper(w);
    for (const char* a : kSmartAxes)
        if (u == a) {
            out = a;
            return true;
        }
    if (u == "2THETA" || u == "TTH") {
        out = "TWOTHETA";
        return true;
    }
    return false;
}

std::string shown(const std::string& w) { return w.size() > 32 ? w.substr(0, 32) + "..." : w; }

} // namespace

bool parse_smart_command(std::string_view line, SmartCommand& out, std::string& why) {
    out = SmartCommand{};
    for (std::size_t i = 0; i < line.size(); ++i) {
        const unsigned char ch = static_cast<unsigned char>(line[i]);
        if ((ch < 32 && ch != '\t') || ch > 126) {
            char b[80];
            std::snprintf(b, sizeof b, "byte 0x%02x at column %zu is not printable ASCII", ch, i + 1);
            why = b;
            return false;
        }
    }
    const std::vector<std::string> w = words_of(line);
    if (w.empty()) {
        why = "empty line";
        return false;
    }
    out.keyword = upper(w[0]);
    const std::size_t n = w.size();
    auto bad_axis = [&](const std::string& a) {
        why = "'" + shown(a) + "' is not an axis (TWOTHETA, OMEGA, PHI, KAPPA)";
        return false;
    };
    auto bad_number = [&](const std::string& x, const char* what) {
        why = "'" + shown(x) + "' is not a number (" + what + ")";
        return false;
    };
    auto count = [&](std::size_t lo, std::size_t hi, const char* usage) {
        if (n >= lo && n <= hi) return true;
        why = std::string("usage: ") + usage;
        return false;
    };
    const std::string& k = out.keyword;
    if (k == "ID" || k == "HELP" || k == "STOP" || k == "STATUS") {
        if (!count(1, 1, (k + " (no arguments)").c_str())) return false;
        out.kind = k == "ID" ? SmartCommand::Kind::Id : k == "HELP" ? SmartCommand::Kind::Help : k == "STOP" ? SmartCommand::Kind::Stop : SmartCommand::Kind::Status;
        return true;
    }
    if (k == "POS" || k == "LIMITS") {
        if (!count(1, 2, k == "POS" ? "POS [axis]" : "LIMITS [axis]")) return false;
        out.kind = k == "POS" ? SmartCommand::Kind::Pos : SmartCommand::Kind::Limits;
        if (n == 2 && !axis_name(w[1], out.axis)) return bad_axis(w[1]);
        return true;
    }
    if (k == "VELO") {
        if (!count(2, 3, "VELO axis [velocity]")) return false;
        out.kind = SmartCommand::Kind::Velo;
        if (!axis_name(w[1], out.axis)) return bad_axis(w[1]);
        if (n == 3) {
            if (!number(w[2], out.value)) return bad_number(w[2], "velocity");
            if (!(out.value > 0)) {
                why = "the velocity should be above 0";
                return false;
            }
            out.has_value = true;
        }
        return true;
    }
    if (k == "MOVE") {
        if (n < 3 || n % 2 == 0) {
            why = "usage: MOVE axis position [axis position ...]";
            return false;
        }
        out.kind = SmartCommand::Kind::Move;
        for (std::size_t i = 1; i + 1 < n; i += 2) {
            std::string a;
            double v = 0;
            if (!axis_name(w[i], a)) return bad_axis(w[i]);
            if (!number(w[i + 1], v)) return bad_number(w[i + 1], "position");
            for (const auto& t : out.targets)
                if (t.first == a) {
                    why = a + " is given twice";
                    return false;
                }
            out.targets.emplace_back(a, v);
        }
        return true;
    }
    if (k == "SHUTTER") {
        if (!count(1, 2, "SHUTTER [OPEN|CLOSE]")) return false;
        out.kind = SmartCommand::Kind::Shutter;
        if (n == 2) {
            const std::string s = upper(w[1]);
            if (s != "OPEN" && s != "CLOSE") {
                why = "'" + shown(w[1]) + "' should be OPEN or CLOSE";
                return false;
            }
            out.has_value = true;
            out.open = s == "OPEN";
        }
        return true;
    }
    if (k == "COUNT") {
        if (!count(2, 2, "COUNT seconds")) return false;
        out.kind = SmartCommand::Kind::Count;
        if (!number(w[1], out.value)) return bad_number(w[1], "seconds");
        if (!(out.value > 0 && out.value <= 86400)) {
            why = "the counting time should be above 0 and at most 86400 s";
            return false;
        }
        return true;
    }
    if (k == "SCAN") {
        if (!count(5, 5, "SCAN axis start end seconds")) return false;
        out.kind = SmartCommand::Kind::Scan;
        if (!axis_name(w[1], out.axis)) return bad_axis(w[1]);
        if (!number(w[2], out.start)) return bad_number(w[2], "start");
        if (!number(w[3], out.end)) return bad_number(w[3], "end");
        if (!number(w[4], out.seconds)) return bad_number(w[4], "seconds");
        if (!(out.seconds > 0 && out.seconds <= 86400)) {
            why = "the exposure should be above 0 and at most 86400 s";
            return false;
        }
        if (out.start == out.end) {
            why = "start and end are the same";
            return false;
        }
        return true;
    }
    why = "unknown command '" + shown(w[0]) + "' (ID, HELP, STATUS, POS, LIMITS, VELO, MOVE, STOP, SHUTTER, COUNT, SCAN)";
    return false;
}

bool smart_to_motor(const SmartAxisSetup& a, double smart, double& motor, std::string& why) {
    motor = a.sign * smart + a.offset;
    if (!(a.high_cut > a.low_cut)) return true;
    motor -= 360.0 * std::floor((motor - a.low_cut) / 360.0); // into [low_cut, low_cut + 360)
    if (motor > a.high_cut) {
        why = "has no place in the cut window";
        return false;
    }
    return true;
}

double motor_to_smart(const SmartAxisSetup& a, double motor) {
    double s = (motor - a.offset) * a.sign;
    if (a.high_cut > a.low_cut) {
        s -= 360.0 * std::floor((s + 180.0) / 360.0); // into [-180, 180)
        if (s == -180.0) s = 180.0;
    }
    return s;
}

} // namespace beamctl::automation
