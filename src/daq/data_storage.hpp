// ECMC's data storage (ecmcDataStorage; specs/ecmc.md "Data storage"): a buffer of doubles that
// PLC code fills in the cycle (ds_append_data, ds<n>.append, ec_mm_append_to_ds) and that
// clients read as a waveform PV (DSnn-DataAct).
//
// Buffer types, as ECMC:
//   Normal (0)  fills from the current index; when full, further values are discarded (no error)
//   Ring   (1)  fills from the current index and wraps to the start; never an error
//   Fifo   (2)  the newest value at the end, older ones shifted left; the index is not used
// A block larger than the buffer is refused (0x20202) and nothing is written.
//
// The buffer is allocated once, at configuration, with room for `capacity` values; resizing
// (ds<n>.size, ECMC reallocates) is allowed up to that capacity and refused above it (0x20205,
// beamctl's own: the cycle never allocates).
//
// Publication: the cycle copies the buffer into a triple buffer when it changed and the sample
// period passed, or at once after ds_push_asyn (publish()); the IOC loop reads the latest copy.
// Requests from the IOC loop (clear, set the index, write the data: the DSnn-ClrCmd, -DataIdAct,
// -DataSet PVs) go through a bounded queue and are applied by the cycle in publish().
// Capture tap (docs/flyscan.md "Data storages in the capture"): while a capture runs, every value
// appended is also queued, with its cycle, time and capture number, for the capture's writer
// thread, which writes them into the capture file; a full queue drops the value and counts it.
// Threading: the constructor and enable_tap() before the cycle starts; the RT methods on the RT
// thread; update(), snapshot() and the request_*() methods on ONE non-RT thread (the IOC loop);
// tap_pop() on ONE other thread (the capture's writer).
#pragma once

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

namespace beamctl::daq {

enum class BufferType : uint8_t { Normal = 0, Ring = 1, Fifo = 2 };
const char* to_string(BufferType t) noexcept;
// "normal", "ring", "fifo" (or 0, 1, 2); false if it is none of them.
bool parse_buffer_type(std::string_view s, BufferType& out) noexcept;

// Error ids (ECMC's where ECMC has one).
namespace ds_error {
constexpr uint32_t kBlockTooLarge = 0x20202;      // ERROR_DATA_STORAGE_SIZE_TO_SMALL
constexpr uint32_t kPositionOutOfRange = 0x20203; // ERROR_DATA_STORAGE_POSITION_OUT_OF_RANGE
constexpr uint32_t kSizeOverCapacity = 0x20205;   // beamctl: a resize above the capacity
constexpr uint32_t kIndexOutOfRange = 0x20509;    // ERROR_PLC_DATA_STORAGE_INDEX_OUT_OF_RANGE (ds id not 0..31)
constexpr uint32_t kObjectNull = 0x2050A;         // ERROR_PLC_DATA_STORAGE_OBJECT_NULL (no such ds)
} // namespace ds_error

constexpr int kMaxStorages = 32; // ds0..ds31, as ECMC

class DataStorage {
public:
    // size > 0 values of `type`; capacity (>= size; 0: size) is the most ds<n>.size may grow to.
    // sample_period_cycles: publish a changed buffer at most every that many cycles (>= 1).
    DataStorage(int id, std::size_t size, BufferType type, std::size_t capacity = 0,
                uint64_t sample_period_cycles = 100);
    DataStorage(const DataStorage&) = delete;
    DataStorage& operator=(const DataStorage&) = delete;

    int id() const noexcept { return id_; }
    std::size_t capacity() const noexcept { return buf_.size(); }

    // ---- capture tap ---------------------------------------------------------------------------
    struct TapEntry {
        uint64_t cycle = 0, t_ns = 0; // the cycle that appended the value and its time [ns]
        uint64_t capture = 0;         // the capture it belongs to (1, 2, ...)
        double value = 0;
    };
    // Configuration: a queue of `capacity` values for the capture path.
    void enable_tap(std::size_t capacity);
    bool tapped() const noexcept { return tap_ != nullptr; }
    // RT, once a cycle, before the next cycle's PLCs: the values appended from now on belong to
    // `capture` (0: none, not queued) and carry that cycle and time.
    void tap_next(uint64_t cycle, uint64_t t_ns, uint64_t capture) noexcept {
        tap_cycle_ = cycle;
        tap_t_ns_ = t_ns;
        tap_capture_ = capture;
    }
    // Values the tap had no room for, since the start.
    uint64_t tap_dropped() const noexcept { return tap_dropped_.load(std::memory_order_relaxed); }
    // The writer thread: the next queued value; false when none.
    bool tap_pop(TapEntry& e) noexcept { return tap_ && tap_->pop(e); }

    // ---- RT (the cycle's thread) -------------------------------------------------------------
    // Appends n values (ECMC appendData); 0 or the error id (also latched in error()).
    uint32_t append(const double* v, std::size_t n) noexcept;
    uint32_t append(double v) noexcept { return append(&v, 1); }
    // Zero-fills; index, count and full reset.
    void clear() noexcept;
    // The write index: 0..size inclusive, else kPositionOutOfRange.
    uint32_t set_index(double i) noexcept;
    // Element at an absolute index 0..size-1 (kPositionOutOfRange otherwise; v untouched).
    uint32_t get(double i, double& v) noexcept;
    uint32_t set(double i, double v) noexcept;
    // ds<n>.size: a new size of 1..capacity (the values kept, not zeroed; count and full reset,
    // the index kept as ECMC); kSizeOverCapacity otherwise.
    uint32_t resize(double n) noexcept;
    // Over the valid values (normal and ring: [0, count), FIFO: the last count); 0 when empty.
    double average() const noexcept;
    double minimum() const noexcept;
    double maximum() const noexcept;
    // ds_push_asyn: publish at the next publish() whatever the sample period.
    void request_push() noexcept { push_ = true; }
    // Once per cycle after the PLCs: applies the IOC loop's requests, then publishes if due.
    void publish(uint64_t cycle) noexcept;

    std::size_t size() const noexcept { return size_; }
    std::size_t index() const noexcept { return index_; }
    std::size_t count() const noexcept { return count_; }
    bool full() const noexcept { return count_ >= size_; }
    BufferType type() const noexcept { return type_; }
    uint32_t error() const noexcept { return error_; }
    const double* data() const noexcept { return buf_.data(); }
    uint64_t appended() const noexcept { return appended_; } // values appended since start

    // ---- non-RT (the IOC loop) ---------------------------------------------------------------
    struct Snapshot {
        std::vector<double> data; // capacity() long; the first `size` are the buffer
        std::size_t size = 0, index = 0, count = 0;
        bool full = false;
        BufferType type = BufferType::Normal;
        uint32_t error = 0;
        uint64_t appended = 0;
        uint64_t version = 0; // counts publications
    };
    // True when a newer snapshot arrived; snapshot() is it.
    bool update() noexcept { return snapshots_.update(); }
    const Snapshot& snapshot() const noexcept { return snapshots_.read_buffer(); }
    // ECMC status word: bit 0 full, bits 16..19 the buffer type.
    static uint32_t status_word(const Snapshot& s) noexcept { return (s.full ? 1u : 0u) | uint32_t(s.type) << 16; }
    // Requests applied by the cycle; false if the queue (or the data slot) is busy.
    bool request_clear() noexcept;
    bool request_index(std::size_t i) noexcept;
    // Writes n values from index 0 (ECMC setData: index 0, then append).
    bool request_data(const double* v, std::size_t n) noexcept;

private:
    void publish_now(uint64_t cycle) noexcept;

    int id_;
    BufferType type_;
    std::vector<double> buf_; // capacity values, allocated once
    std::size_t size_, index_ = 0, count_ = 0;
    uint32_t error_ = 0;
    uint64_t appended_ = 0;
    uint64_t period_;
    uint64_t last_publish_ = 0, version_ = 0;
    bool dirty_ = true, push_ = false, published_once_ = false;

    struct Request {
        enum class Op : uint8_t { Clear, Index, Data } op = Op::Clear;
        std::size_t index = 0;
    };
    std::unique_ptr<SpscQueue<TapEntry>> tap_;
    uint64_t tap_cycle_ = 0, tap_t_ns_ = 0, tap_capture_ = 0;
    std::atomic<uint64_t> tap_dropped_{0};

    SpscQueue<Request> requests_{16};
    std::vector<double> incoming_;        // request_data's values (capacity long)
    std::size_t incoming_n_ = 0;
    std::atomic<bool> incoming_busy_{false}; // set by request_data, cleared by the cycle
    TripleBuffer<Snapshot> snapshots_;
};

} // namespace beamctl::daq
