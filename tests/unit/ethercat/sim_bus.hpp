// Test fixture shared by the EtherCAT unit tests: a simulated segment of the given catalog types
// behind an in-process link, with the matching slave configuration.
#pragma once

#include "ethercat/catalog.hpp"
#include "ethercat/link.hpp"
#include "ethercat/sim/inprocess_link.hpp"
#include "ethercat/master.hpp"
#include "core/error.hpp"
#include "ethercat/sim/segment.hpp"
#include "ethercat/sim/sim_config.hpp"

#include <memory>

#include <iterator>
#include <string>
#include <vector>

namespace beamctl::ethercat::simbus {

inline const char* kDemo[] = {"EK1100", "EL1008", "EL1008", "EL2008", "EL2808", "EL3104", "EL4134",
                              "EL5101", "EL7041", "EL7211", "EL5042", "EL3102", "EL4102", "EL1252"};

inline std::vector<std::string> demo() { return std::vector<std::string>(std::begin(kDemo), std::end(kDemo)); }

struct Bus {
    sim::Segment seg;
    sim::InProcessLink link{seg};
    std::vector<SlaveConfig> cfg;
    explicit Bus(std::vector<std::string> types) {
        for (std::size_t i = 0; i < types.size(); ++i) {
            seg.add(*Catalog::builtin().find(types[i]));
            cfg.push_back({int(i), types[i]});
        }
    }
};


// A master in OP over an in-process segment with the plant of a SIM.yaml text (slaves listed),
// advanced in 1 ms cycles of virtual time; `sdos_for_last` are startup SDOs of the last slave.
struct PlantBus {
    sim::Segment seg;
    sim::InProcessLink link{seg};
    std::shared_ptr<sim::Plant> plant;
    std::unique_ptr<Master> m;
    uint64_t t = 1'000'000'000;

    explicit PlantBus(const std::string& yaml, std::vector<StartupSdo> sdos_for_last = {}) {
        const Catalog& cat = Catalog::builtin();
        sim::SimConfig c = sim::SimConfig::parse(yaml, "plant.yaml", cat);
        plant = c.build(seg, cat);
        std::vector<SlaveConfig> cfg;
        for (auto& [pos, type] : c.slaves) cfg.emplace_back(pos, type);
        if (!sdos_for_last.empty()) cfg.back().sdos = sdos_for_last;
        seg.set_time(t);
        m = std::make_unique<Master>(link, 0, cfg, cat);
        m->bring_up();
    }
    // One cycle: receive, then `work` (what the RT stages between receive and send do), send next.
    template <class F>
    void cycle(F&& work) {
        t += 1'000'000;
        seg.set_time(t);
        m->send_process_data();
        m->receive_process_data();
        work();
    }
    void cycles(int n) {
        for (int i = 0; i < n; ++i) cycle([] {});
    }
    const SignalInfo& sig(const std::string& name) {
        const SignalInfo* s = m->find_signal(name);
        if (!s) throw Error("no signal " + name);
        return *s;
    }
    uint64_t get(const std::string& name) { return m->get(sig(name)); }
    int64_t get_signed(const std::string& name) {
        const SignalInfo& s = sig(name);
        uint64_t v = m->get(s);
        if (s.bits < 64 && (v >> (s.bits - 1) & 1)) v |= ~uint64_t(0) << s.bits;
        return int64_t(v);
    }
    void set(const std::string& name, uint64_t v) { m->set(sig(name), v); }
};

} // namespace beamctl::ethercat::simbus
