// Test fixture of the motion unit tests: the EtherCAT tests' PlantBus (a master in OP over an
// in-process simulated segment with its plant, 1 ms cycles of virtual time).
#pragma once

#include "../ethercat/sim_bus.hpp"

namespace beamctl::motion::test {

using SimBus = ethercat::simbus::PlantBus;

} // namespace beamctl::motion::test
