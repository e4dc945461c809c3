#include "ethercat/catalog.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"
#include "core/error_list.hpp"
#include "ethercat/sii.hpp"

#include <tinyxml2.h>

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

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open");
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

std::optional<SmType> sm_type_from(const std::string& s) {
    if (s == "MBoxOut") return SmType::MailboxOut;
    if (s == "MBoxIn") return SmType::MailboxIn;
    if (s == "Outputs") return SmType::Outputs;
    if (s == "Inputs") return SmType::Inputs;
    if (s == "Unused") return SmType::Unused;
    return std::nullopt;
}

const char* sm_type_name(SmType t) {
    switch (t) {
    case SmType::MailboxOut:
        return "MBoxOut";
    case SmType::MailboxIn:
        return "MBoxIn";
    case SmType::Outputs:
        return "Outputs";
    case SmType::Inputs:
        return "Inputs";
    case SmType::Unused:
        break;
    }
    return "Unused";
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
        std::optional<SmType> t = type ? sm_type_from(*type) : std::nullopt;
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
    std::map<std::string, std::string> entry_names; // name -> path of first use
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
                    if (!e.name.empty()) {
                        auto [it, fresh] = entry_names.emplace(e.name, en.path());
                        if (!fresh)
                            en["name"].error(SB() << "'" << e.name << "' is already used by "
                                                  << it->second);
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

// ---------------------------------------------------------------------------------------------
// ESI

class EsiReader {
public:
    EsiReader(std::string file, const std::string& text)
        : file_(std::move(file))
        , text_(text) {
        line_starts_.push_back(0);
        for (size_t i = 0; i < text_.size(); ++i)
            if (text_[i] == '\n') line_starts_.push_back(i + 1);
    }

    // file:line:col of an element: tinyxml2 gives the line; the column is where "<Name" starts.
    std::string where(const tinyxml2::XMLElement* e) const {
        int line = e->GetLineNum();
        int col = 1;
        if (line >= 1 && static_cast<size_t>(line) <= line_starts_.size()) {
            size_t begin = line_starts_[line - 1];
            size_t end =
                static_cast<size_t>(line) < line_starts_.size() ? line_starts_[line] : text_.size();
            std::string tag = std::string("<") + e->Name();
            size_t pos = text_.find(tag, begin);
            if (pos != std::string::npos && pos < end) col = static_cast<int>(pos - begin) + 1;
        }
        return SourceLoc{file_, line, col}.str();
    }

    [[noreturn]] void fail(const tinyxml2::XMLElement* e, const std::string& what) const {
        throw Error(SB() << where(e) << ": " << e->Name() << ": " << what);
    }

    // ESI number: "#x1A00" hex, or decimal (optionally negative when `allow_negative`).
    int64_t number(const tinyxml2::XMLElement* e, const char* what, const char* s,
                   bool allow_negative = false) const {
        std::string t = s ? s : "";
        t.erase(0, t.find_first_not_of(" \t\r\n"));
        t.erase(t.find_last_not_of(" \t\r\n") + 1);
        bool neg = false;
        std::string digits = t;
        int base = 10;
        if (digits.size() > 2 && digits[0] == '#' && (digits[1] == 'x' || digits[1] == 'X')) {
            digits = digits.substr(2);
            base = 16;
        } else if (allow_negative && !digits.empty() && digits[0] == '-') {
            neg = true;
            digits = digits.substr(1);
        }
        if (digits.empty() || digits.size() > 16)
            fail(e, SB() << what << " '" << t << "' is not a number");
        int64_t v = 0;
        for (char c : digits) {
            c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
            int digit;
            if (c >= '0' && c <= '9')
                digit = c - '0';
            else if (base == 16 && c >= 'a' && c <= 'f')
                digit = c - 'a' + 10;
            else
                fail(e, SB() << what << " '" << t << "' is not a number");
            v = v * base + digit;
        }
        return neg ? -v : v;
    }

    uint64_t unsigned_in(const tinyxml2::XMLElement* e, const char* what, const char* s,
                         uint64_t max) const {
        int64_t v = number(e, what, s);
        if (v < 0 || static_cast<uint64_t>(v) > max)
            fail(e, SB() << what << " " << s << " is out of range (maximum " << max << ")");
        return static_cast<uint64_t>(v);
    }

    // Text of the required child element `name`.
    const char* child_text(const tinyxml2::XMLElement* e, const char* name) const {
        const tinyxml2::XMLElement* c = e->FirstChildElement(name);
        if (!c) fail(e, SB() << "missing <" << name << ">");
        const char* t = c->GetText();
        return t ? t : "";
    }

private:
    std::string file_;
    const std::string& text_;
    std::vector<size_t> line_starts_;
};

// First <Name> child, preferring LcId 1033 (English).
std::string esi_name(const tinyxml2::XMLElement* e) {
    const tinyxml2::XMLElement* first = nullptr;
    for (auto* n = e->FirstChildElement("Name"); n; n = n->NextSiblingElement("Name")) {
        if (!first) first = n;
        const char* lcid = n->Attribute("LcId");
        if (lcid && std::string(lcid) == "1033") return n->GetText() ? n->GetText() : "";
    }
    return first && first->GetText() ? first->GetText() : "";
}

std::string without_spaces(std::string s) {
    s.erase(std::remove_if(s.begin(), s.end(), [](unsigned char c) { return std::isspace(c); }),
            s.end());
    return s;
}

// ESI (IEC 61131) type names -> the CoE names used in the catalog; unknown names pass through.
std::string normalize_datatype(std::string t) {
    static const std::map<std::string, std::string> kMap{
        {"BIT", "BOOL"},    {"SINT", "INT8"},    {"INT", "INT16"},    {"DINT", "INT32"},
        {"LINT", "INT64"},  {"USINT", "UINT8"},  {"BYTE", "UINT8"},   {"UINT", "UINT16"},
        {"WORD", "UINT16"}, {"UDINT", "UINT32"}, {"DWORD", "UINT32"}, {"ULINT", "UINT64"},
        {"REAL", "REAL32"}, {"LREAL", "REAL64"}, {"FLOAT", "REAL32"},
    };
    t = without_spaces(t);
    if (auto it = kMap.find(t); it != kMap.end()) return it->second;
    return t;
}

std::vector<DeviceDesc> parse_esi(const EsiReader& r, const tinyxml2::XMLDocument& doc) {
    const tinyxml2::XMLElement* root = doc.RootElement();
    if (!root || std::string(root->Name()) != "EtherCATInfo")
        throw Error(SB() << (root ? r.where(root) : "") << ": root element should be "
                         << "<EtherCATInfo>, got <" << (root ? root->Name() : "") << ">");
    const tinyxml2::XMLElement* vendor_el = root->FirstChildElement("Vendor");
    if (!vendor_el) r.fail(root, "missing <Vendor>");
    uint32_t vendor = static_cast<uint32_t>(r.unsigned_in(
        vendor_el->FirstChildElement("Id") ? vendor_el->FirstChildElement("Id") : vendor_el,
        "Vendor Id", r.child_text(vendor_el, "Id"), 0xFFFFFFFF));
    const tinyxml2::XMLElement* descs = root->FirstChildElement("Descriptions");
    if (!descs) r.fail(root, "missing <Descriptions>");
    const tinyxml2::XMLElement* devices = descs->FirstChildElement("Devices");
    if (!devices) r.fail(descs, "missing <Devices>");

    std::vector<DeviceDesc> out;
    for (auto* dev = devices->FirstChildElement("Device"); dev;
         dev = dev->NextSiblingElement("Device")) {
        DeviceDesc d;
        d.vendor = vendor;
        const tinyxml2::XMLElement* type = dev->FirstChildElement("Type");
        if (!type) r.fail(dev, "missing <Type>");
        d.type = without_spaces(type->GetText() ? type->GetText() : "");
        if (d.type.empty()) r.fail(type, "empty device type");
        const char* pc = type->Attribute("ProductCode");
        if (!pc) r.fail(type, "missing attribute ProductCode");
        d.product = static_cast<uint32_t>(r.unsigned_in(type, "ProductCode", pc, 0xFFFFFFFF));
        if (const char* rev = type->Attribute("RevisionNo"))
            d.revision = static_cast<uint32_t>(r.unsigned_in(type, "RevisionNo", rev, 0xFFFFFFFF));
        d.name = esi_name(dev);

        for (auto* sm = dev->FirstChildElement("Sm"); sm; sm = sm->NextSiblingElement("Sm")) {
            SyncManagerDesc s;
            s.index = static_cast<uint8_t>(d.sms.size());
            const char* start = sm->Attribute("StartAddress");
            if (!start) r.fail(sm, "missing attribute StartAddress");
            s.start = static_cast<uint16_t>(r.unsigned_in(sm, "StartAddress", start, 0xFFFF));
            if (const char* v = sm->Attribute("ControlByte"))
                s.control = static_cast<uint8_t>(r.unsigned_in(sm, "ControlByte", v, 0xFF));
            if (const char* v = sm->Attribute("DefaultSize"))
                s.default_size = static_cast<uint16_t>(r.unsigned_in(sm, "DefaultSize", v, 0xFFFF));
            uint64_t enable = 1;
            if (const char* v = sm->Attribute("Enable"))
                enable = r.unsigned_in(sm, "Enable", v, 0xFF);
            s.enable = enable & kSiiSmEnable;
            s.is_virtual = enable & kSiiSmVirtual;
            if (const char* v = sm->Attribute("Virtual"))
                s.is_virtual = std::string(v) == "true" || std::string(v) == "1";
            std::string text = without_spaces(sm->GetText() ? sm->GetText() : "");
            if (text.empty())
                s.type = SmType::Unused;
            else if (auto t = sm_type_from(text))
                s.type = *t;
            else
                r.fail(sm, SB() << "'" << text
                                << "' should be MBoxOut, MBoxIn, Outputs or "
                                   "Inputs");
            d.sms.push_back(s);
        }

        std::vector<std::pair<uint8_t, uint16_t>> rx_assign, tx_assign;
        for (bool rx : {true, false}) {
            const char* tag = rx ? "RxPdo" : "TxPdo";
            for (auto* pe = dev->FirstChildElement(tag); pe; pe = pe->NextSiblingElement(tag)) {
                Pdo p;
                p.index = static_cast<uint16_t>(r.unsigned_in(
                    pe->FirstChildElement("Index") ? pe->FirstChildElement("Index") : pe,
                    "PDO Index", r.child_text(pe, "Index"), 0xFFFF));
                p.name = esi_name(pe);
                if (const char* sm = pe->Attribute("Sm")) {
                    uint64_t smi = r.unsigned_in(pe, "Sm", sm, 255);
                    if (smi >= d.sms.size())
                        r.fail(pe, SB() << "PDO " << hex(p.index) << " is assigned to SM" << smi
                                        << " but the device has " << d.sms.size()
                                        << " <Sm> elements");
                    (rx ? rx_assign : tx_assign).emplace_back(static_cast<uint8_t>(smi), p.index);
                }
                const std::string pdo_name = without_spaces(p.name);
                for (auto* en = pe->FirstChildElement("Entry"); en;
                     en = en->NextSiblingElement("Entry")) {
                    PdoEntry e;
                    auto* idx = en->FirstChildElement("Index");
                    e.index = static_cast<uint16_t>(r.unsigned_in(
                        idx ? idx : en, "Entry Index", r.child_text(en, "Index"), 0xFFFF));
                    auto* bl = en->FirstChildElement("BitLen");
                    uint64_t bits =
                        r.unsigned_in(bl ? bl : en, "BitLen", r.child_text(en, "BitLen"), 255);
                    if (bits == 0) r.fail(bl ? bl : en, "BitLen 0 should be > 0");
                    e.bits = static_cast<uint8_t>(bits);
                    auto* sub = en->FirstChildElement("SubIndex");
                    auto* dt = en->FirstChildElement("DataType");
                    if (e.index != 0 && sub && dt) {
                        e.sub = static_cast<uint8_t>(
                            r.unsigned_in(sub, "SubIndex", sub->GetText(), 255));
                        e.datatype = normalize_datatype(dt->GetText() ? dt->GetText() : "");
                        std::string entry_name = without_spaces(esi_name(en));
                        e.name = pdo_name.empty() ? entry_name : pdo_name + "." + entry_name;
                    } else {
                        e.index = 0; // entries without SubIndex or DataType are padding
                    }
                    p.entries.push_back(std::move(e));
                }
                (rx ? d.rx_pdos : d.tx_pdos).push_back(std::move(p));
            }
        }
        d.pdo_assign = std::move(rx_assign);
        d.pdo_assign.insert(d.pdo_assign.end(), tx_assign.begin(), tx_assign.end());

        if (auto* mbx = dev->FirstChildElement("Mailbox")) d.coe = mbx->FirstChildElement("CoE");
        if (auto* dc = dev->FirstChildElement("Dc")) {
            for (auto* om = dc->FirstChildElement("OpMode"); om;
                 om = om->NextSiblingElement("OpMode")) {
                auto* aa = om->FirstChildElement("AssignActivate");
                if (!aa) continue;
                uint64_t v = r.unsigned_in(aa, "AssignActivate", aa->GetText(), 0xFFFF);
                if (v != 0) {
                    d.dc_assign_activate = static_cast<uint16_t>(v);
                    break;
                }
            }
        }
        if (auto* el = dev->FirstChildElement("Electrical")) {
            if (auto* cur = el->FirstChildElement("EBusCurrent")) {
                int64_t ma = r.number(cur, "EBusCurrent", cur->GetText(), true);
                d.ebus_current_ma = static_cast<uint16_t>(std::clamp<int64_t>(ma, 0, 0xFFFF));
            }
        }
        out.push_back(std::move(d));
    }
    return out;
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

    // YAML device of the same product with ecmc names (same revision preferred, else highest).
    const Item* names_for(const DeviceDesc& d) const {
        const Item* best = nullptr;
        for (const auto& it : items) {
            if (it->from_esi || it->desc.vendor != d.vendor || it->desc.product != d.product)
                continue;
            if (it->desc.revision == d.revision) return it.get();
            if (!best || it->desc.revision > best->desc.revision) best = it.get();
        }
        return best;
    }

    void add_esi(DeviceDesc d, const std::string& source) {
        if (const Item* named = names_for(d)) {
            std::map<uint32_t, std::string> names; // index << 8 | sub -> ecmc name
            for (const auto* list : {&named->desc.rx_pdos, &named->desc.tx_pdos})
                for (const Pdo& p : *list)
                    for (const PdoEntry& e : p.entries)
                        if (e.index != 0) names.emplace(uint32_t{e.index} << 8 | e.sub, e.name);
            for (auto* list : {&d.rx_pdos, &d.tx_pdos})
                for (Pdo& p : *list)
                    for (PdoEntry& e : p.entries)
                        if (e.index != 0)
                            if (auto it = names.find(uint32_t{e.index} << 8 | e.sub);
                                it != names.end())
                                e.name = it->second;
        }
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
    const std::string text = read_file(path);
    tinyxml2::XMLDocument doc;
    if (doc.Parse(text.data(), text.size()) != tinyxml2::XML_SUCCESS)
        throw Error(SB() << SourceLoc{path, doc.ErrorLineNum(), 1}.str()
                         << ": XML error: " << doc.ErrorStr());
    EsiReader r(path, text);
    for (DeviceDesc& d : parse_esi(r, doc)) impl_->add_esi(std::move(d), path);
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
