// The simulator's configuration (SIM.yaml, also the `plant:` file of an IOC's sim link). Every
// key is documented in docs/simulator.md.
//   slaves:  [{position: 0, type: EK1100}, ...]   (omitted when the IOC file lists the bus)
//   wiring:  [{from: s3.binaryOutput01, to: s1.binaryInput01}, ...]            outputs -> inputs
//   stages:  [{name: x, drive: s11, travel: [-50, 50], limits: {...}, home: {...}, encoders: [...]}]
//   signals: [{to: s5.analogInput01, shape: sine, amplitude: 5, frequency: 1}, {to: ..., stage: x, gain: 0.1}]
//   bridges: [{slave: 4, pair: gap_mono}]  an EL6692 side joined to the other side of that name
//            (on another segment of this process: bridge.hpp)
//   clock: {offset_us: 120, drift_ppm: 25}  the segment's clock: apart and running fast by that
//            much (its DC time base against another segment's; default 0, 0)
// Every drive terminal (EL70x1 stepper, EL72x1 servo) that no stage names moves a default stage
// (no hard stops, no switches), so a bus can be tried before anyone writes a plant.
#pragma once

#include "core/error_list.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/sim/io_point.hpp"
#include "ethercat/sim/plant.hpp"
#include "ethercat/sim/segment.hpp"

#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <sys/socket.h>
#include <vector>

namespace beamctl::ethercat::sim {

// "s3.binaryOutput01" (or "ec0.s3.binaryOutput01") as written in the file, with its place.
struct EntryRef {
    int slave = -1;
    std::string entry;
    std::string where; // file:line:col
};

struct Wire {
    EntryRef from, to;
};

struct BridgeConfig {
    int slave = -1;   // the EL6692 side's position
    std::string pair; // its pair's name, the same on the other side's segment
    std::string where;
};

struct StageConfig {
    StageParams stage;
    MotorParams motor;
    EntryRef drive;                  // slave of the drive terminal (entry unused)
    double feedback_counts_per_rev = 0; // drive's own positionActual01; 0 = terminal default
    struct Encoder {
        EntryRef entry;
        double counts_per_unit = 1000;
        bool absolute = false;
        double zero = 0; // absolute: position that reads 0 [units]
        double index_every = 0, index_offset = 0; // index marks (latch C) [units]; 0 = none
    };
    std::vector<Encoder> encoders;
    struct Switch {
        SwitchModel::Kind kind;
        EntryRef input;
        double at = 0, width = 1;
        bool normally_closed = true;
    };
    std::vector<Switch> switches;
    std::string where;
};

struct SignalConfig {
    EntryRef to;
    SignalModel::Shape shape = SignalModel::Shape::Constant;
    double amplitude = 0, offset = 0, frequency = 1, phase = 0, gain = 1, noise = 0, full_scale = 10;
    std::string stage; // sensor of this stage's position
    int beam = -1;     // diode under the beam: 0 the whole beam, 1..4 a quadrant
    std::string where;
};

// `beam:` (beam.hpp): the spot, the source's motion, the optics' levers and the slit's blades.
struct BeamConfig {
    BeamParams params;
    struct Lever {
        std::string stage;  // a stage, or
        EntryRef output;    // an analog output (slave -1: none)
        double full_scale = 10, x = 0, y = 0;
        std::string where;
    };
    std::vector<Lever> optics;
    std::string top, bottom, left, right; // slit blades (stage names; empty: open)
    std::string where;
};

// Which drive model a device type gets (by Beckhoff family): EL/EP70xx stepper, EL/EP72xx servo.
enum class DriveKind { None, Stepper, Cia402 };
DriveKind drive_kind(const DeviceDesc& d);

struct SimConfig {
    std::vector<std::pair<int, std::string>> slaves; // {position, type}
    std::vector<Wire> wiring;
    std::vector<StageConfig> stages;
    std::vector<SignalConfig> signals;
    std::vector<BridgeConfig> bridges;
    std::optional<BeamConfig> beam;
    // `clock: {offset_us, drift_ppm}`: the segment's own clock (Segment::set_clock), as the
    // crystals of another machine would run it; default the simulated time itself.
    double clock_offset_us = 0, clock_drift_ppm = 0;
    // Loads SIM.yaml with config::YamlReader; throws one MultiError with every error of the file
    // (file:line:col, key path). Unknown keys are errors. With slaves:, the whole plant is also
    // checked against them (entries exist, inputs driven once, ...) once the file itself is
    // correct.
    static SimConfig load(const std::string& path, const Catalog& catalog);
    static SimConfig parse(const std::string& text, const std::string& filename, const Catalog& catalog);
    // The same, recording every error in `errors` and returning what could be read.
    static SimConfig load(const std::string& path, const Catalog& catalog, ErrorList& errors);
    static SimConfig parse(const std::string& text, const std::string& filename, const Catalog& catalog,
                           ErrorList& errors);
    // Adds the slaves (if `slaves` is given) and builds the plant over the segment, installed as
    // its on_frame hook. Errors (file:line:col) when an entry, drive or stage does not fit the
    // segment, all of them in one MultiError. An empty configuration still gives every drive its
    // default stage.
    std::shared_ptr<Plant> build(Segment& seg, const Catalog& catalog) const;
    // The same, recording every error in `errors` (the plant then lacks what did not fit).
    std::shared_ptr<Plant> build(Segment& seg, const Catalog& catalog, ErrorList& errors) const;
};

// Runs a segment behind a UDP socket: every datagram is an EtherCAT frame, processed and sent
// back to its sender (what `beamctl sim --udp PORT` does).
class UdpServer {
public:
    UdpServer(Segment& seg, const std::string& bind_addr, uint16_t port);
    ~UdpServer();
    uint16_t port() const { return port_; }
    // Serves frames until `stop` becomes true (checked every `poll_ms`).
    void run(const volatile bool& stop, int poll_ms = 100);
    // Serves at most one frame; returns false on timeout.
    bool serve_one(int timeout_ms);
    uint64_t frames = 0, malformed = 0;

private:
    void send_due(int64_t now_ns);
    Segment& seg_;
    int fd_ = -1;
    uint16_t port_ = 0;
    struct Held { // an answer held back (Segment::answer_delay_us)
        int64_t due_ns;
        std::vector<uint8_t> frame;
        sockaddr_storage to;
        socklen_t to_len;
    };
    std::deque<Held> held_;
};

} // namespace beamctl::ethercat::sim
