// The IOC's memory maps (ECMC's Cfg.EcAddMemMapDT, which ecmccfg's hardware scripts issue for
// oversampling terminals): one per oversampled channel of every configured slave whose catalog
// device has them (EL3702 mm.analogInputArray01/02, EL4732 mm.analogOutputArray01/02), with
// ECMC's ids in creation order: bus, slave position, channel. PLC code uses them by id
// (ec_get_mm_data, ec_mm_cp, ec_mm_append_to_ds, ...); each is served as a waveform named as
// ecmccfg's ecmc_analogInputArray-chX.template / ecmc_analogOutputArray-chX.template:
//   $(P)m<bus>s<kkk>-AI01-Arr  (waveform, FTVL from the entry type, NELM = samples per cycle)
//       the samples of the last cycle: published on change at most every 0.1 s, and at the
//       next look after ec_mm_push_asyn; INVALID with the slave's alarm while it has no data
//   $(P)m<bus>s<kkk>-AO01-Arr  a put writes the samples sent from the next cycle on
// Other memory map names get $(P)m<bus>s<kkk>-mm-<name>.
// Threading: construction and bind before the cycle starts; publish() and puts on the IOC loop
// (they read the bus snapshot and queue output writes, never the RT image).
#pragma once

#include "config/ioc_config.hpp"
#include "ethercat/bus.hpp"
#include "ethercat/catalog.hpp"
#include "pv/database.hpp"
#include "registry/memmap.hpp"
#include "registry/registry.hpp"

#include <deque>
#include <string>
#include <vector>

namespace beamctl::ioc {

class IocMemMaps {
public:
    // Makes the memory maps of `cfg`'s buses and their records (loaded into `db` here).
    IocMemMaps(const config::IocConfig& cfg, const ethercat::Catalog& catalog, pv::Database& db);
    IocMemMaps(const IocMemMaps&) = delete;
    IocMemMaps& operator=(const IocMemMaps&) = delete;

    // Bring-up, after the buses: every map bound to the image (its elements must follow each
    // other there, else Error naming the map). `buses` in the order of cfg.buses.
    void bind(registry::Registry& reg, const std::vector<ethercat::Bus*>& buses);
    // IOC loop: input arrays into their PVs (change or push), after the buses' snapshot().
    void publish(double now_s);

    std::vector<registry::MemMap*> memmaps(); // by ECMC id
    std::size_t bus_index(std::size_t id) const { return items_.at(id).bus; } // memory map id's bus (index in cfg.buses)
    // The registry names of map `name`'s elements ("ec0.s7.mm.analogInputArray01" ->
    // ec0.s7.analogInputArray01_1 .. _n, in time order); nullptr if there is no such map.
    const std::vector<std::string>* elements(const std::string& name) const;
    std::size_t size() const { return items_.size(); }

private:
    struct Item {
        registry::MemMap map;
        std::size_t bus = 0;           // index in cfg.buses / bind's `buses`
        int slave = 0;                 // bus position
        std::string first;             // registry name of element 0, "ec0.s5.analogInputArray01_1"
        std::vector<std::string> elements; // registry names of every element
        pv::Record* rec = nullptr;
        std::vector<const ethercat::SignalInfo*> sig; // per element (after bind)
        std::vector<double> last;      // values last published
        uint32_t pushes_seen = 0;
        double published_s = -1;
    };
    bool fresh(const Item& it, const ethercat::BusSnapshot& s, std::size_t& slave_index) const;

    pv::Database& db_;
    std::deque<Item> items_; // MemMap holds an atomic: never moved
    std::vector<ethercat::Bus*> buses_;
    std::vector<double> scratch_;
};

} // namespace beamctl::ioc
