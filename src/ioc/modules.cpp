#include "ioc/modules.hpp"

#include "detector/mca_module.hpp"
#include "detector/quadem_module.hpp"
#include "feedback/feedback_module.hpp"

namespace beamctl::ioc {
namespace {

template <class M, auto Section>
std::unique_ptr<module::Module> make(const config::IocConfig& cfg, module::BuildContext& ctx) {
    const auto& s = cfg.*Section;
    if (s.empty()) return nullptr;
    return std::make_unique<M>(s, ctx);
}

const ModuleEntry kModules[] = {
    // before feedback: the electrometers' values are loop inputs, read in the same cycle
    {"detectors.quadem", make<detector::QuadEmModule, &config::IocConfig::quadem>},
    {"feedback", make<feedback::FeedbackModule, &config::IocConfig::feedback>},
    // simulated energy-dispersive detectors behind synApps' mca record; they see the plant's beam
    {"detectors.mca", make<detector::McaModule, &config::IocConfig::mca>},
};

} // namespace

std::span<const ModuleEntry> module_table() { return kModules; }

} // namespace beamctl::ioc
