// Kernels of the CA server path, without sockets: a circuit answering pipelined requests, the
// DBR encoding of a monitor update, and a record put that processes and posts to a monitor.
#include "ca/circuit.hpp"
#include "ca/dbr.hpp"

#include <benchmark/benchmark.h>

using namespace beamctl;

namespace {

pv::Database& db() {
    static pv::Database* d = [] {
        auto* x = new pv::Database;
        std::string text;
        for (int i = 0; i < 1000; ++i)
            text += "record(ao, \"b:" + std::to_string(i) + "\") { field(PREC, \"3\") }\n";
        x->load(pv::parse_db(text, "bench.db", {}));
        x->init_records();
        return x;
    }();
    return *d;
}

std::string msg(uint16_t cmd, uint16_t dtype, uint32_t count, uint32_t p1, uint32_t p2,
                const std::string& payload = {}) {
    std::string out;
    ca::append_message(out, cmd, dtype, count, p1, p2, payload.data(), payload.size());
    return out;
}

struct Setup {
    ca::ServerContext ctx{db(), ca::AccessSecurity(), 5064, 1 << 24, 4096, 16 << 20, {}};
    ca::Circuit c{ctx, 0x7F000001, 1};
    Setup() {
        std::string s = msg(ca::kVersion, 0, 13, 0, 0);
        for (int i = 0; i < 1000; ++i) {
            std::string n = "b:" + std::to_string(i);
            n.push_back('\0');
            s += msg(ca::kCreateChan, 0, 0, uint32_t(i), 13, n);
        }
        c.receive(reinterpret_cast<const uint8_t*>(s.data()), s.size());
        c.consume_output(c.output_size());
    }
};

// READ_NOTIFY DBR_TIME_DOUBLE, 1000 pipelined requests per batch (what cabench get sends).
void BM_CircuitReadNotify(benchmark::State& st) {
    Setup s;
    std::string batch;
    for (uint32_t i = 0; i < 1000; ++i) batch += msg(ca::kReadNotify, 20, 1, i + 1, i);
    for (auto _ : st) {
        s.c.receive(reinterpret_cast<const uint8_t*>(batch.data()), batch.size());
        s.c.consume_output(s.c.output_size());
    }
    st.SetItemsProcessed(st.iterations() * 1000);
}
BENCHMARK(BM_CircuitReadNotify);

// WRITE_NOTIFY DBR_DOUBLE: convert, process the ao record, reply.
void BM_CircuitWriteNotify(benchmark::State& st) {
    Setup s;
    std::string batch;
    for (uint32_t i = 0; i < 1000; ++i) {
        std::string v(8, '\0');
        ca::putf64(reinterpret_cast<uint8_t*>(v.data()), i * 0.5);
        batch += msg(ca::kWriteNotify, 6, 1, i + 1, i, v);
    }
    for (auto _ : st) {
        s.c.receive(reinterpret_cast<const uint8_t*>(batch.data()), batch.size());
        s.c.consume_output(s.c.output_size());
    }
    st.SetItemsProcessed(st.iterations() * 1000);
}
BENCHMARK(BM_CircuitWriteNotify);

// A put with a monitor on the same PV in another circuit: process + post + encode the event.
void BM_PutWithMonitor(benchmark::State& st) {
    Setup writer, watcher;
    std::string sub(16, '\0');
    ca::put16(reinterpret_cast<uint8_t*>(sub.data()) + 12, pv::kDbeValue | pv::kDbeAlarm);
    std::string s;
    for (uint32_t i = 0; i < 1000; ++i) s += msg(ca::kEventAdd, 20, 1, i + 1, i, sub);
    watcher.c.receive(reinterpret_cast<const uint8_t*>(s.data()), s.size());
    watcher.c.fill_events(1 << 30);
    watcher.c.consume_output(watcher.c.output_size());
    std::string batch;
    double v = 0;
    for (auto _ : st) {
        batch.clear();
        for (uint32_t i = 0; i < 1000; ++i) {
            std::string p(8, '\0');
            ca::putf64(reinterpret_cast<uint8_t*>(p.data()), v += 1);
            batch += msg(ca::kWrite, 6, 1, i + 1, i, p);
        }
        writer.c.receive(reinterpret_cast<const uint8_t*>(batch.data()), batch.size());
        watcher.c.fill_events(1 << 30);
        watcher.c.consume_output(watcher.c.output_size());
    }
    st.SetItemsProcessed(st.iterations() * 1000);
}
BENCHMARK(BM_PutWithMonitor);

} // namespace

BENCHMARK_MAIN();
