// A BridgeCore on a fresh Database in virtual time, with its outgoing packets captured, and
// helpers to build beacons and data packets and to read PVs. Shared by the RCP bridge tests.
#pragma once

#include "bridge/rcp/bridge_core.hpp"
#include "bridge/rcp/protocol.hpp"
#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::bridge::rcp::test {

inline constexpr uint32_t kRcpIp = 0x0A000002; // 10.0.0.2
inline constexpr Endpoint kRcp{kRcpIp, 5000};  // where its beacons and data come from

inline BeaconObject obj(uint8_t id, ObjectType t, DataType d, std::string name,
                        uint16_t port_rcp = 18066) {
    BeaconObject b;
    b.id = id;
    b.type = t;
    b.data_type = d;
    b.ip_rcp = kRcpIp;
    b.port_rcp = port_rcp;
    b.ip_ioc = 0x0A000001;
    b.port_ioc = kDefaultPort;
    b.name = std::move(name);
    return b;
}

inline Packet beacon(const std::string& app, const std::vector<BeaconObject>& objs,
                     bool continuation = false, double ts = 1.0) {
    Packet p;
    WriteResult r = write_beacon(p, ts, app, continuation, objs);
    EXPECT_TRUE(r.ok()) << to_string(r.status);
    return p;
}

// One entry of a data packet under construction (owns its values).
struct Entry {
    uint8_t id;
    ObjectType type;
    DataType dt;
    std::string name;
    std::vector<double> v;
};

inline Packet data(const std::vector<Entry>& es, double ts = 2.0) {
    std::vector<DataEntry> d;
    for (const Entry& e : es)
        d.push_back(DataEntry{e.id, e.type, e.dt, uint16_t(e.v.size()), e.name,
                              std::span<const double>(e.v)});
    Packet p;
    WriteResult r = write_data(p, ts, d);
    EXPECT_TRUE(r.ok()) << to_string(r.status);
    return p;
}

struct Sent {
    Endpoint to;
    std::vector<uint8_t> bytes;
};

struct Harness {
    pv::Database db;
    double t = 100; // [s] virtual monotonic time
    std::vector<Sent> sent;
    bool send_ok = true;
    std::unique_ptr<BridgeCore> core;

    static BridgeConfig config() {
        BridgeConfig c;
        c.prefix = "T:";
        c.allow = {"10.0.0.0/8", "127.0.0.0/8"}; // the test machines (loopback only by default)
        return c;
    }
    explicit Harness(BridgeConfig cfg = config()) {
        core = std::make_unique<BridgeCore>(
            db, std::move(cfg),
            [this](const Endpoint& to, std::span<const uint8_t> p) {
                sent.push_back(Sent{to, std::vector<uint8_t>(p.begin(), p.end())});
                return send_ok;
            },
            [this] { return t; });
    }
    void feed(const Packet& p, Endpoint from = kRcp) {
        core->handle_packet(std::span<const uint8_t>(p), from, t);
    }
    void feed_bytes(const std::vector<uint8_t>& p, Endpoint from = kRcp) {
        core->handle_packet(std::span<const uint8_t>(p), from, t);
    }
    void advance(double dt) {
        t += dt;
        core->tick(t);
    }
    // A beacon and the end of its continuation window.
    void announce(const std::string& app, const std::vector<BeaconObject>& objs,
                  Endpoint from = kRcp) {
        feed(beacon(app, objs), from);
        advance(0.15);
    }

    pv::Address addr(const std::string& ch) {
        pv::Address a;
        std::string why;
        EXPECT_TRUE(db.resolve(ch, a, &why)) << ch << ": " << why;
        return a;
    }
    bool exists(const std::string& rec) { return db.find(rec) != nullptr; }
    double get(const std::string& ch) {
        double v = NAN;
        pv::Address a;
        if (!db.resolve(ch, a)) {
            ADD_FAILURE() << "no channel " << ch;
            return v;
        }
        db.get(a, pv::Prim::Double, &v, 1);
        return v;
    }
    std::vector<double> get_array(const std::string& ch) {
        pv::Address a = addr(ch);
        std::vector<double> v(a.count);
        uint32_t n = db.get(a, pv::Prim::Double, v.data(), a.count);
        v.resize(n);
        return v;
    }
    std::string str(const std::string& ch) {
        char s[40] = {};
        pv::Address a;
        if (!db.resolve(ch, a)) {
            ADD_FAILURE() << "no channel " << ch;
            return "";
        }
        db.get(a, pv::Prim::String, s, 1);
        return s;
    }
    std::string type(const std::string& rec) {
        pv::Record* r = db.find(rec);
        return r ? r->type().name() : "<none>";
    }
    std::string alarm(const std::string& rec) {
        return str(rec + ".SEVR") + "/" + str(rec + ".STAT");
    }
    pv::PutStatus put(const std::string& ch, double v, pv::PutCallback cb = {}) {
        return db.put(addr(ch), pv::Prim::Double, &v, 1, std::move(cb));
    }
    // Parses the i-th sent packet as data.
    const DataEntry& sent_entry(std::size_t i, DataPacket& d, std::size_t entry = 0) {
        static DataEntry none;
        if (i >= sent.size()) {
            ADD_FAILURE() << "only " << sent.size() << " packets sent";
            return none;
        }
        ParseResult r = parse_data(std::span<const uint8_t>(sent[i].bytes), d);
        EXPECT_TRUE(r.ok()) << to_string(r.reason) << " at " << r.offset;
        if (!r || entry >= d.entry_count) {
            ADD_FAILURE() << "no entry " << entry;
            return none;
        }
        return d.entries[entry];
    }
};

} // namespace beamctl::bridge::rcp::test
