#include "core/local_socket.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <grp.h>
#include <sstream>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

namespace beamctl::core {

namespace {
bool address(const std::string& path, sockaddr_un& a) {
    std::memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    if (path.empty() || path.size() >= sizeof a.sun_path) return false;
    std::memcpy(a.sun_path, path.c_str(), path.size() + 1);
    return true;
}

// Whether a server answers on the socket file at `path`.
bool answers(const sockaddr_un& a) {
    int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return false;
    bool ok = ::connect(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0;
    ::close(fd);
    return ok;
}

// The supplementary groups of a process, from /proc/<pid>/status ("Groups:\t4 24 100").
bool has_group(pid_t pid, gid_t gid) {
    std::ifstream f(SB() << "/proc/" << pid << "/status");
    std::string line;
    while (std::getline(f, line)) {
        if (line.rfind("Groups:", 0) != 0) continue;
        std::istringstream is(line.substr(7));
        long g;
        while (is >> g)
            if (gid_t(g) == gid) return true;
        return false;
    }
    return false;
}
} // namespace

SocketGroup socket_group_named(const std::string& v, const std::string& what) {
    SocketGroup g;
    if (group* gr = ::getgrnam(v.c_str())) {
        g.gid = gr->gr_gid;
    } else {
        char* end = nullptr;
        long n = std::strtol(v.c_str(), &end, 10);
        if (v.empty() || !end || *end || n < 0) throw Error(SB() << what << "=" << v << ": no such group on this system");
        g.gid = gid_t(n);
    }
    group* gr = ::getgrgid(g.gid);
    g.name = gr ? std::string(gr->gr_name) : std::to_string(g.gid);
    return g;
}

SocketGroup socket_group() {
    const char* env = std::getenv("BEAMCTL_SOCKET_GROUP");
    if (env && *env) return socket_group_named(env, "BEAMCTL_SOCKET_GROUP");
    SocketGroup g;
    g.gid = ::getegid();
    group* gr = ::getgrgid(g.gid);
    g.name = gr ? std::string(gr->gr_name) : std::to_string(g.gid);
    return g;
}

int listen_local(const std::string& path, const std::string& what, int backlog, bool nonblocking, const SocketGroup* with) {
    sockaddr_un a;
    if (!address(path, a))
        throw Error(SB() << what << " '" << path << "': the path must be 1.." << sizeof a.sun_path - 1 << " characters");
    SocketGroup group = with ? *with : socket_group();
    struct stat st {};
    if (::lstat(path.c_str(), &st) == 0) {
        if (!S_ISSOCK(st.st_mode)) throw Error(SB() << what << " " << path << ": the path exists and is not a socket");
        if (answers(a)) throw Error(SB() << what << " " << path << ": in use by another running process");
        if (::unlink(path.c_str()) != 0 && errno != ENOENT) // stale: its process is gone
            throw Error(SB() << what << " " << path << ": cannot remove the stale socket file: " << std::strerror(errno));
    }
    int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | (nonblocking ? SOCK_NONBLOCK : 0), 0);
    if (fd < 0) throw Error(SB() << what << " " << path << ": " << std::strerror(errno));
    mode_t old = ::umask(0177); // created 0600; 0660 once it has its group (no window with other groups)
    int rc = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    int e = errno;
    ::umask(old);
    if (rc == 0 && ::chown(path.c_str(), uid_t(-1), group.gid) != 0) rc = -1, e = errno;
    if (rc == 0 && ::chmod(path.c_str(), 0660) != 0) rc = -1, e = errno;
    if (rc == 0 && ::listen(fd, backlog) != 0) rc = -1, e = errno;
    if (rc != 0) {
        ::close(fd);
        std::string hint = e == EPERM ? std::string(SB() << " (giving it group " << group.name << ": is this user a member?)") : "";
        throw Error(SB() << what << " " << path << ": " << std::strerror(e) << hint);
    }
    return fd;
}

bool peer_allowed(int fd, const SocketGroup& group, Peer& peer) {
    ucred c{};
    socklen_t len = sizeof c;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &c, &len) != 0) {
        peer = Peer{0, uid_t(-1), gid_t(-1)};
        return false;
    }
    peer = Peer{c.pid, c.uid, c.gid};
    if (c.uid == ::geteuid() || c.uid == 0) return true;
    return c.gid == group.gid || has_group(c.pid, group.gid);
}

} // namespace beamctl::core
