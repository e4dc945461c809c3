// Detectors in an IOC (docs/detectors.md): the simulated energy-dispersive detectors of
// `detectors.mca`, each behind synApps' mca record $(P)<name> (DTYP asynMCA, INP "@<name>") with
// the PVs of mca's mca.db around it: $(P)<name>Start, Stop, Erase, EraseStart (acquisition
// commands), Read (reads the spectrum every second while acquiring) and Status (every 0.1 s while
// acquiring); the detector acquires on the IOC loop's clock.
// Threading: the IOC loop (records and the simulated detectors alike).
#pragma once

#include "config/ioc_config.hpp"
#include "detector/sim_mca.hpp"
#include "ethercat/sim/beam.hpp"
#include "pv/database.hpp"

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ioc {

class IocDetectors {
public:
    // Makes the records (loaded into `db`) and the simulated detectors on `clock` [s].
    IocDetectors(const config::IocConfig& cfg, pv::Database& db, std::function<double()> clock);
    ~IocDetectors();
    // Device support of an mca record's INP "@<name>"; nullptr with `why` if no detector has it.
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view name, std::string& why);
    // The beam each detector's sample sees: `beam_of(bus)` (bus -1: the first with one), or nullptr
    // (the configured rates as they are). The rates follow the beam's transmission through the
    // slit. Throws Error naming the entry whose bus has no beam.
    void bind(const std::function<std::function<ethercat::sim::BeamTally()>(int bus)>& beam_of);
    std::size_t mcas() const { return mcas_.size(); }
    detector::SimMca& mca(std::size_t i) { return *mcas_.at(i); }

private:
    class McaRef;
    std::vector<std::string> names_;
    std::vector<config::McaEntry> entries_;
    std::vector<std::unique_ptr<detector::SimMca>> mcas_;
};

} // namespace beamctl::ioc
