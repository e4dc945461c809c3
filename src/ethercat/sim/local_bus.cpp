#include "ethercat/sim/local_bus.hpp"

#include "core/error.hpp"
#include "ethercat/raw_link.hpp"
#include "ethercat/sim/faults.hpp"
#include "ethercat/sim/inprocess_link.hpp"
#include "ethercat/sim/sim_config.hpp"

namespace beamctl::ethercat::sim {

namespace {
// The simulator follows the engine clock (ns since 2000-01-01 in the slaves' DC registers).
struct SimTimeStage : rt::Stage {
    Segment& seg;
    explicit SimTimeStage(Segment& s) : seg(s) {}
    const char* name() const noexcept override { return "simulator time"; }
    void run(const rt::CycleInfo& c) noexcept override { seg.set_time(c.t_ns); }
};
} // namespace

LocalBus make_local_bus(const config::BusConfig& bc, const Catalog& catalog, const std::string& config_path) {
    LocalBus b;
    std::vector<SlaveConfig> slaves;
    for (const auto& s : bc.slaves) {
        if (!catalog.find(s.type))
            throw Error(SB() << config_path << ": bus " << bc.id << " position " << s.position << ": "
                             << catalog.unknown_type_error(s.type));
        if (s.oversampling != 1) {
            try {
                (void)catalog.find(s.type)->with_oversampling(s.oversampling);
            } catch (const Error& e) {
                throw Error(SB() << s.oversampling_where << ": " << e.what());
            }
        }
        std::vector<StartupSdo> sdos;
        for (const auto& d : s.sdo) sdos.push_back({d.index, d.sub, d.value, d.size});
        slaves.emplace_back(s.position, s.type, std::move(sdos));
        slaves.back().oversampling = s.oversampling;
    }
    std::unique_ptr<Link> link;
    if (bc.link.type == "sim") {
        // The simulated segment has exactly the configured slaves; gaps get an EK1100.
        b.segment = std::make_unique<Segment>();
        b.segment->add_configured(config::positions_and_types(bc), catalog);
        // The plant: the file's stages, signals and wiring; every drive it does not name moves a
        // default stage (also without a plant file).
        SimConfig sim;
        if (!bc.link.plant.empty()) {
            sim = SimConfig::load(bc.link.plant, catalog);
            if (!sim.slaves.empty())
                throw Error(SB() << bc.link.plant << ": a plant file used by an IOC or a scanner takes its slaves from that file; remove 'slaves:'");
        }
        b.plant = sim.build(*b.segment, catalog);
        // link.faults: the segment starts with them (a slave without power, a refusal, ...).
        for (std::size_t k = 0; k < bc.link.faults.size(); ++k) {
            try {
                b.segment->apply(parse_fault(bc.link.faults[k], catalog, b.segment->size()));
            } catch (const Error& e) {
                throw Error(SB() << bc.link.faults_where[k] << ": " << e.what());
            }
        }
        link = std::make_unique<InProcessLink>(*b.segment);
        b.sim_stage = std::make_unique<SimTimeStage>(*b.segment);
    } else if (bc.link.type == "raw") {
        link = std::make_unique<RawLink>(bc.link.iface, bc.link.busy_poll);
    } else if (bc.link.type == "udp") {
        link = std::make_unique<UdpLink>(bc.link.host, bc.link.port);
    } else {
        throw Error(SB() << config_path << ": bus " << bc.id << ": link type '" << bc.link.type << "' is not a bus of this process");
    }
    b.bus = std::make_unique<Bus>(bc.id, std::move(link), std::move(slaves), catalog);
    b.bus->set_strict(bc.strict);
    return b;
}

} // namespace beamctl::ethercat::sim
