// The quad-electrometer module (docs/detectors.md): each entry of `detectors.quadem` reads four
// engine values (the diodes' currents: bus entries of analog inputs, as a current amplifier on an
// EL3104 gives them) once per cycle, computes quadEM's 11 values (detector/quadem.hpp) and serves
// quadEM's PVs under $(P)<name>: (quadEM.template's Acquire, AcquireMode, NumAcquire, NumAcquired,
// AveragingTime, NumAverage_RBV, NumAveraged_RBV, SampleTime_RBV, Geometry, CurrentOffset/Scale1-4,
// PositionOffset/ScaleX/Y, Current1Ave .. PositionYAve, RingOverflows, and the statistics plugins'
// <value>:MeanValue_RBV, SigmaValue_RBV, MinValue_RBV, MaxValue_RBV), and the time-series plugin's
// under $(P)<name>:TS: (NDTimeSeries: TSAcquire, TSAcquireMode, TSNumPoints, TSAveragingTime, ...;
// NDTimeSeriesN: TS:<value>:TimeSeries, TS:<value>:Name): every sample of the cycle, averaged
// TSNumAverage = TSAveragingTime / SampleTime at a time, a point each.
// The cycle's values are engine signals <name in lower case>.<value in lower case> (qe1.posy,
// qe1.sumall, ...): a fast feedback loop reads them in the same cycle (the stage runs before the
// loops). They follow every cycle whatever Acquire says; Acquire gates the averaged readings.
// Threading: construction before the registry freezes; bind() at bring-up; the stage on the RT
// thread; publish() and the records on the IOC loop.
#pragma once

#include "config/ioc_config.hpp"
#include "detector/quadem.hpp"
#include "module/module.hpp"
#include "module/value_source.hpp"
#include "pv/database.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::detector {

class QuadEmModule : public module::Module {
public:
    // Declares the signals, makes the records (loaded into `db`). Throws Error (file:line:col).
    QuadEmModule(std::vector<config::QuadEmEntry> section, module::BuildContext& ctx);
    ~QuadEmModule() override;
    QuadEmModule(const QuadEmModule&) = delete;
    QuadEmModule& operator=(const QuadEmModule&) = delete;

    // Bring-up: resolves the currents in the cycle of `engine` and adds the stage (Triggers, before
    // the feedback loops: bind this first).
    std::string_view name() const override { return "detectors.quadem"; }
    void bind(module::BindContext& ctx) override;
    // IOC loop: the readings into the PVs.
    void publish(double now_s) override;

    std::size_t size() const { return units_.size(); }
    const QuadEm& unit(std::size_t i) const;

private:
    struct Unit;
    class Stage;

    void apply(Unit& u); // the parameter PVs -> the electrometer
    void set_acquire(Unit& u, bool on);
    void ts_settings(Unit& u); // the time series' parameter PVs -> their readbacks
    void ts_start(Unit& u);
    void ts_stop(Unit& u);
    void ts_take(Unit& u);
    void ts_publish(Unit& u);

    registry::Registry& reg_;
    pv::Database& db_;
    std::vector<std::unique_ptr<Unit>> units_;
    std::unique_ptr<Stage> stage_;
    double cycle_s_ = 1e-3;
};

} // namespace beamctl::detector
