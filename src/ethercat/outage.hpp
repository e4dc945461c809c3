// Bus outages as the health thread sees them (ethercat.md, "Bus outages"): fed one sample of the
// bus per health pass with the time passed in, it says what to log: when an outage begins (what
// is wrong), again at most every `repeat_s` while it lasts, and when it ends: once the bus has been
// good for `settle_s` (so a flapping link is one outage, not many), with how long it lasted.
// Errors counted between two good passes (a lost frame, one wrong working counter) are summed
// and logged at most every `repeat_s`.
// Threading: one thread (the bus health thread); no clock, no I/O.
#pragma once

#include "core/log.hpp"

#include <cstdint>
#include <optional>
#include <string>

namespace beamctl::ethercat {

// The bus as one health pass sees it.
struct BusSample {
    bool send_ok = true;                      // the link took the last cycle's frames
    bool frames_back = true;                  // the last cycle's frames came back
    uint16_t wkc = 0, expected_wkc = 0;       // of the last cycle
    uint64_t frames_lost = 0, wkc_errors = 0; // totals since the start
    std::string slaves; // slaves not in OP per the status poll ("slave 2 (EL7041) not answering"); "" if none
    bool ok() const { return send_ok && frames_back && wkc == expected_wkc; }
};

class OutageMonitor {
public:
    explicit OutageMonitor(std::string bus_name, double repeat_s = 5.0, double settle_s = 0.5)
        : bus_(std::move(bus_name))
        , repeat_s_(repeat_s)
        , settle_s_(settle_s) {}

    struct Report {
        log::Level level;
        std::string text;
    };
    // One health pass at `now_s` (monotonic [s]): the line to log, if any.
    std::optional<Report> update(const BusSample& s, double now_s);
    bool in_outage() const { return in_outage_; }

private:
    static std::string describe(const BusSample& s);

    std::string bus_;
    double repeat_s_, settle_s_;                    // [s]
    bool started_ = false;
    bool in_outage_ = false;
    double began_s_ = 0, reported_s_ = 0;           // outage start, last line about it [s]
    double good_since_s_ = -1;                      // first of the good passes ending it [s]; -1: bad
    uint64_t lost0_ = 0, wkc0_ = 0;                 // counters at the outage start
    uint64_t last_lost_ = 0, last_wkc_ = 0;         // counters at the previous pass
    uint64_t glitch_lost_ = 0, glitch_wkc_ = 0;     // errors outside outages, not yet logged
    double glitch_since_s_ = 0, glitch_reported_s_ = -1e300;
};

} // namespace beamctl::ethercat
