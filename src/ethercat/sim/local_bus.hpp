// A bus this process masters, assembled from its configuration (an IOC file's or a scanner
// file's `buses:` entry): the slave list for the master, the link (a raw interface, UDP to
// `beamctl sim`, or an in-process simulated segment with its plant and start-up faults), and for
// a simulated segment the stage that keeps its clock on the engine's. One place for the IOC and
// the scanner, so both run the same buses the same way.
// Threading: configuration time; the stage runs on the RT thread.
#pragma once

#include "config/ioc_config.hpp"
#include "ethercat/bus.hpp"
#include "ethercat/sim/plant.hpp"
#include "ethercat/sim/segment.hpp"

#include <memory>

namespace beamctl::ethercat::sim {

struct LocalBus {
    std::unique_ptr<Segment> segment;  // type sim: the simulated slaves (owned here, used by the link)
    std::shared_ptr<Plant> plant;      // type sim: runs in the segment's on_frame
    std::unique_ptr<rt::Stage> sim_stage; // type sim: the segment's clock follows the engine (add it at BusSend)
    std::unique_ptr<Bus> bus;
};

// Throws Error naming the file position of what is wrong (unknown type, bad plant, bad fault).
// `config_path` names the file in errors. Not for `type: scanner` links.
LocalBus make_local_bus(const config::BusConfig& bc, const Catalog& catalog, const std::string& config_path);

} // namespace beamctl::ethercat::sim
