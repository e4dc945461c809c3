// A CA circuit driven without sockets: requests in, exact replies out (ca-protocol.md §3, §7).
#include "ca/circuit.hpp"

#include <gtest/gtest.h>

#include <cstring>

using namespace beamctl;
using namespace beamctl::ca;

namespace {

std::string msg(uint16_t cmd, uint16_t dtype = 0, uint32_t count = 0, uint32_t p1 = 0, uint32_t p2 = 0,
                std::string payload = {}) {
    std::string out;
    append_message(out, cmd, dtype, count, p1, p2, payload.data(), payload.size());
    return out;
}

std::string name(const char* s) { return std::string(s) + '\0'; }

std::string dbl(double v) {
    std::string s(8, '\0');
    putf64(reinterpret_cast<uint8_t*>(s.data()), v);
    return s;
}

std::string mon_payload(uint16_t mask) {
    std::string s(16, '\0');
    put16(reinterpret_cast<uint8_t*>(s.data()) + 12, mask);
    return s;
}

struct Reply {
    Header h;
    std::string payload;
};

struct CircuitTest : ::testing::Test {
    pv::Database db;
    ServerContext ctx{db, AccessSecurity(), 5064, 1 << 20, 8, 1 << 20, {}};
    std::unique_ptr<Circuit> c;

    void SetUp() override {
        db.load(pv::parse_db(R"(
record(ao, "x") { field(PREC, "1") field(VAL, "1") field(PINI, "YES") }
record(ai, "ro") { field(ASG, "RO") }
record(waveform, "w") { field(FTVL, "LONG") field(NELM, "100") }
)",
                             "c.db", {}));
        db.init_records();
        c = std::make_unique<Circuit>(ctx, 0x7F000001, 5555);
        replies(); // server VERSION
        send(msg(kVersion, 0, 13));
    }
    void send(const std::string& s) { c->receive(reinterpret_cast<const uint8_t*>(s.data()), s.size()); }
    std::vector<Reply> replies() {
        c->fill_events(1 << 30);
        std::string_view out = c->pending_output();
        std::vector<Reply> v;
        std::size_t off = 0;
        while (off < out.size()) {
            Reply r;
            std::size_t hs = decode_header(reinterpret_cast<const uint8_t*>(out.data()) + off,
                                           out.size() - off, true, r.h);
            EXPECT_GT(hs, 0u);
            if (!hs) break;
            r.payload = std::string(out.substr(off + hs, r.h.payload_size));
            off += hs + r.h.payload_size;
            EXPECT_EQ((hs + r.h.payload_size) % 8, 0u);
            v.push_back(r);
        }
        c->consume_output(out.size());
        return v;
    }
    uint32_t create(const char* n, uint32_t cid) {
        send(msg(kCreateChan, 0, 0, cid, 13, name(n)));
        auto r = replies();
        EXPECT_EQ(r.size(), 2u);
        EXPECT_EQ(r[0].h.cmd, kAccessRights);
        EXPECT_EQ(r[1].h.cmd, kCreateChan);
        return r[1].h.p2;
    }
};

} // namespace

TEST_F(CircuitTest, CreateChanSendsRightsThenNativeTypeAndCount) {
    send(msg(kCreateChan, 0, 0, 42, 13, name("w")));
    auto r = replies();
    ASSERT_EQ(r.size(), 2u);
    EXPECT_EQ(r[0].h.cmd, kAccessRights);
    EXPECT_EQ(r[0].h.p1, 42u);
    EXPECT_EQ(r[0].h.p2, 3u);
    EXPECT_EQ(r[1].h.dtype, 5); // DBR_LONG
    EXPECT_EQ(r[1].h.count, 100u);
    EXPECT_EQ(r[1].h.p1, 42u);
}

TEST_F(CircuitTest, UnknownNameGetsCreateChFail) {
    send(msg(kCreateChan, 0, 0, 7, 13, name("nope")));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kCreateChFail);
    EXPECT_EQ(r[0].h.p1, 7u);
}

TEST_F(CircuitTest, ReadOnlyFieldHasNoWriteRight) {
    send(msg(kCreateChan, 0, 0, 1, 13, name("x.NAME")));
    auto r = replies();
    EXPECT_EQ(r[0].h.p2, 1u); // read only
}

TEST_F(CircuitTest, ReadNotifyReplyCarriesStatusAndIoid) {
    uint32_t sid = create("x", 1);
    send(msg(kReadNotify, 6, 1, sid, 99));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kReadNotify);
    EXPECT_EQ(r[0].h.p1, kEcaNormal);
    EXPECT_EQ(r[0].h.p2, 99u);
    EXPECT_EQ(getf64(reinterpret_cast<const uint8_t*>(r[0].payload.data())), 1.0);
}

TEST_F(CircuitTest, WriteNotifyAlwaysAnswered) {
    uint32_t sid = create("x", 1);
    send(msg(kWriteNotify, 6, 1, sid, 5, dbl(2.5)));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kWriteNotify);
    EXPECT_EQ(r[0].h.p1, kEcaNormal);
    EXPECT_EQ(r[0].h.p2, 5u);
    EXPECT_EQ(r[0].h.payload_size, 0u);
    // A string that is not a number: PUTFAIL, value unchanged.
    send(msg(kWriteNotify, 0, 1, sid, 6, std::string("abc").append(37, '\0')));
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.p1, kEcaPutFail);
    send(msg(kReadNotify, 0, 1, sid, 7));
    r = replies();
    EXPECT_STREQ(r[0].payload.c_str(), "2.5");
}

TEST_F(CircuitTest, PlainWriteToReadOnlyFieldGetsErrorNoWtAccess) {
    uint32_t sid = create("x.NAME", 1);
    send(msg(kWrite, 0, 1, sid, 1, std::string(40, 'a')));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kError);
    EXPECT_EQ(r[0].h.p2, kEcaNoWtAccess);
    EXPECT_EQ(get16(reinterpret_cast<const uint8_t*>(r[0].payload.data())), kWrite); // request header
}

TEST_F(CircuitTest, EventAddFirstUpdateThenEventCancelAnsweredByEmptyEventAdd) {
    uint32_t sid = create("x", 1);
    send(msg(kEventAdd, 20, 1, sid, 77, mon_payload(pv::kDbeValue)));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kEventAdd);
    EXPECT_EQ(r[0].h.p1, kEcaNormal);
    EXPECT_EQ(r[0].h.p2, 77u);
    EXPECT_EQ(r[0].h.payload_size, 24u);
    send(msg(kWrite, 6, 1, sid, 1, dbl(3)));
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(getf64(reinterpret_cast<const uint8_t*>(r[0].payload.data()) + 16), 3.0);
    send(msg(kEventCancel, 20, 1, sid, 77));
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kEventAdd);
    EXPECT_EQ(r[0].h.payload_size, 0u);
    EXPECT_EQ(r[0].h.p1, sid);
    EXPECT_EQ(r[0].h.p2, 77u);
    send(msg(kEventCancel, 20, 1, sid, 77)); // unknown now
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kError);
    EXPECT_EQ(r[0].h.p2, kEcaBadMonId);
}

TEST_F(CircuitTest, EventsOffKeepsOnlyTheLatestValue) {
    uint32_t sid = create("x", 1);
    send(msg(kEventAdd, 6, 1, sid, 1, mon_payload(pv::kDbeValue)));
    replies();
    send(msg(kEventsOff));
    for (int i = 10; i < 20; ++i) send(msg(kWrite, 6, 1, sid, 1, dbl(i)));
    EXPECT_TRUE(replies().empty());
    send(msg(kEventsOn));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(getf64(reinterpret_cast<const uint8_t*>(r[0].payload.data())), 19.0);
}

TEST_F(CircuitTest, SlowClientQueueCoalescesButKeepsLatest) {
    uint32_t sid = create("x", 1);
    send(msg(kEventAdd, 6, 1, sid, 1, mon_payload(pv::kDbeValue)));
    // The client reads nothing: fill the output past the high-water mark with echo replies, so
    // monitor events queue (limit 8 in this context) and then coalesce.
    std::string chunk = msg(kEcho, 0, 0, 0, 0, std::string(60000, 'e'));
    for (std::size_t i = 0; i * 60000 < Circuit::kDefaultHighWater + 60000; ++i) send(chunk);
    for (int i = 0; i < 100; ++i) send(msg(kWrite, 6, 1, sid, 1, dbl(i)));
    EXPECT_TRUE(c->has_queued_events());
    EXPECT_GT(ctx.stats.events_coalesced, 0u);
    auto r = replies();
    std::vector<double> vals;
    for (auto& x : r)
        if (x.h.cmd == kEventAdd) vals.push_back(getf64(reinterpret_cast<const uint8_t*>(x.payload.data())));
    ASSERT_GE(vals.size(), 2u);
    EXPECT_LE(vals.size(), 1u + 8u + 1u); // first update + bounded queue
    EXPECT_EQ(vals.back(), 99.0);          // the latest value is never lost
}

TEST_F(CircuitTest, DynamicCountFollowsNord) {
    uint32_t sid = create("w", 1);
    std::string three(12, '\0');
    for (int i = 0; i < 3; ++i) put32(reinterpret_cast<uint8_t*>(three.data()) + 4 * i, uint32_t(i + 1));
    send(msg(kWriteNotify, 5, 3, sid, 1, three));
    replies();
    send(msg(kReadNotify, 5, 0, sid, 2));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.count, 3u);
    EXPECT_EQ(r[0].h.payload_size, 16u); // 12 padded to 16
}

TEST_F(CircuitTest, MisalignedMessageClosesCircuit) {
    std::string bad(16, '\0');
    put16(reinterpret_cast<uint8_t*>(bad.data()), kEcho);
    put16(reinterpret_cast<uint8_t*>(bad.data()) + 2, 3);
    bad += "abc";
    send(bad);
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kError);
    EXPECT_EQ(r[0].h.p2, kEcaInternal);
    EXPECT_TRUE(c->wants_close());
}

TEST_F(CircuitTest, UnknownCommandClosesCircuit) {
    send(msg(200));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kError);
    EXPECT_TRUE(c->wants_close());
}

TEST_F(CircuitTest, BadSidIsAnErrorButCircuitStays) {
    send(msg(kReadNotify, 6, 1, 12345, 1));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kError);
    EXPECT_EQ(r[0].h.p2, kEcaInternal);
    EXPECT_FALSE(c->wants_close());
    create("x", 1);
}

TEST_F(CircuitTest, OversizedMessageIsDrained) {
    ctx.max_payload = 1024;
    uint32_t sid = create("w", 1);
    std::string big = msg(kWrite, 5, 100, sid, 1, std::string(2048, '\0'));
    send(big.substr(0, 100));
    send(big.substr(100));
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.p2, kEcaTooLarge);
    EXPECT_FALSE(c->wants_close());
    send(msg(kEcho)); // the stream is in sync again
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kEcho);
}

TEST_F(CircuitTest, ByteAtATimeParsing) {
    std::string s = msg(kCreateChan, 0, 0, 9, 13, name("x")) + msg(kEcho);
    for (char ch : s) send(std::string(1, ch));
    auto r = replies();
    ASSERT_EQ(r.size(), 3u);
    EXPECT_EQ(r[2].h.cmd, kEcho);
}

TEST_F(CircuitTest, AccessSecurityDeniesWriteAndRightsChangeLive) {
    ctx.acf = AccessSecurity::parse("ASG(DEFAULT) { RULE(1, WRITE) }\nASG(RO) { RULE(1, READ) }\n", "t.acf");
    send(msg(kCreateChan, 0, 0, 1, 13, name("ro")));
    auto r = replies();
    EXPECT_EQ(r[0].h.p2, 1u);
    uint32_t sid = r[1].h.p2;
    send(msg(kWriteNotify, 6, 1, sid, 3, dbl(5)));
    r = replies();
    EXPECT_EQ(r[0].h.p1, kEcaNoWtAccess);
    ctx.acf = AccessSecurity::parse("ASG(DEFAULT) { RULE(1, WRITE) }\nASG(RO) { RULE(1, WRITE) }\n", "t.acf");
    c->refresh_rights();
    r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kAccessRights);
    EXPECT_EQ(r[0].h.p2, 3u);
}

TEST_F(CircuitTest, RemovedRecordSendsServerDisconn) {
    create("x", 33);
    db.remove("x");
    auto r = replies();
    ASSERT_EQ(r.size(), 1u);
    EXPECT_EQ(r[0].h.cmd, kServerDisconn);
    EXPECT_EQ(r[0].h.p1, 33u);
    EXPECT_EQ(c->channel_count(), 0u);
}
