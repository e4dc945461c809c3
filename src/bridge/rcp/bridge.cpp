#include "bridge/rcp/bridge.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <array>
#include <cerrno>
#include <cstring>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::bridge::rcp {
namespace {

log::Logger lg("rcp");

constexpr double kTickPeriod_s = 0.05;
constexpr int kBatch = 32;              // datagrams per recvmmsg
constexpr int kBatchesPerWake = 8;      // then back to the loop (level-triggered: it comes back)
constexpr std::size_t kRxBuffer = 1024; // > 1000 so that longer datagrams are seen as Long
constexpr int kRcvBuf = 4 << 20;        // [bytes] room for bursts at 10 000 packets/s

sockaddr_in to_sockaddr(const Endpoint& e) {
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(e.ip);
    sa.sin_port = htons(e.port);
    return sa;
}

// The address to listen on when the configuration names none: the local interface on the
// first machine's network, loopback when only loopback is accepted, else every interface.
std::string default_listen(const BridgeConfig& cfg) {
    if (cfg.machines.empty()) return cfg.allow.empty() ? "127.0.0.1" : "0.0.0.0";
    Ipv4Net m;
    if (!parse_ipv4_net(cfg.machines[0].address, m)) return "0.0.0.0";
    ifaddrs* list = nullptr;
    if (getifaddrs(&list) != 0) return "0.0.0.0";
    std::string found;
    for (ifaddrs* i = list; i && found.empty(); i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET || !i->ifa_netmask) continue;
        uint32_t ip = ntohl(reinterpret_cast<sockaddr_in*>(i->ifa_addr)->sin_addr.s_addr);
        uint32_t mask = ntohl(reinterpret_cast<sockaddr_in*>(i->ifa_netmask)->sin_addr.s_addr);
        if ((ip & mask) == (m.ip & mask)) found = ipv4_to_string(ip);
    }
    freeifaddrs(list);
    if (found.empty())
        LOG_WARN(lg, "no local interface is on the network of machine " << cfg.machines[0].name << " ("
                                                                         << cfg.machines[0].address
                                                                         << "): listening on every interface");
    return found.empty() ? "0.0.0.0" : found;
}

} // namespace

RcpBridge::RcpBridge(pv::Database& db, EventLoop& loop, BridgeConfig cfg)
    : loop_(loop) {
    cfg.validate();
    if (cfg.listen_address.empty()) cfg.listen_address = default_listen(cfg);
    if (cfg.machines.empty() && cfg.allow.empty())
        LOG_INFO(lg, "accepting RCP beacons and data from loopback only; to accept a prototyping machine, set "
                     "bridges.rcp.machines: [{name: APP, address: 10.0.3.7}] (or bridges.rcp.allow: [10.0.3.0/24])");
    parse_ipv4(cfg.listen_address, listen_ip_);
    fd_ = open_socket(cfg.port);
    if (fd_ < 0)
        throw Error(SB() << "rcp bridge: cannot open UDP " << cfg.listen_address << ":" << cfg.port
                         << ": " << std::strerror(errno));
    sockaddr_in sa{};
    socklen_t len = sizeof sa;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&sa), &len);
    port_ = ntohs(sa.sin_port);
    cfg.port = port_;
    int fd = fd_;
    auto send = [fd](const Endpoint& to, std::span<const uint8_t> p) {
        sockaddr_in d = to_sockaddr(to);
        return ::sendto(fd, p.data(), p.size(), MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&d),
                        sizeof d) == ssize_t(p.size());
    };
    try {
        core_ = std::make_unique<BridgeCore>(db, std::move(cfg), send, &EventLoop::now_s);
    } catch (...) {
        ::close(fd_);
        throw;
    }
    loop_.add_fd(fd_, EPOLLIN, [this](uint32_t) { on_readable(fd_); });
    timer_ = loop_.call_every(kTickPeriod_s, [this] {
        core_->tick(EventLoop::now_s());
        sync_ports();
    });
    LOG_INFO(lg, "listening for RCP beacons and data on udp " << core_->config().listen_address
                                                              << ":" << port_);
}

RcpBridge::~RcpBridge() {
    loop_.cancel(timer_);
    for (auto& [port, fd] : data_fds_) {
        loop_.remove_fd(fd);
        ::close(fd);
    }
    loop_.remove_fd(fd_);
    core_.reset(); // removes the records while nothing can send any more
    ::close(fd_);
}

int RcpBridge::open_socket(uint16_t port) {
    int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    int buf = kRcvBuf;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buf, sizeof buf); // best effort (rmem_max caps it)
    sockaddr_in sa = to_sockaddr(Endpoint{listen_ip_, port});
    if (::bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0) {
        int e = errno;
        ::close(fd);
        errno = e;
        return -1;
    }
    return fd;
}

void RcpBridge::on_readable(int fd) {
    static thread_local std::array<std::array<uint8_t, kRxBuffer>, kBatch> bufs;
    mmsghdr msgs[kBatch];
    iovec iov[kBatch];
    sockaddr_in from[kBatch];
    for (int batch = 0; batch < kBatchesPerWake; ++batch) {
        for (int i = 0; i < kBatch; ++i) {
            iov[i] = {bufs[i].data(), bufs[i].size()};
            msgs[i] = {};
            msgs[i].msg_hdr.msg_iov = &iov[i];
            msgs[i].msg_hdr.msg_iovlen = 1;
            msgs[i].msg_hdr.msg_name = &from[i];
            msgs[i].msg_hdr.msg_namelen = sizeof from[i];
        }
        int n = ::recvmmsg(fd, msgs, kBatch, MSG_DONTWAIT, nullptr);
        if (n <= 0) {
            if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
                LOG_WARN(lg, "receive: " << std::strerror(errno));
            break;
        }
        double now = EventLoop::now_s();
        for (int i = 0; i < n; ++i) {
            std::size_t len = msgs[i].msg_len;
            // A truncated datagram was longer than the buffer: still seen as too long.
            if (msgs[i].msg_hdr.msg_flags & MSG_TRUNC) len = kRxBuffer;
            Endpoint src{ntohl(from[i].sin_addr.s_addr), ntohs(from[i].sin_port)};
            core_->handle_packet(std::span<const uint8_t>(bufs[i].data(), len), src, now);
        }
        if (n < kBatch) break;
    }
    sync_ports();
}

void RcpBridge::sync_ports() {
    if (core_->ports_version() == ports_version_) return;
    ports_version_ = core_->ports_version();
    const auto& want = core_->data_ports();
    for (auto it = data_fds_.begin(); it != data_fds_.end();) {
        if (std::find(want.begin(), want.end(), it->first) != want.end()) {
            ++it;
            continue;
        }
        LOG_INFO(lg, "closing data port " << it->first);
        loop_.remove_fd(it->second);
        ::close(it->second);
        it = data_fds_.erase(it);
    }
    for (uint16_t p : want) {
        if (data_fds_.count(p)) continue;
        int fd = open_socket(p);
        if (fd < 0) {
            LOG_ERR(lg, "cannot open data port udp "
                            << core_->config().listen_address << ":" << p
                            << " announced by an application: " << std::strerror(errno));
            continue;
        }
        LOG_INFO(lg,
                 "listening for RCP data on udp " << core_->config().listen_address << ":" << p);
        data_fds_[p] = fd;
        loop_.add_fd(fd, EPOLLIN, [this, fd](uint32_t) { on_readable(fd); });
    }
}

} // namespace beamctl::bridge::rcp
