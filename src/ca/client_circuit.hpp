// The client end of one Channel Access TCP circuit, and the parser of UDP search replies, sans
// I/O: bytes from the server go in through receive(), each well-formed message comes out as one
// call of a ClientCircuitHandler, requests are appended to an output buffer. ca::Client owns the
// sockets around it; the fuzzer (tests/fuzz/fuzz_ca_client.cpp) feeds it directly.
// Threading: used by one thread (the client's EventLoop thread).
#pragma once

#include "ca/protocol.hpp"

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ca {

struct ClientStats {
    uint64_t circuits_opened = 0, circuits_closed = 0, messages = 0, protocol_errors = 0,
             search_datagrams = 0, search_replies = 0, udp_malformed = 0, beacons = 0,
             echo_timeouts = 0, reconnects = 0;
};

// What a circuit's messages mean to the client. Called from inside receive(); `payload` points
// into the receive buffer and is valid only during the call.
class ClientCircuitHandler {
public:
    virtual ~ClientCircuitHandler() = default;
    virtual void on_server_version(uint16_t minor) = 0;
    virtual void on_access_rights(uint32_t cid, uint32_t rights) = 0; // bit0 read, bit1 write
    virtual void on_create_chan(uint32_t cid, uint32_t sid, uint16_t native_type, uint32_t count) = 0;
    virtual void on_create_fail(uint32_t cid) = 0;
    virtual void on_server_disconn(uint32_t cid) = 0;
    // READ_NOTIFY reply (status is the ECA code).
    virtual void on_read(uint32_t ioid, uint32_t status, uint16_t dtype, uint32_t count,
                         const uint8_t* payload, std::size_t len) = 0;
    // A monitor update (EVENT_ADD reply with a payload).
    virtual void on_event(uint32_t subid, uint32_t status, uint16_t dtype, uint32_t count,
                          const uint8_t* payload, std::size_t len) = 0;
    virtual void on_event_cancelled(uint32_t subid) = 0;
    virtual void on_write_notify(uint32_t ioid, uint32_t status) = 0;
    // ERROR: `request` is the header of the request that failed (cmd 0xFFFF if not given).
    virtual void on_error(uint32_t cid, uint32_t eca, const Header& request, std::string_view text) = 0;
    virtual void on_echo() = 0;
};

class ClientCircuit {
public:
    ClientCircuit(ClientCircuitHandler& h, ClientStats& stats, std::size_t max_payload = 64u << 20);

    // Consumes bytes from the server. After a protocol violation (counted in
    // stats.protocol_errors, reason in error()) wants_close() is true and the rest is ignored.
    void receive(const uint8_t* data, std::size_t n);
    bool wants_close() const { return close_; }
    const std::string& error() const { return error_; }
    uint16_t server_minor() const { return server_minor_; }

    // Requests (appended to the output).
    void send_hello(uint16_t priority, std::string_view user, std::string_view host);
    void create_chan(uint32_t cid, std::string_view name);
    void clear_chan(uint32_t sid, uint32_t cid);
    void read_notify(uint32_t sid, uint32_t ioid, uint16_t dtype, uint32_t count);
    // `payload` is the big-endian DBR data (padded here).
    void write(uint32_t sid, uint32_t cid, uint16_t dtype, uint32_t count, const void* payload, std::size_t len);
    void write_notify(uint32_t sid, uint32_t ioid, uint16_t dtype, uint32_t count, const void* payload,
                      std::size_t len);
    void event_add(uint32_t sid, uint32_t subid, uint16_t dtype, uint32_t count, uint16_t mask);
    void event_cancel(uint32_t sid, uint32_t subid, uint16_t dtype, uint32_t count);
    void echo();

    std::string_view pending_output() const { return std::string_view(out_).substr(out_off_); }
    void consume_output(std::size_t n);
    std::size_t output_size() const { return out_.size() - out_off_; }

private:
    void dispatch(const Header& h, const uint8_t* payload);
    void fail(std::string why);

    ClientCircuitHandler& h_;
    ClientStats& stats_;
    std::size_t max_payload_;
    uint16_t server_minor_ = 0;
    bool close_ = false;
    std::string error_;
    std::string in_;
    std::string out_;
    std::size_t out_off_ = 0;
};

// One server's answer to a search, from a UDP reply datagram.
struct SearchReply {
    uint32_t search_id;
    uint32_t server_ip;    // host order; the datagram's sender when the reply says 0xFFFFFFFF
    uint16_t server_port;  // TCP port
    uint16_t server_minor; // 0 if the reply carries no payload
};
// A beacon (RSRV_IS_UP) relayed by the repeater or received directly.
struct Beacon {
    uint32_t server_ip; // host order; the sender when the beacon says 0
    uint16_t server_port;
    uint32_t id;
};

// Parses one UDP datagram a client receives (search replies, NOT_FOUND, beacons, repeater
// confirmation). Returns false (counted in stats.udp_malformed) at the first malformed message;
// what parsed before it is kept.
bool parse_client_datagram(const uint8_t* p, std::size_t n, uint32_t sender_ip,
                           std::vector<SearchReply>& replies, std::vector<Beacon>& beacons,
                           ClientStats& stats);

} // namespace beamctl::ca
