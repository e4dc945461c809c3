#include "ca/repeater.hpp"

#include "core/log.hpp"
#include "core/signals.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>
#include <unordered_map>
#include <utility>

namespace beamctl::ca {
namespace {
log::Logger lg("ca.repeater");

constexpr std::size_t kHeader = 16;

sockaddr_in to_sockaddr(uint32_t ip, uint16_t port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(ip);
    a.sin_port = htons(port);
    return a;
}

// A UDP socket, closed when it goes out of scope.
struct UdpSocket {
    int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    UdpSocket() = default;
    UdpSocket(const UdpSocket&) = delete;
    UdpSocket& operator=(const UdpSocket&) = delete;
    ~UdpSocket() {
        if (fd >= 0) ::close(fd);
    }
    int release() { return std::exchange(fd, -1); }
    // bind(2): 0, or the errno of the failure.
    int bind_to(uint32_t ip, uint16_t port) const {
        if (fd < 0) return errno;
        sockaddr_in a = to_sockaddr(ip, port);
        return ::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0 ? 0 : errno;
    }
};

} // namespace

std::string to_string(const UdpEndpoint& e) {
    char buf[INET_ADDRSTRLEN] = "?";
    in_addr a{htonl(e.ip)};
    inet_ntop(AF_INET, &a, buf, sizeof buf);
    return SB() << buf << ":" << e.port;
}

// ---------------------------------------------------------------------------------------------
// Protocol
// ---------------------------------------------------------------------------------------------
void RepeaterCore::receive(const UdpEndpoint& from, const uint8_t* data, std::size_t n) {
    ++stats_.datagrams;
    if (n == 0) { // an empty datagram registers too (old clients)
        register_client(from);
        return;
    }
    if (n >= kHeader) {
        const uint16_t cmd = get16(data);
        if (cmd == kRepeaterRegister) {
            register_client(from);
            data += kHeader; // whatever follows the registration goes on like any datagram
            n -= kHeader;
            if (n == 0) return;
        } else if (cmd == kRsrvIsUp && get32(data + 12) == 0) {
            // A beacon without the server's address: the clients would take the repeater's.
            patched_.assign(data, data + n);
            put32(patched_.data() + 12, from.ip);
            fan_out(from, patched_.data(), n);
            return;
        }
    }
    fan_out(from, data, n);
}

void RepeaterCore::register_client(const UdpEndpoint& from) {
    if (from.ip != kLoopbackIp && !io_.is_local(from.ip)) {
        ++stats_.foreign;
        LOG_DEBUG(lg, "registration from " << to_string(from) << " ignored: not an address of this host");
        return;
    }
    ++stats_.registrations;
    // One client per port, as libca alternates between the loopback and an interface address.
    auto it = std::find_if(clients_.begin(), clients_.end(),
                           [&](const UdpEndpoint& c) { return c.port == from.port; });
    const bool is_new = it == clients_.end();
    std::size_t i = std::size_t(it - clients_.begin());
    if (is_new) {
        clients_.push_back(from);
        LOG_DEBUG(lg, "client " << to_string(from) << " registered (" << clients_.size() << " clients)");
    }
    uint8_t confirm[kHeader];
    encode_header(confirm, kRepeaterConfirm, 0, 0, 0, 0, clients_[i].ip);
    if (!io_.send(clients_[i], confirm, sizeof confirm)) {
        ++stats_.send_failures;
        remove_at(i);
    }
    // A no-op (VERSION) to every other client: sends to clients that have gone fail from now on,
    // so they are dropped even while no server sends beacons.
    const uint8_t noop[kHeader] = {};
    const uint64_t forwarded = stats_.forwarded;
    fan_out(from, noop, sizeof noop);
    stats_.forwarded = forwarded;
    if (is_new) remove_closed_clients();
}

void RepeaterCore::fan_out(const UdpEndpoint& from, const uint8_t* data, std::size_t n) {
    for (std::size_t i = 0; i < clients_.size();) {
        const UdpEndpoint c = clients_[i];
        if (c == from) { // never back to the sender
            ++i;
            continue;
        }
        if (io_.send(c, data, n)) {
            ++stats_.forwarded;
            ++i;
            continue;
        }
        ++stats_.send_failures;
        if (io_.port_in_use(c.port)) {
            ++i;
        } else {
            remove_at(i);
        }
    }
}

void RepeaterCore::remove_closed_clients() {
    for (std::size_t i = 0; i < clients_.size();) {
        if (io_.port_in_use(clients_[i].port)) ++i;
        else remove_at(i);
    }
}

void RepeaterCore::remove_at(std::size_t i) {
    const UdpEndpoint c = clients_[i];
    clients_.erase(clients_.begin() + std::ptrdiff_t(i));
    io_.forget(c);
    ++stats_.removed;
    LOG_DEBUG(lg, "client " << to_string(c) << " removed: its port has closed (" << clients_.size()
                            << " clients)");
}

// ---------------------------------------------------------------------------------------------
// Sockets
// ---------------------------------------------------------------------------------------------
struct Repeater::Impl final : RepeaterIo {
    EventLoop& loop;
    uint16_t port;
    int fd = -1;
    RepeaterCore core{*this};
    std::unordered_map<uint64_t, int> client_fds; // one connected socket per client, as EPICS
    std::vector<uint8_t> buf = std::vector<uint8_t>(65536);
    log::RateLimit errors_logged;

    static uint64_t key(const UdpEndpoint& e) { return uint64_t(e.ip) << 16 | e.port; }

    Impl(EventLoop& l, uint16_t p) : loop(l), port(p) {
        UdpSocket s;
        if (s.fd < 0) throw Error(SB() << "CA repeater: socket: " << std::strerror(errno));
        if (int err = s.bind_to(INADDR_ANY, port)) {
            if (err == EADDRINUSE) throw PortInUse(SB() << "UDP port " << port << " is in use");
            throw Error(SB() << "CA repeater: bind to UDP port " << port << ": " << std::strerror(err));
        }
        fd = s.release();
        loop.add_fd(fd, EPOLLIN, [this](uint32_t) { on_readable(); });
    }

    ~Impl() override {
        loop.remove_fd(fd);
        ::close(fd);
        for (auto& [k, cfd] : client_fds) ::close(cfd);
    }

    void on_readable() {
        for (int k = 0; k < 256; ++k) { // then let the loop breathe
            sockaddr_in from{};
            socklen_t len = sizeof from;
            ssize_t r = ::recvfrom(fd, buf.data(), buf.size(), 0, reinterpret_cast<sockaddr*>(&from), &len);
            if (r < 0) {
                if (errno == EAGAIN || errno == EWOULDBLOCK) return;
                if (errno == ECONNREFUSED || errno == ECONNRESET || errno == EINTR) continue;
                if (errors_logged.allow()) LOG_WARN(lg, "recvfrom on UDP port " << port << ": " << std::strerror(errno));
                return;
            }
            if (from.sin_family != AF_INET) continue;
            core.receive(UdpEndpoint{ntohl(from.sin_addr.s_addr), ntohs(from.sin_port)}, buf.data(),
                         std::size_t(r));
        }
    }

    bool send(const UdpEndpoint& to, const uint8_t* data, std::size_t n) override {
        auto it = client_fds.find(key(to));
        if (it == client_fds.end()) {
            UdpSocket s;
            sockaddr_in a = to_sockaddr(to.ip, to.port);
            if (s.fd < 0 || ::connect(s.fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
                if (errors_logged.allow())
                    LOG_WARN(lg, "no socket for client " << to_string(to) << ": " << std::strerror(errno));
                return false;
            }
            it = client_fds.emplace(key(to), s.release()).first;
        }
        ssize_t r = ::send(it->second, data, n, MSG_NOSIGNAL);
        if (r == ssize_t(n)) return true;
        LOG_TRACE(lg, "send to " << to_string(to) << ": " << (r < 0 ? std::strerror(errno) : "short"));
        return false;
    }

    void forget(const UdpEndpoint& c) override {
        auto it = client_fds.find(key(c));
        if (it == client_fds.end()) return;
        ::close(it->second);
        client_fds.erase(it);
    }

    bool port_in_use(uint16_t p) override {
        UdpSocket s;
        int err = s.bind_to(INADDR_ANY, p);
        if (err == 0) return false;
        if (err != EADDRINUSE && errors_logged.allow())
            LOG_WARN(lg, "cannot probe UDP port " << p << " (" << std::strerror(err) << "); keeping its client");
        return true;
    }

    bool is_local(uint32_t ip) override { return UdpSocket().bind_to(ip, 0) == 0; }
};

Repeater::Repeater(EventLoop& loop, uint16_t port) : impl_(std::make_unique<Impl>(loop, port)) {}
Repeater::~Repeater() = default;
uint16_t Repeater::port() const { return impl_->port; }
const RepeaterCore& Repeater::core() const { return impl_->core; }

uint16_t repeater_port_from_env() {
    const char* v = std::getenv("EPICS_CA_REPEATER_PORT");
    if (!v || !*v) return kDefaultRepeaterPort;
    char* end;
    long p = std::strtol(v, &end, 10);
    if (*end || p <= 0 || p > 65535)
        throw Error(SB() << "EPICS_CA_REPEATER_PORT='" << v << "' should be a port number (1..65535)");
    return uint16_t(p);
}

bool repeater_answers(uint16_t port, double timeout_s) {
    UdpSocket s;
    if (s.fd < 0 || s.bind_to(INADDR_ANY, 0) != 0) return false;
    uint8_t reg[kHeader];
    encode_header(reg, kRepeaterRegister, 0, 0, 0, 0, kLoopbackIp);
    sockaddr_in to = to_sockaddr(kLoopbackIp, port);
    if (::sendto(s.fd, reg, sizeof reg, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to) != ssize_t(sizeof reg))
        return false;
    const double deadline = EventLoop::now_s() + timeout_s;
    for (double now = EventLoop::now_s(); now < deadline; now = EventLoop::now_s()) {
        pollfd p{s.fd, POLLIN, 0};
        if (::poll(&p, 1, int((deadline - now) * 1000) + 1) <= 0) continue;
        uint8_t in[64];
        ssize_t r = ::recv(s.fd, in, sizeof in, 0);
        if (r >= ssize_t(kHeader) && get16(in) == kRepeaterConfirm) return true;
    }
    return false;
}

int run_ca_repeater(uint16_t port) {
    EventLoop loop;
    std::unique_ptr<Repeater> rep;
    for (int attempt = 0; !rep; ++attempt) {
        try {
            rep = std::make_unique<Repeater>(loop, port);
        } catch (const PortInUse&) {
            if (repeater_answers(port, 1.0)) {
                LOG_DEBUG(lg, "a CA repeater already serves UDP port " << port << ": exiting");
                return 0;
            }
            // libca probes the port by binding it for a moment: look once more before giving up.
            if (attempt == 1) {
                std::fprintf(stderr,
                             "ca-repeater: UDP port %u is in use by something that is not a CA repeater "
                             "(no REPEATER_CONFIRM within 1 s)\n",
                             unsigned(port));
                return 1;
            }
        }
    }
    LoopSignals signals(loop, {});
    std::printf("ready: CA repeater on udp 0.0.0.0:%u\n", unsigned(port));
    std::fflush(stdout);
    loop.run();
    const RepeaterStats& s = rep->core().stats();
    LOG_DEBUG(lg, "stopped: " << s.datagrams << " datagrams, " << s.registrations << " registrations, "
                              << s.forwarded << " forwarded, " << s.removed << " clients removed");
    return 0;
}

int ca_repeater_main(int argc, char** argv) {
    bool detach = true;
    const char* name = argc > 0 ? argv[0] : "caRepeater";
    auto usage = [name](FILE* f) {
        std::fprintf(f,
                     "Usage: %s [-hv]\n"
                     "Channel Access repeater (beamctl ca-repeater): fans CA server beacons that reach\n"
                     "UDP port EPICS_CA_REPEATER_PORT (5065) out to the CA clients of this host.\n"
                     " -h  print this message\n"
                     " -v  keep stdin/stdout/stderr and the terminal (do not detach)\n",
                     name);
    };
    for (int i = 1; i < argc; ++i) {
        const char* a = argv[i];
        if (a[0] != '-' || !a[1]) {
            usage(stderr);
            std::fprintf(stderr, "\nUnexpected argument '%s'\n", a);
            return 1;
        }
        for (const char* c = a + 1; *c; ++c) {
            if (*c == 'h') {
                usage(stdout);
                return 0;
            }
            if (*c == 'v') {
                detach = false;
                continue;
            }
            usage(stderr);
            std::fprintf(stderr, "\nUnknown option '%c'\n", *c);
            return 1;
        }
    }
    try {
        const uint16_t port = repeater_port_from_env();
        if (detach) {
            // libca forks us from a client: leave its terminal (a Ctrl-C there must not end the
            // repeater) and its stdin/stdout/stderr (its pipes must close when it exits).
            ::setsid();
            int null_in = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
            int null_out = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
            if (null_in >= 0) ::dup2(null_in, 0);
            if (null_out >= 0) {
                ::dup2(null_out, 1);
                ::dup2(null_out, 2);
            }
            if (null_in > 2) ::close(null_in);
            if (null_out > 2) ::close(null_out);
            if (::chdir("/") != 0) { /* stays where it was; harmless */
            }
        }
        return run_ca_repeater(port);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "caRepeater: %s\n", e.what());
        return 1;
    }
}

} // namespace beamctl::ca
