#include "daq/capture.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <limits>

namespace beamctl::daq {

const char* to_string(CaptureMode m) noexcept {
    switch (m) {
    case CaptureMode::Value: return "Value";
    case CaptureMode::Diff: return "Diff";
    case CaptureMode::Sum: return "Sum";
    case CaptureMode::Min: return "Min";
    case CaptureMode::Max: return "Max";
    }
    return "?";
}

bool parse_capture_mode(std::string_view s, CaptureMode& out) noexcept {
    static const CaptureMode all[] = {CaptureMode::Value, CaptureMode::Diff, CaptureMode::Sum, CaptureMode::Min, CaptureMode::Max};
    for (CaptureMode m : all) {
        std::string_view n = to_string(m);
        if (n.size() == s.size() && std::equal(n.begin(), n.end(), s.begin(), [](char a, char b) {
                return std::tolower(static_cast<unsigned char>(a)) == std::tolower(static_cast<unsigned char>(b));
            })) {
            out = m;
            return true;
        }
    }
    return false;
}

CaptureRing::CaptureRing(std::size_t rows, std::size_t columns)
    : rows_(std::max<std::size_t>(rows, 1) + 1), cols_(columns), heads_(new RowHeader[rows_]),
      vals_(new double[rows_ * std::max<std::size_t>(columns, 1)]()) {}

bool CaptureRing::push(const RowHeader& h, const double* values) noexcept {
    std::size_t head = head_.load(std::memory_order_relaxed);
    std::size_t next = head + 1 == rows_ ? 0 : head + 1;
    if (next == tail_.load(std::memory_order_acquire)) return false;
    heads_[head] = h;
    if (cols_) std::memcpy(&vals_[head * cols_], values, cols_ * sizeof(double));
    head_.store(next, std::memory_order_release);
    return true;
}

std::size_t CaptureRing::pop(RowHeader* h, double* values, std::size_t max) noexcept {
    std::size_t tail = tail_.load(std::memory_order_relaxed);
    const std::size_t head = head_.load(std::memory_order_acquire);
    std::size_t n = 0;
    while (tail != head && n < max) {
        h[n] = heads_[tail];
        if (cols_) std::memcpy(&values[n * cols_], &vals_[tail * cols_], cols_ * sizeof(double));
        ++n;
        tail = tail + 1 == rows_ ? 0 : tail + 1;
    }
    tail_.store(tail, std::memory_order_release);
    return n;
}

std::size_t CaptureRing::size() const noexcept {
    std::size_t h = head_.load(std::memory_order_acquire), t = tail_.load(std::memory_order_acquire);
    return h >= t ? h - t : h + rows_ - t;
}

Capture::Capture(std::size_t fields, std::vector<Column> columns, std::size_t ring_rows)
    : fields_(fields), cols_(std::move(columns)), ring_(ring_rows, cols_.size()), sum_(cols_.size()), min_(cols_.size()),
      max_(cols_.size()), last_(cols_.size()), row_(cols_.size()) {}

void Capture::reset_accumulators() noexcept {
    for (std::size_t c = 0; c < cols_.size(); ++c) {
        sum_[c] = 0;
        min_[c] = std::numeric_limits<double>::infinity();
        max_[c] = -std::numeric_limits<double>::infinity();
    }
    gated_ = 0;
}

void Capture::sample(uint64_t cycle, uint64_t t_ns, const double* in, bool gate, bool trigger, uint64_t trigger_t_ns) noexcept {
    (void)t_ns;
    // An arm first, then a disarm: both in one cycle make an empty capture that has ended.
    const uint64_t arm = arm_req_.load(std::memory_order_acquire);
    if (arm > capture_) { // a new capture: counters start over, Diff from the values at arm
        capture_ = arm;
        armed_ = true;
        pushed_.store(0, std::memory_order_relaxed);
        dropped_.store(0, std::memory_order_relaxed);
        capture_pub_.store(arm, std::memory_order_release);
        armed_pub_.store(true, std::memory_order_release);
        reset_accumulators();
        for (std::size_t c = 0; c < cols_.size(); ++c) last_[c] = in[cols_[c].field];
    }
    const uint64_t disarm = disarm_req_.load(std::memory_order_acquire);
    if (disarm != disarm_seen_) {
        disarm_seen_ = disarm;
        if (armed_) {
            armed_ = false;
            armed_pub_.store(false, std::memory_order_release);
        }
    }
    if (!armed_) return;
    if (gate) {
        ++gated_;
        for (std::size_t c = 0; c < cols_.size(); ++c) {
            const double v = in[cols_[c].field];
            sum_[c] += v;
            min_[c] = std::min(min_[c], v);
            max_[c] = std::max(max_[c], v);
        }
    }
    if (!trigger) return;
    for (std::size_t c = 0; c < cols_.size(); ++c) {
        const double v = in[cols_[c].field];
        switch (cols_[c].mode) {
        case CaptureMode::Value: row_[c] = v; break;
        case CaptureMode::Diff: row_[c] = v - last_[c]; break;
        case CaptureMode::Sum: row_[c] = sum_[c]; break;
        case CaptureMode::Min: row_[c] = gated_ ? min_[c] : std::numeric_limits<double>::quiet_NaN(); break;
        case CaptureMode::Max: row_[c] = gated_ ? max_[c] : std::numeric_limits<double>::quiet_NaN(); break;
        }
        last_[c] = v;
    }
    RowHeader h{cycle, trigger_t_ns, capture_, gated_};
    if (ring_.push(h, row_.data())) {
        pushed_.fetch_add(1, std::memory_order_release);
    } else {
        dropped_.fetch_add(1, std::memory_order_release);
        dropped_total_.fetch_add(1, std::memory_order_release);
    }
    reset_accumulators();
}

} // namespace beamctl::daq
