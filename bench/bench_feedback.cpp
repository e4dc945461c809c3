// Fast feedback cost: CPU per cycle of one EPID loop in the cycle (feedback::FastEpidLoop: the
// parameter mailbox, averaging, the step, the state published to the IOC loop), on a loop-back
// plant (the input follows the output), a step every cycle (DT = one cycle) and averaging over 10
// samples. Issue 16 target: <= 100 ns per loop per cycle. BM_EpidStep: the controller step alone.
#include "feedback/fast_epid.hpp"

#include <benchmark/benchmark.h>

using namespace beamctl::feedback;

namespace {

void BM_EpidStep(benchmark::State& st) {
    EpidInput in;
    in.kp = 0.3, in.ki = 100, in.kd = 0.001, in.drvh = 5, in.drvl = -5, in.fbon = in.fbop = true, in.dt = 1e-4;
    in.setpoint = 1;
    EpidTerms t;
    double y = 0;
    for (auto _ : st) {
        in.cval = y;
        t.oval = epid_step(in, t);
        y += 0.5 * (t.oval - y);
        benchmark::DoNotOptimize(y);
    }
}
BENCHMARK(BM_EpidStep);

void BM_FastEpidLoopCycle(benchmark::State& st) {
    const int samples = int(st.range(0));
    FastEpidLoop::Params p;
    p.kp = 0.3, p.ki = 100, p.drvh = 5, p.drvl = -5, p.fbon = true, p.setpoint = 1, p.dt = samples * 1e-4;
    FastEpidLoop loop(1e-4, p); // 10 kHz
    double y = 0, out = 0, u = 0;
    for (auto _ : st) {
        if (loop.cycle(true, y, u, out)) u = out;
        y += 0.5 * (u - y);
        benchmark::DoNotOptimize(y);
    }
    st.counters["steps"] = double(loop.steps());
}
BENCHMARK(BM_FastEpidLoopCycle)->Arg(1)->Arg(10);

} // namespace

BENCHMARK_MAIN();
