// The scanner's cycle ring (src/scanner/ring.hpp): in order, never blocking the writer, losses
// counted exactly when the reader falls behind, torn slots never delivered; between threads and
// between processes (a memfd shared across fork, the writer killed mid-stream).
#include "../alloc_counter.hpp"
#include "core/error.hpp"
#include "scanner/ring.hpp"

#include <gtest/gtest.h>

#include <csignal>
#include <cstring>
#include <sys/mman.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

using namespace beamctl;
using namespace beamctl::scanner;

namespace {
struct Mem {
    std::size_t bytes;
    void* p;
    explicit Mem(std::size_t n) : bytes(n), p(std::aligned_alloc(64, (n + 63) / 64 * 64)) {}
    ~Mem() { std::free(p); }
};
std::vector<uint8_t> pattern(uint64_t k, uint32_t n) { return std::vector<uint8_t>(n, uint8_t(k * 7 + 1)); }
} // namespace

TEST(CycleRing, InOrderAndLossesCountedExactly) {
    const uint32_t depth = 8, data = 100;
    Mem m(ring_bytes(depth, data));
    RingWriter w(m.p, m.bytes, depth, data, 0xABCD, 42);
    RingReader r(m.p, m.bytes);
    EXPECT_EQ(r.layout_hash(), 0xABCDu);
    EXPECT_EQ(r.instance(), 42u);
    CycleSlot s;
    std::vector<uint8_t> buf(data);
    EXPECT_EQ(r.read(s, buf.data()), RingReader::Result::Empty);
    for (uint64_t k = 0; k < 5; ++k) {
        auto p = pattern(k, data);
        w.publish(1000 + k, k * 100, k * 100 + 3, kLinkUp, p.data(), data);
        ASSERT_EQ(r.read(s, buf.data()), RingReader::Result::Cycle);
        EXPECT_EQ(s.cycle, 1000 + k);
        EXPECT_EQ(s.t_ns, k * 100);
        EXPECT_EQ(s.flags, kLinkUp);
        EXPECT_EQ(buf, p);
    }
    EXPECT_EQ(r.lost(), 0u);
    // the reader stalls while 20 cycles pass: it gets the last 8, 12 are counted lost
    for (uint64_t k = 5; k < 25; ++k) {
        auto p = pattern(k, data);
        w.publish(1000 + k, 0, 0, 0, p.data(), data);
    }
    std::vector<uint64_t> got;
    while (r.read(s, buf.data()) == RingReader::Result::Cycle) {
        got.push_back(s.cycle);
        EXPECT_EQ(buf, pattern(s.cycle - 1000, data));
    }
    EXPECT_EQ(got, (std::vector<uint64_t>{1017, 1018, 1019, 1020, 1021, 1022, 1023, 1024}));
    EXPECT_EQ(r.lost(), 12u);
    // a reader that attaches late starts at the newest cycle
    RingReader late(m.p, m.bytes);
    EXPECT_EQ(late.read(s, buf.data()), RingReader::Result::Empty);
    // publishing and reading allocate nothing
    auto p = pattern(1, data);
    test::count_allocations(true);
    for (int k = 0; k < 100; ++k) {
        w.publish(2000 + uint64_t(k), 0, 0, 0, p.data(), data);
        (void)r.read(s, buf.data());
    }
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
}

TEST(CycleRing, BadRingsAreRefusedByName) {
    Mem m(ring_bytes(4, 16));
    std::memset(m.p, 0, m.bytes);
    EXPECT_THROW(RingReader(m.p, m.bytes), Error); // no magic
    EXPECT_THROW(RingWriter(m.p, m.bytes, 3, 16, 0, 0), Error); // not a power of two
    EXPECT_THROW(RingWriter(m.p, m.bytes - 1, 4, 16, 0, 0), Error);
    RingWriter w(m.p, m.bytes, 4, 16, 0, 0);
    EXPECT_THROW(RingReader(m.p, m.bytes - 64), Error); // mapped smaller than it says
}

// A fast writer and a slower reader on two threads: every cycle read is whole (its data matches
// its cycle), in order, and read + lost accounts for every cycle published.
TEST(CycleRing, ConcurrentReaderNeverSeesATornSlot) {
    const uint32_t depth = 4, data = 512;
    Mem m(ring_bytes(depth, data));
    RingWriter w(m.p, m.bytes, depth, data, 0, 0);
    RingReader r(m.p, m.bytes);
    const uint64_t total = 200000;
    std::thread writer([&] {
        std::vector<uint8_t> p(data);
        for (uint64_t k = 0; k < total; ++k) {
            std::memset(p.data(), int(uint8_t(k)), data);
            w.publish(k, k, k, 0, p.data(), data);
        }
    });
    uint64_t read = 0, last = 0, bad = 0;
    bool first = true;
    std::vector<uint8_t> buf(data);
    CycleSlot s;
    while (true) {
        if (r.read(s, buf.data()) == RingReader::Result::Cycle) {
            ++read;
            if (!first && s.cycle <= last) ++bad;
            for (uint8_t b : buf)
                if (b != uint8_t(s.cycle)) {
                    ++bad;
                    break;
                }
            last = s.cycle;
            first = false;
        } else if (w.published() == total) {
            break;
        }
    }
    writer.join();
    while (r.read(s, buf.data()) == RingReader::Result::Cycle) ++read;
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(read + r.lost(), total);
    EXPECT_GT(read, 0u);
}

// Across processes: the writer in a child process on a shared mapping; it is SIGKILLed in the
// middle of its stream and the reader just sees no newer cycles.
TEST(CycleRing, AcrossProcessesAndAWriterKilledMidStream) {
    const uint32_t depth = 1024, data = 64;
    const std::size_t bytes = ring_bytes(depth, data);
    void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    ASSERT_NE(p, MAP_FAILED);
    RingWriter cw(p, bytes, depth, data, 7, 8); // the child writes through its copy (the state is in the mapping)
    pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        std::vector<uint8_t> d(data);
        for (uint64_t k = 0;; ++k) {
            std::memset(d.data(), int(uint8_t(k)), data);
            cw.publish(k, 0, 0, 0, d.data(), data);
            if (k % 64 == 0) ::usleep(100);
        }
    }
    RingReader r(p, bytes);
    CycleSlot s;
    std::vector<uint8_t> buf(data);
    uint64_t got = 0, bad = 0;
    while (got < 5000) {
        if (r.read(s, buf.data()) != RingReader::Result::Cycle) continue;
        ++got;
        if (buf[0] != uint8_t(s.cycle) || buf[data - 1] != uint8_t(s.cycle)) ++bad;
    }
    ::kill(child, SIGKILL);
    int st = 0;
    ::waitpid(child, &st, 0);
    while (r.read(s, buf.data()) == RingReader::Result::Cycle) ++got; // what it published before dying
    EXPECT_EQ(r.read(s, buf.data()), RingReader::Result::Empty);
    EXPECT_EQ(bad, 0u);
    EXPECT_GE(got, 5000u);
    ::munmap(p, bytes);
}
