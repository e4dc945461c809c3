#include "ioc/storages.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "module/pv_table.hpp"
#include "ioc/pv_util.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace beamctl::ioc {
namespace {

log::Logger lg("storages");

// A storage's PVs, as ecmccfg names them ($(P) = "<prefix>DSnn"). Soft records: the IOC loop
// sets them from the storage's snapshots; DataSet and ClrCmd act through their put hooks.
const module::PvTable& storage_table() {
    static const module::PvTable t{"storage", {
        {"-DataAct", "waveform", "", {{"DESC", "$(DESC)"}, {"FTVL", "DOUBLE"}, {"NELM", "$(NELM)"}}},
        {"-DataSet", "waveform", "", {{"DESC", "ds$(ID): write from index 0"}, {"FTVL", "DOUBLE"}, {"NELM", "$(NELM)"}}},
        {"-DataIdAct", "ai", "", {{"DESC", "ds$(ID): write index"}, {"PREC", "0"}}},
        {"-Stat", "longin", "", {{"DESC", "ds$(ID): status word"}}},
        {"-Full", "bi", "", {{"DESC", "ds$(ID): buffer full"}, {"ZNAM", "Buffer not full"}, {"ONAM", "Buffer full"}}},
        {"-Type", "mbbi", "", {{"DESC", "ds$(ID): buffer type"}, {"ZRST", "Normal"}, {"ONST", "Ring"}, {"TWST", "FIFO"}}},
        {"-Size", "longin", "", {{"DESC", "ds$(ID): size (values)"}}},
        {"-Count", "longin", "", {{"DESC", "ds$(ID): valid values"}}},
        {"-Err", "longin", "", {{"DESC", "ds$(ID): error id (0 none)"}, {"HIGH", "1"}, {"HSV", "MINOR"}}},
        {"-ClrCmd", "bo", "", {{"DESC", "ds$(ID): clear (1)"}, {"ZNAM", "FALSE"}, {"ONAM", "TRUE"}}},
        {"-Desc", "stringin", "", {{"DESC", "ds$(ID): description"}, {"VAL", "$(DESC)"}}},
    }};
    return t;
}

void set_if_changed(pv::Database& db, pv::Record* r, double v) {
    if (r && (r->udf || get_value(*r) != v)) set_value(db, *r, v, false);
}

} // namespace

IocStorages::IocStorages(const config::IocConfig& cfg, pv::Database& db) : db_(db) {
    pv::DbFile f;
    double cycle_ms = 1000.0 / cfg.rate_hz;
    std::size_t most = 0;
    for (const config::StorageEntry& e : cfg.storages) {
        uint64_t period = uint64_t(std::max(1.0, std::round(e.sample_rate_ms / cycle_ms)));
        Item it;
        it.ds = std::make_unique<daq::DataStorage>(e.id, e.size, daq::BufferType(e.type), e.capacity, period);
        most = std::max(most, it.ds->capacity());
        module::PvInstance in{cfg.prefix + "DS" + two_digits(e.id), "",
                      {{"DESC", e.desc.substr(0, 40)}, {"ID", std::to_string(e.id)}, {"NELM", std::to_string(it.ds->capacity())}}};
        pv::merge_db(f, make_records(storage_table(), in, registry::Registry()));
        items_.push_back(std::move(it));
    }
    db_.load(f);
    scratch_.assign(most, 0.0);
    for (std::size_t k = 0; k < items_.size(); ++k) {
        Item& it = items_[k];
        std::string p = cfg.prefix + "DS" + two_digits(it.ds->id());
        auto find = [&](const char* suffix) {
            pv::Record* r = db_.find(p + suffix);
            if (!r) throw Error(SB() << "data storage " << it.ds->id() << ": no record " << p << suffix);
            return r;
        };
        it.data = find("-DataAct");
        it.data_set = find("-DataSet");
        it.index = find("-DataIdAct");
        it.stat = find("-Stat");
        it.full = find("-Full");
        it.type = find("-Type");
        it.size = find("-Size");
        it.count = find("-Count");
        it.err = find("-Err");
        it.clear = find("-ClrCmd");
        for (pv::Record* r : {it.data, it.index, it.stat, it.full, it.type, it.size, it.count, it.err})
            r->val_read_only = true; // the storage's values
        daq::DataStorage* ds = it.ds.get();
        std::string where = cfg.storages[k].where;
        it.data_set->put_hook = [this, ds, where](pv::Record& r, const pv::FieldDesc& f) {
            if (std::string_view(f.name) != "VAL") return pv::PutStatus::Ok;
            pv::Elements e = r.elements(f);
            uint32_t n = std::min<uint32_t>(e.count, uint32_t(scratch_.size()));
            for (uint32_t i = 0; i < n; ++i) pv::get_element(r, f, e, i, pv::Prim::Double, &scratch_[i]);
            if (ds->request_data(scratch_.data(), n)) return pv::PutStatus::Ok;
            LOG_WARN(lg, r.name() << ": refused, the cycle has not taken the last write yet");
            return pv::PutStatus::Failed;
        };
        it.clear->put_hook = [ds](pv::Record& r, const pv::FieldDesc& f) {
            if (std::string_view(f.name) != "VAL" || get_value(r) == 0) return pv::PutStatus::Ok;
            return ds->request_clear() ? pv::PutStatus::Ok : pv::PutStatus::Failed;
        };
    }
}

std::vector<daq::DataStorage*> IocStorages::storages() {
    std::vector<daq::DataStorage*> v;
    for (Item& i : items_) v.push_back(i.ds.get());
    return v;
}

void IocStorages::bind(rt::Engine& engine) {
    if (items_.empty()) return;
    stage_ = std::make_unique<Stage>(items_);
    engine.add_stage(rt::StageOrder::Triggers, *stage_);
}

void IocStorages::publish() {
    for (Item& it : items_) {
        if (!it.ds->update()) continue;
        const daq::DataStorage::Snapshot& s = it.ds->snapshot();
        set_array(db_, *it.data, s.data.data(), uint32_t(s.size));
        set_if_changed(db_, it.index, double(s.index));
        set_if_changed(db_, it.stat, double(daq::DataStorage::status_word(s)));
        set_if_changed(db_, it.full, s.full ? 1 : 0);
        set_if_changed(db_, it.type, double(int(s.type)));
        set_if_changed(db_, it.size, double(s.size));
        set_if_changed(db_, it.count, double(s.count));
        set_if_changed(db_, it.err, double(s.error));
    }
}

} // namespace beamctl::ioc
