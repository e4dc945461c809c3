#include "daq/data_storage.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace beamctl::daq {

const char* to_string(BufferType t) noexcept {
    switch (t) {
    case BufferType::Normal: return "normal";
    case BufferType::Ring: return "ring";
    case BufferType::Fifo: return "fifo";
    }
    return "?";
}

bool parse_buffer_type(std::string_view s, BufferType& out) noexcept {
    if (s == "normal" || s == "0") out = BufferType::Normal;
    else if (s == "ring" || s == "1") out = BufferType::Ring;
    else if (s == "fifo" || s == "2") out = BufferType::Fifo;
    else return false;
    return true;
}

DataStorage::DataStorage(int id, std::size_t size, BufferType type, std::size_t capacity, uint64_t sample_period_cycles)
    : id_(id), type_(type), buf_(std::max(std::max<std::size_t>(size, 1), capacity), 0.0), size_(std::max<std::size_t>(size, 1)),
      period_(std::max<uint64_t>(sample_period_cycles, 1)), incoming_(buf_.size(), 0.0) {
    snapshots_.init([&](Snapshot& s) { s.data.assign(buf_.size(), 0.0); });
}

uint32_t DataStorage::append(const double* v, std::size_t n) noexcept {
    if (n > size_) return error_ = ds_error::kBlockTooLarge;
    if (n == 0) return 0;
    double* b = buf_.data();
    switch (type_) {
    case BufferType::Normal: { // fill, then discard
        std::size_t k = std::min(n, size_ - std::min(index_, size_));
        std::memcpy(b + index_, v, k * sizeof(double));
        index_ += k;
        count_ = std::min(size_, count_ + k);
        break;
    }
    case BufferType::Ring: { // fill to the end, the rest from the start
        std::size_t k = std::min(n, size_ - std::min(index_, size_));
        std::memcpy(b + index_, v, k * sizeof(double));
        index_ += k;
        if (k < n) {
            std::memcpy(b, v + k, (n - k) * sizeof(double));
            index_ = n - k;
        }
        count_ = std::min(size_, count_ + n);
        break;
    }
    case BufferType::Fifo: // shift left, newest at the end; the index is not used
        if (n < size_) std::memmove(b, b + n, (size_ - n) * sizeof(double));
        std::memcpy(b + (size_ - n), v, n * sizeof(double));
        count_ = std::min(size_, count_ + n);
        break;
    }
    appended_ += n;
    dirty_ = true;
    if (tap_ && tap_capture_)
        for (std::size_t i = 0; i < n; ++i)
            if (!tap_->push({tap_cycle_, tap_t_ns_, tap_capture_, v[i]})) tap_dropped_.fetch_add(1, std::memory_order_relaxed);
    return 0;
}

void DataStorage::enable_tap(std::size_t capacity) {
    tap_ = std::make_unique<SpscQueue<TapEntry>>(std::max<std::size_t>(capacity, 1));
}

void DataStorage::clear() noexcept {
    std::fill(buf_.begin(), buf_.begin() + std::ptrdiff_t(size_), 0.0);
    index_ = count_ = 0;
    dirty_ = true;
}

uint32_t DataStorage::set_index(double i) noexcept {
    if (!(i >= 0 && i <= double(size_))) return error_ = ds_error::kPositionOutOfRange;
    index_ = std::size_t(i);
    dirty_ = true;
    return 0;
}

uint32_t DataStorage::get(double i, double& v) noexcept {
    if (!(i >= 0 && i < double(size_))) return error_ = ds_error::kPositionOutOfRange;
    v = buf_[std::size_t(i)];
    return 0;
}

uint32_t DataStorage::set(double i, double v) noexcept {
    if (!(i >= 0 && i < double(size_))) return error_ = ds_error::kPositionOutOfRange;
    buf_[std::size_t(i)] = v;
    dirty_ = true;
    return 0;
}

uint32_t DataStorage::resize(double n) noexcept {
    if (!(n >= 1 && n <= double(buf_.size()))) return error_ = ds_error::kSizeOverCapacity;
    size_ = std::size_t(n);
    count_ = 0;
    index_ = std::min(index_, size_);
    dirty_ = true;
    return 0;
}

double DataStorage::average() const noexcept {
    if (count_ == 0) return 0;
    std::size_t first = type_ == BufferType::Fifo ? size_ - count_ : 0;
    double sum = 0;
    for (std::size_t i = first; i < first + count_; ++i) sum += buf_[i];
    return sum / double(count_);
}

double DataStorage::minimum() const noexcept {
    if (count_ == 0) return 0;
    std::size_t first = type_ == BufferType::Fifo ? size_ - count_ : 0;
    return *std::min_element(buf_.begin() + std::ptrdiff_t(first), buf_.begin() + std::ptrdiff_t(first + count_));
}

double DataStorage::maximum() const noexcept {
    if (count_ == 0) return 0;
    std::size_t first = type_ == BufferType::Fifo ? size_ - count_ : 0;
    return *std::max_element(buf_.begin() + std::ptrdiff_t(first), buf_.begin() + std::ptrdiff_t(first + count_));
}

void DataStorage::publish(uint64_t cycle) noexcept {
    Request r;
    while (requests_.pop(r)) {
        switch (r.op) {
        case Request::Op::Clear: clear(); break;
        case Request::Op::Index: (void)set_index(double(r.index)); break;
        case Request::Op::Data:
            if (incoming_busy_.load(std::memory_order_acquire)) {
                index_ = 0;
                (void)append(incoming_.data(), std::min(incoming_n_, size_));
                incoming_busy_.store(false, std::memory_order_release);
            }
            break;
        }
        push_ = true; // an operator's request shows at once
    }
    if (push_ || !published_once_ || (dirty_ && cycle >= last_publish_ + period_)) publish_now(cycle);
}

void DataStorage::publish_now(uint64_t cycle) noexcept {
    Snapshot& s = snapshots_.write_buffer();
    std::memcpy(s.data.data(), buf_.data(), size_ * sizeof(double));
    s.size = size_;
    s.index = index_;
    s.count = count_;
    s.full = full();
    s.type = type_;
    s.error = error_;
    s.appended = appended_;
    s.version = ++version_;
    snapshots_.publish();
    last_publish_ = cycle;
    dirty_ = push_ = false;
    published_once_ = true;
}

bool DataStorage::request_clear() noexcept { return requests_.push(Request{Request::Op::Clear, 0}); }

bool DataStorage::request_index(std::size_t i) noexcept { return requests_.push(Request{Request::Op::Index, i}); }

bool DataStorage::request_data(const double* v, std::size_t n) noexcept {
    if (incoming_busy_.load(std::memory_order_acquire)) return false;
    n = std::min(n, incoming_.size());
    std::memcpy(incoming_.data(), v, n * sizeof(double));
    incoming_n_ = n;
    incoming_busy_.store(true, std::memory_order_release);
    if (requests_.push(Request{Request::Op::Data, 0})) return true;
    incoming_busy_.store(false, std::memory_order_release);
    return false;
}

} // namespace beamctl::daq
