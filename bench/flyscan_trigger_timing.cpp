// Trigger timing of a distance-based position compare, plain digital output (EL2808: the edge
// leaves with the next frame) against DC-timestamped output (EL2252: the edge at the predicted
// crossing time), at 1, 5 and 10 kHz. The IOC of examples/flyscan/timestamped.yaml runs in virtual
// time (the simulator's frames pass at the cycle times; the figures are the method's, not a
// network's); the spiral arc moves 0 -> 30 mm at 1 mm/s with a pulse every 0.8 mm, and an EL1252
// latches the DC time of both outputs' edges. The error of an edge is its latched time minus the
// time the compared input crossed the point (linear between its samples, each at the DC time of
// the frame that sampled it). Reported per rate and input (the trajectory setpoint, a smooth
// input; the encoder readback of the stepper XY stage, through the kinematics): mean and largest
// error at constant velocity (1 mm .. 29 mm), and all edges.
//   bench_flyscan_trigger_timing [SOURCE_DIR]
#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "pv/database.hpp"
#include "rt/engine.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace beamctl;

namespace {

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
    for (std::size_t p = 0; (p = s.find(from, p)) != std::string::npos; p += to.size()) s.replace(p, from.size(), to);
    return s;
}

struct Stats {
    double mean = 0, max_abs = 0;
    int n = 0;
    void add(double e) {
        mean += e;
        max_abs = std::max(max_abs, std::fabs(e));
        ++n;
    }
    double avg() const { return n ? mean / n : 0; }
};

void put(ioc::Ioc& ioc, const std::string& name, double v) {
    pv::Address a;
    if (!ioc.database().resolve(name, a)) throw std::runtime_error("no PV " + name);
    ioc.database().put(a, pv::Prim::Double, &v, 1);
}

void run(const std::string& src, const std::filesystem::path& dir, int rate, const std::string& input) {
    std::ifstream in(src + "/examples/flyscan/timestamped.yaml");
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    text = replace_all(text, "rate_hz: 1000", "rate_hz: " + std::to_string(rate));
    text = replace_all(text, "input: ax3.traj.setpos", "input: " + input);
    text = replace_all(text, "../", src + "/examples/");
    text = replace_all(text, "plant: timestamped_plant.yaml", "plant: " + src + "/examples/flyscan/timestamped_plant.yaml");
    const auto path = dir / ("ts_" + std::to_string(rate) + ".yaml");
    std::ofstream(path) << text;

    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(path.string()), clock);
    ioc.bring_up();
    const int per_publish = std::max(1, rate / 100);
    auto cycles = [&](int n) {
        for (int k = 0; k < n; ++k) {
            ioc.engine().run_cycles(1);
            if (k % per_publish == 0) ioc.publish();
        }
    };
    cycles(rate / 5);
    put(ioc, "FLY:PCOMP1:ENABLE", 1);
    put(ioc, "FLY:PCOMP3:ENABLE", 1);
    const int arc_i = ioc.axes().find("SpiralL");
    motion::Axis& arc = ioc.axes().group()->axis(std::size_t(arc_i));
    ioc.axes().send(std::size_t(arc_i), motion::AxisCommand{motion::CommandType::MoveAbsolute, 30});
    std::string why;
    registry::BoundSignal plain = ioc.signals().bind("ec0.s5.timestampLatchPositive01", why),
                          timed = ioc.signals().bind("ec0.s5.timestampLatchPositive02", why);
    const bool setpos = input.find("setpos") != std::string::npos;
    std::vector<std::pair<uint64_t, double>> samples;
    std::vector<uint64_t> plain_rises, timed_rises;
    uint64_t lp = plain.get_raw(), lt = timed.get_raw();
    const uint64_t t0 = ioc.bus(0).dc_time();
    bool moving = true;
    for (int k = 0; k < rate * 40 && (moving || k < rate / 10); ++k) {
        ioc.engine().run_cycles(1);
        samples.emplace_back(ioc.bus(0).dc_time(), setpos ? arc.variables().traj.setpos : arc.variables().enc.actpos);
        if (plain.get_raw() != lp) plain_rises.push_back(lp = plain.get_raw());
        if (timed.get_raw() != lt) timed_rises.push_back(lt = timed.get_raw());
        moving = arc.status().busy;
    }
    auto rel = [&](uint64_t t) { return double(int64_t(t - t0)); };
    auto ideal = [&](double p) -> double {
        for (std::size_t i = 1; i < samples.size(); ++i)
            if (samples[i - 1].second < p && samples[i].second >= p)
                return rel(samples[i - 1].first) +
                       (p - samples[i - 1].second) / (samples[i].second - samples[i - 1].second) * double(samples[i].first - samples[i - 1].first);
        return NAN;
    };
    Stats pc, tc, pa, ta;
    const std::size_t n = std::min(plain_rises.size(), timed_rises.size());
    for (std::size_t i = 0; i < n; ++i) {
        const double p = 0.8 * double(i + 1), t = ideal(p);
        if (std::isnan(t)) continue;
        const double ep = rel(plain_rises[i]) - t, et = rel(timed_rises[i]) - t;
        pa.add(ep);
        ta.add(et);
        if (p > 1.0 && p < 29.0) {
            pc.add(ep);
            tc.add(et);
        }
    }
    const auto* out = ioc.flyscan().timed_output(1);
    std::printf("%6d Hz  %-16s edges %2zu/%2zu  constant v: plain mean %8.1f us max %8.1f us | timestamped mean %7.3f us max %7.3f us"
                "  | all edges: timestamped max %7.3f us  late %llu\n",
                rate, input.c_str(), plain_rises.size(), timed_rises.size(), pc.avg() * 1e-3, pc.max_abs * 1e-3, tc.avg() * 1e-3,
                tc.max_abs * 1e-3, ta.max_abs * 1e-3, static_cast<unsigned long long>(out ? out->late() : 0));
    std::fflush(stdout);
}

} // namespace

int main(int argc, char** argv) {
    const std::string src = argc > 1 ? argv[1] : BEAMCTL_SOURCE_DIR;
    const auto dir = std::filesystem::temp_directory_path() / ("bench_trigger_timing_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    try {
        for (const char* input : {"ax3.traj.setpos", "ax3.enc.actpos"})
            for (int rate : {1000, 5000, 10000}) run(src, dir, rate, input);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_flyscan_trigger_timing: %s\n", e.what());
        std::filesystem::remove_all(dir);
        return 1;
    }
    std::filesystem::remove_all(dir);
    return 0;
}
