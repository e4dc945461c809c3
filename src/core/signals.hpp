// Process signals for a program built around an EventLoop: SIGTERM and SIGINT stop the loop
// cleanly, SIGHUP calls a reload hook. The signals are blocked and read from a signalfd on the
// loop thread, so handlers may do anything the loop thread may do.
#pragma once

#include "core/event_loop.hpp"

#include <functional>

namespace beamctl {

// Blocks SIGTERM, SIGINT and SIGHUP in the calling thread. Call it first thing in main(), before
// any thread starts: threads inherit the mask, so the signals reach only the signalfd below and
// never kill the process behind the loop's back.
void block_stop_signals();

class LoopSignals {
public:
    LoopSignals(EventLoop& loop, std::function<void()> on_hup);
    ~LoopSignals();
    // After the loop stopped: true if SIGTERM or SIGINT arrived since (a second signal during a
    // clean shutdown: exit at once). Does not block.
    bool stop_pending();
    LoopSignals(const LoopSignals&) = delete;
    LoopSignals& operator=(const LoopSignals&) = delete;

private:
    EventLoop& loop_;
    int fd_ = -1;
};

} // namespace beamctl
