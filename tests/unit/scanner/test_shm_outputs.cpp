// Shared memory of the scanner (src/scanner/shm.hpp) and the output path (src/scanner/outputs.hpp):
// sealed memfds a client cannot resize or (for the ring) map writable, file descriptors over a
// UNIX socket, the futex wake-up, the output block's seqlock, and the claim masks.
#include "core/error.hpp"
#include "scanner/outputs.hpp"
#include "scanner/shm.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <thread>
#include <time.h>
#include <unistd.h>

using namespace beamctl;
using namespace beamctl::scanner;

namespace {
uint64_t mono_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}
} // namespace

TEST(ScannerShm, SealedAgainstResizeAndReadOnlyForTheClient) {
    SharedMemory ring = SharedMemory::create("test-ring", 8192, false);
    ASSERT_TRUE(ring);
    std::memset(ring.data(), 0x5A, 8192); // the scanner's own mapping stays writable
    EXPECT_NE(::ftruncate(ring.fd(), 0), 0) << "shrinking a sealed memfd must fail";
    EXPECT_NE(::ftruncate(ring.fd(), 1 << 20), 0) << "growing a sealed memfd must fail";
    void* w = ::mmap(nullptr, 8192, PROT_READ | PROT_WRITE, MAP_SHARED, ring.fd(), 0);
    EXPECT_EQ(w, MAP_FAILED) << "a new writable mapping of the ring must be refused";
    SharedMemory ro = SharedMemory::map(::dup(ring.fd()), "ring", 4096, false);
    EXPECT_EQ(static_cast<const uint8_t*>(ro.data())[100], 0x5A);
    EXPECT_THROW(SharedMemory::map(::dup(ring.fd()), "ring", 1 << 20, false), Error); // too small

    SharedMemory out = SharedMemory::create("test-out", 4096, true); // the client writes this one
    SharedMemory rw = SharedMemory::map(::dup(out.fd()), "out", 64, true);
    static_cast<uint8_t*>(rw.data())[7] = 9;
    EXPECT_EQ(static_cast<uint8_t*>(out.data())[7], 9);
    EXPECT_NE(::ftruncate(out.fd(), 0), 0);
}

TEST(ScannerShm, MapRefusesAnUnsealedFile) {
    int fd = ::memfd_create("plain", MFD_CLOEXEC);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::ftruncate(fd, 4096), 0);
    try {
        SharedMemory::map(fd, "cycle ring", 64, false);
        FAIL() << "an unsealed memfd was mapped";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("cycle ring: not sealed"), std::string::npos) << e.what();
    }
}

TEST(ScannerShm, FileDescriptorsTravelWithTheirMessage) {
    int sv[2];
    ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv), 0);
    SharedMemory m = SharedMemory::create("fd-pass", 4096, true);
    static_cast<uint8_t*>(m.data())[0] = 42;
    const uint8_t msg[] = {1, 2, 3, 4, 5};
    send_fds(sv[0], msg, sizeof msg, {m.fd()});
    uint8_t buf[16];
    std::vector<int> fds;
    long n = recv_fds(sv[1], buf, sizeof buf, fds);
    ASSERT_EQ(n, 5);
    EXPECT_EQ(std::memcmp(buf, msg, 5), 0);
    ASSERT_EQ(fds.size(), 1u);
    SharedMemory got = SharedMemory::map(fds[0], "passed", 4096, true);
    EXPECT_EQ(static_cast<uint8_t*>(got.data())[0], 42);
    ::close(sv[0]);
    ::close(sv[1]);
}

TEST(ScannerShm, FutexWaitTimesOutAndWakes) {
    SharedMemory m = SharedMemory::create("futex", 4096, true);
    auto* word = static_cast<uint32_t*>(m.data());
    // Nothing changes: the wait ends at its deadline (false).
    EXPECT_FALSE(futex_wait_until(word, 0, mono_ns() + 2'000'000));
    // The word already differs: no sleep at all.
    *word = 1;
    EXPECT_TRUE(futex_wait_until(word, 0, mono_ns() + 5'000'000'000ull));
    // Another thread bumps and wakes: the waiter returns true long before its deadline.
    std::atomic<bool> woke{false};
    std::thread t([&] {
        woke = futex_wait_until(word, 1, mono_ns() + 10'000'000'000ull);
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::atomic_ref<uint32_t>(*word).store(2);
    int n = 0;
    for (int i = 0; i < 1000 && !n; ++i) {
        n = futex_wake(word);
        if (!n) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    t.join();
    EXPECT_TRUE(woke.load());
}

TEST(ScannerOutputs, CommitsTakenOnceNewestWins) {
    std::vector<uint8_t> mem(out_block_bytes(8) + 64);
    void* p = mem.data() + (64 - reinterpret_cast<uintptr_t>(mem.data()) % 64) % 64;
    init_out_block(p, 8);
    OutWriter w(p, out_block_bytes(8));
    OutReader r(p, 8);
    uint8_t dst[8] = {};
    uint64_t cycle = 0, t = 0;
    EXPECT_FALSE(r.take(dst, cycle, t)) << "nothing committed yet";
    uint8_t a[8] = {1, 1, 1, 1, 1, 1, 1, 1}, b[8] = {2, 2, 2, 2, 2, 2, 2, 2};
    w.commit(10, 1000, a);
    w.commit(11, 2000, b);
    ASSERT_TRUE(r.take(dst, cycle, t));
    EXPECT_EQ(cycle, 11u);
    EXPECT_EQ(t, 2000u);
    EXPECT_EQ(dst[3], 2);
    EXPECT_FALSE(r.take(dst, cycle, t)) << "the same commit twice";
    EXPECT_EQ(r.taken(), 1u);
    w.report_drops(5);
    EXPECT_EQ(r.drops(), 5u);
    w.set_waiting(true);
    EXPECT_TRUE(r.waiting());
}

TEST(ScannerOutputs, ACommitInProgressIsNotTaken) {
    std::vector<uint8_t> mem(out_block_bytes(4));
    init_out_block(mem.data(), 4);
    auto* h = reinterpret_cast<OutHeader*>(mem.data());
    OutReader r(mem.data(), 4);
    h->seq = 3; // odd: the client is in the middle of a commit
    uint8_t dst[4];
    uint64_t c, t;
    EXPECT_FALSE(r.take(dst, c, t));
    EXPECT_EQ(r.torn(), 1u);
    h->seq = 4;
    EXPECT_TRUE(r.take(dst, c, t));
}

TEST(ScannerOutputs, NotAnOutputBlockIsRefused) {
    std::vector<uint8_t> mem(out_block_bytes(1000), 0);
    EXPECT_THROW(OutWriter(mem.data(), mem.size()), Error);
    init_out_block(mem.data(), 1000);
    EXPECT_THROW(OutWriter(mem.data(), 256), Error); // the block says more than is mapped
    EXPECT_NO_THROW(OutWriter(mem.data(), mem.size()));
}

TEST(ScannerOutputs, ByteMergeCopiesOnlyTheMaskedBits) {
    // Bytes 1-2 whole, bit 0 and bit 7 of byte 4.
    std::vector<uint8_t> mask = {0, 0xFF, 0xFF, 0, 0x81, 0};
    ByteMerge m(mask);
    EXPECT_EQ(m.bytes(), 3u);
    uint8_t dst[6] = {0x11, 0x22, 0x33, 0x44, 0x55, 0x66};
    const uint8_t src[6] = {0xA0, 0xA1, 0xA2, 0xA3, 0xFF, 0xA5};
    m.apply(dst, src);
    const uint8_t want[6] = {0x11, 0xA1, 0xA2, 0x44, 0xD5, 0x66};
    EXPECT_EQ(std::memcmp(dst, want, 6), 0);
    m.clear(dst);
    const uint8_t cleared[6] = {0x11, 0, 0, 0x44, 0x54, 0x66};
    EXPECT_EQ(std::memcmp(dst, cleared, 6), 0);
    EXPECT_TRUE(ByteMerge(std::vector<uint8_t>(4, 0)).empty());
}

TEST(ScannerOutputs, TheScannerWaitsForAnAnswerUntilItsDeadline) {
    SharedMemory m = SharedMemory::create("answer", out_block_bytes(8), true);
    init_out_block(m.data(), 8);
    OutWriter w(m.data(), m.size());
    OutReader r(m.data(), 8);
    uint8_t d[8] = {};
    // No answer: false at the deadline.
    uint64_t t0 = mono_ns();
    EXPECT_FALSE(r.wait_answer(5, t0 + 5'000'000));
    EXPECT_GE(mono_ns() - t0, 4'000'000u);
    // An answer to an older cycle is not one.
    w.commit(4, 0, d);
    EXPECT_FALSE(r.wait_answer(5, mono_ns() + 2'000'000));
    // The client answers from another thread while the scanner sleeps: woken, true, well before the deadline.
    std::thread t([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        w.commit(5, 0, d);
    });
    t0 = mono_ns();
    EXPECT_TRUE(r.wait_answer(5, t0 + 10'000'000'000ull));
    EXPECT_LT(mono_ns() - t0, 5'000'000'000ull);
    t.join();
    EXPECT_TRUE(r.wait_answer(5, 0)) << "already answered: no wait";
}
