// The bus scanner (src/scanner/scanner.hpp) in virtual time, with clients played by the test
// through the scanner's protocol handler and the memories it hands out: the chain, attach with
// claims (a double claim refused naming both), every cycle in each client's ring, outputs of two
// clients merged into one frame with only the claimed bits, a slow client's losses on its own
// side, detach zeroing the claimed outputs, refusals with their reasons.
#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "scanner/layout.hpp"
#include "scanner/outputs.hpp"
#include "scanner/ring.hpp"
#include "scanner/scanner.hpp"
#include "scanner/shm.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <unistd.h>

using namespace beamctl;
using namespace beamctl::scanner;

namespace {

const char* kScanner = R"(scanner: {name: test-scanner, socket: s.sock, depth: 16}
engine: {rate_hz: 1000}
buses:
  - id: 0
    link: {type: sim}
    slaves:
      - {position: 0, type: EK1100, name: COUPLER}
      - {position: 1, type: EL2008, name: OUTA}
      - {position: 2, type: EL1008, name: IN}
      - {position: 3, type: EL2008, name: OUTB}
)";

// One client as the test plays it: its connection id, the layout, its two memories.
struct Client {
    int conn;
    proto::Attached at;
    SharedMemory ring_mem, out_mem;
    std::unique_ptr<RingReader> ring;
    std::unique_ptr<OutWriter> out;
    std::vector<uint8_t> image;
    const proto::LayoutEntry* entry(const std::string& slave_type_pos, const std::string& name) const {
        for (const auto& s : at.slaves)
            for (const auto& e : s.entries)
                if ((s.slave.name == slave_type_pos) && e.name == name) return &e;
        return nullptr;
    }
    void set_bit(const proto::LayoutEntry& e, bool v) {
        uint8_t& b = image[e.bit_offset / 8];
        b = uint8_t(v ? b | 1u << (e.bit_offset % 8) : b & ~(1u << (e.bit_offset % 8)));
    }
};

struct Fixture {
    test::TempDir dir;
    rt::VirtualClock clock;
    std::unique_ptr<Scanner> sc;
    Fixture() {
        sc = std::make_unique<Scanner>(ScannerConfig::load(dir.write("scanner.yaml", kScanner)), ethercat::Catalog::builtin(), clock);
        sc->start_virtual();
        sc->engine().run_cycles(3);
    }
    std::vector<Scanner::Reply> say(int conn, proto::Body b, pid_t pid = 100) {
        return sc->handle(conn, proto::Message{7, std::move(b)}, pid);
    }
    void hello(int conn, const std::string& ioc) {
        proto::Hello h;
        h.ioc = ioc;
        auto r = say(conn, h);
        ASSERT_EQ(r.size(), 1u);
        ASSERT_TRUE(std::holds_alternative<proto::Welcome>(r[0].msg.body));
    }
    // Attach; on success the client's memories are mapped. Returns the error text otherwise.
    std::string attach(Client& c, std::vector<std::string> slaves, std::vector<proto::Claim> claims, uint16_t depth = 0) {
        proto::Attach a;
        a.slaves = std::move(slaves);
        a.claims = std::move(claims);
        a.depth = depth;
        auto r = say(c.conn, a);
        if (r.size() != 1) return "no single reply";
        if (const auto* e = std::get_if<proto::ErrorMsg>(&r[0].msg.body)) return e->text;
        c.at = std::get<proto::Attached>(r[0].msg.body);
        EXPECT_EQ(r[0].msg.request_id, 7u);
        EXPECT_EQ(r[0].fds.size(), 2u);
        c.ring_mem = SharedMemory::map(r[0].fds[0], "ring", sizeof(RingHeader), false);
        c.out_mem = SharedMemory::map(r[0].fds[1], "out", sizeof(OutHeader), true);
        c.ring = std::make_unique<RingReader>(c.ring_mem.data(), c.ring_mem.size());
        c.out = std::make_unique<OutWriter>(c.out_mem.data(), c.out_mem.size());
        c.image.assign(c.at.image_bytes, 0);
        return "";
    }
    bool master_bit(const std::string& signal) {
        ethercat::Master& m = sc->bus(0).master();
        return m.get(*m.find_signal(signal)) != 0;
    }
};

} // namespace

TEST(Scanner, ChainDescribesEverySlaveWithItsName) {
    Fixture f;
    f.hello(1, "A");
    auto r = f.say(1, proto::Describe{0});
    const auto& ch = std::get<proto::Chain>(r.at(0).msg.body);
    ASSERT_EQ(ch.slaves.size(), 4u);
    EXPECT_EQ(ch.slaves[1].name, "OUTA");
    EXPECT_EQ(ch.slaves[1].type, "EL2008");
    EXPECT_EQ(ch.slaves[3].position, 3);
    EXPECT_NE(ch.slaves[2].product, 0u);
    auto bad = f.say(1, proto::Describe{5});
    EXPECT_EQ(std::get<proto::ErrorMsg>(bad.at(0).msg.body).code, proto::ErrorCode::UnknownBus);
}

TEST(Scanner, RequestsBeforeHelloAreRefused) {
    Fixture f;
    auto r = f.say(1, proto::Describe{0});
    const auto& e = std::get<proto::ErrorMsg>(r.at(0).msg.body);
    EXPECT_EQ(e.code, proto::ErrorCode::BadMessage);
    EXPECT_NE(e.text.find("before Hello"), std::string::npos) << e.text;
}

TEST(Scanner, EveryCycleInOrderWithTheImageAndStatus) {
    Fixture f;
    f.hello(1, "A");
    Client a{1, {}, {}, {}, {}, {}, {}};
    ASSERT_EQ(f.attach(a, {"OUTA", "2"}, {{"OUTA", "*"}}), "");
    EXPECT_EQ(a.at.slaves.size(), 2u);
    EXPECT_EQ(a.at.slaves[1].slave.name, "IN");
    EXPECT_EQ(a.ring->layout_hash(), a.at.layout_hash);
    EXPECT_EQ(a.at.layout_hash, layout_hash(a.at));
    EXPECT_EQ(a.ring->instance(), f.sc->instance());
    f.sc->engine().run_cycles(5);
    std::vector<uint8_t> data(a.ring->data_bytes());
    EXPECT_EQ(data.size(), slot_data_bytes(a.at.image_bytes, 4));
    CycleSlot s;
    uint64_t prev = 0;
    for (int i = 0; i < 5; ++i) {
        ASSERT_EQ(a.ring->read(s, data.data()), RingReader::Result::Cycle);
        if (i) {
            EXPECT_EQ(s.cycle, prev + 1);
        }
        prev = s.cycle;
        EXPECT_EQ(s.flags, kLinkUp | kWkcOk);
    }
    EXPECT_EQ(a.ring->read(s, data.data()), RingReader::Result::Empty);
    CycleTail t;
    std::memcpy(&t, data.data() + a.at.image_bytes, sizeof t);
    EXPECT_EQ(t.wkc, t.expected_wkc);
    EXPECT_EQ(t.responding, 4);
    const uint8_t* st = data.data() + a.at.image_bytes + sizeof t;
    for (int i = 0; i < 4; ++i) EXPECT_EQ(st[i * kSlaveStatusBytes + 2], 1) << "slave " << i << " valid";
}

TEST(Scanner, OutputsOfTwoClientsInOneFrameOnlyTheClaimedBits) {
    Fixture f;
    f.hello(1, "A");
    f.hello(2, "B");
    Client a{1, {}, {}, {}, {}, {}, {}}, b{2, {}, {}, {}, {}, {}, {}};
    ASSERT_EQ(f.attach(a, {"OUTA"}, {{"OUTA", "*"}}), "");
    ASSERT_EQ(f.attach(b, {"OUTB", "OUTA"}, {{"OUTB", "binaryOutput02"}}), "");
    const proto::LayoutEntry* a1 = a.entry("OUTA", "binaryOutput01");
    const proto::LayoutEntry* b2 = b.entry("OUTB", "binaryOutput02");
    const proto::LayoutEntry* b3 = b.entry("OUTB", "binaryOutput03");
    const proto::LayoutEntry* ba1 = b.entry("OUTA", "binaryOutput01");
    ASSERT_TRUE(a1 && b2 && b3 && ba1);
    a.set_bit(*a1, true);
    b.set_bit(*b2, true);
    b.set_bit(*b3, true);   // not claimed by B: ignored
    b.set_bit(*ba1, false); // A's: ignored
    a.out->commit(1, 0, a.image.data());
    b.out->commit(1, 0, b.image.data());
    f.sc->engine().run_cycles(2);
    EXPECT_TRUE(f.master_bit("ec0.s1.binaryOutput01"));
    EXPECT_TRUE(f.master_bit("ec0.s3.binaryOutput02"));
    EXPECT_FALSE(f.master_bit("ec0.s3.binaryOutput03")) << "B wrote a bit it did not claim";
    // Both see both outputs as sent, in the same cycle's slot.
    std::vector<uint8_t> da(a.ring->data_bytes()), db(b.ring->data_bytes());
    CycleSlot sa, sb;
    while (a.ring->read(sa, da.data()) == RingReader::Result::Cycle) {
    }
    while (b.ring->read(sb, db.data()) == RingReader::Result::Cycle) {
    }
    EXPECT_EQ(sa.cycle, sb.cycle);
    EXPECT_EQ(std::memcmp(da.data(), db.data(), a.at.image_bytes), 0);
    EXPECT_TRUE(db[b2->bit_offset / 8] >> (b2->bit_offset % 8) & 1);
    EXPECT_TRUE(db[ba1->bit_offset / 8] >> (ba1->bit_offset % 8) & 1);
}

TEST(Scanner, ADoubleClaimIsRefusedNamingBoth) {
    Fixture f;
    f.hello(1, "SCA");
    f.hello(2, "SCB");
    Client a{1, {}, {}, {}, {}, {}, {}}, b{2, {}, {}, {}, {}, {}, {}};
    ASSERT_EQ(f.attach(a, {"OUTA"}, {{"OUTA", "*"}}), "");
    std::string e = f.attach(b, {"1"}, {{"1", "binaryOutput05"}});
    EXPECT_NE(e.find("OUTA binaryOutput05 is claimed by 'SCA' (pid 100); 'SCB' (pid 100) cannot claim it too"), std::string::npos) << e;
    EXPECT_EQ(f.sc->clients(), 1u);
    // Attached to the same slave without claiming its outputs: fine.
    EXPECT_EQ(f.attach(b, {"OUTA"}, {}), "");
    EXPECT_EQ(f.sc->clients(), 2u);
}

TEST(Scanner, RefusalsNameWhatIsWrong) {
    Fixture f;
    f.hello(1, "A");
    Client a{1, {}, {}, {}, {}, {}, {}};
    std::string e = f.attach(a, {"OUTX"}, {});
    EXPECT_NE(e.find("no slave 'OUTX' in the chain (0 COUPLER, 1 OUTA, 2 IN, 3 OUTB)"), std::string::npos) << e;
    e = f.attach(a, {"IN"}, {{"OUTA", "*"}});
    EXPECT_NE(e.find("claim on 'OUTA', which this client does not attach"), std::string::npos) << e;
    e = f.attach(a, {"OUTA"}, {{"OUTA", "binaryInput01"}});
    EXPECT_NE(e.find("OUTA: no output entry 'binaryInput01'"), std::string::npos) << e;
    e = f.attach(a, {}, {});
    EXPECT_NE(e.find("names no slave"), std::string::npos) << e;
    EXPECT_EQ(f.sc->clients(), 0u);
    ASSERT_EQ(f.attach(a, {"OUTA"}, {}), "");
    e = f.attach(a, {"OUTA"}, {});
    EXPECT_NE(e.find("attached already"), std::string::npos) << e;
}

TEST(Scanner, ASlowClientLosesItsOwnOldestCyclesCounted) {
    Fixture f;
    f.hello(1, "slow");
    f.hello(2, "fast");
    Client slow{1, {}, {}, {}, {}, {}, {}}, fast{2, {}, {}, {}, {}, {}, {}};
    ASSERT_EQ(f.attach(slow, {"IN"}, {}, 16), "");
    ASSERT_EQ(f.attach(fast, {"IN"}, {}, 16), "");
    EXPECT_EQ(slow.at.depth, 16u);
    std::vector<uint8_t> d(fast.ring->data_bytes());
    CycleSlot s;
    uint64_t got = 0;
    for (int i = 0; i < 100; ++i) {
        f.sc->engine().run_cycles(1);
        while (fast.ring->read(s, d.data()) == RingReader::Result::Cycle) ++got;
    }
    EXPECT_EQ(got, 100u);
    EXPECT_EQ(fast.ring->lost(), 0u);
    uint64_t slow_got = 0;
    while (slow.ring->read(s, d.data()) == RingReader::Result::Cycle) ++slow_got;
    EXPECT_EQ(slow_got, 16u);
    EXPECT_EQ(slow.ring->lost(), 84u);
    slow.out->report_drops(slow.ring->lost());
    proto::Status st = f.sc->status();
    ASSERT_EQ(st.clients.size(), 2u);
    for (const auto& c : st.clients) EXPECT_EQ(c.drops, c.name == "slow" ? 84u : 0u) << c.name;
}

TEST(Scanner, DetachSetsTheClaimedOutputsToZero) {
    Fixture f;
    f.hello(1, "A");
    Client a{1, {}, {}, {}, {}, {}, {}};
    ASSERT_EQ(f.attach(a, {"OUTA"}, {{"OUTA", "*"}}), "");
    a.set_bit(*a.entry("OUTA", "binaryOutput03"), true);
    a.out->commit(1, 0, a.image.data());
    f.sc->engine().run_cycles(2);
    EXPECT_TRUE(f.master_bit("ec0.s1.binaryOutput03"));
    f.sc->disconnect(1); // the connection closed (the IOC was killed)
    EXPECT_EQ(f.sc->clients(), 0u);
    EXPECT_FALSE(f.master_bit("ec0.s1.binaryOutput03"));
    f.sc->engine().run_cycles(2);
    EXPECT_FALSE(f.master_bit("ec0.s1.binaryOutput03"));
}

TEST(Scanner, SdoWritesOnlyToClaimedSlaves) {
    Fixture f;
    f.hello(1, "A");
    auto r = f.say(1, proto::SdoWrite{0, 1, 0x8000, 1, false, {1}});
    const auto& e = std::get<proto::ErrorMsg>(r.at(0).msg.body);
    EXPECT_EQ(e.code, proto::ErrorCode::Denied);
    EXPECT_NE(e.text.find("SDO writes only to a slave whose outputs this client claimed"), std::string::npos) << e.text;
    auto r2 = f.say(1, proto::AlInfoRequest{0, 2});
    const auto& al = std::get<proto::AlInfo>(r2.at(0).msg.body);
    EXPECT_EQ(al.al_state & 0x0F, 8);
    EXPECT_EQ(al.slave_state, uint8_t(ethercat::SlaveState::Op));
    auto r3 = f.say(1, proto::AlInfoRequest{0, 9});
    EXPECT_EQ(std::get<proto::ErrorMsg>(r3.at(0).msg.body).code, proto::ErrorCode::UnknownSlave);
}

TEST(ScannerConfig, EveryErrorWithItsPlace) {
    test::TempDir d;
    std::string p = d.write("bad.yaml", R"(scanner: {socket: s.sock, depth: 10, max_clients: 0}
engine: {rate_hz: 0}
buses:
  - id: 0
    link: {type: scanner, socket: x}
    slaves:
      - {position: 0, type: EK1100}
      - {position: 1, type: EL2008, name: A}
      - {position: 2, type: EL2008, name: A}
      - {position: 3, type: EL2008, name: "7"}
)");
    try {
        ScannerConfig::load(p);
        FAIL() << "no error";
    } catch (const MultiError& e) {
        std::string all;
        for (const auto& m : e.errors()) all += m + "\n";
        EXPECT_NE(all.find("bad.yaml:1:34: scanner.depth: 10 should be a power of two from 2 to 4096"), std::string::npos) << all;
        EXPECT_NE(all.find("bad.yaml:1:51: scanner.max_clients: should be at least 1"), std::string::npos) << all;
        EXPECT_NE(all.find("bad.yaml:2:19: engine.rate_hz should be from 1 to 20000, got 0"), std::string::npos) << all;
        EXPECT_NE(all.find("buses[0].link.type should be sim, udp or raw, got 'scanner'"), std::string::npos) << all;
        EXPECT_NE(all.find("buses[0].slaves[0]: missing required key 'name'"), std::string::npos) << all;
        EXPECT_NE(all.find("bad.yaml:9:43: buses[0].slaves[2].name: 'A' is used twice"), std::string::npos) << all;
        EXPECT_NE(all.find("buses[0].slaves[3].name: '7' should be a word"), std::string::npos) << all;
    }
}
