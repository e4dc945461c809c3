#include "core/signals.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <cerrno>
#include <csignal>
#include <pthread.h>
#include <cstring>
#include <sys/epoll.h>
#include <sys/signalfd.h>
#include <unistd.h>

namespace beamctl {
namespace {
log::Logger lg("signals");

sigset_t stop_signals() {
    sigset_t mask;
    sigemptyset(&mask);
    sigaddset(&mask, SIGTERM);
    sigaddset(&mask, SIGINT);
    sigaddset(&mask, SIGHUP);
    return mask;
}
} // namespace

void block_stop_signals() {
    sigset_t mask = stop_signals();
    pthread_sigmask(SIG_BLOCK, &mask, nullptr);
}

bool LoopSignals::stop_pending() {
    signalfd_siginfo si;
    bool stop = false;
    while (::read(fd_, &si, sizeof si) == sizeof si) stop = stop || si.ssi_signo != SIGHUP;
    return stop;
}

LoopSignals::LoopSignals(EventLoop& loop, std::function<void()> on_hup) : loop_(loop) {
    sigset_t mask = stop_signals();
    pthread_sigmask(SIG_BLOCK, &mask, nullptr);
    fd_ = signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC);
    if (fd_ < 0) throw Error(SB() << "signalfd: " << std::strerror(errno));
    loop_.add_fd(fd_, EPOLLIN, [this, hup = std::move(on_hup)](uint32_t) {
        signalfd_siginfo si;
        while (::read(fd_, &si, sizeof si) == sizeof si) {
            if (si.ssi_signo == SIGHUP) {
                if (hup) hup();
                else LOG_WARN(lg, "SIGHUP ignored: nothing to reload");
            } else {
                LOG_INFO(lg, "signal " << si.ssi_signo << ": stopping");
                loop_.stop();
            }
        }
    });
}

LoopSignals::~LoopSignals() {
    loop_.remove_fd(fd_);
    ::close(fd_);
}

} // namespace beamctl
