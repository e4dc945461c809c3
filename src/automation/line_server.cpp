#include "automation/line_server.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

namespace beamctl::automation {
namespace {

log::Logger lg("lineserver");

} // namespace

LineServer::LineServer(EventLoop& loop, Handler handler, std::function<void(int)> on_clients, std::function<void(const std::string&)> on_rejected)
    : loop_(loop), handler_(std::move(handler)), on_clients_(std::move(on_clients)), on_rejected_(std::move(on_rejected)) {}

LineServer::~LineServer() {
    while (!conns_.empty()) close_conn(conns_.begin()->first);
    if (listen_fd_ >= 0) {
        loop_.remove_fd(listen_fd_);
        ::close(listen_fd_);
    }
    if (pty_slave_ >= 0) ::close(pty_slave_);
    if (!pty_link_.empty()) ::unlink(pty_link_.c_str());
}

void LineServer::listen_tcp(const std::string& bind, int port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(port));
    if (::inet_pton(AF_INET, bind.c_str(), &a.sin_addr) != 1) throw Error(SB() << "'" << bind << "' is not an IPv4 address to listen on");
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) throw Error(SB() << "socket: " << std::strerror(errno));
    const int one = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 8) != 0) {
        const int e = errno;
        ::close(fd);
        throw Error(SB() << "cannot listen on " << bind << ":" << port << ": " << std::strerror(e));
    }
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    listen_fd_ = fd;
    loop_.add_fd(fd, EPOLLIN, [this](uint32_t) { on_accept(); });
}

void LineServer::open_pty(const std::string& path) {
    struct stat st {};
    if (::lstat(path.c_str(), &st) == 0 && !S_ISLNK(st.st_mode))
        throw Error(SB() << "pty: '" << path << "' exists and is not a symlink (not replacing it)");
    const int m = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (m < 0 || ::grantpt(m) != 0 || ::unlockpt(m) != 0) {
        const int e = errno;
        if (m >= 0) ::close(m);
        throw Error(SB() << "pty: cannot open a pseudo-terminal: " << std::strerror(e));
    }
    pty_name_ = ::ptsname(m);
    pty_slave_ = ::open(pty_name_.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
    termios t{};
    if (pty_slave_ < 0 || ::tcgetattr(pty_slave_, &t) != 0) {
        const int e = errno;
        ::close(m);
        throw Error(SB() << "pty: " << pty_name_ << ": " << std::strerror(e));
    }
    ::cfmakeraw(&t); // no echo, no CR/LF translation: bytes as a serial line carries them
    ::tcsetattr(pty_slave_, TCSANOW, &t);
    ::unlink(path.c_str());
    if (::symlink(pty_name_.c_str(), path.c_str()) != 0) {
        const int e = errno;
        ::close(m);
        throw Error(SB() << "pty: cannot link '" << path << "' to " << pty_name_ << ": " << std::strerror(e));
    }
    pty_link_ = path;
    const uint64_t id = next_id_++;
    conns_[id] = Conn{m, false, {}, {}, false};
    loop_.add_fd(m, EPOLLIN, [this, id](uint32_t ev) { on_io(id, ev); });
}

void LineServer::on_accept() {
    for (;;) {
        const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) return;
        std::size_t tcp = 0;
        for (const auto& [id, c] : conns_) tcp += c.tcp;
        if (tcp >= kMaxClients) {
            static const char msg[] = "ERR too many clients\r\n";
            (void)!::write(fd, msg, sizeof msg - 1);
            ::close(fd);
            LOG_WARN(lg, "refused a client: " << kMaxClients << " are connected");
            continue;
        }
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        const uint64_t id = next_id_++;
        conns_[id] = Conn{fd, true, {}, {}, false};
        loop_.add_fd(fd, EPOLLIN | EPOLLRDHUP, [this, id](uint32_t ev) { on_io(id, ev); });
        clients_changed();
    }
}

void LineServer::on_io(uint64_t id, uint32_t events) {
    auto it = conns_.find(id);
    if (it == conns_.end()) return;
    if (events & EPOLLOUT) flush(id);
    if (conns_.find(id) == conns_.end() || !(events & (EPOLLIN | EPOLLHUP | EPOLLRDHUP | EPOLLERR))) return;
    char buf[4096];
    for (;;) {
        auto c = conns_.find(id);
        if (c == conns_.end()) return;
        const ssize_t n = ::read(c->second.fd, buf, sizeof buf);
        if (n > 0) {
            c->second.in.append(buf, std::size_t(n));
            take_lines(id);
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EINTR)) return;
        // end of the stream: a TCP client left; a pty without a client reads EIO (the slave is ours)
        if (c->second.tcp) close_conn(id);
        return;
    }
}

LineEvent next_line(std::string& in, bool& dropping, std::string& line, std::size_t max) {
    for (;;) {
        const std::size_t end = in.find_first_of("\r\n");
        if (end == std::string::npos) {
            if (in.size() <= max) return LineEvent::None;
            in.clear(); // no terminator in sight: drop what is there, and the rest up to one
            if (dropping) return LineEvent::None;
            dropping = true;
            return LineEvent::TooLong;
        }
        const bool dropped = dropping;
        dropping = false;
        if (dropped) { // the tail of a line that was too long
            in.erase(0, end + 1);
            continue;
        }
        if (end > max) {
            in.erase(0, end + 1);
            return LineEvent::TooLong;
        }
        line.assign(in, 0, end);
        in.erase(0, end + 1);
        if (line.find_first_not_of(" \t") == std::string::npos) continue; // blank (or the \n of \r\n)
        return LineEvent::Line;
    }
}

void LineServer::take_lines(uint64_t id) {
    std::string line;
    for (;;) {
        auto it = conns_.find(id); // again each time: a reply may have closed the connection
        if (it == conns_.end()) return;
        const LineEvent e = next_line(it->second.in, it->second.dropping, line, kMaxLine);
        if (e == LineEvent::None) return;
        if (e == LineEvent::TooLong) {
            ++too_long_;
            const std::string why = "ERR line too long (at most " + std::to_string(kMaxLine) + " bytes)";
            if (on_rejected_) on_rejected_(why);
            send(id, why);
            continue;
        }
        handler_(line, [this, id](const std::string& reply) { send(id, reply); });
    }
}

void LineServer::send(uint64_t id, const std::string& line) {
    auto it = conns_.find(id);
    if (it == conns_.end()) return; // gone
    Conn& c = it->second;
    c.out += line;
    c.out += "\r\n";
    if (c.out.size() > kMaxOutput) {
        if (!c.tcp) { // a pty nobody reads: its replies are dropped, the pty stays
            c.out.clear();
            return;
        }
        LOG_WARN(lg, "closed a client that does not read its replies");
        return close_conn(id);
    }
    flush(id);
}

void LineServer::flush(uint64_t id) {
    auto it = conns_.find(id);
    if (it == conns_.end()) return;
    Conn& c = it->second;
    while (!c.out.empty()) {
        const ssize_t n = ::write(c.fd, c.out.data(), c.out.size());
        if (n > 0) {
            c.out.erase(0, std::size_t(n));
            continue;
        }
        if (n < 0 && errno == EAGAIN) {
            loop_.modify_fd(c.fd, EPOLLIN | EPOLLOUT | (c.tcp ? EPOLLRDHUP : 0));
            return;
        }
        if (c.tcp) return close_conn(id);
        c.out.clear(); // a pty nobody reads: the reply is lost with the client
        return;
    }
    loop_.modify_fd(c.fd, EPOLLIN | (c.tcp ? EPOLLRDHUP : 0));
}

void LineServer::close_conn(uint64_t id) {
    auto it = conns_.find(id);
    if (it == conns_.end()) return;
    const bool tcp = it->second.tcp;
    loop_.remove_fd(it->second.fd);
    ::close(it->second.fd);
    conns_.erase(it);
    if (tcp) clients_changed();
}

void LineServer::clients_changed() {
    if (!on_clients_) return;
    int n = 0;
    for (const auto& [id, c] : conns_) n += c.tcp;
    on_clients_(n);
}

} // namespace beamctl::automation
