// The fast-feedback module (docs/feedback.md): the loops of `feedback:`, synApps' EPID run in the
// Triggers stage of the cycle (after the axes and PLCs, before bus send: an output leaves in the
// same cycle's frame) on an engine value (a bus entry, an axis variable) and a bus output entry.
// Each loop's interface is the epid record $(P)<name> (DTYP "Fast Epid", INP "@<name>"), from the
// module's PV table: its scan hands the loop KP KI KD VAL FBON DRVH DRVL DT and reads back CVAL
// ERR OVAL P I D DT. A loop takes no step while the bus of its input or output is not in OP and
// all its slaves answer (ec<m>.masterstatus); the record is INVALID then, and the loop restarts
// bumplessly after.
// Threading: construction and bind() before the cycle starts; the stage on the RT thread; the
// records' exchange on the IOC loop.
#pragma once

#include "config/ioc_config.hpp"
#include "feedback/fast_epid.hpp"
#include "module/module.hpp"
#include "module/pv_table.hpp"
#include "module/value_source.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::feedback {

class FeedbackModule : public module::Module {
public:
    // Loads the loops' records and claims their outputs. Throws Error (file:line:col).
    FeedbackModule(std::vector<config::FeedbackEntry> section, module::BuildContext& ctx);
    ~FeedbackModule() override;
    FeedbackModule(const FeedbackModule&) = delete;
    FeedbackModule& operator=(const FeedbackModule&) = delete;

    std::string_view name() const override { return "feedback"; }
    // "Fast Epid" device support of an epid record, INP "@<loop name>".
    bool owns_device(std::string_view record_type, std::string_view address) const override;
    std::unique_ptr<pv::LinkDevice> make_device(const module::DeviceRequest& rq, std::string& why) override;
    // Resolves the inputs and outputs in the IOC's cycle; adds the stage.
    void bind(module::BindContext& ctx) override;

    // The PV table of one loop (docs, `beamctl signals`): the epid record, its fields from the
    // loop's configuration ($(NAME), $(KP), ...).
    static const module::PvTable& table();

    // Tests and benchmarks.
    std::size_t loops() const { return loops_.size(); }
    const FastEpidLoop& loop(std::size_t i) const { return *loops_.at(i)->loop; }
    // The output's present value [output units], as the loop reads it back (RT side).
    double output_value(std::size_t i) const { return loops_.at(i)->read_output(); }

private:
    struct Loop {
        config::FeedbackEntry cfg;
        std::unique_ptr<FastEpidLoop> loop;
        module::ValueSource inp;
        registry::BoundSignal out;
        uint8_t out_float_bits = 0;      // 32/64: a REAL/LREAL output, else an integer one
        int64_t out_min = 0, out_max = 0; // an integer output's range
        registry::BoundSignal in_ok, out_ok; // the buses' masterstatus (unbound: always good)
        double read_output() const noexcept;
        void write_output(double v) const noexcept;
    };
    class Stage;
    class Device;

    registry::Registry& reg_;
    std::vector<std::unique_ptr<Loop>> loops_;
    std::unique_ptr<Stage> stage_;
};

} // namespace beamctl::feedback
