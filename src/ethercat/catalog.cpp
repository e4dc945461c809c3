#include "ethercat/catalog.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"
#include "core/error_list.hpp"
#include "ethercat/esi.hpp"
#include "ethercat/sii.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <tuple>

namespace fs = std::filesystem;

namespace beamctl::ethercat {

namespace {

std::string hex(uint32_t v, int digits = 4) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%0*X", digits, v);
    return buf;
}

std::string identity_str(const DeviceDesc& d) {
    return SB() << d.type << " (vendor " << hex(d.vendor, 8) << ", product " << hex(d.product, 8)
                << ", revision " << hex(d.revision, 8) << ")";
}

// ---------------------------------------------------------------------------------------------
// YAML

template <typename T> T uint_of(const config::YamlNode& n, uint64_t max, T def = 0) {
    return static_cast<T>(n.unsigned_integer(max).value_or(def));
}

// One device file; every error goes to the reader.
DeviceDesc parse_yaml_device(const config::YamlNode& root) {
    DeviceDesc d;
    if (!root.keys({"type", "variant_of", "name", "vendor", "product", "revision", "coe",
                    "dc_assign_activate", "ebus_current_ma", "sync_managers", "rx_pdos",
                    "tx_pdos", "oversampling"}))
        return d;
    d.type = root.required("type").string().value_or("");
    d.variant_of = root["variant_of"].string().value_or("");
    if (root.has("type") &&
        (d.type.empty() || std::any_of(d.type.begin(), d.type.end(),
                                       [](unsigned char c) { return std::isspace(c); })))
        root["type"].error(SB() << "'" << d.type << "' should be a non-empty name without spaces");
    d.name = root.required("name").string().value_or("");
    d.vendor = uint_of<uint32_t>(root.required("vendor"), 0xFFFFFFFF);
    d.product = uint_of<uint32_t>(root.required("product"), 0xFFFFFFFF);
    d.revision = uint_of<uint32_t>(root.required("revision"), 0xFFFFFFFF);
    d.coe = root["coe"].boolean().value_or(false);
    d.dc_assign_activate = uint_of<uint16_t>(root["dc_assign_activate"], 0xFFFF);
    d.ebus_current_ma = uint_of<uint16_t>(root["ebus_current_ma"], 0xFFFF);

    // Sync managers.
    std::vector<config::YamlNode> sm_nodes;
    const auto sms = root["sync_managers"].list();
    for (size_t i = 0; i < sms.size(); ++i) {
        const config::YamlNode& n = sms[i];
        if (!n.keys({"index", "start", "size", "control", "type", "enable", "virtual"})) continue;
        SyncManagerDesc sm;
        auto index = n.required("index").unsigned_integer(255);
        if (index && *index != i)
            n["index"].error(SB() << *index << " should be " << i
                                  << " (sync managers are listed in SM order)");
        sm.index = static_cast<uint8_t>(i);
        sm.start = uint_of<uint16_t>(n.required("start"), 0xFFFF);
        sm.default_size = uint_of<uint16_t>(n["size"], 0xFFFF);
        sm.control = uint_of<uint8_t>(n.required("control"), 0xFF);
        auto type = n.required("type").string();
        std::optional<SmType> t = type ? sm_type_from_name(*type) : std::nullopt;
        if (type && !t)
            n["type"].error(SB() << "'" << *type
                                 << "' should be one of MBoxOut, MBoxIn, Outputs, Inputs, Unused");
        sm.type = t.value_or(SmType::Unused);
        sm.enable = n["enable"].boolean().value_or(true);
        sm.is_virtual = n["virtual"].boolean().value_or(false);
        bool mailbox = sm.type == SmType::MailboxOut || sm.type == SmType::MailboxIn;
        if (mailbox && sm.default_size == 0)
            n.error(SB() << "a " << *type << " sync manager needs a size > 0");
        if (mailbox && sm.is_virtual) n["virtual"].error("a mailbox cannot be virtual");
        for (const SyncManagerDesc& other : d.sms)
            if (mailbox && other.type == sm.type) {
                n.error(SB() << "second " << *type << " sync manager (SM"
                             << unsigned(other.index) << " is one already)");
                break;
            }
        d.sms.push_back(sm);
        sm_nodes.push_back(n);
    }
    bool has_mbx_out = false, has_mbx_in = false;
    for (const SyncManagerDesc& sm : d.sms) {
        has_mbx_out |= sm.type == SmType::MailboxOut;
        has_mbx_in |= sm.type == SmType::MailboxIn;
    }
    if (d.coe && !(has_mbx_out && has_mbx_in))
        root["coe"].error("true needs an MBoxOut and an MBoxIn sync manager");

    // PDOs.
    std::set<uint16_t> pdo_indices;
    struct NamedEntry {
        std::string path; // of its first use
        uint16_t index;
        uint8_t sub, bits;
    };
    std::map<std::string, NamedEntry> entry_names;
    std::vector<std::pair<uint8_t, uint16_t>> rx_assign, tx_assign;
    for (bool rx : {true, false}) {
        for (const config::YamlNode& n : root[rx ? "rx_pdos" : "tx_pdos"].list()) {
            if (!n.keys({"index", "name", "sm", "entries"})) continue;
            Pdo p;
            p.index = uint_of<uint16_t>(n.required("index"), 0xFFFF);
            uint16_t lo = rx ? 0x1600 : 0x1A00, hi = rx ? 0x17FF : 0x1BFF;
            if (n.has("index") && (p.index < lo || p.index > hi))
                n["index"].error(SB() << hex(p.index) << " should be in " << hex(lo) << "-"
                                      << hex(hi) << (rx ? " (RxPDO, outputs)" : " (TxPDO, inputs)"));
            else if (n.has("index") && !pdo_indices.insert(p.index).second)
                n["index"].error(SB() << "PDO " << hex(p.index) << " is defined twice");
            p.name = n["name"].string().value_or("");
            if (auto sm = n["sm"].unsigned_integer(255)) {
                SmType want = rx ? SmType::Outputs : SmType::Inputs;
                if (*sm >= d.sms.size())
                    n["sm"].error(SB() << "SM" << *sm << " does not exist (" << d.sms.size()
                                       << " sync managers)");
                else if (d.sms[*sm].type != want)
                    n["sm"].error(SB() << "SM" << *sm << " is " << sm_type_name(d.sms[*sm].type)
                                       << ", a " << (rx ? "RxPDO" : "TxPDO") << " needs "
                                       << sm_type_name(want));
                else
                    (rx ? rx_assign : tx_assign).emplace_back(static_cast<uint8_t>(*sm), p.index);
            }
            for (const config::YamlNode& en : n["entries"].list()) {
                if (!en.keys({"index", "sub", "bits", "name", "datatype"})) continue;
                PdoEntry e;
                e.index = uint_of<uint16_t>(en.required("index"), 0xFFFF);
                e.sub = uint_of<uint8_t>(en["sub"], 0xFF);
                auto bits = en.required("bits").unsigned_integer(0xFF);
                e.bits = static_cast<uint8_t>(bits.value_or(0));
                e.name = en["name"].string().value_or("");
                e.datatype = en["datatype"].string().value_or("");
                if (bits && *bits == 0) en["bits"].error("0 should be > 0");
                const bool has_index = en.has("index");
                if (has_index && e.index == 0) {
                    if (e.sub != 0) en["sub"].error("padding (index 0) has no subindex");
                    if (!e.name.empty()) en["name"].error("padding (index 0) has no name");
                    if (!e.datatype.empty())
                        en["datatype"].error("padding (index 0) has no datatype");
                } else if (has_index) {
                    if (!en.has("name")) en.required("name", " (the ecmc entry name)");
                    if (!en.has("datatype")) en.required("datatype");
                    unsigned width = e.datatype.empty() ? 0 : coe_datatype_bits(e.datatype);
                    if (!e.datatype.empty() && width == 0)
                        en["datatype"].error(SB() << "unknown datatype '" << e.datatype
                                                  << "' (BOOL, BIT2-BIT8, INT8-INT64, "
                                                     "UINT8-UINT64, REAL32, REAL64)");
                    if (width != 0 && bits && *bits != 0 && width != e.bits)
                        en["bits"].error(SB() << unsigned(e.bits) << " should be " << width
                                              << " for datatype " << e.datatype);
                    if (!e.name.empty()) { // one name, one object (alternative PDOs may share an object)
                        auto [it, fresh] = entry_names.emplace(e.name, NamedEntry{en.path(), e.index, e.sub, e.bits});
                        if (!fresh && !(it->second.index == e.index && it->second.sub == e.sub && it->second.bits == e.bits))
                            en["name"].error(SB() << "'" << e.name << "' is already used by "
                                                  << it->second.path << " (another object)");
                    }
                }
                p.entries.push_back(std::move(e));
            }
            (rx ? d.rx_pdos : d.tx_pdos).push_back(std::move(p));
        }
    }
    d.pdo_assign = std::move(rx_assign);
    d.pdo_assign.insert(d.pdo_assign.end(), tx_assign.begin(), tx_assign.end());

    // Process-data SM sizes follow from their PDOs.
    for (size_t i = 0; i < d.sms.size(); ++i) {
        SyncManagerDesc& sm = d.sms[i];
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        if (sm.is_virtual) continue;
        uint32_t bytes = d.sm_bytes(sm.index);
        if (sm_nodes[i].has("size") && sm.default_size != bytes)
            sm_nodes[i]["size"].error(SB() << sm.default_size << " should be " << bytes
                                           << " (bytes of the PDOs assigned to SM" << i << ")");
        if (bytes > 0xFFFF)
            sm_nodes[i].error(SB() << "assigned PDOs need " << bytes
                                   << " bytes, more than an SM holds");
        sm.default_size = static_cast<uint16_t>(bytes);
    }

    // Oversampling: each listed PDO is a channel's first sample (one entry named <channel>_1),
    // assigned by default; sample k is PDO index+k-1, so those indices must be free.
    if (config::YamlNode o = root["oversampling"]; o && o.keys({"max", "channels"})) {
        d.oversampling.max = uint_of<uint16_t>(o.required("max", " (the largest factor)"), 1000);
        if (o.has("max") && d.oversampling.max < 2) o["max"].error("should be at least 2");
        for (const config::YamlNode& c : o.required("channels", " (a list of {pdo, memmap})").list()) {
            if (!c.keys({"pdo", "memmap"})) continue;
            auto idx = c.required("pdo", " (the channel's first sample PDO)").unsigned_integer(0xFFFF);
            auto mm = c.required("memmap", " (ECMC's memory map name, e.g. analogInputArray01)").string();
            if (!idx || !mm) continue;
            const Pdo* p = d.find_pdo(uint16_t(*idx));
            bool assigned = std::any_of(d.pdo_assign.begin(), d.pdo_assign.end(),
                                        [&](const auto& a) { return a.second == *idx; });
            if (!p || !assigned) {
                c["pdo"].error(SB() << hex(uint16_t(*idx)) << " is not a PDO assigned by default");
                continue;
            }
            if (p->entries.size() != 1 || p->entries[0].name.size() < 3 ||
                p->entries[0].name.compare(p->entries[0].name.size() - 2, 2, "_1") != 0) {
                c["pdo"].error(SB() << hex(p->index) << " should have one entry named <channel>_1 (the first sample)");
                continue;
            }
            bool clash = false;
            for (unsigned k = 1; k < d.oversampling.max && !clash; ++k)
                if (d.find_pdo(uint16_t(*idx + k))) {
                    c["pdo"].error(SB() << "PDO " << hex(uint16_t(*idx + k)) << " would be sample " << k + 1
                                        << " of " << hex(p->index) << "'s channel; it cannot be defined too");
                    clash = true;
                }
            if (!clash) d.oversampling.channels.push_back({uint16_t(*idx), *mm});
        }
    }
    return d;
}

bool has_suffix(const std::string& s, std::initializer_list<const char*> suffixes) {
    std::string lower = s;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    for (const char* suf : suffixes) {
        std::string x = suf;
        if (lower.size() >= x.size() && lower.compare(lower.size() - x.size(), x.size(), x) == 0)
            return true;
    }
    return false;
}

} // namespace

// ---------------------------------------------------------------------------------------------

struct Catalog::Impl {
    std::string dir; // the directory of the first load_dir, for messages
    struct Item {
        DeviceDesc desc;
        std::string source;
        bool from_esi = false;
    };
    std::vector<std::unique_ptr<Item>> items; // unique_ptr: find() results stay valid

    // The base description of an identity (operating-mode variants share it and are found by
    // type only).
    Item* find_identity(uint32_t vendor, uint32_t product, uint32_t revision) {
        for (auto& it : items)
            if (it->desc.vendor == vendor && it->desc.product == product &&
                it->desc.revision == revision && it->desc.variant_of.empty())
                return it.get();
        return nullptr;
    }

    // Catalog::ecmc_names.
    void apply_ecmc_names(DeviceDesc& d) const {
        // YAML devices of the same product: the same revision first (its base description
        // before its operating-mode variants), then the others, highest revision first.
        std::vector<const Item*> named;
        for (const auto& it : items)
            if (!it->from_esi && it->desc.vendor == d.vendor && it->desc.product == d.product)
                named.push_back(it.get());
        if (named.empty()) return;
        auto rank = [&](const Item* it) {
            return std::make_tuple(it->desc.revision != d.revision, !it->desc.variant_of.empty(),
                                   ~it->desc.revision);
        };
        std::stable_sort(named.begin(), named.end(),
                         [&](const Item* a, const Item* b) { return rank(a) < rank(b); });
        std::map<uint32_t, std::string> names; // index << 8 | sub -> ecmc name; the first wins
        for (const Item* it : named)
            for (const auto* list : {&it->desc.rx_pdos, &it->desc.tx_pdos})
                for (const Pdo& p : *list)
                    for (const PdoEntry& e : p.entries)
                        if (e.index != 0) names.emplace(uint32_t{e.index} << 8 | e.sub, e.name);
        std::set<std::string> used;
        for (const auto* list : {&d.rx_pdos, &d.tx_pdos})
            for (const Pdo& p : *list)
                for (const PdoEntry& e : p.entries) used.insert(e.name);
        // Entries of default-assigned PDOs first: one entry per name.
        for (bool assigned_pass : {true, false})
            for (auto* list : {&d.rx_pdos, &d.tx_pdos})
                for (Pdo& p : *list) {
                    bool assigned = std::any_of(d.pdo_assign.begin(), d.pdo_assign.end(),
                                                [&](const auto& a) { return a.second == p.index; });
                    if (assigned != assigned_pass) continue;
                    for (PdoEntry& e : p.entries) {
                        if (e.index == 0) continue;
                        auto it = names.find(uint32_t{e.index} << 8 | e.sub);
                        if (it == names.end() || it->second == e.name || used.count(it->second)) continue;
                        used.insert(it->second);
                        e.name = it->second;
                    }
                }
        // An oversampled channel's memory map: the YAML device's for the same PDO, else named
        // after its first sample (esi_memmap_name).
        for (auto& ch : d.oversampling.channels) {
            Pdo* p = nullptr;
            for (auto* list : {&d.rx_pdos, &d.tx_pdos})
                for (Pdo& x : *list)
                    if (x.index == ch.pdo) p = &x;
            if (!p || p->entries.size() != 1) continue;
            std::string& n = p->entries[0].name;
            if (!(n.size() > 2 && n.compare(n.size() - 2, 2, "_1") == 0)) n += "_1";
            ch.memmap = esi_memmap_name(n);
            bool found = false;
            for (const Item* it : named)
                for (const auto& c : it->desc.oversampling.channels)
                    if (!found && c.pdo == ch.pdo) {
                        ch.memmap = c.memmap;
                        found = true;
                    }
        }
    }

    void add_esi(DeviceDesc d, const std::string& source) {
        apply_ecmc_names(d);
        if (Item* old = find_identity(d.vendor, d.product, d.revision)) {
            old->desc = std::move(d);
            old->source = source;
            old->from_esi = true;
            return;
        }
        items.push_back(std::make_unique<Item>(Item{std::move(d), source, true}));
    }
};

Catalog::Catalog()
    : impl_(std::make_unique<Impl>()) {}
Catalog::~Catalog() = default;
Catalog::Catalog(Catalog&&) noexcept = default;
Catalog& Catalog::operator=(Catalog&&) noexcept = default;

void Catalog::load_yaml(const std::string& path) {
    config::YamlReader r = config::YamlReader::load(path, "the device");
    config::YamlNode root = r.root();
    if (root.is_null()) r.error(r.top(), "empty file, expected a device");
    DeviceDesc d;
    if (root && !root.is_null()) d = parse_yaml_device(root);
    r.throw_if_errors(); // a bad file changes nothing
    if (!d.variant_of.empty()) { // an operating-mode variant: its own type, the base's identity
        for (auto& it : impl_->items)
            if (it->desc.type == d.type)
                throw Error(SB() << r.loc(root.yaml()).str() << ": type " << d.type
                                 << " is already defined in " << it->source);
        impl_->items.push_back(std::make_unique<Impl::Item>(Impl::Item{std::move(d), path, false}));
        return;
    }
    if (Impl::Item* old = impl_->find_identity(d.vendor, d.product, d.revision)) {
        if (!old->from_esi)
            throw Error(SB() << r.loc(root.yaml()).str() << ": " << identity_str(d)
                             << " is already defined in " << old->source);
        old->desc = std::move(d);
        old->source = path;
        old->from_esi = false;
        return;
    }
    impl_->items.push_back(std::make_unique<Impl::Item>(Impl::Item{std::move(d), path, false}));
}

void Catalog::load_esi(const std::string& path) {
    std::vector<EsiDevice> devices = read_esi(path); // a bad file changes nothing
    for (EsiDevice& d : devices) impl_->add_esi(std::move(d.desc), path);
}

void Catalog::ecmc_names(DeviceDesc& d) const {
    impl_->apply_ecmc_names(d);
}

std::string Catalog::unknown_type_error(std::string_view type) const {
    SB msg;
    msg << "unknown device type '" << type << "'";
    auto close = config::close_matches(type, types(), 5);
    for (std::size_t i = 0; i < close.size(); ++i)
        msg << (i ? ", " : "; close matches in the catalog: ") << close[i];
    msg << "; to add a device, import its vendor's ESI file: beamctl esi import VENDOR.xml --out "
        << (impl_->dir.empty() ? std::string("CATALOG_DIR") : impl_->dir)
        << " (BEAMCTL_CATALOG selects the catalog directory; docs/esi.md)";
    return msg;
}

void Catalog::load_dir(const std::string& dir) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw Error(SB() << dir << ": not a directory");
    std::vector<std::string> yaml, xml;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        if (!entry.is_regular_file()) continue;
        std::string p = entry.path().string();
        if (has_suffix(p, {".yaml", ".yml"}))
            yaml.push_back(p);
        else if (has_suffix(p, {".xml"}))
            xml.push_back(p);
    }
    if (ec) throw Error(SB() << dir << ": cannot list: " << ec.message());
    if (impl_->dir.empty()) impl_->dir = dir;
    std::sort(yaml.begin(), yaml.end());
    std::sort(xml.begin(), xml.end());
    ErrorList errors; // every bad file, each with all its errors
    for (const std::string& p : yaml) errors.capture([&] { load_yaml(p); });
    for (const std::string& p : xml) errors.capture([&] { load_esi(p); });
    errors.throw_if_any();
}

const DeviceDesc* Catalog::find(std::string_view type) const {
    const DeviceDesc* best = nullptr;
    for (const auto& it : impl_->items)
        if (it->desc.type == type && (!best || it->desc.revision > best->revision))
            best = &it->desc;
    return best;
}

const DeviceDesc* Catalog::find(uint32_t vendor, uint32_t product, uint32_t revision) const {
    Impl::Item* it = impl_->find_identity(vendor, product, revision);
    return it ? &it->desc : nullptr;
}

const DeviceDesc* Catalog::find_latest(uint32_t vendor, uint32_t product) const {
    const DeviceDesc* best = nullptr;
    for (const auto& it : impl_->items)
        if (it->desc.vendor == vendor && it->desc.product == product && it->desc.variant_of.empty() &&
            (!best || it->desc.revision > best->revision))
            best = &it->desc;
    return best;
}

std::vector<std::string> Catalog::types() const {
    std::set<std::string> s;
    for (const auto& it : impl_->items) s.insert(it->desc.type);
    return {s.begin(), s.end()};
}

std::string Catalog::source(const DeviceDesc* d) const {
    for (const auto& it : impl_->items)
        if (&it->desc == d) return it->source;
    return {};
}

size_t Catalog::size() const {
    return impl_->items.size();
}

std::string Catalog::builtin_dir() {
    std::vector<std::string> tried;
    std::error_code ec;
    if (const char* env = std::getenv("BEAMCTL_CATALOG"); env && *env) {
        if (!fs::is_directory(env, ec))
            throw Error(SB() << "BEAMCTL_CATALOG=" << env << " is not a directory");
        return env;
    }
    fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        fs::path dir = exe.parent_path();
        for (fs::path p :
             {dir / ".." / ".." / "catalog", dir / ".." / "catalog", dir / "catalog"}) {
            p = p.lexically_normal();
            if (fs::is_directory(p, ec)) return p.string();
            tried.push_back(p.string());
        }
    }
#ifdef BEAMCTL_SOURCE_CATALOG_DIR
    if (fs::is_directory(BEAMCTL_SOURCE_CATALOG_DIR, ec)) return BEAMCTL_SOURCE_CATALOG_DIR;
    tried.push_back(BEAMCTL_SOURCE_CATALOG_DIR);
#endif
    std::string list;
    for (const std::string& t : tried) list += (list.empty() ? "" : ", ") + t;
    throw Error(SB() << "no EtherCAT device catalog directory found (tried " << list
                     << "); set BEAMCTL_CATALOG");
}

const Catalog& Catalog::builtin() {
    static const Catalog catalog = [] {
        Catalog c;
        c.load_dir(builtin_dir());
        return c;
    }();
    return catalog;
}

} // namespace beamctl::ethercat
