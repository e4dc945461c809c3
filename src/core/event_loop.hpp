// A single-threaded epoll reactor: file-descriptor handlers, one-shot and periodic timers on the
// monotonic clock, an after-batch hook (used to flush output once per wake-up), and post() for
// handing work in from other threads. The IOC loop (PV database + CA server) runs on one of these.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace beamctl {

class EventLoop {
public:
    using FdHandler = std::function<void(uint32_t events)>;
    using TimerId = uint64_t;

    EventLoop();
    ~EventLoop();
    EventLoop(const EventLoop&) = delete;
    EventLoop& operator=(const EventLoop&) = delete;

    // fd handlers (loop thread only). `events` are EPOLLIN/EPOLLOUT/...
    void add_fd(int fd, uint32_t events, FdHandler h);
    void modify_fd(int fd, uint32_t events);
    void remove_fd(int fd);

    // Timers (loop thread only). Delays and periods in seconds.
    TimerId call_after(double delay_s, std::function<void()> fn);
    TimerId call_every(double period_s, std::function<void()> fn);
    void cancel(TimerId id);

    // Runs after every batch of handlers and timers, before the loop sleeps again, until removed
    // (an owner that goes before the loop removes its hook in its destructor).
    using HookId = uint64_t;
    HookId add_after_batch(std::function<void()> fn);
    void remove_after_batch(HookId id);

    // Thread-safe: runs fn on the loop thread soon.
    void post(std::function<void()> fn);
    // Thread-safe: makes run() return after the current batch.
    void stop();
    void run();

    static double now_s(); // CLOCK_MONOTONIC seconds

private:
    struct Timer {
        TimerId id;
        double period_s; // 0: one-shot
        std::function<void()> fn;
    };
    void drain_posted();

    int epfd_ = -1;
    int wakefd_ = -1;
    bool stop_ = false;
    std::unordered_map<int, std::shared_ptr<FdHandler>> handlers_;
    std::multimap<double, Timer> timers_;
    std::unordered_map<TimerId, double> timer_due_;
    TimerId next_timer_ = 1;
    std::vector<std::pair<HookId, std::function<void()>>> after_batch_;
    HookId next_hook_ = 1;
    std::mutex posted_mu_;
    std::vector<std::function<void()>> posted_;
};

} // namespace beamctl
