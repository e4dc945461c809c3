// The IOC side of the RCP bridge without sockets: beacons become records, data packets update
// them, client puts and motor commands become data packets handed to a send function, silence
// turns an application's PVs INVALID/COMM, malformed input is counted and logged. Time is what
// the caller passes in (virtual time in tests); RcpBridge (bridge.hpp) feeds it from a UDP socket
// on the IOC's event loop. See README.md in this folder for every rule the spec leaves open.
//
// PVs ($(P) = BridgeConfig::prefix, APP = application name, NAME = object name, '.' -> '_'):
//   per object (pv_pattern, default $(P)APP:NAME):
//     AI ai, AO ao + NAME_RBV ai, BI bi, BO bo + NAME_RBV bi, LI longin, LO longout + NAME_RBV
//     longin; with a learned count > 1 a waveform instead (AI/AO DOUBLE, LI/LO LONG, BI/BO
//     UCHAR; outputs get a waveform NAME_RBV too); MOTOR: motor record + NAME_PosErr (ai) +
//     NAME_ErrCode (longin).
//   per application: $(P)APP:RxCount TxCount BeaconAge (ai), Online (bi), Objects (longin),
//     Malformed-<Reason> (ai) for every reason of protocol.hpp but None, NotWritable and
//     UnknownApplication.
//   bridge-wide: $(P)RxCount TxCount DataBeforeBeacon (ai), Applications (longin),
//     Malformed-<Reason> (ai, all but None and NotWritable), Refused-<Reason> (ai, every Refusal);
//     per application also Refused-ForeignWriteAddress, -TooManyObjects, -TooManyChanges.
// Counters and BeaconAge are published once per second by tick(). A PV whose name would be
// longer than 60 characters is left out (logged); an object whose PV names are taken or too long
// gets no PVs (logged) and its data is accepted and ignored.
//
// Offline (no beacon and no data for timeout_s): every object PV is INVALID/COMM, puts to
// outputs fail (PutStatus::Failed, nothing sent, the value unchanged), motor commands other
// than stop are refused by the motor driver (motor_driver.hpp) and nothing is kept to be sent
// later. Back online: each output (and each idle motor record) takes the machine's first
// readback as its setpoint once, without sending it. Data from an address with no announced
// application (a machine whose beacon has not been seen yet) is counted in before_beacon and
// logged at debug (at warn once it has gone on for timeout_s).
//
// Threading: one thread (the IOC loop, owner of the Database) makes every call. The Database
// must outlive the core; the destructor removes every record the core created.
#pragma once

#include "bridge/rcp/protocol.hpp"
#include "pv/database.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::bridge::rcp {

// An IPv4 UDP endpoint; ip as a number (127.0.0.1 = 0x7F000001).
struct Endpoint {
    uint32_t ip = 0;
    uint16_t port = 0;
    bool operator==(const Endpoint&) const = default;
    std::string str() const; // "127.0.0.1:18065"
};

// An IPv4 network: `address/bits` ("10.0.3.0/24"; a bare address is /32).
struct Ipv4Net {
    uint32_t ip = 0, mask = 0;
    bool contains(uint32_t a) const { return (a & mask) == (ip & mask); }
    std::string str() const;
};
// Parses "10.0.3.0/24" or "10.0.3.7"; false if it is neither.
bool parse_ipv4_net(std::string_view text, Ipv4Net& out);

// Why the bridge refused a well-formed packet (issue 19: who may talk to it, and how much).
enum class Refusal : uint8_t {
    NotAllowed,          // from an address outside `machines`/`allow` (loopback only when neither)
    ForeignWriteAddress, // a beacon whose ip_rcp names another host than its own source
    TooManyApplications, // max_applications reached
    TooManyObjects,      // a beacon announcing more than max_objects objects
    TooManyChanges,      // more than max_model_changes_per_minute beacons changing the model
};
inline constexpr std::size_t kRefusals = std::size_t(Refusal::TooManyChanges) + 1;
const char* to_string(Refusal r); // "NotAllowed", ...

struct BridgeConfig {
    // IPv4 dotted quad the sockets bind to; "" (the default): the local interface on the network
    // of the first machine when `machines` is set, 127.0.0.1 when neither `machines` nor `allow`
    // is, else 0.0.0.0 (RcpBridge chooses and logs it).
    std::string listen_address;
    uint16_t port = kDefaultPort;           // the beacon port (data is accepted on it too)
    std::string prefix;                     // e.g. "DEMO:RCP:"
    double timeout_s = 3;                   // [s] silence before INVALID/COMM
    std::string db_out;                     // generated .db file; empty: none
    // Object PV names: <prefix>, <application> and <name> are replaced.
    std::string pv_pattern = "<prefix><application>:<name>";
    double continuation_window_s = 0.1; // [s] a beacon and its continuations
    double motor_ack_timeout_s = 0.5;   // [s] see motor_driver.hpp
    std::size_t max_applications = 32;  // beacons of further applications are refused
    // Who may talk to the bridge. A machine is an application name and the address (or network)
    // its beacons and data come from; `allow` networks may announce any application. Packets
    // from anywhere else are refused (counted, logged at most once a second per reason); with
    // neither set, only loopback is accepted.
    struct Machine {
        std::string name;    // the application name its beacons carry
        std::string address; // "10.0.3.7" or "10.0.3.0/24"
    };
    std::vector<Machine> machines;
    std::vector<std::string> allow; // networks, "10.0.3.0/24"
    // Bounded resources per application: objects (PVs) one model may announce, and beacons that
    // change its model (new or changed objects) per minute; beyond them a beacon is refused and
    // nothing already served changes.
    std::size_t max_objects = 255;
    std::size_t max_model_changes_per_minute = 30;
    std::size_t max_applications_per_address = 8; // one machine cannot take every application slot
    // Fields of every generated motor record (after the generated DESC/DTYP/OUT).
    std::vector<std::pair<std::string, std::string>> motor_fields = {
        {"MRES", "0.0001"}, {"PREC", "4"}, {"VELO", "1"}, {"ACCL", "0.5"},
        {"JVEL", "1"},      {"HVEL", "1"}, {"RTRY", "0"}, {"TWV", "1"},
    };
    // Told when an object's PVs are made (added) and removed (the object went with a new beacon,
    // or the bridge stops): the IOC declares the object in its signal registry. Optional.
    struct ObjectEvent {
        bool added = true;
        std::string application, name; // as the beacon announced them
        std::string pv;                 // the object's main PV
        ObjectType type = ObjectType::AI;
        DataType data_type = DataType::Float64;
        uint16_t count = 1;             // elements (a waveform PV when > 1)
    };
    std::function<void(const ObjectEvent&)> on_object;
    // Throws Error naming the bad setting.
    void validate() const;
};

class BridgeCore {
public:
    using SendFn = std::function<bool(const Endpoint& to, std::span<const uint8_t> packet)>;
    using Clock = std::function<double()>; // monotonic [s], the time of puts and motor commands

    struct Counters {
        uint64_t rx = 0; // packets accepted (bridge-wide: every datagram handed in)
        uint64_t tx = 0; // packets sent
        std::array<uint64_t, kMalformedReasons> malformed{};
        // Bridge-wide only: well-formed data packets from an address that no application has
        // announced itself from (yet): ignored, not malformed.
        uint64_t before_beacon = 0;
        std::array<uint64_t, kRefusals> refused{}; // well-formed packets refused, per reason
    };
    struct AppInfo {
        std::string name;
        Endpoint beacon_from; // source of the latest beacon
        bool online = true;
        std::size_t objects = 0;
        double last_beacon_s = 0; // [s]
        Counters counters;
    };

    // Creates the bridge-wide diagnostic records. Throws Error on a bad config or a name clash.
    BridgeCore(pv::Database& db, BridgeConfig cfg, SendFn send, Clock clock);
    ~BridgeCore();
    BridgeCore(const BridgeCore&) = delete;
    BridgeCore& operator=(const BridgeCore&) = delete;

    // One received datagram (any size) from `from`, arrived at now_s [s].
    void handle_packet(std::span<const uint8_t> packet, const Endpoint& from, double now_s);
    // Ends beacon windows, detects silence, publishes diagnostics. Call every <= 50 ms.
    void tick(double now_s);

    // Local ports the applications send data to besides config().port (their port_ioc);
    // changes are announced by ports_version().
    const std::vector<uint16_t>& data_ports() const;
    uint64_t ports_version() const;

    const Counters& totals() const;
    std::vector<AppInfo> applications() const;
    // The PV name an object of an application gets.
    std::string pv_name(std::string_view application, std::string_view object_name) const;
    const BridgeConfig& config() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace beamctl::bridge::rcp
