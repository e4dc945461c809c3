#include "ethercat/outage.hpp"

#include "core/error.hpp"

#include <cstdio>

namespace beamctl::ethercat {
namespace {

constexpr double kEps = 1e-6; // [s] passes scheduled exactly `repeat_s` apart count as that far apart

std::string secs(double s) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.1f s", s);
    return buf;
}

std::string counts(uint64_t lost, uint64_t wkc) {
    return SB() << lost << " cyclic frame(s) lost, " << wkc << " cycle(s) with a wrong working counter";
}

} // namespace

std::string OutageMonitor::describe(const BusSample& s) {
    SB sb;
    const char* sep = "";
    if (!s.send_ok) {
        sb << "the link refuses to send frames";
        sep = "; ";
    }
    if (!s.frames_back) {
        sb << sep << "no cyclic frame comes back";
        return sb; // the slave status is the last one seen, from before
    }
    if (s.wkc != s.expected_wkc) {
        sb << sep << "working counter " << s.wkc << ", expected " << s.expected_wkc;
        sep = "; ";
    }
    if (!s.slaves.empty()) sb << sep << s.slaves;
    return sb;
}

std::optional<OutageMonitor::Report> OutageMonitor::update(const BusSample& s, double now_s) {
    if (!started_) {
        started_ = true;
        last_lost_ = s.frames_lost;
        last_wkc_ = s.wkc_errors;
    }
    uint64_t dl = s.frames_lost >= last_lost_ ? s.frames_lost - last_lost_ : 0;
    uint64_t dw = s.wkc_errors >= last_wkc_ ? s.wkc_errors - last_wkc_ : 0;
    uint64_t prev_lost = last_lost_, prev_wkc = last_wkc_;
    last_lost_ = s.frames_lost;
    last_wkc_ = s.wkc_errors;

    if (in_outage_) {
        uint64_t lost = s.frames_lost - lost0_, wkc = s.wkc_errors - wkc0_;
        bool clean = s.ok() && dl == 0 && dw == 0;
        if (!clean) good_since_s_ = -1;
        else if (good_since_s_ < 0) good_since_s_ = now_s;
        if (clean && now_s - good_since_s_ >= settle_s_ - kEps) {
            in_outage_ = false;
            return Report{log::Level::info, SB() << bus_ << ": bus outage ended after " << secs(good_since_s_ - began_s_)
                                                 << " (" << counts(lost, wkc) << ")"};
        }
        if (now_s - reported_s_ < repeat_s_ - kEps) return std::nullopt;
        reported_s_ = now_s;
        return Report{log::Level::err, SB() << bus_ << ": bus outage for " << secs(now_s - began_s_) << ": "
                                            << (s.ok() ? std::string("recovering") : describe(s)) << " ("
                                            << counts(lost, wkc) << " so far)"};
    }
    if (!s.ok()) {
        in_outage_ = true;
        began_s_ = reported_s_ = now_s;
        good_since_s_ = -1;
        lost0_ = prev_lost; // the errors since the previous (good) pass belong to this outage
        wkc0_ = prev_wkc;
        SB sb;
        sb << bus_ << ": bus outage: " << describe(s);
        if (glitch_lost_ || glitch_wkc_) // brief errors before it, not logged yet
            sb << " (before it, in the last " << secs(now_s - glitch_since_s_) << ": "
               << counts(glitch_lost_, glitch_wkc_) << ")";
        glitch_lost_ = glitch_wkc_ = 0;
        return Report{log::Level::err, sb};
    }
    if (dl || dw) {
        if (!glitch_lost_ && !glitch_wkc_) glitch_since_s_ = now_s;
        glitch_lost_ += dl;
        glitch_wkc_ += dw;
    }
    if ((glitch_lost_ || glitch_wkc_) && now_s - glitch_reported_s_ >= repeat_s_ - kEps) {
        std::string when = glitch_since_s_ == now_s ? std::string("since the previous check")
                                                    : std::string(SB() << "in the last " << secs(now_s - glitch_since_s_));
        Report r{log::Level::warn, SB() << bus_ << ": brief bus errors, the bus is OK: "
                                        << counts(glitch_lost_, glitch_wkc_) << " " << when};
        glitch_lost_ = glitch_wkc_ = 0;
        glitch_reported_s_ = now_s;
        return r;
    }
    return std::nullopt;
}

} // namespace beamctl::ethercat
