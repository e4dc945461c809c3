#include "daq/capture_writer.hpp"

#include "core/error.hpp"

#include <chrono>
#include <memory>
#include <time.h>

namespace beamctl::daq {
namespace {

double thread_cpu_s() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

double now_s() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

} // namespace

CaptureWriter::CaptureWriter(Capture& capture, Options opt) : capture_(capture), opt_(std::move(opt)) {
    std::size_t values = 0;
    for (const NexusColumn& c : opt_.columns) values += c.width;
    if (values != capture_.columns().size())
        throw Error(SB() << "capture writer: " << values << " values a row in the file for " << capture_.columns().size()
                         << " capture columns");
    if (opt_.storages.size() != opt_.nexus.logs.size())
        throw Error(SB() << "capture writer: " << opt_.storages.size() << " storages for " << opt_.nexus.logs.size() << " logs");
    for (DataStorage* ds : opt_.storages)
        if (!ds || !ds->tapped()) throw Error("capture writer: a data storage without its capture tap");
    tap_dropped_at_arm_.assign(opt_.storages.size(), 0);
    last_.assign(values, std::vector<double>(opt_.last_rows, 0.0));
    last_cycle_.assign(opt_.last_rows, 0.0);
    thread_ = std::thread([this] { thread_main(); });
}

CaptureWriter::~CaptureWriter() {
    {
        std::lock_guard<std::mutex> l(mu_);
        quit_ = true;
    }
    cv_.notify_all();
    thread_.join();
}

bool CaptureWriter::start(const std::string& path) {
    {
        std::lock_guard<std::mutex> l(mu_);
        if (st_.busy || !pending_path_.empty()) return false;
        pending_path_ = path;
        st_.busy = true;
        ++st_.version;
    }
    cv_.notify_all();
    return true;
}

CaptureWriter::Status CaptureWriter::status() const {
    std::lock_guard<std::mutex> l(mu_);
    Status s = st_;
    s.armed = capture_.armed() && capture_.capture() == s.capture && s.capture != 0;
    s.dropped = capture_.capture() == s.capture ? capture_.dropped() : 0;
    if (s.capture)
        for (std::size_t i = 0; i < opt_.storages.size(); ++i) s.dropped += opt_.storages[i]->tap_dropped() - tap_dropped_at_arm_[i];
    return s;
}

void CaptureWriter::last_rows(std::size_t c, std::vector<double>& out, std::size_t width) const {
    std::lock_guard<std::mutex> l(mu_);
    out.clear();
    if (c + width > last_.size()) return;
    std::size_t n = opt_.last_rows, first = (last_head_ + n - last_count_) % (n ? n : 1);
    for (std::size_t i = 0; i < last_count_; ++i)
        for (std::size_t k = 0; k < width; ++k) out.push_back(last_[c + k][(first + i) % n]);
}

void CaptureWriter::last_cycles(std::vector<double>& out) const {
    std::lock_guard<std::mutex> l(mu_);
    out.clear();
    std::size_t n = opt_.last_rows, first = (last_head_ + n - last_count_) % (n ? n : 1);
    for (std::size_t i = 0; i < last_count_; ++i) out.push_back(last_cycle_[(first + i) % n]);
}

void CaptureWriter::set_status(const std::function<void(Status&)>& f) {
    std::lock_guard<std::mutex> l(mu_);
    f(st_);
    ++st_.version;
}

void CaptureWriter::finish(NexusFile& f) {
    std::string msg;
    bool error = false;
    double t0 = thread_cpu_s();
    try {
        f.close();
        msg = SB() << "wrote " << f.rows() << " rows to " << f.path();
        for (std::size_t k = 0; k < opt_.nexus.logs.size(); ++k)
            msg += SB() << (k ? ", " : " and ") << f.log_rows(k) << " " << opt_.nexus.logs[k].name << " values";
    } catch (const std::exception& e) {
        msg = e.what();
        error = true;
    }
    double dt = thread_cpu_s() - t0;
    uint64_t dropped = capture_.dropped();
    if (dropped) {
        msg += SB() << "; " << dropped << " rows were dropped (the ring was full: the disk did not keep up)";
        error = true;
    }
    uint64_t values_dropped = 0;
    {
        std::lock_guard<std::mutex> l(mu_);
        for (std::size_t i = 0; i < opt_.storages.size(); ++i) values_dropped += opt_.storages[i]->tap_dropped() - tap_dropped_at_arm_[i];
    }
    if (values_dropped) {
        msg += SB() << "; " << values_dropped << " data-storage values were dropped (their queue was full)";
        error = true;
    }
    if (opt_.log) opt_.log(error, msg);
    set_status([&](Status& s) {
        s.busy = false;
        s.message = msg;
        s.error = error;
        s.rows = f.rows();
        s.bytes = f.bytes();
        s.write_s += dt;
        ++s.files;
    });
}

void CaptureWriter::thread_main() {
    const std::size_t cols = capture_.columns().size(), batch = std::max<std::size_t>(opt_.batch_rows, 1);
    std::vector<RowHeader> heads(batch);
    std::vector<double> vals(batch * std::max<std::size_t>(cols, 1));
    std::vector<uint64_t> cycles(batch), times(batch);
    std::vector<uint64_t> log_cycles(batch), log_times(batch); // a storage's values
    std::vector<double> log_vals(batch);
    std::unique_ptr<NexusFile> file;
    uint64_t capture_no = 0, dropped_logged = 0;
    std::size_t pending = 0; // rows gathered in the batch, not yet appended
    double last_flush = now_s(), last_drop_log = 0, write_s = 0, last_append = 0;
    for (;;) {
        std::string path;
        bool quit = false;
        {
            std::unique_lock<std::mutex> l(mu_);
            if (!file && pending_path_.empty() && !quit_) cv_.wait_for(l, std::chrono::duration<double>(opt_.poll_s * 10));
            quit = quit_;
            path.swap(pending_path_);
        }
        if (!path.empty() && !file) {
            try {
                double t0 = thread_cpu_s();
                file = std::make_unique<NexusFile>(path, opt_.columns, opt_.nexus);
                write_s = thread_cpu_s() - t0;
            } catch (const std::exception& e) {
                std::string msg = SB() << "capture not started: " << e.what();
                if (opt_.log) opt_.log(true, msg);
                set_status([&](Status& s) {
                    s.busy = false;
                    s.error = true;
                    s.message = msg;
                });
                continue;
            }
            ++capture_no;
            dropped_logged = 0;
            set_status([&](Status& s) {
                s.capture = capture_no;
                s.file = path;
                s.rows = s.bytes = s.values = 0;
                s.write_s = 0;
                s.error = false;
                s.message = SB() << "capturing to " << path;
            });
            {
                std::lock_guard<std::mutex> l(mu_);
                last_head_ = last_count_ = 0;
                for (std::size_t i = 0; i < opt_.storages.size(); ++i) tap_dropped_at_arm_[i] = opt_.storages[i]->tap_dropped();
            }
            if (opt_.log) opt_.log(false, SB() << "capture " << capture_no << ": writing " << path);
            pending = 0;
            capture_.request_arm(capture_no);
            last_flush = last_append = now_s();
        }
        if (!file) {
            if (quit) return;
            continue;
        }
        // Whether the capture has ended is read before draining: every row it pushed is then
        // in the ring.
        const bool ended = capture_.capture() == capture_no && !capture_.armed();
        // Rows gather in the batch until it is full or `append_s` passed since the last append
        // (each append costs a few HDF5 calls per dataset, whatever its size).
        std::size_t n = 0, total = 0;
        for (;;) {
            const std::size_t base = pending;
            n = capture_.ring().pop(&heads[base], &vals[base * cols], batch - base);
            for (std::size_t i = 0; i < n; ++i) {
                const std::size_t from = base + i;
                if (heads[from].capture != capture_no) continue; // a row of an earlier capture
                if (pending != from) {
                    std::copy_n(&vals[from * cols], cols, &vals[pending * cols]);
                    heads[pending] = heads[from];
                }
                cycles[pending] = heads[from].cycle;
                times[pending] = heads[from].t_ns;
                ++pending;
            }
            total += n;
            const bool full = pending == batch;
            if (pending && (full || ended || quit || now_s() - last_append >= opt_.append_s)) {
                double t0 = thread_cpu_s();
                try {
                    file->append(cycles.data(), times.data(), vals.data(), pending);
                } catch (const std::exception& e) {
                    if (opt_.log) opt_.log(true, e.what());
                    set_status([&](Status& s) {
                        s.error = true;
                        s.message = e.what();
                    });
                }
                write_s += thread_cpu_s() - t0;
                last_append = now_s();
                std::lock_guard<std::mutex> l(mu_);
                std::size_t L = opt_.last_rows;
                for (std::size_t i = 0; L && i < pending; ++i) {
                    for (std::size_t c = 0; c < cols; ++c) last_[c][last_head_] = vals[i * cols + c];
                    last_cycle_[last_head_] = double(cycles[i]);
                    last_head_ = (last_head_ + 1) % L;
                    last_count_ = std::min(last_count_ + 1, L);
                }
                st_.rows = file->rows();
                st_.bytes = file->bytes();
                st_.write_s = write_s;
                ++st_.version;
                pending = 0;
            }
            if (!full) break;
        }
        // The storages' values of this capture, as they came (all of them once it has ended).
        for (std::size_t k = 0; k < opt_.storages.size(); ++k) {
            for (;;) {
                std::size_t m = 0;
                DataStorage::TapEntry e;
                while (m < batch && opt_.storages[k]->tap_pop(e)) {
                    if (e.capture != capture_no) continue; // an earlier capture's
                    log_cycles[m] = e.cycle;
                    log_times[m] = e.t_ns;
                    log_vals[m++] = e.value;
                }
                if (m == 0) break;
                total += m;
                double t0 = thread_cpu_s();
                try {
                    file->append_log(k, log_cycles.data(), log_times.data(), log_vals.data(), m);
                } catch (const std::exception& e) {
                    if (opt_.log) opt_.log(true, e.what());
                    set_status([&](Status& s) {
                        s.error = true;
                        s.message = e.what();
                    });
                    break;
                }
                write_s += thread_cpu_s() - t0;
                set_status([&](Status& s) {
                    s.values += m;
                    s.bytes = file->bytes();
                    s.write_s = write_s;
                });
                if (m < batch) break;
            }
        }
        const double now = now_s();
        if (uint64_t d = capture_.capture() == capture_no ? capture_.dropped() : 0; d > dropped_logged && now - last_drop_log >= 1.0) {
            if (opt_.log) opt_.log(true, SB() << "capture " << capture_no << ": " << d << " rows dropped so far: " << file->path()
                                              << " does not keep up with the cycle");
            dropped_logged = d;
            last_drop_log = now;
        }
        if (ended || quit) {
            finish(*file);
            file.reset();
            continue;
        }
        if (now - last_flush >= opt_.flush_s) {
            double t0 = thread_cpu_s();
            try {
                file->flush();
            } catch (const std::exception& e) {
                if (opt_.log) opt_.log(true, e.what());
            }
            write_s += thread_cpu_s() - t0;
            last_flush = now;
        }
        if (total == 0) std::this_thread::sleep_for(std::chrono::duration<double>(opt_.poll_s));
    }
}

} // namespace beamctl::daq
