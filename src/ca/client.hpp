// A Channel Access client: reaches PVs of other servers (IOCs, softIoc, beamctl) by name.
//
//   ca::Client client(loop, ca::ClientConfig::from_env());
//   auto ch = client.channel("OTHER:temp");
//   ch->on_connection([](bool up) { ... });
//   ch->get([](const ca::Result& r) { if (r.ok()) use(r.value.as_double()); });
//   ch->put(1.5, [](const ca::Result& r) { ... });        // put-callback (WRITE_NOTIFY)
//   ch->put(1.5);                                          // plain put (WRITE), no reply
//   auto sub = ch->monitor(pv::kDbeValue | pv::kDbeAlarm, [](const ca::Result& r) { ... });
//
// Searches go over UDP to EPICS_CA_ADDR_LIST (and the broadcast addresses), with back-off; one TCP
// circuit per server carries its channels. A circuit that closes or stops answering echoes takes
// its channels to disconnected; they search again and, once found, their monitors are re-added.
// Beacons of a server that (re)starts restart the searches at once.
//
// Threading: a Client, its channels and monitors are used from the thread that runs `loop`, and
// every callback runs there; from another thread, hand work over with EventLoop::post.
// Handles: dropping the last shared_ptr to a Channel clears it on the server, dropping a Monitor
// cancels it; handles outlive the Client safely (their calls then do nothing).
#pragma once

#include "ca/client_circuit.hpp"
#include "ca/dbr.hpp"
#include "core/event_loop.hpp"
#include "pv/types.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <netinet/in.h>
#include <string>
#include <vector>

namespace beamctl::ca {

struct ClientConfig {
    std::vector<sockaddr_in> addr_list;   // search destinations [EPICS_CA_ADDR_LIST, ip[:port]]
    bool auto_addr_list = true;           // + broadcast addresses [EPICS_CA_AUTO_ADDR_LIST]
    uint16_t server_port = kDefaultServerPort;     // default search port [EPICS_CA_SERVER_PORT]
    uint16_t repeater_port = kDefaultRepeaterPort; // beacons via the repeater [EPICS_CA_REPEATER_PORT]
    double conn_tmo_s = 30.0;             // silence before an echo is sent [EPICS_CA_CONN_TMO]
    double echo_timeout_s = 5.0;          // echo unanswered for this long: circuit dead [s]
    double search_min_s = 0.02;           // first search retry interval [s]
    double search_max_s = 5.0;            // longest retry interval [EPICS_CA_MAX_SEARCH_PERIOD, s]
    std::string user, host;               // CLIENT_NAME / HOST_NAME; empty: the login and hostname
    // Reads the environment; throws Error naming the variable on a malformed value.
    static ClientConfig from_env();
};

// A value as received: elements in host order and the metadata its DBR type carried (TIME:
// status, severity, stamp; CTRL: units, precision, limits, enum strings).
struct Value : DbrValue {
    double as_double(std::size_t i = 0) const;    // 0 if no such element; strings parsed
    std::string as_string(std::size_t i = 0) const; // numbers formatted with %g
    std::vector<double> as_doubles() const;
};

// The outcome of a get, put or monitor update.
struct Result {
    uint32_t eca = kEcaNormal; // ECA code (kEcaNormal, kEcaDisconn, kEcaNoWtAccess, ...)
    std::string message;       // eca_message(eca), or the server's error text
    Value value;               // get and monitor only
    bool ok() const { return eca == kEcaNormal; }
};

using ResultCallback = std::function<void(const Result&)>;

class Client;
struct ClientImpl;

// An active subscription; dropping it cancels it.
class Monitor {
public:
    ~Monitor();
    Monitor(const Monitor&) = delete;
    Monitor& operator=(const Monitor&) = delete;

private:
    friend struct ClientImpl;
    friend class Channel;
    Monitor(std::weak_ptr<ClientImpl> impl, uint32_t subid) : impl_(std::move(impl)), subid_(subid) {}
    std::weak_ptr<ClientImpl> impl_;
    uint32_t subid_;
};

class Channel {
public:
    ~Channel();
    Channel(const Channel&) = delete;
    Channel& operator=(const Channel&) = delete;

    const std::string& name() const { return name_; }
    bool connected() const;
    pv::Prim native_type() const;    // valid while connected
    uint32_t element_count() const;  // valid while connected
    bool read_access() const;
    bool write_access() const;
    std::string server() const;      // "ip:port" while connected, else ""

    // Called with true on each connection and false on each disconnection (and at once with
    // true if already connected).
    void on_connection(std::function<void(bool connected)> fn);

    // READ_NOTIFY as DBR_TIME_<native> (or `dbr`, e.g. DBR_CTRL_DOUBLE = 34); count 0: all.
    // Fails at once with kEcaDisconn while disconnected, and later if the circuit dies.
    void get(ResultCallback cb, int dbr = -1, uint32_t count = 0);
    // Puts: without a callback a WRITE (no reply), with one a WRITE_NOTIFY whose status the
    // callback gets when the server's processing completes. While disconnected the callback gets
    // kEcaDisconn at once (a put without callback returns false).
    bool put(double v, ResultCallback cb = {});
    bool put(const std::string& v, ResultCallback cb = {});
    bool put(const std::vector<double>& v, ResultCallback cb = {});
    // n host-order elements of plain type t (strings char[40] each).
    bool put_raw(pv::Prim t, const void* data, uint32_t n, ResultCallback cb = {});

    // EVENT_ADD as DBR_TIME_<native> (or `dbr`) with mask pv::kDbeValue|kDbeAlarm|...: updates
    // (the first at once) while connected; re-added after every reconnection.
    std::shared_ptr<Monitor> monitor(unsigned mask, ResultCallback cb, int dbr = -1);

private:
    friend struct ClientImpl;
    friend class Client;
    Channel(std::weak_ptr<ClientImpl> impl, uint32_t cid, std::string name)
        : impl_(std::move(impl)), cid_(cid), name_(std::move(name)) {}
    std::weak_ptr<ClientImpl> impl_;
    uint32_t cid_;
    std::string name_;
};

class Client {
public:
    Client(EventLoop& loop, ClientConfig cfg);
    ~Client();
    Client(const Client&) = delete;
    Client& operator=(const Client&) = delete;

    // A channel to `name` (searched at once). priority 0..99 selects the circuit.
    std::shared_ptr<Channel> channel(const std::string& name, uint16_t priority = 0);
    const ClientStats& stats() const;
    std::size_t circuit_count() const;

private:
    std::shared_ptr<ClientImpl> impl_;
};

} // namespace beamctl::ca
