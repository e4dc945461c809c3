// The IOC's data storages: `storages:` of the IOC file (ecmccfg addDataStorage.cmd), each a
// daq::DataStorage that PLC code fills in the cycle (ds<n>.*, ds_*), published once per cycle
// after the PLCs (stage Triggers) when due, and served as PVs.
//
// PVs ($(P) = the IOC prefix, nn = the id as two digits, as ecmccfg's ecmcDS.substitutions), from
// one table (storages.cpp, storage_table):
//   $(P)DSnn-DataAct  (waveform, NELM = capacity) the buffer's `size` values
//   $(P)DSnn-DataSet  (waveform) a put writes the values from index 0 (ECMC setData)
//   $(P)DSnn-DataIdAct (ai) the write index    -Stat (longin: bit 0 full, bits 16..19 type)
//   $(P)DSnn-Full (bi)  -Type (mbbi)  -Size, -Count, -Err (longin)  -ClrCmd (bo: 1 clears)
//   $(P)DSnn-Desc (stringin)
// Threading: construction before the cycle starts; publish() and the PVs' puts on the IOC loop.
#pragma once

#include "config/ioc_config.hpp"
#include "daq/data_storage.hpp"
#include "pv/database.hpp"
#include "rt/engine.hpp"

#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

class IocStorages {
public:
    // Makes the storages and their records (the records are loaded into `db` here).
    IocStorages(const config::IocConfig& cfg, pv::Database& db);
    IocStorages(const IocStorages&) = delete;
    IocStorages& operator=(const IocStorages&) = delete;

    // Bring-up: the storages' publication stage (after the PLCs).
    void bind(rt::Engine& engine);
    // IOC loop: new snapshots into the PVs.
    void publish();

    std::vector<daq::DataStorage*> storages();
    std::size_t size() const { return items_.size(); }

private:
    struct Item {
        std::unique_ptr<daq::DataStorage> ds;
        pv::Record *data = nullptr, *data_set = nullptr, *index = nullptr, *stat = nullptr, *full = nullptr,
                   *type = nullptr, *size = nullptr, *count = nullptr, *err = nullptr, *clear = nullptr;
    };
    class Stage : public rt::Stage {
    public:
        explicit Stage(std::vector<Item>& items) : items_(items) {}
        const char* name() const noexcept override { return "storages"; }
        void run(const rt::CycleInfo& c) noexcept override {
            for (Item& i : items_) i.ds->publish(c.cycle);
        }

    private:
        std::vector<Item>& items_;
    };

    pv::Database& db_;
    std::vector<Item> items_;
    std::unique_ptr<Stage> stage_;
    std::vector<double> scratch_;
};

} // namespace beamctl::ioc
