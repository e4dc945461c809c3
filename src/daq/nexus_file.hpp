// A fly scan's capture file: HDF5 (C API) in a NeXus layout, written in SWMR mode so that a reader
// (H5F_ACC_SWMR_READ, or h5py's swmr=True) can follow it while it grows.
//
// Layout (every dataset chunked, extendible, uncompressed, one row per captured cycle; 1-D, or
// [rows, width] for a column of `width` values a row such as an oversampled input's samples):
//   /                      default="entry"
//   /entry                 NX_class="NXentry", default="data", title (if given), extra attributes
//   /entry/data            NX_class="NXdata", signal, axes, <axes>_indices=0
//   /entry/data/<column>   float64, units (if any), source, capture_mode (and samples_per_row
//                          when width > 1)
//   /entry/data/cycle      uint64: the engine cycle of the row
//   /entry/data/time       float64 [s] since the first row
//   /entry/data/timestamp_ns  uint64 [ns], absolute
//   /entry/<log>           NX_class="NXlog", source: values that come one by one rather than a row
//                          a cycle (a data storage's appends): value float64 (units), time
//                          float64 [s] since its first value, cycle uint64, timestamp_ns uint64
// The layout is fixed at construction: SWMR allows no new objects or attributes afterwards.
// Rows become visible to readers at flush() (and close()), not at append().
//
// Threading: ONE thread (the capture's writer thread) constructs, uses and destroys a NexusFile;
// HDF5 serialises all of its calls in the process behind one lock, so keep other HDF5 users
// out of the writer's process or expect them to stall it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::daq {

struct NexusColumn {
    std::string name;   // dataset name under /entry/data ("ax1_enc_actpos"): no '/', not "." nor a
                        // reserved name (cycle, time, timestamp_ns)
    std::string units;  // NeXus "units" ("mm", "s"); no attribute if empty
    std::string source; // the engine signal it captures ("ax1.enc.actpos"), attribute "source"
    std::string mode;   // "Value", "Diff", "Sum", "Min", "Max": attribute "capture_mode"
    bool uint64 = false; // the row's double holds a uint64's bit pattern (a DC time stamp): a
                         // uint64 dataset
    std::size_t width = 1; // values a row (>= 1): the dataset is [rows, width] when > 1 (the n
                           // samples a cycle of an oversampled input, in time order)
};

// A log of values written as they come (NXlog under /entry): name (not "data" nor "title"),
// units of the values, the engine source it records.
struct NexusLog {
    std::string name, units, source;
};

struct NexusOptions {
    std::size_t chunk_rows = 4096; // chunk size of every dataset [rows] (>= 1)
    std::string title;             // /entry/title (string dataset); none if empty
    std::string axis;   // NXdata "axes": a dataset of /entry/data (default: first column)
    std::string signal; // NXdata "signal": a dataset of /entry/data (default: the second column,
                        // or the first if it is the only one)
    // Extra string attributes on /entry (IOC name, ISO 8601 start time).
    std::vector<std::pair<std::string, std::string>> attributes;
    std::vector<NexusLog> logs; // /entry/<name> each
};

class NexusFile {
public:
    // Creates (truncates) `path` with the layout above and starts SWMR writing. Throws
    // beamctl::Error naming the path and HDF5's reason; bad columns or options are refused
    // before the file is touched.
    NexusFile(const std::string& path, std::vector<NexusColumn> columns, NexusOptions opt = {});
    ~NexusFile(); // close(), errors swallowed
    NexusFile(NexusFile&&) noexcept;
    NexusFile& operator=(NexusFile&&) noexcept;
    NexusFile(const NexusFile&) = delete;
    NexusFile& operator=(const NexusFile&) = delete;

    // Appends n rows: cycle[n], t_ns[n] [ns] and values[n * columns()] row-major (a column of
    // width w takes w consecutive values of a row). One write per
    // dataset; its own buffers grow only when n exceeds every earlier n (HDF5 mallocs inside).
    // After an Error the file takes no more rows (close it).
    void append(const uint64_t* cycle, const uint64_t* t_ns, const double* values, std::size_t n);
    // Appends n values to log k (of NexusOptions::logs): cycle[n], t_ns[n], values[n].
    void append_log(std::size_t k, const uint64_t* cycle, const uint64_t* t_ns, const double* values, std::size_t n);
    std::uint64_t log_rows(std::size_t k) const noexcept;
    // Makes the rows appended so far visible to SWMR readers (H5Dflush of every dataset; no fsync).
    void flush();
    // Flushes and closes; idempotent. Throws Error on failure (the handles are released anyway).
    void close();

    std::uint64_t rows() const noexcept;
    // Row data handed to HDF5 so far [bytes]: 8 * (columns() + 3) a row, 32 a log value.
    std::uint64_t bytes() const noexcept;
    const std::string& path() const noexcept;
    std::size_t columns() const noexcept; // values a row: the columns' widths summed
    bool is_open() const noexcept;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace beamctl::daq
