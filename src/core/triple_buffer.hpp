// Triple buffer: the RT cycle publishes a snapshot every cycle without waiting; a non-RT reader
// always gets the latest complete one. One writer thread, one reader thread; no allocation after
// construction (buffers are sized once with `init`).
#pragma once

#include <atomic>
#include <cstdint>

namespace beamctl {

template <typename T> class TripleBuffer {
public:
    // Not thread-safe: call before the writer and reader start.
    template <typename Fn> void init(Fn&& fn) {
        for (auto& b : bufs_) fn(b);
    }
    // Writer: the buffer to fill, then publish().
    T& write_buffer() noexcept { return bufs_[write_]; }
    void publish() noexcept {
        uint8_t prev = middle_.exchange(uint8_t(write_ | kFresh), std::memory_order_acq_rel);
        write_ = prev & 3;
    }
    // Reader: true if a newer snapshot arrived since the last call; read_buffer() is it.
    bool update() noexcept {
        if (!(middle_.load(std::memory_order_acquire) & kFresh)) return false;
        uint8_t prev = middle_.exchange(read_, std::memory_order_acq_rel);
        read_ = prev & 3;
        return true;
    }
    const T& read_buffer() const noexcept { return bufs_[read_]; }

private:
    static constexpr uint8_t kFresh = 4;
    T bufs_[3];
    uint8_t write_ = 0, read_ = 1;
    std::atomic<uint8_t> middle_{2};
};

} // namespace beamctl
