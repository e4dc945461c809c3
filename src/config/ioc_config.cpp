#include "config/ioc_config.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace beamctl::config {

namespace {

// Where the IOC file's relative paths start.
std::string resolve(const std::string& dir, const std::string& p) {
    if (p.empty() || p[0] == '/') return p;
    return (std::filesystem::path(dir) / p).lexically_normal().string();
}

MacroMap macros_of(const YamlNode& n) {
    MacroMap mm;
    for (auto& [k, v] : n.string_pairs()) mm[k] = v;
    return mm;
}

int int_of(const YamlNode& n, int def, double lo, double hi) {
    return int(n.integer(between(lo, hi)).value_or(def));
}

void read_buses(const YamlNode& buses, const std::string& dir, IocConfig& cfg) {
    cfg.buses = read_bus_list(buses, dir, false);
}

// `include: [dirs]`, `libraries: [files]`: resolved paths.
std::vector<std::string> paths_of(const YamlNode& n, const std::string& dir) {
    std::vector<std::string> out;
    for (const YamlNode& item : n.list())
        if (auto s = item.string()) out.push_back(resolve(dir, *s));
    return out;
}


// The name of an entry that becomes part of PV names: letters, digits, _ - (and : when `colon`),
// unique among `names` (its kind says which, in the error).
void check_name_part(const YamlNode& n, const std::string& name, const char* kind, std::set<std::string>& names, bool colon) {
    if (name.empty()) return;
    const char* ok = colon ? "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_:-"
                           : "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-";
    if (name.find_first_not_of(ok) != std::string::npos)
        n.error(SB() << "'" << name << "' should be a plain PV name part (letters, digits, _ " << (colon ? ": " : "") << "-)");
    else if (!names.insert(name).second)
        n.error(SB() << kind << " '" << name << "' is defined twice");
}

} // namespace

std::string McaEntry::element_name(int i) const {
    if (i == 0) return name;
    std::size_t d = name.size();
    while (d > 0 && std::isdigit(static_cast<unsigned char>(name[d - 1]))) --d;
    return name.substr(0, d) + std::to_string(std::strtoull(name.c_str() + d, nullptr, 10) + unsigned(i));
}

std::string McaEntry::dxp_prefix(int i) const {
    const std::string n = element_name(i);
    std::size_t d = n.size();
    while (d > 0 && std::isdigit(static_cast<unsigned char>(n[d - 1]))) --d;
    return d < n.size() ? "dxp" + n.substr(d) + ":" : "dxp_" + n + ":";
}

std::string McaEntry::sum_name() const {
    std::size_t d = name.size();
    while (d > 0 && std::isdigit(static_cast<unsigned char>(name[d - 1]))) --d;
    return name.substr(0, d) + "Sum";
}

std::vector<BusConfig> read_bus_list(const YamlNode& buses, const std::string& dir, bool scanner_file) {
    std::vector<BusConfig> out;
    std::set<int> ids;
    const auto items = buses.list();
    for (std::size_t i = 0; i < items.size(); ++i) {
        const YamlNode& b = items[i];
        if (!b.keys({"id", "link", "slaves", "strict", "rate_hz", "dc_follow"})) continue;
        BusConfig bc;
        bc.id = int_of(b["id"], int(i), 0, 15);
        bc.strict = b["strict"].boolean().value_or(false);
        if (b.has("dc_follow")) {
            if (scanner_file)
                b["dc_follow"].error("belongs to the IOC's file: the IOC's master steers the clock");
            else if (auto f = b["dc_follow"].integer(between(0, 65534))) {
                bc.dc_follow = int(*f);
                bc.dc_follow_where = b["dc_follow"].where();
            }
        }
        if (b.has("rate_hz")) {
            if (scanner_file)
                b["rate_hz"].error("the scanner runs its buses in one cycle: its file's engine.rate_hz");
            else if (auto r = b["rate_hz"].number(between(1, 20000))) {
                bc.rate_hz = *r;
                bc.rate_where = b["rate_hz"].where();
            }
        }
        if (!ids.insert(bc.id).second) b.error(SB() << "bus id " << bc.id << " used twice");
        if (YamlNode l = b["link"]; l.keys({"type", "plant", "host", "port", "iface", "busy_poll", "faults", "socket", "slaves", "tick_timeout_ms", "claims"}) && l) {
            bc.link.where = l.where();
            if (scanner_file)
                bc.link.type = l.required("type", " (sim, udp or raw)").one_of({"sim", "udp", "raw"}).value_or("sim");
            else
                bc.link.type = l.required("type", " (sim, udp, raw or scanner)").one_of({"sim", "udp", "raw", "scanner"}).value_or("sim");
            const bool scanner = bc.link.type == "scanner";
            for (const char* k : {"socket", "slaves", "tick_timeout_ms", "claims"})
                if (l.has(k) && !scanner) l[k].error("is a key of a scanner link (type: scanner)");
            for (const char* k : {"plant", "host", "port", "iface", "busy_poll", "faults"})
                if (l.has(k) && scanner) l[k].error("belongs to the scanner's file: the scanner runs this bus");
            if (scanner) {
                bc.link.socket = resolve(dir, l.required("socket", " (the scanner's socket, its file's scanner.socket)").string().value_or(""));
                bc.link.attach_where = l["slaves"].where();
                for (const YamlNode& a : l["slaves"].list())
                    if (auto t = a.string()) bc.link.attach.push_back(*t);
                bc.link.tick_timeout_s = l["tick_timeout_ms"].number(between(1, 10000)).value_or(100) / 1000.0;
                if (YamlNode c = l["claims"]; c && c.is_scalar()) {
                    bc.link.claim_all = c.one_of({"all", "none"}).value_or("all") == "all";
                } else if (c) {
                    bc.link.claim_all = false;
                    for (const YamlNode& e : c.list()) {
                        std::string t = e.string().value_or("");
                        std::size_t colon = t.find(':');
                        if (colon == std::string::npos || colon == 0 || colon + 1 == t.size())
                            e.error(SB() << "'" << t << "' should be SLAVE:entry or SLAVE:* (SLAVE a name or position)");
                        else
                            bc.link.claims.emplace_back(t.substr(0, colon), t.substr(colon + 1));
                    }
                }
            }
            if (auto p = l["plant"].string()) {
                bc.link.plant = resolve(dir, *p);
                bc.link.plant_where = l["plant"].where();
            }
            bc.link.host = l["host"].string().value_or(bc.link.host);
            bc.link.port = uint16_t(l["port"].unsigned_integer(65535).value_or(bc.link.port));
            bc.link.iface = l["iface"].string().value_or("");
            bc.link.busy_poll = l["busy_poll"].boolean().value_or(false);
            for (const YamlNode& f : l["faults"].list())
                if (auto t = f.string()) {
                    bc.link.faults.push_back(*t);
                    bc.link.faults_where.push_back(f.where());
                }
            if (l.has("faults") && bc.link.type != "sim")
                l["faults"].error("faults are injected into a simulated segment: only with type: sim");
            if (bc.link.type == "raw" && bc.link.iface.empty() && (!l.has("iface") || l["iface"].is_scalar()))
                l.error("a raw link needs 'iface' (the network interface of the segment)");
        }
        const bool attach_only = bc.link.type == "scanner" && !bc.link.attach.empty();
        if (bc.link.type == "scanner" && !b.has("slaves") && bc.link.attach.empty() && b["link"].has("socket"))
            b["link"].error("a scanner link needs 'slaves' (the scanner's slaves this IOC attaches: names or positions) or the bus's 'slaves' list");
        if (attach_only && b.has("slaves"))
            b["slaves"].error("give the slaves once: link.slaves (resolved with the scanner) or this list, not both");
        YamlNode slaves = attach_only || bc.link.type == "scanner" && !b.has("slaves") ? b["slaves"]
                                                                                       : b.required("slaves", " (a list of {position, type})");
        std::set<std::string> names;
        std::set<int> positions;
        for (const YamlNode& s : slaves.list()) {
            if (!s.keys({"position", "type", "sdo", "oversampling", "name", "revision"})) continue;
            SlaveEntry se;
            se.position = int_of(s.required("position"), -1, 0, 65534);
            se.type = s.required("type", " (a device of the catalog, e.g. EL1008)").string().value_or("");
            se.type_where = s["type"].where();
            if (auto nm = scanner_file ? s.required("name", " (the slave's unique name, e.g. OUT0)").string() : s["name"].string()) {
                if (nm->empty() || nm->find_first_of(" \t,\"'") != std::string::npos ||
                    nm->find_first_not_of("0123456789") == std::string::npos)
                    s["name"].error(SB() << "'" << *nm << "' should be a word (not a number, no spaces or commas)");
                else if (!names.insert(*nm).second)
                    s["name"].error(SB() << "'" << *nm << "' is used twice");
                else
                    se.name = *nm;
            }
            se.revision = uint32_t(s["revision"].unsigned_integer(0xFFFFFFFF).value_or(0));
            if (s.has("oversampling")) { // checked against the device's range once its type is known
                se.oversampling = unsigned(s["oversampling"].unsigned_integer(1000).value_or(1));
                se.oversampling_where = s["oversampling"].where();
                if (se.oversampling == 0) s["oversampling"].error("0 should be at least 1 (samples per cycle)");
            }
            if (se.position >= 0 && !positions.insert(se.position).second)
                s["position"].error(SB() << se.position << " is used twice");
            for (const YamlNode& d : s["sdo"].list()) {
                if (!d.keys({"index", "sub", "value", "size"})) continue;
                SdoConfig sc;
                sc.index = uint16_t(d.required("index").unsigned_integer(0xFFFF).value_or(0));
                sc.sub = uint8_t(d["sub"].unsigned_integer(255).value_or(0));
                if (auto size = d["size"].unsigned_integer(8)) {
                    if (*size != 1 && *size != 2 && *size != 4 && *size != 8)
                        d["size"].error(SB() << *size << " should be 1, 2, 4 or 8");
                    else
                        sc.size = uint8_t(*size);
                }
                sc.value = d.required("value")
                               .unsigned_integer(sc.size == 8 ? UINT64_MAX
                                                              : (uint64_t(1) << (8 * sc.size)) - 1)
                               .value_or(0);
                se.sdo.push_back(sc);
            }
            if (se.position >= 0) bc.slaves.push_back(se);
        }
        out.push_back(bc);
    }
    return out;
}

std::string expand_ioc_macros(const std::string& text, const MacroMap& macros, const std::string& path) {
    // A reference is expanded when its name (up to '=', ',' or the closing bracket) has a value
    // or the reference has a default; nested names ($(A$(B))) are left to the files that use them.
    auto expands = [&](std::size_t pos) {
        std::size_t end = text.find_first_of(")}=,$\\'\"\n", pos + 2);
        if (end == std::string::npos) return false;
        return text[end] == '=' || macros.count(text.substr(pos + 2, end - pos - 2)) > 0;
    };
    std::string out;
    out.reserve(text.size());
    SourceLoc loc{path, 1, 1};
    for (std::size_t pos = 0; pos < text.size();) {
        if (is_macro_ref(text, pos) && expands(pos)) {
            out += expand_macro_ref(text, pos, loc, macros);
            continue;
        }
        advance_loc(loc, text[pos]);
        out += text[pos++];
    }
    return out;
}

std::string axis_entry_context(const AxisEntry& e, std::size_t index) {
    std::string m;
    for (const auto& [k, v] : e.macros) m += (m.empty() ? " with " : ", ") + k + "=" + v;
    std::string file = e.file.substr(e.file.find_last_of('/') + 1);
    return SB() << (e.where.empty() ? std::string() : e.where + ": ") << "axes[" << index << "] (" << file << m << ")";
}

IocConfig IocConfig::load(const std::string& path, const MacroMap& macros) {
    ErrorList errors;
    IocConfig cfg = load(path, errors, macros);
    errors.throw_if_any();
    return cfg;
}

IocConfig IocConfig::load(const std::string& path, ErrorList& errors, const MacroMap& macros) {
    std::ifstream f(path);
    if (!f) {
        errors.add(SB() << path << ": cannot open: " << std::strerror(errno));
        IocConfig cfg;
        cfg.path = path;
        return cfg;
    }
    std::stringstream ss;
    ss << f.rdbuf();
    std::string text;
    if (!errors.capture([&] { text = expand_ioc_macros(ss.str(), macros, path); })) {
        IocConfig cfg;
        cfg.path = path;
        return cfg;
    }
    return parse(text, path, errors);
}

IocConfig IocConfig::parse(const std::string& text, const std::string& path) {
    ErrorList errors;
    IocConfig cfg = parse(text, path, errors);
    errors.throw_if_any();
    return cfg;
}

IocConfig IocConfig::parse(const std::string& text, const std::string& path, ErrorList& errors) {
    std::string dir = std::filesystem::path(path).parent_path().string();
    if (dir.empty()) dir = ".";
    YamlReader rd(path, text, "the IOC file");
    IocConfig cfg;
    cfg.path = path;
    YamlNode root = rd.root();
    if (root.is_null()) rd.error(rd.top(), "empty configuration (needs at least ioc:)");
    if (!root.keys({"ioc", "engine", "buses", "axes", "plugins", "plcs", "kinematics", "storages", "luts", "m2m", "db", "bridges", "ca", "autosave", "pvt", "pcomp", "capture", "feedback", "detectors", "smart_control", "compound_motors", "state_machines", "notify", "collision_zones", "plans"},
                   {{"web", "it is not supported by this version of beamctl yet", true}}) ||
        root.is_null()) {
        rd.take_errors(errors);
        return cfg;
    }
    if (YamlNode n = root.required("ioc", " ({name: ..., prefix: ...})"); n.keys({"name", "prefix", "stats"}) && n) {
        if (auto name = n.required("name").string()) {
            if (name->empty() || name->find_first_of(" .$\"'") != std::string::npos)
                n["name"].error(SB() << "'" << *name << "' should be a plain PV name part");
            else
                cfg.name = *name;
        }
        cfg.prefix = n["prefix"].string().value_or(cfg.name + ":");
        cfg.stats = cfg.name;
        // devIocStats's records as $(IOC):HEARTBEAT ...: `stats: NAME` names $(IOC), `false` leaves them out
        if (YamlNode st = n["stats"]; st) {
            std::string raw = st.raw();
            if (raw == "false" || raw == "no" || raw == "off") cfg.stats.clear();
            else if (raw == "true" || raw == "yes" || raw == "on") cfg.stats = cfg.name;
            else if (raw.empty() || raw.find_first_of(" .$\"'") != std::string::npos)
                st.error("should be false, true or the $(IOC) name of the IOC health PVs (devIocStats's, e.g. IOC:BL1)");
            else cfg.stats = raw;
        }
    } else {
        cfg.prefix = cfg.name + ":";
        cfg.stats = cfg.name;
    }
    if (YamlNode n = root["engine"]; n.keys({"rate_hz", "cpu", "priority"})) {
        cfg.rate_hz = n["rate_hz"].number(between(1, 20000)).value_or(cfg.rate_hz);
        cfg.cpu = int_of(n["cpu"], cfg.cpu, 0, 1023);
        cfg.priority = int_of(n["priority"], cfg.priority, 0, 99);
    }
    read_buses(root["buses"], dir, cfg);
    for (const YamlNode& a : root["axes"].list()) {
        if (!a.keys({"file", "macros", "encoders"})) continue;
        AxisEntry e;
        e.where = a.where();
        e.file = resolve(dir, a.required("file", " (an ECMC axis YAML file)").string().value_or(""));
        e.file_where = a["file"].where();
        e.macros = macros_of(a["macros"]);
        for (const YamlNode& enc : a["encoders"].list()) {
            if (!enc.keys({"file", "macros"})) continue;
            AxisEntry::Encoder x;
            x.file = resolve(dir, enc.required("file").string().value_or(""));
            x.file_where = enc["file"].where();
            x.macros = macros_of(enc["macros"]);
            e.encoders.push_back(std::move(x));
        }
        cfg.axes.push_back(std::move(e));
    }
    for (const YamlNode& p : root["plugins"].list()) {
        if (!p.keys({"file", "config"})) continue;
        PluginEntry e;
        e.file = resolve(dir, p.required("file", " (a plugin shared library)").string().value_or(""));
        e.file_where = p["file"].where();
        e.config = p["config"].string().value_or("");
        e.where = p.where();
        cfg.plugins.push_back(std::move(e));
    }
    {
        std::set<int> ids;
        const auto plcs = root["plcs"].list();
        for (std::size_t i = 0; i < plcs.size(); ++i) {
            const YamlNode& p = plcs[i];
            if (!p.keys({"id", "file", "rate_ms", "enable", "macros", "include", "libraries", "strict", "bus"}))
                continue;
            PlcEntry e;
            e.id = int_of(p["id"], int(i), 0, 99);
            if (!ids.insert(e.id).second) p.error(SB() << "PLC id " << e.id << " used twice");
            e.file = resolve(dir, p.required("file", " (a PLC file in ECMC's language)").string().value_or(""));
            e.file_where = p["file"].where();
            if (auto r = p["rate_ms"].number()) {
                if (*r > 0 || *r == -1)
                    e.rate_ms = *r;
                else
                    p["rate_ms"].error(SB() << *r << " should be > 0, or -1 (every cycle)");
            }
            e.enable = p["enable"].boolean().value_or(true);
            e.strict = p["strict"].boolean().value_or(false);
            if (p.has("bus")) {
                e.bus_where = p["bus"].where();
                int id = int_of(p["bus"], -1, 0, 15);
                bool known = false;
                for (const auto& bc : cfg.buses) known |= bc.id == id;
                if (!known && id >= 0)
                    p["bus"].error(SB() << "no bus " << id << " in buses: (a PLC runs in the cycle of one of them)");
                else
                    e.bus = id;
            }
            e.macros = macros_of(p["macros"]);
            e.include = paths_of(p["include"], dir);
            e.libraries = paths_of(p["libraries"], dir);
            e.where = p.where();
            cfg.plcs.push_back(std::move(e));
        }
    }
    {
        const auto kins = root["kinematics"].list();
        for (std::size_t i = 0; i < kins.size(); ++i) {
            const YamlNode& k = kins[i];
            if (!k.keys({"name", "virtual", "real", "inverse", "file", "macros", "include"})) continue;
            KinematicsEntry e;
            e.where = k.where();
            e.name = k["name"].string().value_or(k.path());
            auto ids = [&](const char* key, std::vector<int>& out) {
                YamlNode l = k.required(key, " (a list of axis ids)");
                if (l && (!l.is_list() || l.yaml().size() == 0)) {
                    l.error("should be a list of axis ids");
                    return;
                }
                for (const YamlNode& id : l.list())
                    if (auto v = id.unsigned_integer(999)) out.push_back(int(*v));
            };
            ids("virtual", e.virt);
            ids("real", e.real);
            if (k.has("inverse") == k.has("file"))
                k.error("give the inverse transform as 'inverse' (PLC code) or 'file', one of them");
            e.code = k["inverse"].string().value_or("");
            if (k.has("inverse")) e.code_at = k["inverse"].text_loc(&e.code_block);
            if (auto f = k["file"].string()) {
                e.file = resolve(dir, *f);
                e.file_where = k["file"].where();
            }
            e.macros = macros_of(k["macros"]);
            e.include = paths_of(k["include"], dir);
            cfg.kinematics.push_back(std::move(e));
        }
    }
    {
        std::set<int> ids;
        const auto list = root["storages"].list();
        for (std::size_t i = 0; i < list.size(); ++i) {
            const YamlNode& d = list[i];
            if (!d.keys({"id", "size", "type", "capacity", "sample_rate_ms", "desc"})) continue;
            StorageEntry e;
            e.where = d.where();
            e.id = int_of(d["id"], int(i), 0, 31);
            if (!ids.insert(e.id).second) d.error(SB() << "data storage id " << e.id << " used twice");
            e.size = std::size_t(d["size"].unsigned_integer(10000000).value_or(e.size));
            if (e.size == 0) d["size"].error("should be at least 1 value");
            if (YamlNode t = d["type"]) {
                std::string v = t.string().value_or("");
                if (v == "normal" || v == "0") e.type = 0;
                else if (v == "ring" || v == "1") e.type = 1;
                else if (v == "fifo" || v == "2") e.type = 2;
                else t.error(SB() << "'" << v << "' is not a buffer type (normal or 0, ring or 1, fifo or 2)");
            }
            e.capacity = std::size_t(d["capacity"].unsigned_integer(10000000).value_or(0));
            if (e.capacity && e.capacity < e.size)
                d["capacity"].error(SB() << e.capacity << " is less than the size " << e.size);
            e.sample_rate_ms = d["sample_rate_ms"].number(between(0, 3600000)).value_or(e.sample_rate_ms);
            e.desc = d["desc"].string().value_or(SB() << "ds" << e.id);
            cfg.storages.push_back(std::move(e));
        }
    }
    {
        std::set<int> ids;
        const auto list = root["pcomp"].list();
        for (std::size_t i = 0; i < list.size(); ++i) {
            const YamlNode& d = list[i];
            if (!d.keys({"id", "input", "output", "start", "step", "width", "pulses", "pre_start", "relative", "dir", "enable",
                         "egu", "desc", "analog_high", "analog_low"}))
                continue;
            PcompEntry e;
            e.where = d.where();
            e.id = int_of(d["id"], int(i) + 1, 1, 32);
            if (!ids.insert(e.id).second) d.error(SB() << "pcomp id " << e.id << " used twice");
            e.input = d.required("input", " (an engine signal such as ax1.enc.actpos, or time)").string().value_or("");
            e.input_where = d["input"].where();
            e.output = d["output"].string().value_or("");
            e.output_where = d["output"].where();
            e.start = d["start"].number().value_or(0);
            e.step = d["step"].number().value_or(0);
            e.width = d["width"].number().value_or(0);
            e.pre_start = d["pre_start"].number(at_least(0)).value_or(0);
            e.pulses = uint32_t(d["pulses"].unsigned_integer(0x7FFFFFFF).value_or(0));
            e.relative = d["relative"].boolean().value_or(false);
            if (auto dir = d["dir"].one_of({"positive", "negative", "either"})) e.dir = *dir == "positive" ? 0 : *dir == "negative" ? 1 : 2;
            e.enable = d["enable"].boolean().value_or(false);
            e.analog_high = d["analog_high"].integer(between(-32768, 65535)).value_or(16384);
            e.analog_low = d["analog_low"].integer(between(-32768, 65535)).value_or(0);
            e.egu = d["egu"].string().value_or(e.input == "time" ? "s" : "");
            e.desc = d["desc"].string().value_or(SB() << "pcomp" << e.id << " on " << e.input);
            cfg.pcomp.push_back(std::move(e));
        }
    }
    if (YamlNode c = root["capture"]; c && c.keys({"trigger", "gate", "fields", "storages", "ring_rows", "last_rows", "file_path", "file_name", "flush_s"})) {
        CaptureEntry e;
        e.where = c.where();
        if (YamlNode t = c["trigger"]; t && t.is_list()) {
            e.triggers.clear();
            for (const YamlNode& ti : t.list())
                if (auto v = ti.string()) e.triggers.push_back(*v);
            if (e.triggers.empty()) t.error("should name at least one trigger (pcomp<n>, cycle or a signal)");
        } else if (t) {
            e.triggers = {t.string().value_or("cycle")};
        }
        e.trigger_where = c["trigger"].present() ? c["trigger"].where() : e.where;
        e.gate = c["gate"].string().value_or("");
        e.gate_where = c["gate"].where();
        std::set<std::string> names;
        for (const YamlNode& f : c.required("fields", " (a list of {signal, name, units, modes})").list()) {
            if (!f.keys({"signal", "name", "units", "modes"})) continue;
            CaptureField cf;
            cf.where = f.where();
            cf.signal = f.required("signal").string().value_or("");
            std::string def = cf.signal;
            for (char& ch : def)
                if (ch == '.') ch = '_';
            cf.name = f["name"].string().value_or(def);
            if (cf.name.empty() || cf.name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") != std::string::npos)
                f["name"].error(SB() << "'" << cf.name << "' should be letters, digits and '_' (a column of the file and a PV name part)");
            cf.units = f["units"].string().value_or("");
            if (YamlNode m = f["modes"]) {
                cf.modes.clear();
                for (const YamlNode& mi : m.list())
                    if (auto v = mi.one_of({"value", "diff", "sum", "min", "max"})) cf.modes.push_back(*v);
                if (cf.modes.empty()) m.error("should name at least one of value, diff, sum, min, max");
            }
            for (const std::string& mode : cf.modes) {
                std::string col = mode == "value" ? cf.name : cf.name + "_" + mode;
                if (!names.insert(col).second) f.error(SB() << "column '" << col << "' is captured twice");
            }
            e.fields.push_back(std::move(cf));
        }
        for (const YamlNode& d : c["storages"].list()) { // data storages whose appends go into the file
            auto id = d.integer(between(0, 31));
            if (!id) continue;
            bool exists = false;
            for (const StorageEntry& st : cfg.storages) exists = exists || st.id == *id;
            if (!exists) d.error(SB() << "ds" << *id << " is not in storages:");
            else if (std::find(e.storages.begin(), e.storages.end(), int(*id)) != e.storages.end()) d.error(SB() << "ds" << *id << " is listed twice");
            else e.storages.push_back(int(*id));
        }
        e.ring_rows = std::size_t(c["ring_rows"].unsigned_integer(1u << 26).value_or(e.ring_rows));
        if (e.ring_rows < 16) c["ring_rows"].error("should be at least 16 rows");
        e.last_rows = std::size_t(c["last_rows"].unsigned_integer(1000000).value_or(e.last_rows));
        e.file_path = c["file_path"].string().value_or(e.file_path);
        e.file_name = c["file_name"].string().value_or(e.file_name);
        e.flush_s = c["flush_s"].number(between(0.01, 3600)).value_or(e.flush_s);
        cfg.capture = std::move(e);
    }
    if (YamlNode dets = root["detectors"]; dets && dets.keys({"mca", "quadem", "area_detector"})) {
        std::set<std::string> parts; // every PV name part of every area detector
        for (const YamlNode& d : dets["area_detector"].list()) {
            if (!d.keys({"cam", "image", "hdf", "stats", "bus", "size", "pixel_size", "centre", "photons_per_flux", "dark", "read_noise",
                         "data_type", "acquire_time", "acquire_period", "gain", "file_path"}))
                continue;
            AreaDetectorEntry e;
            e.where = d.where();
            for (auto [key, out] : {std::pair<const char*, std::string*>{"cam", &e.cam}, {"image", &e.image}, {"hdf", &e.hdf}, {"stats", &e.stats}}) {
                *out = d[key].string().value_or(*out);
                const std::string kind = std::string("area_detector ") + key;
                check_name_part(d.has(key) ? d[key] : d, *out, kind.c_str(), parts, false);
            }
            e.bus = int(d["bus"].integer(between(0, 255)).value_or(-1));
            if (YamlNode v = d["size"]) {
                auto items = v.list();
                if (items.size() != 2) v.error("should be [x, y] pixels");
                else {
                    e.size_x = int(items[0].integer(between(1, 8192)).value_or(e.size_x));
                    e.size_y = int(items[1].integer(between(1, 8192)).value_or(e.size_y));
                }
            }
            if (YamlNode v = d["centre"]) {
                auto items = v.list();
                if (items.size() != 2) v.error("should be [x, y] mm");
                else e.centre_x = items[0].number().value_or(0), e.centre_y = items[1].number().value_or(0);
            }
            e.pixel_size = d["pixel_size"].number(between(1e-6, 100)).value_or(e.pixel_size);
            e.photons_per_flux = d["photons_per_flux"].number(between(0, 1e15)).value_or(e.photons_per_flux);
            e.dark = d["dark"].number(between(0, 1e9)).value_or(e.dark);
            e.read_noise = d["read_noise"].number(between(0, 1e9)).value_or(e.read_noise);
            if (auto t = d["data_type"].string()) {
                static const std::set<std::string> types = {"Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Float32", "Float64"};
                if (types.count(*t)) e.data_type = *t;
                else d["data_type"].error(SB() << "'" << *t << "' is not a data type (Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64)");
            }
            e.acquire_time = d["acquire_time"].number(between(0, 3600)).value_or(e.acquire_time);
            e.acquire_period = d["acquire_period"].number(between(0, 3600)).value_or(e.acquire_period);
            e.gain = d["gain"].number(between(0, 1e6)).value_or(e.gain);
            e.file_path = d["file_path"].string().value_or("");
            cfg.area_detector.push_back(std::move(e));
        }
        std::set<std::string> qnames;
        for (const YamlNode& d : dets["quadem"].list()) {
            if (!d.keys({"name", "currents", "geometry", "averaging_time", "current_scale", "current_offset", "position_scale",
                         "position_offset", "egu", "prec", "ts_points", "ranges", "range"}))
                continue;
            QuadEmEntry e;
            e.where = d.where();
            e.name = d.required("name", " (the PV prefix after the IOC's, e.g. QE1)").string().value_or("");
            check_name_part(d["name"], e.name, "quadem", qnames, false);
            YamlNode cur = d.required("currents", " (four engine values: the diodes' currents)");
            e.currents_where = cur.where();
            for (const YamlNode& c : cur.list())
                if (auto v = c.string()) e.currents.push_back(*v);
            if (cur && e.currents.size() != 4) cur.error(SB() << "should name four values, got " << e.currents.size());
            if (auto g = d["geometry"].string()) {
                if (*g == "Diamond" || *g == "Square" || *g == "SquareCC") e.geometry = *g;
                else d["geometry"].error(SB() << "'" << *g << "' is not a geometry (Diamond, Square, SquareCC)");
            }
            e.averaging_time = d["averaging_time"].number(between(0, 3600)).value_or(e.averaging_time);
            auto numbers = [&](const char* key, double* out, std::size_t n) {
                YamlNode v = d[key];
                if (!v) return;
                auto items = v.list();
                if (items.size() != n) {
                    v.error(SB() << "should be " << n << " numbers");
                    return;
                }
                for (std::size_t i = 0; i < n; ++i)
                    if (auto x = items[i].number()) out[i] = *x;
            };
            numbers("current_scale", e.current_scale, 4);
            numbers("current_offset", e.current_offset, 4);
            numbers("position_scale", e.position_scale, 2);
            numbers("position_offset", e.position_offset, 2);
            e.egu = d["egu"].string().value_or("");
            e.prec = int(d["prec"].integer(between(0, 15)).value_or(4));
            e.ts_points = int(d["ts_points"].integer(between(1, 100000)).value_or(1000));
            for (const YamlNode& r : d["ranges"].list()) {
                if (!r.keys({"name", "full_scale"})) continue;
                QuadEmEntry::Range x;
                x.name = r.required("name", " (the Range PV's choice)").string().value_or("");
                if (x.name.size() > 25) r["name"].error(SB() << "'" << x.name << "' is longer than an mbbo state string (25 characters)");
                x.full_scale = r.required("full_scale", " [current units; 0: no limit]").number(at_least(0)).value_or(0);
                e.ranges.push_back(std::move(x));
            }
            if (e.ranges.size() > 16) d["ranges"].error(SB() << "has " << e.ranges.size() << " ranges: an mbbo holds 16");
            e.range = int(d["range"].integer(between(0, 15)).value_or(0));
            if (e.range >= int(std::max<std::size_t>(e.ranges.size(), 1)))
                d["range"].error(SB() << "range " << e.range << " is not one of the " << std::max<std::size_t>(e.ranges.size(), 1) << " ranges");
            cfg.quadem.push_back(std::move(e));
        }
        std::set<std::string> names, dxps;
        int multi_element = 0;
        for (const YamlNode& d : dets["mca"].list()) {
            if (!d.keys({"name", "channels", "offset", "slope", "lines", "background", "dead_time", "bus", "elements", "noise_fwhm",
                         "preamp_gains", "dxp"}))
                continue;
            McaEntry e;
            e.where = d.where();
            e.name = d.required("name", " (the mca record's name after the IOC prefix, e.g. mca1)").string().value_or("");
            e.elements = int(d["elements"].integer(between(1, 64)).value_or(1));
            if (e.elements > 1 && (e.name.empty() || !std::isdigit(static_cast<unsigned char>(e.name.back()))))
                d["name"].error(SB() << "'" << e.name << "' should end in the first element's number (mca1: mca1 .. mca" << e.elements << ")");
            else if (e.elements > 1 && multi_element++)
                d["elements"].error("only one multi-element detector per IOC (dxpMED's PVs are $(P)StartAll, ...)");
            else
                for (int i = 0; i < e.elements; ++i) {
                    const bool fresh = !names.count(e.element_name(i));
                    check_name_part(d["name"], e.element_name(i), "mca", names, true);
                    if (fresh && !dxps.insert(e.dxp_prefix(i)).second)
                        d["name"].error(SB() << "the DXP records " << e.dxp_prefix(i) << " of " << e.element_name(i) << " are another mca's");
                }
            if (e.elements > 1) check_name_part(d["name"], e.sum_name(), "mca", names, true);
            e.channels = uint32_t(d["channels"].integer(between(1, 1 << 20)).value_or(2048));
            e.offset = d["offset"].number().value_or(0);
            e.slope = d["slope"].number().value_or(0.01);
            if (e.slope == 0) d["slope"].error("should not be 0 (keV per channel)");
            e.background = d["background"].number(at_least(0)).value_or(50);
            e.dead_time = d["dead_time"].number(between(0, 1)).value_or(2e-6);
            e.bus = int(d["bus"].integer(between(0, 255)).value_or(-1));
            e.noise_fwhm = d["noise_fwhm"].number(between(0, 100)).value_or(0.1);
            if (d.has("preamp_gains")) {
                for (const YamlNode& g : d["preamp_gains"].list()) e.preamp_gains.push_back(g.number(between(1e-6, 1e4)).value_or(2.0));
                if (int(e.preamp_gains.size()) != e.elements)
                    d["preamp_gains"].error(SB() << "should have one gain [mV/keV] per element (" << e.elements << "), not " << e.preamp_gains.size());
            }
            if (YamlNode x = d["dxp"]; x && x.keys({"peaking_time", "gap_time", "trigger_threshold", "energy_threshold", "preamp_gain",
                                                   "max_energy", "adc_percent_rule", "calibration_energy"})) {
                e.dxp.peaking_time = x["peaking_time"].number(between(0.01, 100)).value_or(2.0);
                e.dxp.gap_time = x["gap_time"].number(between(0, 100)).value_or(0.15);
                e.dxp.trigger_threshold = x["trigger_threshold"].number(between(0, 1000)).value_or(0);
                e.dxp.energy_threshold = x["energy_threshold"].number(between(0, 1000)).value_or(0);
                e.dxp.preamp_gain = x["preamp_gain"].number(between(1e-6, 1e4)).value_or(2.0);
                e.dxp.max_energy = x["max_energy"].number(between(1e-6, 1e4)).value_or(0);
                e.dxp.adc_percent_rule = x["adc_percent_rule"].number(between(1e-6, 100)).value_or(0);
                e.dxp.calibration_energy = x["calibration_energy"].number(between(1e-6, 1000)).value_or(5.9);
                if (e.dxp.max_energy > 0 && !(e.dxp.max_energy > e.offset))
                    x["max_energy"].error(SB() << "should be above the spectrum's offset (" << e.offset << " keV)");
            }
            for (const YamlNode& l : d["lines"].list()) {
                if (!l.keys({"name", "energy", "rate", "fwhm"})) continue;
                McaEntry::Line x;
                x.name = l["name"].string().value_or("");
                x.energy = l.required("energy", " [keV]").number(at_least(0)).value_or(0);
                x.rate = l.required("rate", " [counts/s]").number(at_least(0)).value_or(0);
                x.fwhm = l["fwhm"].number(between(1e-6, 1000)).value_or(0.15);
                e.lines.push_back(std::move(x));
            }
            cfg.mca.push_back(std::move(e));
        }
    }
    {
        std::set<std::string> names;
        for (const YamlNode& d : root["feedback"].list()) {
            if (!d.keys({"name", "input", "input_scale", "input_offset", "output", "output_scale", "output_offset", "dt", "kp", "ki", "kd",
                         "val", "drvh", "drvl", "fbon", "scan", "hopr", "lopr", "prec", "egu", "desc"}))
                continue;
            FeedbackEntry e;
            e.where = d.where();
            e.name = d.required("name", " (the epid record's name after the IOC prefix)").string().value_or("");
            check_name_part(d["name"], e.name, "feedback loop", names, true);
            e.input = d.required("input", " (an engine value: a bus entry or an axis variable)").string().value_or("");
            e.input_where = d["input"].where();
            e.output = d.required("output", " (a bus output entry)").string().value_or("");
            e.output_where = d["output"].where();
            e.input_scale = d["input_scale"].number().value_or(1);
            e.input_offset = d["input_offset"].number().value_or(0);
            e.output_scale = d["output_scale"].number().value_or(1);
            if (e.output_scale == 0) d["output_scale"].error("should not be 0 (raw = (OVAL - offset) / scale)");
            e.output_offset = d["output_offset"].number().value_or(0);
            e.dt = d["dt"].number(between(0, 3600)).value_or(0);
            e.kp = d["kp"].number().value_or(0);
            e.ki = d["ki"].number().value_or(0);
            e.kd = d["kd"].number().value_or(0);
            e.val = d["val"].number().value_or(0);
            e.drvh = d["drvh"].number().value_or(0);
            e.drvl = d["drvl"].number().value_or(0);
            if (e.drvl > e.drvh) d["drvl"].error(SB() << "drvl " << e.drvl << " is above drvh " << e.drvh);
            if (!d["drvh"].present() || !d["drvl"].present()) d.error("needs drvh and drvl: the output's limits (OVAL is clamped to them)");
            e.fbon = d["fbon"].boolean().value_or(false);
            if (auto sc = d["scan"].one_of({"Passive", "10 second", "5 second", "2 second", "1 second", ".5 second", ".2 second", ".1 second"})) e.scan = *sc;
            e.hopr = d["hopr"].number().value_or(0);
            e.lopr = d["lopr"].number().value_or(0);
            e.prec = int(d["prec"].integer(between(0, 15)).value_or(3));
            e.egu = d["egu"].string().value_or("");
            e.desc = d["desc"].string().value_or(SB() << "EPID " << e.input << " -> " << e.output);
            cfg.feedback.push_back(std::move(e));
        }
    }
    {
        std::set<int> ids;
        const auto list = root["luts"].list();
        for (std::size_t i = 0; i < list.size(); ++i) {
            const YamlNode& l = list[i];
            if (!l.keys({"id", "file"})) continue;
            LutEntry e;
            e.where = l.where();
            e.id = int_of(l["id"], int(i), 0, 15);
            if (!ids.insert(e.id).second) l.error(SB() << "lookup table id " << e.id << " used twice");
            e.file = resolve(dir, l.required("file", " (an ECMC lookup table file)").string().value_or(""));
            e.file_where = l["file"].where();
            cfg.luts.push_back(std::move(e));
        }
    }
    if (YamlNode m = root["m2m"]; m.keys({"name", "master"}) && m) {
        M2mEntry e;
        e.where = m.where();
        if (auto n = m["name"].string()) {
            if (n->empty() || n->find('/') != std::string::npos) m["name"].error(SB() << "'" << *n << "' should be a plain name (no '/')");
            else e.name = *n;
        }
        if (m.has("master")) e.master = int_of(m["master"], 0, -15, 15);
        cfg.m2m = e;
    }
    for (const YamlNode& d : root["db"].list()) {
        if (!d.keys({"file", "macros"})) continue;
        DbConfig dc;
        dc.file = resolve(dir, d.required("file", " (an EPICS .db file)").string().value_or(""));
        dc.file_where = d["file"].where();
        dc.macros = macros_of(d["macros"]);
        cfg.db.push_back(dc);
    }
    if (YamlNode bridges = root["bridges"]; bridges.keys({"rcp"})) {
        if (YamlNode r = bridges["rcp"];
            r.keys({"listen", "port", "prefix", "timeout_s", "db_out", "pv_pattern", "motor_fields", "machines", "allow",
                    "max_applications", "max_applications_per_address", "max_objects", "max_model_changes_per_minute"}) &&
            r) {
            RcpBridgeEntry e;
            e.prefix = r["prefix"].string().value_or(cfg.prefix + "RCP:");
            e.listen = r["listen"].string().value_or(e.listen);
            e.port = uint16_t(r["port"].unsigned_integer(65535).value_or(e.port));
            e.timeout_s = r["timeout_s"].number(Range{0, 3600, true}).value_or(e.timeout_s);
            if (auto o = r["db_out"].string()) e.db_out = resolve(dir, *o);
            e.pv_pattern = r["pv_pattern"].string().value_or("");
            e.motor_fields = r["motor_fields"].string_pairs();
            for (const YamlNode& m : r["machines"].list()) {
                if (!m.keys({"name", "address"})) continue;
                auto name = m.required("name", " (the application name its beacons carry)").string();
                auto addr = m.required("address", " (its IPv4 address or network, e.g. 10.0.3.7)").string();
                if (name && addr) e.machines.emplace_back(*name, *addr);
            }
            for (const YamlNode& a : r["allow"].list())
                if (auto t = a.string()) e.allow.push_back(*t);
            e.max_applications = std::size_t(r["max_applications"].unsigned_integer(1000).value_or(e.max_applications));
            e.max_objects = std::size_t(r["max_objects"].unsigned_integer(255).value_or(e.max_objects));
            e.max_applications_per_address =
                std::size_t(r["max_applications_per_address"].unsigned_integer(1000).value_or(e.max_applications_per_address));
            e.max_model_changes_per_minute =
                std::size_t(r["max_model_changes_per_minute"].unsigned_integer(100000).value_or(e.max_model_changes_per_minute));
            e.where = r.where();
            cfg.rcp = e;
        }
    }
    if (YamlNode ca = root["ca"]; ca.keys({"port", "acf"})) {
        if (auto p = ca["port"].unsigned_integer(65535)) cfg.ca_port = uint16_t(*p);
        if (auto a = ca["acf"].string()) {
            cfg.acf = resolve(dir, *a);
            cfg.acf_where = ca["acf"].where();
        }
    }
    if (YamlNode as = root["autosave"]; as.keys({"dir", "period_s"}) && as) {
        AutosaveEntry e;
        e.where = as.where();
        if (auto d = as.required("dir", " (the directory of the .sav files)").string()) e.dir = resolve(dir, *d);
        e.period_s = as["period_s"].number(between(0.1, 86400)).value_or(e.period_s);
        cfg.autosave = e;
    }
    if (YamlNode pv = root["pvt"]; pv.keys({"trigger", "trigger_duration_s"}) && pv) {
        PvtEntry e;
        e.where = pv.where();
        e.trigger = pv["trigger"].string().value_or("");
        e.trigger_duration_s = pv["trigger_duration_s"].number(between(0.0001, 3600)).value_or(e.trigger_duration_s);
        cfg.pvt = e;
    }
    if (YamlNode sc = root["smart_control"]; sc.keys({"name", "bind", "port", "pty", "axes", "shutter", "trigger", "scaler"}) && sc) {
        SmartControlEntry e;
        e.where = sc.where();
        e.name = sc["name"].string().value_or("smart");
        std::set<std::string> unused;
        check_name_part(sc["name"], e.name, "smart_control", unused, false);
        e.bind = sc["bind"].string().value_or("127.0.0.1");
        e.port = int(sc["port"].integer(between(0, 65535)).value_or(0));
        if (auto pty = sc["pty"].string()) e.pty = resolve(dir, *pty);
        e.shutter = sc["shutter"].string().value_or("");
        e.trigger = sc["trigger"].string().value_or("");
        e.scaler = sc["scaler"].string().value_or("");
        if (e.port == 0 && e.pty.empty()) sc.error("needs port: (TCP) or pty: (a pseudo-terminal), or both");
        static const char* kAxes[] = {"two_theta", "omega", "phi", "kappa"};
        static const char* kNames[] = {"TWOTHETA", "OMEGA", "PHI", "KAPPA"};
        if (YamlNode ax = sc.required("axes", " (two_theta, omega, phi, kappa: {motor, offset, sign, low_cut, high_cut})");
            ax.keys({"two_theta", "omega", "phi", "kappa"}) && ax) {
            for (int i = 0; i < 4; ++i) {
                YamlNode a = ax[kAxes[i]];
                if (!a || !a.keys({"motor", "offset", "sign", "low_cut", "high_cut"})) continue;
                SmartControlEntry::Axis x;
                x.name = kNames[i];
                x.where = a.where();
                x.motor = a.required("motor", " (a motor record of this IOC)").string().value_or("");
                x.offset = a["offset"].number().value_or(0);
                x.sign = int(a["sign"].integer().value_or(1));
                if (x.sign != 1 && x.sign != -1) a["sign"].error("should be 1 or -1");
                x.low_cut = a["low_cut"].number().value_or(0);
                x.high_cut = a["high_cut"].number().value_or(0);
                if (x.low_cut > x.high_cut) a["low_cut"].error(SB() << "low_cut " << x.low_cut << " is above high_cut " << x.high_cut);
                else if (x.high_cut > x.low_cut && x.high_cut - x.low_cut < 360)
                    a["high_cut"].error(SB() << "the cut window " << x.low_cut << " .. " << x.high_cut
                                             << " should span at least 360 (every angle has a place in it), or none (equal cuts)");
                e.axes.push_back(std::move(x));
            }
            if (e.axes.empty()) ax.error("needs at least one of two_theta, omega, phi, kappa");
        }
        cfg.smart_control = e;
    }
    std::set<std::string> compound_names;
    for (YamlNode g : root["compound_motors"].list()) {
        if (!g.keys({"name", "reals", "inputs", "virtuals", "inverse"})) continue;
        CompoundMotorEntry e;
        e.where = g.where();
        e.name = g.required("name", " (the group's name)").string().value_or("");
        std::set<std::string> names; // every expression name of the group, once
        auto expr_name = [&](const YamlNode& at, const std::string& n) {
            bool ident = !n.empty() && (std::isalpha((unsigned char)n[0]) || n[0] == '_');
            for (char c : n) ident = ident && (std::isalnum((unsigned char)c) || c == '_');
            if (!ident) at.error(SB() << "'" << n << "' is not a name the expressions can use (letters, digits, _)");
            else if (!names.insert(n).second) at.error(SB() << "'" << n << "' is used twice in compound motor group '" << e.name << "'");
        };
        for (const char* key : {"reals", "inputs"}) {
            YamlNode m = std::string_view(key) == "reals" ? g.required(key, " (name: motor record PV)") : g[key];
            for (const auto& [n, v] : m.entries()) {
                expr_name(v, n);
                CompoundMotorEntry::Name x{n, v.string().value_or(""), v.where()};
                (std::string_view(key) == "reals" ? e.reals : e.inputs).push_back(x);
            }
        }
        for (const auto& [n, v] : g.required("virtuals", " (name: {forward, egu, prec, velocity})").entries()) {
            if (!v.keys({"forward", "egu", "prec", "velocity", "mres", "desc"})) continue;
            expr_name(v, n);
            check_name_part(v, n, "compound motor", compound_names, true);
            CompoundMotorEntry::Virtual x;
            x.name = n, x.where = v.where();
            x.forward = v.required("forward", " (an expression in the reals and inputs)").string().value_or("");
            x.egu = v["egu"].string().value_or("");
            x.desc = v["desc"].string().value_or("");
            x.prec = int(v["prec"].integer(between(0, 15)).value_or(3));
            x.velocity = v["velocity"].number(above(0)).value_or(1);
            x.mres = v["mres"].number(above(0)).value_or(0);
            e.virtuals.push_back(std::move(x));
        }
        for (const auto& [n, v] : g.required("inverse", " (real name: expression in the virtuals and inputs)").entries()) {
            bool real = false;
            for (const auto& r : e.reals) real = real || r.name == n;
            if (!real) v.error(SB() << "'" << n << "' is not one of the group's reals");
            e.inverse.emplace_back(n, v.string().value_or(""));
            e.inverse_where.push_back(v.where());
        }
        cfg.compound_motors.push_back(std::move(e));
    }
    std::set<std::string> fsm_names;
    for (YamlNode m : root["state_machines"].list()) {
        if (!m.keys({"name", "states", "initial", "latch", "after_ack", "names", "transitions"})) continue;
        StateMachineEntry e;
        e.where = m.where();
        e.name = m.required("name", " (its PVs are $(P)<name>:...)").string().value_or("");
        check_name_part(m["name"], e.name, "state machine", fsm_names, false);
        auto steps = [](const YamlNode& list, std::vector<StateMachineEntry::Step>& out) {
            for (YamlNode st : list.list()) {
                if (!st.keys({"put", "value", "wait", "timeout", "wait_for", "delay"})) continue;
                StateMachineEntry::Step x;
                x.where = st.where();
                const int kinds = st.has("put") + st.has("wait_for") + st.has("delay");
                if (kinds != 1) {
                    st.error("a step is one of put: PV (with value:), wait_for: expression, delay: seconds");
                    continue;
                }
                if (st.has("put")) {
                    x.kind = StateMachineEntry::Step::Kind::Put;
                    x.pv = st["put"].string().value_or("");
                    x.value = st.required("value", " (the number written)").number().value_or(0);
                    x.wait = st["wait"].boolean().value_or(true);
                    x.seconds = st["timeout"].number(above(0)).value_or(0);
                } else if (st.has("wait_for")) {
                    x.kind = StateMachineEntry::Step::Kind::WaitFor;
                    x.expr = st["wait_for"].string().value_or("");
                    x.seconds = st["timeout"].number(above(0)).value_or(0);
                } else {
                    x.kind = StateMachineEntry::Step::Kind::Delay;
                    x.seconds = st["delay"].number(between(0, 86400)).value_or(0);
                }
                out.push_back(std::move(x));
            }
        };
        std::set<std::string> states;
        for (const auto& [n, v] : m.required("states", " (name: {parent, invariant, entry, exit})").entries()) {
            if (!v.keys({"parent", "invariant", "entry", "exit"})) continue;
            StateMachineEntry::State x;
            x.name = n, x.where = v.where();
            if (n.empty() || n.size() > 25) v.error(SB() << "state name '" << n << "' should be 1 to 25 characters (an mbbi string)");
            check_name_part(v, n, "state", states, false);
            x.parent = v["parent"].string().value_or("");
            x.invariant = v["invariant"].string().value_or("");
            steps(v["entry"], x.entry);
            steps(v["exit"], x.exit);
            e.states.push_back(std::move(x));
        }
        if (e.states.size() > 16) m["states"].error(SB() << e.states.size() << " states; an mbbi shows at most 16");
        auto is_state = [&](const std::string& s) { return states.count(s) > 0; };
        for (const auto& x : e.states)
            if (!x.parent.empty() && (!is_state(x.parent) || x.parent == x.name))
                m["states"][x.name]["parent"].error(SB() << "'" << x.parent << "' is not another state of '" << e.name << "'");
        e.initial = m.required("initial", " (the state at start-up)").string().value_or("");
        if (!e.initial.empty() && !is_state(e.initial)) m["initial"].error(SB() << "'" << e.initial << "' is not a state of '" << e.name << "'");
        e.latch = m["latch"].string().value_or("");
        if (!e.latch.empty() && !is_state(e.latch)) m["latch"].error(SB() << "'" << e.latch << "' is not a state of '" << e.name << "'");
        e.after_ack = m["after_ack"].string().value_or(e.initial);
        if (m.has("after_ack") && !is_state(e.after_ack)) m["after_ack"].error(SB() << "'" << e.after_ack << "' is not a state of '" << e.name << "'");
        for (const auto& [n, v] : m["names"].entries()) {
            e.names.emplace_back(n, v.string().value_or(""));
            e.names_where.push_back(v.where());
        }
        for (YamlNode t : m["transitions"].list()) {
            if (!t.keys({"name", "from", "to", "guard", "steps", "timeout"})) continue;
            StateMachineEntry::Transition x;
            x.where = t.where();
            x.from = t.required("from", " (a state)").string().value_or("");
            x.to = t.required("to", " (a state)").string().value_or("");
            x.name = t["name"].string().value_or(x.from + "->" + x.to);
            for (const auto& [key, val] : {std::pair{"from", &x.from}, {"to", &x.to}})
                if (!val->empty() && !is_state(*val)) t[key].error(SB() << "'" << *val << "' is not a state of '" << e.name << "'");
            x.guard = t["guard"].string().value_or("");
            x.timeout = t["timeout"].number(above(0)).value_or(300);
            steps(t["steps"], x.steps);
            e.transitions.push_back(std::move(x));
        }
        cfg.state_machines.push_back(std::move(e));
    }
    if (YamlNode n = root["notify"];
        n.keys({"smtp", "webhooks", "rules", "min_interval", "dedup", "retries", "retry_interval", "timeout"}) && n) {
        NotifyEntry e;
        e.where = n.where();
        if (YamlNode sm = n["smtp"]; sm.keys({"host", "port", "from", "to"}) && sm) {
            e.smtp_host = sm.required("host", " (the mail server)").string().value_or("");
            e.smtp_port = int(sm["port"].integer(between(1, 65535)).value_or(25));
            e.from = sm["from"].string().value_or("beamctl");
            for (YamlNode t : sm.required("to", " (a list of addresses)").list()) e.to.push_back(t.string().value_or(""));
            if (e.to.empty()) sm["to"].error("needs at least one address");
        }
        for (YamlNode w : n["webhooks"].list()) {
            NotifyEntry::Webhook h;
            h.url = w.string().value_or("");
            const std::string scheme = "http://";
            std::string rest = h.url.rfind(scheme, 0) == 0 ? h.url.substr(scheme.size()) : "";
            const std::size_t slash = rest.find('/');
            std::string hostport = rest.substr(0, slash);
            h.path = slash == std::string::npos ? "/" : rest.substr(slash);
            const std::size_t colon = hostport.rfind(':');
            h.host = hostport.substr(0, colon);
            if (colon != std::string::npos) h.port = std::atoi(hostport.c_str() + colon + 1);
            if (rest.empty() || h.host.empty() || h.port <= 0 || h.port > 65535)
                w.error(SB() << "'" << h.url << "' should be http://host[:port]/path (https is not supported)");
            else
                e.webhooks.push_back(h);
        }
        for (YamlNode r : n.required("rules", " (a list of {state_machine: NAME} or {pv: NAME, severity: MAJOR})").list()) {
            if (!r.keys({"state_machine", "pv", "severity"})) continue;
            NotifyEntry::Rule x;
            x.where = r.where();
            x.state_machine = r["state_machine"].string().value_or("");
            x.pv = r["pv"].string().value_or("");
            const std::string sev = r["severity"].one_of({"MINOR", "MAJOR", "INVALID"}).value_or("MAJOR");
            x.severity = sev == "MINOR" ? 1 : sev == "INVALID" ? 3 : 2;
            if (x.state_machine.empty() == x.pv.empty()) r.error("a rule names one of state_machine: or pv:");
            else if (!x.state_machine.empty() && x.state_machine != "*") {
                bool known = false;
                for (const auto& m : cfg.state_machines) known = known || m.name == x.state_machine;
                if (!known) r["state_machine"].error(SB() << "'" << x.state_machine << "' is not one of state_machines:");
            }
            e.rules.push_back(std::move(x));
        }
        if (e.smtp_host.empty() && e.webhooks.empty()) n.error("needs smtp: or webhooks: (somewhere to send to)");
        e.min_interval_s = n["min_interval"].number(between(0, 86400)).value_or(60);
        e.dedup_s = n["dedup"].number(between(0, 864000)).value_or(600);
        e.retries = int(n["retries"].integer(between(0, 100)).value_or(3));
        e.retry_interval_s = n["retry_interval"].number(between(0, 3600)).value_or(10);
        e.timeout_s = n["timeout"].number(between(0.1, 120)).value_or(5);
        cfg.notify = e;
    }
    std::set<std::string> zone_names;
    for (YamlNode z : root["collision_zones"].list()) {
        if (!z.keys({"name", "axes", "forbidden", "lookahead"})) continue;
        CollisionZoneEntry e;
        e.where = z.where();
        e.name = z.required("name", " (its PVs are $(P)<name>:...)").string().value_or("");
        check_name_part(z["name"], e.name, "collision zone", zone_names, false);
        for (const auto& [n, v] : z.required("axes", " (name: motor record)").entries()) e.axes.emplace_back(n, v.string().value_or(""));
        if (e.axes.empty()) z["axes"].error("needs at least one axis");
        e.forbidden = z.required("forbidden", " (an expression, true inside the forbidden region)").string().value_or("");
        e.lookahead_s = z["lookahead"].number(between(0, 10)).value_or(0.2);
        cfg.collision_zones.push_back(std::move(e));
    }
    std::set<std::string> plan_names;
    for (YamlNode pl : root["plans"].list()) {
        if (!pl.keys({"name", "type", "desc", "args", "names", "axes", "points", "snake", "relative", "return", "dwell",
                      "detectors", "triggers", "signal", "motor", "center", "passes", "model", "sigma", "max_reduced_chi2",
                      "min_r_squared", "max_width", "latch", "steps", "directory"}))
            continue;
        PlanEntry e;
        e.where = pl.where();
        e.name = pl.required("name", " (its PVs are $(P)<name>:...)").string().value_or("");
        check_name_part(pl["name"], e.name, "plan", plan_names, false);
        const std::string type = pl.required("type", " (scan, grid, list, align or sequence)")
                                     .one_of({"scan", "grid", "list", "align", "sequence"}).value_or("scan");
        using T = PlanEntry::Type;
        e.type = type == "grid" ? T::Grid : type == "list" ? T::List : type == "align" ? T::Align : type == "sequence" ? T::Sequence : T::Scan;
        e.desc = pl["desc"].string().value_or("");
        auto expr = [](const YamlNode& n, const std::string& fallback) { return n ? n.string().value_or(fallback) : fallback; };
        for (const auto& [n, v] : pl["args"].entries()) {
            if (n.empty() || !(std::isalpha(static_cast<unsigned char>(n[0])) || n[0] == '_') ||
                n.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") != std::string::npos)
                v.error(SB() << "argument '" << n << "' should be a name (letters, digits, _)");
            e.args.emplace_back(n, v.number().value_or(0));
        }
        for (const auto& [n, v] : pl["names"].entries()) e.names.emplace_back(n, v.string().value_or(""));
        e.relative = pl["relative"].boolean().value_or(false);
        if (pl.has("return")) e.return_to_start = pl["return"].boolean().value_or(false);
        e.dwell = expr(pl["dwell"], "0");
        for (const auto& [n, v] : pl["detectors"].entries()) e.detectors.emplace_back(n, v.string().value_or(""));
        for (const auto& [n, v] : pl["triggers"].entries()) e.triggers.emplace_back(n, v.number().value_or(0));
        e.signal = pl["signal"].string().value_or("");
        e.directory = pl["directory"].string().value_or("/tmp");
        const bool stepping = e.type == T::Scan || e.type == T::Grid || e.type == T::List;
        if (stepping) {
            for (YamlNode a : pl.required("axes", " (a list of {motor, start, stop} / {motor, positions})").list()) {
                if (!a.keys({"motor", "start", "stop", "points", "positions"})) continue;
                PlanEntry::Axis x;
                x.where = a.where();
                x.motor = a.required("motor", " (a motor record)").string().value_or("");
                if (e.type == T::List) {
                    for (YamlNode p : a.required("positions", " (a list of positions)").list()) x.positions.push_back(p.string().value_or("0"));
                    if (a.has("start") || a.has("stop") || a.has("points")) a.error("a list plan's axis has positions:, not start/stop/points");
                } else {
                    x.start = expr(a.required("start", " (a position, or relative with relative: true)"), "0");
                    x.stop = expr(a.required("stop", ""), "0");
                    if (e.type == T::Grid) x.points = expr(a.required("points", " (this axis's points)"), "2");
                    else if (a.has("points")) a["points"].error("a scan's points: is the plan's (all its axes move together)");
                    if (a.has("positions")) a["positions"].error("positions: is for a list plan");
                }
                e.axes.push_back(std::move(x));
            }
            if (e.type == T::Scan) e.points = expr(pl.required("points", " (points of the scan)"), "2");
            if (e.type == T::List && !e.axes.empty()) {
                for (const auto& x : e.axes)
                    if (x.positions.size() != e.axes[0].positions.size() || x.positions.empty())
                        pl["axes"].error("every axis of a list plan needs the same (nonzero) number of positions");
            }
            e.snake = pl["snake"].boolean().value_or(false);
            if (e.snake && e.type != T::Grid) pl["snake"].error("snake: is for a grid plan");
        }
        if (e.type == T::Align) {
            e.motor = pl.required("motor", " (the motor aligned)").string().value_or("");
            e.center = pl["center"].string().value_or("");
            for (YamlNode p : pl.required("passes", " (a list of {range, points}: coarse to fine)").list()) {
                if (!p.keys({"range", "points"})) continue;
                PlanEntry::Pass x;
                x.where = p.where();
                x.range = expr(p.required("range", " (the scan's full width)"), "0");
                x.points = expr(p.required("points", ""), "2");
                e.passes.push_back(std::move(x));
            }
            e.model = pl["model"].one_of({"lorentzian", "gaussian", "edge"}).value_or("lorentzian");
            e.sigma = pl["sigma"].string().value_or("");
            e.max_reduced_chi2 = pl["max_reduced_chi2"].number(above(0)).value_or(0);
            e.min_r_squared = pl["min_r_squared"].number(between(0, 1)).value_or(0);
            e.max_width = pl["max_width"].number(above(0)).value_or(0);
            if (e.max_reduced_chi2 > 0 && e.sigma.empty())
                pl["max_reduced_chi2"].error("needs sigma: (a point's standard deviation), else chi^2 is in the signal's units squared");
            e.latch = pl["latch"].string().value_or("");
            if (!e.latch.empty()) {
                bool known = false;
                for (const auto& m : cfg.state_machines) known = known || m.name == e.latch;
                if (!known) pl["latch"].error(SB() << "'" << e.latch << "' is not one of state_machines:");
            }
        } else {
            for (const char* k : {"motor", "center", "passes", "model", "sigma", "max_reduced_chi2", "min_r_squared", "max_width", "latch"})
                if (pl.has(k)) pl[k].error(SB() << k << ": is for an align plan");
        }
        if (stepping || e.type == T::Align) {
            if (e.detectors.empty()) pl.required("detectors", " (name: PV, read at each point)");
        } else {
            for (const char* k : {"axes", "points", "detectors", "triggers", "signal", "dwell", "relative", "return"})
                if (pl.has(k)) pl[k].error(SB() << k << ": is for a scan, grid, list or align plan");
        }
        if (e.type == T::Sequence) {
            for (YamlNode st : pl.required("steps", " (a list of {plan: NAME, args}, {move: {MOTOR: POSITION}}, {put: PV, value})").list()) {
                if (!st.keys({"plan", "args", "move", "put", "value", "wait"})) continue;
                PlanEntry::Step x;
                x.where = st.where();
                const int kinds = st.has("plan") + st.has("move") + st.has("put");
                if (kinds != 1) {
                    st.error("a step is one of plan: NAME (with args:), move: {MOTOR: POSITION}, put: PV (with value:)");
                    continue;
                }
                using K = PlanEntry::Step::Kind;
                if (st.has("plan")) {
                    x.kind = K::Plan;
                    x.plan = st["plan"].string().value_or("");
                    for (const auto& [n, v] : st["args"].entries()) x.args.emplace_back(n, v.string().value_or("0"));
                    const PlanEntry* target = nullptr;
                    for (const auto& q : cfg.plans) target = q.name == x.plan ? &q : target;
                    if (!target) st["plan"].error(SB() << "'" << x.plan << "' is not a plan defined above this one");
                    else if (target->type == T::Sequence) st["plan"].error(SB() << "'" << x.plan << "' is a sequence (a step runs a scan, grid, list or align plan)");
                    else
                        for (const auto& [n, v] : x.args) {
                            bool known = false;
                            for (const auto& a : target->args) known = known || a.first == n;
                            if (!known) st["args"][n].error(SB() << "'" << x.plan << "' has no argument '" << n << "'");
                        }
                } else if (st.has("move")) {
                    x.kind = K::Move;
                    for (const auto& [n, v] : st["move"].entries()) x.moves.emplace_back(n, v.string().value_or("0"));
                    if (x.moves.empty()) st["move"].error("needs at least one MOTOR: POSITION");
                } else {
                    x.kind = K::Put;
                    x.pv = st["put"].string().value_or("");
                    x.value = expr(st.required("value", " (the number written)"), "0");
                    x.wait = st["wait"].boolean().value_or(true);
                }
                e.steps.push_back(std::move(x));
            }
        }
        cfg.plans.push_back(std::move(e));
    }
    rd.take_errors(errors);
    return cfg;
}

std::vector<std::pair<int, std::string>> positions_and_types(const BusConfig& bc) {
    std::vector<std::pair<int, std::string>> v;
    for (const auto& s : bc.slaves) v.emplace_back(s.position, s.type);
    return v;
}

} // namespace beamctl::config
