// A client's outputs on their way to the bus frame, and the byte masks that keep every client to
// what it claimed.
//   - OutBlock: one per client, in a memfd the scanner creates and the client maps writable: the
//     client commits its output bytes once per cycle under a seqlock; the scanner's gather stage
//     takes the newest complete commit and never waits (a commit caught in the middle is left for
//     the next cycle). Layout: a 64-byte header, then `data_bytes` (the bus's output bytes).
//     The scanner trusts nothing in it but the bytes it copies, and copies only the claimed ones.
//   - ByteMerge: "copy these bits of src into dst", from a per-byte mask, as runs of whole bytes
//     plus single bytes with a partial mask (bit-level claims such as one output of an EL2008).
// Threading: OutWriter on the client's RT thread, OutReader on the scanner's RT thread; no locks,
// no system calls, no allocation after construction.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace beamctl::scanner {

struct OutHeader {
    uint32_t magic;      // "BCSO"
    uint16_t version;    // 1
    uint16_t reserved;
    uint32_t data_bytes; // [bytes] after the header
    uint32_t waiting;    // the client is asleep on its ring's tick word: the scanner wakes it (atomic)
    uint64_t seq;        // seqlock (atomic): odd while a commit is written
    uint64_t cycle;      // the bus cycle whose inputs the committed outputs answer
    uint64_t commit_ns;  // when the client committed them (CLOCK_MONOTONIC) [ns]
    uint64_t drops;      // cycles the client's ring lost, as the client reports them (for `status`)
    uint32_t commits;    // futex word: +1 after every commit (the scanner may sleep on it)
    uint32_t scanner_waiting; // the scanner is asleep on `commits`: the client wakes it (atomic)
    uint64_t reserved2;
};
static_assert(sizeof(OutHeader) == 64);
constexpr uint32_t kOutMagic = 0x4F534342; // "BCSO" in memory order

inline std::size_t out_block_bytes(uint32_t data_bytes) { return sizeof(OutHeader) + data_bytes; }
// Scanner: lays out an empty block (no commit yet).
void init_out_block(void* mem, uint32_t data_bytes) noexcept;

class OutWriter {
public:
    OutWriter(void* mem, std::size_t bytes); // throws Error for a block that is not one
    // data_bytes() of them; wakes the scanner if it waits for this commit (one system call then).
    void commit(uint64_t cycle, uint64_t now_ns, const uint8_t* data) noexcept;
    void set_waiting(bool w) noexcept;
    void report_drops(uint64_t n) noexcept;
    uint32_t data_bytes() const noexcept { return n_; }

private:
    OutHeader* h_;
    uint8_t* data_;
    uint32_t n_;
};

class OutReader {
public:
    OutReader(const void* mem, uint32_t data_bytes) noexcept; // the scanner's own sizes
    // The newest complete commit into `dst` (data_bytes), if there is one not taken before.
    // False: nothing new, or a commit in progress (torn() counts those).
    bool take(uint8_t* dst, uint64_t& cycle, uint64_t& commit_ns) noexcept;
    bool waiting() const noexcept;
    uint64_t drops() const noexcept; // what the client reports (not trusted for anything else)
    // The scanner waiting for this client's answer to `cycle`, until `deadline_ns`
    // (CLOCK_MONOTONIC): true once its newest complete commit answers `cycle` (or a later one).
    bool wait_answer(uint64_t cycle, uint64_t deadline_ns) noexcept;
    uint64_t torn() const noexcept { return torn_; }
    uint64_t taken() const noexcept { return taken_; }

private:
    const OutHeader* h_;
    const uint8_t* data_;
    uint32_t n_;
    uint64_t last_seq_ = 0, torn_ = 0, taken_ = 0;
};

class ByteMerge {
public:
    ByteMerge() = default;
    // mask[i]: the bits of byte (offset + i) to copy.
    ByteMerge(const std::vector<uint8_t>& mask, uint32_t offset = 0);
    // dst[b] = (dst[b] & ~m) | (src[b] & m) over the mask; src and dst indexed alike.
    void apply(uint8_t* dst, const uint8_t* src) const noexcept;
    // dst[b] &= ~m over the mask (claimed outputs to zero).
    void clear(uint8_t* dst) const noexcept;
    std::size_t bytes() const noexcept; // bytes touched
    bool empty() const noexcept { return runs_.empty() && partial_.empty(); }

private:
    struct Run {
        uint32_t off, len;
    };
    struct Partial {
        uint32_t off;
        uint8_t mask;
    };
    std::vector<Run> runs_;
    std::vector<Partial> partial_;
};

} // namespace beamctl::scanner
