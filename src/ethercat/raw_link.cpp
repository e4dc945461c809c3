#include "ethercat/raw_link.hpp"

#include "core/error.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#ifndef PACKET_IGNORE_OUTGOING
#define PACKET_IGNORE_OUTGOING 23 // Linux >= 4.20; older kernels: the pkttype check below suffices
#endif

namespace beamctl::ethercat {
namespace {

const uint8_t kBroadcast[6] = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
const uint8_t kMasterMac[6] = {0x01, 0x01, 0x01, 0x01, 0x01, 0x01}; // as SOEM sends

std::string reason(int err) {
    std::string r = std::strerror(err);
    if (err == EPERM || err == EACCES) r += " (raw sockets need root or CAP_NET_RAW)";
    return r;
}

int64_t now_ns() noexcept {
    timespec t{};
    clock_gettime(CLOCK_MONOTONIC, &t);
    return int64_t(t.tv_sec) * 1000000000 + t.tv_nsec;
}

} // namespace

RawSocket::RawSocket(const std::string& iface, bool busy_poll)
    : iface_(iface)
    , busy_poll_(busy_poll) {
    if (iface.empty()) throw Error("raw link: no interface given (link: {type: raw, iface: NAME})");
    if (iface.size() >= IFNAMSIZ)
        throw Error(SB() << "raw link on '" << iface << "': interface names are at most "
                         << IFNAMSIZ - 1 << " characters");
    ifindex_ = int(if_nametoindex(iface.c_str()));
    if (ifindex_ == 0)
        throw Error(SB() << "raw link on '" << iface
                         << "': no such network interface (`ip link` lists them)");
    // Protocol 0 receives nothing until bind(), so no frame of another interface gets queued.
    fd_ = socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, 0);
    if (fd_ < 0)
        throw Error(SB() << "raw link on '" << iface
                         << "': cannot open an AF_PACKET socket: " << reason(errno));
    auto fail = [&](const char* what) {
        int err = errno;
        ::close(fd_);
        fd_ = -1;
        throw Error(SB() << "raw link on '" << iface << "': " << what << ": " << reason(err));
    };
    ifreq ifr{};
    std::memcpy(ifr.ifr_name, iface.c_str(), iface.size() + 1);
    if (ioctl(fd_, SIOCGIFFLAGS, &ifr) != 0) fail("cannot read the interface flags");
    if (!(ifr.ifr_flags & IFF_UP)) {
        ::close(fd_);
        fd_ = -1;
        throw Error(SB() << "raw link on '" << iface << "': the interface is down (ip link set "
                         << iface << " up)");
    }
    int one = 1;
    // Best effort: the receive path checks PACKET_OUTGOING itself. (No PACKET_QDISC_BYPASS: it
    // would hide the sent frames from tcpdump/Wireshark on this host.)
    (void)setsockopt(fd_, SOL_PACKET, PACKET_IGNORE_OUTGOING, &one, sizeof one);
    sockaddr_ll a{};
    a.sll_family = AF_PACKET;
    a.sll_protocol = htons(kEtherType);
    a.sll_ifindex = ifindex_;
    if (bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
        fail("cannot bind to the interface");
    // Promiscuous while the socket is open (the kernel drops the membership on close, unlike
    // setting IFF_PROMISC on the interface).
    packet_mreq mr{};
    mr.mr_ifindex = ifindex_;
    mr.mr_type = PACKET_MR_PROMISC;
    if (setsockopt(fd_, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mr, sizeof mr) != 0)
        fail("cannot switch to promiscuous mode");
}

RawSocket::~RawSocket() {
    if (fd_ >= 0) ::close(fd_);
}

bool RawSocket::send(const uint8_t* eth_frame, std::size_t len) noexcept {
    return ::send(fd_, eth_frame, len, MSG_DONTWAIT) == ssize_t(len);
}

std::size_t RawSocket::receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept {
    int64_t deadline = -1;
    for (;;) {
        sockaddr_ll from{};
        socklen_t flen = sizeof from;
        ssize_t n = ::recvfrom(fd_, buf, cap, MSG_DONTWAIT | MSG_TRUNC,
                               reinterpret_cast<sockaddr*>(&from), &flen);
        if (n > 0) {
            bool ecat = std::size_t(n) >= kEthernetHeader + 2 && std::size_t(n) <= cap &&
                        buf[12] == (kEtherType >> 8) && buf[13] == (kEtherType & 0xFF);
            if (from.sll_pkttype != PACKET_OUTGOING && ecat) return std::size_t(n);
            ++ignored;
            continue;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return 0;
        if (timeout_us <= 0) return 0;
        int64_t now = now_ns();
        if (deadline < 0) deadline = now + int64_t(timeout_us) * 1000;
        int64_t left = deadline - now;
        if (left <= 0) return 0;
        if (busy_poll_) continue;
        pollfd p{fd_, POLLIN, 0};
        timespec ts{time_t(left / 1000000000), long(left % 1000000000)};
        int r = ppoll(&p, 1, &ts, nullptr);
        if (r < 0 && errno != EINTR) return 0;
    }
}

std::size_t ethercat_pdu_length(const uint8_t* payload, std::size_t n) noexcept {
    if (n < 2) return n;
    std::size_t len = 2 + (le16(payload) & 0x07FF);
    return len <= n ? len : n;
}

RawLink::RawLink(const std::string& iface, bool busy_poll)
    : sock_(iface, busy_poll) {
    std::memcpy(tx_.data(), kBroadcast, 6);
    std::memcpy(tx_.data() + 6, kMasterMac, 6);
    tx_[12] = uint8_t(kEtherType >> 8);
    tx_[13] = uint8_t(kEtherType & 0xFF);
}

bool RawLink::send(const uint8_t* frame, std::size_t len) noexcept {
    if (len > kMaxFrame) return false;
    std::memcpy(tx_.data() + kEthernetHeader, frame, len);
    std::size_t total = kEthernetHeader + len;
    if (total < kMinEthernetFrame) {
        std::memset(tx_.data() + total, 0, kMinEthernetFrame - total); // padding, not counted
        total = kMinEthernetFrame;
    }
    return sock_.send(tx_.data(), total);
}

std::size_t RawLink::receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept {
    std::size_t n = 0;
    for (;;) {
        n = sock_.receive(rx_.data(), rx_.size(), timeout_us);
        if (n == 0) return 0;
        // Our own frame with the source MAC no ESC has marked: reflected by a loopback, hub or
        // bridge, not returned by a segment.
        if (std::memcmp(rx_.data() + 6, kMasterMac, 6) != 0) break;
        ++sock_.ignored;
    }
    const uint8_t* pdu = rx_.data() + kEthernetHeader;
    std::size_t len = ethercat_pdu_length(pdu, n - kEthernetHeader);
    if (len > cap) len = cap;
    std::memcpy(buf, pdu, len);
    return len;
}

} // namespace beamctl::ethercat
