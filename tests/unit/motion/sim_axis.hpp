// Test fixture shared by the motion unit tests: a master in OP over an in-process simulated
// segment with the plant of a YAML text, advanced in 1 ms cycles of virtual time.
#pragma once

#include "ethercat/catalog.hpp"
#include "ethercat/link.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::motion::test {

struct SimBus {
    ethercat::sim::Segment seg;
    ethercat::InProcessLink link{seg};
    std::shared_ptr<ethercat::sim::Plant> plant;
    std::unique_ptr<ethercat::Master> m;
    uint64_t t = 1'000'000'000;
    explicit SimBus(const std::string& yaml) {
        const auto& cat = ethercat::Catalog::builtin();
        auto c = ethercat::sim::SimConfig::parse(yaml, "plant.yaml", cat);
        plant = c.build(seg, cat);
        std::vector<ethercat::SlaveConfig> cfg;
        for (auto& [pos, type] : c.slaves) cfg.emplace_back(pos, type);
        seg.set_time(t);
        m = std::make_unique<ethercat::Master>(link, 0, cfg, cat);
        m->bring_up();
    }
    // One 1 ms cycle: receive, then `work` (what the axis stage does), then send.
    template <class F>
    void cycle(F&& work) {
        t += 1'000'000;
        seg.set_time(t);
        m->send_process_data();
        m->receive_process_data();
        work();
    }
};

} // namespace beamctl::motion::test
