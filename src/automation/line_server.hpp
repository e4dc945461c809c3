// A line-protocol transport on the IOC's EventLoop: a TCP listener and/or a pseudo-terminal (its
// slave reachable through a symlink, raw mode: what a serial client would open), each delivering
// '\n'- or '\r'-terminated lines to a handler that answers with lines (sent with "\r\n"). A line
// longer than kMaxLine is answered "ERR line too long" and dropped; at most kMaxClients TCP
// clients at once (one more is told so and closed). Replies to a connection that has gone are
// dropped. Nothing blocks.
// Threading: the EventLoop's thread.
#pragma once

#include "core/event_loop.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <string_view>

namespace beamctl::automation {

// The framing, apart (fuzzed: tests/fuzz/fuzz_smart_command.cpp): takes the next event out of a
// connection's input `in`. Returns Line (in `line`: not blank, at most max bytes), TooLong (a line
// over max bytes, or max bytes with no terminator yet: dropped up to its terminator), or None
// (wait for more bytes). `dropping` is the connection's state between calls.
enum class LineEvent { None, Line, TooLong };
LineEvent next_line(std::string& in, bool& dropping, std::string& line, std::size_t max);

class LineServer {
public:
    static constexpr std::size_t kMaxLine = 256;
    static constexpr std::size_t kMaxClients = 8;
    static constexpr std::size_t kMaxOutput = 1 << 20; // [bytes] waiting for a slow client: then it is closed
    using Reply = std::function<void(const std::string& line)>;
    using Handler = std::function<void(std::string_view line, const Reply& reply)>;

    LineServer(EventLoop& loop, Handler handler, std::function<void(int clients)> on_clients = {},
               std::function<void(const std::string& why)> on_rejected = {});
    ~LineServer(); // closes everything, removes the pty's symlink
    LineServer(const LineServer&) = delete;
    LineServer& operator=(const LineServer&) = delete;

    // Listens on bind:port (port 0: an ephemeral port; port() tells which). Throws Error.
    void listen_tcp(const std::string& bind, int port);
    // Opens a pseudo-terminal and links `path` to its slave (a symlink there is replaced; any
    // other file is an error). Throws Error.
    void open_pty(const std::string& path);
    int port() const { return port_; }
    const std::string& pty_name() const { return pty_name_; } // the slave, /dev/pts/N
    uint64_t too_long() const { return too_long_; }

private:
    struct Conn {
        int fd = -1;
        bool tcp = true;
        std::string in, out;
        bool dropping = false; // the rest of a line that was too long
    };
    void on_accept();
    void on_io(uint64_t id, uint32_t events);
    void take_lines(uint64_t id);
    void send(uint64_t id, const std::string& line);
    void flush(uint64_t id);
    void close_conn(uint64_t id);
    void clients_changed();

    EventLoop& loop_;
    Handler handler_;
    std::function<void(int)> on_clients_;
    std::function<void(const std::string&)> on_rejected_;
    int listen_fd_ = -1, port_ = 0;
    int pty_slave_ = -1; // kept open: the master stays readable when the client closes
    std::string pty_link_, pty_name_;
    std::map<uint64_t, Conn> conns_;
    uint64_t next_id_ = 1;
    uint64_t too_long_ = 0;
};

} // namespace beamctl::automation
