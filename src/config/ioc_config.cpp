#include "config/ioc_config.hpp"

#include "core/error.hpp"

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace beamctl::config {
namespace {

struct Ctx {
    std::string file;
    std::string dir;
    std::string at(const YAML::Node& n) const {
        return SB() << file << ":" << n.Mark().line + 1 << ":" << n.Mark().column + 1;
    }
    std::string resolve(const std::string& p) const {
        if (p.empty() || p[0] == '/') return p;
        return (std::filesystem::path(dir) / p).lexically_normal().string();
    }
};

void only_keys(const Ctx& c, const YAML::Node& map, const std::string& where,
               std::initializer_list<const char*> keys) {
    if (!map.IsMap()) throw Error(SB() << c.at(map) << ": " << where << " should be a mapping");
    for (auto kv : map) {
        std::string k = kv.first.as<std::string>();
        bool ok = false;
        for (const char* want : keys) ok = ok || k == want;
        if (!ok) {
            SB sb;
            sb << c.at(kv.first) << ": unknown key '" << k << "' in " << where << " (expected:";
            for (const char* want : keys) sb << " " << want;
            throw Error(sb << ")");
        }
    }
}

template <typename T> T get(const Ctx& c, const YAML::Node& n, const std::string& what) {
    try {
        return n.as<T>();
    } catch (const YAML::Exception&) {
        throw Error(SB() << c.at(n) << ": " << what << ": '" << (n.IsScalar() ? n.Scalar() : std::string("<not a scalar>"))
                         << "' is not a valid " << (std::is_same_v<T, std::string> ? "string" : "number"));
    }
}

uint64_t get_uint(const Ctx& c, const YAML::Node& n, const std::string& what, uint64_t max) {
    std::string s = get<std::string>(c, n, what);
    char* end = nullptr;
    errno = 0;
    unsigned long long v = std::strtoull(s.c_str(), &end, 0);
    if (s.empty() || *end || errno || s[0] == '-' || v > max)
        throw Error(SB() << c.at(n) << ": " << what << ": '" << s << "' should be an integer from 0 to " << max);
    return v;
}

} // namespace

IocConfig IocConfig::load(const std::string& path) {
    std::ifstream f(path);
    if (!f) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), path);
}

IocConfig IocConfig::parse(const std::string& text, const std::string& path) {
    Ctx c{path, std::filesystem::path(path).parent_path().string()};
    if (c.dir.empty()) c.dir = ".";
    YAML::Node root;
    try {
        root = YAML::Load(text);
    } catch (const YAML::ParserException& e) {
        throw Error(SB() << path << ":" << e.mark.line + 1 << ":" << e.mark.column + 1 << ": " << e.msg);
    }
    IocConfig cfg;
    cfg.path = path;
    if (!root || root.IsNull()) throw Error(SB() << path << ":1:1: empty configuration (needs at least ioc:)");
    for (auto kv : root) {
        std::string k = kv.first.as<std::string>();
        if (k == "web")
            throw Error(SB() << c.at(kv.first) << ": '" << k
                             << "' is not supported by this version of beamctl yet");
    }
    only_keys(c, root, "the IOC file", {"ioc", "engine", "buses", "axes", "plugins", "plcs", "db", "bridges", "ca"});
    if (!root["ioc"]) throw Error(SB() << path << ":1:1: missing required key 'ioc' ({name: ..., prefix: ...})");
    {
        auto n = root["ioc"];
        only_keys(c, n, "ioc", {"name", "prefix"});
        if (!n["name"]) throw Error(SB() << c.at(n) << ": ioc: missing required key 'name'");
        cfg.name = get<std::string>(c, n["name"], "ioc.name");
        if (cfg.name.empty() || cfg.name.find_first_of(" .$\"'") != std::string::npos)
            throw Error(SB() << c.at(n["name"]) << ": ioc.name '" << cfg.name << "' should be a plain PV name part");
        cfg.prefix = n["prefix"] ? get<std::string>(c, n["prefix"], "ioc.prefix") : cfg.name + ":";
    }
    if (auto n = root["engine"]) {
        only_keys(c, n, "engine", {"rate_hz", "cpu", "priority"});
        if (n["rate_hz"]) {
            cfg.rate_hz = get<double>(c, n["rate_hz"], "engine.rate_hz");
            if (!(cfg.rate_hz >= 1 && cfg.rate_hz <= 20000))
                throw Error(SB() << c.at(n["rate_hz"]) << ": engine.rate_hz: " << cfg.rate_hz
                                 << " should be between 1 and 20000");
        }
        if (n["cpu"]) cfg.cpu = int(get_uint(c, n["cpu"], "engine.cpu", 1023));
        if (n["priority"]) cfg.priority = int(get_uint(c, n["priority"], "engine.priority", 99));
    }
    if (auto buses = root["buses"]) {
        if (!buses.IsSequence()) throw Error(SB() << c.at(buses) << ": buses should be a list");
        std::set<int> ids;
        for (std::size_t i = 0; i < buses.size(); ++i) {
            auto b = buses[i];
            std::string where = SB() << "buses[" << i << "]";
            only_keys(c, b, where, {"id", "link", "slaves"});
            BusConfig bc;
            bc.id = b["id"] ? int(get_uint(c, b["id"], where + ".id", 15)) : int(i);
            if (!ids.insert(bc.id).second) throw Error(SB() << c.at(b) << ": " << where << ": bus id " << bc.id << " used twice");
            if (auto l = b["link"]) {
                only_keys(c, l, where + ".link", {"type", "plant", "host", "port", "iface", "busy_poll"});
                if (!l["type"]) throw Error(SB() << c.at(l) << ": " << where << ".link: missing 'type' (sim, udp or raw)");
                bc.link.type = get<std::string>(c, l["type"], where + ".link.type");
                if (bc.link.type != "sim" && bc.link.type != "udp" && bc.link.type != "raw")
                    throw Error(SB() << c.at(l["type"]) << ": " << where << ".link.type: '" << bc.link.type
                                     << "' should be sim, udp or raw");
                if (l["plant"]) bc.link.plant = c.resolve(get<std::string>(c, l["plant"], where + ".link.plant"));
                if (l["host"]) bc.link.host = get<std::string>(c, l["host"], where + ".link.host");
                if (l["port"]) bc.link.port = uint16_t(get_uint(c, l["port"], where + ".link.port", 65535));
                if (l["iface"]) bc.link.iface = get<std::string>(c, l["iface"], where + ".link.iface");
                if (auto bp = l["busy_poll"]) {
                    bool v = false;
                    if (!bp.IsScalar() || !YAML::convert<bool>::decode(bp, v))
                        throw Error(SB() << c.at(bp) << ": " << where << ".link.busy_poll: should be true or false");
                    bc.link.busy_poll = v;
                }
                if (bc.link.type == "raw" && bc.link.iface.empty())
                    throw Error(SB() << c.at(l) << ": " << where
                                     << ".link: a raw link needs 'iface' (the network interface of the segment)");
            }
            auto slaves = b["slaves"];
            if (!slaves || !slaves.IsSequence())
                throw Error(SB() << c.at(b) << ": " << where << ": 'slaves' should be a list of {position, type}");
            std::set<int> positions;
            for (std::size_t k = 0; k < slaves.size(); ++k) {
                auto s = slaves[k];
                std::string sw = SB() << where << ".slaves[" << k << "]";
                only_keys(c, s, sw, {"position", "type", "sdo"});
                if (!s["position"] || !s["type"])
                    throw Error(SB() << c.at(s) << ": " << sw << ": needs position and type");
                SlaveEntry se;
                se.position = int(get_uint(c, s["position"], sw + ".position", 65534));
                se.type = get<std::string>(c, s["type"], sw + ".type");
                if (!positions.insert(se.position).second)
                    throw Error(SB() << c.at(s["position"]) << ": " << sw << ": position " << se.position << " used twice");
                if (auto sdos = s["sdo"]) {
                    if (!sdos.IsSequence()) throw Error(SB() << c.at(sdos) << ": " << sw << ".sdo should be a list");
                    for (std::size_t q = 0; q < sdos.size(); ++q) {
                        auto d = sdos[q];
                        std::string dw = SB() << sw << ".sdo[" << q << "]";
                        only_keys(c, d, dw, {"index", "sub", "value", "size"});
                        if (!d["index"] || !d["value"]) throw Error(SB() << c.at(d) << ": " << dw << ": needs index and value");
                        SdoConfig sc;
                        sc.index = uint16_t(get_uint(c, d["index"], dw + ".index", 0xFFFF));
                        sc.sub = d["sub"] ? uint8_t(get_uint(c, d["sub"], dw + ".sub", 255)) : 0;
                        sc.size = d["size"] ? uint8_t(get_uint(c, d["size"], dw + ".size", 8)) : 4;
                        if (sc.size != 1 && sc.size != 2 && sc.size != 4 && sc.size != 8)
                            throw Error(SB() << c.at(d["size"]) << ": " << dw << ".size: " << int(sc.size) << " should be 1, 2, 4 or 8");
                        sc.value = get_uint(c, d["value"], dw + ".value",
                                            sc.size == 8 ? UINT64_MAX : (uint64_t(1) << (8 * sc.size)) - 1);
                        se.sdo.push_back(sc);
                    }
                }
                bc.slaves.push_back(se);
            }
            cfg.buses.push_back(bc);
        }
    }
    auto macros = [&](const YAML::Node& m, const std::string& where) {
        MacroMap mm;
        if (!m) return mm;
        if (!m.IsMap()) throw Error(SB() << c.at(m) << ": " << where << ".macros should be a mapping");
        for (auto kv : m) mm[kv.first.as<std::string>()] = get<std::string>(c, kv.second, where + ".macros");
        return mm;
    };
    if (auto axes = root["axes"]) {
        if (!axes.IsSequence()) throw Error(SB() << c.at(axes) << ": axes should be a list of {file, macros}");
        for (std::size_t i = 0; i < axes.size(); ++i) {
            auto a = axes[i];
            std::string where = SB() << "axes[" << i << "]";
            only_keys(c, a, where, {"file", "macros", "encoders"});
            if (!a["file"]) throw Error(SB() << c.at(a) << ": " << where << ": missing 'file' (an ECMC axis YAML file)");
            AxisEntry e;
            e.file = c.resolve(get<std::string>(c, a["file"], where + ".file"));
            e.macros = macros(a["macros"], where);
            e.where = c.at(a);
            if (auto encs = a["encoders"]) {
                if (!encs.IsSequence()) throw Error(SB() << c.at(encs) << ": " << where << ".encoders should be a list of {file, macros}");
                for (std::size_t k = 0; k < encs.size(); ++k) {
                    std::string ew = SB() << where << ".encoders[" << k << "]";
                    only_keys(c, encs[k], ew, {"file", "macros"});
                    if (!encs[k]["file"]) throw Error(SB() << c.at(encs[k]) << ": " << ew << ": missing 'file'");
                    e.encoders.push_back({c.resolve(get<std::string>(c, encs[k]["file"], ew + ".file")), macros(encs[k]["macros"], ew)});
                }
            }
            cfg.axes.push_back(std::move(e));
        }
    }
    if (auto plugins = root["plugins"]) {
        if (!plugins.IsSequence()) throw Error(SB() << c.at(plugins) << ": plugins should be a list of {file, config}");
        for (std::size_t i = 0; i < plugins.size(); ++i) {
            auto p = plugins[i];
            std::string where = SB() << "plugins[" << i << "]";
            only_keys(c, p, where, {"file", "config"});
            if (!p["file"]) throw Error(SB() << c.at(p) << ": " << where << ": missing 'file' (a plugin shared library)");
            PluginEntry e;
            e.file = c.resolve(get<std::string>(c, p["file"], where + ".file"));
            if (p["config"]) e.config = get<std::string>(c, p["config"], where + ".config");
            e.where = c.at(p);
            cfg.plugins.push_back(std::move(e));
        }
    }
    if (auto plcs = root["plcs"]) {
        if (!plcs.IsSequence()) throw Error(SB() << c.at(plcs) << ": plcs should be a list of {id, file, rate_ms, macros}");
        std::set<int> ids;
        for (std::size_t i = 0; i < plcs.size(); ++i) {
            auto p = plcs[i];
            std::string where = SB() << "plcs[" << i << "]";
            only_keys(c, p, where, {"id", "file", "rate_ms", "enable", "macros", "include", "libraries"});
            if (!p["file"]) throw Error(SB() << c.at(p) << ": " << where << ": missing 'file' (a PLC file in ECMC's language)");
            PlcEntry e;
            e.id = p["id"] ? int(get_uint(c, p["id"], where + ".id", 99)) : int(i);
            if (!ids.insert(e.id).second) throw Error(SB() << c.at(p) << ": " << where << ": PLC id " << e.id << " used twice");
            e.file = c.resolve(get<std::string>(c, p["file"], where + ".file"));
            if (auto r = p["rate_ms"]) {
                e.rate_ms = get<double>(c, r, where + ".rate_ms");
                if (!(e.rate_ms > 0 || e.rate_ms == -1))
                    throw Error(SB() << c.at(r) << ": " << where << ".rate_ms: " << e.rate_ms << " should be > 0, or -1 (every cycle)");
            }
            if (auto en = p["enable"]) {
                bool v = true;
                if (!en.IsScalar() || !YAML::convert<bool>::decode(en, v))
                    throw Error(SB() << c.at(en) << ": " << where << ".enable: should be true or false");
                e.enable = v;
            }
            e.macros = macros(p["macros"], where);
            auto list = [&](const char* key, std::vector<std::string>& out) {
                auto l = p[key];
                if (!l) return;
                if (!l.IsSequence()) throw Error(SB() << c.at(l) << ": " << where << "." << key << " should be a list");
                for (std::size_t k = 0; k < l.size(); ++k) out.push_back(c.resolve(get<std::string>(c, l[k], where + "." + key)));
            };
            list("include", e.include);
            list("libraries", e.libraries);
            e.where = c.at(p);
            cfg.plcs.push_back(std::move(e));
        }
    }
    if (auto dbs = root["db"]) {
        if (!dbs.IsSequence()) throw Error(SB() << c.at(dbs) << ": db should be a list of {file, macros}");
        for (std::size_t i = 0; i < dbs.size(); ++i) {
            auto d = dbs[i];
            std::string where = SB() << "db[" << i << "]";
            only_keys(c, d, where, {"file", "macros"});
            if (!d["file"]) throw Error(SB() << c.at(d) << ": " << where << ": missing 'file'");
            DbConfig dc;
            dc.file = c.resolve(get<std::string>(c, d["file"], where + ".file"));
            if (auto m = d["macros"]) {
                if (!m.IsMap()) throw Error(SB() << c.at(m) << ": " << where << ".macros should be a mapping");
                for (auto kv : m) dc.macros[kv.first.as<std::string>()] = get<std::string>(c, kv.second, where + ".macros");
            }
            cfg.db.push_back(dc);
        }
    }
    if (auto bridges = root["bridges"]) {
        only_keys(c, bridges, "bridges", {"rcp"});
        if (auto r = bridges["rcp"]) {
            only_keys(c, r, "bridges.rcp", {"listen", "port", "prefix", "timeout_s", "db_out", "pv_pattern", "motor_fields"});
            RcpBridgeEntry e;
            e.prefix = cfg.prefix + "RCP:";
            if (r["listen"]) e.listen = get<std::string>(c, r["listen"], "bridges.rcp.listen");
            if (r["port"]) e.port = uint16_t(get_uint(c, r["port"], "bridges.rcp.port", 65535));
            if (r["prefix"]) e.prefix = get<std::string>(c, r["prefix"], "bridges.rcp.prefix");
            if (auto t = r["timeout_s"]) {
                e.timeout_s = get<double>(c, t, "bridges.rcp.timeout_s");
                if (!(e.timeout_s > 0 && e.timeout_s <= 3600))
                    throw Error(SB() << c.at(t) << ": bridges.rcp.timeout_s: " << e.timeout_s << " should be > 0 and <= 3600");
            }
            if (r["db_out"]) e.db_out = c.resolve(get<std::string>(c, r["db_out"], "bridges.rcp.db_out"));
            if (r["pv_pattern"]) e.pv_pattern = get<std::string>(c, r["pv_pattern"], "bridges.rcp.pv_pattern");
            if (auto m = r["motor_fields"]) {
                if (!m.IsMap()) throw Error(SB() << c.at(m) << ": bridges.rcp.motor_fields should be a mapping of motor record fields, e.g. {DHLM: 45, DLLM: -45}");
                for (auto kv : m) e.motor_fields.emplace_back(kv.first.as<std::string>(), get<std::string>(c, kv.second, "bridges.rcp.motor_fields"));
            }
            e.where = c.at(r);
            cfg.rcp = e;
        }
    }
    if (auto ca = root["ca"]) {
        only_keys(c, ca, "ca", {"port", "acf"});
        if (ca["port"]) cfg.ca_port = uint16_t(get_uint(c, ca["port"], "ca.port", 65535));
        if (ca["acf"]) cfg.acf = c.resolve(get<std::string>(c, ca["acf"], "ca.acf"));
    }
    return cfg;
}

} // namespace beamctl::config
