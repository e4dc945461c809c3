#include "ethercat/sim/faults.hpp"

#include "core/error.hpp"
#include "ethercat/catalog.hpp"

#include <charconv>
#include <sstream>
#include <vector>

namespace beamctl::ethercat::sim {
namespace {

std::vector<std::string> words(std::string_view t) {
    std::vector<std::string> w;
    std::istringstream is{std::string(t)};
    for (std::string s; is >> s;) w.push_back(s);
    return w;
}

// Decimal or 0x-hex, whole token.
bool number(const std::string& s, int64_t& v) {
    const char* b = s.data();
    const char* e = b + s.size();
    bool neg = b != e && *b == '-';
    if (neg) ++b;
    int base = 10;
    if (e - b > 2 && b[0] == '0' && (b[1] == 'x' || b[1] == 'X')) b += 2, base = 16;
    uint64_t u = 0;
    auto r = std::from_chars(b, e, u, base);
    if (r.ec != std::errc() || r.ptr != e || b == e) return false;
    v = neg ? -int64_t(u) : int64_t(u);
    return true;
}

} // namespace

std::string fault_usage() {
    return "power K off|on, break K, repair, loss F, corrupt F, delay MS, refuse-state K SAFEOP|OP|PREOP CODE, "
           "refuse-sdo K INDEX:SUB ABORT, replace K TYPE, glitch K COUNTS, drive-fault K, clear";
}

Fault parse_fault(std::string_view text, const Catalog& catalog, std::size_t slaves) {
    std::vector<std::string> w = words(text);
    auto fail = [&](const std::string& why) -> Error {
        return Error(SB() << "fault '" << text << "': " << why << " (faults: " << fault_usage() << ")");
    };
    if (w.empty()) throw fail("empty");
    const std::string& verb = w[0];
    Fault f;
    auto want = [&](std::size_t n) {
        if (w.size() != n) throw fail(SB() << verb << " takes " << n - 1 << " argument(s)");
    };
    auto position = [&](std::size_t at) {
        int64_t k = 0;
        if (!number(w[at], k) || k < 0 || std::size_t(k) >= slaves)
            throw fail(SB() << "'" << w[at] << "' is not a slave position (0.." << int64_t(slaves) - 1 << ")");
        return int(k);
    };
    auto real = [&](std::size_t at, double hi, const char* what) { // a number 0..hi
        char* end = nullptr;
        double v = std::strtod(w[at].c_str(), &end);
        if (end == w[at].c_str() || *end || !(v >= 0 && v <= hi)) throw fail(SB() << "'" << w[at] << "' is not " << what);
        return v;
    };
    if (verb == "power") {
        want(3);
        f.position = position(1);
        if (w[2] == "off") f.kind = Fault::Kind::PowerOff;
        else if (w[2] == "on") f.kind = Fault::Kind::PowerOn;
        else throw fail("power takes off or on");
    } else if (verb == "break") {
        want(2);
        f.kind = Fault::Kind::BreakAfter;
        f.position = position(1);
    } else if (verb == "repair") {
        want(1);
        f.kind = Fault::Kind::Repair;
    } else if (verb == "loss" || verb == "corrupt") {
        want(2);
        f.kind = verb == "loss" ? Fault::Kind::Loss : Fault::Kind::Corrupt;
        f.fraction = real(1, 1, "a fraction 0..1");
    } else if (verb == "delay") {
        want(2);
        f.kind = Fault::Kind::Delay;
        f.fraction = real(1, 1000, "a delay of 0..1000 ms");
    } else if (verb == "refuse-state") {
        want(4);
        f.kind = Fault::Kind::RefuseState;
        f.position = position(1);
        if (w[2] == "PREOP") f.state = 2;
        else if (w[2] == "SAFEOP") f.state = 4;
        else if (w[2] == "OP") f.state = 8;
        else throw fail(SB() << "'" << w[2] << "' is not PREOP, SAFEOP or OP");
        int64_t c = 0;
        if (!number(w[3], c) || c <= 0 || c > 0xFFFF) throw fail(SB() << "'" << w[3] << "' is not an AL status code (e.g. 0x001D)");
        f.al_code = uint16_t(c);
    } else if (verb == "refuse-sdo") {
        want(4);
        f.kind = Fault::Kind::RefuseSdo;
        f.position = position(1);
        std::size_t colon = w[2].find(':');
        int64_t idx = 0, sub = 0, ab = 0;
        if (colon == std::string::npos || !number(w[2].substr(0, colon), idx) || !number("0x" + w[2].substr(colon + 1), sub) ||
            idx < 0 || idx > 0xFFFF || sub < 0 || sub > 0xFF)
            throw fail(SB() << "'" << w[2] << "' is not an object INDEX:SUB (e.g. 0x8012:01)");
        if (!number(w[3], ab) || ab <= 0 || ab > 0xFFFFFFFF) throw fail(SB() << "'" << w[3] << "' is not an SDO abort code (e.g. 0x06090030)");
        f.index = uint16_t(idx);
        f.sub = uint8_t(sub);
        f.abort = uint32_t(ab);
    } else if (verb == "replace") {
        want(3);
        f.kind = Fault::Kind::Replace;
        f.position = position(1);
        f.desc = catalog.find(w[2]);
        if (!f.desc) throw fail(SB() << "'" << w[2] << "' is not a device type of the catalog");
    } else if (verb == "glitch") {
        want(3);
        f.kind = Fault::Kind::Glitch;
        f.position = position(1);
        if (!number(w[2], f.counts) || f.counts == 0) throw fail(SB() << "'" << w[2] << "' is not a count (non-zero integer)");
    } else if (verb == "drive-fault") {
        want(2);
        f.kind = Fault::Kind::DriveFault;
        f.position = position(1);
    } else if (verb == "clear") {
        want(1);
        f.kind = Fault::Kind::Clear;
    } else {
        throw fail(SB() << "unknown fault '" << verb << "'");
    }
    return f;
}

std::string describe(const Fault& f) {
    auto hex = [](uint64_t v, int w) {
        std::ostringstream os;
        os << "0x" << std::hex << std::uppercase;
        os.width(w);
        os.fill('0');
        os << v;
        return os.str();
    };
    const char* st = f.state == 2 ? "PREOP" : f.state == 4 ? "SAFEOP" : "OP";
    switch (f.kind) {
    case Fault::Kind::PowerOff: return SB() << "power " << f.position << " off";
    case Fault::Kind::PowerOn: return SB() << "power " << f.position << " on";
    case Fault::Kind::BreakAfter: return SB() << "break " << f.position;
    case Fault::Kind::Repair: return "repair";
    case Fault::Kind::Loss: return SB() << "loss " << f.fraction;
    case Fault::Kind::Corrupt: return SB() << "corrupt " << f.fraction;
    case Fault::Kind::Delay: return SB() << "delay " << f.fraction;
    case Fault::Kind::RefuseState: return SB() << "refuse-state " << f.position << " " << st << " " << hex(f.al_code, 4);
    case Fault::Kind::RefuseSdo:
        return SB() << "refuse-sdo " << f.position << " " << hex(f.index, 4) << ":" << hex(f.sub, 2).substr(2) << " " << hex(f.abort, 8);
    case Fault::Kind::Replace: return SB() << "replace " << f.position << " " << (f.desc ? f.desc->type : "?");
    case Fault::Kind::Glitch: return SB() << "glitch " << f.position << " " << f.counts;
    case Fault::Kind::DriveFault: return SB() << "drive-fault " << f.position;
    case Fault::Kind::Clear: return "clear";
    }
    return "?";
}

} // namespace beamctl::ethercat::sim
