// Bus scanner latency (issue 14), one process, real time (CLOCK_MONOTONIC, SCHED_FIFO when allowed):
// a `Scanner` on a simulated bus serves N minimal IOCs, each a Bus on a scanner::ClientBackend with
// its own engine whose only stage copies an input bit to its own output bit (what a PLC
// `ec0.s2.binaryOutput0k := ec0.s3.binaryInput0k` does). Measured per point (N clients, rate):
//   A  bus -> client: the client's cycle start minus the scanner's publication of that cycle,
//   B  client output -> frame: the scanner's merge of a commit minus the commit (the frame is sent
//      right after the merge, in the same cycle),
//   scanner CPU per client per cycle: the fanout + gather stage time per cycle, divided by N.
// Reference, same run: the same minimal IOC on a local master (in-process segment): its wake-up
// latency (cycle start minus its scheduled time), which is what an IOC on its own bus pays.
// Each point runs with the scanner's gather window 0 (client outputs go in the next cycle's frame)
// and 0.5 (the scanner waits up to half a cycle for the clients' answers to this cycle).
// Usage: bench_scanner_latency [SECONDS_PER_POINT=2] [RATES=1000,5000,10000] [CLIENTS=1,3,8] [WINDOWS=0,0.5]
#include "core/event_loop.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/local_bus.hpp"
#include "scanner/client.hpp"
#include "scanner/scanner.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <sstream>
#include <thread>
#include <unistd.h>

using namespace beamctl;

namespace {

const char* kChain = R"(
    slaves:
      - {position: 0, type: EK1100, name: COUPLER}
      - {position: 1, type: EL1008, name: IN}
      - {position: 2, type: EL2008, name: OUT}
      - {position: 3, type: EL7041, name: M1}
)";

// The minimal IOC's work: copy IN bit k to OUT bit k; record A (or, locally, the wake-up latency).
struct CopyStage : rt::Stage {
    registry::BoundSignal in, out;
    rt::Clock& clock;
    std::vector<uint32_t> samples; // [ns], preallocated
    std::size_t n = 0;
    CopyStage(registry::BoundSignal i, registry::BoundSignal o, rt::Clock& c, std::size_t cap) : in(i), out(o), clock(c), samples(cap) {}
    const char* name() const noexcept override { return "copy"; }
    void run(const rt::CycleInfo& c) noexcept override {
        uint64_t now = clock.now_ns();
        if (n < samples.size()) samples[n++] = uint32_t(std::min<uint64_t>(now > c.t_ns ? now - c.t_ns : 0, UINT32_MAX));
        out.set(in.get());
    }
};

struct Pct {
    double p50 = 0, p99 = 0, max = 0;
};
Pct percentiles(std::vector<uint32_t> v) {
    Pct p;
    if (v.empty()) return p;
    std::sort(v.begin(), v.end());
    p.p50 = v[v.size() / 2] / 1000.0;
    p.p99 = v[std::min(v.size() - 1, v.size() * 99 / 100)] / 1000.0;
    p.max = v.back() / 1000.0;
    return p;
}
Pct percentiles_hist(const std::array<uint64_t, scanner::kOutLatencyBins>& h) {
    Pct p;
    uint64_t total = 0;
    for (auto x : h) total += x;
    if (!total) return p;
    uint64_t acc = 0;
    bool got50 = false;
    for (std::size_t i = 0; i < h.size(); ++i) {
        acc += h[i];
        if (!got50 && acc * 2 >= total) p.p50 = double(i) + 0.5, got50 = true;
        if (acc * 100 >= total * 99) {
            p.p99 = double(i) + 0.5;
            break;
        }
    }
    for (std::size_t i = h.size(); i-- > 0;)
        if (h[i]) {
            p.max = double(i) + 1;
            break;
        }
    return p;
}

std::vector<double> list_of(const char* s, std::vector<double> def) {
    if (!s) return def;
    std::vector<double> v;
    std::stringstream ss(s);
    std::string t;
    while (std::getline(ss, t, ',')) v.push_back(std::atof(t.c_str()));
    return v;
}

Pct local_reference(const ethercat::Catalog& cat, const std::string& dir, int rate, double secs) {
    std::string path = dir + "/local.yaml";
    std::ofstream(path) << "scanner: {socket: unused.sock}\nengine: {rate_hz: " << rate << "}\nbuses:\n  - id: 0\n    link: {type: sim}"
                        << kChain;
    scanner::ScannerConfig sc = scanner::ScannerConfig::load(path);
    rt::MonotonicClock clock;
    ethercat::sim::LocalBus lb = ethercat::sim::make_local_bus(sc.buses[0], cat, path);
    rt::EngineConfig ec;
    ec.rate_hz = rate;
    rt::Engine eng(ec, clock);
    lb.bus->add_stages(eng);
    if (lb.sim_stage) eng.add_stage(rt::StageOrder::BusSend, *lb.sim_stage);
    lb.bus->bring_up();
    CopyStage st(lb.bus->bind("ec0.s1.binaryInput01"), lb.bus->bind("ec0.s2.binaryOutput01"), clock, std::size_t(rate * secs * 2));
    eng.add_stage(rt::StageOrder::Axes, st);
    eng.start();
    std::this_thread::sleep_for(std::chrono::duration<double>(secs));
    eng.stop();
    st.samples.resize(st.n);
    return percentiles(st.samples);
}

} // namespace

int main(int argc, char** argv) {
    log::configure("warn");
    const double secs = argc > 1 ? std::atof(argv[1]) : 2.0;
    const std::vector<double> rates = list_of(argc > 2 ? argv[2] : nullptr, {1000, 5000, 10000});
    const std::vector<double> counts = list_of(argc > 3 ? argv[3] : nullptr, {1, 3, 8});
    const std::vector<double> windows = list_of(argc > 4 ? argv[4] : nullptr, {0, 0.5});
    const ethercat::Catalog& cat = ethercat::Catalog::builtin();
    char tmpl[] = "/tmp/beamctl_scanner_bench_XXXXXX";
    const std::string dir = ::mkdtemp(tmpl);
    std::printf("bus scanner latency, %.1f s per point, %u CPUs; [us] p50 / p99 / max\n", secs, std::thread::hardware_concurrency());
    std::printf("%6s %7s %6s | %-26s | %-26s | %-26s | %s\n", "rate", "clients", "window", "A: bus -> client cycle", "B: output -> frame",
                "local master wake-up (ref)", "scanner CPU/client/cycle");
    for (double rate_d : rates) {
        const int rate = int(rate_d);
        Pct ref = local_reference(cat, dir, rate, secs);
        for (double n_d : counts)
        for (double window : windows) {
            const int n = int(n_d);
            std::string path = dir + "/scanner.yaml";
            std::ofstream(path) << "scanner: {socket: " << dir << "/s.sock, depth: 1024, gather_window: " << window
                                << "}\nengine: {rate_hz: " << rate
                                << "}\nbuses:\n  - id: 0\n    link: {type: sim}" << kChain;
            rt::MonotonicClock clock;
            scanner::Scanner sc(scanner::ScannerConfig::load(path), cat, clock);
            sc.start();
            EventLoop loop;
            sc.serve(loop);
            std::thread lt([&] { loop.run(); });
            struct C {
                std::unique_ptr<ethercat::Bus> bus;
                std::unique_ptr<rt::Engine> eng;
                std::unique_ptr<CopyStage> st;
            };
            std::vector<C> cs(static_cast<std::size_t>(n));
            for (int i = 0; i < n; ++i) {
                scanner::ClientConfig cc;
                cc.socket = dir + "/s.sock";
                cc.ioc = "bench" + std::to_string(i);
                cc.slaves = {"IN", "OUT"};
                char entry[32];
                std::snprintf(entry, sizeof entry, "binaryOutput%02d", i % 8 + 1);
                if (i < 8) cc.claims = {{"OUT", entry}};
                C& c = cs[std::size_t(i)];
                c.bus = std::make_unique<ethercat::Bus>(0, std::make_unique<scanner::ClientBackend>(cc));
                rt::EngineConfig ec;
                ec.rate_hz = rate;
                c.eng = std::make_unique<rt::Engine>(ec, clock);
                c.bus->add_stages(*c.eng); // the engine's period first: bring-up checks it against the scanner's
                c.bus->bring_up();
                char in[32];
                std::snprintf(in, sizeof in, "ec0.s1.binaryInput%02d", i % 8 + 1);
                c.st = std::make_unique<CopyStage>(c.bus->bind(in), c.bus->bind(std::string("ec0.s2.") + entry), clock,
                                                   std::size_t(rate * secs * 2));
                c.eng->add_stage(rt::StageOrder::Axes, *c.st);
            }
            for (auto& c : cs) c.eng->start();
            std::this_thread::sleep_for(std::chrono::milliseconds(300)); // settle
            sc.engine().request_reset();
            for (auto& c : cs) c.st->n = 0;
            std::this_thread::sleep_for(std::chrono::duration<double>(secs));
            std::vector<uint32_t> a;
            for (auto& c : cs) a.insert(a.end(), c.st->samples.begin(), c.st->samples.begin() + std::ptrdiff_t(c.st->n));
            rt::EngineStats es = sc.engine().stats();
            for (auto& c : cs) c.eng->stop();
            std::array<uint64_t, scanner::kOutLatencyBins> hist{};
            std::vector<scanner::Scanner::ClientFigures> figs;
            std::promise<void> done;
            loop.post([&] {
                figs = sc.client_figures();
                done.set_value();
            });
            done.get_future().wait();
            for (const auto& f : figs)
                for (std::size_t i = 0; i < hist.size(); ++i) hist[i] += f.out_latency_us[i];
            double stage_ns = 0;
            for (const auto& s : es.stages)
                if (s.name == "fanout" || s.name == "gather") stage_ns += double(s.total_ns);
            const double cycles = double(es.latency_samples ? es.latency_samples : 1);
            Pct pa = percentiles(a), pb = percentiles_hist(hist);
            char cpu[32] = "(gather waits)"; // with a window the gather stage's time is mostly waiting
            if (window == 0) std::snprintf(cpu, sizeof cpu, "%.2f us", stage_ns / cycles / 1000.0 / n);
            uint64_t missed = 0;
            for (const auto& f : figs) missed += f.missed_window;
            std::printf("%6d %7d %6.2f | %7.1f / %7.1f / %8.1f | %7.1f / %7.1f / %8.1f | %7.1f / %7.1f / %8.1f | %s%s\n", rate, n,
                        window, pa.p50, pa.p99, pa.max, pb.p50, pb.p99, pb.max, ref.p50, ref.p99, ref.max, cpu,
                        missed ? (" (window missed " + std::to_string(missed) + "x)").c_str() : "");
            std::fflush(stdout);
            cs.clear();
            loop.stop();
            lt.join();
            sc.stop("benchmark done");
        }
    }
    std::filesystem::remove_all(dir);
    return 0;
}
