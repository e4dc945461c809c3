// The IOC configuration file (`beamctl run ioc.yaml`, ARCHITECTURE.md §4) as typed structs.
// Every error names file:line:col and the key; unknown keys are errors; files it references
// are resolved relative to it.
#pragma once

#include "core/macros.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace beamctl::config {

struct SdoConfig {
    uint16_t index = 0;
    uint8_t sub = 0;
    uint64_t value = 0;
    uint8_t size = 4; // bytes: 1, 2, 4 or 8
};

struct SlaveEntry {
    int position = 0;
    std::string type;
    std::vector<SdoConfig> sdo;
};

struct LinkConfig {
    std::string type = "sim"; // sim | udp | raw
    std::string plant;        // sim: simulator file (wiring, plants), resolved path; may be empty
    std::string host = "127.0.0.1";
    uint16_t port = 0x88A4;   // udp
    std::string iface;        // raw: network interface of the segment
    bool busy_poll = false;   // raw: spin in receive instead of sleeping (no wake-up latency)
};

struct BusConfig {
    int id = 0;
    LinkConfig link;
    std::vector<SlaveEntry> slaves;
};

struct DbConfig {
    std::string file; // resolved path
    MacroMap macros;
};

// An ECMC axis file with its macros (ecmccfg loadYamlAxis.cmd), and extra encoder files
// (loadYamlEnc.cmd).
struct AxisEntry {
    std::string file; // resolved path
    MacroMap macros;
    struct Encoder {
        std::string file;
        MacroMap macros;
    };
    std::vector<Encoder> encoders;
    std::string where; // file:line:col of the entry in the IOC file
};

// A PLC file (ecmccfg loadPLCFile.cmd): `plcs: [{id, file, rate_ms, enable, macros, include,
// libraries}]`.
struct PlcEntry {
    int id = 0;              // plc<id>, PV PLC<id as 2 digits>-...
    std::string file;        // resolved path
    double rate_ms = -1;     // scan period [ms]; -1 = every cycle
    bool enable = true;
    MacroMap macros;
    std::vector<std::string> include;   // resolved directories searched by `include`
    std::vector<std::string> libraries; // resolved files of `function` definitions
    std::string where;       // file:line:col of the entry
};

// A plugin (include/beamctl/plugin.h): `plugins: [{file, config}]`.
struct PluginEntry {
    std::string file; // resolved path
    std::string config;
    std::string where;
};

// The UDP bridge to rapid-control-prototyping machines (`bridges: rcp:`; docs/rcp.md).
struct RcpBridgeEntry {
    std::string listen = "0.0.0.0"; // IPv4 address the bridge's sockets bind to
    uint16_t port = 18065;          // beacon port (data is accepted on it too)
    std::string prefix;             // PV prefix; default: the IOC prefix + "RCP:"
    double timeout_s = 3;           // [s] silence before an application's PVs go INVALID/COMM
    std::string db_out;             // resolved path of the generated .db file; empty: none
    std::string pv_pattern;         // object PV names; empty: "<prefix><application>:<name>"
    // Fields of every generated motor record, added to (or replacing) the bridge's defaults,
    // e.g. {DHLM: 45, DLLM: -45}: the protocol does not carry limits.
    std::vector<std::pair<std::string, std::string>> motor_fields;
    std::string where;
};

struct IocConfig {
    std::string path; // the file itself
    std::string name = "IOC";
    std::string prefix; // "NAME:" unless given
    double rate_hz = 1000;
    int cpu = -1;
    int priority = 80;
    std::vector<BusConfig> buses;
    std::vector<AxisEntry> axes;
    std::vector<PluginEntry> plugins;
    std::vector<PlcEntry> plcs;
    std::vector<DbConfig> db;
    std::optional<RcpBridgeEntry> rcp;
    std::optional<uint16_t> ca_port; // default: EPICS_CAS_SERVER_PORT / 5064
    std::string acf;                 // resolved path

    static IocConfig load(const std::string& path);
    static IocConfig parse(const std::string& text, const std::string& path);
};

} // namespace beamctl::config
