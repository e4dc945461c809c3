// The cycle ring between the bus scanner and one client: a one-writer, one-reader ring of cycle
// slots in memory both processes map (a memfd the scanner passes with SCM_RIGHTS). The scanner
// writes every cycle's slot and never waits for the reader; the reader takes the cycles in order
// and learns exactly how many it lost when it fell behind by more than the ring holds.
//
// Each slot is a seqlock: seq = 2c+1 while cycle c is being written, 2c+2 once complete. A reader
// that the writer laps in the middle of a copy sees seq change and counts that cycle as lost
// instead of using torn data. `head` is the number of cycles published. Layout (little-endian,
// fixed, checked by static_assert): a 64-byte header, then `depth` slots of a 48-byte slot header
// and `data_bytes` of data each, every slot 64-byte aligned.
// Threading: RingWriter on the writer's thread, RingReader on the reader's; no locks, no system
// calls, no allocation (publish and read are RT-safe).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

namespace beamctl::scanner {

struct RingHeader {
    uint32_t magic;        // "BCSR"
    uint16_t version;      // 1
    uint16_t reserved;
    uint32_t depth;        // slots (a power of two)
    uint32_t slot_stride;  // [bytes] from one slot to the next
    uint32_t data_bytes;   // [bytes] of data per slot
    uint32_t tick;         // futex word: +1 after every publish (atomic; the reader sleeps on it)
    uint64_t layout_hash;  // the client's layout (Attached::layout_hash)
    uint64_t instance;     // the scanner's instance (Welcome::instance)
    uint64_t head;         // cycles published (atomic)
    uint64_t reserved3[2];
};
static_assert(sizeof(RingHeader) == 64);

struct SlotHeader {
    uint64_t seq;        // seqlock (atomic): 2c+1 writing cycle c, 2c+2 complete
    uint64_t cycle;      // the bus cycle number
    uint64_t t_ns;       // the cycle's scheduled time (CLOCK_MONOTONIC) [ns]
    uint64_t publish_ns; // when the scanner published it [ns]
    uint32_t flags;      // kLinkUp | kWkcOk | ...
    uint32_t data_bytes; // valid bytes of data
    uint64_t reserved;
};
static_assert(sizeof(SlotHeader) == 48);

constexpr uint32_t kRingMagic = 0x52534342; // "BCSR" in memory order
constexpr uint32_t kLinkUp = 1, kWkcOk = 2;

// Bytes of a ring of `depth` slots of `data_bytes` each (what the memfd must hold).
std::size_t ring_bytes(uint32_t depth, uint32_t data_bytes) noexcept;

class RingWriter {
public:
    // Lays the ring out in `mem` (ring_bytes(depth, data_bytes) of them, zeroed or not); depth a
    // power of two >= 2. Throws Error for a bad size.
    RingWriter(void* mem, std::size_t bytes, uint32_t depth, uint32_t data_bytes, uint64_t layout_hash, uint64_t instance);
    // Publishes cycle `cycle` (cycles must increase by one per call: the ring counts them): its
    // `n` bytes of data (at most data_bytes), times and flags.
    void publish(uint64_t cycle, uint64_t t_ns, uint64_t publish_ns, uint32_t flags, const uint8_t* data, uint32_t n) noexcept;
    uint64_t published() const noexcept;
    // The futex word publish() bumps: the scanner wakes a sleeping reader on it (futex_wake).
    const uint32_t* tick_word() const noexcept { return &h_->tick; }

private:
    uint8_t* mem_;
    RingHeader* h_;
    uint32_t depth_, stride_, data_bytes_;
};

struct CycleSlot {
    uint64_t cycle = 0, t_ns = 0, publish_ns = 0;
    uint32_t flags = 0, data_bytes = 0;
};

class RingReader {
public:
    // Checks the ring in `mem` (magic, version, sizes against `bytes`); throws Error naming what is
    // wrong. Starts at the newest cycle published (earlier ones are not the reader's).
    RingReader(const void* mem, std::size_t bytes);
    enum class Result { Cycle, Empty };
    // The next cycle in order into `slot` and `data` (capacity data_bytes()), or Empty when the
    // writer has published nothing newer. Cycles the writer overwrote before they were read are
    // skipped and counted in lost().
    Result read(CycleSlot& slot, uint8_t* data) noexcept;
    uint64_t lost() const noexcept { return lost_; }
    uint64_t next() const noexcept { return next_; } // the index of the next cycle to read
    uint32_t data_bytes() const noexcept { return data_bytes_; }
    uint64_t layout_hash() const noexcept;
    uint64_t instance() const noexcept;
    // Whether a cycle newer than the last one read has been published (acquire).
    bool pending() const noexcept;
    // When the next cycle to read was published [ns, CLOCK_MONOTONIC]; 0 if none or it is being
    // overwritten (a hint for latency figures, not data).
    uint64_t peek_publish_ns() const noexcept;
    // The futex word to sleep on (futex_wait_until with its current value, read before pending()).
    const uint32_t* tick_word() const noexcept { return &h_->tick; }
    uint32_t tick() const noexcept;

private:
    const uint8_t* mem_;
    const RingHeader* h_;
    uint32_t depth_, stride_, data_bytes_;
    uint64_t next_ = 0, lost_ = 0;
};

} // namespace beamctl::scanner
