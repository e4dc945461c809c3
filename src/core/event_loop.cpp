#include "core/event_loop.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <unistd.h>

namespace beamctl {

double EventLoop::now_s() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + ts.tv_nsec * 1e-9;
}

EventLoop::EventLoop() {
    epfd_ = epoll_create1(EPOLL_CLOEXEC);
    wakefd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (epfd_ < 0 || wakefd_ < 0) throw Error(SB() << "event loop: " << std::strerror(errno));
    add_fd(wakefd_, EPOLLIN, [this](uint32_t) {
        uint64_t v;
        while (::read(wakefd_, &v, sizeof v) > 0) {
        }
        drain_posted();
    });
}

EventLoop::~EventLoop() {
    ::close(wakefd_);
    ::close(epfd_);
}

void EventLoop::add_fd(int fd, uint32_t events, FdHandler h) {
    epoll_event ev{};
    ev.events = events;
    ev.data.fd = fd;
    if (epoll_ctl(epfd_, EPOLL_CTL_ADD, fd, &ev) != 0)
        throw Error(SB() << "epoll add fd " << fd << ": " << std::strerror(errno));
    handlers_[fd] = std::make_shared<FdHandler>(std::move(h));
}

void EventLoop::modify_fd(int fd, uint32_t events) {
    epoll_event ev{};
    ev.events = events;
    ev.data.fd = fd;
    epoll_ctl(epfd_, EPOLL_CTL_MOD, fd, &ev);
}

void EventLoop::remove_fd(int fd) {
    epoll_ctl(epfd_, EPOLL_CTL_DEL, fd, nullptr);
    handlers_.erase(fd);
}

EventLoop::TimerId EventLoop::call_after(double delay_s, std::function<void()> fn) {
    TimerId id = next_timer_++;
    double due = now_s() + delay_s;
    timers_.emplace(due, Timer{id, 0, std::move(fn)});
    timer_due_[id] = due;
    return id;
}

EventLoop::TimerId EventLoop::call_every(double period_s, std::function<void()> fn) {
    TimerId id = next_timer_++;
    double due = now_s() + period_s;
    timers_.emplace(due, Timer{id, period_s, std::move(fn)});
    timer_due_[id] = due;
    return id;
}

void EventLoop::cancel(TimerId id) {
    auto it = timer_due_.find(id);
    if (it == timer_due_.end()) return;
    auto range = timers_.equal_range(it->second);
    for (auto t = range.first; t != range.second; ++t)
        if (t->second.id == id) {
            timers_.erase(t);
            break;
        }
    timer_due_.erase(it);
}

EventLoop::HookId EventLoop::add_after_batch(std::function<void()> fn) {
    after_batch_.emplace_back(next_hook_, std::move(fn));
    return next_hook_++;
}

void EventLoop::remove_after_batch(HookId id) {
    // emptied, not erased: a hook may remove another (or itself) while they run
    for (auto& [hid, fn] : after_batch_)
        if (hid == id) fn = nullptr;
}

void EventLoop::post(std::function<void()> fn) {
    {
        std::lock_guard<std::mutex> g(posted_mu_);
        posted_.push_back(std::move(fn));
    }
    uint64_t one = 1;
    [[maybe_unused]] ssize_t r = ::write(wakefd_, &one, sizeof one);
}

void EventLoop::stop() {
    post([this] { stop_ = true; });
}

void EventLoop::drain_posted() {
    std::vector<std::function<void()>> work;
    {
        std::lock_guard<std::mutex> g(posted_mu_);
        work.swap(posted_);
    }
    for (auto& fn : work) fn();
}

void EventLoop::run() {
    stop_ = false;
    epoll_event events[128];
    while (!stop_) {
        int timeout_ms = -1;
        if (!timers_.empty()) {
            double dt = timers_.begin()->first - now_s();
            timeout_ms = dt <= 0 ? 0 : int(std::ceil(dt * 1000));
        }
        int n = epoll_wait(epfd_, events, 128, timeout_ms);
        if (n < 0 && errno != EINTR) throw Error(SB() << "epoll_wait: " << std::strerror(errno));
        for (int i = 0; i < n; ++i) {
            auto it = handlers_.find(events[i].data.fd);
            if (it == handlers_.end()) continue;
            std::shared_ptr<FdHandler> h = it->second; // survives remove_fd inside the handler
            (*h)(events[i].events);
        }
        double now = now_s();
        while (!timers_.empty() && timers_.begin()->first <= now) {
            auto node = timers_.extract(timers_.begin());
            Timer t = std::move(node.mapped());
            timer_due_.erase(t.id);
            if (t.period_s > 0) {
                double due = node.key() + t.period_s;
                if (due < now) due = now + t.period_s; // fell behind: no burst
                timer_due_[t.id] = due;
                auto fn = t.fn;
                timers_.emplace(due, std::move(t));
                fn();
            } else {
                t.fn();
            }
        }
        for (std::size_t i = 0; i < after_batch_.size(); ++i)
            if (after_batch_[i].second) {
                auto fn = after_batch_[i].second; // the hook may remove itself while it runs
                fn();
            }
        std::erase_if(after_batch_, [](const auto& h) { return !h.second; });
    }
}

} // namespace beamctl
