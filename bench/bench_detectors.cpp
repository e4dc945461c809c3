// MCA cost: one status-and-read update of a 4096-channel mca record over the simulated detector
// (0.1 s of acquisition counted with Poisson statistics, the spectrum read, 32 ROIs summed, the
// monitors posted), as the IOC loop does at 10 Hz per element. Issue 16's load: 16 elements x 4096
// channels at 10 Hz = 160 updates/s; the CPU share is 160 x the time per update.
#include "detector/mca_record.hpp"
#include "detector/sim_mca.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"

#include <benchmark/benchmark.h>

#include <string>

using namespace beamctl;

namespace {

void BM_McaUpdate4096(benchmark::State& st) {
    detector::register_detector_records(pv::RecordTypes::global());
    double now = 0;
    pv::Database db;
    db.set_clock([&] { return now; });
    std::string text = R"(record(mca, "m") { field(NMAX, "4096") field(NUSE, "4096") )";
    for (int r = 0; r < 32; ++r)
        text += "field(R" + std::to_string(r) + "LO, \"" + std::to_string(100 * r) + "\") field(R" + std::to_string(r) + "HI, \"" +
                std::to_string(100 * r + 60) + "\") field(R" + std::to_string(r) + "BG, \"2\") ";
    text += "}";
    db.load(pv::parse_db(text, "bench.db", {}));
    db.init_records();
    detector::SimMcaConfig c;
    c.channels = 4096;
    c.cals = 0.005;
    c.lines = {{"Fe Ka", 6.404, 8000, 0.16}, {"Cu Ka", 8.048, 5000, 0.18}, {"Zn Ka", 8.639, 3000, 0.18}};
    c.background = 500;
    detector::SimMca dev(c, [&] { return now; });
    pv::Record& r = *db.find("m");
    detector::set_mca_device(r, &dev);
    pv::Address a;
    db.resolve("m.ERST", a);
    double one = 1;
    db.put(a, pv::Prim::Double, &one, 1);
    db.resolve("m.READ", a);
    for (auto _ : st) {
        now += 0.1;
        db.put(a, pv::Prim::Double, &one, 1); // status, read, ROIs, monitors
    }
}
BENCHMARK(BM_McaUpdate4096);

} // namespace

BENCHMARK_MAIN();
