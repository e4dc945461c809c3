// One Channel Access TCP circuit (a client connection), sans I/O: bytes in, bytes out. The
// server feeds received bytes to receive() and sends what pending_output() holds; monitor events
// queue per subscription with latest-value coalescing when the client is slow or sent EVENTS_OFF.
// Threading: everything runs on the IOC loop thread that owns the Database.
#pragma once

#include "ca/access_security.hpp"
#include "ca/protocol.hpp"
#include "pv/database.hpp"

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace beamctl::ca {

struct ServerStats {
    uint64_t circuits_opened = 0, circuits_closed = 0, messages = 0, searches_udp = 0,
             search_hits = 0, protocol_errors = 0, bad_ids = 0, oversized = 0, put_denied = 0,
             events_sent = 0, events_coalesced = 0, udp_malformed = 0;
};

// What every circuit of one server shares.
struct ServerContext {
    pv::Database& db;
    AccessSecurity acf;           // replaced on reload
    uint16_t tcp_port = 0;        // put in TCP search replies
    std::size_t max_payload = 0;  // largest accepted/sent payload (EPICS_CA_MAX_ARRAY_BYTES rule)
    std::size_t event_queue_limit = 4096;      // queued events before coalescing per circuit
    std::size_t event_queue_bytes = 16 << 20;  // queued event bytes before coalescing
    ServerStats stats;
};

class Circuit {
public:
    Circuit(ServerContext& ctx, uint32_t peer_ip, uint16_t peer_port);
    ~Circuit();
    Circuit(const Circuit&) = delete;
    Circuit& operator=(const Circuit&) = delete;

    // Consumes bytes received from the client; replies are appended to the output.
    void receive(const uint8_t* data, std::size_t n);
    // Bytes waiting to be sent, and how many of them were sent.
    std::string_view pending_output() const {
        return std::string_view(out_).substr(out_off_);
    }
    void consume_output(std::size_t n);
    std::size_t output_size() const { return out_.size() - out_off_; }
    // Moves queued monitor events into the output while it holds fewer than `high_water` bytes.
    void fill_events(std::size_t high_water);
    bool has_queued_events() const { return !queue_.empty(); }
    bool events_enabled() const { return !events_off_; }
    // True after a protocol violation: send the pending output, then close.
    bool wants_close() const { return close_; }
    // Re-evaluates access rights of every channel (ACF reloaded) and sends the changes.
    void refresh_rights();
    // Called whenever output was added outside receive() (monitor events, put completions).
    void set_wake(std::function<void()> wake) { wake_ = std::move(wake); }
    // Called after a client wrote some record's ASG field (rights of all circuits may change).
    std::function<void()> on_asg_changed;
    std::size_t channel_count() const { return channels_.size(); }
    // The names of the open channels, in sid order (casr).
    std::vector<std::string> channel_names() const;
    std::size_t subscription_count() const { return monitors_.size(); }
    const std::string& user() const { return user_; }
    const std::string& host() const { return host_; }
    std::string peer() const;

    // Output kept below this many bytes per circuit while filling events (flow control).
    static constexpr std::size_t kDefaultHighWater = 256 * 1024;

private:
    struct Channel;
    struct Monitor;
    struct QueuedEvent {
        Monitor* mon; // nullptr once cancelled
        std::string msg;
    };
    struct Life {
        Circuit* c;
    };

    void dispatch(const Header& h, const uint8_t* payload);
    void on_create_chan(const Header& h, const uint8_t* payload);
    void on_event_add(const Header& h, const uint8_t* payload);
    void on_event_cancel(const Header& h);
    void on_read_notify(const Header& h, bool old_read);
    void on_write(const Header& h, const uint8_t* payload, bool notify);
    void on_search(const Header& h, const uint8_t* payload);
    void on_name(const Header& h, const uint8_t* payload, bool host);
    void send_error(const Header& h, const uint8_t* raw_header, uint32_t cid, uint32_t eca,
                    std::string_view text);
    void protocol_error(const Header& h, const uint8_t* raw_header, uint32_t eca,
                        std::string_view text); // error, then close
    Channel* channel(uint32_t sid, const Header& h, const uint8_t* raw_header);
    unsigned compute_rights(const Channel& ch) const;
    void queue_event(Monitor& m, bool first);
    void encode_event(Monitor& m, std::string& out);
    void remove_channel(Channel* ch, bool server_disconnect);
    void changed();
    uint32_t client_limit_count(uint16_t dtype) const;

    ServerContext& ctx_;
    uint16_t peer_port_;
    std::string peer_ip_str_;
    uint16_t minor_ = 0;
    uint16_t priority_ = 0;
    std::string user_, host_;
    std::string origin_; // "user@host" during a put (Database::put_origin)
    bool events_off_ = false;
    bool close_ = false;

    std::string in_;           // partial message bytes
    std::size_t drain_ = 0;    // payload bytes of an oversized message still to skip
    std::string out_;
    std::size_t out_off_ = 0;

    std::unordered_map<uint32_t, std::unique_ptr<Channel>> channels_; // by sid
    std::unordered_map<uint32_t, std::unique_ptr<Monitor>> monitors_; // by subid
    uint32_t next_sid_ = 1;
    std::deque<QueuedEvent> queue_;
    std::size_t queued_bytes_ = 0;
    std::shared_ptr<Life> life_;
    std::function<void()> wake_;
    const uint8_t* current_raw_ = nullptr; // header bytes of the request being handled
};

} // namespace beamctl::ca
