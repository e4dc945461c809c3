// Fly-scan figures (issue 15): PCOMP cost per block per cycle; the capture path at 10 kHz (64
// signals, a row every cycle, paced by the monotonic clock) with rows lost counted; and the HDF5
// layer's write rate unpaced (fsync included), to compare with the disk's sequential rate that
// bench/flyscan_capture.sh measures with dd in the same run.
//   bench_flyscan_capture [DIR] [PACED_SECONDS=60] [UNPACED_ROWS=2000000]
#include "daq/capture.hpp"
#include "daq/capture_writer.hpp"
#include "daq/pcomp.hpp"

#include <fcntl.h>
#include <time.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

using namespace beamctl::daq;

namespace {

double now_s() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

double cpu_s() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// 64 blocks on a ramp, each firing every 100 cycles: ns per block evaluation.
void pcomp_cost() {
    constexpr int kBlocks = 64;
    constexpr long kCycles = 200000;
    std::vector<Pcomp> blocks(kBlocks);
    for (int b = 0; b < kBlocks; ++b) {
        blocks[b].params.start = 1 + b * 0.01;
        blocks[b].params.step = 1.0;
        blocks[b].params.width = 0.5;
    }
    double x = 0, sink = 0;
    double t0 = now_s();
    for (long k = 0; k < kCycles; ++k) {
        x += 0.01;
        for (Pcomp& p : blocks) sink += p.step(true, x);
    }
    double dt = now_s() - t0;
    unsigned long produced = 0;
    for (Pcomp& p : blocks) produced += p.produced();
    std::printf("pcomp: %d blocks x %ld cycles: %.1f ns per block per cycle (target <= 50 ns); %lu pulses (%g)\n", kBlocks, kCycles,
                dt * 1e9 / double(kBlocks * kCycles), produced, sink);
}

struct Run {
    uint64_t rows = 0, written = 0, dropped = 0;
    double wall_s = 0, writer_cpu_s = 0, bytes = 0;
};

// The cycle side on this thread: rows at `rate_hz` (woken every 1 ms, as many rows as are due),
// or as fast as the ring takes them when rate_hz is 0; the writer thread writes the file.
Run capture_run(const std::string& path, double rate_hz, double seconds, uint64_t max_rows) {
    constexpr std::size_t kCols = 64;
    std::vector<Capture::Column> cols;
    std::vector<NexusColumn> ncols;
    for (std::size_t c = 0; c < kCols; ++c) {
        cols.push_back({c, CaptureMode::Value});
        ncols.push_back({"s" + std::to_string(c), "mm", "bench.s" + std::to_string(c), "Value"});
    }
    Capture cap(kCols, cols, 1 << 16);
    CaptureWriter::Options o;
    o.columns = ncols;
    o.nexus.chunk_rows = 8192;
    o.batch_rows = 8192;
    CaptureWriter w(cap, o);
    if (!w.start(path)) std::abort();
    while (!cap.armed()) {
        double in[kCols] = {};
        cap.sample(0, 0, in, true, false, 0); // takes the arm
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    double in[kCols];
    const double t0 = now_s();
    uint64_t k = 0;
    if (rate_hz > 0) {
        timespec next{};
        clock_gettime(CLOCK_MONOTONIC, &next);
        const uint64_t total = uint64_t(rate_hz * seconds);
        while (k < total) {
            next.tv_nsec += 1000000;
            if (next.tv_nsec >= 1000000000) {
                next.tv_nsec -= 1000000000;
                ++next.tv_sec;
            }
            clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
            const uint64_t due = std::min<uint64_t>(total, uint64_t((now_s() - t0) * rate_hz));
            for (; k < due; ++k) {
                for (std::size_t c = 0; c < kCols; ++c) in[c] = double(k) + double(c) * 1e-3;
                cap.sample(k, k * 100000, in, true, true, k * 100000);
            }
        }
    } else {
        while (k < max_rows) {
            if (cap.ring().size() + 1 >= cap.ring().capacity()) {
                std::this_thread::yield();
                continue;
            }
            for (std::size_t c = 0; c < kCols; ++c) in[c] = double(k) + double(c) * 1e-3;
            cap.sample(k, k * 100000, in, true, true, k * 100000);
            ++k;
        }
    }
    w.stop();
    double dummy[kCols] = {};
    while (w.status().busy) {
        cap.sample(k, 0, dummy, true, false, 0); // the disarm is taken by a cycle
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    int fd = ::open(path.c_str(), O_RDONLY);
    if (fd >= 0) {
        ::fsync(fd);
        ::close(fd);
    }
    Run r;
    r.wall_s = now_s() - t0;
    CaptureWriter::Status s = w.status();
    r.rows = cap.pushed();
    r.written = s.rows;
    r.dropped = cap.dropped();
    r.writer_cpu_s = s.write_s;
    r.bytes = double(s.bytes);
    return r;
}

} // namespace

int main(int argc, char** argv) {
    std::string dir = argc > 1 ? argv[1] : "/tmp";
    double paced_s = argc > 2 ? std::atof(argv[2]) : 60;
    uint64_t unpaced_rows = argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 2000000;
    pcomp_cost();
    if (paced_s > 0) {
        double c0 = cpu_s();
        Run r = capture_run(dir + "/bench_capture_paced.h5", 10000, paced_s, 0);
        double cpu = cpu_s() - c0;
        std::printf("capture 64 signals at 10 kHz for %.0f s: %llu rows captured, %llu written, %llu dropped; "
                    "%.2f MB/s to HDF5; writer thread %.2f s in HDF5 (%.1f %% of one core); process CPU %.1f %%\n",
                    paced_s, (unsigned long long)r.rows, (unsigned long long)r.written, (unsigned long long)r.dropped,
                    r.bytes / r.wall_s / 1e6, r.writer_cpu_s, 100 * r.writer_cpu_s / r.wall_s, 100 * cpu / r.wall_s);
        std::remove((dir + "/bench_capture_paced.h5").c_str());
    }
    if (unpaced_rows > 0) {
        Run r = capture_run(dir + "/bench_capture_unpaced.h5", 0, 0, unpaced_rows);
        std::printf("capture unpaced, 64 signals: %llu rows (%.0f MB) in %.2f s incl. fsync: %.1f MB/s at the HDF5 layer "
                    "(writer thread %.2f s in HDF5), %llu dropped\n",
                    (unsigned long long)r.written, r.bytes / 1e6, r.wall_s, r.bytes / r.wall_s / 1e6, r.writer_cpu_s,
                    (unsigned long long)r.dropped);
        std::remove((dir + "/bench_capture_unpaced.h5").c_str());
    }
    return 0;
}
