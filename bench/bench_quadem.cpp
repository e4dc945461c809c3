// Quad electrometer cost (issue 16: quadEM at 10 kHz with 100-sample averaging, CPU):
//   BM_QuadEmSample       the cycle's part per sample: quadEM's 11 values from four currents and
//                         the running mean/sigma/min/max, a reading every 100 samples;
//   BM_QuadEmIocReading   the IOC loop's part per reading: the reading taken from the queue and
//                         its 55 averaged and statistics PVs and counters set and posted (no CA
//                         client), on examples/bpm at 10 kHz with AveragingTime 0.01 s.
// At 10 kHz with 100-sample averaging: 10 000 samples and 100 readings per second; the CPU share is
// 10 000 x BM_QuadEmSample + 100 x BM_QuadEmIocReading.
#include "config/ioc_config.hpp"
#include "detector/quadem.hpp"
#include "ioc/ioc.hpp"
#include "rt/engine.hpp"

#include <benchmark/benchmark.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>

using namespace beamctl;

namespace {

void BM_QuadEmSample(benchmark::State& st) {
    detector::QuadEmParams p;
    p.num_average = 100;
    detector::QuadEm q(p);
    detector::QuadEmReading r;
    double raw[4] = {1.0, 1.1, 0.9, 1.05};
    uint64_t cycle = 0;
    for (auto _ : st) {
        raw[0] += 1e-6;
        q.sample(raw, true, ++cycle);
        if (cycle % 100 == 0) q.pop(r); // the IOC loop's side, so the queue never fills
        benchmark::DoNotOptimize(q.values());
    }
}
BENCHMARK(BM_QuadEmSample);

void BM_QuadEmIocReading(benchmark::State& st) {
    const std::string dir = std::string(BEAMCTL_SOURCE_DIR) + "/examples/bpm/";
    std::ifstream in(dir + "ioc.yaml");
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    auto replace = [&](const std::string& a, const std::string& b) { text.replace(text.find(a), a.size(), b); };
    replace("rate_hz: 1000", "rate_hz: 10000");
    replace("averaging_time: 0.1", "averaging_time: 0.01");
    replace("plant: plant.yaml", "plant: " + dir + "plant.yaml");
    replace("file: ../", "file: " + dir + "../");
    char path[] = "/tmp/bench_quadem_XXXXXX.yaml";
    int fd = mkstemps(path, 5);
    if (fd < 0 || write(fd, text.data(), text.size()) != ssize_t(text.size())) {
        st.SkipWithError("cannot write the IOC file");
        return;
    }
    close(fd);
    rt::VirtualClock clock;
    ioc::Ioc ioc(config::IocConfig::load(path), clock);
    ioc.bring_up();
    std::remove(path);
    ioc.run_cycles(3000);
    ioc.publish();
    for (auto _ : st) {
        st.PauseTiming();
        ioc.run_cycles(100); // one reading
        st.ResumeTiming();
        ioc.publish(); // everything the IOC loop publishes; the quadEM reading is nearly all of it
    }
}
BENCHMARK(BM_QuadEmIocReading);

} // namespace

BENCHMARK_MAIN();
