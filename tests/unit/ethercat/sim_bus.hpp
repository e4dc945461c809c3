// Test fixture shared by the EtherCAT unit tests: a simulated segment of the given catalog types
// behind an in-process link, with the matching slave configuration.
#pragma once

#include "ethercat/catalog.hpp"
#include "ethercat/link.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/segment.hpp"

#include <iterator>
#include <string>
#include <vector>

namespace beamctl::ethercat::simbus {

inline const char* kDemo[] = {"EK1100", "EL1008", "EL1008", "EL2008", "EL2808", "EL3104", "EL4134",
                              "EL5101", "EL7041", "EL7211", "EL5042", "EL3102", "EL4102", "EL1252"};

inline std::vector<std::string> demo() { return std::vector<std::string>(std::begin(kDemo), std::end(kDemo)); }

struct Bus {
    sim::Segment seg;
    InProcessLink link{seg};
    std::vector<SlaveConfig> cfg;
    explicit Bus(std::vector<std::string> types) {
        for (std::size_t i = 0; i < types.size(); ++i) {
            seg.add(*Catalog::builtin().find(types[i]));
            cfg.push_back({int(i), types[i]});
        }
    }
};

} // namespace beamctl::ethercat::test
