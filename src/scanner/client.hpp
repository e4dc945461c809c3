// An IOC's bus run by a bus scanner: the BusBackend behind ethercat::Bus for `link: {type:
// scanner}` (docs/scanner.md). The IOC above it works as on a bus of its own.
//
// At bring-up (after add_stages: the engine's period must be the scanner's cycle, else it is
// refused naming both rates) it connects to the scanner's socket (waiting for it up to a time-out), says Hello,
// reads the chain, attaches its slaves with its claims, and maps the two memories that come with
// Attached: its cycle ring (read-only) and its output block. The image has the scanner master's
// layout, so signals bind to the same offsets; the IOC's own word ec<b>.masterstatus follows it.
// RT thread, per cycle: the engine waits on the ring's tick (this is its TickSource); receive takes
// the next cycle of the ring into the image, all but the outputs this client claimed (those are
// its own); send commits the image's outputs to the output block (the scanner keeps only the
// claimed bits). No tick within the time-out: a cycle without bus data (invalid, as on a lost frame).
// Health thread: notices the scanner gone (EOF, Goodbye): the session is withdrawn from the RT
// side, every slave reads invalid, axes stop as on bus loss; then it reconnects every second and
// carries on when the scanner is back with the same layout (a different layout is refused, loudly).
// It also fetches each slave's AL state and health once a second.
#pragma once

#include "ethercat/bus.hpp"
#include "scanner/protocol.hpp"

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace beamctl::scanner {

// A blocking request/response connection to a scanner (clients, `beamctl scanner status`).
class Channel {
public:
    Channel() = default;
    ~Channel();
    // Connects to `socket`; throws Error naming it.
    void connect(const std::string& socket);
    bool connected() const { return fd_ >= 0; }
    void close();
    // Sends `req` and returns its reply (the next message with its request id; a Goodbye in
    // between throws), with the file descriptors that came with it. Throws Error on EOF, a
    // protocol error or after `timeout_s`.
    proto::Message call(proto::Body req, double timeout_s, std::vector<int>* fds = nullptr);
    // Without waiting: true if the scanner closed the connection or said Goodbye (its reason).
    bool closed_by_peer(std::string& reason);
    int fd() const { return fd_; }

private:
    bool read_message(proto::Message& m, double timeout_s, std::vector<int>* fds);
    int fd_ = -1;
    proto::Decoder dec_;
    uint32_t next_id_ = 1;
    std::string socket_;
};

struct ClientConfig {
    std::string socket;
    int bus = 0;
    std::string ioc;                   // the IOC's name, as the scanner shows it
    std::vector<std::string> slaves;   // names or positions
    std::vector<proto::Claim> claims;  // the outputs it writes ({slave, "*"}: all of a slave's)
    uint16_t depth = 0;                // 0: the scanner's default
    double tick_timeout_s = 0.1;
    double connect_timeout_s = 30;
};

class ClientBackend : public ethercat::BusBackend, public rt::TickSource {
public:
    explicit ClientBackend(ClientConfig cfg);
    ~ClientBackend() override;

    // Describe only: the chain slaves named by `slaves` (names or positions), for an IOC file that
    // lists only link.slaves. Throws Error naming the socket or the slave.
    static std::vector<proto::ChainSlave> resolve(const std::string& socket, int bus, const std::vector<std::string>& slaves,
                                                  double timeout_s);

    const char* kind() const noexcept override { return "scanner"; }
    void bring_up() override;
    void set_cycle_time_ns(uint64_t ns) override { period_ns_ = ns; }
    void set_strict(bool) override {}
    void to_safe_op() override {} // the scanner owns the slaves' states
    const std::vector<ethercat::SlaveInfo>& slaves() const override { return slaves_; }
    const std::vector<ethercat::SignalInfo>& signals() const override { return signals_; }
    const ethercat::SignalInfo* find_signal(std::string_view name) const override;
    uint8_t* image() noexcept override { return image_.data(); }
    std::size_t image_size() const override { return image_.size(); }
    std::size_t bus_bytes() const override { return bus_bytes_; }
    ethercat::CycleStatus receive(const rt::CycleInfo& c) noexcept override;
    void send(const rt::CycleInfo& c) noexcept override;
    void fill(ethercat::BusSnapshot& s, ethercat::CycleStatus last) noexcept override;
    void start_cycling() override {}
    void health_pass() override;
    bool health_due() const override { return false; }
    ethercat::SlaveHealth slave_health(std::size_t i) const override;
    std::string slave_last_error(std::size_t i) const override;
    uint64_t health_version() const override { return health_version_.load(); }
    std::vector<uint8_t> sdo_read(int position, uint16_t index, uint8_t sub) override;
    void sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) override;
    rt::TickSource* tick_source() noexcept override { return this; }
    uint64_t tick_grace_ns() const noexcept override { return uint64_t(cfg_.tick_timeout_s * 1e9); }
    bool wait(uint64_t deadline_ns, uint64_t& tick_ns) noexcept override;

    // Counters (any thread).
    bool attached() const { return session_.load() != nullptr; }
    uint64_t drops() const { return drops_.load(std::memory_order_relaxed); }   // cycles this session's ring lost
    uint64_t gaps() const { return gaps_.load(std::memory_order_relaxed); }     // bus cycles never seen (drops and outages)
    uint64_t attaches() const { return attaches_.load(); }
    uint64_t last_cycle() const { return last_cycle_.load(std::memory_order_relaxed); }

private:
    struct Session;
    void attach_once(); // throws Error
    void detach_session(const std::string& why);

    ClientConfig cfg_;
    uint64_t period_ns_ = 1'000'000;
    std::mutex ctl_mu_; // the channel: the health thread and SDO callers
    Channel ch_;
    uint64_t layout_hash_ = 0;
    int bus_ = 0;
    std::vector<ethercat::SlaveInfo> slaves_;
    std::vector<ethercat::SignalInfo> signals_;
    std::vector<int> chain_index_; // per slave: its index in the scanner's chain
    std::size_t chain_size_ = 0;
    std::vector<uint8_t> image_;    // the scanner's image, then ec<b>.masterstatus
    std::size_t scanner_image_ = 0, bus_bytes_ = 0, outputs_bytes_ = 0, masterstatus_offset_ = 0;
    std::vector<uint8_t> recv_;     // one slot's data
    std::unique_ptr<struct KeepMerge> keep_; // what of a slot goes into the image (all but the claimed outputs)

    std::atomic<Session*> session_{nullptr};
    std::unique_ptr<Session> owned_;        // the session the RT side may be using
    std::atomic<uint64_t> rt_epoch_{0};     // +1 every RT cycle end: a retired session is unused after it moved
    // RT state of the last cycle
    bool have_cycle_ = false;
    uint32_t flags_ = 0;
    uint64_t prev_cycle_ = 0;
    std::atomic<uint64_t> drops_{0}, gaps_{0}, attaches_{0}, last_cycle_{0};
    std::vector<uint8_t> slave_status_; // per slave: al, online, valid
    const Session* rt_session_ = nullptr; // the session the last RT cycle used
    uint64_t drops_total_ = 0;            // drops of earlier sessions (RT)
    // Health (non-RT)
    mutable std::mutex health_mu_;
    std::vector<ethercat::SlaveHealth> health_;
    std::vector<std::string> last_error_;
    std::atomic<uint64_t> health_version_{0};
    double next_try_s_ = 0, next_health_s_ = 0;
    std::string last_refusal_;
};

} // namespace beamctl::scanner
