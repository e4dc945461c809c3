#include "scanner/ring.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cstring>

namespace beamctl::scanner {

namespace {
constexpr std::size_t kAlign = 64;

uint32_t stride_of(uint32_t data_bytes) {
    std::size_t s = sizeof(SlotHeader) + data_bytes;
    return uint32_t((s + kAlign - 1) / kAlign * kAlign);
}

std::atomic_ref<uint64_t> atomic(uint64_t& v) { return std::atomic_ref<uint64_t>(v); }
// Loads from a read-only mapping: atomic_ref needs a non-const object; only load() is used on it.
std::atomic_ref<uint64_t> atomic(const uint64_t& v) { return std::atomic_ref<uint64_t>(const_cast<uint64_t&>(v)); }
} // namespace

std::size_t ring_bytes(uint32_t depth, uint32_t data_bytes) noexcept {
    return sizeof(RingHeader) + std::size_t(depth) * stride_of(data_bytes);
}

RingWriter::RingWriter(void* mem, std::size_t bytes, uint32_t depth, uint32_t data_bytes, uint64_t layout_hash, uint64_t instance)
    : mem_(static_cast<uint8_t*>(mem)), h_(static_cast<RingHeader*>(mem)), depth_(depth), stride_(stride_of(data_bytes)),
      data_bytes_(data_bytes) {
    if (depth < 2 || (depth & (depth - 1)) != 0) throw Error(SB() << "cycle ring: depth " << depth << " should be a power of two >= 2");
    if (bytes < ring_bytes(depth, data_bytes))
        throw Error(SB() << "cycle ring: " << bytes << " bytes, " << ring_bytes(depth, data_bytes) << " needed");
    if (reinterpret_cast<uintptr_t>(mem) % kAlign != 0) throw Error("cycle ring: memory not 64-byte aligned");
    std::memset(mem_, 0, ring_bytes(depth, data_bytes));
    h_->version = 1;
    h_->depth = depth;
    h_->slot_stride = stride_;
    h_->data_bytes = data_bytes;
    h_->layout_hash = layout_hash;
    h_->instance = instance;
    atomic(h_->head).store(0, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    std::atomic_ref<uint32_t>(h_->magic).store(kRingMagic, std::memory_order_release); // last: the ring is ready
}

void RingWriter::publish(uint64_t cycle, uint64_t t_ns, uint64_t publish_ns, uint32_t flags, const uint8_t* data,
                         uint32_t n) noexcept {
    const uint64_t k = atomic(h_->head).load(std::memory_order_relaxed); // only this thread writes it
    SlotHeader* s = reinterpret_cast<SlotHeader*>(mem_ + sizeof(RingHeader) + std::size_t(k & (depth_ - 1)) * stride_);
    atomic(s->seq).store(2 * k + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release); // seq odd before any byte of the slot changes
    n = std::min(n, data_bytes_);
    s->cycle = cycle;
    s->t_ns = t_ns;
    s->publish_ns = publish_ns;
    s->flags = flags;
    s->data_bytes = n;
    if (n) std::memcpy(reinterpret_cast<uint8_t*>(s + 1), data, n);
    atomic(s->seq).store(2 * k + 2, std::memory_order_release);
    atomic(h_->head).store(k + 1, std::memory_order_release);
    std::atomic_ref<uint32_t>(h_->tick).fetch_add(1, std::memory_order_seq_cst);
}

uint64_t RingWriter::published() const noexcept { return atomic(h_->head).load(std::memory_order_relaxed); }

RingReader::RingReader(const void* mem, std::size_t bytes)
    : mem_(static_cast<const uint8_t*>(mem)), h_(static_cast<const RingHeader*>(mem)) {
    if (bytes < sizeof(RingHeader)) throw Error(SB() << "cycle ring: " << bytes << " bytes, no room for its header");
    if (std::atomic_ref<uint32_t>(const_cast<uint32_t&>(h_->magic)).load(std::memory_order_acquire) != kRingMagic)
        throw Error("cycle ring: not a ring (no BCSR magic)");
    if (h_->version != 1) throw Error(SB() << "cycle ring: version " << h_->version << " (this side reads 1)");
    depth_ = h_->depth, stride_ = h_->slot_stride, data_bytes_ = h_->data_bytes;
    if (depth_ < 2 || (depth_ & (depth_ - 1)) != 0 || stride_ != stride_of(data_bytes_) || bytes < ring_bytes(depth_, data_bytes_))
        throw Error(SB() << "cycle ring: inconsistent header (depth " << depth_ << ", stride " << stride_ << ", data "
                         << data_bytes_ << " bytes, " << bytes << " bytes mapped)");
    next_ = atomic(h_->head).load(std::memory_order_acquire);
}

uint64_t RingReader::layout_hash() const noexcept { return h_->layout_hash; }
uint64_t RingReader::instance() const noexcept { return h_->instance; }

bool RingReader::pending() const noexcept { return atomic(h_->head).load(std::memory_order_acquire) > next_; }

uint64_t RingReader::peek_publish_ns() const noexcept {
    const uint64_t head = atomic(h_->head).load(std::memory_order_acquire);
    if (next_ >= head) return 0;
    const uint64_t k = head - next_ > depth_ ? head - depth_ : next_;
    const SlotHeader* s = reinterpret_cast<const SlotHeader*>(mem_ + sizeof(RingHeader) + std::size_t(k & (depth_ - 1)) * stride_);
    const uint64_t s1 = atomic(s->seq).load(std::memory_order_acquire);
    const uint64_t t = s->publish_ns;
    std::atomic_thread_fence(std::memory_order_acquire);
    return s1 == 2 * k + 2 && atomic(s->seq).load(std::memory_order_relaxed) == s1 ? t : 0;
}

uint32_t RingReader::tick() const noexcept {
    return std::atomic_ref<uint32_t>(const_cast<uint32_t&>(h_->tick)).load(std::memory_order_seq_cst);
}

RingReader::Result RingReader::read(CycleSlot& slot, uint8_t* data) noexcept {
    for (;;) {
        const uint64_t head = atomic(h_->head).load(std::memory_order_acquire);
        if (next_ >= head) return Result::Empty;
        if (head - next_ > depth_) { // lapped: the oldest ones are gone
            lost_ += head - depth_ - next_;
            next_ = head - depth_;
        }
        const SlotHeader* s =
            reinterpret_cast<const SlotHeader*>(mem_ + sizeof(RingHeader) + std::size_t(next_ & (depth_ - 1)) * stride_);
        const uint64_t want = 2 * next_ + 2;
        const uint64_t s1 = atomic(s->seq).load(std::memory_order_acquire);
        if (s1 != want) { // already overwritten by a later cycle (or being overwritten)
            ++lost_;
            ++next_;
            continue;
        }
        slot.cycle = s->cycle;
        slot.t_ns = s->t_ns;
        slot.publish_ns = s->publish_ns;
        slot.flags = s->flags;
        slot.data_bytes = std::min(s->data_bytes, data_bytes_);
        if (slot.data_bytes) std::memcpy(data, reinterpret_cast<const uint8_t*>(s + 1), slot.data_bytes);
        std::atomic_thread_fence(std::memory_order_acquire); // the copy before the second look
        if (atomic(s->seq).load(std::memory_order_relaxed) != s1) { // the writer came round mid-copy
            ++lost_;
            ++next_;
            continue;
        }
        ++next_;
        return Result::Cycle;
    }
}

} // namespace beamctl::scanner
