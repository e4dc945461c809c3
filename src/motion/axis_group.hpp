// The axes of one IOC in the RT cycle (stage Axes) and their face to non-RT code: commands go
// in through a bounded SPSC queue, statuses come out through a triple buffer.
// Threading: run() on the RT thread; send() and snapshot() on ONE non-RT thread (the IOC loop).
#pragma once

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"
#include "motion/axis.hpp"
#include "motion/kinematics.hpp"
#include "rt/engine.hpp"

#include <atomic>
#include <memory>
#include <vector>

namespace beamctl::motion {

// Runs just before an axis in the cycle: its axis PLC (ARCHITECTURE.md §2). RT thread.
class AxisHook {
public:
    virtual ~AxisHook() = default;
    virtual void before_axis(std::size_t index, const rt::CycleInfo& c) noexcept = 0;
};

class AxisGroup : public rt::Stage {
public:
    explicit AxisGroup(std::vector<std::unique_ptr<Axis>> axes, std::size_t queue = 1024);

    const char* name() const noexcept override { return "axes"; }
    // RT: applies queued commands, runs every axis for the cycle's period, publishes statuses.
    void run(const rt::CycleInfo& c) noexcept override;

    // Non-RT: queues a command for axis `index` (position in the group). False if the queue is
    // full (counted in commands_dropped()).
    bool send(std::size_t index, const AxisCommand& c) noexcept;
    // Non-RT: the latest statuses, one per axis, and the result of each command as it was taken
    // by the cycle (tag, 0 or the refusal id), newest last.
    struct Result {
        uint64_t tag = 0;
        uint32_t code = 0;
        std::size_t axis = 0;       // group index of the commanded axis
        int kinematics = -1;        // index of the kinematics group that refused or stopped it
        KinematicsVerdict verdict;  // its reason (real axis, position, limit)
    };
    const std::vector<AxisStatus>& snapshot() noexcept;
    bool pop_result(Result& r) noexcept { return results_.pop(r); }
    uint64_t commands_dropped() const noexcept { return dropped_.load(); }

    // Before the cycle starts: who runs before each axis (nullptr: nobody).
    void set_hook(AxisHook* hook) noexcept { hook_ = hook; }
    // Before the cycle starts: a kinematics group over axes of this group (checked on every
    // command to its virtual axes, supervised every cycle). Returns its index.
    std::size_t add_kinematics(std::unique_ptr<Kinematics> k);
    std::size_t kinematics_count() const noexcept { return kinematics_.size(); }
    const Kinematics& kinematics(std::size_t i) const noexcept { return *kinematics_[i]; }

    std::size_t size() const noexcept { return axes_.size(); }
    Axis& axis(std::size_t i) noexcept { return *axes_[i]; } // RT side (tests in virtual time)

private:
    struct Queued {
        std::size_t index = 0;
        AxisCommand cmd;
    };
    std::vector<std::unique_ptr<Axis>> axes_;
    SpscQueue<Queued> commands_;
    SpscQueue<Result> results_;
    TripleBuffer<std::vector<AxisStatus>> statuses_;
    std::atomic<uint64_t> dropped_{0};
    AxisHook* hook_ = nullptr;
    std::vector<std::unique_ptr<Kinematics>> kinematics_;
    std::vector<int> kinematics_of_; // per axis: the kinematics group it is a virtual axis of, or -1
};

} // namespace beamctl::motion
