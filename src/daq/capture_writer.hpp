// The writer thread of the capture path: drains a Capture's ring into one HDF5/NeXus file per
// capture (daq::NexusFile, SWMR: a reader may watch the file grow), flushes it every `flush_s`,
// keeps the last rows for live plots, and says what happened (rows written, the file, errors).
//
// One capture: start(path) asks the thread to create the file; once it exists the thread arms the
// Capture (the cycle then pushes rows); a DISARM (Capture::request_disarm) ends it: the thread
// writes every row pushed before the disarm, closes the file and reports it. A file that cannot be
// created leaves the capture unarmed with the reason in status(). Rows the ring had no room for
// are counted by the Capture (dropped) and logged here once a second, naming the file: the cycle
// never waits for the disk.
// Threading: HDF5 is used only on the writer thread; start(), stop() and status() on any one
// non-RT thread (the IOC loop).
#pragma once

#include "daq/capture.hpp"
#include "daq/data_storage.hpp"
#include "daq/nexus_file.hpp"

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace beamctl::daq {

class CaptureWriter {
public:
    struct Options {
        std::vector<NexusColumn> columns; // the Capture's columns in order (one of width w takes w)
        // Data storages whose appended values go into the file (their taps enabled), storage i as
        // the log nexus.logs[i].
        std::vector<DataStorage*> storages;
        NexusOptions nexus;
        double flush_s = 1.0;         // [s] SWMR flush period while capturing
        std::size_t last_rows = 1000; // rows kept for the live waveforms
        std::size_t batch_rows = 4096; // rows per append at most
        double append_s = 0.05;        // [s] rows wait at most this long for a fuller append
        double poll_s = 0.002;        // [s] the thread's sleep when the ring is empty
        // Log lines (file created, closed, dropped rows, errors); called on the writer thread.
        std::function<void(bool error, const std::string&)> log;
    };
    CaptureWriter(Capture& capture, Options opt);
    ~CaptureWriter(); // ends a running capture (its rows are written) and joins the thread
    CaptureWriter(const CaptureWriter&) = delete;
    CaptureWriter& operator=(const CaptureWriter&) = delete;

    // Starts a capture into `path` (an existing file is replaced). False if one is running or
    // starting (status().busy).
    bool start(const std::string& path);
    // Ends the running capture (as DISARM).
    void stop() { capture_.request_disarm(); }

    struct Status {
        bool busy = false;          // a capture is starting, running or being written
        bool armed = false;         // the cycle captures
        uint64_t capture = 0;       // number of the last capture started (1, 2, ...)
        uint64_t rows = 0;          // rows written into its file so far
        uint64_t bytes = 0;         // row bytes handed to HDF5 in it
        uint64_t dropped = 0;       // rows of it the ring had no room for, and storage values
                                    // their taps had none for
        uint64_t values = 0;        // data-storage values written into its file
        uint64_t files = 0;         // files completed
        std::string file;           // its file
        std::string message;        // last news: "capturing to F", "wrote N rows to F", an error
        bool error = false;         // message is an error
        double write_s = 0;         // writer thread time in HDF5 calls, this capture [s]
        uint64_t version = 0;       // changes when anything above changed
    };
    Status status() const;
    // The last `last_rows` rows of Capture column c (oldest first), and their cycle numbers; with
    // `width`, of columns c .. c + width - 1, row by row.
    void last_rows(std::size_t c, std::vector<double>& out, std::size_t width = 1) const;
    void last_cycles(std::vector<double>& out) const;

private:
    void thread_main();
    void set_status(const std::function<void(Status&)>& f);
    void finish(NexusFile& f);

    Capture& capture_;
    Options opt_;
    mutable std::mutex mu_;
    std::condition_variable cv_;
    Status st_;
    std::string pending_path_; // start() -> thread
    bool quit_ = false;
    // last rows (under mu_): a ring of last_rows per column
    std::vector<std::vector<double>> last_;
    std::vector<double> last_cycle_;
    std::size_t last_head_ = 0, last_count_ = 0;
    std::vector<uint64_t> tap_dropped_at_arm_; // per storage (under mu_)
    std::thread thread_;
};

} // namespace beamctl::daq
