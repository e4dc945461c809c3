// The real-time engine: one thread per bus master running a fixed-rate cycle of stages in the
// order of ARCHITECTURE.md §2, with per-stage and cycle timing statistics. The clock is
// injectable: tests run in virtual time (cycles back to back, deterministic), `run` uses the
// monotonic clock with absolute sleeps, mlockall, SCHED_FIFO and CPU affinity when permitted.
// Threading: stages run on the RT thread; stats() and request_reset() may be called from any thread.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace beamctl::rt {

class Clock {
public:
    virtual ~Clock() = default;
    virtual uint64_t now_ns() noexcept = 0;              // monotonic
    virtual void sleep_until(uint64_t t_ns) noexcept = 0; // absolute
};

class MonotonicClock : public Clock {
public:
    uint64_t now_ns() noexcept override;
    void sleep_until(uint64_t t_ns) noexcept override;
};

// Virtual time: sleeping jumps the clock to the deadline; each stage can add simulated work.
class VirtualClock : public Clock {
public:
    uint64_t now_ns() noexcept override { return t_; }
    void sleep_until(uint64_t t_ns) noexcept override {
        if (t_ns > t_) t_ = t_ns;
    }
    void advance(uint64_t ns) noexcept { t_ += ns; }

private:
    uint64_t t_ = 1'000'000'000;
};

// An external cycle source: the tick of a bus scanner whose cycle an IOC's engine follows. The
// engine waits for the next tick instead of sleeping on its own schedule.
// Threading: wait() is called on the RT thread only.
class TickSource {
public:
    virtual ~TickSource() = default;
    // Waits for the next tick until `deadline_ns` (engine clock). True with the tick's time
    // [ns, the engine clock's time base] when one came; false at the deadline.
    virtual bool wait(uint64_t deadline_ns, uint64_t& tick_ns) noexcept = 0;
};

// Stage order within a cycle (ARCHITECTURE.md §2).
enum class StageOrder : int { BusReceive = 1, Axes = 2, GeneralPlcs = 3, Triggers = 4, BusSend = 5, Publish = 6 };

struct CycleInfo {
    uint64_t cycle;     // 0, 1, 2, ...
    uint64_t t_ns;      // scheduled start of this cycle (engine clock)
    uint64_t period_ns;
};

class Stage {
public:
    virtual ~Stage() = default;
    virtual const char* name() const noexcept = 0;
    virtual void run(const CycleInfo& c) noexcept = 0;
};

struct EngineConfig {
    double rate_hz = 1000;  // 1..20000
    int cpu = -1;           // pin the RT thread to this CPU (-1: no affinity)
    int priority = 80;      // SCHED_FIFO priority when permitted
    bool lock_memory = true;
};

// Wake-up latency histogram (as cyclictest's, on a 1-2-5 scale): bucket i counts cycles that
// started between kLatencyEdgesUs[i] and kLatencyEdgesUs[i + 1] µs late (lower edge included);
// the last bucket counts everything from 50 ms up.
inline constexpr std::array<uint32_t, 16> kLatencyEdgesUs = {0,   1,    2,    5,    10,    20,    50,    100,
                                                             200, 500, 1000, 2000, 5000, 10000, 20000, 50000};
inline constexpr std::size_t kLatencyBuckets = kLatencyEdgesUs.size();
// The bucket of a latency [ns].
std::size_t latency_bucket(uint64_t latency_ns) noexcept;

struct StageStats {
    std::string name;
    uint64_t last_ns = 0, max_ns = 0, total_ns = 0; // total: since the last reset
};

// Everything but `cycles`, `exec_last_ns` and `resets` counts from the last reset.
struct EngineStats {
    uint64_t cycles = 0;
    uint64_t missed = 0;         // cycle slots skipped because earlier cycles overran
    uint64_t latency_max_ns = 0; // wake-up latency (ecmc ThdLatMax)
    uint64_t exec_max_ns = 0;    // time of all stages of one cycle (ecmc ThdExeMax)
    uint64_t exec_last_ns = 0;
    int64_t jitter_max_ns = 0;   // largest |actual period - nominal|
    uint64_t latency_samples = 0;  // cycles whose wake-up latency was measured (sum of the histogram)
    uint64_t latency_total_ns = 0; // sum of those latencies
    std::array<uint64_t, kLatencyBuckets> latency_hist{}; // counts per bucket of kLatencyEdgesUs
    uint64_t resets = 0;           // resets the RT thread has applied so far
    uint64_t ticks = 0;            // cycles started by the tick source (Engine::set_tick_source)
    uint64_t free_run = 0;         // cycles run on the engine's own clock because no tick came
    std::vector<StageStats> stages;
    double latency_mean_ns() const { return latency_samples ? double(latency_total_ns) / double(latency_samples) : 0.0; }
};

class Engine {
public:
    Engine(EngineConfig cfg, Clock& clock);
    ~Engine();
    Engine(const Engine&) = delete;
    Engine& operator=(const Engine&) = delete;

    // Before start: stages run in StageOrder, then in the order added.
    void add_stage(StageOrder order, Stage& s);
    // Runs n cycles on the calling thread (virtual time in tests; no sleeping if the clock is
    // virtual). Returns when done.
    void run_cycles(uint64_t n) noexcept;
    // Before start: cycles follow `tick` (not owned). A cycle starts at each tick, at the tick's
    // time (wake-up latency is then measured from the tick); when no tick comes within `grace_ns`
    // after the cycle was due, the engine runs that cycle on its own clock (counted as free_run:
    // axes decelerate, PVs update) and keeps waiting for ticks, which it follows again when they
    // return. nullptr: the engine's own schedule.
    void set_tick_source(TickSource* tick, uint64_t grace_ns) noexcept {
        tick_ = tick;
        grace_ns_ = grace_ns;
    }
    // Starts the RT thread (real time setup logged once); stop() joins it.
    void start();
    void stop();
    bool running() const { return running_.load(); }

    EngineStats stats() const; // consistent enough for display (relaxed counters)
    uint64_t period_ns() const { return period_ns_; }
    // Virtual time, between run_cycles calls: when the next cycle is due [ns, engine clock].
    uint64_t next_due_ns() const noexcept { return next_ns_ ? next_ns_ : clock_.now_ns(); }
    // What the RT setup achieved ("SCHED_FIFO 80 on CPU 1, memory locked" or the reasons not).
    const std::string& rt_setup() const { return rt_setup_; }
    // Asks the RT thread to clear the statistics (max times, jitter, missed cycles, stage totals,
    // the latency histogram and mean) at the start of its next cycle; stats().resets counts the
    // resets done. Any thread; the RT thread is the only one that writes the statistics.
    void request_reset() noexcept { reset_req_.fetch_add(1, std::memory_order_release); }
    uint64_t resets_requested() const noexcept { return reset_req_.load(std::memory_order_relaxed); }

private:
    void cycle(uint64_t scheduled_ns) noexcept;
    void clear_stats() noexcept; // RT thread
    void thread_main();

    struct Entry {
        int order;
        Stage* stage;
        std::atomic<uint64_t> last{0}, max{0}, total{0};
    };
    EngineConfig cfg_;
    Clock& clock_;
    uint64_t period_ns_;
    std::vector<std::unique_ptr<Entry>> stages_;
    std::atomic<uint64_t> cycles_{0}, missed_{0}, lat_max_{0}, exe_max_{0}, exe_last_{0};
    std::atomic<int64_t> jitter_max_{0};
    std::atomic<uint64_t> lat_samples_{0}, lat_total_{0};
    std::array<std::atomic<uint64_t>, kLatencyBuckets> lat_hist_{};
    std::atomic<uint64_t> reset_req_{0}, reset_done_{0};
    uint64_t next_ns_ = 0, last_start_ns_ = 0;
    TickSource* tick_ = nullptr;
    uint64_t grace_ns_ = 0;
    std::atomic<uint64_t> ticks_{0}, free_run_{0};
    std::atomic<bool> running_{false}, stop_{false};
    std::thread thread_;
    std::string rt_setup_;
};

} // namespace beamctl::rt
