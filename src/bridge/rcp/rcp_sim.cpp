#include "bridge/rcp/rcp_sim.hpp"

#include "bridge/rcp/model.hpp"
#include "core/error.hpp"
#include "core/log.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <netinet/in.h>
#include <poll.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::bridge::rcp {
namespace {

log::Logger lg("rcp.sim");

double mono_s() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + ts.tv_nsec * 1e-9;
}

sockaddr_in sockaddr_of(uint32_t ip, uint16_t port) {
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(ip);
    sa.sin_port = htons(port);
    return sa;
}

// Closes a descriptor at scope exit.
struct Fd {
    int fd = -1;
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
};

// Blocks SIGINT/SIGTERM while alive and restores the previous mask.
struct BlockSignals {
    sigset_t old{};
    explicit BlockSignals(const sigset_t& set) { sigprocmask(SIG_BLOCK, &set, &old); }
    ~BlockSignals() { sigprocmask(SIG_SETMASK, &old, nullptr); }
};

} // namespace

int run_rcp_sim(const std::string& model_file, const RcpSimOptions& opt) {
    ModelConfig cfg = ModelConfig::load(model_file);
    if (!opt.ioc_host.empty() && !parse_ipv4(opt.ioc_host, cfg.ioc_ip))
        throw Error(SB() << "rcp-sim: IOC host '" << opt.ioc_host << "' should be an IPv4 address");
    if (opt.ioc_port >= 0) {
        if (opt.ioc_port < 1 || opt.ioc_port > 65535)
            throw Error(SB() << "rcp-sim: IOC port " << opt.ioc_port << " should be 1..65535");
        if (cfg.ioc_data_port == cfg.ioc_port) cfg.ioc_data_port = uint16_t(opt.ioc_port);
        cfg.ioc_port = uint16_t(opt.ioc_port);
    }
    if (opt.listen_port >= 0) {
        if (opt.listen_port > 65535)
            throw Error(SB() << "rcp-sim: listen port " << opt.listen_port
                             << " should be 0..65535");
        cfg.listen_port = uint16_t(opt.listen_port);
    }
    if (opt.rate_hz > 0) {
        if (opt.rate_hz > 100000)
            throw Error(SB() << "rcp-sim: rate " << opt.rate_hz << " Hz should be <= 100000");
        cfg.rate_hz = opt.rate_hz;
    }
    Model model(cfg);

    Fd sock{::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0)};
    if (sock.fd < 0) throw Error(SB() << "rcp-sim: socket: " << std::strerror(errno));
    int buf = 4 << 20;
    ::setsockopt(sock.fd, SOL_SOCKET, SO_SNDBUF, &buf, sizeof buf);
    sockaddr_in local = sockaddr_of(cfg.listen_ip, cfg.listen_port);
    if (::bind(sock.fd, reinterpret_cast<sockaddr*>(&local), sizeof local) != 0)
        throw Error(SB() << "rcp-sim: cannot bind udp " << ipv4_to_string(cfg.listen_ip) << ":"
                         << cfg.listen_port << ": " << std::strerror(errno));
    socklen_t len = sizeof local;
    getsockname(sock.fd, reinterpret_cast<sockaddr*>(&local), &len);
    model.set_listen_port(ntohs(local.sin_port));

    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    BlockSignals blocked(set);
    Fd sig{signalfd(-1, &set, SFD_NONBLOCK | SFD_CLOEXEC)};
    if (sig.fd < 0) throw Error(SB() << "rcp-sim: signalfd: " << std::strerror(errno));

    sockaddr_in beacon_to = sockaddr_of(cfg.ioc_ip, cfg.ioc_port);
    sockaddr_in data_to = sockaddr_of(cfg.ioc_ip, cfg.ioc_data_port);
    auto send = [&](const Packet& p, const sockaddr_in& to) {
        return ::sendto(sock.fd, p.data(), p.size(), 0, reinterpret_cast<const sockaddr*>(&to),
                        sizeof to) == ssize_t(p.size());
    };

    std::printf("ready: rcp-sim %s: %zu objects at %g Hz; writes on udp %s:%u; beacons to %s:%u, "
                "data to %s:%u\n",
                cfg.application.c_str(), cfg.objects.size(), cfg.rate_hz,
                ipv4_to_string(cfg.listen_ip).c_str(), unsigned(model.config().listen_port),
                ipv4_to_string(cfg.ioc_ip).c_str(), unsigned(cfg.ioc_port),
                ipv4_to_string(cfg.ioc_ip).c_str(), unsigned(cfg.ioc_data_port));
    std::fflush(stdout);

    const double dt = 1.0 / cfg.rate_hz;
    const double start = mono_s();
    double next_step = start, next_beacon = start;
    uint64_t steps = 0, sent = 0, send_errors = 0, writes = 0, refused = 0, skipped = 0;
    std::vector<Packet> packets;
    DataPacket rx;
    std::array<uint8_t, 1024> rxbuf;
    double next_log = 0;
    bool stop = false;
    while (!stop) {
        double now = mono_s();
        if (opt.duration_s > 0 && now - start >= opt.duration_s) break;
        if (now >= next_beacon) {
            for (const Packet& p : model.beacon_packets())
                (send(p, beacon_to) ? sent : send_errors)++;
            next_beacon += cfg.beacon_period_s;
            if (next_beacon <= now) next_beacon = now + cfg.beacon_period_s;
        }
        if (now >= next_step) {
            // Catch up after short delays; after a long stall (> 0.1 s) skip ahead instead.
            if (now - next_step > 0.1) {
                uint64_t n = uint64_t((now - next_step) / dt);
                skipped += n;
                next_step += double(n) * dt;
            }
            model.step(dt);
            ++steps;
            model.data_packets(packets);
            for (const Packet& p : packets) (send(p, data_to) ? sent : send_errors)++;
            next_step += dt;
            continue;
        }
        double wait = std::min(next_step, next_beacon) - now;
        if (opt.duration_s > 0) wait = std::min(wait, start + opt.duration_s - now);
        timespec ts{time_t(wait), long((wait - std::floor(wait)) * 1e9)};
        pollfd fds[2] = {{sock.fd, POLLIN, 0}, {sig.fd, POLLIN, 0}};
        int n = ::ppoll(fds, 2, &ts, nullptr);
        if (n < 0 && errno != EINTR)
            throw Error(SB() << "rcp-sim: ppoll: " << std::strerror(errno));
        if (n <= 0) continue;
        if (fds[1].revents & POLLIN) {
            signalfd_siginfo si;
            while (::read(sig.fd, &si, sizeof si) == sizeof si)
                LOG_INFO(lg, "signal " << si.ssi_signo << ": stopping");
            stop = true;
        }
        if (fds[0].revents & POLLIN) {
            for (;;) {
                sockaddr_in from{};
                socklen_t fl = sizeof from;
                ssize_t got = ::recvfrom(sock.fd, rxbuf.data(), rxbuf.size(), MSG_TRUNC,
                                         reinterpret_cast<sockaddr*>(&from), &fl);
                if (got < 0) break;
                std::size_t size = std::size_t(got);
                Malformed why = Malformed::None;
                uint16_t at = 0;
                ParseResult r = parse_data(
                    std::span<const uint8_t>(rxbuf.data(), std::min(size, rxbuf.size())), rx);
                if (size > rxbuf.size()) r = {Malformed::Long, uint16_t(kPacketSize)};
                if (!r) {
                    why = r.reason;
                    at = r.offset;
                } else {
                    for (const DataEntry& e : rx.view()) {
                        Malformed m = model.check_write(e);
                        if (m != Malformed::None && why == Malformed::None) {
                            why = m;
                            at = uint16_t(reinterpret_cast<const uint8_t*>(e.name.data()) -
                                          rxbuf.data() - 5);
                        }
                    }
                    if (why == Malformed::None)
                        for (const DataEntry& e : rx.view()) model.apply_write(e);
                }
                if (why == Malformed::None) {
                    ++writes;
                    continue;
                }
                ++refused;
                double t = mono_s();
                if (t >= next_log) {
                    LOG_WARN(lg, "write from " << ipv4_to_string(ntohl(from.sin_addr.s_addr)) << ":"
                                               << ntohs(from.sin_port) << " refused: "
                                               << to_string(why) << " at byte " << at);
                    next_log = t + 1;
                }
            }
        }
    }
    LOG_INFO(lg, "rcp-sim " << cfg.application << ": " << steps << " steps, " << sent
                            << " packets sent (" << send_errors << " send errors, " << skipped
                            << " steps skipped), " << writes << " writes applied, " << refused
                            << " refused");
    return 0;
}

} // namespace beamctl::bridge::rcp
