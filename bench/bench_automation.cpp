// Automation kernels (issue 17): the Levenberg-Marquardt fit of a rocking curve (a 101-point
// Lorentzian on a background with 2 % noise, the seed's alignment step) and of a Gaussian and an
// edge of the same size. Issue 17 figure: fit time for a 101-point Lorentzian.
#include "automation/fit.hpp"

#include <benchmark/benchmark.h>

#include <random>
#include <vector>

using namespace beamctl::automation;

namespace {

void BM_Fit101(benchmark::State& st) {
    const auto model = FitModel(st.range(0));
    FitResult truth;
    truth.model = model, truth.center = 0.3, truth.width = 0.02, truth.amplitude = 1, truth.background = 0.1;
    std::vector<double> x(101), y(101);
    std::mt19937 rng(1);
    std::normal_distribution<double> noise(0, 0.02);
    for (int i = 0; i < 101; ++i) x[i] = 0.25 + 0.1 * i / 100.0, y[i] = truth(x[i]) + noise(rng);
    FitResult r;
    for (auto _ : st) {
        r = fit_curve(model, x, y);
        benchmark::DoNotOptimize(r.center);
    }
    st.counters["evaluations"] = r.evaluations;
    st.counters["ok"] = r.ok;
    st.SetLabel(fit_model_name(model));
}
BENCHMARK(BM_Fit101)->Arg(int(FitModel::Lorentzian))->Arg(int(FitModel::Gaussian))->Arg(int(FitModel::Edge))->Unit(benchmark::kMicrosecond);

} // namespace

BENCHMARK_MAIN();
