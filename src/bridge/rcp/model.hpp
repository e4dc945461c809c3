// The model `beamctl rcp-sim MODEL.yaml` runs in place of a Speedgoat target: a few signals of a
// Simulink-like model stepped in virtual time, announced in beacons, sent as data packets, and
// written by the IOC. Deterministic: the same writes and steps give the same packets.
//
// MODEL.yaml:
//   application: sgDemo            # 1..39 characters of [A-Za-z0-9_:.-]
//   rate_hz: 100                   # model steps (and data packets) per second
//   beacon_period_s: 1
//   ioc: {host: 127.0.0.1, port: 18065, data_port: 18065}   # beacons to port, data to data_port
//   listen: {host: 0.0.0.0, port: 18066}   # where writes arrive (0.0.0.0 is announced as 0:
//                                          # "use the beacon's source address"); port 0: any
//   objects:                       # id 1..255, name, type AI AO BI BO LI LO MOTOR,
//     - {id: 1, name: Sine, type: AI, signal: {shape: sine, amplitude: 1, frequency_hz: 0.5}}
//   # optional per object: data_type (default AI/AO/MOTOR float64, BI/BO bool, LI/LO int32),
//   # count (default 1; > 1 makes a waveform), and one behaviour:
//   #   signal:   {shape: sine|square|ramp|constant, amplitude, frequency_hz, offset, phase}
//   #             (AI, BI: 1 when > 0, LI: rounded; element k of a waveform is shifted by k/count
//   #             of a period; phase in periods)
//   #   plant:    {input: <AO>, time_constant_s, gain, initial, enable: <BO>}   (AI) first order:
//   #             y' = (gain * u - y) / time_constant_s, held while the enable BO is 0
//   #   within:   {value: <object>, target: <object>, tolerance}   (BI) |value - target| <= tol
//   #   counter:  {step, enable: <BO>}   (LI, integer data type) += step per model step, wrapping
//   #   setpoint: {initial, min, max}    (AO BO LO, the default) holds what the IOC writes,
//   #             clamped to [min, max]
//   #   motor:    {position, velocity, max_velocity, acceleration, max_acceleration,
//   #             soft_limits: [lo, hi], hard_limits: [lo, hi], home_position, home_velocity,
//   #             enabled}   (MOTOR)
//
// Motor: commands (protocol.hpp) move absolute, stop, home forward/reverse (search in that
// direction, reverse at a hard limit, stop on the home position, set homed), jog (to the soft
// limit in that direction, if any), enable, disable. Velocity/acceleration <= 0 or NaN take the
// configured defaults, larger ones are clamped to the maxima. A hard limit switch stops the axis
// on the switch. A write equal to the previous one (sequence number included) is a duplicate and
// ignored.
// Every accepted motion command shows done=0 in at least one data packet. Error codes (bit 5
// set): 1 target outside the soft limits, 2 motor disabled, 3 unknown command, 4 bad parameter;
// cleared by the next accepted command. Position error [3] is always 0 (ideal tracking).
//
// Threading: a Model is used by one thread.
#pragma once

#include "bridge/rcp/protocol.hpp"

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace beamctl::bridge::rcp {

struct SignalSpec {
    enum class Shape : uint8_t { Sine, Square, Ramp, Constant };
    Shape shape = Shape::Sine;
    double amplitude = 1, frequency_hz = 1, offset = 0;
    double phase = 0; // [periods]
};
struct PlantSpec {
    std::string input;  // an AO object
    std::string enable; // a BO object, or empty
    double time_constant_s = 1, gain = 1, initial = 0;
};
struct WithinSpec {
    std::string value, target; // scalar non-motor objects
    double tolerance = 0;
};
struct CounterSpec {
    int64_t step = 1;
    std::string enable; // a BO object, or empty
};
struct SetpointSpec {
    double initial = 0;
    double min = -1e300, max = 1e300;
};
struct MotorSpec {
    double position = 0;                              // start [EGU]
    double velocity = 1, max_velocity = 10;           // [EGU/s]
    double acceleration = 10, max_acceleration = 100; // [EGU/s^2]
    bool has_soft_limits = false;
    double soft_low = 0, soft_high = 0; // [EGU]
    bool has_hard_limits = false;
    double hard_low = 0, hard_high = 0;          // switch positions [EGU]
    double home_position = 0, home_velocity = 1; // [EGU], [EGU/s]
    bool enabled = true;
};
using Behaviour =
    std::variant<SignalSpec, PlantSpec, WithinSpec, CounterSpec, SetpointSpec, MotorSpec>;

struct ObjectSpec {
    uint8_t id = 0;
    std::string name;
    ObjectType type = ObjectType::AI;
    DataType data_type = DataType::Float64;
    uint16_t count = 1;
    Behaviour behaviour;
    std::string where; // "file:line:col" of the object
};

struct ModelConfig {
    std::string application;
    double rate_hz = 100;
    double beacon_period_s = 1;
    uint32_t ioc_ip = 0x7F000001;
    uint16_t ioc_port = kDefaultPort;
    uint16_t ioc_data_port = kDefaultPort;
    uint32_t listen_ip = 0;
    uint16_t listen_port = 0;
    std::vector<ObjectSpec> objects;

    // Reads MODEL.yaml; throws Error "file:line:col: what" (every check of the Model included).
    static ModelConfig load(const std::string& file);
    static ModelConfig parse(std::string_view yaml, const std::string& filename);
};

// Motor state, for tests and the data packets.
struct MotorState {
    enum class Mode : uint8_t { Idle, Moving, Stopping, Jogging, Homing, HomeFinal };
    Mode mode = Mode::Idle;
    double position = 0, velocity = 0; // [EGU], [EGU/s]
    double target = 0;                 // [EGU]
    double v_max = 0, accel = 0;       // of the present motion
    int direction = 1;                 // jog/home search direction
    bool enabled = true, homed = false;
    bool high_limit = false, low_limit = false;
    double error_code = 0;
    int busy_steps = 0; // steps still shown not done after a command
    std::array<double, 5> last_command{-1, -1, -1, -1, -1}; // the previous write (duplicates)
    uint32_t status_bits() const;
};

class Model {
public:
    // Checks cross references, counts and sizes; throws Error "<where>: what".
    explicit Model(ModelConfig cfg);

    // Advances the model by dt_s [s] (> 0).
    void step(double dt_s);
    double time_s() const { return t_; }

    // A write entry from the IOC: None when applied, else why not (UnknownObject,
    // TypeMismatch, NameMismatch, CountMismatch, NotWritable).
    Malformed apply_write(const DataEntry& e);
    // The same checks without applying (a packet is applied only if all its entries pass).
    Malformed check_write(const DataEntry& e) const;

    // Beacon packets (17 objects each; continuations after the first). `port_rcp` announced is
    // config().listen_port unless set_listen_port() changed it.
    std::vector<Packet> beacon_packets() const;
    // Data packets with every object's present values (as many packets as needed).
    void data_packets(std::vector<Packet>& out) const;
    void set_listen_port(uint16_t port) { cfg_.listen_port = port; }

    const ModelConfig& config() const { return cfg_; }
    // Present values of an object (MOTOR: the five readback values); empty if no such object.
    std::span<const double> values(std::string_view name) const;
    double value(std::string_view name) const; // first value; NaN if no such object
    const MotorState* motor(std::string_view name) const;

private:
    struct Obj {
        ObjectSpec spec;
        std::vector<double> values; // present values (count; MOTOR 5)
        MotorState motor;
        double plant_state = 0;
        int64_t counter = 0;
        int input = -1, enable = -1, target = -1; // indexes of referenced objects
    };
    int index(std::string_view name) const;
    void step_motor(Obj& o, double dt);
    void motor_command(Obj& o, std::span<const double> v);
    void refresh_motor_values(Obj& o);

    ModelConfig cfg_;
    std::vector<Obj> objs_;
    std::array<int16_t, 256> by_id_{};
    double t_ = 0;
};

} // namespace beamctl::bridge::rcp
