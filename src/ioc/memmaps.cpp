#include "ioc/memmaps.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ioc/pv_util.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>

namespace beamctl::ioc {

namespace {
log::Logger lg("memmaps");

// ecmccfg's record name suffix of a memory map: analogInputArrayNN -> AINN-Arr,
// analogOutputArrayNN -> AONN-Arr; other names -> mm-<name>.
std::string pv_suffix(const std::string& mm) {
    for (auto [prefix, key] : {std::pair{"analogInputArray", "AI"}, std::pair{"analogOutputArray", "AO"}}) {
        std::string p = prefix;
        if (mm.size() > p.size() && mm.compare(0, p.size(), p) == 0 &&
            mm.find_first_not_of("0123456789", p.size()) == std::string::npos)
            return std::string(key) + mm.substr(p.size()) + "-Arr";
    }
    return "mm-" + mm;
}

const char* ftvl_of(const std::string& coe) {
    struct T {
        const char* coe;
        const char* ftvl;
    };
    static constexpr T types[] = {{"INT8", "CHAR"},   {"UINT8", "UCHAR"},  {"INT16", "SHORT"}, {"UINT16", "USHORT"},
                                  {"INT32", "LONG"},  {"UINT32", "ULONG"}, {"REAL32", "FLOAT"}};
    for (const T& t : types)
        if (coe == t.coe) return t.ftvl;
    return "DOUBLE";
}
} // namespace

IocMemMaps::IocMemMaps(const config::IocConfig& cfg, const ethercat::Catalog& catalog, pv::Database& db) : db_(db) {
    pv::DbFile f;
    for (std::size_t b = 0; b < cfg.buses.size(); ++b) {
        const config::BusConfig& bc = cfg.buses[b];
        std::vector<const config::SlaveEntry*> slaves;
        for (const auto& s : bc.slaves) slaves.push_back(&s);
        std::sort(slaves.begin(), slaves.end(), [](auto* x, auto* y) { return x->position < y->position; });
        for (const config::SlaveEntry* s : slaves) {
            const ethercat::DeviceDesc* d = catalog.find(s->type);
            if (!d || d->oversampling.channels.empty()) continue;
            ethercat::DeviceDesc dd = d->with_oversampling(s->oversampling); // checked by the IOC
            for (const auto& mm : dd.memmaps()) {
                Item& it = items_.emplace_back();
                std::string pre = SB() << "ec" << bc.id << ".s" << s->position << ".";
                it.map.name = pre + "mm." + mm.name;
                it.map.count = mm.count;
                it.map.type = registry::ecmc_data_type(mm.datatype);
                it.map.output = mm.output;
                it.bus = b;
                it.slave = s->position;
                std::string channel = mm.first.substr(0, mm.first.size() - 2); // "..._1"
                for (unsigned k = 1; k <= mm.count; ++k) it.elements.push_back(pre + channel + "_" + std::to_string(k));
                it.first = it.elements.front();
                it.last.assign(mm.count, 0.0);
                char sp[16];
                std::snprintf(sp, sizeof sp, "s%03d-", s->position);
                std::string name = SB() << cfg.prefix << "m" << bc.id << sp << pv_suffix(mm.name);
                std::string desc = SB() << s->type << ": " << mm.name << " [" << mm.count << "]";
                f.records.push_back(record("waveform", name,
                                           {{"DESC", desc.substr(0, 40)},
                                            {"FTVL", ftvl_of(mm.datatype)},
                                            {"NELM", std::to_string(mm.count)}}));
                scratch_.resize(std::max<std::size_t>(scratch_.size(), mm.count));
            }
        }
    }
    if (items_.empty()) return;
    db_.load(f);
    for (Item& it : items_) {
        char sp[16];
        std::snprintf(sp, sizeof sp, "s%03d-", it.slave);
        const config::BusConfig& bc = cfg.buses[it.bus];
        std::string name = SB() << cfg.prefix << "m" << bc.id << sp
                                << pv_suffix(it.map.name.substr(it.map.name.find(".mm.") + 4));
        it.rec = db_.find(name);
        if (!it.rec) throw Error(SB() << "memory map " << it.map.name << ": no record " << name);
        if (!it.map.output) {
            it.rec->val_read_only = true; // the cycle's samples
            continue;
        }
        Item* self = &it;
        it.rec->put_hook = [this, self](pv::Record& r, const pv::FieldDesc& fd) {
            if (std::string_view(fd.name) != "VAL") return pv::PutStatus::Ok;
            if (self->sig.empty()) return pv::PutStatus::Failed; // not brought up
            pv::Elements e = r.elements(fd);
            uint32_t n = std::min<uint32_t>(e.count, self->map.count);
            ethercat::Bus& bus = *buses_[self->bus];
            for (uint32_t i = 0; i < n; ++i) {
                double v = 0;
                pv::get_element(r, fd, e, i, pv::Prim::Double, &v);
                if (!bus.write(*self->sig[i], registry::double_to_raw(v, self->sig[i]->entry()))) {
                    LOG_WARN(lg, r.name() << ": refused, the cycle has not taken the last writes yet");
                    return pv::PutStatus::Failed;
                }
            }
            return pv::PutStatus::Ok;
        };
    }
}

void IocMemMaps::bind(registry::Registry& reg, const std::vector<ethercat::Bus*>& buses) {
    buses_ = buses;
    for (Item& it : items_) {
        std::string why;
        it.map.first = reg.bind(it.first, why);
        if (!it.map.first.bound()) throw Error(SB() << "memory map " << it.map.name << ": " << why);
        if (it.map.first.bit_offset % 8 != 0 || it.map.first.bits % 8 != 0)
            throw Error(SB() << "memory map " << it.map.name << ": " << it.first << " is not byte aligned");
        ethercat::Bus& bus = *buses_.at(it.bus);
        it.sig.clear();
        for (uint32_t k = 0; k < it.map.count; ++k) {
            const ethercat::SignalInfo* si = bus.find_signal(it.elements[k]);
            uint32_t want = it.map.first.bit_offset + k * it.map.first.bits;
            if (!si || si->bit_offset != want || si->bits != it.map.first.bits)
                throw Error(SB() << "memory map " << it.map.name << ": " << it.elements[k]
                                 << (si ? " does not follow the element before it in the process image"
                                        : " is not in the PDO assignment the slave reported"));
            it.sig.push_back(si);
        }
        // an output channel another writer claimed (a PCOMP block's samples): its PV is read-only,
        // as the entries' own PVs are; a put would be overwritten by the next cycle
        if (it.map.output && it.rec)
            for (const std::string& el : it.elements)
                if (const registry::Signal* s = reg.find(el); s && !s->writer.empty()) {
                    it.rec->val_read_only = true;
                    LOG_INFO(lg, it.rec->name() << ": read-only, " << el << " is set by " << s->writer);
                    break;
                }
    }
}

std::vector<registry::MemMap*> IocMemMaps::memmaps() {
    std::vector<registry::MemMap*> v;
    for (Item& it : items_) v.push_back(&it.map);
    return v;
}

const std::vector<std::string>* IocMemMaps::elements(const std::string& name) const {
    for (const Item& it : items_)
        if (it.map.name == name) return &it.elements;
    return nullptr;
}

bool IocMemMaps::fresh(const Item& it, const ethercat::BusSnapshot& s, std::size_t& slave_index) const {
    if (!s.link_up || !s.wkc_ok) return false;
    const auto& sl = buses_[it.bus]->slaves();
    for (std::size_t i = 0; i < sl.size(); ++i)
        if (sl[i].position == it.slave) slave_index = i;
    return slave_index < s.slave_valid.size() && s.slave_valid[slave_index];
}

void IocMemMaps::publish(double now_s) {
    for (Item& it : items_) {
        if (it.sig.empty() || it.map.output) continue; // an output array shows what was put
        const ethercat::BusSnapshot& s = buses_[it.bus]->looked();
        if (s.image.empty()) continue;
        uint32_t pushes = it.map.pushes.load(std::memory_order_acquire);
        bool pushed = pushes != it.pushes_seen;
        std::size_t si = ~std::size_t(0);
        bool ok = fresh(it, s, si);
        bool alarm_changed = (!ok) != (it.rec->sevr == pv::kInvalid); // at once, as a push
        if (!pushed && !alarm_changed && it.published_s >= 0 && now_s - it.published_s < 0.1) continue;
        bool changed = it.rec->udf != 0 || pushed || alarm_changed;
        for (uint32_t k = 0; k < it.map.count; ++k) {
            const ethercat::SignalInfo& sig = *it.sig[k];
            uint64_t raw = ethercat::Bus::get(s.image, sig);
            registry::MemMap probe; // the conversion of MemMap::get, on the snapshot
            double v = sig.is_signed ? double(registry::sign_extend(raw, sig.bits)) : double(raw);
            if (it.map.type == 13 || it.map.type == 14) {
                probe.type = it.map.type;
                probe.first = registry::BoundSignal{const_cast<uint8_t*>(s.image.data()), sig.bit_offset, sig.bits,
                                                    sig.is_signed};
                probe.count = 1;
                (void)probe.get(0, v);
            }
            changed |= v != it.last[k];
            scratch_[k] = v;
        }
        if (!changed) continue;
        std::copy(scratch_.begin(), scratch_.begin() + it.map.count, it.last.begin());
        it.pushes_seen = pushes;
        it.published_s = now_s;
        if (!ok) it.rec->set_sevr(pv::kStatComm, pv::kInvalid);
        set_array(db_, *it.rec, scratch_.data(), it.map.count);
    }
}

} // namespace beamctl::ioc
