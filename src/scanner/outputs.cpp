#include "scanner/outputs.hpp"

#include "core/error.hpp"
#include "scanner/shm.hpp"

#include <atomic>
#include <cstring>

namespace beamctl::scanner {

namespace {
std::atomic_ref<uint64_t> atomic(uint64_t& v) { return std::atomic_ref<uint64_t>(v); }
std::atomic_ref<uint64_t> atomic(const uint64_t& v) { return std::atomic_ref<uint64_t>(const_cast<uint64_t&>(v)); }
std::atomic_ref<uint32_t> atomic32(const uint32_t& v) { return std::atomic_ref<uint32_t>(const_cast<uint32_t&>(v)); }
} // namespace

void init_out_block(void* mem, uint32_t data_bytes) noexcept {
    std::memset(mem, 0, out_block_bytes(data_bytes));
    auto* h = static_cast<OutHeader*>(mem);
    h->version = 1;
    h->data_bytes = data_bytes;
    atomic32(h->magic).store(kOutMagic, std::memory_order_release);
}

OutWriter::OutWriter(void* mem, std::size_t bytes) : h_(static_cast<OutHeader*>(mem)) {
    if (bytes < sizeof(OutHeader) || atomic32(h_->magic).load(std::memory_order_acquire) != kOutMagic || h_->version != 1)
        throw Error("output block: not an output block (no BCSO magic, version 1)");
    n_ = h_->data_bytes;
    if (bytes < out_block_bytes(n_)) throw Error(SB() << "output block: " << bytes << " bytes mapped, " << out_block_bytes(n_) << " needed");
    data_ = static_cast<uint8_t*>(mem) + sizeof(OutHeader);
}

void OutWriter::commit(uint64_t cycle, uint64_t now_ns, const uint8_t* data) noexcept {
    const uint64_t s = atomic(h_->seq).load(std::memory_order_relaxed) | 1; // only this side writes it
    atomic(h_->seq).store(s, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    std::memcpy(data_, data, n_);
    h_->cycle = cycle;
    h_->commit_ns = now_ns;
    atomic(h_->seq).store(s + 1, std::memory_order_release);
    atomic32(h_->commits).fetch_add(1, std::memory_order_seq_cst);
    if (atomic32(h_->scanner_waiting).load(std::memory_order_seq_cst)) futex_wake(&h_->commits);
}

void OutWriter::set_waiting(bool w) noexcept { atomic32(h_->waiting).store(w ? 1 : 0, std::memory_order_seq_cst); }

OutReader::OutReader(const void* mem, uint32_t data_bytes) noexcept
    : h_(static_cast<const OutHeader*>(mem)), data_(static_cast<const uint8_t*>(mem) + sizeof(OutHeader)), n_(data_bytes) {}

bool OutReader::take(uint8_t* dst, uint64_t& cycle, uint64_t& commit_ns) noexcept {
    const uint64_t s1 = atomic(h_->seq).load(std::memory_order_acquire);
    if (s1 == last_seq_) return false;
    if (s1 & 1) {
        ++torn_;
        return false;
    }
    std::memcpy(dst, data_, n_);
    cycle = h_->cycle;
    commit_ns = h_->commit_ns;
    std::atomic_thread_fence(std::memory_order_acquire);
    if (atomic(h_->seq).load(std::memory_order_relaxed) != s1) {
        ++torn_;
        return false;
    }
    last_seq_ = s1;
    ++taken_;
    return true;
}

void OutWriter::report_drops(uint64_t n) noexcept { atomic(h_->drops).store(n, std::memory_order_relaxed); }

uint64_t OutReader::drops() const noexcept { return atomic(h_->drops).load(std::memory_order_relaxed); }

bool OutReader::wait_answer(uint64_t cycle, uint64_t deadline_ns) noexcept {
    auto answered = [&] {
        const uint64_t s1 = atomic(h_->seq).load(std::memory_order_acquire);
        const uint64_t c = atomic(const_cast<OutHeader*>(h_)->cycle).load(std::memory_order_relaxed);
        return !(s1 & 1) && s1 != 0 && c >= cycle;
    };
    auto* hw = const_cast<OutHeader*>(h_);
    for (;;) {
        if (answered()) return true;
        const uint32_t w = atomic32(h_->commits).load(std::memory_order_seq_cst);
        atomic32(hw->scanner_waiting).store(1, std::memory_order_seq_cst);
        bool ok = answered();
        if (!ok && !futex_wait_until(&h_->commits, w, deadline_ns)) {
            atomic32(hw->scanner_waiting).store(0, std::memory_order_relaxed);
            return answered();
        }
        atomic32(hw->scanner_waiting).store(0, std::memory_order_relaxed);
        if (ok) return true;
    }
}

bool OutReader::waiting() const noexcept { return atomic32(h_->waiting).load(std::memory_order_seq_cst) != 0; }

ByteMerge::ByteMerge(const std::vector<uint8_t>& mask, uint32_t offset) {
    for (uint32_t i = 0; i < mask.size();) {
        if (mask[i] == 0) {
            ++i;
        } else if (mask[i] != 0xFF) {
            partial_.push_back({offset + i, mask[i]});
            ++i;
        } else {
            uint32_t j = i;
            while (j < mask.size() && mask[j] == 0xFF) ++j;
            runs_.push_back({offset + i, j - i});
            i = j;
        }
    }
}

void ByteMerge::apply(uint8_t* dst, const uint8_t* src) const noexcept {
    for (const Run& r : runs_) std::memcpy(dst + r.off, src + r.off, r.len);
    for (const Partial& p : partial_) dst[p.off] = uint8_t((dst[p.off] & ~p.mask) | (src[p.off] & p.mask));
}

void ByteMerge::clear(uint8_t* dst) const noexcept {
    for (const Run& r : runs_) std::memset(dst + r.off, 0, r.len);
    for (const Partial& p : partial_) dst[p.off] = uint8_t(dst[p.off] & ~p.mask);
}

std::size_t ByteMerge::bytes() const noexcept {
    std::size_t n = partial_.size();
    for (const Run& r : runs_) n += r.len;
    return n;
}

} // namespace beamctl::scanner
