// Motion cycle cost: CPU per cycle of an AxisGroup of physical axes (encoder, S-curve or
// trapezoid trajectory, PID + feed-forward, monitoring, drive), the RT work of the Axes stage.
// The axes read and write a plain process image (no bus): a loop-back "drive" integrates the
// velocity setpoint into the encoder counter so that they really move, and each axis is sent a
// new target whenever it arrives. Issue #4 target: 16 axes at 10 kHz within 5 % of one core,
// i.e. <= 5 us per cycle for all 16. BM_AxisGroupPvt: the same axes following PVT profile paths
// (cubic Hermite, 2000 points) with the profile controller's per-cycle work (issue 13).
#include "motion/axis_group.hpp"
#include "motion/pvt.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

using namespace beamctl;
using namespace beamctl::motion;

namespace {

// Per axis in the image: control u16 @0, setpoint s32 @2, status u16 @6, encoder u32 @8.
constexpr uint32_t kStride = 12;

struct Bench {
    std::vector<uint8_t> image;
    std::unique_ptr<AxisGroup> group;
    std::vector<double> pos; // loop-back plant position [counts]
    int n;
    bool scurve;
    bool retarget = true; // send new targets to idle axes
    uint64_t cycle = 0;

    Bench(int axes, bool s) : image(std::size_t(axes) * kStride, 0), pos(std::size_t(axes), 0), n(axes), scurve(s) {
        std::vector<std::unique_ptr<Axis>> v;
        for (int i = 0; i < n; ++i) {
            uint8_t* base = image.data();
            uint32_t off = uint32_t(i) * kStride * 8;
            AxisParams p;
            p.id = i + 1;
            p.encoder.numerator = 1;
            p.encoder.denominator = 10000; // 0.1 um counts
            p.encoder.bits = 32;
            p.drive.type = DriveParams::Type::Stepper;
            p.drive.numerator = 100; // 100 mm/s at 2^31
            p.drive.denominator = 2147483648.0;
            p.controller.kp = 50;
            p.controller.ki = 10;
            p.trajectory = {20, 200, 200, scurve ? 2000.0 : 0.0};
            p.lag_enable = true;
            p.lag_tolerance = 1;
            p.lag_time_cycles = 1000;
            p.target_enable = true;
            p.target_tolerance = 0.001;
            p.target_time_cycles = 10;
            p.velocity_enable = true;
            p.velocity_max = 50;
            p.soft_fwd_enable = p.soft_bwd_enable = true;
            p.soft_fwd = 100;
            p.soft_bwd = -100;
            AxisIo io;
            io.drive_control = registry::BoundSignal{base, off, 16, false, -1};
            io.drive_setpoint = registry::BoundSignal{base, off + 16, 32, true, -1};
            io.drive_status = registry::BoundSignal{base, off + 48, 16, false, -1};
            io.encoder = registry::BoundSignal{base, off + 64, 32, false, -1};
            v.push_back(std::make_unique<Axis>(p, io));
        }
        group = std::make_unique<AxisGroup>(std::move(v));
        for (int i = 0; i < n; ++i) {
            AxisCommand on{CommandType::Power};
            on.on = true;
            group->send(std::size_t(i), on);
        }
    }
    // The "terminals": enabled bit follows enable, velocity integrates into the counter.
    void plant(double dt) {
        for (int i = 0; i < n; ++i) {
            uint8_t* a = image.data() + std::size_t(i) * kStride;
            uint16_t cw;
            int32_t sp;
            std::memcpy(&cw, a, 2);
            std::memcpy(&sp, a + 2, 4);
            uint16_t sw = (cw & 1) ? 0x3 : 0x1;
            std::memcpy(a + 6, &sw, 2);
            pos[std::size_t(i)] += double(sp) / 2147483648.0 * 100 * 10000 * dt;
            uint32_t c = uint32_t(int64_t(std::llround(pos[std::size_t(i)])));
            std::memcpy(a + 8, &c, 4);
        }
    }
    void step(double dt) {
        plant(dt);
        rt::CycleInfo ci{cycle++, 0, uint64_t(dt * 1e9)};
        group->run(ci);
        // new targets for idle axes (through the queue, as PV writes would come)
        if (retarget && cycle % 16 == 0)
            for (int i = 0; i < n; ++i)
                if (!group->axis(std::size_t(i)).status().busy && group->axis(std::size_t(i)).status().enabled) {
                    double t = (cycle / 16 + i) % 2 ? 5.0 + i : -5.0 - i;
                    group->send(std::size_t(i), AxisCommand{CommandType::MoveAbsolute, t});
                }
    }
};

void BM_AxisGroupCycle(benchmark::State& st) {
    Bench b(int(st.range(0)), st.range(1) != 0);
    double dt = 1e-4; // 10 kHz
    for (int i = 0; i < 100; ++i) b.step(dt);
    for (auto _ : st) b.step(dt);
    int moving = 0;
    for (int i = 0; i < b.n; ++i) moving += b.group->axis(std::size_t(i)).status().busy;
    st.counters["axes"] = double(b.n);
    st.counters["busy_at_end"] = moving;
    uint32_t errors = 0;
    for (int i = 0; i < b.n; ++i) errors |= b.group->axis(std::size_t(i)).status().error_id;
    st.counters["errors"] = errors;
}
BENCHMARK(BM_AxisGroupCycle)->Args({1, 1})->Args({16, 0})->Args({16, 1})->ArgNames({"axes", "scurve"});

// 16 axes each on its own 2000-point path (20 s at 10 ms per segment), run by one PvtController
// with 2000 pulses and readbacks: the cost per cycle while the profile executes.
void BM_AxisGroupPvt(benchmark::State& st) {
    Bench b(int(st.range(0)), true);
    b.retarget = false;
    const double dt = 1e-4;
    const std::size_t points = 2000;
    std::vector<PvtPath> paths;
    for (int i = 0; i < b.n; ++i) {
        std::vector<double> pos(points), t(points - 1, 0.01);
        for (std::size_t k = 0; k < points; ++k) pos[k] = 5 * std::sin(double(k) * 0.01 + i);
        paths.push_back(PvtPath::build(pos, t, 0.1));
    }
    std::vector<std::vector<double>> rb(std::size_t(b.n), std::vector<double>(points)), fe = rb;
    std::vector<std::atomic<uint32_t>> counts(std::size_t(b.n));
    PvtController ctl(dt);
    PvtController::Job job;
    job.n = std::size_t(b.n);
    job.pulses = uint32_t(points);
    job.start_t = 0.1;
    job.between = 0.01;
    job.duration_s = 0.001;
    for (int i = 0; i < b.n; ++i)
        job.axes[std::size_t(i)] = {&b.group->axis(std::size_t(i)), i, &paths[std::size_t(i)], rb[std::size_t(i)].data(),
                                    fe[std::size_t(i)].data(), uint32_t(points), &counts[std::size_t(i)]};
    auto step = [&] {
        b.step(dt);
        rt::CycleInfo ci{b.cycle, 0, uint64_t(dt * 1e9)};
        ctl.run(ci);
        if (ctl.status().state == PvtController::State::Idle) (void)ctl.execute(job);
    };
    (void)ctl.execute(job);
    int k = 0;
    while (ctl.status().state != PvtController::State::Executing && k++ < 2000000) step(); // enable, go to start
    for (auto _ : st) step();
    st.counters["axes"] = double(b.n);
    st.counters["executing_at_end"] = ctl.status().state == PvtController::State::Executing;
    st.counters["pulses"] = ctl.status().pulses;
    uint32_t errors = 0;
    for (int i = 0; i < b.n; ++i) errors |= b.group->axis(std::size_t(i)).status().error_id;
    st.counters["errors"] = errors;
}
BENCHMARK(BM_AxisGroupPvt)->Arg(1)->Arg(16)->ArgNames({"axes"});

} // namespace

BENCHMARK_MAIN();
