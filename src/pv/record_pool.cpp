#include "pv/record_pool.hpp"

#include <algorithm>
#include <mutex>
#include <new>
#include <unordered_map>
#include <vector>

#if defined(__SANITIZE_ADDRESS__)
#define BEAMCTL_RECORD_POOL 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define BEAMCTL_RECORD_POOL 0
#endif
#endif
#ifndef BEAMCTL_RECORD_POOL
#define BEAMCTL_RECORD_POOL 1
#endif

namespace beamctl::pv::record_pool {
namespace {

constexpr std::size_t kAlign = alignof(std::max_align_t); // 16 on x86-64
constexpr std::size_t kBlockBytes = 64 * 1024;             // a block holds many records of one size
constexpr std::size_t kMinPerBlock = 8;                    // large records (motor): 8 per block

struct Node {
    Node* next;
};

struct SizeClass {
    Node* free = nullptr;    // records given back, reused first
    char* next = nullptr;    // the unused rest of the newest block
    std::size_t left = 0;    // bytes in it
};

struct Pool {
    std::mutex mu;
    std::unordered_map<std::size_t, SizeClass> classes; // by rounded size
    std::vector<void*> blocks;                          // kept for the life of the process
};

Pool& pool() {
    static Pool* p = new Pool; // never destroyed: records may outlive static destruction order
    return *p;
}

std::size_t rounded(std::size_t size) { return (size + kAlign - 1) / kAlign * kAlign; }

} // namespace

void* allocate(std::size_t size) {
    if (!BEAMCTL_RECORD_POOL) return ::operator new(size);
    const std::size_t n = rounded(size);
    Pool& p = pool();
    std::lock_guard lock(p.mu);
    SizeClass& c = p.classes[n];
    if (c.free) {
        Node* r = c.free;
        c.free = r->next;
        return r;
    }
    if (c.left < n) {
        std::size_t bytes = std::max(kBlockBytes / n, kMinPerBlock) * n;
        c.next = static_cast<char*>(::operator new(bytes));
        c.left = bytes;
        p.blocks.push_back(c.next);
    }
    void* r = c.next;
    c.next += n;
    c.left -= n;
    return r;
}

void deallocate(void* ptr, std::size_t size) {
    if (!ptr) return;
    if (!BEAMCTL_RECORD_POOL) return ::operator delete(ptr);
    Pool& p = pool();
    std::lock_guard lock(p.mu);
    SizeClass& c = p.classes[rounded(size)];
    c.free = new (ptr) Node{c.free};
}

} // namespace beamctl::pv::record_pool
