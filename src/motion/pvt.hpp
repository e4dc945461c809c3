// PVT profile moves (position-velocity-time), as ECMC's profile-move support (ecmcPVTController,
// ecmcAxisPVTSequence; the motor module's profileMove PVs are served by ioc/pvt.*):
//   PvtPath        one axis's path: ECMC's construction from positions and segment times, an
//                  acceleration point Ta before the first position and one Ta after the last,
//                  interior velocities the mean of the neighbouring segments', and cubic Hermite
//                  segments between the points; built on the IOC loop, read by the RT thread.
//   PvtController  the RT state machine that runs one profile on several axes: enable them, move
//                  each to its start (the point Ta before its first position), start every path
//                  in the same cycle, emit the trigger pulses and take the readbacks, and end in
//                  Success only when every axis ran its whole path (an interlock, an error, a
//                  stop or a disable ends it as Failure or Abort, never as Success).
// Threading: PvtController::run on the RT thread (after the axes, StageOrder::Axes); execute(),
// abort() and the status accessors on the IOC loop (SPSC queue in, atomics out). No allocation
// in the cycle: jobs carry pointers to paths and buffers the IOC loop keeps alive while busy.
#pragma once

#include "core/spsc_queue.hpp"
#include "registry/signal.hpp"
#include "rt/engine.hpp"

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::motion {

class Axis;

class PvtPath {
public:
    struct Point {
        double t, p, v; // [s] from the start of the path, [units], [units/s]
    };
    // positions: n >= 2 points; durations: n-1 segment times (point i -> i+1) [s], each > 0;
    // ta: acceleration time before the first and after the last point [s], > 0. Throws Error.
    static PvtPath build(const std::vector<double>& positions, const std::vector<double>& durations, double ta);

    double end_time() const noexcept { return pts_.empty() ? 0 : pts_.back().t; }
    std::size_t real_points() const noexcept { return pts_.size() < 2 ? 0 : pts_.size() - 2; }
    double point_time(std::size_t i) const noexcept { return pts_[i + 1].t; } // of real point i
    double start_position() const noexcept { return pts_.front().p; }        // Ta before point 0
    const std::vector<Point>& points() const noexcept { return pts_; }
    // The state at time t (clamped to the path); `seg` is the caller's segment cursor, advanced as
    // t grows (RT: a few instructions per cycle).
    void eval(double t, std::size_t& seg, double& p, double& v, double& a) const noexcept;
    // The path's extremes, sampled every `step` seconds and at every point.
    void extremes(double step, double& pmin, double& pmax, double& vmax) const noexcept;

private:
    std::vector<Point> pts_;
};

class PvtController : public rt::Stage {
public:
    static constexpr std::size_t kMaxAxes = 16;
    enum class State : uint8_t { Idle, EnableAxes, MoveToStart, WaitAtStart, Executing, Stopping };
    enum class Result : uint8_t { Undefined, Success, Failure, Abort };
    // Why a profile failed (with the axis index and its error/warning id in Status).
    enum class Why : uint8_t { None, AxisError, EnableTimeout, StartRefused, StartMissed, PathRefused, EndedShort };

    struct AxisJob {
        Axis* axis = nullptr;
        int index = -1;                // the caller's axis index (for messages)
        const PvtPath* path = nullptr;
        double* readback = nullptr;    // capacity elements each (readback, following error)
        double* ferror = nullptr;
        uint32_t capacity = 0;
        std::atomic<uint32_t>* count = nullptr; // samples taken (release after the data)
    };
    struct Job {
        std::array<AxisJob, kMaxAxes> axes{};
        std::size_t n = 0;
        bool relative = false;          // positions are offsets from each axis's setpoint
        // Pulses (NumPulses > 0): at start_t, start_t + between, ... (count of them), each
        // high for duration_s; readbacks are taken at each rising edge. Without pulses they
        // are taken at every point.
        uint32_t pulses = 0;
        double start_t = 0, between = 0, duration_s = 0.1;
        double enable_timeout_s = 5;
    };
    struct Status {
        State state = State::Idle;
        Result result = Result::Undefined;
        Why why = Why::None;
        int axis = -1;            // the axis index (AxisJob::index) the failure names
        uint32_t id = 0;          // its error or warning id
        int32_t current_point = 0; // 0 ramp in, k = segment k-1 -> k, n ramp out
        uint32_t pulses = 0;       // pulses emitted (NumActualPulses, SftTrg)
        uint64_t runs = 0;         // profiles finished (any result)
    };

    explicit PvtController(double cycle_s) : dt_(cycle_s) {}
    const char* name() const noexcept override { return "pvt"; }
    void run(const rt::CycleInfo& c) noexcept override;

    // IOC loop. False when the queue is full. The job's paths and buffers must stay valid and
    // unchanged until status().state is Idle again after it.
    bool execute(const Job& j) noexcept { return cmds_.push(Cmd{Cmd::Execute, j}); }
    bool abort() noexcept { return cmds_.push(Cmd{Cmd::Abort, {}}); }
    Status status() const noexcept;
    bool busy() const noexcept { return state_.load(std::memory_order_acquire) != State::Idle || !cmds_.empty(); }
    // The trigger output (a bit of the bus image; unbound: none), set before the cycle runs.
    void set_trigger(registry::BoundSignal s) { trigger_ = s; }

private:
    struct Cmd {
        enum Kind : uint8_t { Execute, Abort } kind;
        Job job;
    };
    void fail(Why why, std::size_t k, uint32_t id) noexcept;
    void stop_all() noexcept;
    void finish(Result r) noexcept;
    void pulses_and_readbacks() noexcept;
    void sample(std::size_t k_limit) noexcept;

    double dt_;
    SpscQueue<Cmd> cmds_{4};
    Job job_;
    State st_ = State::Idle;
    std::atomic<State> state_{State::Idle};
    std::atomic<Result> result_{Result::Undefined};
    std::atomic<Why> why_{Why::None};
    std::atomic<int> fail_axis_{-1};
    std::atomic<uint32_t> fail_id_{0};
    std::atomic<int32_t> current_point_{0};
    std::atomic<uint32_t> pulses_{0};
    std::atomic<uint64_t> runs_{0};
    Result pending_result_ = Result::Undefined;
    double t_ = 0, waited_ = 0;
    std::array<double, kMaxAxes> offset_{}, start_{};
    std::size_t point_ = 0;      // points the path has passed (CurrentPoint)
    std::size_t next_point_ = 0; // readback per point: the next point to sample at
    uint32_t pulse_id_ = 0;  // pulses emitted
    double high_until_ = 0;  // the trigger output is high until this path time [s]
    bool pulse_high_ = false;
    registry::BoundSignal trigger_;
};

} // namespace beamctl::motion
