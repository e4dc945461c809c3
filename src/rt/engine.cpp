#include "rt/engine.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

namespace beamctl::rt {
namespace {
log::Logger lg("rt.engine");

void atomic_max(std::atomic<uint64_t>& a, uint64_t v) noexcept {
    uint64_t cur = a.load(std::memory_order_relaxed);
    while (v > cur && !a.compare_exchange_weak(cur, v, std::memory_order_relaxed)) {
    }
}

// Adds to a counter only the RT thread writes (readers see whole values).
void bump(std::atomic<uint64_t>& a, uint64_t v) noexcept {
    a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
}
} // namespace

std::size_t latency_bucket(uint64_t latency_ns) noexcept {
    std::size_t i = kLatencyBuckets - 1;
    while (i > 0 && latency_ns < uint64_t(kLatencyEdgesUs[i]) * 1000u) --i;
    return i;
}

uint64_t MonotonicClock::now_ns() noexcept {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000u + uint64_t(ts.tv_nsec);
}

void MonotonicClock::sleep_until(uint64_t t) noexcept {
    timespec ts{time_t(t / 1'000'000'000u), long(t % 1'000'000'000u)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
}

Engine::Engine(EngineConfig cfg, Clock& clock) : cfg_(cfg), clock_(clock) {
    if (!(cfg_.rate_hz >= 1 && cfg_.rate_hz <= 20000))
        throw Error(SB() << "engine.rate_hz: " << cfg_.rate_hz << " should be between 1 and 20000");
    period_ns_ = uint64_t(1e9 / cfg_.rate_hz + 0.5);
}

Engine::~Engine() { stop(); }

void Engine::add_stage(StageOrder order, Stage& s) {
    if (running_) throw Error("engine: stages must be added before the cycle starts");
    auto e = std::make_unique<Entry>();
    e->order = int(order);
    e->stage = &s;
    stages_.push_back(std::move(e));
    std::stable_sort(stages_.begin(), stages_.end(),
                     [](const auto& a, const auto& b) { return a->order < b->order; });
}

void Engine::cycle(uint64_t scheduled) noexcept {
    uint64_t start = clock_.now_ns();
    uint64_t req = reset_req_.load(std::memory_order_acquire);
    if (req != reset_done_.load(std::memory_order_relaxed)) {
        clear_stats();
        reset_done_.store(req, std::memory_order_release);
    }
    uint64_t n = cycles_.load(std::memory_order_relaxed);
    if (n > 0) {
        uint64_t latency = start > scheduled ? start - scheduled : 0;
        atomic_max(lat_max_, latency);
        bump(lat_hist_[latency_bucket(latency)], 1);
        bump(lat_total_, latency);
        bump(lat_samples_, 1);
        int64_t jitter = int64_t(start - last_start_ns_) - int64_t(period_ns_);
        if (jitter < 0) jitter = -jitter;
        if (jitter > jitter_max_.load(std::memory_order_relaxed))
            jitter_max_.store(jitter, std::memory_order_relaxed);
    }
    last_start_ns_ = start;
    CycleInfo info{n, scheduled, period_ns_};
    uint64_t t0 = start;
    for (auto& e : stages_) {
        e->stage->run(info);
        uint64_t t1 = clock_.now_ns();
        uint64_t dt = t1 - t0;
        e->last.store(dt, std::memory_order_relaxed);
        bump(e->total, dt);
        atomic_max(e->max, dt);
        t0 = t1;
    }
    uint64_t exe = t0 - start;
    exe_last_.store(exe, std::memory_order_relaxed);
    atomic_max(exe_max_, exe);
    cycles_.fetch_add(1, std::memory_order_relaxed);
}

void Engine::run_cycles(uint64_t n) noexcept {
    if (next_ns_ == 0) next_ns_ = clock_.now_ns();
    for (uint64_t i = 0; i < n; ++i) {
        if (tick_) { // the cycle follows the tick source; its own clock only when no tick comes
            uint64_t t = 0;
            if (tick_->wait(next_ns_ + grace_ns_, t)) {
                bump(ticks_, 1);
                cycle(t);
                next_ns_ = t + period_ns_;
            } else {
                bump(free_run_, 1);
                cycle(next_ns_ + grace_ns_);
                next_ns_ += period_ns_;
            }
            continue;
        }
        clock_.sleep_until(next_ns_);
        cycle(next_ns_);
        next_ns_ += period_ns_;
        uint64_t now = clock_.now_ns();
        if (now >= next_ns_ + period_ns_) {
            // Whole periods passed while this cycle ran: those slots are missed (counted), and the
            // schedule skips them instead of bursting to catch up.
            uint64_t skipped = (now - next_ns_) / period_ns_;
            bump(missed_, skipped);
            next_ns_ += skipped * period_ns_;
        }
    }
}

void Engine::start() {
    if (running_) return;
    stop_ = false;
    running_ = true;
    std::string setup;
    if (cfg_.lock_memory) {
        if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) setup += "memory locked";
        else
            setup += SB() << "mlockall refused (" << std::strerror(errno)
                          << "): memory may page; grant CAP_IPC_LOCK or raise the memlock limit (LimitMEMLOCK=infinity)";
    }
    thread_ = std::thread([this] { thread_main(); });
    // Scheduling policy and affinity are set on the new thread from here.
    sched_param sp{};
    sp.sched_priority = cfg_.priority;
    int r = pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &sp);
    setup += r == 0 ? std::string(SB() << ", SCHED_FIFO " << cfg_.priority)
                    : std::string(SB() << ", SCHED_FIFO refused (" << std::strerror(r)
                                       << "): normal scheduling; grant CAP_SYS_NICE or an RT priority limit (LimitRTPRIO=" << cfg_.priority << ")");
    if (cfg_.cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(cfg_.cpu, &set);
        r = pthread_setaffinity_np(thread_.native_handle(), sizeof set, &set);
        setup += r == 0 ? std::string(SB() << ", pinned to CPU " << cfg_.cpu)
                        : std::string(SB() << ", CPU " << cfg_.cpu << " affinity refused (" << std::strerror(r) << ")");
    }
    rt_setup_ = setup;
    LOG_INFO(lg, "RT cycle at " << cfg_.rate_hz << " Hz: " << rt_setup_);
}

void Engine::thread_main() {
    next_ns_ = clock_.now_ns() + period_ns_;
    while (!stop_.load(std::memory_order_relaxed)) run_cycles(1);
}

void Engine::stop() {
    if (!running_) return;
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    running_ = false;
}

void Engine::clear_stats() noexcept {
    constexpr auto r = std::memory_order_relaxed;
    lat_max_.store(0, r);
    exe_max_.store(0, r);
    jitter_max_.store(0, r);
    missed_.store(0, r);
    lat_samples_.store(0, r);
    lat_total_.store(0, r);
    for (auto& b : lat_hist_) b.store(0, r);
    for (auto& e : stages_) {
        e->max.store(0, r);
        e->total.store(0, r);
    }
}

EngineStats Engine::stats() const {
    EngineStats s;
    s.cycles = cycles_.load();
    s.missed = missed_.load();
    s.ticks = ticks_.load(std::memory_order_relaxed);
    s.free_run = free_run_.load(std::memory_order_relaxed);
    s.latency_max_ns = lat_max_.load();
    s.exec_max_ns = exe_max_.load();
    s.exec_last_ns = exe_last_.load();
    s.jitter_max_ns = jitter_max_.load();
    s.latency_samples = lat_samples_.load(std::memory_order_relaxed);
    s.latency_total_ns = lat_total_.load(std::memory_order_relaxed);
    for (std::size_t i = 0; i < kLatencyBuckets; ++i) s.latency_hist[i] = lat_hist_[i].load(std::memory_order_relaxed);
    s.resets = reset_done_.load(std::memory_order_acquire);
    for (auto& e : stages_)
        s.stages.push_back(StageStats{e->stage->name(), e->last.load(), e->max.load(), e->total.load()});
    return s;
}

} // namespace beamctl::rt
