#include "ioc/area_detector.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "daq/frame_file.hpp"
#include "detector/sim_camera.hpp"
#include "ioc/pv_util.hpp"
#include "pv/db_file.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <mutex>
#include <thread>
#include <unordered_map>

namespace beamctl::ioc {
namespace {

log::Logger lg("areadetector");

using Fields = std::vector<std::pair<std::string, std::string>>;

static_assert(int(detector::NdType::Float64) == int(daq::PixelType::Float64), "one pixel type order (areaDetector's)");

constexpr double kEpicsEpoch = 631152000; // 1990-01-01 in Unix seconds

// ADCore's menus.
const Fields kImageModes = {{"ZRST", "Single"}, {"ONST", "Multiple"}, {"TWST", "Continuous"}};
const Fields kTriggerModes = {{"ZRST", "Internal"}, {"ONST", "Software"}}; // Software: an exposure a TriggerSoftware
const Fields kColorModes = {{"ZRST", "Mono"}, {"ONST", "Bayer"}, {"TWST", "RGB1"}, {"THST", "RGB2"},
                            {"FRST", "RGB3"}, {"FVST", "YUV444"}, {"SXST", "YUV422"}, {"SVST", "YUV421"}};
const Fields kStates = {{"ZRST", "Idle"},    {"ONST", "Acquire"}, {"TWST", "Readout"},      {"THST", "Correct"},
                        {"FRST", "Saving"},  {"FVST", "Aborting"}, {"SXST", "Error"},       {"SVST", "Waiting"},
                        {"EIST", "Initializing"}, {"NIST", "Disconnected"}, {"TEST", "Aborted"}};
const Fields kWriteModes = {{"ZRST", "Single"}, {"ONST", "Capture"}, {"TWST", "Stream"}};
const Fields kDisableEnable = {{"ZNAM", "Disable"}, {"ONAM", "Enable"}};
const Fields kNoYes = {{"ZNAM", "No"}, {"ONAM", "Yes"}};
enum State { kIdle = 0, kAcquire = 1, kReadout = 2, kWaiting = 7 };
enum ImageMode { kSingle = 0, kMultiple = 1, kContinuous = 2 };
enum WriteMode { kWriteSingle = 0, kWriteCapture = 1, kWriteStream = 2 };

Fields data_types() {
    static const char* const f[] = {"ZRST", "ONST", "TWST", "THST", "FRST", "FVST", "SXST", "SVST", "EIST", "NIST"};
    Fields out;
    for (int i = 0; i < detector::kNdTypes; ++i) out.push_back({f[i], detector::kNdTypeNames[i]});
    return out;
}

// The image waveform's FTVL for a pixel type.
const char* ftvl_of(detector::NdType t) {
    static const char* const f[] = {"CHAR", "UCHAR", "SHORT", "USHORT", "LONG", "ULONG", "INT64", "UINT64", "FLOAT", "DOUBLE"};
    return f[int(t)];
}

Fields with(Fields a, const Fields& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

std::string num(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

double wall_epics_s() {
    using namespace std::chrono;
    return double(duration_cast<nanoseconds>(system_clock::now().time_since_epoch()).count()) * 1e-9 - kEpicsEpoch;
}

} // namespace

bool format_file_name(const std::string& tmpl, const std::string& path, const std::string& name, int number, std::string& out,
                      std::string& why) {
    out.clear();
    int strings = 0;
    bool integer = false;
    for (std::size_t i = 0; i < tmpl.size(); ++i) {
        if (tmpl[i] != '%') {
            out += tmpl[i];
            continue;
        }
        std::size_t j = i + 1;
        if (j < tmpl.size() && tmpl[j] == '%') {
            out += '%';
            i = j;
            continue;
        }
        std::string spec = "%";
        while (j < tmpl.size() && std::string_view("-+ #0").find(tmpl[j]) != std::string_view::npos) spec += tmpl[j++];
        std::size_t digits = 0;
        while (j < tmpl.size() && std::isdigit(static_cast<unsigned char>(tmpl[j])) && digits < 3) spec += tmpl[j++], ++digits;
        if (j < tmpl.size() && tmpl[j] == '.') {
            spec += tmpl[j++];
            digits = 0;
            while (j < tmpl.size() && std::isdigit(static_cast<unsigned char>(tmpl[j])) && digits < 3) spec += tmpl[j++], ++digits;
        }
        if (j >= tmpl.size()) {
            why = "the template ends inside a conversion";
            return false;
        }
        const char conv = tmpl[j];
        char buf[512];
        if (conv == 's') {
            if (integer || strings >= 2) {
                why = "the template's %s conversions come first, two at most (the path, the name)";
                return false;
            }
            spec += 's';
            std::snprintf(buf, sizeof buf, spec.c_str(), (strings == 0 ? path : name).c_str());
            ++strings;
        } else if (std::string_view("diuoxX").find(conv) != std::string_view::npos) {
            if (integer) {
                why = "the template has one number conversion at most (the file number)";
                return false;
            }
            spec += conv;
            std::snprintf(buf, sizeof buf, spec.c_str(), number);
            integer = true;
        } else {
            why = std::string("the template's conversion %") + conv + " is not one of %s (path, name) and %d (number)";
            return false;
        }
        out += buf;
        i = j;
    }
    if (out.size() > 255) {
        why = "the file name is longer than 255 characters";
        return false;
    }
    return true;
}

// --- the worker: renders, computes statistics, writes files --------------------------------------

struct FileSettings {
    std::string path, name, tmpl;
    int number = 0;
    bool auto_increment = false, auto_save = false;
    int mode = kWriteStream;
    int num_capture = 1;
};

struct Job {
    enum Kind { Frame, StartCapture, StopCapture, WriteFile } kind = Frame;
    detector::CameraSettings cam;
    detector::CameraSpot spot;
    int32_t uid = 0;
    double timestamp = 0;
    bool image = true, stats = true, hdf = true;
    bool compute_stats = true, compute_centroid = true;
    double threshold = 1;
    int bgd_width = 0;
    FileSettings file;
};

struct Result {
    int kind = Job::Frame;   // the job's
    bool frame_done = false; // a Frame job's result (else a file command's)
    std::shared_ptr<detector::Frame> frame;
    bool has_stats = false;
    detector::FrameStats stats;
    double stats_seconds = 0, file_seconds = 0;
    bool to_image = false, to_stats = false, to_hdf = false; // the plugins that had the frame
    // the file plugin after the job
    bool capturing = false;
    int num_captured = 0, file_number = 0;
    std::string full_name;
    bool wrote = false, write_error = false;
    std::string message;
    double io_mb_s = 0, run_time = 0;
};

struct IocAreaDetector::Worker {
    explicit Worker(detector::CameraSensor s) : camera(s) {}
    ~Worker() { stop(); }

    void start() {
        thread = std::thread([this] { run(); });
    }
    void stop() {
        {
            std::lock_guard<std::mutex> l(mu);
            quit = true;
        }
        cv.notify_all();
        if (thread.joinable()) thread.join();
    }
    void submit(Job j) {
        {
            std::lock_guard<std::mutex> l(mu);
            jobs.push_back(std::move(j));
            ++pending;
        }
        cv.notify_all();
    }
    bool take(Result& r) {
        std::lock_guard<std::mutex> l(mu);
        if (results.empty()) return false;
        r = std::move(results.front());
        results.pop_front();
        return true;
    }
    std::size_t outstanding() const {
        std::lock_guard<std::mutex> l(mu);
        return pending;
    }

    // worker thread
    void run() {
        for (;;) {
            Job j;
            {
                std::unique_lock<std::mutex> l(mu);
                cv.wait(l, [this] { return quit || !jobs.empty(); });
                if (quit) return;
                j = std::move(jobs.front());
                jobs.pop_front();
            }
            Result r = handle(j);
            std::lock_guard<std::mutex> l(mu);
            results.push_back(std::move(r));
            --pending;
        }
    }

    Result handle(const Job& j) {
        Result r;
        r.kind = j.kind;
        try {
            if (j.kind == Job::Frame) frame(j, r);
            else command(j, r);
        } catch (const std::exception& e) { // a file that cannot be written: the plugin's error
            r.write_error = true;
            r.message = e.what();
            try {
                close_file(r);
            } catch (const std::exception&) { // the reason above is the first one
            }
            file.reset();
            capturing = false;
        }
        r.capturing = capturing;
        r.num_captured = num_captured;
        r.file_number = number;
        r.full_name = full_name;
        return r;
    }

    void frame(const Job& j, Result& r) {
        r.frame_done = true;
        r.to_image = j.image, r.to_stats = j.stats, r.to_hdf = j.hdf;
        auto f = std::make_shared<detector::Frame>();
        camera.render(j.cam, j.spot, *f);
        f->unique_id = j.uid;
        f->timestamp = j.timestamp;
        r.frame = f;
        const auto t0 = std::chrono::steady_clock::now();
        if (j.stats && j.compute_stats) {
            r.stats = detector::frame_stats(*f, j.compute_centroid ? j.threshold : 1e300, j.bgd_width);
            r.has_stats = true;
        }
        const auto t1 = std::chrono::steady_clock::now();
        r.stats_seconds = std::chrono::duration<double>(t1 - t0).count();
        if (!j.hdf) return;
        last = f;
        adopt_number(j.file.number);
        if (!capturing && j.file.mode == kWriteSingle) {
            if (j.file.auto_save) write_frames(j.file, {f}, r);
        } else if (capturing && settings.mode == kWriteCapture) {
            buffered.push_back(f);
            ++num_captured;
            if (num_captured >= settings.num_capture) {
                capturing = false;
                if (settings.auto_save) write_frames(settings, buffered, r);
            }
        } else if (capturing && settings.mode == kWriteStream) {
            const auto w0 = std::chrono::steady_clock::now();
            if (!file) file = std::make_unique<daq::FrameFile>(stream_name, daq::PixelType(f->type), f->nx, f->ny);
            file->append(f->data.data(), daq::PixelType(f->type), f->nx, f->ny, f->unique_id, f->timestamp);
            ++num_captured;
            stream_bytes += f->data.size();
            stream_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
            if (settings.num_capture > 0 && num_captured >= settings.num_capture) {
                capturing = false;
                close_file(r);
            }
        }
        r.file_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    }

    // The IOC's FileNumber as a job saw it: taken when a client changed it, not when it is only the
    // IOC's stale copy of a number this thread advanced.
    void adopt_number(int n) {
        if (n != seen_number) number = n, seen_number = n;
    }

    void command(const Job& j, Result& r) {
        adopt_number(j.file.number);
        switch (j.kind) {
        case Job::StartCapture:
            settings = j.file;
            num_captured = 0;
            buffered.clear();
            close_file(r);
            if (j.file.mode == kWriteStream) { // the name now, the file at the first frame (its size)
                stream_name = open_name(j.file);
                stream_bytes = 0, stream_seconds = 0;
            }
            capturing = true;
            break;
        case Job::StopCapture:
            if (capturing && settings.mode == kWriteCapture && settings.auto_save && !buffered.empty()) write_frames(settings, buffered, r);
            capturing = false;
            close_file(r);
            break;
        case Job::WriteFile:
            if (j.file.mode == kWriteSingle) {
                if (!last) throw Error("WriteFile: no frame to write yet");
                write_frames(j.file, {last}, r);
            } else if (j.file.mode == kWriteCapture) {
                if (buffered.empty()) throw Error("WriteFile: no captured frame to write");
                write_frames(j.file, buffered, r);
            } else {
                throw Error("WriteFile: in Stream mode the file is written as frames come (use Capture)");
            }
            break;
        case Job::Frame: break;
        }
    }

    // The next file's name from the settings (FileNumber advances when AutoIncrement is on).
    std::string open_name(const FileSettings& s) {
        std::string name, why;
        if (!format_file_name(s.tmpl, s.path, s.name, number, name, why)) throw Error("FileTemplate: " + why);
        full_name = name;
        if (s.auto_increment) ++number;
        return name;
    }

    void write_frames(const FileSettings& s, const std::vector<std::shared_ptr<detector::Frame>>& frames, Result& r) {
        const auto t0 = std::chrono::steady_clock::now();
        const std::string name = open_name(s);
        const detector::Frame& f0 = *frames.front();
        daq::FrameFile out(name, daq::PixelType(f0.type), f0.nx, f0.ny);
        uint64_t bytes = 0;
        for (const auto& f : frames) {
            out.append(f->data.data(), daq::PixelType(f->type), f->nx, f->ny, f->unique_id, f->timestamp);
            bytes += f->data.size();
        }
        out.close();
        const double s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        r.wrote = true;
        r.run_time = s_;
        r.io_mb_s = s_ > 0 ? double(bytes) / s_ / 1e6 : 0;
    }

    void close_file(Result& r) {
        if (!file) return;
        file->close();
        r.wrote = true;
        r.run_time = stream_seconds;
        r.io_mb_s = stream_seconds > 0 ? double(stream_bytes) / stream_seconds / 1e6 : 0;
        file.reset();
    }

    detector::Camera camera;
    std::thread thread;
    mutable std::mutex mu;
    std::condition_variable cv;
    std::deque<Job> jobs;
    std::deque<Result> results;
    std::size_t pending = 0;
    bool quit = false;
    // the file plugin (worker thread only)
    FileSettings settings;
    bool capturing = false;
    std::string stream_name;
    int num_captured = 0, number = 0, seen_number = -1;
    std::string full_name;
    std::unique_ptr<daq::FrameFile> file;
    std::vector<std::shared_ptr<detector::Frame>> buffered;
    std::shared_ptr<detector::Frame> last;
    uint64_t stream_bytes = 0;
    double stream_seconds = 0;
};

// --- one detector ---------------------------------------------------------------------------------

struct IocAreaDetector::Unit {
    config::AreaDetectorEntry cfg;
    std::string cam, image, hdf, stats; // PV prefixes: DEMO:cam1:, ...
    std::unordered_map<std::string, pv::Record*> rec; // by full name
    std::unique_ptr<Worker> worker;
    BeamSource beam;
    detector::CameraSettings settings; // as applied (clipped)
    // acquisition (IOC loop)
    bool acquiring = false, stopping = false;
    double exposure_start = 0, exposure_end = 0;
    ethercat::sim::BeamTally tally0;
    int images = 0;           // this acquisition's
    std::size_t in_flight = 0; // frames at the worker
    int32_t counter = 0, uid = 0;
    std::deque<double> frame_times; // for ArrayRate_RBV
    int pending_starts = 0;    // StartCapture commands the worker has not answered
    bool capturing = false, write_pending = false;
    int triggers = 0; // software triggers not yet taken
    detector::NdType image_type = detector::NdType::UInt16; // ArrayData's FTVL
    uint64_t dropped = 0;

    pv::Record& r(const std::string& name) const {
        auto it = rec.find(name);
        if (it == rec.end()) throw Error(SB() << "area detector: record " << name << " missing");
        return *it->second;
    }
};

void IocAreaDetector::make_records(const config::AreaDetectorEntry& e, const std::string& p, pv::DbFile& f) {
    const std::string c = p + e.cam + ":", im = p + e.image + ":", h = p + e.hdf + ":", s = p + e.stats + ":";
    auto add = [&](const std::string& type, const std::string& name, Fields fl) { f.records.push_back(record(type, name, std::move(fl))); };
    // an output with its readback (asyn's pair, as ADCore's templates have them)
    auto pair = [&](const std::string& out, const std::string& in, const std::string& name, Fields fl, const std::string& val) {
        Fields o = fl;
        if (!val.empty()) o.push_back({"VAL", val});
        add(out, name, o);
        add(in, name + "_RBV", fl);
    };
    auto text = [&](const std::string& name) { add("waveform", name, {{"FTVL", "CHAR"}, {"NELM", "256"}}); };
    const detector::NdType type = detector::NdType(std::find_if(std::begin(detector::kNdTypeNames), std::end(detector::kNdTypeNames),
                                                                [&](const char* n) { return e.data_type == n; }) -
                                                   std::begin(detector::kNdTypeNames));
    // NDArrayBase's dimensions: NDimensions, ArraySize0..2 (the array's; _RBV alike)
    auto dims = [&](const std::string& q) {
        pair("longout", "longin", q + "NDimensions", {}, "2");
        for (const char* k : {"ArraySize0", "ArraySize1", "ArraySize2", "ArraySize0_RBV", "ArraySize1_RBV", "ArraySize2_RBV"}) add("longin", q + k, {});
    };
    // the driver: ADBase, NDArrayBase
    add("bo", c + "Acquire", {{"ZNAM", "Done"}, {"ONAM", "Acquire"}, {"VAL", "0"}, {"FLNK", c + "SetAcquireBusy"}});
    add("bi", c + "Acquire_RBV", {{"ZNAM", "Done"}, {"ONAM", "Acquiring"}, {"OSV", "MINOR"}});
    add("calcout", c + "SetAcquireBusy",
        {{"INPA", c + "Acquire NPP"}, {"CALC", "A"}, {"OOPT", "Transition To Non-zero"}, {"OUT", c + "AcquireBusy PP"}});
    add("busy", c + "AcquireBusy", {{"ZNAM", "Done"}, {"ONAM", "Acquiring"}, {"OSV", "MINOR"}, {"VAL", "0"}});
    add("bi", c + "AcquireBusyCB", {{"ZNAM", "Done"}, {"ONAM", "Acquiring"}, {"OSV", "MINOR"}});
    add("calcout", c + "ClearAcquireBusy",
        {{"INPA", c + "AcquireBusyCB CP"}, {"CALC", "A"}, {"OOPT", "Transition To Zero"}, {"OUT", c + "AcquireBusy PP"}});
    add("bo", c + "WaitForPlugins", with(kNoYes, {{"VAL", "1"}}));
    pair("ao", "ai", c + "AcquireTime", {{"PREC", "3"}, {"EGU", "s"}}, num(e.acquire_time));
    pair("ao", "ai", c + "AcquirePeriod", {{"PREC", "3"}, {"EGU", "s"}}, num(e.acquire_period));
    add("ai", c + "TimeRemaining_RBV", {{"PREC", "3"}, {"EGU", "s"}});
    pair("ao", "ai", c + "Gain", {{"PREC", "3"}}, num(e.gain));
    for (const char* k : {"BinX", "BinY"}) pair("longout", "longin", c + k, {}, "1");
    for (const char* k : {"MinX", "MinY"}) pair("longout", "longin", c + k, {}, "0");
    pair("longout", "longin", c + "SizeX", {}, std::to_string(e.size_x));
    pair("longout", "longin", c + "SizeY", {}, std::to_string(e.size_y));
    add("longin", c + "MaxSizeX_RBV", {});
    add("longin", c + "MaxSizeY_RBV", {});
    for (const char* k : {"ReverseX", "ReverseY"}) pair("bo", "bi", c + k, kNoYes, "0");
    pair("mbbo", "mbbi", c + "ImageMode", kImageModes, "0");
    pair("mbbo", "mbbi", c + "TriggerMode", kTriggerModes, "0");
    add("bo", c + "TriggerSoftware", {{"ZNAM", "Done"}, {"ONAM", "Trigger"}});
    pair("longout", "longin", c + "NumImages", {}, "1");
    add("longin", c + "NumImagesCounter_RBV", {});
    pair("longout", "longin", c + "NumExposures", {}, "1");
    add("longin", c + "NumExposuresCounter_RBV", {});
    add("mbbi", c + "DetectorState_RBV", with(kStates, {{"SXSV", "MAJOR"}, {"NISV", "INVALID"}}));
    text(c + "StatusMessage_RBV");
    pair("mbbo", "mbbi", c + "DataType", data_types(), std::to_string(int(type)));
    pair("mbbo", "mbbi", c + "ColorMode", kColorModes, "0");
    pair("longout", "longin", c + "ArrayCounter", {}, "0");
    add("ai", c + "ArrayRate_RBV", {{"PREC", "1"}, {"EGU", "Hz"}});
    pair("bo", "bi", c + "ArrayCallbacks", kDisableEnable, "1");
    for (const char* k : {"ArraySizeX_RBV", "ArraySizeY_RBV", "ArraySizeZ_RBV", "ArraySize_RBV", "UniqueId_RBV", "EpicsTSSec_RBV",
                          "EpicsTSNsec_RBV"})
        add("longin", c + k, {});
    dims(c);
    add("ai", c + "TimeStamp_RBV", {{"PREC", "3"}, {"EGU", "s"}});
    const Fields info = {{"Manufacturer_RBV", "beamctl"}, {"Model_RBV", "Simulated beam camera"}, {"SerialNumber_RBV", "sim-" + e.cam},
                         {"SDKVersion_RBV", "none"},      {"FirmwareVersion_RBV", "none"},        {"DriverVersion_RBV", "1.0"},
                         {"ADCoreVersion_RBV", "3.12.1 (names)"}, {"PortName_RBV", e.cam}};
    for (auto& [k, v] : info) add("stringin", c + k, {{"VAL", v}});
    // the plugins' common part (NDPluginBase)
    auto plugin = [&](const std::string& q, const char* kind) {
        add("stringin", q + "PluginType_RBV", {{"VAL", kind}});
        pair("stringout", "stringin", q + "NDArrayPort", {}, e.cam);
        add("stringin", q + "PortName_RBV", {{"VAL", q.substr(p.size(), q.size() - p.size() - 1)}});
        pair("bo", "bi", q + "EnableCallbacks", kDisableEnable, "1");
        pair("bo", "bi", q + "BlockingCallbacks", kNoYes, "0");
        pair("ao", "ai", q + "MinCallbackTime", {{"PREC", "3"}, {"EGU", "s"}}, "0");
        pair("longout", "longin", q + "ArrayCounter", {}, "0");
        pair("longout", "longin", q + "DroppedArrays", {}, "0");
        pair("longout", "longin", q + "QueueSize", {}, "16");
        add("longin", q + "QueueFree", {});
        add("ai", q + "ArrayRate_RBV", {{"PREC", "1"}, {"EGU", "Hz"}});
        add("ai", q + "ExecutionTime_RBV", {{"PREC", "3"}, {"EGU", "ms"}});
        for (const char* k : {"UniqueId_RBV", "ArraySizeX_RBV", "ArraySizeY_RBV", "ArraySizeZ_RBV", "ArraySize_RBV", "EpicsTSSec_RBV",
                              "EpicsTSNsec_RBV"})
            add("longin", q + k, {});
        add("longin", q + "UniqueId", {}); // pyepics' AD_ImagePlugin name (ADCore 1.x)
        dims(q);
        add("ai", q + "TimeStamp_RBV", {{"PREC", "3"}, {"EGU", "s"}});
        pair("mbbo", "mbbi", q + "DataType", data_types(), std::to_string(int(type)));
        pair("mbbo", "mbbi", q + "ColorMode", kColorModes, "0");
    };
    // image1: NDStdArrays
    plugin(im, "NDPluginStdArrays");
    add("waveform", im + "ArrayData", {{"FTVL", ftvl_of(type)}, {"NELM", std::to_string(std::size_t(e.size_x) * std::size_t(e.size_y))}});
    // HDF1: NDFile, NDFileHDF5
    plugin(h, "NDFileHDF5");
    for (const char* k : {"FilePath", "FilePath_RBV", "FileName", "FileName_RBV", "FileTemplate", "FileTemplate_RBV", "FullFileName_RBV",
                          "WriteMessage"})
        text(h + k);
    add("bi", h + "FilePathExists_RBV", kNoYes);
    pair("longout", "longin", h + "CreateDirectory", {}, "0");
    pair("longout", "longin", h + "FileNumber", {}, "1");
    pair("bo", "bi", h + "AutoIncrement", kNoYes, "1");
    pair("bo", "bi", h + "AutoSave", kNoYes, "0");
    add("busy", h + "WriteFile", {{"ZNAM", "Done"}, {"ONAM", "Write"}});
    add("bi", h + "WriteFile_RBV", {{"ZNAM", "Done"}, {"ONAM", "Writing"}});
    add("busy", h + "ReadFile", {{"ZNAM", "Done"}, {"ONAM", "Read"}});
    add("bi", h + "ReadFile_RBV", {{"ZNAM", "Done"}, {"ONAM", "Reading"}});
    pair("mbbo", "mbbi", h + "FileFormat", {{"ZRST", "HDF5"}}, "0");
    pair("mbbo", "mbbi", h + "FileWriteMode", kWriteModes, "0");
    add("busy", h + "Capture", {{"ZNAM", "Done"}, {"ONAM", "Capture"}});
    add("bi", h + "Capture_RBV", {{"ZNAM", "Done"}, {"ONAM", "Capturing"}});
    pair("longout", "longin", h + "NumCapture", {}, "1");
    add("longin", h + "NumCaptured_RBV", {});
    add("bi", h + "WriteStatus", {{"ZNAM", "Write OK"}, {"ONAM", "Write error"}, {"OSV", "MAJOR"}});
    add("ai", h + "RunTime", {{"PREC", "3"}, {"EGU", "s"}});
    add("ai", h + "IOSpeed", {{"PREC", "1"}, {"EGU", "Mbytes/s"}});
    pair("bo", "bi", h + "LazyOpen", kNoYes, "0");
    pair("mbbo", "mbbi", h + "Compression", {{"ZRST", "None"}}, "0");
    pair("bo", "bi", h + "SWMRMode", kNoYes, "0");
    // Stats1: NDStats
    plugin(s, "NDPluginStats");
    pair("bo", "bi", s + "ComputeStatistics", {{"ZNAM", "No"}, {"ONAM", "Yes"}}, "1");
    pair("bo", "bi", s + "ComputeCentroid", {{"ZNAM", "No"}, {"ONAM", "Yes"}}, "1");
    pair("longout", "longin", s + "BgdWidth", {}, "0");
    pair("ao", "ai", s + "CentroidThreshold", {{"PREC", "3"}}, "1");
    for (const char* k : {"MinValue_RBV", "MaxValue_RBV", "MeanValue_RBV", "Sigma_RBV", "Total_RBV", "Net_RBV", "MinX_RBV", "MinY_RBV",
                          "MaxX_RBV", "MaxY_RBV", "CentroidTotal_RBV", "CentroidX_RBV", "CentroidY_RBV", "SigmaX_RBV", "SigmaY_RBV",
                          "SigmaXY_RBV", "SkewX_RBV", "SkewY_RBV", "KurtosisX_RBV", "KurtosisY_RBV", "Eccentricity_RBV", "Orientation_RBV"})
        add("ai", s + k, {{"PREC", "3"}});
}

IocAreaDetector::IocAreaDetector(const config::IocConfig& cfg, pv::Database& db, std::function<double()> clock)
    : db_(db), clock_(std::move(clock)) {
    pv::DbFile f;
    std::vector<std::size_t> first;
    for (const config::AreaDetectorEntry& e : cfg.area_detector) {
        first.push_back(f.records.size());
        make_records(e, cfg.prefix, f);
        auto u = std::make_unique<Unit>();
        u->cfg = e;
        u->cam = cfg.prefix + e.cam + ":", u->image = cfg.prefix + e.image + ":", u->hdf = cfg.prefix + e.hdf + ":",
        u->stats = cfg.prefix + e.stats + ":";
        detector::CameraSensor sn;
        sn.max_x = e.size_x, sn.max_y = e.size_y, sn.pixel_size = e.pixel_size, sn.centre_x = e.centre_x, sn.centre_y = e.centre_y;
        sn.photons_per_flux = e.photons_per_flux, sn.dark = e.dark, sn.read_noise = e.read_noise;
        u->worker = std::make_unique<Worker>(sn);
        for (int t = 0; t < detector::kNdTypes; ++t)
            if (e.data_type == detector::kNdTypeNames[t]) u->image_type = detector::NdType(t);
        units_.push_back(std::move(u));
    }
    if (f.records.empty()) return;
    const std::vector<pv::DbRecord> defs = f.records;
    db_.load(f);
    for (std::size_t k = 0; k < units_.size(); ++k) {
        Unit& u = *units_[k];
        const std::size_t end = k + 1 < first.size() ? first[k + 1] : defs.size();
        for (std::size_t i = first[k]; i < end; ++i) {
            pv::Record* r = db_.find(defs[i].name);
            if (!r) throw Error(SB() << "area detector " << u.cfg.cam << ": record " << defs[i].name << " missing");
            u.rec[defs[i].name] = r;
            const std::string& n = defs[i].name;
            if (n.size() > 4 && n.compare(n.size() - 4, 4, "_RBV") == 0) r->val_read_only = true;
        }
        for (const char* k2 : {"TimeRemaining_RBV", "ArrayRate_RBV", "AcquireBusyCB"}) u.r(u.cam + k2).val_read_only = true;
        for (const char* k2 : {"QueueFree", "ArrayRate_RBV", "ExecutionTime_RBV"})
            for (const std::string* q : {&u.image, &u.hdf, &u.stats}) u.r(*q + k2).val_read_only = true;
        for (const char* k2 : {"WriteStatus", "WriteMessage", "RunTime", "IOSpeed"}) u.r(u.hdf + k2).val_read_only = true;
        hook(u);
    }
}

IocAreaDetector::~IocAreaDetector() = default;

std::size_t IocAreaDetector::busy() const {
    std::size_t n = 0;
    for (const auto& u : units_) n += u->worker->outstanding() + u->in_flight;
    return n;
}

std::size_t IocAreaDetector::busy_worker() const {
    std::size_t n = 0;
    for (const auto& u : units_) n += u->worker->outstanding();
    return n;
}

// An output's value into its readback: text for CHAR waveforms and strings, else the number.
void IocAreaDetector::copy_readback(pv::Record& out, pv::Record& rbv) {
    std::string_view type = out.type().name();
    if (type == "waveform") {
        set_text(db_, rbv, get_text(out));
    } else if (type == "stringout") {
        char s[pv::kStringSize] = {};
        db_.get(pv::Address{&out, out.type().find("VAL")}, pv::Prim::String, s, 1);
        set_string(db_, rbv, s);
    } else {
        set_value(db_, rbv, get_value(out), false);
    }
}

void IocAreaDetector::hook(Unit& u) {
    Unit* self = &u;
    // every output with a readback: the applied value into it (the camera's outputs clipped to the
    // sensor first)
    for (auto& entry : u.rec) {
        const std::string name = entry.first; // a copy the hook keeps (clang 14 cannot capture a binding)
        pv::Record* r = entry.second;
        const std::string rbv = name + "_RBV";
        if (!u.rec.count(rbv) || r->put_hook) continue;
        const bool camera = name.compare(0, u.cam.size(), u.cam) == 0;
        const bool is_text = std::string_view(r->type().name()) == "waveform";
        pv::Record* back = u.rec.find(rbv)->second;
        r->put_hook = [this, self, r, back, camera, is_text, name](pv::Record&, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            Unit& u2 = *self;
            if (name == u2.cam + "ColorMode" && get_value(*r) != 0) {
                LOG_WARN(lg, name << ": refused: the simulated camera is Mono");
                return pv::PutStatus::Failed;
            }
            if ((name == u2.cam + "AcquireTime" || name == u2.cam + "AcquirePeriod" || name == u2.cam + "Gain") && !(get_value(*r) >= 0)) {
                LOG_WARN(lg, name << ": " << get_value(*r) << " refused: should be >= 0");
                return pv::PutStatus::Failed;
            }
            if (name == u2.cam + "DataType") {
                const int t = int(get_value(*r));
                if (t == int(detector::NdType::Int64) || t == int(detector::NdType::UInt64) || t < 0 || t >= detector::kNdTypes) {
                    LOG_WARN(lg, name << ": refused: the camera makes Int8 .. UInt32, Float32, Float64 pixels");
                    return pv::PutStatus::Failed;
                }
            }
            if (name == u2.hdf + "FileTemplate") {
                std::string out, why;
                if (!format_file_name(get_text(*r), "", "", 0, out, why)) {
                    LOG_WARN(lg, name << ": refused: " << why);
                    return pv::PutStatus::Failed;
                }
            }
            if (name == u2.hdf + "FileWriteMode" && u2.capturing) {
                LOG_WARN(lg, name << ": refused while capturing");
                return pv::PutStatus::Failed;
            }
            if (camera && !is_text) {
                apply_camera(u2);
            } else if (std::string_view(r->type().name()) == "stringout") { // NDArrayPort: a string, not a number
                copy_readback(*r, *back);
            } else if (is_text) {
                std::string t = get_text(*r);
                if (name == u2.hdf + "FilePath") {
                    if (!t.empty() && t.back() != '/') t += '/';
                    struct stat st {};
                    set_value(db_, u2.r(u2.hdf + "FilePathExists_RBV"), !t.empty() && ::stat(t.c_str(), &st) == 0 && S_ISDIR(st.st_mode), false);
                }
                set_text(db_, *back, t);
            } else {
                set_value(db_, *back, get_value(*r), false);
            }
            return pv::PutStatus::Ok;
        };
    }
    u.r(u.cam + "Acquire").put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
        Unit& u2 = *self;
        if (get_value(r) != 0) {
            if (!u2.acquiring) start(u2, clock_());
        } else if (u2.acquiring) {
            u2.stopping = true; // the exposure in progress is abandoned; done when the frames are
        }
        return pv::PutStatus::Ok;
    };
    u.r(u.hdf + "Capture").put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
        Unit& u2 = *self;
        const bool on = get_value(r) != 0;
        if (on && int(get_value(u2.r(u2.hdf + "FileWriteMode"))) == kWriteSingle) {
            LOG_WARN(lg, r.name() << ": refused: Capture needs FileWriteMode Capture or Stream");
            set_text(db_, u2.r(u2.hdf + "WriteMessage"), "Capture needs FileWriteMode Capture or Stream");
            return pv::PutStatus::Failed;
        }
        if (on && int(get_value(u2.r(u2.hdf + "FileWriteMode"))) == kWriteCapture && get_value(u2.r(u2.hdf + "NumCapture")) < 1) {
            LOG_WARN(lg, r.name() << ": refused: NumCapture should be >= 1 in Capture mode");
            return pv::PutStatus::Failed;
        }
        file_command(u2, on ? Job::StartCapture : Job::StopCapture);
        set_value(db_, u2.r(u2.hdf + "Capture_RBV"), on, false);
        return pv::PutStatus::Ok;
    };
    u.r(u.hdf + "WriteFile").put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
        if (int(get_value(self->r(self->hdf + "FileWriteMode"))) == kWriteStream) {
            LOG_WARN(lg, r.name() << ": refused: in Stream mode the file is written as the frames come (Capture)");
            set_text(db_, self->r(self->hdf + "WriteMessage"), "WriteFile: in Stream mode the file is written as the frames come");
            return pv::PutStatus::Failed;
        }
        file_command(*self, Job::WriteFile);
        set_value(db_, self->r(self->hdf + "WriteFile_RBV"), 1, false);
        return pv::PutStatus::Ok;
    };
    u.r(u.hdf + "ReadFile").put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
        LOG_WARN(lg, r.name() << ": refused: the HDF5 plugin writes files, it does not read them back here");
        set_text(db_, self->r(self->hdf + "WriteMessage"), "ReadFile: refused: this plugin writes files, it does not read them");
        return pv::PutStatus::Failed;
    };
    u.r(u.cam + "TriggerSoftware").put_hook = [self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
        if (!self->acquiring || int(get_value(self->r(self->cam + "TriggerMode"))) != 1) {
            LOG_WARN(lg, r.name() << ": refused: a software trigger needs TriggerMode Software and Acquire 1");
            return pv::PutStatus::Failed;
        }
        ++self->triggers;
        return pv::PutStatus::Ok;
    };
    u.r(u.cam + "ArrayCounter").put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
        if (std::string_view(fd.name) == "VAL") {
            self->counter = int32_t(get_value(r));
            set_value(db_, self->r(self->cam + "ArrayCounter_RBV"), self->counter, false);
        }
        return pv::PutStatus::Ok;
    };
}

void IocAreaDetector::apply_camera(Unit& u) {
    detector::CameraSettings c;
    c.exposure = get_value(u.r(u.cam + "AcquireTime"));
    c.gain = get_value(u.r(u.cam + "Gain"));
    c.bin_x = int(get_value(u.r(u.cam + "BinX"))), c.bin_y = int(get_value(u.r(u.cam + "BinY")));
    c.min_x = int(get_value(u.r(u.cam + "MinX"))), c.min_y = int(get_value(u.r(u.cam + "MinY")));
    c.size_x = int(get_value(u.r(u.cam + "SizeX"))), c.size_y = int(get_value(u.r(u.cam + "SizeY")));
    c.reverse_x = get_value(u.r(u.cam + "ReverseX")) != 0, c.reverse_y = get_value(u.r(u.cam + "ReverseY")) != 0;
    c.type = detector::NdType(int(get_value(u.r(u.cam + "DataType"))));
    u.settings = detector::clip_settings(u.worker->camera.sensor(), c);
    const detector::CameraSettings& s = u.settings;
    auto rbv = [&](const char* k, double v) { set_value(db_, u.r(u.cam + k), v, false); };
    rbv("AcquireTime_RBV", s.exposure);
    rbv("AcquirePeriod_RBV", get_value(u.r(u.cam + "AcquirePeriod")));
    rbv("Gain_RBV", s.gain);
    rbv("BinX_RBV", s.bin_x), rbv("BinY_RBV", s.bin_y), rbv("MinX_RBV", s.min_x), rbv("MinY_RBV", s.min_y);
    rbv("SizeX_RBV", s.size_x), rbv("SizeY_RBV", s.size_y);
    rbv("ReverseX_RBV", s.reverse_x), rbv("ReverseY_RBV", s.reverse_y);
    rbv("DataType_RBV", double(int(s.type)));
    rbv("MaxSizeX_RBV", u.worker->camera.sensor().max_x), rbv("MaxSizeY_RBV", u.worker->camera.sensor().max_y);
    rbv("ImageMode_RBV", get_value(u.r(u.cam + "ImageMode")));
    rbv("TriggerMode_RBV", get_value(u.r(u.cam + "TriggerMode")));
    rbv("NumImages_RBV", get_value(u.r(u.cam + "NumImages")));
    rbv("NumExposures_RBV", get_value(u.r(u.cam + "NumExposures")));
    rbv("ColorMode_RBV", get_value(u.r(u.cam + "ColorMode")));
    rbv("ArrayCallbacks_RBV", get_value(u.r(u.cam + "ArrayCallbacks")));
    const int nx = s.size_x / s.bin_x, ny = s.size_y / s.bin_y;
    rbv("ArraySizeX_RBV", nx), rbv("ArraySizeY_RBV", ny), rbv("ArraySizeZ_RBV", 0);
    rbv("ArraySize_RBV", double(std::size_t(nx) * std::size_t(ny) * detector::nd_type_size(s.type)));
}

void IocAreaDetector::bind(const std::function<BeamSource(int bus)>& beam_of) {
    for (auto& up : units_) {
        Unit& u = *up;
        u.beam = beam_of ? beam_of(u.cfg.bus) : BeamSource{};
        if (!u.beam && u.cfg.bus >= 0)
            throw Error(SB() << u.cfg.where << ": area_detector " << u.cfg.cam << ": bus " << u.cfg.bus
                             << " has no simulated beam in this IOC (a sim link whose plant has a beam: section)");
        if (!u.beam) LOG_WARN(lg, u.cam << ": no simulated beam in this IOC: the camera takes dark frames");
    }
}

void IocAreaDetector::start() {
    for (auto& up : units_) {
        Unit& u = *up;
        // the text PVs' initial values (arrays take values once the records are initialised)
        if (get_text(u.r(u.hdf + "FileTemplate")).empty()) set_text(db_, u.r(u.hdf + "FileTemplate"), "%s%s_%3.3d.h5");
        if (get_text(u.r(u.hdf + "FileName")).empty()) set_text(db_, u.r(u.hdf + "FileName"), u.cfg.cam);
        if (get_text(u.r(u.hdf + "FilePath")).empty() && !u.cfg.file_path.empty()) set_text(db_, u.r(u.hdf + "FilePath"), u.cfg.file_path);
        for (auto& [name, r] : u.rec) { // the readbacks of what was configured or saved
            const std::string rbv = name + "_RBV";
            auto it = u.rec.find(rbv);
            if (it == u.rec.end() || !r->put_hook) continue;
            copy_readback(*r, *it->second);
        }
        apply_camera(u);
        std::string fp = get_text(u.r(u.hdf + "FilePath"));
        if (!fp.empty() && fp.back() != '/') set_text(db_, u.r(u.hdf + "FilePath"), fp += '/');
        set_text(db_, u.r(u.hdf + "FilePath_RBV"), fp);
        struct stat st {};
        set_value(db_, u.r(u.hdf + "FilePathExists_RBV"), !fp.empty() && ::stat(fp.c_str(), &st) == 0 && S_ISDIR(st.st_mode), false);
        set_value(db_, u.r(u.cam + "DetectorState_RBV"), kIdle, false);
        set_value(db_, u.r(u.cam + "AcquireBusyCB"), 0, false);
        for (const std::string* q : {&u.image, &u.hdf, &u.stats}) set_value(db_, u.r(*q + "QueueFree"), 16, false);
        set_text(db_, u.r(u.cam + "StatusMessage_RBV"), u.beam ? "Idle" : "Idle (no simulated beam: dark frames)");
        u.worker->start();
    }
}

void IocAreaDetector::start(Unit& u, double now_s) {
    apply_camera(u);
    u.acquiring = true, u.stopping = false;
    u.images = 0;
    set_value(db_, u.r(u.cam + "NumImagesCounter_RBV"), 0, false);
    set_value(db_, u.r(u.cam + "Acquire_RBV"), 1, false);
    set_value(db_, u.r(u.cam + "AcquireBusyCB"), 1, false);
    set_text(db_, u.r(u.cam + "StatusMessage_RBV"), "Acquiring");
    u.exposure_start = now_s;
    u.exposure_end = now_s + u.settings.exposure;
    u.triggers = 0;
    if (u.beam) u.tally0 = u.beam();
    const bool software = int(get_value(u.r(u.cam + "TriggerMode"))) == 1;
    set_value(db_, u.r(u.cam + "DetectorState_RBV"), software ? kWaiting : kAcquire, false);
}

void IocAreaDetector::finish(Unit& u) {
    u.acquiring = false, u.stopping = false;
    set_value(db_, u.r(u.cam + "DetectorState_RBV"), kIdle, false);
    set_value(db_, u.r(u.cam + "TimeRemaining_RBV"), 0, false);
    set_text(db_, u.r(u.cam + "StatusMessage_RBV"), "Acquisition complete");
    pv::Record& acq = u.r(u.cam + "Acquire");
    if (get_value(acq) != 0) set_value(db_, acq, 0, false); // no FLNK effect: SetAcquireBusy only sets on non-zero
    set_value(db_, u.r(u.cam + "Acquire_RBV"), 0, false);
    set_value(db_, u.r(u.cam + "AcquireBusyCB"), 0, false); // -> ClearAcquireBusy -> AcquireBusy 0
}

// The file plugin's settings as applied (the _RBV texts: FilePath with its trailing '/').
static FileSettings file_settings_of(const std::function<pv::Record&(const char*)>& r) {
    FileSettings fs;
    fs.path = get_text(r("FilePath_RBV")), fs.name = get_text(r("FileName_RBV")), fs.tmpl = get_text(r("FileTemplate_RBV"));
    fs.number = int(get_value(r("FileNumber")));
    fs.auto_increment = get_value(r("AutoIncrement")) != 0, fs.auto_save = get_value(r("AutoSave")) != 0;
    fs.mode = int(get_value(r("FileWriteMode"))), fs.num_capture = int(get_value(r("NumCapture")));
    return fs;
}

// The exposure that ended: its beam, a frame job for the worker.
void IocAreaDetector::expose(Unit& u, double now_s) {
    Job j;
    j.cam = u.settings;
    if (u.beam) {
        const ethercat::sim::BeamTally t1 = u.beam();
        const ethercat::sim::BeamExposure e = ethercat::sim::exposure(u.tally0, t1);
        j.spot.x = e.x, j.spot.y = e.y;
        j.spot.sigma_x = std::sqrt(e.sigma_x * e.sigma_x + e.var_x), j.spot.sigma_y = std::sqrt(e.sigma_y * e.sigma_y + e.var_y);
        j.spot.flux = e.flux; // the whole beam: the render cuts it at the aperture, pixel by pixel
        j.spot.left = e.left, j.spot.right = e.right, j.spot.bottom = e.bottom, j.spot.top = e.top;
        u.tally0 = t1;
    }
    j.uid = ++u.uid;
    u.counter += 1;
    j.timestamp = wall_epics_s();
    const bool callbacks = get_value(u.r(u.cam + "ArrayCallbacks")) != 0;
    j.image = callbacks && get_value(u.r(u.image + "EnableCallbacks")) != 0;
    j.stats = callbacks && get_value(u.r(u.stats + "EnableCallbacks")) != 0;
    j.hdf = callbacks && get_value(u.r(u.hdf + "EnableCallbacks")) != 0;
    j.compute_stats = get_value(u.r(u.stats + "ComputeStatistics")) != 0;
    j.compute_centroid = get_value(u.r(u.stats + "ComputeCentroid")) != 0;
    j.threshold = get_value(u.r(u.stats + "CentroidThreshold"));
    j.bgd_width = int(get_value(u.r(u.stats + "BgdWidth")));
    j.file = file_settings_of([&u](const char* k) -> pv::Record& { return u.r(u.hdf + k); });
    set_value(db_, u.r(u.cam + "ArrayCounter"), u.counter, false);
    set_value(db_, u.r(u.cam + "ArrayCounter_RBV"), u.counter, false);
    set_value(db_, u.r(u.cam + "UniqueId_RBV"), j.uid, false);
    set_value(db_, u.r(u.cam + "TimeStamp_RBV"), j.timestamp, false);
    set_value(db_, u.r(u.cam + "EpicsTSSec_RBV"), std::floor(j.timestamp), false);
    set_value(db_, u.r(u.cam + "EpicsTSNsec_RBV"), std::floor((j.timestamp - std::floor(j.timestamp)) * 1e9), false);
    set_value(db_, u.r(u.cam + "NDimensions_RBV"), 2, false);
    const int nx = u.settings.size_x / u.settings.bin_x, ny = u.settings.size_y / u.settings.bin_y;
    for (const char* k : {"ArraySize0", "ArraySize0_RBV"}) set_value(db_, u.r(u.cam + k), nx, false);
    for (const char* k : {"ArraySize1", "ArraySize1_RBV"}) set_value(db_, u.r(u.cam + k), ny, false);
    u.frame_times.push_back(now_s);
    while (!u.frame_times.empty() && u.frame_times.front() < now_s - 1) u.frame_times.pop_front();
    set_value(db_, u.r(u.cam + "ArrayRate_RBV"), double(u.frame_times.size()), false);
    if (j.image || j.stats || j.hdf) {
        if (u.worker->outstanding() >= 16) { // the plugins' queues are full: the frame is dropped
            ++u.dropped;
            for (const std::string* q : {&u.image, &u.hdf, &u.stats}) {
                set_value(db_, u.r(*q + "DroppedArrays"), clamp_long(u.dropped), false);
                set_value(db_, u.r(*q + "DroppedArrays_RBV"), clamp_long(u.dropped), false);
            }
        } else {
            ++u.in_flight;
            u.worker->submit(std::move(j));
        }
    }
    ++u.images;
    set_value(db_, u.r(u.cam + "NumImagesCounter_RBV"), u.images, false);
    set_value(db_, u.r(u.cam + "NumExposuresCounter_RBV"), 1, false);
}

void IocAreaDetector::file_command(Unit& u, int kind) {
    Job j;
    j.kind = Job::Kind(kind);
    j.cam = u.settings;
    j.file = file_settings_of([&u](const char* k) -> pv::Record& { return u.r(u.hdf + k); });
    if (kind == Job::StartCapture) ++u.pending_starts, u.capturing = true;
    if (kind == Job::WriteFile) u.write_pending = true;
    u.worker->submit(std::move(j));
}

void IocAreaDetector::take_results(Unit& u) {
    Result r;
    std::shared_ptr<detector::Frame> latest;
    while (u.worker->take(r)) {
        if (r.frame_done) {
            if (u.in_flight) --u.in_flight;
            if (r.to_image) latest = r.frame;
            const detector::Frame& f = *r.frame;
            for (const std::string* q : {&u.image, &u.hdf, &u.stats}) {
                if ((q == &u.image && !r.to_image) || (q == &u.hdf && !r.to_hdf) || (q == &u.stats && !r.to_stats)) continue;
                pv::Record& cnt = u.r(*q + "ArrayCounter");
                set_value(db_, cnt, get_value(cnt) + 1, false);
                set_value(db_, u.r(*q + "ArrayCounter_RBV"), get_value(cnt), false);
                set_value(db_, u.r(*q + "UniqueId_RBV"), f.unique_id, false);
                set_value(db_, u.r(*q + "UniqueId"), f.unique_id, false);
                set_value(db_, u.r(*q + "TimeStamp_RBV"), f.timestamp, false);
                set_value(db_, u.r(*q + "NDimensions_RBV"), 2, false);
                for (const char* k : {"ArraySize0", "ArraySize0_RBV"}) set_value(db_, u.r(*q + k), f.nx, false);
                for (const char* k : {"ArraySize1", "ArraySize1_RBV"}) set_value(db_, u.r(*q + k), f.ny, false);
                set_value(db_, u.r(*q + "ArraySizeX_RBV"), f.nx, false);
                set_value(db_, u.r(*q + "ArraySizeY_RBV"), f.ny, false);
                set_value(db_, u.r(*q + "ArraySize_RBV"), double(f.data.size()), false);
                set_value(db_, u.r(*q + "DataType_RBV"), double(int(f.type)), false);
            }
            if (r.has_stats) { // the statistics plugin had it
                const detector::FrameStats& s = r.stats;
                const std::pair<const char*, double> v[] = {
                    {"MinValue_RBV", s.min},        {"MaxValue_RBV", s.max},           {"MeanValue_RBV", s.mean},
                    {"Sigma_RBV", s.sigma},         {"Total_RBV", s.total},            {"Net_RBV", s.net},
                    {"MinX_RBV", s.min_x},          {"MinY_RBV", s.min_y},             {"MaxX_RBV", s.max_x},
                    {"MaxY_RBV", s.max_y},          {"CentroidTotal_RBV", s.centroid_total}, {"CentroidX_RBV", s.centroid_x},
                    {"CentroidY_RBV", s.centroid_y}, {"SigmaX_RBV", s.sigma_x},         {"SigmaY_RBV", s.sigma_y},
                    {"SigmaXY_RBV", s.sigma_xy},    {"SkewX_RBV", s.skew_x},           {"SkewY_RBV", s.skew_y},
                    {"KurtosisX_RBV", s.kurtosis_x}, {"KurtosisY_RBV", s.kurtosis_y},  {"Eccentricity_RBV", s.eccentricity},
                    {"Orientation_RBV", s.orientation}};
                for (auto& [k, x] : v) set_value(db_, u.r(u.stats + k), x, false);
                set_value(db_, u.r(u.stats + "ExecutionTime_RBV"), r.stats_seconds * 1e3, false);
            }
            if (r.to_hdf) set_value(db_, u.r(u.hdf + "ExecutionTime_RBV"), r.file_seconds * 1e3, false);
        }
        // the file plugin's state after every job
        set_value(db_, u.r(u.hdf + "NumCaptured_RBV"), r.num_captured, false);
        if (int(get_value(u.r(u.hdf + "FileNumber"))) != r.file_number) {
            set_value(db_, u.r(u.hdf + "FileNumber"), r.file_number, false);
            set_value(db_, u.r(u.hdf + "FileNumber_RBV"), r.file_number, false);
        }
        if (!r.full_name.empty() && get_text(u.r(u.hdf + "FullFileName_RBV")) != r.full_name)
            set_text(db_, u.r(u.hdf + "FullFileName_RBV"), r.full_name);
        if (r.write_error || r.wrote) {
            set_value(db_, u.r(u.hdf + "WriteStatus"), r.write_error, false);
            set_text(db_, u.r(u.hdf + "WriteMessage"), r.write_error ? r.message : "");
            if (r.write_error) LOG_WARN(lg, u.hdf << ": " << r.message);
            if (r.wrote) {
                set_value(db_, u.r(u.hdf + "RunTime"), r.run_time, false);
                set_value(db_, u.r(u.hdf + "IOSpeed"), r.io_mb_s, false);
            }
        }
        if (r.kind == Job::StartCapture && u.pending_starts > 0) --u.pending_starts;
        if (r.kind == Job::WriteFile) {
            {
                u.write_pending = false;
                set_value(db_, u.r(u.hdf + "WriteFile_RBV"), 0, false);
                pv::Record& wf = u.r(u.hdf + "WriteFile");
                if (get_value(wf) != 0) set_value(db_, wf, 0, false);
            }
        }
        u.capturing = r.capturing || u.pending_starts > 0;
        if (!r.capturing && u.pending_starts == 0) {
            pv::Record& cap = u.r(u.hdf + "Capture");
            if (get_value(cap) != 0) set_value(db_, cap, 0, false); // done: the put-callback completes
            if (get_value(u.r(u.hdf + "Capture_RBV")) != 0) set_value(db_, u.r(u.hdf + "Capture_RBV"), 0, false);
        }
    }
    if (latest) {
        pv::Record& data = u.r(u.image + "ArrayData");
        const pv::FieldDesc* fd = data.type().find("VAL");
        const pv::Elements e = data.elements(*fd);
        if (latest->type == u.image_type && e.stride == detector::nd_type_size(latest->type))
            set_array_raw(db_, data, latest->data.data(), uint32_t(latest->data.size() / e.stride));
        else { // the waveform's FTVL is another type (DataType changed since start-up): convert
            std::vector<double> v(latest->data.size() / detector::nd_type_size(latest->type));
            for (std::size_t i = 0; i < v.size(); ++i) v[i] = latest->value(i);
            set_array(db_, data, v.data(), uint32_t(v.size()));
        }
    }
}

void IocAreaDetector::poll(double now_s) {
    for (auto& up : units_) {
        Unit& u = *up;
        take_results(u);
        if (!u.acquiring) continue;
        if (u.stopping) {
            if (u.in_flight == 0) finish(u);
            continue;
        }
        const int mode = int(get_value(u.r(u.cam + "ImageMode")));
        const int want = std::max(1, int(get_value(u.r(u.cam + "NumImages"))));
        const bool last_done = (mode == kSingle && u.images >= 1) || (mode == kMultiple && u.images >= want);
        if (last_done) {
            if (u.in_flight == 0) finish(u);
            continue;
        }
        const bool software = int(get_value(u.r(u.cam + "TriggerMode"))) == 1;
        if (software && now_s >= u.exposure_start && int(get_value(u.r(u.cam + "DetectorState_RBV"))) != kAcquire) {
            if (u.triggers == 0) { // waiting for TriggerSoftware
                if (int(get_value(u.r(u.cam + "DetectorState_RBV"))) != kWaiting) set_value(db_, u.r(u.cam + "DetectorState_RBV"), kWaiting, false);
                continue;
            }
            --u.triggers;
            u.exposure_start = now_s, u.exposure_end = now_s + u.settings.exposure;
        }
        if (now_s < u.exposure_start) { // waiting for the period
            set_value(db_, u.r(u.cam + "TimeRemaining_RBV"), u.exposure_start - now_s, false);
            continue;
        }
        if (int(get_value(u.r(u.cam + "DetectorState_RBV"))) != kAcquire) {
            set_value(db_, u.r(u.cam + "DetectorState_RBV"), kAcquire, false);
            if (u.beam) u.tally0 = u.beam();
        }
        if (now_s < u.exposure_end) {
            set_value(db_, u.r(u.cam + "TimeRemaining_RBV"), u.exposure_end - now_s, false);
            continue;
        }
        expose(u, now_s);
        const bool more = mode == kContinuous || (mode == kMultiple && u.images < want);
        if (!more) {
            set_value(db_, u.r(u.cam + "DetectorState_RBV"), kReadout, false);
            continue;
        }
        const double period = std::max(get_value(u.r(u.cam + "AcquirePeriod")), u.settings.exposure);
        u.exposure_start = std::max(u.exposure_start + period, now_s);
        u.exposure_end = u.exposure_start + u.settings.exposure;
        // waiting for the period, or (Software) for the next trigger whatever the period
        if (u.exposure_start > now_s || software) set_value(db_, u.r(u.cam + "DetectorState_RBV"), kWaiting, false);
    }
}

} // namespace beamctl::ioc
