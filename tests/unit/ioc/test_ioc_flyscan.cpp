// The fly-scan example (examples/flyscan/ioc.yaml, seed 000 "Position Compare") in virtual time:
// the log-spiral arc axis at constant velocity, a distance-based and a time-based PCOMP block
// driving EL2808 outputs, and the capture writing a row per trigger into an HDF5/NeXus file.
#include "../temp_dir.hpp"
#include "../alloc_counter.hpp"
#include "core/error.hpp"
#include "pv/convert.hpp"
#include "virtual_ioc.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <thread>

using namespace beamctl;
using beamctl::test::TempDir;
using beamctl::test::VirtualIoc;

namespace {

const std::string kSource = BEAMCTL_SOURCE_DIR;

struct FlyIoc : VirtualIoc {
    explicit FlyIoc(const std::string& path) : VirtualIoc(path) {}
    pv::PutStatus put(const std::string& name, double v) {
        pv::Address a;
        if (!ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        return ioc->database().put(a, pv::Prim::Double, &v, 1);
    }
    pv::PutStatus put_text(const std::string& name, const std::string& s) {
        pv::Address a;
        if (!ioc->database().resolve(name, a)) throw std::runtime_error("no PV " + name);
        std::vector<char> c(s.begin(), s.end());
        c.push_back(0);
        return ioc->database().put(a, pv::Prim::Char, c.data(), uint32_t(c.size()));
    }
    // The writer thread works in wall-clock time: cycle on until `done` (at most 10 s).
    template <typename F> bool run_until(F done) {
        auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (!done()) {
            if (std::chrono::steady_clock::now() > end) return false;
            run(10);
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        return true;
    }
};

// A dataset of /entry/data (or at `name` if it starts with '/') read as T (memory type `mem`);
// `is` (if given) says whether the dataset's own type is `file_type`.
template <class T> std::vector<T> read_column(const std::string& file, const std::string& name, hid_t mem, hid_t file_type = -1, bool* is = nullptr) {
    hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0) throw std::runtime_error("cannot open " + file);
    hid_t d = H5Dopen2(f, (name[0] == '/' ? name : "/entry/data/" + name).c_str(), H5P_DEFAULT);
    std::vector<T> v;
    if (d >= 0) {
        if (is) {
            hid_t t = H5Dget_type(d);
            *is = H5Tequal(t, file_type) > 0;
            H5Tclose(t);
        }
        hid_t s = H5Dget_space(d);
        hsize_t n = 0;
        H5Sget_simple_extent_dims(s, &n, nullptr);
        v.resize(n);
        if (n) H5Dread(d, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
        H5Sclose(s);
        H5Dclose(d);
    }
    H5Fclose(f);
    return v;
}

std::vector<double> read_dataset(const std::string& file, const std::string& name) { return read_column<double>(file, name, H5T_NATIVE_DOUBLE); }

// A [rows, width] dataset of /entry/data, row-major; width 0 if it is not 2-D.
std::vector<double> read_matrix(const std::string& file, const std::string& name, std::size_t& width) {
    hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0) throw std::runtime_error("cannot open " + file);
    hid_t d = H5Dopen2(f, ("/entry/data/" + name).c_str(), H5P_DEFAULT);
    std::vector<double> v;
    width = 0;
    if (d >= 0) {
        hid_t s = H5Dget_space(d);
        hsize_t dims[2] = {};
        if (H5Sget_simple_extent_ndims(s) == 2) {
            H5Sget_simple_extent_dims(s, dims, nullptr);
            width = dims[1];
            v.resize(dims[0] * dims[1]);
            if (!v.empty()) H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
        }
        H5Sclose(s);
        H5Dclose(d);
    }
    H5Fclose(f);
    return v;
}

// examples/flyscan/timestamped.yaml with `edits` (every occurrence of each first replaced by its
// second) and its relative paths made absolute, written to `path`.
void write_timestamped_variant(const std::string& path, const std::vector<std::pair<std::string, std::string>>& edits) {
    std::ifstream in(kSource + "/examples/flyscan/timestamped.yaml");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    auto all = [&](const std::string& from, const std::string& to) {
        for (std::size_t p = 0; (p = text.find(from, p)) != std::string::npos; p += to.size()) text.replace(p, from.size(), to);
    };
    for (const auto& [from, to] : edits) all(from, to);
    all("plant: timestamped_plant.yaml", "plant: " + kSource + "/examples/flyscan/timestamped_plant.yaml");
    all("../", kSource + "/examples/");
    std::ofstream(path) << text;
}

TEST(IocFlyScan, SpiralExampleFiresAtEveryPointAndWritesTheFile) {
    FlyIoc v(kSource + "/examples/flyscan/ioc.yaml");
    TempDir dir;
    ASSERT_EQ(v.put_text("FLY:PCAP:FILE_PATH", dir.path.string()), pv::PutStatus::Ok);
    ASSERT_EQ(v.put_text("FLY:PCAP:FILE_NAME", "spiral_%03d.h5"), pv::PutStatus::Ok);
    v.run(200);
    ASSERT_EQ(v.put("FLY:PCAP:ARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); })) << v.text("FLY:PCAP:STATUS");
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 39});
    std::string why;
    registry::BoundSignal do1 = v.ioc->signals().bind("ec0.s3.binaryOutput01", why), do2 = v.ioc->signals().bind("ec0.s3.binaryOutput02", why);
    ASSERT_TRUE(do1.bound()) << why;
    const daq::Pcomp& distance = v.ioc->flyscan().pcomp(0);
    const daq::Pcomp& timed = v.ioc->flyscan().pcomp(1);
    motion::Axis& arc = v.axis("SpiralL");
    std::vector<double> rise_pos;
    std::vector<uint64_t> timed_rises;
    std::set<uint64_t> trigger_cycles; // a row per cycle in which either block rose
    ASSERT_EQ(v.put("FLY:PCOMP1:ENABLE", 1), pv::PutStatus::Ok);
    ASSERT_EQ(v.put("FLY:PCOMP2:ENABLE", 1), pv::PutStatus::Ok);
    double prev_pos = arc.status().act_pos;
    uint64_t cycle = 0;
    bool moving = true;
    for (int k = 0; k < 60000 && (moving || k < 100); ++k) {
        v.cycles(1);
        ++cycle;
        if (k % 10 == 0) v.ioc->publish();
        const double pos = arc.variables().enc.actpos;
        // the block's OUT is on the EL2808's output bit in the frame of the same cycle
        ASSERT_EQ(do1.get() != 0, distance.out()) << "cycle " << k;
        ASSERT_EQ(do2.get() != 0, timed.out()) << "cycle " << k;
        if (distance.rose()) {
            double ideal = 0.8 * double(rise_pos.size() + 1);
            EXPECT_GE(pos, ideal - 1e-9) << "pulse " << rise_pos.size() + 1;
            EXPECT_LE(pos - ideal, pos - prev_pos + 1e-9) << "pulse " << rise_pos.size() + 1 << ": more than one cycle late";
            EXPECT_NEAR(distance.edge_position(), ideal, 1e-9);
            rise_pos.push_back(pos);
        }
        if (timed.rose()) timed_rises.push_back(cycle);
        if (timed.rose() || distance.rose()) trigger_cycles.insert(cycle);
        prev_pos = pos;
        moving = arc.status().busy;
    }
    EXPECT_NEAR(arc.status().act_pos, 39, 0.01);
    ASSERT_EQ(rise_pos.size(), 48u); // 0.8 .. 38.4 mm
    EXPECT_EQ(distance.health(), daq::PcompHealth::Ok);
    ASSERT_GE(timed_rises.size(), 30u);
    for (std::size_t i = 1; i < timed_rises.size(); ++i) EXPECT_EQ(timed_rises[i] - timed_rises[i - 1], 1200u) << i;
    v.run(20);
    EXPECT_EQ(v.get("FLY:PCOMP1:PRODUCED"), 48);
    EXPECT_EQ(v.get("FLY:PCOMP1:HEALTH"), 0);
    EXPECT_EQ(timed_rises.front(), 1u); // the first pulse at enable (relative, START 0)
    const uint64_t rows = trigger_cycles.size();
    EXPECT_EQ(v.ioc->flyscan().capture()->pushed(), rows);

    ASSERT_EQ(v.put("FLY:PCAP:DISARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return !v.ioc->flyscan().writer()->status().busy; }));
    v.run(10);
    const std::string file = (dir.path / "spiral_001.h5").string();
    EXPECT_EQ(v.text("FLY:PCAP:FULL_FILE_NAME"), file);
    EXPECT_EQ(v.get("FLY:PCAP:ROWS_WRITTEN"), double(rows));
    EXPECT_EQ(v.get("FLY:PCAP:ROWS_DROPPED"), 0);
    EXPECT_EQ(v.get("FLY:PCAP:FILES"), 1);
    EXPECT_EQ(v.get("FLY:PCAP:ERROR"), 0) << v.text("FLY:PCAP:STATUS");
    EXPECT_EQ(v.get("FLY:PCAP:ACTIVE"), 0);
    // the file: one row per trigger, the arc at each distance trigger as the cycle saw it
    std::vector<double> arc_col = read_dataset(file, "arc"), dt = read_dataset(file, "distance_trigger"),
                        tt = read_dataset(file, "time_trigger"), out1 = read_dataset(file, "distance_out");
    ASSERT_EQ(arc_col.size(), rows);
    std::vector<double> from_file;
    for (std::size_t i = 0; i < rows; ++i)
        if (dt[i] == 1) from_file.push_back(arc_col[i]);
    ASSERT_EQ(from_file.size(), rise_pos.size());
    for (std::size_t i = 0; i < from_file.size(); ++i) EXPECT_DOUBLE_EQ(from_file[i], rise_pos[i]) << i;
    std::size_t timed_rows = 0;
    for (double x : tt) timed_rows += x == 1;
    for (std::size_t i = 0; i < rows; ++i) EXPECT_TRUE(dt[i] == 0 || out1[i] == 1) << i; // a rise: OUT is high
    ASSERT_GE(rows, 48 + timed_rises.size() - 2); // at most a couple of coincidences
    EXPECT_EQ(timed_rows, timed_rises.size());
    // the last rows as waveforms for live plots
    EXPECT_DOUBLE_EQ(v.get("FLY:PCAP:LAST:arc", 0), arc_col[0]);
}

// The row of a distance trigger is stamped with the crossing's interpolated time, between the
// previous cycle and the cycle that saw it.
TEST(IocFlyScan, DistanceRowsCarryTheInterpolatedCrossingTime) {
    FlyIoc v(kSource + "/examples/flyscan/ioc.yaml");
    TempDir dir;
    v.put_text("FLY:PCAP:FILE_PATH", dir.path.string());
    v.run(200);
    v.put("FLY:PCAP:ARM", 1);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); }));
    v.put("FLY:PCOMP1:ENABLE", 1);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 5});
    v.run(8000);
    v.put("FLY:PCAP:DISARM", 1);
    ASSERT_TRUE(v.run_until([&] { return !v.ioc->flyscan().writer()->status().busy; }));
    std::string file = v.ioc->flyscan().writer()->status().file;
    std::vector<double> ts = read_dataset(file, "timestamp_ns"), cyc = read_dataset(file, "cycle"), t = read_dataset(file, "t");
    ASSERT_EQ(ts.size(), 6u); // 0.8 .. 4.8 mm
    for (std::size_t i = 0; i < ts.size(); ++i) {
        const double cycle_t_ns = t[i] * 1e9; // the engine clock at the cycle that saw it
        EXPECT_LE(ts[i], cycle_t_ns + 1);
        EXPECT_GT(ts[i], cycle_t_ns - 1e6 - 1) << i;
    }
}

TEST(IocFlyScan, ConfigurationErrorsNameWhatAndWhere) {
    TempDir dir;
    std::string base = std::string("ioc: {name: T}\nengine: {rate_hz: 1000}\nbuses:\n  - id: 0\n    link: {type: sim}\n    slaves:\n") +
                       "      - {position: 0, type: EK1100}\n      - {position: 1, type: EL1008}\n      - {position: 2, type: EL2808}\n";
    auto fails = [&](const std::string& extra, const std::string& what) {
        std::string path = dir.write("bad.yaml", base + extra);
        try {
            rt::VirtualClock clock;
            ioc::Ioc ioc(config::IocConfig::load(path), clock); // what `beamctl check` builds
            ADD_FAILURE() << "built without an error: " << extra;
            ioc.bring_up();
            ADD_FAILURE() << "no error for: " << extra;
        } catch (const std::exception& e) {
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("bad.yaml:"), std::string::npos) << e.what();
        }
    };
    fails("pcomp:\n  - {id: 1, input: ax9.enc.actpos}\n", "no signal 'ax9.enc.actpos'");
    fails("pcomp:\n  - {id: 1, input: time, output: ec0.s1.binaryInput01}\n", "is not an output entry");
    fails("pcomp:\n  - {id: 1, input: time, dir: sideways}\n", "sideways");
    fails("capture:\n  fields: [{signal: nothing.here}]\n", "no signal 'nothing.here'");
    fails("capture:\n  trigger: pcomp7\n  fields: [{signal: time}]\n", "capture trigger");
    fails("capture:\n  fields: [{signal: time, modes: [mean]}]\n", "mean");
    fails("pcomp:\n  - {id: 1, input: time, output: ec0.s2.binaryOutput01}\n  - {id: 2, input: time, output: ec0.s2.binaryOutput01}\n",
          "pcomp1");
}

// An ARM into a directory that does not exist: refused with the reason, nothing armed.
TEST(IocFlyScan, AnUnwritableFileIsAnErrorNotACapture) {
    FlyIoc v(kSource + "/examples/flyscan/ioc.yaml");
    v.put_text("FLY:PCAP:FILE_PATH", "/nonexistent/dir");
    v.run(20);
    v.put("FLY:PCAP:ARM", 1);
    ASSERT_TRUE(v.run_until([&] { return !v.ioc->flyscan().writer()->status().busy; }));
    v.run(10);
    EXPECT_FALSE(v.ioc->flyscan().capture()->armed());
    EXPECT_EQ(v.get("FLY:PCAP:ERROR"), 1);
    EXPECT_NE(v.text("FLY:PCAP:STATUS").find("/nonexistent/dir"), std::string::npos) << v.text("FLY:PCAP:STATUS");
}

// RT rule 1: the cycle with blocks firing and a capture running allocates nothing.
TEST(IocFlyScan, TheCycleWithCaptureAllocatesNothing) {
    FlyIoc v(kSource + "/examples/flyscan/ioc.yaml");
    TempDir dir;
    v.put_text("FLY:PCAP:FILE_PATH", dir.path.string());
    v.run(200);
    v.put("FLY:PCAP:ARM", 1);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); }));
    v.put("FLY:PCOMP1:ENABLE", 1);
    v.put("FLY:PCOMP2:ENABLE", 1);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 4});
    v.cycles(10);
    test::count_allocations(true, true); // the cycle's thread (the writer thread allocates in HDF5)
    v.cycles(6000);
    test::count_allocations(false);
    EXPECT_EQ(test::allocations(), 0);
    EXPECT_GE(v.ioc->flyscan().pcomp(0).produced(), 4u);
    v.put("FLY:PCAP:DISARM", 1);
    ASSERT_TRUE(v.run_until([&] { return !v.ioc->flyscan().writer()->status().busy; }));
}

} // namespace

namespace {

// PLC code drives a block (pcomp<n>.* names): it sets STEP and ENABLE in its first scan and reads
// OUT and PRODUCED; the PVs show what the PLC set, and a later PV put still acts.
TEST(IocFlyScan, PlcCodeReachesTheBlocks) {
    TempDir dir;
    dir.write("p.plc",
              "if (plc0.firstscan) { pcomp1.step := 0.02; pcomp1.enable := 1; };\n"
              "static.produced := pcomp1.produced;\n"
              "if (pcomp1.out) { static.high := static.high + 1; };\n"
              "static.state := pcomp1.state;\n");
    std::string path = dir.write("ioc.yaml",
                                 "ioc: {name: T}\nengine: {rate_hz: 1000}\n"
                                 "buses:\n  - id: 0\n    link: {type: sim}\n    slaves:\n"
                                 "      - {position: 0, type: EK1100}\n      - {position: 1, type: EL2808}\n"
                                 "plcs:\n  - {id: 0, file: p.plc}\n"
                                 "pcomp:\n  - {id: 1, input: time, step: 0.01, width: 0.005, relative: true, output: ec0.s1.binaryOutput01}\n");
    FlyIoc v(path);
    v.run(1000);
    const daq::Pcomp& pc = v.ioc->flyscan().pcomp(0);
    EXPECT_DOUBLE_EQ(pc.params.step, 0.02);
    EXPECT_TRUE(pc.active());
    EXPECT_NEAR(double(pc.produced()), 50, 1.5); // one every 20 cycles over ~1000 cycles
    EXPECT_EQ(v.stat(0, "produced"), double(pc.produced()));
    EXPECT_NEAR(v.stat(0, "high"), 0.25 * 1000, 30); // WIDTH 5 ms of every 20 ms
    EXPECT_EQ(v.stat(0, "state"), pc.out() ? 4 : 3); // WAIT_FALLING while high, else WAIT_RISING
    EXPECT_DOUBLE_EQ(v.get("T:PCOMP1:STEP"), 0.02);
    EXPECT_EQ(v.get("T:PCOMP1:ENABLE"), 1);
    // a PV put after the PLC's change still acts, and keeps the PLC's other values
    ASSERT_EQ(v.put("T:PCOMP1:WIDTH", 0.01), pv::PutStatus::Ok);
    v.run(20);
    EXPECT_DOUBLE_EQ(pc.params.width, 0.01);
    EXPECT_DOUBLE_EQ(pc.params.step, 0.02);
    EXPECT_TRUE(pc.active());
}

// The timestamped example: the same compare points on an EL2808 (next frame) and an EL2252 (the
// predicted crossing time), both cabled to an EL1252 that latches each edge's DC time. The ideal
// time of a point is where the compared input, interpolated between its samples (each at the DC
// time of the frame that sampled it), reaches it.
TEST(IocFlyScan, TimestampedOutputSwitchesWithin1usOfTheCrossing) {
    FlyIoc v(kSource + "/examples/flyscan/timestamped.yaml");
    v.run(200);
    ASSERT_EQ(v.put("FLY:PCOMP1:ENABLE", 1), pv::PutStatus::Ok);
    ASSERT_EQ(v.put("FLY:PCOMP3:ENABLE", 1), pv::PutStatus::Ok);
    ASSERT_EQ(v.put("FLY:PCOMP4:ENABLE", 1), pv::PutStatus::Ok);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 10.1});
    std::string why;
    registry::BoundSignal plain = v.ioc->signals().bind("ec0.s5.timestampLatchPositive01", why),
                          timed = v.ioc->signals().bind("ec0.s5.timestampLatchPositive02", why),
                          timed_fall = v.ioc->signals().bind("ec0.s5.timestampLatchNegative02", why);
    ASSERT_TRUE(plain.bound() && timed.bound() && timed_fall.bound()) << why;
    motion::Axis& arc = v.axis("SpiralL");
    const uint64_t period = 1'000'000;
    std::vector<std::pair<uint64_t, double>> samples; // (DC time of the sample, setpos)
    std::vector<uint64_t> plain_rises, timed_rises, timed_falls;
    uint64_t last_plain = plain.get_raw(), last_timed = timed.get_raw(), last_fall = timed_fall.get_raw();
    // the EL4732 read back by the EL3702, 10 samples per cycle: the time of each step's first sample
    constexpr unsigned kN = 10;
    std::vector<registry::BoundSignal> in;
    for (unsigned i = 1; i <= kN; ++i) in.push_back(v.ioc->signals().bind("ec0.s7.analogInputArray01_" + std::to_string(i), why));
    ASSERT_TRUE(in.back().bound()) << why;
    std::vector<std::pair<uint64_t, bool>> steps; // (DC time of the sample, rising)
    std::set<unsigned> step_samples;              // which of the n samples the steps were in
    bool level = false;
    bool moving = true;
    for (int k = 0; k < 20000 && (moving || k < 100); ++k) {
        v.cycles(1);
        const uint64_t dc = v.ioc->bus(0).dc_time();
        samples.emplace_back(dc, arc.variables().traj.setpos);
        // received this cycle: what the EL4732 played after the frame before the last one, sample
        // i at that frame + (i + 1) / n cycles
        for (unsigned i = 0; i < kN; ++i) {
            const int64_t raw = in[i].get();
            ASSERT_TRUE(raw == 0 || raw == 16384) << raw;
            if ((raw != 0) != level) {
                level = raw != 0;
                steps.emplace_back(dc - period + (i + 1) * period / kN, level);
                step_samples.insert(i);
            }
        }
        if (plain.get_raw() != last_plain) plain_rises.push_back(last_plain = plain.get_raw());
        if (timed.get_raw() != last_timed) timed_rises.push_back(last_timed = timed.get_raw());
        if (timed_fall.get_raw() != last_fall) timed_falls.push_back(last_fall = timed_fall.get_raw());
        moving = arc.status().busy;
    }
    // times relative to the first sample [ns] (absolute DC times exceed a double's 53 bits)
    const uint64_t t0 = samples.front().first;
    auto rel = [&](uint64_t t) { return double(int64_t(t - t0)); };
    auto ideal = [&](double p) -> double {
        for (std::size_t i = 1; i < samples.size(); ++i)
            if (samples[i - 1].second < p && samples[i].second >= p)
                return rel(samples[i - 1].first) +
                       (p - samples[i - 1].second) / (samples[i].second - samples[i - 1].second) * double(samples[i].first - samples[i - 1].first);
        return -1;
    };
    ASSERT_EQ(plain_rises.size(), 12u); // 0.8 .. 9.6 mm
    ASSERT_EQ(timed_rises.size(), 12u);
    ASSERT_EQ(timed_falls.size(), 12u); // 0.4 mm later each, the last at 10.0
    // Within 1 us at constant velocity (1 mm/s from 1 mm on, until the deceleration 1 mm before
    // 10.1); while the axis accelerates (0.5 mm/s^2) the linear prediction over three cycles from
    // a 2 ms velocity is off by some us (about a * (3 ms)^2 / 2 / v + 3 ms * a * 1 ms / v, 12 us at
    // 10.0 mm where v is 0.32 mm/s).
    auto tolerance = [](double p) { return p > 1.0 && p < 9.1 ? 1000.0 : 20000.0; };
    for (std::size_t i = 0; i < 12; ++i) {
        const double p_rise = 0.8 * double(i + 1), p_fall = p_rise + 0.4;
        const double t_rise = ideal(p_rise), t_fall = ideal(p_fall);
        ASSERT_GT(t_rise, 0);
        ASSERT_GT(t_fall, 0);
        EXPECT_NEAR(rel(timed_rises[i]), t_rise, tolerance(p_rise)) << "timestamped rise " << i + 1;
        EXPECT_NEAR(rel(timed_falls[i]), t_fall, tolerance(p_fall)) << "timestamped fall " << i + 1;
        // the plain output: with the frame after the cycle that saw the point passed
        EXPECT_GE(rel(plain_rises[i]), t_rise) << "plain rise " << i + 1;
        EXPECT_LE(rel(plain_rises[i]), t_rise + 2.0 * double(period)) << "plain rise " << i + 1;
        // the timestamped edge is between frames, not on one
        EXPECT_NE(timed_rises[i] % period, plain_rises[i] % period);
        // the oversampled output steps in the sample at or first after the crossing
        ASSERT_EQ(steps.size(), 24u);
        for (auto [p, k] : {std::pair{p_rise, 2 * i}, std::pair{p_fall, 2 * i + 1}}) {
            EXPECT_EQ(steps[k].second, k % 2 == 0);
            const double t = ideal(p), sample_t = rel(steps[k].first);
            EXPECT_GE(sample_t, t - tolerance(p)) << "oversampled edge " << k;
            EXPECT_LT(sample_t, t + double(period / kN) + tolerance(p)) << "oversampled edge " << k;
        }
    }
    EXPECT_GE(step_samples.size(), 4u); // the crossings fall anywhere in the cycle, not on frames
    const daq::TimedPcompOutput* out = v.ioc->flyscan().timed_output(1);
    ASSERT_NE(out, nullptr);
    EXPECT_EQ(out->scheduled(), 24u);
    EXPECT_EQ(out->late(), 0u);
    EXPECT_EQ(v.ioc->flyscan().timed_output(0), nullptr);
    v.run(20);
    EXPECT_EQ(v.get("FLY:PCOMP3:TIMED"), 24);
    EXPECT_EQ(v.get("FLY:PCOMP3:LATE"), 0);
    EXPECT_EQ(v.get("FLY:PCOMP3:PRODUCED"), 12);
    EXPECT_EQ(v.get("FLY:PCOMP4:TIMED"), 24);
    // the EL4732 channel's memory-map PV is the block's: read-only, as the entries' PVs
    pv::Record* ao = v.ioc->database().find("FLY:m0s006-AO01-Arr");
    ASSERT_NE(ao, nullptr);
    EXPECT_TRUE(ao->val_read_only);
    EXPECT_FALSE(v.ioc->database().find("FLY:m0s006-AO02-Arr")->val_read_only);
    EXPECT_EQ(v.get("FLY:PCOMP4:PRODUCED"), 12);
}

// Two blocks cannot share one EL2252 (its one startTime), and the claim names the first.
TEST(IocFlyScan, OneTimestampedBlockPerEl2252) {
    TempDir dir;
    const std::string path = (dir.path / "two.yaml").string();
    write_timestamped_variant(path, {{"output: ec0.s3.binaryOutput01", "output: ec0.s4.binaryOutput02"}});
    try {
        VirtualIoc v(path);
        FAIL() << "two blocks on one EL2252 were taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("ec0.s4.startTime"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("pcomp1"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("two.yaml:"), std::string::npos) << e.what();
    }
}

// Without oversampling an analog output follows OUT with analog_high / analog_low, in the cycle.
TEST(IocFlyScan, AnalogOutputFollowsOut) {
    TempDir dir;
    const std::string path = (dir.path / "analog.yaml").string();
    write_timestamped_variant(path, {{"type: EL4732, oversampling: 10", "type: EL4732"},
                                     {"analog_high: 16384, analog_low: 0", "analog_high: 3000, analog_low: -200"}});
    FlyIoc v(path);
    EXPECT_EQ(v.ioc->flyscan().oversampled_output(2), nullptr);
    v.run(100);
    ASSERT_EQ(v.put("FLY:PCOMP4:ENABLE", 1), pv::PutStatus::Ok);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 2.5});
    std::string why;
    registry::BoundSignal ao = v.ioc->signals().bind("ec0.s6.analogOutput01_1", why);
    ASSERT_TRUE(ao.bound()) << why;
    const daq::Pcomp& pc = v.ioc->flyscan().pcomp(2);
    int high = 0;
    for (int k = 0; k < 8000; ++k) {
        v.cycles(1);
        ASSERT_EQ(ao.get(), pc.out() ? 3000 : -200) << "cycle " << k;
        high += pc.out();
    }
    EXPECT_EQ(pc.produced(), 3u);
    EXPECT_GT(high, 1000);
}

// EL1252 edge times into the capture: a row at each rising edge the EL1252 sees (a signal trigger),
// its DC time stamp kept exactly (a uint64 dataset; a double holds only 53 bits of ns).
TEST(IocFlyScan, LatchedEdgeTimesAreCapturedExactly) {
    TempDir dir;
    const std::string path = (dir.path / "latch.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "capture:\n  trigger: ec0.s5.binaryInput02\n  fields:\n"
                                                  "    - {signal: ec0.s5.timestampLatchPositive02, name: edge, units: ns}\n"
                                                  "    - {signal: ax3.traj.setpos, name: arc, units: mm}\n"
                                                  "  file_path: " + dir.path.string() + "\n  file_name: latch_%03d.h5\npcomp:\n"}});
    FlyIoc v(path);
    v.run(100);
    ASSERT_EQ(v.put("FLY:PCAP:ARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); })) << v.text("FLY:PCAP:STATUS");
    ASSERT_EQ(v.put("FLY:PCOMP3:ENABLE", 1), pv::PutStatus::Ok);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 5.1});
    std::string why;
    registry::BoundSignal latch = v.ioc->signals().bind("ec0.s5.timestampLatchPositive02", why);
    std::vector<uint64_t> seen;
    uint64_t last = latch.get_raw();
    for (int k = 0; k < 9000; ++k) {
        v.cycles(1);
        if (k % 10 == 0) v.ioc->publish();
        if (latch.get_raw() != last) seen.push_back(last = latch.get_raw());
    }
    ASSERT_EQ(seen.size(), 6u); // 0.8 .. 4.8 mm
    ASSERT_GT(seen[0], uint64_t(1) << 53); // beyond a double's integers
    ASSERT_EQ(v.put("FLY:PCAP:DISARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.get("FLY:PCAP:ACTIVE") == 0 && v.get("FLY:PCAP:FILES") == 1; }));
    bool is_uint64 = false;
    const std::vector<uint64_t> edge =
        read_column<uint64_t>((dir.path / "latch_001.h5").string(), "edge", H5T_NATIVE_UINT64, H5T_STD_U64LE, &is_uint64);
    EXPECT_TRUE(is_uint64);
    EXPECT_EQ(edge, seen);
    // the live waveform shows them as numbers (ns, to a double's precision)
    v.run(20);
    EXPECT_NEAR(v.get("FLY:PCAP:LAST:edge", 5), double(seen[5]), 256.0);
}

TEST(IocFlyScan, ATimeStampIsCapturedAsItsValueOnly) {
    TempDir dir;
    const std::string path = (dir.path / "diff.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "capture:\n  trigger: cycle\n  fields:\n"
                                                  "    - {signal: ec0.s5.timestampLatchPositive02, name: edge, modes: [value, diff]}\n"
                                                  "pcomp:\n"}});
    try {
        VirtualIoc v(path);
        FAIL() << "a diff of a UINT64 time stamp was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("diff.yaml:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("value only, not 'diff'"), std::string::npos) << e.what();
    }
}

// EL4732 -> EL3702 at 10 samples a cycle, both channels' memory maps captured every cycle: each row
// of the EL3702's [rows, 10] dataset holds the samples that cycle received, in order, and equals the
// EL4732's samples a fixed number of cycles earlier (the loop's latency) sample by sample: an edge
// the oversampled output placed comes back in the same sample.
TEST(IocFlyScan, OversampledSamplesAreCapturedInTheirSlots) {
    TempDir dir;
    const std::string path = (dir.path / "samples.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "capture:\n  trigger: cycle\n  fields:\n"
                                                  "    - {signal: ec0.s7.mm.analogInputArray01, name: ai}\n"
                                                  "    - {signal: ec0.s6.mm.analogOutputArray01, name: ao}\n"
                                                  "    - {signal: ax3.traj.setpos, name: arc, units: mm}\n"
                                                  "  last_rows: 100\n  file_path: " + dir.path.string() + "\n  file_name: os_%03d.h5\npcomp:\n"}});
    FlyIoc v(path);
    v.run(100);
    ASSERT_EQ(v.put("FLY:PCAP:ARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); })) << v.text("FLY:PCAP:STATUS");
    ASSERT_EQ(v.put("FLY:PCOMP4:ENABLE", 1), pv::PutStatus::Ok);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 5.5});
    constexpr unsigned kN = 10;
    std::string why;
    std::vector<registry::BoundSignal> in;
    for (unsigned i = 1; i <= kN; ++i) in.push_back(v.ioc->signals().bind("ec0.s7.analogInputArray01_" + std::to_string(i), why));
    ASSERT_TRUE(in.back().bound()) << why;
    std::map<uint64_t, std::vector<double>> seen; // engine cycle -> the EL3702 samples it received
    for (int k = 0; k < 8000; ++k) {
        v.cycles(1);
        std::vector<double>& s = seen[v.ioc->engine().stats().cycles - 1];
        for (unsigned i = 0; i < kN; ++i) s.push_back(double(in[i].get()));
        if (k % 10 == 0) v.ioc->publish();
    }
    ASSERT_EQ(v.put("FLY:PCAP:DISARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.get("FLY:PCAP:ACTIVE") == 0 && v.get("FLY:PCAP:FILES") == 1; }));
    EXPECT_EQ(v.get("FLY:PCAP:ROWS_DROPPED"), 0);
    const std::string file = (dir.path / "os_001.h5").string();
    const std::vector<uint64_t> cycle = read_column<uint64_t>(file, "cycle", H5T_NATIVE_UINT64);
    std::size_t wi = 0, wo = 0;
    const std::vector<double> ai = read_matrix(file, "ai", wi), ao = read_matrix(file, "ao", wo);
    ASSERT_EQ(wi, kN);
    ASSERT_EQ(wo, kN);
    ASSERT_GE(cycle.size(), 8000u);
    ASSERT_EQ(ai.size(), cycle.size() * kN);
    ASSERT_EQ(ao.size(), cycle.size() * kN);
    // every row: the samples of its cycle, in order
    std::size_t checked = 0;
    for (std::size_t r = 0; r < cycle.size(); ++r) {
        auto it = seen.find(cycle[r]);
        if (it == seen.end()) continue; // the cycles run by run_until / run, not watched
        for (unsigned i = 0; i < kN; ++i) ASSERT_EQ(ai[r * kN + i], it->second[i]) << "row " << r << " sample " << i;
        ++checked;
    }
    EXPECT_EQ(checked, 8000u);
    // the steps the output placed: 6 pulses (0.8 .. 4.8 mm, each 0.4 mm wide), 12 edges, in several different samples
    std::vector<std::size_t> out_steps, in_steps; // flattened sample index of each change
    for (std::size_t j = 1; j < ao.size(); ++j) {
        if (ao[j] != ao[j - 1]) out_steps.push_back(j);
        if (ai[j] != ai[j - 1]) in_steps.push_back(j);
    }
    ASSERT_EQ(out_steps.size(), 12u);
    ASSERT_EQ(in_steps.size(), 12u);
    std::set<std::size_t> slots;
    for (std::size_t j : out_steps) slots.insert(j % kN);
    EXPECT_GE(slots.size(), 3u) << "the crossings fall anywhere in the cycle";
    // the input is the output `lag` rows later, every sample of every row
    const std::size_t lag = (in_steps[0] - out_steps[0]) / kN;
    EXPECT_EQ(in_steps[0] - out_steps[0], lag * kN) << "an edge came back in another sample";
    // written in cycle c, sent with its frame and played across the next cycle, where the EL3702
    // samples it; the frame after carries those samples back, received at the start of c + 2
    EXPECT_EQ(lag, 2u);
    for (std::size_t k = 0; k < 12; ++k) EXPECT_EQ(in_steps[k], out_steps[k] + lag * kN) << "edge " << k;
    for (std::size_t r = lag; r < cycle.size(); ++r)
        for (unsigned i = 0; i < kN; ++i) ASSERT_EQ(ai[r * kN + i], ao[(r - lag) * kN + i]) << "row " << r << " sample " << i;
    // the live waveform: the last 100 rows' samples, row by row
    v.run(20);
    const std::size_t last = cycle.size() - 1;
    for (unsigned i = 0; i < kN; ++i) EXPECT_EQ(v.get("FLY:PCAP:LAST:ai", 99 * kN + i), ai[last * kN + i]) << i;
    EXPECT_EQ(v.ioc->database().find("FLY:PCAP:LAST:ai")->elements(*v.ioc->database().find("FLY:PCAP:LAST:ai")->type().find("VAL")).count, 100 * kN);
}

TEST(IocFlyScan, AMemoryMapIsCapturedAsItsValuesOnly) {
    TempDir dir;
    const std::string path = (dir.path / "mm.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "capture:\n  trigger: cycle\n  fields:\n"
                                                  "    - {signal: ec0.s7.mm.analogInputArray01, name: ai, modes: [value, max]}\n"
                                                  "pcomp:\n"}});
    try {
        VirtualIoc v(path);
        FAIL() << "a max of a memory map was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("mm.yaml:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("10 samples a cycle) is captured as its values only, not 'max'"), std::string::npos) << e.what();
    }
}

// A data storage listed in capture.storages: every value PLC code appends while the capture runs
// goes into the file (/entry/ds3, NXlog) with the cycle that appended it, none lost though the
// storage's own buffer (a ring of 4) keeps only the last few, none from before ARM or after DISARM.
TEST(IocFlyScan, DataStorageValuesGoIntoTheCaptureFile) {
    TempDir dir;
    std::ofstream(dir.path / "ds.plc") << "static.n += 1;\nif (static.n % 7 == 0) { ds_append_data(3, static.n); };\n";
    const std::string path = (dir.path / "ds.yaml").string();
    write_timestamped_variant(path, {{"plcs:\n", "storages:\n  - {id: 3, size: 4, type: ring}\nplcs:\n  - {id: 1, file: " + (dir.path / "ds.plc").string() + "}\n"},
                                     {"pcomp:\n", "capture:\n  trigger: cycle\n  fields:\n"
                                                   "    - {signal: ax3.traj.setpos, name: arc, units: mm}\n"
                                                   "  storages: [3]\n"
                                                   "  file_path: " + dir.path.string() + "\n  file_name: ds_%03d.h5\npcomp:\n"}});
    FlyIoc v(path);
    v.run(100);
    ASSERT_EQ(v.put("FLY:PCAP:ARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.ioc->flyscan().capture()->armed(); })) << v.text("FLY:PCAP:STATUS");
    v.cycles(3000);
    ASSERT_EQ(v.put("FLY:PCAP:DISARM", 1), pv::PutStatus::Ok);
    ASSERT_TRUE(v.run_until([&] { return v.get("FLY:PCAP:ACTIVE") == 0 && v.get("FLY:PCAP:FILES") == 1; }));
    v.cycles(500); // appends after the DISARM stay out of the file
    EXPECT_EQ(v.get("FLY:PCAP:ROWS_DROPPED"), 0);
    EXPECT_EQ(v.get("FLY:DS03-Count"), 4); // the storage's own ring holds 4
    const std::string file = (dir.path / "ds_001.h5").string();
    const std::vector<uint64_t> rows = read_column<uint64_t>(file, "cycle", H5T_NATIVE_UINT64);
    const std::vector<uint64_t> row_t = read_column<uint64_t>(file, "timestamp_ns", H5T_NATIVE_UINT64);
    ASSERT_GT(rows.size(), 3000u);
    const std::vector<double> value = read_column<double>(file, "/entry/ds3/value", H5T_NATIVE_DOUBLE),
                              time = read_column<double>(file, "/entry/ds3/time", H5T_NATIVE_DOUBLE);
    const std::vector<uint64_t> cycle = read_column<uint64_t>(file, "/entry/ds3/cycle", H5T_NATIVE_UINT64),
                                t_ns = read_column<uint64_t>(file, "/entry/ds3/timestamp_ns", H5T_NATIVE_UINT64);
    ASSERT_GE(value.size(), rows.size() / 7 - 1);
    ASSERT_LE(value.size(), rows.size() / 7 + 1);
    ASSERT_EQ(cycle.size(), value.size());
    ASSERT_EQ(t_ns.size(), value.size());
    ASSERT_EQ(time.size(), value.size());
    for (std::size_t i = 0; i < value.size(); ++i) {
        EXPECT_EQ(std::fmod(value[i], 7.0), 0.0) << i;
        if (i) EXPECT_EQ(value[i] - value[i - 1], 7.0) << "value " << i << " lost or repeated";
        // the PLC counts the cycles: the appending cycle is the count plus a constant
        EXPECT_EQ(double(cycle[i]) - value[i], double(cycle[0]) - value[0]) << i;
        EXPECT_NEAR(time[i], double(t_ns[i] - t_ns[0]) * 1e-9, 1e-9) << i;
        // within the capture: a row of the same cycle has the same time stamp
        ASSERT_GE(cycle[i], rows.front());
        ASSERT_LE(cycle[i], rows.back() + 1);
        if (cycle[i] <= rows.back()) EXPECT_EQ(t_ns[i], row_t[cycle[i] - rows.front()]) << i;
    }
    hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    char cls[16] = {};
    hid_t a = H5Aopen_by_name(f, "/entry/ds3", "NX_class", H5P_DEFAULT, H5P_DEFAULT);
    hid_t t = H5Aget_type(a);
    char* pc = nullptr;
    hid_t mt = H5Tcopy(H5T_C_S1);
    H5Tset_size(mt, H5T_VARIABLE);
    H5Tset_cset(mt, H5T_CSET_UTF8);
    if (H5Aread(a, mt, &pc) >= 0 && pc) {
        std::snprintf(cls, sizeof cls, "%s", pc);
        H5free_memory(pc);
    }
    H5Tclose(mt);
    H5Tclose(t);
    H5Aclose(a);
    H5Fclose(f);
    EXPECT_STREQ(cls, "NXlog");
    EXPECT_NE(v.text("FLY:PCAP:STATUS").find(std::to_string(value.size()) + " ds3 values"), std::string::npos) << v.text("FLY:PCAP:STATUS");
}

TEST(IocFlyScan, ACapturedStorageMustExist) {
    TempDir dir;
    const std::string path = (dir.path / "nods.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "capture:\n  trigger: cycle\n  fields:\n    - {signal: ax3.traj.setpos, name: arc}\n"
                                                  "  storages: [5]\npcomp:\n"}});
    try {
        config::IocConfig::load(path);
        FAIL() << "a storage that does not exist was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("nods.yaml:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("ds5 is not in storages:"), std::string::npos) << e.what();
    }
}

// Records read a block's signals with device support (INP "@pcomp1.out"): an I/O Intr bi is
// processed once for every pulse, even one cycle wide, shorter than the IOC loop's look.
TEST(IocFlyScan, RecordsReadTheBlocksThroughDeviceSupport) {
    TempDir dir;
    std::ofstream(dir.path / "p.db")
        << "record(bi, \"FLY:Pulse\") { field(DTYP, \"beamctl\") field(INP, \"@pcomp1.out\") field(SCAN, \"I/O Intr\") field(FLNK, \"FLY:Seen\") }\n"
           "record(calc, \"FLY:Seen\") { field(INPA, \"FLY:Seen\") field(CALC, \"A+1\") }\n"
           "record(longin, \"FLY:Made\") { field(DTYP, \"beamctl\") field(INP, \"@pcomp1.produced\") field(SCAN, \"I/O Intr\") }\n";
    const std::string path = (dir.path / "dev.yaml").string();
    write_timestamped_variant(path, {{"pcomp:\n", "db:\n  - {file: " + (dir.path / "p.db").string() + "}\npcomp:\n"}});
    FlyIoc v(path);
    v.run(100);
    const double seen0 = v.get("FLY:Seen");
    ASSERT_EQ(v.put("FLY:PCOMP1:WIDTH", 0.0005), pv::PutStatus::Ok); // one cycle at 1 mm/s (1 um a cycle)
    ASSERT_EQ(v.put("FLY:PCOMP1:ENABLE", 1), pv::PutStatus::Ok);
    v.send("SpiralL", motion::AxisCommand{motion::CommandType::MoveAbsolute, 3.3});
    int high = 0;
    for (int k = 0; k < 700; ++k) {
        v.run(10);
        high += v.get("FLY:Pulse") != 0;
    }
    EXPECT_EQ(v.ioc->flyscan().pcomp(0).produced(), 4u); // 0.8, 1.6, 2.4, 3.2 mm
    EXPECT_EQ(v.get("FLY:Made"), 4);
    // a pulse the loop saw high processed the record twice (rise, fall); one that came and went
    // between two looks once (PRODUCED moved)
    EXPECT_LT(high, 4);
    EXPECT_EQ(v.get("FLY:Seen") - seen0, 4 + high);
    // an output link cannot write the block
    std::ofstream(dir.path / "p.db") << "record(bo, \"FLY:Force\") { field(DTYP, \"beamctl\") field(OUT, \"@pcomp1.out\") }\n";
    try {
        VirtualIoc bad(path);
        FAIL() << "an output link on pcomp1.out was taken";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("p.db:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("FLY:PCOMP1:ENABLE, START, STEP"), std::string::npos) << e.what();
    }
}

} // namespace
