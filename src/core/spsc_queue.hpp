// Fixed-capacity single-producer/single-consumer queue: the only way non-RT threads hand
// commands to the RT cycle and the cycle hands events back (ARCHITECTURE.md §2, rule 2).
// push/pop are wait-free and never allocate; capacity is fixed at construction.
#pragma once

#include <atomic>
#include <cstddef>
#include <memory>

namespace beamctl {

template <typename T> class SpscQueue {
public:
    explicit SpscQueue(std::size_t capacity) : cap_(capacity + 1), buf_(new T[capacity + 1]) {}
    // Producer thread only. False when full (the caller counts the drop).
    bool push(const T& v) noexcept {
        std::size_t h = head_.load(std::memory_order_relaxed);
        std::size_t n = h + 1 == cap_ ? 0 : h + 1;
        if (n == tail_.load(std::memory_order_acquire)) return false;
        buf_[h] = v;
        head_.store(n, std::memory_order_release);
        return true;
    }
    // Consumer thread only. False when empty.
    bool pop(T& out) noexcept {
        std::size_t t = tail_.load(std::memory_order_relaxed);
        if (t == head_.load(std::memory_order_acquire)) return false;
        out = buf_[t];
        tail_.store(t + 1 == cap_ ? 0 : t + 1, std::memory_order_release);
        return true;
    }
    bool empty() const noexcept {
        return tail_.load(std::memory_order_acquire) == head_.load(std::memory_order_acquire);
    }

private:
    std::size_t cap_;
    std::unique_ptr<T[]> buf_;
    alignas(64) std::atomic<std::size_t> head_{0};
    alignas(64) std::atomic<std::size_t> tail_{0};
};

} // namespace beamctl
