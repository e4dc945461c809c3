#include "ethercat/link.hpp"

#include "core/error.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::ethercat {

UdpLink::UdpLink(const std::string& host, uint16_t port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    if (inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1)
        throw Error(SB() << "udp link: '" << host << "' is not an IPv4 address");
    fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0 || connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
        throw Error(SB() << "udp link to " << host << ":" << port << ": " << std::strerror(errno));
}

UdpLink::~UdpLink() {
    if (fd_ >= 0) ::close(fd_);
}

bool UdpLink::send(const uint8_t* frame, std::size_t len) noexcept {
    return ::send(fd_, frame, len, MSG_DONTWAIT) == ssize_t(len);
}

std::size_t UdpLink::receive(uint8_t* buf, std::size_t cap, int timeout_us) noexcept {
    for (;;) {
        ssize_t n = ::recv(fd_, buf, cap, MSG_DONTWAIT);
        if (n > 0) return std::size_t(n);
        if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != ECONNREFUSED) return 0;
        if (timeout_us <= 0) return 0;
        pollfd p{fd_, POLLIN, 0};
        timespec ts{timeout_us / 1000000, (timeout_us % 1000000) * 1000};
        int r = ppoll(&p, 1, &ts, nullptr);
        if (r <= 0) return 0;
        timeout_us = 0; // one wait only; then read what arrived
        ssize_t m = ::recv(fd_, buf, cap, MSG_DONTWAIT);
        return m > 0 ? std::size_t(m) : 0;
    }
}

} // namespace beamctl::ethercat
