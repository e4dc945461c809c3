// `beamctl shell`'s transport: a local UNIX stream socket the IOC owns (mode 0600, removed at
// exit; a connection from any user but the IOC's own and root, by SO_PEERCRED, is refused and
// logged), served on the IOC's EventLoop without blocking, and the client that connects to it.
// Protocol: the client sends command lines ('\n'-terminated); for each the server sends the
// command's output, a NUL byte and '0' (succeeded) or '1' (failed). A line longer than
// kMaxLine bytes gets an error and the connection is closed; at most kMaxClients at once.
// Threading: a ShellServer lives on its EventLoop's thread (the thread that owns the Database).
#pragma once

#include "core/event_loop.hpp"
#include "core/local_socket.hpp"
#include "pv/db_shell.hpp"

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace beamctl::pv {

// Where IOC sockets live: $XDG_RUNTIME_DIR/beamctl, else /tmp/beamctl-<uid>.
std::string shell_socket_dir();
// The socket of the IOC called `name`: <shell_socket_dir()>/<name>.sock.
std::string default_shell_socket(const std::string& name);

class ShellServer {
public:
    static constexpr std::size_t kMaxLine = 64 * 1024;      // [bytes] of one command line
    static constexpr std::size_t kMaxOutput = 64u << 20;    // [bytes] waiting for a slow client
    static constexpr std::size_t kMaxClients = 16;

    ShellServer(EventLoop& loop, DbShell& shell);
    ~ShellServer(); // closes every connection and removes the socket file
    ShellServer(const ShellServer&) = delete;
    ShellServer& operator=(const ShellServer&) = delete;

    // Listens on `path` (its directory is created with mode 0700 if missing). A stale socket
    // file (no IOC behind it) is replaced. Throws Error naming the path if it cannot listen, or
    // if another running IOC owns it.
    void start(const std::string& path);
    const std::string& path() const { return path_; }
    std::size_t client_count() const { return conns_.size(); }
    // Connections refused because the peer (SO_PEERCRED) is neither this IOC's user nor root.
    std::uint64_t refused() const { return refused_; }

private:
    struct Conn {
        int fd;
        std::string in, out;
        bool closing = false; // close once `out` is sent
    };
    void on_accept();
    void on_io(int fd, uint32_t events);
    void flush(Conn& c);
    void close_conn(int fd);

    EventLoop& loop_;
    DbShell& shell_;
    std::string path_;
    int listen_fd_ = -1;
    std::unordered_map<int, std::unique_ptr<Conn>> conns_;
    std::uint64_t refused_ = 0;
    std::chrono::steady_clock::time_point last_refusal_log_{};
    core::SocketGroup group_; // who besides this user and root may connect
};

// Starts the shell socket of an IOC: `path` if given (the command line), else
// $BEAMCTL_SHELL_SOCKET, else default_shell_socket(name), or <name>-<pid>.sock when another
// running IOC of the same name owns that. "none" serves nothing (returns nullptr). Prints
// "shell: PATH" on stdout; an error is printed on stderr and the IOC runs without a shell.
std::unique_ptr<ShellServer> start_shell_server(EventLoop& loop, DbShell& shell,
                                                const std::string& name, const std::string& path);

struct ShellClientOptions {
    std::string socket;                // --socket PATH
    std::string name;                  // an IOC name (or a path with '/')
    std::vector<std::string> commands; // -c CMD (repeatable); none: lines from stdin
};
// `beamctl shell`: runs the commands (or stdin's lines, with a prompt on a terminal) against the
// IOC's socket, printing their output. Returns 0, 1 if a command failed, 2 if it cannot connect.
int run_shell_client(const ShellClientOptions& options);

} // namespace beamctl::pv
