// Process signals for a program built around an EventLoop: SIGTERM and SIGINT stop the loop
// cleanly, SIGHUP calls a reload hook. The signals are blocked and read from a signalfd on the
// loop thread, so handlers may do anything the loop thread may do.
#pragma once

#include "core/event_loop.hpp"

#include <functional>

namespace beamctl {

class LoopSignals {
public:
    LoopSignals(EventLoop& loop, std::function<void()> on_hup);
    ~LoopSignals();
    LoopSignals(const LoopSignals&) = delete;
    LoopSignals& operator=(const LoopSignals&) = delete;

private:
    EventLoop& loop_;
    int fd_ = -1;
};

} // namespace beamctl
