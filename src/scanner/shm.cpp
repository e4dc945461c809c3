#include "scanner/shm.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <climits>
#include <cstring>
#include <fcntl.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

namespace beamctl::scanner {

namespace {
[[noreturn]] void fail(const std::string& what, const char* call) {
    throw Error(SB() << what << ": " << call << ": " << std::strerror(errno));
}
} // namespace

SharedMemory::~SharedMemory() { reset(); }

SharedMemory::SharedMemory(SharedMemory&& o) noexcept : fd_(o.fd_), p_(o.p_), n_(o.n_) {
    o.fd_ = -1;
    o.p_ = nullptr;
    o.n_ = 0;
}

SharedMemory& SharedMemory::operator=(SharedMemory&& o) noexcept {
    if (this != &o) {
        reset();
        std::swap(fd_, o.fd_);
        std::swap(p_, o.p_);
        std::swap(n_, o.n_);
    }
    return *this;
}

void SharedMemory::reset() {
    if (p_) ::munmap(p_, n_);
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    p_ = nullptr;
    n_ = 0;
}

SharedMemory SharedMemory::create(const std::string& what, std::size_t bytes, bool client_writes) {
    SharedMemory m;
    m.fd_ = ::memfd_create(what.c_str(), MFD_CLOEXEC | MFD_ALLOW_SEALING);
    if (m.fd_ < 0) fail(what, "memfd_create");
    if (::ftruncate(m.fd_, off_t(bytes)) != 0) fail(what, "ftruncate");
    m.p_ = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, m.fd_, 0);
    if (m.p_ == MAP_FAILED) {
        m.p_ = nullptr;
        fail(what, "mmap");
    }
    m.n_ = bytes;
    // F_SEAL_FUTURE_WRITE keeps this mapping writable but refuses any new writable one (Linux 5.1).
    int seals = F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_SEAL | (client_writes ? 0 : F_SEAL_FUTURE_WRITE);
    if (::fcntl(m.fd_, F_ADD_SEALS, seals) != 0) fail(what, "fcntl(F_ADD_SEALS)");
    return m;
}

SharedMemory SharedMemory::map(int fd, const std::string& what, std::size_t min_bytes, bool writable) {
    SharedMemory m;
    m.fd_ = fd;
    struct stat st {};
    if (::fstat(fd, &st) != 0) fail(what, "fstat");
    if (std::size_t(st.st_size) < min_bytes)
        throw Error(SB() << what << ": " << st.st_size << " bytes, at least " << min_bytes << " expected");
    int seals = ::fcntl(fd, F_GET_SEALS);
    if (seals < 0 || !(seals & F_SEAL_SHRINK)) throw Error(SB() << what << ": not sealed against shrinking; refused");
    m.p_ = ::mmap(nullptr, std::size_t(st.st_size), PROT_READ | (writable ? PROT_WRITE : 0), MAP_SHARED, fd, 0);
    if (m.p_ == MAP_FAILED) {
        m.p_ = nullptr;
        fail(what, "mmap");
    }
    m.n_ = std::size_t(st.st_size);
    return m;
}

void send_fds(int sock, const uint8_t* data, std::size_t n, const std::vector<int>& fds) {
    std::size_t sent = 0;
    while (sent < n) {
        iovec iov{const_cast<uint8_t*>(data + sent), n - sent};
        msghdr msg{};
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        alignas(cmsghdr) char ctl[CMSG_SPACE(sizeof(int) * 8)];
        if (sent == 0 && !fds.empty()) {
            if (fds.size() > 8) throw Error("send_fds: at most 8 file descriptors");
            msg.msg_control = ctl;
            msg.msg_controllen = CMSG_SPACE(sizeof(int) * fds.size());
            cmsghdr* c = CMSG_FIRSTHDR(&msg);
            c->cmsg_level = SOL_SOCKET;
            c->cmsg_type = SCM_RIGHTS;
            c->cmsg_len = CMSG_LEN(sizeof(int) * fds.size());
            std::memcpy(CMSG_DATA(c), fds.data(), sizeof(int) * fds.size());
        }
        ssize_t r = ::sendmsg(sock, &msg, MSG_NOSIGNAL);
        if (r < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN) { // a non-blocking socket whose buffer is full: wait for room
                fd_set w;
                FD_ZERO(&w);
                FD_SET(sock, &w);
                timeval tv{1, 0};
                if (::select(sock + 1, nullptr, &w, nullptr, &tv) > 0) continue;
            }
            throw Error(SB() << "send: " << std::strerror(errno));
        }
        sent += std::size_t(r);
    }
}

long recv_fds(int sock, uint8_t* buf, std::size_t cap, std::vector<int>& fds) noexcept {
    iovec iov{buf, cap};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    alignas(cmsghdr) char ctl[CMSG_SPACE(sizeof(int) * 8)];
    msg.msg_control = ctl;
    msg.msg_controllen = sizeof ctl;
    ssize_t r = ::recvmsg(sock, &msg, MSG_CMSG_CLOEXEC);
    if (r < 0) return -1;
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
        if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_RIGHTS) continue;
        std::size_t k = (c->cmsg_len - CMSG_LEN(0)) / sizeof(int);
        for (std::size_t i = 0; i < k; ++i) {
            int fd;
            std::memcpy(&fd, CMSG_DATA(c) + i * sizeof(int), sizeof fd);
            fds.push_back(fd);
        }
    }
    return long(r);
}

bool futex_wait_until(const uint32_t* word, uint32_t expected, uint64_t deadline_ns) noexcept {
    timespec ts{time_t(deadline_ns / 1'000'000'000), long(deadline_ns % 1'000'000'000)};
    // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC time; shared (no FUTEX_PRIVATE_FLAG).
    long r = ::syscall(SYS_futex, word, FUTEX_WAIT_BITSET, expected, &ts, nullptr, FUTEX_BITSET_MATCH_ANY);
    return !(r < 0 && errno == ETIMEDOUT);
}

int futex_wake(const uint32_t* word) noexcept {
    long r = ::syscall(SYS_futex, word, FUTEX_WAKE, INT_MAX, nullptr, nullptr, 0);
    return r < 0 ? 0 : int(r);
}

} // namespace beamctl::scanner
