// Shared memory between the bus scanner and its clients, and the system calls around it:
//   - SharedMemory: a memfd the scanner creates, sizes and seals (no shrinking or growing, and,
//     for the memory only the scanner writes, no new writable mapping), mapped in both processes.
//     A client cannot make the scanner fault (SIGBUS) by truncating it, nor write the scanner's
//     cycle ring;
//   - send_fds / recv_fds: a message's bytes with file descriptors (SCM_RIGHTS) on a UNIX socket;
//   - futex_wait_until / futex_wake: the per-cycle wake-up between processes (a process-shared
//     futex on a word of the ring).
// Threading: none of its own. futex_* are RT-safe (one system call, no allocation).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::scanner {

class SharedMemory {
public:
    SharedMemory() = default;
    ~SharedMemory();
    SharedMemory(SharedMemory&& o) noexcept;
    SharedMemory& operator=(SharedMemory&& o) noexcept;
    SharedMemory(const SharedMemory&) = delete;
    SharedMemory& operator=(const SharedMemory&) = delete;

    // A new memfd of `bytes` (zeroed), mapped read-write here, sealed against resizing and further
    // sealing; `client_writes` false also seals it against any new writable mapping (the client
    // can only read it). Throws Error naming `what` and the system call that failed.
    static SharedMemory create(const std::string& what, std::size_t bytes, bool client_writes);
    // Maps a memfd received from the scanner: checks its size (at least `min_bytes`) and that it
    // is sealed against shrinking; `writable` selects the mapping. Takes ownership of fd (closed
    // on error too). Throws Error naming `what`.
    static SharedMemory map(int fd, const std::string& what, std::size_t min_bytes, bool writable);

    void* data() const { return p_; }
    std::size_t size() const { return n_; }
    int fd() const { return fd_; }
    explicit operator bool() const { return p_ != nullptr; }
    void reset();

private:
    int fd_ = -1;
    void* p_ = nullptr;
    std::size_t n_ = 0;
};

// Sends `n` bytes (all of them; blocking socket) with `fds` attached to the first byte.
// Throws Error on failure.
void send_fds(int sock, const uint8_t* data, std::size_t n, const std::vector<int>& fds);
// One recvmsg: up to `cap` bytes into `buf`, file descriptors that came with them appended to
// `fds` (close-on-exec). Returns the bytes read, 0 at end of stream, -1 with errno.
long recv_fds(int sock, uint8_t* buf, std::size_t cap, std::vector<int>& fds) noexcept;

// Waits while *word == expected, at most until `deadline_ns` (CLOCK_MONOTONIC). False at the
// deadline; true when woken (or the word had already changed: check your condition again).
bool futex_wait_until(const uint32_t* word, uint32_t expected, uint64_t deadline_ns) noexcept;
// Wakes every process waiting on `word`. Returns how many were woken.
int futex_wake(const uint32_t* word) noexcept;

} // namespace beamctl::scanner
