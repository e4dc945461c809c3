// The capture path (ARCHITECTURE.md §3 "Capture ring"): every cycle's values, lossless, out of the
// RT thread. PandA's PCAP semantics (specs/records.md §7): ARM starts a capture, DISARM (or the
// end of the run) ends it; while armed, each cycle's field values are accumulated while the GATE is
// high, and a TRIG edge captures one row: per field the value at the trigger, the difference since
// the previous row, the sum, minimum or maximum over the gated cycles since the previous row, plus
// the cycle number, its time stamp [ns] and the number of gated cycles (PandA's GATE_DURATION).
//
// CaptureRing: a fixed-size single-producer/single-consumer ring of rows (no allocation, no lock):
// the cycle pushes, a writer thread pops. A full ring drops the row and counts it: the cycle never
// waits for a disk.
// Threading: Capture's configure methods before the cycle starts; sample() on the RT thread;
// request_arm()/request_disarm() and the counters from any thread; the ring's pop side on ONE
// writer thread.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::daq {

enum class CaptureMode : uint8_t { Value, Diff, Sum, Min, Max };
const char* to_string(CaptureMode m) noexcept; // "Value", "Diff", ...
// "value", "diff", "sum", "min", "max" (any case); false if it is none of them.
bool parse_capture_mode(std::string_view s, CaptureMode& out) noexcept;

// One captured row as it travels the ring: the header, then `columns` values.
struct RowHeader {
    uint64_t cycle = 0;   // engine cycle of the trigger
    uint64_t t_ns = 0;    // time of the trigger [ns, engine clock]: the cycle's, or the edge's
                          // interpolated time when the trigger says where it fell
    uint64_t capture = 0; // which arm (1, 2, ...) the row belongs to
    uint64_t gated = 0;   // gated cycles accumulated into this row
};

class CaptureRing {
public:
    CaptureRing(std::size_t rows, std::size_t columns);
    std::size_t capacity() const noexcept { return rows_ - 1; }
    std::size_t columns() const noexcept { return cols_; }
    // Producer (RT): false when full.
    bool push(const RowHeader& h, const double* values) noexcept;
    // Consumer: copies up to `max` rows out (headers and values, row-major); returns how many.
    std::size_t pop(RowHeader* h, double* values, std::size_t max) noexcept;
    std::size_t size() const noexcept;

private:
    std::size_t rows_, cols_;
    std::unique_ptr<RowHeader[]> heads_;
    std::unique_ptr<double[]> vals_;
    alignas(64) std::atomic<std::size_t> head_{0};
    alignas(64) std::atomic<std::size_t> tail_{0};
};

class Capture {
public:
    // `columns` = (field, mode) pairs over `fields` input values per cycle; `ring_rows` rows of room.
    struct Column {
        std::size_t field = 0;
        CaptureMode mode = CaptureMode::Value;
    };
    Capture(std::size_t fields, std::vector<Column> columns, std::size_t ring_rows);

    // ---- RT ----------------------------------------------------------------------------------
    // One cycle: applies an arm/disarm request, then (armed) accumulates `in` (fields values) if
    // `gate`, and pushes a row if `trigger`. `trigger_t_ns` is the row's time stamp.
    void sample(uint64_t cycle, uint64_t t_ns, const double* in, bool gate, bool trigger, uint64_t trigger_t_ns) noexcept;

    // ---- any thread --------------------------------------------------------------------------
    // Asks the cycle to start capture number `capture` (> the last one) / to end it.
    void request_arm(uint64_t capture) noexcept { arm_req_.store(capture, std::memory_order_release); }
    void request_disarm() noexcept { disarm_req_.fetch_add(1, std::memory_order_release); }
    bool armed() const noexcept { return armed_pub_.load(std::memory_order_acquire); }
    // The capture the cycle runs (or ran last) and its counts: rows pushed, rows dropped (the ring
    // was full), and whether it has ended (then pushed is final).
    uint64_t capture() const noexcept { return capture_pub_.load(std::memory_order_acquire); }
    uint64_t pushed() const noexcept { return pushed_.load(std::memory_order_acquire); }
    uint64_t dropped() const noexcept { return dropped_.load(std::memory_order_acquire); }
    uint64_t dropped_total() const noexcept { return dropped_total_.load(std::memory_order_acquire); }

    CaptureRing& ring() noexcept { return ring_; }
    std::size_t fields() const noexcept { return fields_; }
    const std::vector<Column>& columns() const noexcept { return cols_; }

private:
    void reset_accumulators() noexcept;

    std::size_t fields_;
    std::vector<Column> cols_;
    CaptureRing ring_;
    // RT state
    bool armed_ = false;
    uint64_t capture_ = 0, disarm_seen_ = 0, gated_ = 0;
    std::vector<double> sum_, min_, max_, last_; // per column
    std::vector<double> row_;                    // the row being pushed
    // requests and published counters
    std::atomic<uint64_t> arm_req_{0}, disarm_req_{0};
    std::atomic<bool> armed_pub_{false};
    std::atomic<uint64_t> capture_pub_{0}, pushed_{0}, dropped_{0}, dropped_total_{0};
};

} // namespace beamctl::daq
