#include "ca/server.hpp"
#include "ca/net.hpp"

#include "ca/search.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netinet/tcp.h>
#include <ostream>
#include <sstream>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::ca {
namespace {
log::Logger lg("ca.server");

constexpr std::size_t kStopReadingAt = 8u << 20; // output bytes at which a client's input pauses

std::vector<std::string> split_ws(const char* s) {
    std::vector<std::string> out;
    std::istringstream is(s ? s : "");
    std::string w;
    while (is >> w) out.push_back(w);
    return out;
}

sockaddr_in parse_addr(const std::string& item, uint16_t def_port, const char* var) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    std::string host = item;
    uint16_t port = def_port;
    auto colon = item.find(':');
    if (colon != std::string::npos) {
        host = item.substr(0, colon);
        char* end;
        long p = std::strtol(item.c_str() + colon + 1, &end, 10);
        if (*end || p <= 0 || p > 65535) throw Error(SB() << var << ": bad port in '" << item << "'");
        port = uint16_t(p);
    }
    if (inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1)
        throw Error(SB() << var << ": '" << item << "' is not an IPv4 address");
    a.sin_port = htons(port);
    return a;
}

void set_nonblock(int fd) { fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK); }

std::string addr_str(const sockaddr_in& a) {
    char buf[INET_ADDRSTRLEN];
    inet_ntop(AF_INET, &a.sin_addr, buf, sizeof buf);
    return SB() << buf << ":" << ntohs(a.sin_port);
}

// Broadcast address of the interface that holds `ip` (INADDR_NONE if none).
in_addr broadcast_of(in_addr ip) {
    in_addr out{};
    out.s_addr = INADDR_NONE;
    ifaddrs* ifs = nullptr;
    if (getifaddrs(&ifs) != 0) return out;
    for (ifaddrs* i = ifs; i; i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET) continue;
        auto* a = reinterpret_cast<sockaddr_in*>(i->ifa_addr);
        if (a->sin_addr.s_addr != ip.s_addr) continue;
        if ((i->ifa_flags & IFF_BROADCAST) && i->ifa_broadaddr)
            out = reinterpret_cast<sockaddr_in*>(i->ifa_broadaddr)->sin_addr;
    }
    freeifaddrs(ifs);
    return out;
}

} // namespace

ServerConfig ServerConfig::from_env() {
    ServerConfig c;
    c.port = env_port("EPICS_CAS_SERVER_PORT", env_port("EPICS_CA_SERVER_PORT", kDefaultServerPort));
    for (const char* var : {"EPICS_CAS_SERVER_PORT", "EPICS_CA_SERVER_PORT"})
        if (env(var)) {
            c.port_source = SB() << var << "=" << env(var);
            break;
        }
    for (auto& s : split_ws(env("EPICS_CAS_INTF_ADDR_LIST"))) {
        sockaddr_in a = parse_addr(s, c.port, "EPICS_CAS_INTF_ADDR_LIST");
        c.interfaces.push_back(a.sin_addr);
    }
    if (!c.interfaces.empty()) c.interfaces_source = SB() << "EPICS_CAS_INTF_ADDR_LIST='" << env("EPICS_CAS_INTF_ADDR_LIST") << "'";
    if (c.interfaces.size() > 1)
        for (auto& i : c.interfaces)
            if (i.s_addr == INADDR_ANY)
                throw Error("EPICS_CAS_INTF_ADDR_LIST: 0.0.0.0 cannot be combined with other addresses");
    c.beacon_port = env_port("EPICS_CAS_BEACON_PORT", env_port("EPICS_CA_REPEATER_PORT", kDefaultRepeaterPort));
    for (auto& s : split_ws(env("EPICS_CAS_BEACON_ADDR_LIST")))
        c.beacon_addrs.push_back(parse_addr(s, c.beacon_port, "EPICS_CAS_BEACON_ADDR_LIST"));
    if (const char* v = env("EPICS_CAS_AUTO_BEACON_ADDR_LIST")) {
        std::string s(v);
        for (auto& ch : s) ch = char(std::toupper(static_cast<unsigned char>(ch)));
        if (s == "NO") c.auto_beacon_addrs = false;
        else if (s != "YES") throw Error(SB() << "EPICS_CAS_AUTO_BEACON_ADDR_LIST='" << v << "' should be YES or NO");
    }
    const char* period = env("EPICS_CAS_BEACON_PERIOD");
    if (!period) period = env("EPICS_CA_BEACON_PERIOD");
    if (period) {
        char* end;
        double p = std::strtod(period, &end);
        if (*end || !(p > 0)) throw Error(SB() << "EPICS_CAS_BEACON_PERIOD='" << period << "' should be seconds > 0");
        c.beacon_period_s = p;
    }
    for (auto& s : split_ws(env("EPICS_CAS_IGNORE_ADDR_LIST")))
        c.ignore_addrs.push_back(parse_addr(s, 0, "EPICS_CAS_IGNORE_ADDR_LIST").sin_addr);
    const char* autob = env("EPICS_CA_AUTO_ARRAY_BYTES");
    bool auto_array = !(autob && (std::strcmp(autob, "NO") == 0 || std::strcmp(autob, "no") == 0));
    if (const char* v = env("EPICS_CA_MAX_ARRAY_BYTES")) {
        char* end;
        long long b = std::strtoll(v, &end, 10);
        if (*end || b <= 0) throw Error(SB() << "EPICS_CA_MAX_ARRAY_BYTES='" << v << "' should be a byte count");
        if (!auto_array) c.max_array_bytes = std::max<std::size_t>(16384, std::size_t(b)) + 24;
        else c.max_array_bytes = std::max<std::size_t>(c.max_array_bytes, std::size_t(b) + 24);
    }
    return c;
}

struct Server::Conn {
    int fd;
    std::unique_ptr<Circuit> circuit;
    bool dirty = false;
    bool want_out = false;
    bool reading = true;
};

std::size_t Server::channel_count() const {
    std::size_t n = 0;
    for (const auto& [fd, c] : conns_) n += c->circuit->channel_count();
    return n;
}

Server::Server(EventLoop& loop, pv::Database& db, ServerConfig cfg)
    : loop_(loop), ctx_{db, AccessSecurity(), 0, cfg.max_array_bytes, 4096, 16u << 20, {}},
      cfg_(std::move(cfg)), rxbuf_(256 * 1024) {}

Server::~Server() {
    if (beacon_timer_) loop_.cancel(beacon_timer_);
    if (after_batch_) loop_.remove_after_batch(after_batch_);
    for (auto& [fd, c] : conns_) {
        loop_.remove_fd(fd);
        ::close(fd);
    }
    conns_.clear();
    for (int fd : tcp_fds_) {
        loop_.remove_fd(fd);
        ::close(fd);
    }
    for (int fd : udp_fds_) {
        loop_.remove_fd(fd);
        ::close(fd);
    }
    if (beacon_fd_ >= 0) ::close(beacon_fd_);
}

std::string Server::listen_description() const {
    SB sb;
    if (cfg_.interfaces.empty()) sb << "0.0.0.0:" << ctx_.tcp_port;
    for (std::size_t i = 0; i < cfg_.interfaces.size(); ++i) {
        char buf[INET_ADDRSTRLEN];
        inet_ntop(AF_INET, &cfg_.interfaces[i], buf, sizeof buf);
        sb << (i ? " " : "") << buf << ":" << ctx_.tcp_port;
    }
    return sb;
}

std::string Server::bind_context(const char* proto, in_addr ip, uint16_t port) const {
    sockaddr_in a{};
    a.sin_addr = ip;
    a.sin_port = htons(port);
    SB sb;
    sb << proto << " " << addr_str(a) << " (address from ";
    if (cfg_.interfaces_source.empty()) sb << "the default, all interfaces: EPICS_CAS_INTF_ADDR_LIST is not set";
    else sb << cfg_.interfaces_source;
    if (port == cfg_.port) sb << "; port from " << cfg_.port_source;
    else if (port == 0) sb << "; any free port, as " << cfg_.port << " from " << cfg_.port_source << " is in use";
    sb << ")";
    return sb;
}

void Server::start() {
    std::vector<in_addr> ifs = cfg_.interfaces;
    if (ifs.empty()) {
        in_addr any{};
        any.s_addr = INADDR_ANY;
        ifs.push_back(any);
    }
    // TCP: the configured port, or any free one if it is taken (clients learn it from searches).
    // Any other failure (an address that is not this host's, no permission) is an error.
    uint16_t tcp_port = cfg_.port;
    for (int attempt = 0; attempt < 2; ++attempt) {
        int err = 0;
        const char* call = "bind";
        in_addr failed{};
        std::vector<int> fds;
        for (in_addr ip : ifs) {
            int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
            if (fd < 0) throw Error(SB() << "CA server: cannot create a TCP socket: " << std::strerror(errno));
            int one = 1;
            setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
            sockaddr_in a{};
            a.sin_family = AF_INET;
            a.sin_addr = ip;
            a.sin_port = htons(tcp_port);
            bool bound = bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
            if (!bound || listen(fd, 128) != 0) {
                err = errno;
                call = bound ? "listen on" : "bind";
                failed = ip;
                ::close(fd);
                break;
            }
            if (tcp_port == 0) {
                socklen_t len = sizeof a;
                getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
                tcp_port = ntohs(a.sin_port);
            }
            fds.push_back(fd);
        }
        if (!err) {
            tcp_fds_ = fds;
            break;
        }
        for (int fd : fds) ::close(fd);
        if (attempt == 0 && err == EADDRINUSE && tcp_port != 0) {
            LOG_WARN(lg, bind_context("TCP", failed, tcp_port) << ": " << std::strerror(err)
                                                               << "; taking a free port instead");
            tcp_port = 0;
        } else {
            throw Error(SB() << "CA server: cannot " << call << " " << bind_context("TCP", failed, tcp_port) << ": "
                             << std::strerror(err));
        }
    }
    ctx_.tcp_port = tcp_port;
    for (int fd : tcp_fds_) {
        set_nonblock(fd);
        loop_.add_fd(fd, EPOLLIN, [this, fd](uint32_t) { on_accept(fd); });
    }
    // UDP: the configured port on each interface, plus its broadcast address to hear broadcasts.
    auto open_udp = [&](in_addr ip) {
        int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
        int one = 1;
        setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        setsockopt(fd, SOL_SOCKET, SO_BROADCAST, &one, sizeof one);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr = ip;
        a.sin_port = htons(cfg_.port);
        if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
            int e = errno;
            ::close(fd);
            throw Error(SB() << "CA server: cannot bind " << bind_context("UDP", ip, cfg_.port) << ": " << std::strerror(e));
        }
        udp_fds_.push_back(fd);
        loop_.add_fd(fd, EPOLLIN, [this, fd](uint32_t) { on_udp(fd); });
    };
    for (in_addr ip : ifs) {
        open_udp(ip);
        if (ip.s_addr != INADDR_ANY) {
            in_addr b = broadcast_of(ip);
            if (b.s_addr != INADDR_NONE && b.s_addr != ip.s_addr) {
                try {
                    open_udp(b);
                } catch (const Error& e) {
                    LOG_WARN(lg, "no searches by broadcast on this interface: " << e.what());
                }
            }
        }
    }
    // Beacons.
    beacon_fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    int one = 1;
    setsockopt(beacon_fd_, SOL_SOCKET, SO_BROADCAST, &one, sizeof one);
    beacon_targets_ = cfg_.beacon_addrs;
    if (cfg_.auto_beacon_addrs) {
        std::vector<in_addr> bcasts;
        if (cfg_.interfaces.empty()) {
            bcasts = interface_broadcasts();
        } else {
            for (in_addr ip : cfg_.interfaces) {
                in_addr b = broadcast_of(ip);
                if (b.s_addr != INADDR_NONE) bcasts.push_back(b);
            }
        }
        for (in_addr b : bcasts) {
            sockaddr_in t{};
            t.sin_family = AF_INET;
            t.sin_addr = b;
            t.sin_port = htons(cfg_.beacon_port);
            beacon_targets_.push_back(t);
        }
    }
    after_batch_ = loop_.add_after_batch([this] {
        std::vector<int> dirty;
        dirty.swap(dirty_);
        for (int fd : dirty) {
            auto it = conns_.find(fd);
            if (it == conns_.end()) continue;
            it->second->dirty = false;
            flush(*it->second);
        }
    });
    beacons_ = BeaconSchedule(cfg_.beacon_period_s);
    send_beacons();
    LOG_INFO(lg, "CA server on " << listen_description() << " (UDP port " << cfg_.port << ", "
                                 << beacon_targets_.size() << " beacon address(es))");
}

BeaconSchedule::Next BeaconSchedule::next() {
    Next n;
    n.id = sent_ < 2 ? 0 : uint32_t(sent_ - 1); // wraps like RSRV's counter
    if (sent_ > 0) interval_s_ = std::min(interval_s_ * 2, period_s_);
    n.delay_s = std::min(interval_s_, period_s_);
    ++sent_;
    return n;
}

void Server::send_beacons() {
    BeaconSchedule::Next n = beacons_.next();
    uint8_t msg[16];
    for (const sockaddr_in& t : beacon_targets_) {
        in_addr src{};
        if (cfg_.interfaces.size() == 1) src = cfg_.interfaces[0];
        encode_header(msg, kRsrvIsUp, 0, kMinorVersion, ctx_.tcp_port, n.id, ntohl(src.s_addr));
        sendto(beacon_fd_, msg, sizeof msg, 0, reinterpret_cast<const sockaddr*>(&t), sizeof t);
    }
    beacon_timer_ = loop_.call_after(n.delay_s, [this] { send_beacons(); });
}

void Server::set_access_security(AccessSecurity acf) {
    ctx_.acf = std::move(acf);
    refresh_all_rights();
}

bool Server::reload_access_security(const std::string& path) {
    try {
        set_access_security(AccessSecurity::load_file(path));
        LOG_INFO(lg, "access security reloaded from " << path);
        return true;
    } catch (const Error& e) {
        LOG_ERR(lg, "access security reload failed, keeping the previous rules: " << e.what());
        return false;
    }
}

void Server::refresh_all_rights() {
    for (auto& [fd, c] : conns_) {
        c->circuit->refresh_rights();
        if (!c->dirty) {
            c->dirty = true;
            dirty_.push_back(fd);
        }
    }
}

void Server::on_accept(int lfd) {
    for (;;) {
        sockaddr_in peer{};
        socklen_t len = sizeof peer;
        int fd = accept4(lfd, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK) return;
            if (errno == EINTR || errno == ECONNABORTED) continue;
            LOG_WARN(lg, "accept: " << std::strerror(errno));
            return;
        }
        int one = 1;
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &one, sizeof one);
        auto c = std::make_unique<Conn>();
        c->fd = fd;
        c->circuit = std::make_unique<Circuit>(ctx_, ntohl(peer.sin_addr.s_addr), ntohs(peer.sin_port));
        Conn* raw = c.get();
        c->circuit->set_wake([this, raw] {
            if (!raw->dirty) {
                raw->dirty = true;
                dirty_.push_back(raw->fd);
            }
        });
        c->circuit->on_asg_changed = [this] { refresh_all_rights(); };
        LOG_DEBUG(lg, "circuit from " << c->circuit->peer());
        conns_.emplace(fd, std::move(c));
        loop_.add_fd(fd, EPOLLIN, [this, fd](uint32_t ev) { on_conn_io(fd, ev); });
        raw->dirty = true;
        dirty_.push_back(fd);
    }
}

void Server::on_conn_io(int fd, uint32_t events) {
    auto it = conns_.find(fd);
    if (it == conns_.end()) return;
    Conn& c = *it->second;
    if (events & (EPOLLIN | EPOLLERR | EPOLLHUP)) {
        // Read what is there, up to a budget, so one busy client can't starve the others.
        std::size_t budget = 4u << 20;
        while (budget && c.reading) {
            ssize_t n = ::recv(fd, rxbuf_.data(), rxbuf_.size(), 0);
            if (n > 0) {
                c.circuit->receive(rxbuf_.data(), std::size_t(n));
                budget = std::size_t(n) >= budget ? 0 : budget - std::size_t(n);
                if (c.circuit->wants_close()) break;
                if (c.circuit->output_size() > kStopReadingAt) break;
                // A short read emptied the socket: what arrives later wakes the loop again (level-
                // triggered), so no recv that would only say EAGAIN (one syscall less per wake-up).
                if (std::size_t(n) < rxbuf_.size()) break;
                continue;
            }
            if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
                LOG_DEBUG(lg, "circuit " << c.circuit->peer() << " closed by client");
                close_conn(fd);
                return;
            }
            if (errno == EINTR) continue;
            break;
        }
    }
    if (!c.dirty) {
        c.dirty = true;
        dirty_.push_back(fd);
    }
}

void Server::flush(Conn& c) {
    Circuit& circ = *c.circuit;
    for (;;) {
        circ.fill_events(Circuit::kDefaultHighWater);
        std::string_view out = circ.pending_output();
        if (out.empty()) break;
        ssize_t n = ::send(c.fd, out.data(), out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) {
            circ.consume_output(std::size_t(n));
            if (std::size_t(n) < out.size()) break; // socket full
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
        if (n < 0 && errno == EINTR) continue;
        LOG_DEBUG(lg, "circuit " << circ.peer() << ": send failed: " << std::strerror(errno));
        close_conn(c.fd);
        return;
    }
    bool pending = circ.output_size() > 0 || (circ.has_queued_events() && circ.events_enabled());
    if (circ.wants_close() && circ.output_size() == 0) {
        LOG_INFO(lg, "circuit " << circ.peer() << " closed after a protocol error");
        close_conn(c.fd);
        return;
    }
    bool reading = circ.output_size() <= kStopReadingAt && !circ.wants_close();
    if (pending != c.want_out || reading != c.reading) {
        c.want_out = pending;
        c.reading = reading;
        loop_.modify_fd(c.fd, (reading ? uint32_t(EPOLLIN) : 0u) | (pending ? uint32_t(EPOLLOUT) : 0u));
    }
}

void Server::close_conn(int fd) {
    auto it = conns_.find(fd);
    if (it == conns_.end()) return;
    loop_.remove_fd(fd);
    ::close(fd);
    conns_.erase(it);
}

void Server::on_udp(int fd) {
    uint8_t buf[16384];
    for (int i = 0; i < 256; ++i) {
        sockaddr_in from{};
        socklen_t len = sizeof from;
        ssize_t n = recvfrom(fd, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &len);
        if (n < 0) return;
        bool ignored = false;
        for (auto& a : cfg_.ignore_addrs)
            if (a.s_addr == from.sin_addr.s_addr) ignored = true;
        if (!ignored) handle_datagram(fd, buf, std::size_t(n), from);
    }
}

void Server::handle_datagram(int fd, const uint8_t* p, std::size_t n, const sockaddr_in& from) {
    std::vector<std::string> replies;
    answer_search(ctx_.db, ctx_.tcp_port, p, n, replies, ctx_.stats);
    for (auto& r : replies)
        sendto(fd, r.data(), r.size(), 0, reinterpret_cast<const sockaddr*>(&from), sizeof from);
}

void Server::report(int level, std::ostream& os) const {
    os << "Channel Access Server V4.13\n";
    if (conns_.empty()) {
        os << "No clients connected.\n";
    } else {
        os << "Connected circuits:\n";
        std::vector<const Conn*> conns;
        for (const auto& [fd, c] : conns_) conns.push_back(c.get());
        std::sort(conns.begin(), conns.end(), [](const Conn* a, const Conn* b) { return a->fd < b->fd; });
        for (const Conn* c : conns) {
            const Circuit& k = *c->circuit;
            os << "TCP " << k.peer() << "(" << k.host() << "): User=\"" << k.user() << "\", V4.13, "
               << k.channel_count() << " Channel" << (k.channel_count() == 1 ? "" : "s") << ", Priority=0\n";
            if (level >= 1) {
                os << "\t" << k.subscription_count() << " subscription(s), " << k.output_size()
                   << " bytes waiting to be sent\n";
                for (const auto& n : k.channel_names()) os << "\t" << n << "\n";
            }
        }
    }
    if (level >= 2) {
        os << "Server: " << listen_description() << " (UDP and TCP), " << beacon_targets_.size()
           << " beacon address(es)\n";
        const ServerStats& s = ctx_.stats;
        os << "Circuits opened " << s.circuits_opened << ", closed " << s.circuits_closed
           << "; messages " << s.messages << "; UDP searches " << s.searches_udp << " (" << s.search_hits
           << " answered); protocol errors " << s.protocol_errors << "; puts denied " << s.put_denied
           << "; events sent " << s.events_sent << "\n";
    }
}

} // namespace beamctl::ca
