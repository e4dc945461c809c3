// The one policy of local (UNIX) sockets (issue 19): mode 0660 and the socket group, a stale
// socket file from a crashed run replaced, a live server or a non-socket path refused by name,
// the peer's credentials checked.
#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "core/local_socket.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

using namespace beamctl;
using beamctl::test::TempDir;

namespace {
int connect_to(const std::string& path) {
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::snprintf(a.sun_path, sizeof a.sun_path, "%s", path.c_str());
    int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return -1;
    }
    return fd;
}
} // namespace

TEST(LocalSocket, ModeGroupStaleAndLive) {
    TempDir d;
    std::string path = d.file("x.sock");
    int fd = core::listen_local(path, "test socket", 4, false);
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0660u);
    EXPECT_EQ(st.st_gid, ::getegid());
    // a second server on a live socket: refused, naming it
    try {
        (void)core::listen_local(path, "test socket", 4, false);
        FAIL() << "two servers on one path";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("test socket " + path + ": in use by another running process"), std::string::npos)
            << e.what();
    }
    // our own connection is allowed, with our credentials
    int c = connect_to(path);
    ASSERT_GE(c, 0);
    int s = ::accept(fd, nullptr, nullptr);
    ASSERT_GE(s, 0);
    core::Peer peer;
    EXPECT_TRUE(core::peer_allowed(s, core::socket_group(), peer));
    EXPECT_EQ(peer.uid, ::geteuid());
    EXPECT_EQ(peer.pid, ::getpid());
    ::close(s);
    ::close(c);
    // the server crashes (its fd closed, the file left): the next one replaces the file
    ::close(fd);
    ASSERT_EQ(::lstat(path.c_str(), &st), 0);
    fd = core::listen_local(path, "test socket", 4, false);
    EXPECT_GE(connect_to(path), 0);
    ::close(fd);
    // a path that is not a socket is never removed
    std::string file = d.file("not-a-socket");
    std::ofstream(file) << "data";
    EXPECT_THROW((void)core::listen_local(file, "test socket", 4, false), Error);
    EXPECT_EQ(::access(file.c_str(), F_OK), 0);
}

TEST(LocalSocket, SocketGroupFromTheEnvironment) {
    ::setenv("BEAMCTL_SOCKET_GROUP", "no-such-group-xyz", 1);
    try {
        (void)core::socket_group();
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("BEAMCTL_SOCKET_GROUP=no-such-group-xyz: no such group"), std::string::npos);
    }
    ::setenv("BEAMCTL_SOCKET_GROUP", "0", 1);
    EXPECT_EQ(core::socket_group().gid, 0u);
    ::unsetenv("BEAMCTL_SOCKET_GROUP");
    EXPECT_EQ(core::socket_group().gid, ::getegid());
}
