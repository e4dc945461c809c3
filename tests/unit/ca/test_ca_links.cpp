// CA links between two databases (as dbCa): database A links to records of database B, which a
// ca::Server serves on loopback; both on one EventLoop. CP processes A on each change of B and on
// disconnection (LINK/INVALID), MS carries B's severity, an output link puts to B, a CA forward
// link processes B, and the link reconnects when B's server comes back.
#include "ca/ca_link.hpp"
#include "ca/server.hpp"
#include "core/error.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <functional>
#include <sys/socket.h>
#include <unistd.h>

using namespace beamctl;

namespace {

uint16_t free_port() {
    for (int attempt = 0; attempt < 20; ++attempt) {
        int u = socket(AF_INET, SOCK_DGRAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        bind(u, reinterpret_cast<sockaddr*>(&a), sizeof a);
        socklen_t len = sizeof a;
        getsockname(u, reinterpret_cast<sockaddr*>(&a), &len);
        int t = socket(AF_INET, SOCK_STREAM, 0);
        bool tcp_free = bind(t, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
        close(t);
        close(u);
        if (tcp_free) return ntohs(a.sin_port);
    }
    return 0;
}

const char* kDbB = R"(
record(ao, "B:val") { field(VAL, "1") field(HIGH, "5") field(HSV, "MAJOR") }
record(ao, "B:sink") {}
record(calc, "B:count") { field(CALC, "VAL+1") }
record(bo, "B:sw") { field(ZNAM, "Off") field(ONAM, "On") field(VAL, "1") }
)";

const char* kDbA = R"(
record(ai, "A:in") { field(INP, "B:val CP MS") }
record(ai, "A:plain") { field(INP, "B:val CA NMS") }
record(ao, "A:out") { field(OUT, "B:sink CA") }
record(ao, "A:fwd") { field(FLNK, "B:count.PROC CA") }
record(stringin, "A:swtext") { field(INP, "B:sw CP") }
record(ai, "A:swnum") { field(INP, "B:sw CP") }
)";

struct CaLinksTest : ::testing::Test {
    EventLoop loop;
    pv::Database a, b;
    uint16_t port = free_port();
    std::unique_ptr<ca::Server> server;
    std::unique_ptr<ca::CaLinks> links;

    void SetUp() override {
        ASSERT_NE(port, 0);
        b.load(pv::parse_db(kDbB, "b.db", {}));
        b.init_records();
        start_server();
        ca::ClientConfig cc;
        sockaddr_in to{};
        to.sin_family = AF_INET;
        to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        to.sin_port = htons(port);
        cc.addr_list.push_back(to);
        cc.auto_addr_list = false;
        cc.search_max_s = 0.2;
        cc.repeater_port = 1;
        links = std::make_unique<ca::CaLinks>(a, cc);
        a.load(pv::parse_db(kDbA, "a.db", {}));
        a.init_records();
        links->start(loop);
    }
    void TearDown() override { links->stop(); }
    void start_server() {
        ca::ServerConfig sc;
        sc.port = port;
        sc.interfaces.push_back(in_addr{htonl(INADDR_LOOPBACK)});
        sc.auto_beacon_addrs = false;
        server = std::make_unique<ca::Server>(loop, b, sc);
        server->start();
    }
    bool run_until(const std::function<bool()>& pred, double timeout_s = 10) {
        if (pred()) return true;
        double end = EventLoop::now_s() + timeout_s;
        // One stop() a run: a second tick before the first stop is taken would leave a stop
        // queued, which would end the next run_until at once.
        bool stopping = false;
        auto id = loop.call_every(0.002, [&] {
            if (!stopping && (pred() || EventLoop::now_s() > end)) {
                stopping = true;
                loop.stop();
            }
        });
        loop.run();
        loop.cancel(id);
        return pred();
    }
    static pv::Address addr(pv::Database& db, const char* n) {
        pv::Address x;
        EXPECT_TRUE(db.resolve(n, x)) << n;
        return x;
    }
    static double get(pv::Database& db, const char* n) {
        double v = 0;
        db.get(addr(db, n), pv::Prim::Double, &v, 1);
        return v;
    }
    static void put(pv::Database& db, const char* n, double v) { db.put(addr(db, n), pv::Prim::Double, &v, 1); }
};

} // namespace

TEST_F(CaLinksTest, CpProcessesOnEachChangeWithTheRemoteSeverity) {
    ASSERT_TRUE(run_until([&] { return links->connected_count() == 6; }));
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 1; })); // the first update processed it
    put(b, "B:val", 7);                                          // above HIGH: MAJOR
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 7; }));
    EXPECT_EQ(get(a, "A:in.SEVR"), double(pv::kMajor)); // MS
    EXPECT_EQ(get(a, "A:in.STAT"), double(pv::kStatLink));
    put(b, "B:val", 2);
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 2; }));
    EXPECT_EQ(get(a, "A:in.SEVR"), double(pv::kNoAlarm));
    // Without CP the record reads the last value when it is processed; NMS keeps its alarm out.
    put(b, "B:val", 9);
    run_until([&] { return false; }, 0.1);
    a.process(*a.find("A:plain"));
    EXPECT_EQ(get(a, "A:plain"), 9);
    EXPECT_EQ(get(a, "A:plain.SEVR"), double(pv::kNoAlarm));
}

TEST_F(CaLinksTest, AnEnumReadsAsItsStateStringIntoAStringAndAsItsIndexIntoANumber) {
    auto text = [&] {
        char s[40] = {};
        a.get(addr(a, "A:swtext"), pv::Prim::String, s, 1);
        return std::string(s);
    };
    ASSERT_TRUE(run_until([&] { return text() == "On"; })) << text();
    EXPECT_EQ(get(a, "A:swnum"), 1);
    put(b, "B:sw", 0);
    ASSERT_TRUE(run_until([&] { return text() == "Off"; })) << text();
    ASSERT_TRUE(run_until([&] { return get(a, "A:swnum") == 0; }));
}

TEST_F(CaLinksTest, OutputAndForwardLinksWriteTheOtherServer) {
    ASSERT_TRUE(run_until([&] { return links->connected_count() == 6; }));
    put(a, "A:out", 3.5); // processes A:out, which writes OUT
    ASSERT_TRUE(run_until([&] { return get(b, "B:sink") == 3.5; }));
    double before = get(b, "B:count");
    put(a, "A:fwd", 1); // FLNK "B:count.PROC CA": B:count processed once
    ASSERT_TRUE(run_until([&] { return get(b, "B:count") == before + 1; }));
}

TEST_F(CaLinksTest, DisconnectionRaisesLinkInvalidAndTheLinkReconnects) {
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 1 && links->connected_count() == 6; }));
    server.reset();
    ASSERT_TRUE(run_until([&] { return get(a, "A:in.SEVR") == double(pv::kInvalid); })); // CP: processed on disconnection
    EXPECT_EQ(get(a, "A:in.STAT"), double(pv::kStatLink));
    put(a, "A:out", 4); // cannot write: LINK/INVALID on the output record
    EXPECT_EQ(get(a, "A:out.SEVR"), double(pv::kInvalid));
    put(b, "B:val", 6);
    start_server();
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 6; }));
    EXPECT_EQ(get(a, "A:in.SEVR"), double(pv::kMajor));
    put(b, "B:val", 3);
    ASSERT_TRUE(run_until([&] { return get(a, "A:in") == 3; }));
    EXPECT_EQ(get(a, "A:in.SEVR"), double(pv::kNoAlarm));
}

TEST(CaLinksLoad, MissingRecordsWithoutCaAndRemoteForwardLinksWithoutProcAreLoadErrors) {
    pv::Database db;
    ca::CaLinks links(db, ca::ClientConfig{});
    auto error = [&](const char* text) -> std::string {
        try {
            db.load(pv::parse_db(text, "bad.db", {}));
            db.init_records();
        } catch (const Error& e) {
            return e.what();
        }
        return "(no error)";
    };
    std::string e = error("record(ai, \"X:a\") {\n  field(INP, \"nowhere:x\")\n}\n");
    EXPECT_NE(e.find("bad.db:2:"), std::string::npos) << e;
    EXPECT_NE(e.find("needs the CA modifier"), std::string::npos) << e;
    pv::Database db2;
    ca::CaLinks links2(db2, ca::ClientConfig{});
    try {
        db2.load(pv::parse_db("record(ao, \"X:f\") { field(FLNK, \"other:rec CA\") }\n", "fwd.db", {}));
        db2.init_records();
        ADD_FAILURE() << "no error";
    } catch (const Error& ex) {
        EXPECT_NE(std::string(ex.what()).find("must name its PROC field"), std::string::npos) << ex.what();
    }
    // Without a CA client (no remote binder) a CA link says so.
    pv::Database db3;
    try {
        db3.load(pv::parse_db("record(ai, \"X:c\") { field(INP, \"other:rec CP\") }\n", "c.db", {}));
        db3.init_records();
        ADD_FAILURE() << "no error";
    } catch (const Error& ex) {
        EXPECT_NE(std::string(ex.what()).find("no Channel Access client"), std::string::npos) << ex.what();
    }
}

TEST(CaLinksLoad, ALinkToAnotherServerKeepsItsTextAndSaysDisconnected) {
    pv::Database db;
    ca::CaLinks links(db, ca::ClientConfig{});
    db.load(pv::parse_db("record(ai, \"X:c\") { field(INP, \"other:rec.VAL CPP MSS\") }\n", "c.db", {}));
    db.init_records();
    char text[40] = {};
    pv::Address x;
    ASSERT_TRUE(db.resolve("X:c.INP", x));
    db.get(x, pv::Prim::String, text, 1);
    EXPECT_STREQ(text, "other:rec.VAL CPP MSS");
    db.process(*db.find("X:c"));
    double sevr = 0;
    ASSERT_TRUE(db.resolve("X:c.SEVR", x));
    db.get(x, pv::Prim::Double, &sevr, 1);
    EXPECT_EQ(sevr, double(pv::kInvalid)); // never connected: LINK/INVALID
    EXPECT_EQ(links.size(), 1u);
}
