// The in-process transport: frames go straight through a simulated segment in this process (the
// default link of `link: {type: sim}`, and the tests). It lives with the simulator so that the
// master's library never depends on it.
// send/receive are called from the master's thread only; they never allocate.
#pragma once

#include "ethercat/link.hpp"

#include <array>
#include <cstddef>
#include <cstdint>

namespace beamctl::ethercat::sim {

class Segment;

// Frames go through a simulated segment synchronously; a lost frame never comes back.
class InProcessLink : public Link {
public:
    explicit InProcessLink(Segment& seg) : seg_(seg) {}
    bool send(const uint8_t* frame, std::size_t len) noexcept override;
    std::size_t receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept override;
    const char* kind() const noexcept override { return "inproc"; }

private:
    Segment& seg_;
    static constexpr int kSlots = 8;
    std::array<std::array<uint8_t, kMaxFrame>, kSlots> ring_{};
    std::array<std::size_t, kSlots> len_{};
    std::array<int64_t, kSlots> hold_{}; // [us] a frame is still on its way (Segment::answer_delay_us)
    int head_ = 0, tail_ = 0; // frames in flight: [tail, head)
};

} // namespace beamctl::ethercat::sim
