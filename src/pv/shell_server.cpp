#include "pv/shell_server.hpp"

#include "core/error.hpp"
#include "core/local_socket.hpp"
#include "core/log.hpp"

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

namespace beamctl::pv {

namespace {

namespace fs = std::filesystem;

log::Logger lg("pv.shell");

bool make_address(const std::string& path, sockaddr_un& addr) {
    std::memset(&addr, 0, sizeof addr);
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof addr.sun_path) return false;
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    return true;
}

// Connects to a UNIX socket; returns the fd, or -1 with errno set.
int connect_unix(const std::string& path) {
    sockaddr_un addr;
    if (!make_address(path, addr)) {
        errno = ENAMETOOLONG;
        return -1;
    }
    int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        int e = errno;
        ::close(fd);
        errno = e;
        return -1;
    }
    return fd;
}

} // namespace

std::string shell_socket_dir() {
    if (const char* x = std::getenv("XDG_RUNTIME_DIR"); x && *x && fs::is_directory(x))
        return (fs::path(x) / "beamctl").string();
    return SB() << "/tmp/beamctl-" << ::getuid();
}

std::string default_shell_socket(const std::string& name) {
    return (fs::path(shell_socket_dir()) / (name + ".sock")).string();
}

// --- server -------------------------------------------------------------------------------------

ShellServer::ShellServer(EventLoop& loop, DbShell& shell)
    : loop_(loop), shell_(shell) {}

ShellServer::~ShellServer() {
    std::vector<int> fds;
    for (auto& [fd, c] : conns_) fds.push_back(fd);
    for (int fd : fds) close_conn(fd);
    if (listen_fd_ >= 0) {
        loop_.remove_fd(listen_fd_);
        ::close(listen_fd_);
        ::unlink(path_.c_str());
    }
}

void ShellServer::start(const std::string& path) {
    sockaddr_un addr;
    if (!make_address(path, addr))
        throw Error(SB() << "shell socket " << path << ": path longer than " << sizeof addr.sun_path - 1
                         << " characters");
    group_ = core::socket_group();
    fs::path dir = fs::path(path).parent_path();
    if (!dir.empty()) {
        std::error_code ec;
        if (!fs::exists(dir, ec)) {
            fs::create_directories(dir, ec);
            if (ec) throw Error(SB() << "shell socket " << path << ": cannot create " << dir.string() << ": " << ec.message());
            if (group_.gid != ::getegid()) { // a directory of ours: members of the socket group must reach the socket
                ::chown(dir.c_str(), uid_t(-1), group_.gid);
                ::chmod(dir.c_str(), 0750);
            } else {
                ::chmod(dir.c_str(), 0700);
            }
        }
    }
    int fd = core::listen_local(path, "shell socket", 8, true);
    listen_fd_ = fd;
    path_ = path;
    loop_.add_fd(fd, EPOLLIN, [this](uint32_t) { on_accept(); });
}

void ShellServer::on_accept() {
    while (true) {
        int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) return; // EAGAIN, or an error of that one connection
        // The socket file is 0660, but a mode can be changed: the kernel's word on who connected
        // decides. This IOC's own user, root and members of the socket group may use the shell.
        core::Peer peer;
        if (!core::peer_allowed(fd, group_, peer)) {
            ++refused_;
            const auto now = std::chrono::steady_clock::now();
            if (refused_ == 1 || now - last_refusal_log_ >= std::chrono::seconds(10)) {
                last_refusal_log_ = now;
                lg.write(log::Level::warn,
                         SB() << "shell socket " << path_ << ": refused a connection from uid " << peer.uid
                              << " (pid " << peer.pid << "): only uid " << ::geteuid() << ", root and group "
                              << group_.name << " may use it (" << refused_ << " refused so far)");
            }
            const std::string msg = SB() << "error: uid " << peer.uid << " may not use this IOC's shell\n";
            (void)!::send(fd, msg.data(), msg.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
            (void)!::send(fd, "\0" "1", 2, MSG_NOSIGNAL | MSG_DONTWAIT);
            ::close(fd);
            continue;
        }
        if (conns_.size() >= kMaxClients) {
            const char msg[] = "error: too many shell clients\n\0" "1";
            (void)!::send(fd, msg, sizeof msg - 1, MSG_NOSIGNAL | MSG_DONTWAIT);
            ::close(fd);
            continue;
        }
        auto c = std::make_unique<Conn>();
        c->fd = fd;
        conns_[fd] = std::move(c);
        loop_.add_fd(fd, EPOLLIN, [this, fd](uint32_t ev) { on_io(fd, ev); });
    }
}

void ShellServer::on_io(int fd, uint32_t events) {
    auto it = conns_.find(fd);
    if (it == conns_.end()) return;
    Conn& c = *it->second;
    if (events & (EPOLLERR | EPOLLHUP)) {
        if (!(events & EPOLLIN)) {
            close_conn(fd);
            return;
        }
    }
    if ((events & EPOLLIN) && !c.closing) {
        char buf[16384];
        bool eof = false;
        while (true) {
            ssize_t n = ::read(fd, buf, sizeof buf);
            if (n > 0) {
                c.in.append(buf, std::size_t(n));
                if (c.in.size() > 4 * kMaxLine) break; // handled below; read the rest later
                continue;
            }
            if (n == 0) eof = true;
            else if (errno == EINTR) continue;
            else if (errno != EAGAIN && errno != EWOULDBLOCK) eof = true;
            break;
        }
        std::size_t start = 0;
        while (!c.closing) {
            std::size_t nl = c.in.find('\n', start);
            if (nl == std::string::npos) {
                if (c.in.size() - start > kMaxLine) {
                    c.out += SB() << "error: line longer than " << kMaxLine << " bytes\n";
                    c.out += std::string("\0" "1", 2);
                    c.closing = true;
                }
                break;
            }
            std::string_view line(c.in.data() + start, nl - start);
            if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
            start = nl + 1;
            std::ostringstream os;
            bool ok;
            if (line.size() > kMaxLine) {
                os << "error: line longer than " << kMaxLine << " bytes\n";
                ok = false;
            } else if (line.find('\0') != std::string_view::npos) {
                os << "error: NUL byte in the command line\n";
                ok = false;
            } else {
                ok = shell_.execute(line, os);
            }
            c.out += os.str();
            c.out.push_back('\0');
            c.out.push_back(ok ? '0' : '1');
            if (c.out.size() > kMaxOutput) c.closing = true; // a client that does not read
        }
        c.in.erase(0, start);
        if (eof) c.closing = true;
    }
    flush(c);
}

void ShellServer::flush(Conn& c) {
    while (!c.out.empty()) {
        ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) {
            c.out.erase(0, std::size_t(n));
            continue;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            if (c.out.size() > kMaxOutput) {
                close_conn(c.fd);
                return;
            }
            // closing: only the rest of the output matters (no busy loop on unread input)
            loop_.modify_fd(c.fd, c.closing ? EPOLLOUT : EPOLLIN | EPOLLOUT);
            return;
        }
        close_conn(c.fd); // the client went away
        return;
    }
    if (c.closing) {
        close_conn(c.fd);
        return;
    }
    loop_.modify_fd(c.fd, EPOLLIN);
}

void ShellServer::close_conn(int fd) {
    loop_.remove_fd(fd);
    ::close(fd);
    conns_.erase(fd);
}

std::unique_ptr<ShellServer> start_shell_server(EventLoop& loop, DbShell& shell,
                                                const std::string& name, const std::string& path) {
    std::string p = path;
    if (p.empty())
        if (const char* e = std::getenv("BEAMCTL_SHELL_SOCKET"); e && *e) p = e;
    if (p == "none") return nullptr;
    auto server = std::make_unique<ShellServer>(loop, shell);
    try {
        if (!p.empty()) {
            server->start(p);
        } else {
            // The default directory must be ours alone (/tmp is everybody's).
            const std::string dir = shell_socket_dir();
            struct stat st {};
            if (::lstat(dir.c_str(), &st) == 0 &&
                (!S_ISDIR(st.st_mode) || st.st_uid != ::getuid() || (st.st_mode & 077) != 0))
                throw Error(SB() << "shell socket directory " << dir
                                 << ": not a directory of this user with mode 0700");
            try {
                server->start(default_shell_socket(name));
            } catch (const Error&) { // another IOC of this name runs: one of this process's own
                server->start(default_shell_socket(SB() << name << "-" << ::getpid()));
            }
        }
    } catch (const Error& e) {
        std::fprintf(stderr, "%s: the IOC runs without 'beamctl shell'\n", e.what());
        return nullptr;
    }
    std::printf("shell: %s\n", server->path().c_str());
    std::fflush(stdout);
    return server;
}

// --- client -------------------------------------------------------------------------------------

namespace {

// Sends one line and prints its output; returns 0 ok, 1 failed, -1 connection lost.
int run_one(int fd, const std::string& line) {
    std::string msg = line + "\n";
    const char* p = msg.data();
    std::size_t left = msg.size();
    while (left > 0) {
        ssize_t n = ::send(fd, p, left, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return -1;
        p += n;
        left -= std::size_t(n);
    }
    std::string out;
    char buf[8192];
    bool nul = false;
    while (true) {
        ssize_t n = ::read(fd, buf, sizeof buf);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            std::fwrite(out.data(), 1, out.size(), stdout);
            return -1;
        }
        for (ssize_t i = 0; i < n; ++i) {
            if (nul) {
                std::fwrite(out.data(), 1, out.size(), stdout);
                std::fflush(stdout);
                return buf[i] == '0' ? 0 : 1; // one reply per line: nothing follows it
            }
            if (buf[i] == '\0')
                nul = true;
            else
                out.push_back(buf[i]);
        }
    }
}

} // namespace

int run_shell_client(const ShellClientOptions& o) {
    std::string path = o.socket;
    if (path.empty() && !o.name.empty())
        path = o.name.find('/') != std::string::npos ? o.name : default_shell_socket(o.name);
    if (path.empty()) {
        if (const char* e = std::getenv("BEAMCTL_SHELL_SOCKET"); e && *e) path = e;
    }
    if (path.empty()) { // the only IOC of this user, if there is one
        std::vector<std::string> found;
        std::error_code ec;
        for (auto& e : fs::directory_iterator(shell_socket_dir(), ec)) {
            if (e.path().extension() != ".sock") continue;
            int probe = connect_unix(e.path().string()); // left by an IOC that was killed: skip
            if (probe < 0) continue;
            ::close(probe);
            found.push_back(e.path().string());
        }
        if (found.size() != 1) {
            std::fprintf(stderr, "beamctl shell: %s; name one with --socket PATH or NAME%s\n",
                         found.empty() ? ("no running IOC has a socket in " + shell_socket_dir()).c_str()
                                       : "more than one IOC runs",
                         found.empty() ? "" : ":");
            for (auto& f : found) std::fprintf(stderr, "  %s\n", f.c_str());
            return 2;
        }
        path = found[0];
    }
    int fd = connect_unix(path);
    if (fd < 0) {
        std::fprintf(stderr, "beamctl shell: cannot connect to %s: %s\n", path.c_str(), std::strerror(errno));
        return 2;
    }
    int failed = 0;
    auto one = [&](const std::string& line) {
        int r = run_one(fd, line);
        if (r < 0) {
            std::fprintf(stderr, "beamctl shell: the IOC closed the connection\n");
            return false;
        }
        failed |= r;
        return true;
    };
    if (!o.commands.empty()) {
        for (const auto& c : o.commands)
            if (!one(c)) {
                ::close(fd);
                return 2;
            }
    } else {
        const bool tty = ::isatty(0);
        std::string line;
        while (true) {
            if (tty) {
                std::printf("beamctl> ");
                std::fflush(stdout);
            }
            if (!std::getline(std::cin, line)) break;
            if (tty && (line == "exit" || line == "quit")) break;
            if (!one(line)) {
                ::close(fd);
                return 2;
            }
        }
        if (tty) std::printf("\n");
    }
    ::close(fd);
    return failed ? 1 : 0;
}

} // namespace beamctl::pv
