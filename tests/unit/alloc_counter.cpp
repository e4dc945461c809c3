#include "alloc_counter.hpp"

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <thread>

// Every form of global operator new/delete is replaced (plain, array, nothrow, aligned), all on
// malloc/aligned_alloc/free, so allocation and deallocation always match (ASan checks that).

namespace {
std::atomic<bool> g_on{false};
std::atomic<long> g_count{0};
std::atomic<bool> g_one_thread{false};
std::thread::id g_thread; // written before g_on is set

bool counted() {
    if (!g_on.load(std::memory_order_relaxed)) return false;
    return !g_one_thread.load(std::memory_order_relaxed) || std::this_thread::get_id() == g_thread;
}

void* allocate(std::size_t n, std::size_t align, bool nothrow) {
    if (counted()) g_count.fetch_add(1, std::memory_order_relaxed);
    if (n == 0) n = 1;
    void* p = nullptr;
    if (align <= alignof(std::max_align_t)) {
        p = std::malloc(n);
    } else {
        std::size_t rounded = (n + align - 1) / align * align;
        p = std::aligned_alloc(align, rounded);
    }
    if (!p && !nothrow) throw std::bad_alloc();
    return p;
}
} // namespace

namespace beamctl::test {
void count_allocations(bool on, bool this_thread_only) {
    if (on) {
        g_count = 0;
        g_thread = std::this_thread::get_id();
        g_one_thread = this_thread_only;
    }
    g_on = on;
}
long allocations() { return g_count.load(); }
} // namespace beamctl::test

void* operator new(std::size_t n) { return allocate(n, 0, false); }
void* operator new[](std::size_t n) { return allocate(n, 0, false); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0, true); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0, true); }
void* operator new(std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a), false); }
void* operator new[](std::size_t n, std::align_val_t a) { return allocate(n, std::size_t(a), false); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
    return allocate(n, std::size_t(a), true);
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
    return allocate(n, std::size_t(a), true);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
