// pv::ShellServer on a real UNIX socket, its loop on a thread: framing, the line limit, the socket
// file's mode and removal.
#include "pv/shell_server.hpp"

#include "db_fixture.hpp"

#include <filesystem>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>

namespace beamctl::pv {
namespace {

namespace fs = std::filesystem;

int connect_to(const std::string& path) {
    int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, path.c_str(), sizeof a.sun_path - 1);
    EXPECT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0) << std::strerror(errno);
    timeval tv{30, 0}; // generous: a stuck server fails the test instead of hanging it
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return fd;
}

// Everything until the reply's NUL and status byte (or the connection's end).
std::string reply(int fd, char* status) {
    std::string out;
    char c;
    *status = 0;
    while (::read(fd, &c, 1) == 1) {
        if (c == '\0') {
            if (::read(fd, status, 1) != 1) *status = '?';
            return out;
        }
        out += c;
    }
    return out;
}

struct ShellServerTest : DbTest {};

TEST_F(ShellServerTest, AnswersLinesAndRefusesHugeOnes) {
    load("record(ao, \"x:ao\") { field(EGU, \"mm\") }\n");
    std::string dir = (fs::temp_directory_path() / ("beamctl_shell_" + std::to_string(::getpid()))).string();
    std::string path = dir + "/t.sock";
    EventLoop loop;
    DbShell shell(db);
    {
        ShellServer server(loop, shell);
        server.start(path);
        struct stat st {};
        ASSERT_EQ(::stat(path.c_str(), &st), 0);
        EXPECT_EQ(st.st_mode & 0777, 0660u); // this user and the socket group (core/local_socket.hpp)
        EXPECT_THROW(ShellServer(loop, shell).start(path), Error); // in use: a live socket
        std::thread t([&] { loop.run(); });

        int fd = connect_to(path);
        const char two[] = "dbgf x:ao.EGU\r\nnope\n";
        ASSERT_EQ(::write(fd, two, sizeof two - 1), ssize_t(sizeof two - 1));
        char st1, st2;
        EXPECT_EQ(reply(fd, &st1), "DBF_STRING:         \"mm\"      \n");
        EXPECT_EQ(st1, '0');
        EXPECT_EQ(reply(fd, &st2), "error: unknown command 'nope' (help lists the commands)\n");
        EXPECT_EQ(st2, '1');

        std::string huge(ShellServer::kMaxLine + 10, 'x');
        ssize_t w = ::send(fd, huge.data(), huge.size(), MSG_NOSIGNAL);
        EXPECT_GT(w, 0);
        char st3;
        EXPECT_EQ(reply(fd, &st3), "error: line longer than 65536 bytes\n");
        EXPECT_EQ(st3, '1');
        char c;
        EXPECT_EQ(::read(fd, &c, 1), 0); // closed by the server
        ::close(fd);

        int fd2 = connect_to(path); // the server goes on
        ASSERT_EQ(::write(fd2, "dbgf x:ao\n", 10), 10);
        char st4;
        EXPECT_EQ(reply(fd2, &st4), "DBF_DOUBLE:         0         \n");
        ::close(fd2);
        loop.post([&] { loop.stop(); });
        t.join();
    }
    EXPECT_FALSE(fs::exists(path)); // removed with the server
    fs::remove_all(dir);
}

} // namespace
} // namespace beamctl::pv
