// The CA client against the project's own CA server, in-process on loopback with a free port,
// both on one EventLoop: connect, get, put, put-callback status, monitors, reconnection after the
// server is destroyed and made again on the same port; and servers that misbehave (garbage,
// silence) are counted and disconnected without harm.
#include "ca/client.hpp"
#include "ca/server.hpp"
#include "core/event_loop.hpp"
#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <functional>
#include <optional>
#include <netinet/in.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

using namespace beamctl;

namespace {

// A UDP port no one uses now (the server binds it with SO_REUSEADDR, TCP takes the same number).
uint16_t free_port() {
    for (int attempt = 0; attempt < 20; ++attempt) {
        int u = socket(AF_INET, SOCK_DGRAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        bind(u, reinterpret_cast<sockaddr*>(&a), sizeof a);
        socklen_t len = sizeof a;
        getsockname(u, reinterpret_cast<sockaddr*>(&a), &len);
        uint16_t port = ntohs(a.sin_port);
        int t = socket(AF_INET, SOCK_STREAM, 0);
        bool tcp_free = bind(t, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
        close(t);
        close(u);
        if (tcp_free) return port;
    }
    return 0;
}

ca::ClientConfig client_config(uint16_t port) {
    ca::ClientConfig c;
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    c.addr_list.push_back(a);
    c.auto_addr_list = false;
    c.search_max_s = 0.2;
    c.repeater_port = 1; // no repeater in these tests
    return c;
}

const char* kDb = R"(
record(ao, "T:ao") { field(VAL, "1.5") field(HIGH, "5") field(HSV, "MINOR") field(PREC, "2") field(EGU, "mm") }
record(stringout, "T:so") { field(VAL, "hello") }
record(waveform, "T:wf") { field(FTVL, "DOUBLE") field(NELM, "8") }
)";

struct ClientTest : ::testing::Test {
    EventLoop loop;
    pv::Database db;
    uint16_t port = free_port();
    std::unique_ptr<ca::Server> server;

    void SetUp() override {
        ASSERT_NE(port, 0);
        db.load(pv::parse_db(kDb, "client.db", {}));
        db.init_records();
        start_server();
    }
    void start_server() {
        ca::ServerConfig sc;
        sc.port = port;
        sc.interfaces.push_back(in_addr{htonl(INADDR_LOOPBACK)});
        sc.auto_beacon_addrs = false;
        server = std::make_unique<ca::Server>(loop, db, sc);
        server->start();
        ASSERT_EQ(server->tcp_port(), port);
    }
    // Runs the loop until pred() holds or `timeout_s` passed; returns pred().
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
    void db_put(const char* name, double v) {
        pv::Address a;
        ASSERT_TRUE(db.resolve(name, a));
        db.put(a, pv::Prim::Double, &v, 1);
    }
};

} // namespace

TEST_F(ClientTest, ConnectsAndGetsValueAlarmTimeAndMetadata) {
    ca::Client client(loop, client_config(port));
    auto ch = client.channel("T:ao");
    std::vector<bool> events;
    ch->on_connection([&](bool up) { events.push_back(up); });
    ASSERT_TRUE(run_until([&] { return ch->connected(); }));
    EXPECT_EQ(events, std::vector<bool>{true});
    EXPECT_EQ(ch->native_type(), pv::Prim::Double);
    EXPECT_EQ(ch->element_count(), 1u);
    EXPECT_TRUE(ch->read_access());
    EXPECT_TRUE(ch->write_access());
    EXPECT_EQ(ch->server(), "127.0.0.1:" + std::to_string(port));

    std::optional<ca::Result> got;
    ch->get([&](const ca::Result& r) { got = r; });
    ASSERT_TRUE(run_until([&] { return got.has_value(); }));
    ASSERT_TRUE(got->ok()) << got->message;
    EXPECT_DOUBLE_EQ(got->value.as_double(), 1.5);
    EXPECT_EQ(got->value.severity, pv::kNoAlarm);

    got.reset();
    ch->get([&](const ca::Result& r) { got = r; }, 34); // DBR_CTRL_DOUBLE
    ASSERT_TRUE(run_until([&] { return got.has_value(); }));
    ASSERT_TRUE(got->ok());
    EXPECT_EQ(got->value.units, "mm");
    EXPECT_EQ(got->value.precision, 2);
    EXPECT_DOUBLE_EQ(got->value.alarm_high, 5);

    auto s = client.channel("T:so");
    got.reset();
    ASSERT_TRUE(run_until([&] { return s->connected(); }));
    EXPECT_EQ(s->native_type(), pv::Prim::String);
    s->get([&](const ca::Result& r) { got = r; });
    ASSERT_TRUE(run_until([&] { return got.has_value(); }));
    EXPECT_EQ(got->value.as_string(), "hello");
    EXPECT_EQ(client.circuit_count(), 1u); // one circuit carries both channels
}

TEST_F(ClientTest, PutsAndPutCallbacksReportTheirStatus) {
    ca::Client client(loop, client_config(port));
    auto ch = client.channel("T:ao");
    auto wf = client.channel("T:wf");
    ASSERT_TRUE(run_until([&] { return ch->connected() && wf->connected(); }));

    EXPECT_TRUE(ch->put(2.5)); // WRITE, no reply
    std::optional<ca::Result> put_done;
    ch->put(3.25, [&](const ca::Result& r) { put_done = r; });
    ASSERT_TRUE(run_until([&] { return put_done.has_value(); }));
    EXPECT_TRUE(put_done->ok()) << put_done->message;
    pv::Address a;
    ASSERT_TRUE(db.resolve("T:ao", a));
    double v = 0;
    db.get(a, pv::Prim::Double, &v, 1);
    EXPECT_DOUBLE_EQ(v, 3.25);

    put_done.reset(); // a string that is no number: the server's put fails
    ch->put(std::string("not a number"), [&](const ca::Result& r) { put_done = r; });
    ASSERT_TRUE(run_until([&] { return put_done.has_value(); }));
    EXPECT_EQ(put_done->eca, ca::kEcaPutFail);
    EXPECT_FALSE(put_done->ok());

    put_done.reset();
    wf->put(std::vector<double>{1, 2, 3}, [&](const ca::Result& r) { put_done = r; });
    ASSERT_TRUE(run_until([&] { return put_done.has_value(); }));
    EXPECT_TRUE(put_done->ok());
    std::optional<ca::Result> got;
    wf->get([&](const ca::Result& r) { got = r; });
    ASSERT_TRUE(run_until([&] { return got.has_value(); }));
    EXPECT_EQ(got->value.as_doubles(), (std::vector<double>{1, 2, 3}));
}

TEST_F(ClientTest, MonitorDeliversValueSeverityAndStopsWhenDropped) {
    ca::Client client(loop, client_config(port));
    auto ch = client.channel("T:ao");
    std::vector<ca::Value> updates;
    auto mon = ch->monitor(pv::kDbeValue | pv::kDbeAlarm, [&](const ca::Result& r) {
        ASSERT_TRUE(r.ok()) << r.message;
        updates.push_back(r.value);
    });
    ASSERT_TRUE(run_until([&] { return updates.size() == 1; })); // the first update, at once
    EXPECT_DOUBLE_EQ(updates[0].as_double(), 1.5);
    db_put("T:ao", 7); // above HIGH: MINOR
    ASSERT_TRUE(run_until([&] { return updates.size() == 2; }));
    EXPECT_DOUBLE_EQ(updates[1].as_double(), 7);
    EXPECT_EQ(updates[1].severity, pv::kMinor);
    EXPECT_EQ(updates[1].status, pv::kStatHigh);
    EXPECT_GT(updates[1].stamp.sec, 0u); // processed: the record's time (EPICS epoch)
    mon.reset();
    run_until([] { return false; }, 0.05); // the cancel goes out
    db_put("T:ao", 1);
    run_until([] { return false; }, 0.1);
    EXPECT_EQ(updates.size(), 2u);
}

TEST_F(ClientTest, ReconnectsAfterTheServerRestartsAndTheMonitorResumes) {
    ca::Client client(loop, client_config(port));
    auto ch = client.channel("T:ao");
    std::vector<bool> conn;
    ch->on_connection([&](bool up) { conn.push_back(up); });
    std::vector<double> values;
    auto mon = ch->monitor(pv::kDbeValue, [&](const ca::Result& r) {
        if (r.ok()) values.push_back(r.value.as_double());
    });
    ASSERT_TRUE(run_until([&] { return values.size() == 1; }));

    server.reset(); // the server goes away: the circuit closes
    ASSERT_TRUE(run_until([&] { return !ch->connected(); }));
    EXPECT_EQ(conn, (std::vector<bool>{true, false}));
    std::optional<ca::Result> got;
    ch->get([&](const ca::Result& r) { got = r; });
    ASSERT_TRUE(got.has_value());
    EXPECT_EQ(got->eca, ca::kEcaDisconn);
    EXPECT_FALSE(ch->put(1.0));

    db_put("T:ao", 4);
    start_server(); // same port
    ASSERT_TRUE(run_until([&] { return ch->connected() && values.size() == 2; }));
    EXPECT_EQ(conn, (std::vector<bool>{true, false, true}));
    EXPECT_DOUBLE_EQ(values[1], 4); // the monitor was re-added: its first update
    db_put("T:ao", 4.5);
    ASSERT_TRUE(run_until([&] { return values.size() == 3; }));
    EXPECT_DOUBLE_EQ(values[2], 4.5);
    EXPECT_GE(client.stats().circuits_closed, 1u);
}

TEST_F(ClientTest, AChannelOfAnUnknownNameStaysDisconnectedAndHandlesOutliveTheClient) {
    std::shared_ptr<ca::Channel> ch;
    std::shared_ptr<ca::Monitor> mon;
    {
        ca::Client client(loop, client_config(port));
        ch = client.channel("T:nobody");
        mon = ch->monitor(pv::kDbeValue, [](const ca::Result&) {});
        run_until([] { return false; }, 0.3);
        EXPECT_FALSE(ch->connected());
        EXPECT_GE(client.stats().search_datagrams, 2u); // retried
    }
    std::optional<ca::Result> got;
    ch->get([&](const ca::Result& r) { got = r; });
    ASSERT_TRUE(got.has_value());
    EXPECT_EQ(got->eca, ca::kEcaDisconn);
    mon.reset();
    ch.reset();
}

// ---- servers that misbehave -----------------------------------------------------------------

namespace {

// A fake server on the loop: answers every search with its TCP port, and on each accepted
// circuit sends what `on_accept` returns (nothing: a silent server).
struct FakeServer {
    EventLoop& loop;
    int udp = -1, lfd = -1;
    uint16_t port = 0;
    std::vector<int> conns;
    std::string greeting;
    FakeServer(EventLoop& l, uint16_t p, std::string hello, bool tcp = true)
        : loop(l), port(p), greeting(std::move(hello)) {
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        a.sin_port = htons(port);
        udp = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
        bind(udp, reinterpret_cast<sockaddr*>(&a), sizeof a);
        loop.add_fd(udp, EPOLLIN, [this](uint32_t) { on_udp(); });
        if (!tcp) return; // searches answered, connections refused
        lfd = socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK, 0);
        int one = 1;
        setsockopt(lfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        bind(lfd, reinterpret_cast<sockaddr*>(&a), sizeof a);
        listen(lfd, 8);
        loop.add_fd(lfd, EPOLLIN, [this](uint32_t) {
            int fd = accept4(lfd, nullptr, nullptr, SOCK_NONBLOCK);
            if (fd < 0) return;
            conns.push_back(fd);
            if (!greeting.empty()) (void)!::send(fd, greeting.data(), greeting.size(), MSG_NOSIGNAL);
            loop.add_fd(fd, EPOLLIN, [this, fd](uint32_t) {
                char buf[4096];
                if (recv(fd, buf, sizeof buf, 0) == 0) {
                    loop.remove_fd(fd);
                }
            });
        });
    }
    ~FakeServer() {
        for (int fd : conns) {
            loop.remove_fd(fd);
            close(fd);
        }
        loop.remove_fd(udp);
        close(udp);
        if (lfd >= 0) {
            loop.remove_fd(lfd);
            close(lfd);
        }
    }
    void on_udp() {
        uint8_t buf[2048];
        sockaddr_in from{};
        socklen_t len = sizeof from;
        ssize_t n = recvfrom(udp, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &len);
        if (n < 32) return;
        ca::Header h;
        ca::decode_header(buf + 16, std::size_t(n) - 16, true, h); // the first SEARCH
        std::string reply;
        ca::append_message(reply, ca::kVersion, 1, ca::kMinorVersion, 0, 0);
        uint8_t minor[8] = {0, ca::kMinorVersion};
        ca::append_message(reply, ca::kSearch, port, 0, 0xFFFFFFFF, h.p2, minor, sizeof minor);
        sendto(udp, reply.data(), reply.size(), 0, reinterpret_cast<sockaddr*>(&from), len);
    }
};

} // namespace

TEST(ClientMisbehavingServer, AnUnknownCommandIsCountedAndTheCircuitClosed) {
    EventLoop loop;
    uint16_t port = free_port();
    std::string bad;
    ca::append_message(bad, ca::kVersion, 0, ca::kMinorVersion, 0, 0);
    ca::append_message(bad, 999, 0, 0, 0, 0);
    FakeServer fake(loop, port, bad);
    ca::Client client(loop, client_config(port));
    auto ch = client.channel("X:pv");
    double end = EventLoop::now_s() + 10;
    auto id = loop.call_every(0.002, [&] {
        if (client.stats().protocol_errors >= 1 || EventLoop::now_s() > end) loop.stop();
    });
    loop.run();
    loop.cancel(id);
    EXPECT_GE(client.stats().protocol_errors, 1u);
    EXPECT_GE(client.stats().circuits_closed, 1u);
    EXPECT_FALSE(ch->connected());
}

TEST(ClientMisbehavingServer, ASilentServerIsDetectedByTheEchoTimeout) {
    EventLoop loop;
    uint16_t port = free_port();
    FakeServer fake(loop, port, ""); // accepts, never answers
    ca::ClientConfig cfg = client_config(port);
    cfg.conn_tmo_s = 0.1;
    cfg.echo_timeout_s = 0.1;
    ca::Client client(loop, cfg);
    auto ch = client.channel("X:pv");
    double end = EventLoop::now_s() + 10;
    auto id = loop.call_every(0.002, [&] {
        if (client.stats().echo_timeouts >= 1 || EventLoop::now_s() > end) loop.stop();
    });
    loop.run();
    loop.cancel(id);
    EXPECT_GE(client.stats().echo_timeouts, 1u);
    EXPECT_FALSE(ch->connected());
}

TEST(ClientMisbehavingServer, AServerThatRefusesConnectionsIsRetriedWithBackOff) {
    EventLoop loop;
    uint16_t port = free_port();
    FakeServer fake(loop, port, "", false);
    ca::ClientConfig cfg = client_config(port);
    cfg.search_max_s = 0.2;
    ca::Client client(loop, cfg);
    auto ch = client.channel("X:pv");
    loop.call_after(1.0, [&] { loop.stop(); });
    loop.run();
    EXPECT_FALSE(ch->connected());
    EXPECT_GE(client.stats().circuits_opened, 3u);  // it keeps trying ...
    EXPECT_LE(client.stats().circuits_opened, 15u); // ... at the back-off's pace, not every tick (50)
}

namespace {
struct NullHandler : ca::ClientCircuitHandler {
    int reads = 0;
    void on_server_version(uint16_t) override {}
    void on_access_rights(uint32_t, uint32_t) override {}
    void on_create_chan(uint32_t, uint32_t, uint16_t, uint32_t) override {}
    void on_create_fail(uint32_t) override {}
    void on_server_disconn(uint32_t) override {}
    void on_read(uint32_t, uint32_t, uint16_t, uint32_t, const uint8_t*, std::size_t) override { ++reads; }
    void on_event(uint32_t, uint32_t, uint16_t, uint32_t, const uint8_t*, std::size_t) override {}
    void on_event_cancelled(uint32_t) override {}
    void on_write_notify(uint32_t, uint32_t) override {}
    void on_error(uint32_t, uint32_t, const ca::Header&, std::string_view) override {}
    void on_echo() override {}
};
} // namespace

TEST(ClientCircuitCore, AValueReplyShorterThanItsTypeNeedsClosesTheCircuit) {
    NullHandler h;
    ca::ClientStats stats;
    ca::ClientCircuit c(h, stats);
    std::string msg;
    uint8_t payload[8] = {};
    ca::append_message(msg, ca::kReadNotify, 20, 1, ca::kEcaNormal, 7, payload, sizeof payload); // TIME_DOUBLE: 24 bytes
    std::string good;
    uint8_t dbl[8] = {};
    ca::append_message(good, ca::kReadNotify, 6, 1, ca::kEcaNormal, 8, dbl, sizeof dbl);
    c.receive(reinterpret_cast<const uint8_t*>(good.data()), good.size());
    EXPECT_EQ(h.reads, 1);
    c.receive(reinterpret_cast<const uint8_t*>(msg.data()), msg.size());
    EXPECT_TRUE(c.wants_close());
    EXPECT_EQ(stats.protocol_errors, 1u);
    EXPECT_NE(c.error().find("DBR type 20"), std::string::npos) << c.error();
    c.receive(reinterpret_cast<const uint8_t*>(good.data()), good.size()); // ignored once closed
    EXPECT_EQ(h.reads, 1);
}

TEST(ClientCircuitCore, ATruncatedSearchReplyIsCountedAndWhatCameBeforeKept) {
    std::string d;
    ca::append_message(d, ca::kVersion, 1, ca::kMinorVersion, 0, 0);
    uint8_t minor[8] = {0, 13};
    ca::append_message(d, ca::kSearch, 5064, 0, 0xFFFFFFFF, 42, minor, sizeof minor);
    ca::append_message(d, ca::kSearch, 5064, 0, 0xFFFFFFFF, 43, minor, sizeof minor);
    d.resize(d.size() - 4);
    std::vector<ca::SearchReply> replies;
    std::vector<ca::Beacon> beacons;
    ca::ClientStats stats;
    EXPECT_FALSE(ca::parse_client_datagram(reinterpret_cast<const uint8_t*>(d.data()), d.size(), 0x7F000001,
                                           replies, beacons, stats));
    ASSERT_EQ(replies.size(), 1u);
    EXPECT_EQ(replies[0].search_id, 42u);
    EXPECT_EQ(replies[0].server_ip, 0x7F000001u);
    EXPECT_EQ(replies[0].server_port, 5064);
    EXPECT_EQ(stats.udp_malformed, 1u);
}
