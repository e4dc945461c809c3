// EtherCAT cycle cost for a 40-terminal segment:
//   BM_MasterCycle40: the master alone (send + receive + WKC check) over an echo link, i.e. the
//     master CPU per cycle that the target (<= 5 us) is about;
//   BM_SimulatedCycle40: master + in-process simulator (every ESC processing the frame);
//   BM_SimulatedCycle40WithPlant: the same with the terminal and plant models running after each
//     frame (6 drives moving stages, 12 analog signals, a wire), 1 ms of simulated time per cycle;
//   BM_ReturnToOp/<device>: the self-healing bus (issue 20): cycles from a slave's return (power
//     on) to OP, counted as the acyclic datagrams the health pass needs (one per cycle while the
//     bus runs), for a slave in OP before (identity only) and for one missing since the start
//     (whole SII read);
//   BM_SimulatedCycle40Reconfiguring: BM_SimulatedCycle40 while a health thread power-cycles and
//     re-configures the last slave over and over (one acyclic datagram in every cycle);
//   BM_UdpRoundTrip40, BM_VethRoundTrip40: master and simulator on two CPUs, over UDP loopback
//     and over a veth pair with raw sockets (the latter needs root; bench/veth_rate.sh measures
//     the cycle rate with `beamctl run` and `beamctl sim --iface` as separate processes).
#include "ethercat/catalog.hpp"
#include "ethercat/master.hpp"
#include "ethercat/raw_link.hpp"
#include "ethercat/sim/faults.hpp"
#include "ethercat/sim/raw_server.hpp"
#include "ethercat/sim/inprocess_link.hpp"
#include "ethercat/sim/segment.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <pthread.h>
#include <thread>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
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
    sim::InProcessLink link{seg};
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

// Counts the frames sent through it (acyclic transactions outside the cycle: one frame each).
struct CountingLink : Link {
    explicit CountingLink(Link& l) : to(l) {}
    Link& to;
    uint64_t sent = 0;
    bool send(const uint8_t* p, std::size_t n) noexcept override {
        ++sent;
        return to.send(p, n);
    }
    std::size_t receive(uint8_t* b, std::size_t c, int t) noexcept override { return to.receive(b, c, t); }
    const char* kind() const noexcept override { return "counting"; }
};

sim::Fault fault(sim::Segment& seg, const char* text) {
    return sim::parse_fault(text, Catalog::builtin(), seg.size());
}

// Arg: 0 EL1008, 1 EL7041 with a start-up SDO, 2 EL7211 (DC); the slave at position 2.
void BM_ReturnToOp(benchmark::State& st) {
    const char* types[] = {"EL1008", "EL7041", "EL7211"};
    const char* type = types[st.range(0)];
    sim::Segment seg;
    for (const char* t : {"EK1100", "EL1008", type}) seg.add(*Catalog::builtin().find(t));
    sim::InProcessLink link(seg);
    CountingLink counting(link);
    std::vector<SlaveConfig> cfg{{0, "EK1100"}, {1, "EL1008"}, {2, type}};
    if (st.range(0) == 1) cfg[2].sdos = {{0x8010, 1, 1000, 2}};
    seg.apply(fault(seg, "power 2 off"));
    Master m(counting, 0, cfg, Catalog::builtin());
    m.bring_up(); // slave 2 missing
    auto cycle = [&] {
        m.send_process_data();
        m.receive_process_data(0);
    };
    cycle();
    seg.apply(fault(seg, "power 2 on"));
    cycle();
    uint64_t before = counting.sent;
    m.check_and_recover();
    double first_join = double(counting.sent - before);
    if (m.slave_state(2) != SlaveState::Op) st.SkipWithError("the slave did not join");
    double back = 0;
    int n = 0;
    for (auto _ : st) {
        seg.apply(fault(seg, "power 2 off"));
        cycle();
        m.check_and_recover(); // lost
        seg.apply(fault(seg, "power 2 on"));
        cycle();
        before = counting.sent;
        m.check_and_recover(); // configured again
        back += double(counting.sent - before);
        ++n;
        if (m.slave_state(2) != SlaveState::Op) st.SkipWithError("the slave did not come back");
    }
    st.counters["cycles_first_join"] = first_join;
    st.counters["cycles_back_to_op"] = n ? back / n : 0;
    st.SetLabel(type);
}
BENCHMARK(BM_ReturnToOp)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);

void BM_SimulatedCycle40Reconfiguring(benchmark::State& st) {
    Fixture f;
    std::size_t last = f.seg.size() - 1;
    f.m->start_cycling();
    std::atomic<bool> stop{false};
    std::atomic<uint64_t> rejoined{0};
    std::string off = "power " + std::to_string(last) + " off", on = "power " + std::to_string(last) + " on";
    std::thread health([&] {
        while (!stop.load()) {
            f.seg.post(fault(f.seg, off.c_str()));
            while (!stop.load() && f.m->slave_state(last) != SlaveState::Lost) f.m->check_and_recover();
            f.seg.post(fault(f.seg, on.c_str()));
            while (!stop.load() && f.m->slave_state(last) != SlaveState::Op) f.m->check_and_recover();
            if (!stop.load()) rejoined++;
        }
    });
    uint64_t others_invalid = 0;
    for (auto _ : st) {
        f.m->send_process_data();
        benchmark::DoNotOptimize(f.m->receive_process_data(0));
        others_invalid += !f.m->slave_valid(1) || !f.m->slave_valid(last - 1);
    }
    stop = true;
    health.join();
    st.counters["rejoins"] = double(rejoined.load());
    st.counters["others_invalid_cycles"] = double(others_invalid);
}
BENCHMARK(BM_SimulatedCycle40Reconfiguring)->MinTime(2.0);

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
    sim::InProcessLink sim_link(seg);
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
