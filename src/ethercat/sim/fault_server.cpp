#include "ethercat/sim/fault_server.hpp"

#include "core/error.hpp"
#include "core/local_socket.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"

#include <cerrno>
#include <cstring>
#include <ctime>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

namespace beamctl::ethercat::sim {
namespace {
log::Logger lg("sim.faults");

sockaddr_un address(const std::string& path) {
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    if (path.empty() || path.size() >= sizeof a.sun_path)
        throw Error(SB() << "control socket '" << path << "': the path must be 1.." << sizeof a.sun_path - 1 << " characters");
    std::memcpy(a.sun_path, path.data(), path.size());
    return a;
}
} // namespace

FaultServer::FaultServer(Segment& seg, const Catalog& catalog, std::string path)
    : seg_(seg), catalog_(catalog), path_(std::move(path)) {
    (void)address(path_); // checks the length, naming the path
    group_ = core::socket_group();
    fd_ = core::listen_local(path_, "control socket", 4, false); // 0660, the socket group; a stale file replaced
    thread_ = std::thread([this] { serve(); });
}

FaultServer::~FaultServer() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    ::close(fd_);
    ::unlink(path_.c_str());
}

std::string FaultServer::handle(const std::string& line) {
    try {
        Fault f = parse_fault(line, catalog_, seg_.size());
        if (!seg_.post(f)) throw Error("too many faults queued; try again");
        ++posted_;
        LOG_WARN(lg, "fault injected: " << describe(f));
        return SB() << "ok: " << describe(f);
    } catch (const Error& e) {
        ++refused_;
        return SB() << "error: " << e.what();
    }
}

void FaultServer::serve() {
    while (!stop_) {
        pollfd p{fd_, POLLIN, 0};
        if (::poll(&p, 1, 100) <= 0) continue;
        int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
        if (c < 0) continue;
        core::Peer peer;
        std::string reply;
        if (!core::peer_allowed(c, group_, peer)) {
            ++refused_;
            timespec ts{};
            clock_gettime(CLOCK_MONOTONIC, &ts);
            double now = double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
            if (now - refusal_logged_s_ >= 10) { // at most every 10 s
                refusal_logged_s_ = now;
                LOG_WARN(lg, "control socket " << path_ << ": refused a connection from uid " << peer.uid << " (pid "
                                               << peer.pid << "): only uid " << ::geteuid() << ", root and group "
                                               << group_.name << " may inject faults (" << refused_ << " refused so far)");
            }
            reply = SB() << "error: uid " << peer.uid << " may not inject faults here\n";
        } else {
            // One line (up to 512 bytes), read within a second.
            std::string line;
            char buf[512];
            for (int waited = 0; waited < 10 && line.find('\n') == std::string::npos && line.size() < sizeof buf;) {
                pollfd q{c, POLLIN, 0};
                if (::poll(&q, 1, 100) <= 0) {
                    ++waited;
                    continue;
                }
                ssize_t n = ::recv(c, buf, sizeof buf - line.size(), 0);
                if (n <= 0) break;
                line.append(buf, std::size_t(n));
            }
            if (auto nl = line.find('\n'); nl != std::string::npos) line.resize(nl);
            reply = handle(line) + "\n";
        }
        (void)!::send(c, reply.data(), reply.size(), MSG_NOSIGNAL);
        ::close(c);
    }
}

std::string send_fault(const std::string& path, const std::string& command) {
    sockaddr_un a = address(path);
    int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) throw Error(SB() << path << ": " << std::strerror(errno));
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        int e = errno;
        ::close(fd);
        throw Error(SB() << path << ": no simulator control socket there (" << std::strerror(e)
                         << "; start one with beamctl sim --control " << path << ")");
    }
    std::string line = command + "\n";
    (void)!::send(fd, line.data(), line.size(), MSG_NOSIGNAL);
    std::string reply;
    char buf[1024];
    for (ssize_t n; (n = ::recv(fd, buf, sizeof buf, 0)) > 0;) reply.append(buf, std::size_t(n));
    ::close(fd);
    while (!reply.empty() && reply.back() == '\n') reply.pop_back();
    if (reply.empty()) throw Error(SB() << path << ": the simulator closed the connection without an answer");
    return reply;
}

} // namespace beamctl::ethercat::sim
