#include "ca/client.hpp"
#include "ca/net.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/convert.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <ifaddrs.h>
#include <map>
#include <net/if.h>
#include <netdb.h>
#include <netinet/tcp.h>
#include <pwd.h>
#include <set>
#include <sstream>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::ca {
namespace {
log::Logger lg("ca.client");

constexpr uint32_t kLoopbackIp = 0x7F000001;
constexpr double kTick_s = 0.02;          // search and echo bookkeeping period
constexpr double kRegister_s = 30.0;      // repeater registration refresh

double env_seconds(const char* name, double def) {
    const char* v = env(name);
    if (!v) return def;
    char* end;
    double s = std::strtod(v, &end);
    if (*end || !(s > 0)) throw Error(SB() << name << "='" << v << "' should be seconds > 0");
    return s;
}

bool env_yes_no(const char* name, bool def) {
    const char* v = env(name);
    if (!v) return def;
    std::string s(v);
    for (auto& c : s) c = char(std::toupper(static_cast<unsigned char>(c)));
    if (s == "YES") return true;
    if (s == "NO") return false;
    throw Error(SB() << name << "='" << v << "' should be YES or NO");
}

// "host[:port]" (an IPv4 address or a name) as a UDP destination.
sockaddr_in parse_target(const std::string& item, uint16_t def_port, const char* var) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    std::string host = item;
    uint16_t port = def_port;
    auto colon = item.rfind(':');
    if (colon != std::string::npos) {
        host = item.substr(0, colon);
        char* end;
        long p = std::strtol(item.c_str() + colon + 1, &end, 10);
        if (*end || p <= 0 || p > 65535) throw Error(SB() << var << ": bad port in '" << item << "'");
        port = uint16_t(p);
    }
    if (inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1) {
        addrinfo hints{}, *res = nullptr;
        hints.ai_family = AF_INET;
        if (getaddrinfo(host.c_str(), nullptr, &hints, &res) != 0 || !res)
            throw Error(SB() << var << ": '" << item << "' is neither an IPv4 address nor a known host name");
        a.sin_addr = reinterpret_cast<sockaddr_in*>(res->ai_addr)->sin_addr;
        freeaddrinfo(res);
    }
    a.sin_port = htons(port);
    return a;
}

std::string ip_port(uint32_t ip, uint16_t port) {
    in_addr a{};
    a.s_addr = htonl(ip);
    char buf[INET_ADDRSTRLEN];
    inet_ntop(AF_INET, &a, buf, sizeof buf);
    return SB() << buf << ":" << port;
}

uint16_t time_dbr(pv::Prim p) { return uint16_t(14 + int(p)); }

} // namespace

ClientConfig ClientConfig::from_env() {
    ClientConfig c;
    c.server_port = env_port("EPICS_CA_SERVER_PORT", kDefaultServerPort);
    c.repeater_port = env_port("EPICS_CA_REPEATER_PORT", kDefaultRepeaterPort);
    if (const char* v = env("EPICS_CA_ADDR_LIST")) {
        std::istringstream is(v);
        std::string w;
        while (is >> w) c.addr_list.push_back(parse_target(w, c.server_port, "EPICS_CA_ADDR_LIST"));
    }
    c.auto_addr_list = env_yes_no("EPICS_CA_AUTO_ADDR_LIST", true);
    c.conn_tmo_s = env_seconds("EPICS_CA_CONN_TMO", c.conn_tmo_s);
    c.search_max_s = env_seconds("EPICS_CA_MAX_SEARCH_PERIOD", c.search_max_s);
    return c;
}

double Value::as_double(std::size_t i) const {
    if (i >= count || data.size() < (i + 1) * pv::prim_size(prim)) return 0;
    const char* p = data.data() + i * pv::prim_size(prim);
    switch (prim) {
    case pv::Prim::String: {
        double v = 0;
        return pv::parse_double(std::string_view(p, strnlen(p, pv::kStringSize)), v) ? v : 0;
    }
    case pv::Prim::Short: { int16_t v; std::memcpy(&v, p, 2); return v; }
    case pv::Prim::Enum: { uint16_t v; std::memcpy(&v, p, 2); return v; }
    case pv::Prim::Char: return double(uint8_t(*p));
    case pv::Prim::Long: { int32_t v; std::memcpy(&v, p, 4); return v; }
    case pv::Prim::Float: { float v; std::memcpy(&v, p, 4); return v; }
    case pv::Prim::Double: { double v; std::memcpy(&v, p, 8); return v; }
    }
    return 0;
}

std::string Value::as_string(std::size_t i) const {
    if (i >= count || data.size() < (i + 1) * pv::prim_size(prim)) return {};
    if (prim == pv::Prim::String) {
        const char* p = data.data() + i * pv::kStringSize;
        return std::string(p, strnlen(p, pv::kStringSize));
    }
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.17g", as_double(i));
    return buf;
}

std::vector<double> Value::as_doubles() const {
    std::vector<double> v(count);
    for (uint32_t i = 0; i < count; ++i) v[i] = as_double(i);
    return v;
}

// ---------------------------------------------------------------------------------------------

struct ClientImpl : std::enable_shared_from_this<ClientImpl> {
    struct Circ;
    enum class ChanState : uint8_t { Searching, Connecting, Connected };
    struct Chan {
        uint32_t cid;
        std::string name;
        uint16_t priority;
        ChanState state = ChanState::Searching;
        Circ* circ = nullptr;
        uint32_t sid = 0;
        pv::Prim native = pv::Prim::Double;
        uint32_t count = 0;
        uint32_t rights = 0;
        double next_search_s = 0;
        double interval_s = 0;
        std::vector<std::function<void(bool)>> conn_cbs;
        std::set<uint32_t> subids;
    };
    struct Mon {
        uint32_t cid;
        unsigned mask;
        int dbr;
        ResultCallback cb;
        bool added = false;
        uint16_t dtype = 0;
        uint32_t count = 0;
    };
    struct Io {
        uint32_t cid;
        Circ* circ;
        ResultCallback cb;
    };
    // One TCP circuit; receives the parsed messages of its ClientCircuit.
    struct Circ : ClientCircuitHandler {
        ClientImpl& c;
        int fd = -1;
        uint32_t ip;
        uint16_t port;
        uint16_t priority;
        bool established = false;
        bool want_out = false;
        double opened_s, last_rx_s;
        bool echo_pending = false;
        double echo_sent_s = 0;
        std::set<uint32_t> cids;
        ClientCircuit core;
        Circ(ClientImpl& impl, uint32_t ip_, uint16_t port_, uint16_t prio)
            : c(impl), ip(ip_), port(port_), priority(prio), core(*this, impl.stats) {
            opened_s = last_rx_s = EventLoop::now_s();
        }
        void on_server_version(uint16_t) override {}
        void on_access_rights(uint32_t cid, uint32_t rights) override { c.access_rights(*this, cid, rights); }
        void on_create_chan(uint32_t cid, uint32_t sid, uint16_t t, uint32_t n) override {
            c.created(*this, cid, sid, t, n);
        }
        void on_create_fail(uint32_t cid) override { c.create_failed(*this, cid, "CREATE_CH_FAIL"); }
        void on_server_disconn(uint32_t cid) override { c.server_disconn(*this, cid); }
        void on_read(uint32_t ioid, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) override {
            c.io_value(ioid, st, t, n, p, len);
        }
        void on_event(uint32_t subid, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) override {
            c.mon_value(subid, st, t, n, p, len);
        }
        void on_event_cancelled(uint32_t) override {}
        void on_write_notify(uint32_t ioid, uint32_t st) override { c.io_done(ioid, st, {}); }
        void on_error(uint32_t cid, uint32_t eca, const Header& req, std::string_view text) override {
            c.server_error(*this, cid, eca, req, text);
        }
        void on_echo() override { echo_pending = false; }
    };

    EventLoop& loop;
    ClientConfig cfg;
    ClientStats stats;
    int udp_fd = -1;
    std::vector<sockaddr_in> targets;
    std::map<uint32_t, std::unique_ptr<Chan>> chans;
    std::map<uint32_t, Mon> mons;
    std::map<uint32_t, Io> ios;
    std::map<int, std::unique_ptr<Circ>> circs;
    std::map<std::pair<uint32_t, uint16_t>, uint32_t> beacon_ids; // last beacon id per server
    std::set<Circ*> dirty;
    std::vector<std::function<void()>> deferred; // callbacks to run once the state is consistent
    uint32_t next_cid = 1, next_subid = 1, next_ioid = 1;
    EventLoop::TimerId tick_timer = 0, soon_timer = 0;
    EventLoop::HookId flush_hook = 0;
    double registered_s = -1e9;
    bool shut = false;
    std::vector<uint8_t> rxbuf = std::vector<uint8_t>(64 * 1024);

    ClientImpl(EventLoop& l, ClientConfig c) : loop(l), cfg(std::move(c)) {}

    void start() {
        udp_fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
        if (udp_fd < 0) throw Error(SB() << "CA client: cannot create a UDP socket: " << std::strerror(errno));
        int one = 1;
        setsockopt(udp_fd, SOL_SOCKET, SO_BROADCAST, &one, sizeof one);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        if (bind(udp_fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
            throw Error(SB() << "CA client: cannot bind a UDP socket: " << std::strerror(errno));
        targets = cfg.addr_list;
        if (cfg.auto_addr_list)
            for (in_addr b : interface_broadcasts()) {
                sockaddr_in t{};
                t.sin_family = AF_INET;
                t.sin_addr = b;
                t.sin_port = htons(cfg.server_port);
                targets.push_back(t);
            }
        if (targets.empty())
            LOG_WARN(lg, "no search destinations: EPICS_CA_ADDR_LIST is empty and no interface has a broadcast "
                         "address; channels will not connect");
        loop.add_fd(udp_fd, EPOLLIN, [this](uint32_t) { on_udp(); });
        tick_timer = loop.call_every(kTick_s, [this] { tick(); });
        std::weak_ptr<ClientImpl> w = weak_from_this();
        flush_hook = loop.add_after_batch([w] {
            if (auto s = w.lock()) s->flush_dirty();
        });
        if (cfg.user.empty()) {
            passwd* pw = getpwuid(getuid());
            cfg.user = pw ? pw->pw_name : "beamctl";
        }
        if (cfg.host.empty()) {
            char h[256] = {};
            gethostname(h, sizeof h - 1);
            cfg.host = h;
        }
    }

    void shutdown() {
        if (shut) return;
        shut = true;
        if (tick_timer) loop.cancel(tick_timer);
        if (flush_hook) loop.remove_after_batch(flush_hook);
        flush_hook = 0;
        if (soon_timer) loop.cancel(soon_timer);
        for (auto& [fd, c] : circs) {
            loop.remove_fd(fd);
            ::close(fd);
        }
        circs.clear();
        dirty.clear();
        if (udp_fd >= 0) {
            loop.remove_fd(udp_fd);
            ::close(udp_fd);
            udp_fd = -1;
        }
        chans.clear();
        mons.clear();
        ios.clear();
    }

    void run_deferred() {
        auto keep = shared_from_this(); // a callback may destroy the Client
        while (!deferred.empty()) {
            std::vector<std::function<void()>> d;
            d.swap(deferred);
            for (auto& f : d) f();
        }
    }

    Chan* chan(uint32_t cid) {
        auto it = chans.find(cid);
        return it == chans.end() ? nullptr : it->second.get();
    }
    // The channel cid if it is on circuit c (replies for a channel that moved are ignored).
    Chan* chan_on(Circ& c, uint32_t cid) {
        Chan* ch = chan(cid);
        return ch && ch->circ == &c ? ch : nullptr;
    }

    // ---- searching ----
    void search_soon() {
        if (soon_timer || shut) return;
        soon_timer = loop.call_after(0, [this] {
            soon_timer = 0;
            send_searches();
        });
    }

    void restart_search(Chan& ch) {
        ch.state = ChanState::Searching;
        ch.circ = nullptr;
        ch.interval_s = cfg.search_min_s;
        ch.next_search_s = 0;
        search_soon();
    }

    void send_searches() {
        if (udp_fd < 0 || targets.empty()) return;
        double now = EventLoop::now_s();
        std::string dgram;
        auto flush = [&] {
            if (dgram.size() <= 16) return;
            for (const sockaddr_in& t : targets)
                sendto(udp_fd, dgram.data(), dgram.size(), 0, reinterpret_cast<const sockaddr*>(&t), sizeof t);
            stats.search_datagrams++;
            dgram.clear();
        };
        for (auto& [cid, ch] : chans) {
            if (ch->state != ChanState::Searching || ch->next_search_s > now) continue;
            if (dgram.empty()) append_message(dgram, kVersion, 0, kMinorVersion, 0, 0);
            std::size_t need = 16 + pad8(ch->name.size() + 1);
            if (dgram.size() + need > kMaxUdpReply && dgram.size() > 16) {
                flush();
                append_message(dgram, kVersion, 0, kMinorVersion, 0, 0);
            }
            append_message(dgram, kSearch, kSearchDontReply, kMinorVersion, cid, cid, ch->name.c_str(),
                           ch->name.size() + 1);
            if (ch->interval_s <= 0) ch->interval_s = cfg.search_min_s;
            ch->next_search_s = now + ch->interval_s;
            ch->interval_s = std::min(ch->interval_s * 2, cfg.search_max_s);
        }
        flush();
    }

    void on_udp() {
        uint8_t buf[4096];
        for (int i = 0; i < 64; ++i) {
            sockaddr_in from{};
            socklen_t len = sizeof from;
            ssize_t n = recvfrom(udp_fd, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &len);
            if (n < 0) break;
            std::vector<SearchReply> replies;
            std::vector<Beacon> beacons;
            parse_client_datagram(buf, std::size_t(n), ntohl(from.sin_addr.s_addr), replies, beacons, stats);
            for (const SearchReply& r : replies) found(r);
            for (const Beacon& b : beacons) beacon(b);
        }
        run_deferred();
    }

    void beacon(const Beacon& b) {
        auto key = std::make_pair(b.server_ip, b.server_port);
        auto it = beacon_ids.find(key);
        // A new server, or one whose beacon ids started again (it restarted): search now.
        bool anomaly = it == beacon_ids.end() || (b.id != it->second && b.id != it->second + 1);
        beacon_ids[key] = b.id;
        if (!anomaly) return;
        bool any = false;
        for (auto& [cid, ch] : chans)
            if (ch->state == ChanState::Searching) {
                ch->interval_s = cfg.search_min_s;
                ch->next_search_s = 0;
                any = true;
            }
        if (any) search_soon();
    }

    void found(const SearchReply& r) {
        Chan* ch = chan(r.search_id);
        if (!ch || ch->state != ChanState::Searching) return; // late or duplicate reply
        Circ* c = nullptr;
        for (auto& [fd, x] : circs)
            if (x->ip == r.server_ip && x->port == r.server_port && x->priority == ch->priority) c = x.get();
        if (!c) c = open_circuit(r.server_ip, r.server_port, ch->priority);
        if (!c) {
            ch->next_search_s = EventLoop::now_s() + ch->interval_s;
            return;
        }
        ch->state = ChanState::Connecting;
        ch->circ = c;
        c->cids.insert(ch->cid);
        if (c->established) {
            c->core.create_chan(ch->cid, ch->name);
            mark(*c);
        }
    }

    // ---- circuits ----
    Circ* open_circuit(uint32_t ip, uint16_t port, uint16_t priority) {
        int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
        if (fd < 0) {
            LOG_WARN(lg, "cannot create a TCP socket: " << std::strerror(errno));
            return nullptr;
        }
        int one = 1;
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &one, sizeof one);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(ip);
        a.sin_port = htons(port);
        if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 && errno != EINPROGRESS) {
            LOG_DEBUG(lg, "connect to " << ip_port(ip, port) << ": " << std::strerror(errno));
            ::close(fd);
            return nullptr;
        }
        auto c = std::make_unique<Circ>(*this, ip, port, priority);
        c->fd = fd;
        Circ* raw = c.get();
        circs.emplace(fd, std::move(c));
        stats.circuits_opened++;
        loop.add_fd(fd, EPOLLIN | EPOLLOUT, [this, fd](uint32_t ev) { on_circ_io(fd, ev); });
        raw->want_out = true;
        return raw;
    }

    void on_circ_io(int fd, uint32_t events) {
        auto it = circs.find(fd);
        if (it == circs.end()) return;
        Circ& c = *it->second;
        if (!c.established) {
            int err = 0;
            socklen_t len = sizeof err;
            getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
            if (err || (events & (EPOLLERR | EPOLLHUP))) {
                LOG_DEBUG(lg, "connect to " << ip_port(c.ip, c.port) << ": " << std::strerror(err ? err : ECONNREFUSED));
                circuit_dead(c, "connection refused");
                run_deferred();
                return;
            }
            if (!(events & EPOLLOUT)) return;
            c.established = true;
            c.last_rx_s = EventLoop::now_s();
            c.core.send_hello(c.priority, cfg.user, cfg.host);
            for (uint32_t cid : c.cids)
                if (Chan* ch = chan(cid)) c.core.create_chan(cid, ch->name);
            LOG_DEBUG(lg, "circuit to " << ip_port(c.ip, c.port) << " open");
        }
        if (events & (EPOLLIN | EPOLLERR | EPOLLHUP)) {
            for (;;) {
                ssize_t n = ::recv(fd, rxbuf.data(), rxbuf.size(), 0);
                if (n > 0) {
                    c.last_rx_s = EventLoop::now_s();
                    c.echo_pending = false;
                    c.core.receive(rxbuf.data(), std::size_t(n));
                    if (c.core.wants_close()) {
                        LOG_WARN(lg, "circuit to " << ip_port(c.ip, c.port) << " closed: " << c.core.error());
                        circuit_dead(c, c.core.error());
                        run_deferred();
                        return;
                    }
                    if (circs.find(fd) == circs.end()) break;
                    if (std::size_t(n) < rxbuf.size()) break; // emptied: later data wakes the loop again
                    continue;
                }
                if (n < 0 && errno == EINTR) continue;
                if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
                LOG_INFO(lg, "circuit to " << ip_port(c.ip, c.port) << " closed by the server");
                circuit_dead(c, "closed by the server");
                run_deferred();
                return;
            }
        }
        if (circs.count(fd)) flush(c);
        run_deferred();
    }

    void mark(Circ& c) { dirty.insert(&c); }

    void flush_dirty() {
        std::set<Circ*> d;
        d.swap(dirty);
        for (Circ* c : d) {
            auto it = std::find_if(circs.begin(), circs.end(), [c](const auto& x) { return x.second.get() == c; });
            if (it != circs.end()) flush(*c);
        }
        run_deferred();
    }

    void flush(Circ& c) {
        if (!c.established) return;
        for (;;) {
            std::string_view out = c.core.pending_output();
            if (out.empty()) break;
            ssize_t n = ::send(c.fd, out.data(), out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
            if (n > 0) {
                c.core.consume_output(std::size_t(n));
                continue;
            }
            if (n < 0 && errno == EINTR) continue;
            if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
            circuit_dead(c, SB() << "send failed: " << std::strerror(errno));
            return;
        }
        bool want = c.core.output_size() > 0;
        if (want != c.want_out) {
            c.want_out = want;
            loop.modify_fd(c.fd, EPOLLIN | (want ? uint32_t(EPOLLOUT) : 0u));
        }
    }

    // The circuit is gone: its channels disconnect and search again, their pending gets and
    // puts fail with ECA_DISCONN, their monitors wait to be re-added.
    void circuit_dead(Circ& c, const std::string& why) {
        int fd = c.fd;
        std::unique_ptr<Circ> keep;
        {
            auto it = circs.find(fd);
            if (it == circs.end()) return;
            keep = std::move(it->second);
            circs.erase(it);
        }
        dirty.erase(&c);
        loop.remove_fd(fd);
        ::close(fd);
        stats.circuits_closed++;
        LOG_DEBUG(lg, "circuit to " << ip_port(c.ip, c.port) << " gone: " << why);
        std::set<uint32_t> cids;
        cids.swap(c.cids);
        for (uint32_t cid : cids) // a server that never accepted keeps the back-off (no 50 Hz retries)
            if (Chan* ch = chan(cid); ch && ch->circ == &c) disconnect(*ch, c.established);
        for (auto it = ios.begin(); it != ios.end();) {
            if (it->second.circ == &c) {
                ResultCallback cb = std::move(it->second.cb);
                it = ios.erase(it);
                if (cb) deferred.push_back([cb] { cb(Result{kEcaDisconn, eca_message(kEcaDisconn), {}}); });
            } else {
                ++it;
            }
        }
    }

    void disconnect(Chan& ch, bool reset_backoff = true) {
        bool was = ch.state == ChanState::Connected;
        if (ch.circ) ch.circ->cids.erase(ch.cid);
        for (uint32_t s : ch.subids)
            if (auto m = mons.find(s); m != mons.end()) m->second.added = false;
        ch.rights = 0;
        if (reset_backoff) {
            restart_search(ch);
        } else {
            ch.state = ChanState::Searching;
            ch.circ = nullptr;
            ch.next_search_s = EventLoop::now_s() + ch.interval_s;
        }
        if (was) {
            stats.reconnects++;
            for (auto& f : ch.conn_cbs) deferred.push_back([f] { f(false); });
        }
    }

    // ---- circuit messages ----
    void access_rights(Circ& c, uint32_t cid, uint32_t rights) {
        if (Chan* ch = chan_on(c, cid)) ch->rights = rights;
    }

    void created(Circ& c, uint32_t cid, uint32_t sid, uint16_t t, uint32_t n) {
        Chan* ch = chan_on(c, cid);
        if (!ch || ch->state != ChanState::Connecting) return;
        ch->state = ChanState::Connected;
        ch->sid = sid;
        ch->native = pv::Prim(t);
        ch->count = n;
        for (uint32_t s : ch->subids) add_monitor(*ch, s);
        for (auto& f : ch->conn_cbs) deferred.push_back([f] { f(true); });
        mark(c);
    }

    void create_failed(Circ& c, uint32_t cid, const char* why) {
        Chan* ch = chan_on(c, cid);
        if (!ch) return;
        LOG_DEBUG(lg, "channel " << ch->name << ": " << why << " from " << ip_port(c.ip, c.port));
        c.cids.erase(cid);
        ch->state = ChanState::Searching; // keeps its back-off: the server may know it again later
        ch->circ = nullptr;
        ch->next_search_s = EventLoop::now_s() + ch->interval_s;
    }

    void server_disconn(Circ& c, uint32_t cid) {
        if (Chan* ch = chan_on(c, cid)) {
            for (auto it = ios.begin(); it != ios.end();) {
                if (it->second.cid == cid) {
                    ResultCallback cb = std::move(it->second.cb);
                    it = ios.erase(it);
                    if (cb) deferred.push_back([cb] { cb(Result{kEcaDisconn, eca_message(kEcaDisconn), {}}); });
                } else {
                    ++it;
                }
            }
            disconnect(*ch);
        }
    }

    void io_value(uint32_t ioid, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) {
        auto it = ios.find(ioid);
        if (it == ios.end()) return;
        ResultCallback cb = std::move(it->second.cb);
        ios.erase(it);
        Result r;
        r.eca = st;
        if (r.ok() && !decode_dbr(t, p, len, n, r.value)) r.eca = kEcaBadType;
        r.message = eca_message(r.eca);
        if (cb) deferred.push_back([cb, r = std::move(r)] { cb(r); });
    }

    void io_done(uint32_t ioid, uint32_t st, std::string_view text) {
        auto it = ios.find(ioid);
        if (it == ios.end()) return;
        ResultCallback cb = std::move(it->second.cb);
        ios.erase(it);
        Result r;
        r.eca = st;
        r.message = text.empty() ? eca_message(st) : std::string(text);
        if (cb) deferred.push_back([cb, r = std::move(r)] { cb(r); });
    }

    void mon_value(uint32_t subid, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) {
        auto it = mons.find(subid);
        if (it == mons.end() || !it->second.added) return;
        Result r;
        r.eca = st;
        if (r.ok() && !decode_dbr(t, p, len, n, r.value)) r.eca = kEcaBadType;
        r.message = eca_message(r.eca);
        ResultCallback cb = it->second.cb;
        if (cb) deferred.push_back([cb, r = std::move(r)] { cb(r); });
    }

    void server_error(Circ& c, uint32_t cid, uint32_t eca, const Header& req, std::string_view text) {
        switch (req.cmd) {
        case kReadNotify:
        case kWriteNotify: io_done(req.p2, eca, text); return;
        case kEventAdd:
            if (auto m = mons.find(req.p2); m != mons.end()) {
                Result r{eca, std::string(text), {}};
                ResultCallback cb = m->second.cb;
                if (cb) deferred.push_back([cb, r] { cb(r); });
            }
            return;
        case kCreateChan: create_failed(c, req.p1, "ERROR"); return;
        default: break;
        }
        Chan* ch = chan(cid);
        LOG_WARN(lg, "server " << ip_port(c.ip, c.port) << (ch ? " channel " + ch->name : std::string()) << ": "
                               << eca_message(eca) << (text.empty() ? "" : ": ") << text);
    }

    // ---- periodic ----
    void tick() {
        double now = EventLoop::now_s();
        send_searches();
        if (now - registered_s > kRegister_s && udp_fd >= 0) { // beacons through the repeater
            registered_s = now;
            uint8_t reg[16];
            encode_header(reg, kRepeaterRegister, 0, 0, 0, 0, kLoopbackIp);
            sockaddr_in to{};
            to.sin_family = AF_INET;
            to.sin_addr.s_addr = htonl(kLoopbackIp);
            to.sin_port = htons(cfg.repeater_port);
            sendto(udp_fd, reg, sizeof reg, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
        }
        std::vector<Circ*> dead;
        for (auto& [fd, c] : circs) {
            if (!c->established) {
                if (now - c->opened_s > cfg.conn_tmo_s) dead.push_back(c.get());
                continue;
            }
            if (c->echo_pending) {
                if (now - c->echo_sent_s > cfg.echo_timeout_s) dead.push_back(c.get());
            } else if (now - c->last_rx_s > cfg.conn_tmo_s) {
                c->echo_pending = true;
                c->echo_sent_s = now;
                c->core.echo();
                mark(*c);
            }
        }
        for (Circ* c : dead) {
            stats.echo_timeouts++;
            LOG_WARN(lg, "circuit to " << ip_port(c->ip, c->port) << " unresponsive: disconnecting");
            circuit_dead(*c, "unresponsive");
        }
        run_deferred();
    }

    // ---- requests ----
    void add_monitor(Chan& ch, uint32_t subid) {
        auto it = mons.find(subid);
        if (it == mons.end() || ch.state != ChanState::Connected) return;
        Mon& m = it->second;
        m.dtype = m.dbr >= 0 ? uint16_t(m.dbr) : time_dbr(ch.native);
        m.count = ch.circ->core.server_minor() >= 13 ? 0 : ch.count;
        m.added = true;
        ch.circ->core.event_add(ch.sid, subid, m.dtype, m.count, uint16_t(m.mask));
        mark(*ch.circ);
    }

    void cancel_monitor(uint32_t subid) {
        auto it = mons.find(subid);
        if (it == mons.end()) return;
        Mon m = std::move(it->second);
        mons.erase(it);
        Chan* ch = chan(m.cid);
        if (!ch) return;
        ch->subids.erase(subid);
        if (m.added && ch->state == ChanState::Connected) {
            ch->circ->core.event_cancel(ch->sid, subid, m.dtype, m.count);
            mark(*ch->circ);
        }
    }

    void drop_channel(uint32_t cid) {
        Chan* ch = chan(cid);
        if (!ch) return;
        for (uint32_t s : ch->subids) mons.erase(s);
        for (auto it = ios.begin(); it != ios.end();) it = it->second.cid == cid ? ios.erase(it) : std::next(it);
        if (ch->circ) {
            if (ch->state == ChanState::Connected) {
                ch->circ->core.clear_chan(ch->sid, cid);
                mark(*ch->circ);
            }
            ch->circ->cids.erase(cid);
        }
        chans.erase(cid);
    }

    uint32_t new_ioid(Chan& ch, ResultCallback cb) {
        uint32_t ioid = next_ioid++;
        ios.emplace(ioid, Io{ch.cid, ch.circ, std::move(cb)});
        return ioid;
    }

    void get(uint32_t cid, ResultCallback cb, int dbr, uint32_t count) {
        Chan* ch = chan(cid);
        if (!ch || ch->state != ChanState::Connected) {
            if (cb) cb(Result{kEcaDisconn, eca_message(kEcaDisconn), {}});
            return;
        }
        uint16_t t = dbr >= 0 ? uint16_t(dbr) : time_dbr(ch->native);
        if (t > 34) {
            if (cb) cb(Result{kEcaBadType, eca_message(kEcaBadType), {}});
            return;
        }
        if (count == 0 && ch->circ->core.server_minor() < 13) count = ch->count;
        uint32_t ioid = new_ioid(*ch, std::move(cb));
        ch->circ->core.read_notify(ch->sid, ioid, t, count);
        mark(*ch->circ);
    }

    bool put(uint32_t cid, pv::Prim t, const void* data, uint32_t n, ResultCallback cb) {
        Chan* ch = chan(cid);
        if (!ch || ch->state != ChanState::Connected || n == 0) {
            uint32_t eca = n == 0 ? kEcaBadCount : kEcaDisconn;
            if (cb) cb(Result{eca, eca_message(eca), {}});
            return false;
        }
        std::vector<uint8_t> payload(std::size_t(n) * pv::prim_size(t));
        std::memcpy(payload.data(), data, payload.size());
        host_to_wire(t, payload.data(), n);
        if (cb) {
            uint32_t ioid = new_ioid(*ch, std::move(cb));
            ch->circ->core.write_notify(ch->sid, ioid, uint16_t(t), n, payload.data(), payload.size());
        } else {
            ch->circ->core.write(ch->sid, cid, uint16_t(t), n, payload.data(), payload.size());
        }
        mark(*ch->circ);
        return true;
    }
};

// ---------------------------------------------------------------------------------------------

Client::Client(EventLoop& loop, ClientConfig cfg) : impl_(std::make_shared<ClientImpl>(loop, std::move(cfg))) {
    impl_->start();
}

Client::~Client() { impl_->shutdown(); }

std::shared_ptr<Channel> Client::channel(const std::string& name, uint16_t priority) {
    if (name.empty()) throw Error("CA client: a channel needs a name");
    if (priority > 99) throw Error(SB() << "CA client: channel " << name << ": priority " << priority << " should be 0..99");
    uint32_t cid = impl_->next_cid++;
    auto ch = std::make_unique<ClientImpl::Chan>();
    ch->cid = cid;
    ch->name = name;
    ch->priority = priority;
    impl_->chans.emplace(cid, std::move(ch));
    impl_->restart_search(*impl_->chans[cid]);
    return std::shared_ptr<Channel>(new Channel(impl_, cid, name));
}

const ClientStats& Client::stats() const { return impl_->stats; }
std::size_t Client::circuit_count() const { return impl_->circs.size(); }

Monitor::~Monitor() {
    if (auto s = impl_.lock()) s->cancel_monitor(subid_);
}

Channel::~Channel() {
    if (auto s = impl_.lock()) s->drop_channel(cid_);
}

bool Channel::connected() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    return ch && ch->state == ClientImpl::ChanState::Connected;
}

pv::Prim Channel::native_type() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    return ch ? ch->native : pv::Prim::Double;
}

uint32_t Channel::element_count() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    return ch && ch->state == ClientImpl::ChanState::Connected ? ch->count : 0;
}

bool Channel::read_access() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    return ch && ch->state == ClientImpl::ChanState::Connected && (ch->rights & 1);
}

bool Channel::write_access() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    return ch && ch->state == ClientImpl::ChanState::Connected && (ch->rights & 2);
}

std::string Channel::server() const {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    if (!ch || ch->state != ClientImpl::ChanState::Connected) return {};
    return ip_port(ch->circ->ip, ch->circ->port);
}

void Channel::on_connection(std::function<void(bool)> fn) {
    auto s = impl_.lock();
    auto* ch = s ? s->chan(cid_) : nullptr;
    if (!ch || !fn) return;
    ch->conn_cbs.push_back(fn);
    if (ch->state == ClientImpl::ChanState::Connected) fn(true);
}

void Channel::get(ResultCallback cb, int dbr, uint32_t count) {
    if (auto s = impl_.lock()) s->get(cid_, std::move(cb), dbr, count);
    else if (cb) cb(Result{kEcaDisconn, eca_message(kEcaDisconn), {}});
}

bool Channel::put_raw(pv::Prim t, const void* data, uint32_t n, ResultCallback cb) {
    if (auto s = impl_.lock()) return s->put(cid_, t, data, n, std::move(cb));
    if (cb) cb(Result{kEcaDisconn, eca_message(kEcaDisconn), {}});
    return false;
}

bool Channel::put(double v, ResultCallback cb) { return put_raw(pv::Prim::Double, &v, 1, std::move(cb)); }

bool Channel::put(const std::string& v, ResultCallback cb) {
    char buf[pv::kStringSize] = {};
    std::strncpy(buf, v.c_str(), sizeof buf - 1);
    return put_raw(pv::Prim::String, buf, 1, std::move(cb));
}

bool Channel::put(const std::vector<double>& v, ResultCallback cb) {
    return put_raw(pv::Prim::Double, v.data(), uint32_t(v.size()), std::move(cb));
}

std::shared_ptr<Monitor> Channel::monitor(unsigned mask, ResultCallback cb, int dbr) {
    auto s = impl_.lock();
    if (!s) return std::shared_ptr<Monitor>(new Monitor({}, 0));
    if (dbr > 34) throw Error(SB() << "CA client: channel " << name_ << ": DBR type " << dbr << " cannot be monitored");
    uint32_t subid = s->next_subid++;
    ClientImpl::Mon m;
    m.cid = cid_;
    m.mask = mask;
    m.dbr = dbr;
    m.cb = std::move(cb);
    s->mons.emplace(subid, std::move(m));
    if (auto* ch = s->chan(cid_)) {
        ch->subids.insert(subid);
        s->add_monitor(*ch, subid);
    }
    return std::shared_ptr<Monitor>(new Monitor(s, subid));
}

} // namespace beamctl::ca
