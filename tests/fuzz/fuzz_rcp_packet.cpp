// libFuzzer: arbitrary datagrams into the RCP packet parsers and into the bridge's packet
// handler (a BridgeCore on a fresh database that already knows one application).
//
// The input is used twice. (1) Whole, by parse_data and parse_beacon: a refusal must point inside
// the packet; what is accepted must re-encode and parse to the same content. (2) As chunks of
// [control byte][up to 1000 packet bytes] fed to the bridge in virtual time. Control byte:
//   bit 0: send the bytes as they are (else zero-padded to 1000: most are then well sized)
//   bits 1-2: source endpoint (0: the known application's, 1: its address, another port,
//             2: another address, 3: the application's address, a third port)
//   bit 4: +0.07 s before the packet (inside a beacon's continuation window)
//   bit 5: +1.5 s and tick before the packet (silence builds up)
//   bit 6: after the packet, write to an output PV and the motor (value from the control byte)
//   bit 7: from a stranger's address instead (refused: not a configured machine or network)
// The bridge is configured as on a shared network (issue 19): the application's machine by name
// and address, one more allowed network, and small caps on applications, objects and model
// changes, so that fuzzed beacons reach every refusal path. Every packet the bridge sends must
// parse as a data packet, and go to the address of a machine it heard from.
#include "bridge/rcp/bridge_core.hpp"
#include "bridge/rcp/protocol.hpp"
#include "core/log.hpp"
#include "pv/database.hpp"

#include <algorithm>
#include <cstring>
#include <vector>

using namespace beamctl;
using namespace beamctl::bridge::rcp;

namespace {

const Endpoint kSources[4] = {
    {0x0A000002, 5000}, {0x0A000002, 6000}, {0x0A000009, 5000}, {0x0A000002, 7000}};

Packet known_beacon() {
    auto o = [](uint8_t id, ObjectType t, DataType d, const char* name) {
        return BeaconObject{id, t, d, 0x0A000002, 18066, 0x0A000001, 18065, name};
    };
    const BeaconObject objs[] = {o(1, ObjectType::AI, DataType::Float64, "a"),
                                 o(2, ObjectType::AO, DataType::Float32, "b"),
                                 o(3, ObjectType::BI, DataType::Bool, "c"),
                                 o(4, ObjectType::BO, DataType::Bool, "d"),
                                 o(5, ObjectType::LI, DataType::Int16, "e"),
                                 o(6, ObjectType::LO, DataType::UInt8, "f"),
                                 o(7, ObjectType::Motor, DataType::Float64, "m"),
                                 o(8, ObjectType::AI, DataType::Int32, "w")};
    Packet p;
    write_beacon(p, 1, "fz", false, objs);
    return p;
}

void check_parsers(std::span<const uint8_t> in) {
    static DataPacket d, d2;
    static Beacon b, b2;
    ParseResult r = parse_data(in, d);
    if (!r) {
        if (r.offset > kPacketSize) __builtin_trap();
    } else {
        std::vector<DataEntry> es(d.view().begin(), d.view().end());
        Packet out;
        if (!write_data(out, d.timestamp, es)) __builtin_trap();
        if (!parse_data(std::span<const uint8_t>(out), d2)) __builtin_trap();
        if (d2.entry_count != d.entry_count) __builtin_trap();
        for (std::size_t i = 0; i < d.entry_count; ++i)
            if (d2.entries[i].id != d.entries[i].id || d2.entries[i].name != d.entries[i].name ||
                d2.entries[i].count != d.entries[i].count)
                __builtin_trap();
    }
    r = parse_beacon(in, b);
    if (!r) {
        if (r.offset > kPacketSize) __builtin_trap();
    } else {
        Packet out;
        if (!write_beacon(out, b.timestamp, b.application, b.continuation, b.objects))
            __builtin_trap();
        if (!parse_beacon(std::span<const uint8_t>(out), b2)) __builtin_trap();
        if (b2.application != b.application || !(b2.objects == b.objects)) __builtin_trap();
    }
}

void put(pv::Database& db, const char* name, double v) {
    pv::Address a;
    if (db.resolve(name, a)) db.put(a, pv::Prim::Double, &v, 1);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static const bool quiet = [] {
        log::configure("off");
        return true;
    }();
    (void)quiet;
    static const Packet beacon = known_beacon();
    check_parsers(std::span<const uint8_t>(data, size));

    pv::Database db;
    double t = 100;
    BridgeConfig cfg;
    cfg.prefix = "F:";
    cfg.machines = {{"fz", "10.0.0.2"}};
    cfg.allow = {"10.0.0.8/29"}; // source 2 (10.0.0.9): any application
    cfg.max_applications = 3;
    cfg.max_objects = 12;
    cfg.max_model_changes_per_minute = 4;
    BridgeCore core(
        db, cfg,
        [](const Endpoint& to, std::span<const uint8_t> p) {
            static DataPacket d;
            if (p.size() != kPacketSize || !parse_data(p, d)) __builtin_trap();
            if (to.ip != 0x0A000002 && to.ip != 0x0A000009) __builtin_trap(); // only machines it heard from
            return true;
        },
        [&] { return t; });
    core.handle_packet(std::span<const uint8_t>(beacon), kSources[0], t);

    std::vector<uint8_t> packet;
    std::size_t at = 0;
    while (at < size) {
        uint8_t ctrl = data[at++];
        std::size_t n = std::min<std::size_t>(kPacketSize, size - at);
        packet.assign(data + at, data + at + n);
        at += n;
        if (!(ctrl & 1)) packet.resize(kPacketSize, 0);
        if (ctrl & 0x10) t += 0.07;
        if (ctrl & 0x20) {
            t += 1.5;
            core.tick(t);
        }
        const Endpoint stranger{0xC0A80101, 5000};
        core.handle_packet(std::span<const uint8_t>(packet), (ctrl & 0x80) ? stranger : kSources[(ctrl >> 1) & 3], t);
        if (ctrl & 0x40) {
            double v = double(int8_t(ctrl)) / 4;
            put(db, "F:fz:b", v);
            put(db, "F:fz:d", ctrl & 1);
            put(db, "F:fz:f", ctrl);
            put(db, "F:fz:m", v);
            put(db, "F:fz:m.STOP", 1);
        }
    }
    t += 0.2;
    core.tick(t);
    t += 5;
    core.tick(t); // silence: everything INVALID/COMM
    return 0;
}
