// EtherCAT cycle cost for a 40-terminal segment:
//   BM_MasterCycle40: the master alone (send + receive + WKC check) over an echo link, i.e. the
//     master CPU per cycle that the target (<= 5 us) is about;
//   BM_SimulatedCycle40: master + in-process simulator (every ESC processing the frame);
//   BM_SimulatedCycle40WithPlant: the same with the terminal and plant models running after each
//     frame (6 drives moving stages, 12 analog signals, a wire), 1 ms of simulated time per cycle;
//   BM_UdpRoundTrip40, BM_VethRoundTrip40: master and simulator on two CPUs, over UDP loopback
//     and over a veth pair with raw sockets (the latter needs root; bench/veth_rate.sh measures
//     the cycle rate with `beamctl run` and `beamctl sim --iface` as separate processes).
#include "ethercat/catalog.hpp"
#include "ethercat/master.hpp"
#include "ethercat/raw_link.hpp"
#include "ethercat/sim/raw_server.hpp"
#include "ethercat/sim/segment.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <pthread.h>
#include <thread>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>

using namespace beamctl::ethercat;

namespace {

const char* kMix[] = {"EL1008", "EL2008", "EL3104", "EL4134", "EL5101", "EL7041", "EL7211",
                      "EL5042", "EL3102", "EL4102", "EL1252", "EL2808", "EL1008"};

std::vector<std::string> forty() {
    std::vector<std::string> v{"EK1100"};
    for (int i = 0; v.size() < 40; ++i) v.push_back(kMix[i % 13]);
    return v;
}

// Returns each sent frame as it is (an ideal wire with no slaves doing work).
class EchoLink : public Link {
public:
    bool send(const uint8_t* f, std::size_t n) noexcept override {
        std::memcpy(buf_[head_ % 4], f, n);
        len_[head_++ % 4] = n;
        return true;
    }
    std::size_t receive(uint8_t* b, std::size_t, int) noexcept override {
        if (tail_ == head_) return 0;
        std::size_t n = len_[tail_ % 4];
        std::memcpy(b, buf_[tail_++ % 4], n);
        return n;
    }
    const char* kind() const noexcept override { return "echo"; }

private:
    uint8_t buf_[4][kMaxFrame];
    std::size_t len_[4];
    unsigned head_ = 0, tail_ = 0;
};

struct Fixture {
    sim::Segment seg;
    InProcessLink link{seg};
    std::unique_ptr<Master> m;
    std::shared_ptr<sim::Plant> plant;
    explicit Fixture(bool with_plant = false) {
        std::vector<SlaveConfig> cfg;
        auto types = forty();
        for (std::size_t i = 0; i < types.size(); ++i) {
            seg.add(*Catalog::builtin().find(types[i]));
            cfg.push_back({int(i), types[i]});
        }
        if (with_plant) {
            // Default stages for every drive, a generator on every EL3104 channel, a DO->DI wire.
            std::string yaml = "signals:\n";
            for (std::size_t i = 0; i < types.size(); ++i)
                if (types[i] == "EL3104")
                    for (int ch = 1; ch <= 4; ++ch)
                        yaml += "  - {to: s" + std::to_string(i) + ".analogInput0" + std::to_string(ch) +
                                ", shape: sine, amplitude: 5, frequency: 3}\n";
            yaml += "wiring:\n  - {from: s2.binaryOutput01, to: s1.binaryInput01}\n";
            plant = sim::SimConfig::parse(yaml, "bench", Catalog::builtin()).build(seg, Catalog::builtin());
        }
        m = std::make_unique<Master>(link, 0, cfg, Catalog::builtin());
        m->bring_up();
    }
};

void BM_SimulatedCycle40(benchmark::State& st) {
    Fixture f;
    for (auto _ : st) {
        f.m->send_process_data();
        benchmark::DoNotOptimize(f.m->receive_process_data(0));
    }
    st.counters["image_bytes"] = double(f.m->bus_bytes());
    st.counters["wkc_ok"] = f.m->wkc() == f.m->expected_wkc();
}
BENCHMARK(BM_SimulatedCycle40);

void BM_SimulatedCycle40WithPlant(benchmark::State& st) {
    Fixture f(true);
    // enable every drive (stepper: enable bit; CiA402: shutdown, then enable operation) with a
    // small velocity so that the stages really move
    uint64_t t = 1'000'000'000;
    auto cycle = [&] {
        t += 1'000'000;
        f.seg.set_time(t);
        f.m->send_process_data();
        f.m->receive_process_data(0);
    };
    for (uint64_t cia_cw : {0x06, 0x0F}) {
        for (const auto& s : f.m->signals()) {
            bool stepper = f.m->slaves()[std::size_t(s.slave)].type == "EL7041";
            if (s.name.ends_with(".driveControl01")) f.m->set(s, stepper ? 1 : cia_cw);
            if (s.name.ends_with(".velocitySetpoint01")) f.m->set(s, 1000);
        }
        for (int i = 0; i < 3; ++i) cycle();
    }
    for (auto _ : st) {
        t += 1'000'000;
        f.seg.set_time(t);
        f.m->send_process_data();
        benchmark::DoNotOptimize(f.m->receive_process_data(0));
    }
    st.counters["stages"] = double(f.plant->stages().size());
    st.counters["signals"] = double(f.plant->signals.size());
    st.counters["wkc_ok"] = f.m->wkc() == f.m->expected_wkc();
}
BENCHMARK(BM_SimulatedCycle40WithPlant);

// Forwards to another link; retargeted after bring-up.
struct ForwardLink : Link {
    Link* to = nullptr;
    bool send(const uint8_t* p, std::size_t n) noexcept override { return to->send(p, n); }
    std::size_t receive(uint8_t* b, std::size_t c, int t) noexcept override { return to->receive(b, c, t); }
    const char* kind() const noexcept override { return "forward"; }
};

void BM_MasterCycle40(benchmark::State& st) {
    // Bring the master up against the simulator, then put an echo wire under it: what remains
    // per cycle is the master's own work (outputs into the frame, parse, inputs out, WKC).
    auto types = forty();
    std::vector<SlaveConfig> cfg;
    sim::Segment seg;
    for (std::size_t i = 0; i < types.size(); ++i) {
        seg.add(*Catalog::builtin().find(types[i]));
        cfg.push_back({int(i), types[i]});
    }
    InProcessLink sim_link(seg);
    EchoLink echo;
    ForwardLink fwd;
    fwd.to = &sim_link;
    Master m(fwd, 0, cfg, Catalog::builtin());
    m.bring_up();
    fwd.to = &echo;
    for (auto _ : st) {
        m.send_process_data();
        benchmark::DoNotOptimize(m.receive_process_data(0));
    }
    st.counters["image_bytes"] = double(m.bus_bytes());
}
BENCHMARK(BM_MasterCycle40);

// Master and simulator in different threads on different CPUs, frames over UDP on loopback:
// one full cycle round trip per iteration (the inverse is the highest cycle rate this transport
// sustains here).
void BM_UdpRoundTrip40(benchmark::State& st) {
    auto types = forty();
    std::vector<SlaveConfig> cfg;
    sim::Segment seg;
    for (std::size_t i = 0; i < types.size(); ++i) {
        seg.add(*Catalog::builtin().find(types[i]));
        cfg.push_back({int(i), types[i]});
    }
    sim::UdpServer server(seg, "127.0.0.1", 0);
    volatile bool stop = false;
    std::thread t([&] {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(1, &set);
        pthread_setaffinity_np(pthread_self(), sizeof set, &set);
        server.run(stop, 50);
    });
    {
        UdpLink link("127.0.0.1", server.port());
        Master m(link, 0, cfg, Catalog::builtin());
        m.bring_up();
        uint64_t bad = 0;
        for (auto _ : st) {
            m.send_process_data();
            if (m.receive_process_data(100000) != CycleStatus::Ok) ++bad;
        }
        st.counters["bad_cycles"] = double(bad);
        st.counters["rate_hz"] = benchmark::Counter(double(st.iterations()), benchmark::Counter::kIsRate);
    }
    stop = true;
    t.join();
}
BENCHMARK(BM_UdpRoundTrip40)->UseRealTime();

// The same over a veth pair made for the run (both ends in this namespace): the master's RawLink
// on one end, sim::RawServer on the other (CPU 1). Counters: max round trip and cycles slower
// than 50 us (half a 10 kHz period: the master's receive timeout at that rate).
// spin: 0 both sides sleep in ppoll, 1 the simulator busy-polls, 2 both busy-poll.
void BM_VethRoundTrip40(benchmark::State& st) {
    const int spin = int(st.range(0));
    std::string tag = std::to_string(std::random_device{}() % 1000000);
    std::string a = "bcbm" + tag, b = "bcbs" + tag;
    std::string up = "ip link add " + a + " type veth peer name " + b + " && ip link set " + a +
                     " up && ip link set " + b + " up";
    struct Veth { // deletes the pair (both ends) however the run ends
        std::string a;
        ~Veth() {
            if (!a.empty()) (void)std::system(("ip link del " + a + " 2>/dev/null").c_str());
        }
    } veth;
    if (std::system((up + " 2>/dev/null").c_str()) != 0) {
        st.SkipWithError("cannot create a veth pair (needs root / CAP_NET_ADMIN)");
        return;
    }
    veth.a = a;
    {
        auto types = forty();
        std::vector<SlaveConfig> cfg;
        sim::Segment seg;
        for (std::size_t i = 0; i < types.size(); ++i) {
            seg.add(*Catalog::builtin().find(types[i]));
            cfg.push_back({int(i), types[i]});
        }
        sim::RawServer server(seg, b, spin >= 1);
        volatile bool stop = false;
        std::thread t([&] {
            cpu_set_t set;
            CPU_ZERO(&set);
            CPU_SET(1, &set);
            pthread_setaffinity_np(pthread_self(), sizeof set, &set);
            server.run(stop, 50);
        });
        try {
            RawLink link(a, spin >= 2);
            Master m(link, 0, cfg, Catalog::builtin());
            m.bring_up();
            uint64_t bad = 0, late = 0;
            int64_t max_ns = 0;
            for (auto _ : st) {
                auto t0 = std::chrono::steady_clock::now();
                m.send_process_data();
                if (m.receive_process_data(100000) != CycleStatus::Ok) ++bad;
                int64_t ns = (std::chrono::steady_clock::now() - t0).count();
                max_ns = std::max(max_ns, ns);
                if (ns > 50000) ++late;
            }
            st.counters["bad_cycles"] = double(bad);
            st.counters["over_50us"] = double(late);
            st.counters["max_us"] = double(max_ns) / 1000;
            st.counters["rate_hz"] = benchmark::Counter(double(st.iterations()), benchmark::Counter::kIsRate);
        } catch (const std::exception& e) {
            st.SkipWithError(e.what());
        }
        stop = true;
        t.join();
    }
}
BENCHMARK(BM_VethRoundTrip40)->ArgName("spin")->Arg(0)->Arg(1)->Arg(2)->UseRealTime();

} // namespace

BENCHMARK_MAIN();
