// Fast feedback in an IOC (docs/feedback.md): the loops of `feedback:`, synApps' EPID run in the
// Triggers stage of the cycle (after the axes and PLCs, before bus send: an output leaves in the
// same cycle's frame) on an engine value (a bus entry, an axis variable) and a bus output entry.
// Each loop's interface is the epid record $(P)<name> (DTYP "Fast Epid", INP "@<name>"): its scan
// hands the loop KP KI KD VAL FBON DRVH DRVL DT and reads back CVAL ERR OVAL P I D DT. A loop
// takes no step while the bus of its input or output is not in OP and all its slaves answer
// (ec<m>.masterstatus); the record is INVALID then, and the loop restarts bumplessly after.
// Threading: construction and bind() before the cycle starts; the stage on the RT thread; the
// records' exchange on the IOC loop.
#pragma once

#include "config/ioc_config.hpp"
#include "feedback/fast_epid.hpp"
#include "ioc/value_source.hpp"
#include "pv/database.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ioc {

class IocFeedback {
public:
    // Makes the records (loaded into `db`) and claims the outputs. Throws Error (file:line:col).
    IocFeedback(const config::IocConfig& cfg, registry::Registry& reg, pv::Database& db);
    ~IocFeedback();
    IocFeedback(const IocFeedback&) = delete;
    IocFeedback& operator=(const IocFeedback&) = delete;

    bool enabled() const { return !loops_.empty(); }
    // Bring-up: resolves the inputs and outputs in the cycle of `engine`; adds the stage.
    void bind(rt::Engine& engine, motion::AxisGroup* axes);
    // Device support "Fast Epid" of an epid record, INP "@<name>"; nullptr with `why` if no loop
    // has that name.
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view name, std::string& why);

    // Tests and benchmarks.
    std::size_t loops() const { return loops_.size(); }
    const feedback::FastEpidLoop& loop(std::size_t i) const { return *loops_.at(i)->loop; }
    // The output's present value [output units], as the loop reads it back (RT side).
    double output_value(std::size_t i) const { return loops_.at(i)->read_output(); }

private:
    struct Loop {
        config::FeedbackEntry cfg;
        std::unique_ptr<feedback::FastEpidLoop> loop;
        ValueSource inp;
        registry::BoundSignal out;
        uint8_t out_float_bits = 0;      // 32/64: a REAL/LREAL output, else an integer one
        int64_t out_min = 0, out_max = 0; // an integer output's range
        registry::BoundSignal in_ok, out_ok; // the buses' masterstatus (unbound: always good)
        double read_output() const noexcept;
        void write_output(double v) const noexcept;
    };
    class Stage;
    class Device;

    config::IocConfig cfg_;
    registry::Registry& reg_;
    pv::Database& db_;
    std::vector<std::unique_ptr<Loop>> loops_;
    std::unique_ptr<Stage> stage_;
};

} // namespace beamctl::ioc
