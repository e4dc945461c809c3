// Automation kernels (issue 17): the Levenberg-Marquardt fit of a rocking curve (a 101-point
// Lorentzian on a background with 2 % noise, the seed's alignment step) and of a Gaussian and an
// edge of the same size; the compound motors' update (examples/snd: E1, E2 and Delay over 13 of the
// 28 simulated axes), one IOC-loop poll of all three groups, and one forward evaluation.
// Issue 17 figures: fit time for a 101-point Lorentzian, compound motor update cost.
#include "automation/compound_motor.hpp"
#include "automation/fit.hpp"
#include "config/ioc_config.hpp"
#include "core/macros.hpp"
#include "pv/db_file.hpp"

#include <fstream>
#include <sstream>

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

// The split-and-delay example's database and compound motors, initialised (the IOC's order).
struct Snd {
    beamctl::pv::Database db;
    std::unique_ptr<CompoundMotors> cm;
    Snd() {
        const std::string dir = BEAMCTL_SOURCE_DIR "/examples/snd/";
        const auto cfg = beamctl::config::IocConfig::load(dir + "ioc.yaml");
        std::ifstream f(dir + "snd_motors.db");
        std::stringstream text;
        text << f.rdbuf();
        db.load(beamctl::pv::parse_db(text.str(), "snd_motors.db", {{"P", "SND:"}}));
        cm = std::make_unique<CompoundMotors>(cfg.compound_motors, "SND:", db);
        db.init_records();
        cm->start();
    }
};

void BM_CompoundPoll(benchmark::State& st) {
    Snd snd;
    for (auto _ : st) snd.cm->poll();
    st.counters["groups"] = double(snd.cm->groups());
}
BENCHMARK(BM_CompoundPoll)->Unit(benchmark::kMicrosecond);

void BM_CompoundForward(benchmark::State& st) {
    Snd snd;
    double e = 0;
    for (auto _ : st) benchmark::DoNotOptimize(e = snd.cm->evaluate_forward(2)); // Delay: 5 names, 8 functions
    st.counters["delay_ps"] = e;
}
BENCHMARK(BM_CompoundForward);

} // namespace

BENCHMARK_MAIN();
