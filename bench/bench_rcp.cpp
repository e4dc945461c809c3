// RCP bridge throughput and latency (issue #6; results in bench/RESULTS.md):
//   1. the socket-free handler (BridgeCore::handle_packet) on data packets of 17 objects;
//   2. sustained data packets over loopback into a real RcpBridge on an EventLoop, at 10 000,
//      20 000 and 50 000 packets/s for 5 s each, counting what arrived (0 lost is the target
//      at 10 000/s; every packet updates 17 PVs);
//   3. write latency: a put on an AO PV (Database::put, as the CA server does it) until the
//      datagram is received by the RCP's socket, p50/p99 over 5000 puts.
//   taskset -c 0,1 build/release/bench/bench_rcp
#include "bridge/rcp/bridge.hpp"
#include "bridge/rcp/bridge_core.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>
#include <vector>

using namespace beamctl;
using namespace beamctl::bridge::rcp;

static double now() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

static std::vector<BeaconObject> model(uint16_t rcp_port) {
    std::vector<BeaconObject> v;
    for (int i = 1; i <= 15; ++i)
        v.push_back(BeaconObject{uint8_t(i), ObjectType::AI, DataType::Float64, 0x7F000001, rcp_port, 0, 0,
                                 "sig" + std::to_string(i)});
    v.push_back(BeaconObject{16, ObjectType::AO, DataType::Float64, 0x7F000001, rcp_port, 0, 0, "set"});
    v.push_back(BeaconObject{17, ObjectType::Motor, DataType::Float64, 0x7F000001, rcp_port, 0, 0, "stage"});
    return v;
}

static Packet data_packet(int k) {
    static std::vector<std::vector<double>> vals(17);
    static std::vector<std::string> names;
    if (names.empty()) {
        for (int i = 1; i <= 15; ++i) names.push_back("sig" + std::to_string(i));
        names.push_back("set");
        names.push_back("stage");
    }
    std::vector<DataEntry> es;
    for (int i = 0; i < 17; ++i) {
        if (i < 16) vals[i] = {double(k + i)};
        else vals[i] = {double(k) * 0.001, 0.1, double(motor_status::kMoving | motor_status::kEnabled), 0, 0};
        es.push_back(DataEntry{uint8_t(i + 1), i < 15 ? ObjectType::AI : i == 15 ? ObjectType::AO : ObjectType::Motor,
                               DataType::Float64, uint16_t(vals[i].size()), names[i], std::span<const double>(vals[i])});
    }
    Packet p;
    if (!write_data(p, k * 1e-4, es)) std::abort();
    return p;
}

int main() {
    log::configure("warn");
    // 1. The pure handler.
    {
        pv::Database db;
        BridgeConfig cfg;
        cfg.prefix = "B:";
        double t = 0;
        BridgeCore core(db, cfg, [](const Endpoint&, std::span<const uint8_t>) { return true; }, [&] { return t; });
        Packet b;
        auto objs = model(18066);
        write_beacon(b, 0, "bench", false, objs);
        Endpoint src{0x7F000001, 5000};
        core.handle_packet(b, src, t);
        t = 0.2;
        core.tick(t);
        std::vector<Packet> ps;
        for (int k = 0; k < 64; ++k) ps.push_back(data_packet(k));
        const int n = 400000;
        double t0 = now();
        for (int i = 0; i < n; ++i) core.handle_packet(ps[i & 63], src, t);
        double dt = now() - t0;
        std::printf("pure handler: %d packets of 17 objects: %.0f ns/packet (%.0f packets/s)\n", n, dt / n * 1e9,
                    n / dt);
        // parse only
        DataPacket d;
        t0 = now();
        for (int i = 0; i < n; ++i) parse_data(ps[i & 63], d);
        dt = now() - t0;
        std::printf("parse_data only: %.0f ns/packet\n", dt / n * 1e9);
    }
    // 2. Over loopback at 10 000 packets/s, and 3. put -> datagram latency.
    {
        pv::Database db;
        EventLoop loop;
        BridgeConfig cfg;
        cfg.listen_address = "127.0.0.1";
        cfg.port = 0;
        cfg.prefix = "B:";
        RcpBridge bridge(db, loop, cfg);
        int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
        sockaddr_in me{};
        me.sin_family = AF_INET;
        me.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        ::bind(fd, reinterpret_cast<sockaddr*>(&me), sizeof me);
        socklen_t len = sizeof me;
        getsockname(fd, reinterpret_cast<sockaddr*>(&me), &len);
        uint16_t my_port = ntohs(me.sin_port);
        sockaddr_in to{};
        to.sin_family = AF_INET;
        to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        to.sin_port = htons(bridge.port());
        Packet b;
        auto objs = model(my_port);
        write_beacon(b, 0, "bench", false, objs);
        ::sendto(fd, b.data(), b.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to);
        std::vector<Packet> ps;
        for (int k = 0; k < 64; ++k) ps.push_back(data_packet(k));
        for (int rate : {10000, 20000, 50000}) {
            const int total = rate * 5; // 5 s
            std::atomic<bool> go{false};
            std::thread sender([&] {
                while (!go) std::this_thread::sleep_for(std::chrono::milliseconds(1));
                double start = now();
                for (int i = 0; i < total; ++i) {
                    double due = start + double(i) / rate;
                    while (now() < due) {
                    }
                    ::sendto(fd, ps[i & 63].data(), 1000, 0, reinterpret_cast<sockaddr*>(&to), sizeof to);
                }
            });
            uint64_t rx0 = 0;
            loop.call_after(0.25, [&] { rx0 = bridge.core().totals().rx; });
            loop.call_after(0.3, [&] { go = true; });
            loop.call_after(6.0, [&] { loop.stop(); });
            loop.run();
            sender.join();
            uint64_t got = bridge.core().totals().rx - rx0;
            uint64_t bad = 0;
            for (auto m : bridge.core().totals().malformed) bad += m;
            std::printf("loopback at %d packets/s of 17 objects for 5 s: sent %d, received %llu (lost %lld), "
                        "%llu PV updates/s, malformed %llu\n",
                        rate, total, (unsigned long long)got, (long long)total - (long long)got,
                        (unsigned long long)(got * 17 / 5), (unsigned long long)bad);
        }
        // Latency: put on the AO -> datagram at the RCP's socket.
        pv::Address a;
        db.resolve("B:bench:set", a);
        std::vector<double> lat;
        uint8_t buf[2000];
        while (::recv(fd, buf, sizeof buf, MSG_DONTWAIT) > 0) {
        }
        for (int i = 0; i < 5000; ++i) {
            double v = i;
            double t0 = now();
            db.put(a, pv::Prim::Double, &v, 1);
            pollfd p{fd, POLLIN, 0};
            ::poll(&p, 1, 1000);
            ::recv(fd, buf, sizeof buf, 0);
            lat.push_back(now() - t0);
        }
        std::sort(lat.begin(), lat.end());
        std::printf("put -> datagram received: p50 %.1f us, p99 %.1f us, max %.1f us\n", lat[lat.size() / 2] * 1e6,
                    lat[lat.size() * 99 / 100] * 1e6, lat.back() * 1e6);
        ::close(fd);
    }
}
