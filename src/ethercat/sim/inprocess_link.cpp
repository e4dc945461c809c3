#include "ethercat/sim/inprocess_link.hpp"

#include "ethercat/sim/segment.hpp"

#include <cstring>

namespace beamctl::ethercat::sim {

bool InProcessLink::send(const uint8_t* frame, std::size_t len) noexcept {
    if (len > kMaxFrame || head_ - tail_ >= kSlots) return false;
    auto& slot = ring_[head_ % kSlots];
    std::memcpy(slot.data(), frame, len);
    if (!seg_.process(slot.data(), len)) return true; // lost on the wire
    len_[head_ % kSlots] = len;
    hold_[head_ % kSlots] = seg_.answer_delay_us();
    ++head_;
    return true;
}

std::size_t InProcessLink::receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept {
    if (tail_ == head_) return 0;
    int64_t& hold = hold_[tail_ % kSlots];
    if (hold > 0) { // an answer delayed (fault injection): back within this wait, or still on its way
        if (hold > timeout_us) {
            hold -= timeout_us;
            return 0;
        }
        hold = 0;
    }
    std::size_t len = len_[tail_ % kSlots];
    if (len > cap) len = cap;
    std::memcpy(buf, ring_[tail_ % kSlots].data(), len);
    ++tail_;
    return len;
}

} // namespace beamctl::ethercat::sim
