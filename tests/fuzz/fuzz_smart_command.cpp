// libFuzzer: arbitrary bytes into smartControl's line framing and command parser, as a client's
// TCP stream or pty would bring them (src/automation); each parsed position through the setup
// table's conversion with a window from the input. Crashes, UB, or a converted position outside
// its cut window or not the same angle, are bugs.
#include "automation/line_server.hpp"
#include "automation/smart_command.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl::automation;
    std::string in, line;
    bool dropping = false;
    // fed in irregular chunks, as reads would deliver them
    size_t off = 0, step = 1;
    while (off < size) {
        const size_t n = std::min(size - off, step);
        in.append(reinterpret_cast<const char*>(data + off), n);
        off += n;
        step = step * 5 % 61 + 1;
        for (;;) {
            const LineEvent e = next_line(in, dropping, line, LineServer::kMaxLine);
            if (e == LineEvent::None) break;
            if (e == LineEvent::TooLong) continue;
            if (line.size() > LineServer::kMaxLine || line.find_first_of("\r\n") != std::string::npos) __builtin_trap();
            SmartCommand c;
            std::string why;
            if (!parse_smart_command(line, c, why)) {
                if (why.empty() || why.size() > 400) __builtin_trap();
                continue;
            }
            SmartAxisSetup a;
            a.sign = (line.size() & 1) ? -1 : 1;
            a.offset = double(line.size() % 97) - 48;
            if (line.size() % 3 == 0) a.low_cut = -double(line.size() % 360) - 1, a.high_cut = a.low_cut + 360 + double(line.size() % 7);
            auto check = [&](double smart) {
                double m = 0;
                std::string w;
                if (!smart_to_motor(a, smart, m, w)) return;
                if (a.high_cut > a.low_cut && std::fabs(smart) < 1e12) {
                    if (m < a.low_cut - 1e-6 || m > a.high_cut + 1e-6) __builtin_trap();
                    const double back = motor_to_smart(a, m);
                    if (std::fabs(std::remainder(back - smart, 360.0)) > 1e-6 * (1 + std::fabs(smart))) __builtin_trap();
                }
            };
            for (const auto& t : c.targets) check(t.second);
            if (c.kind == SmartCommand::Kind::Scan) check(c.start), check(c.end);
        }
    }
    return 0;
}
