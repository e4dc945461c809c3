// Plant models: the mechanics and signals behind the simulated terminals.
//   Stage   a linear (or rotary) axis with mass, Coulomb and viscous friction, hard stops at the
//           ends of its travel, limit and home switches, driven by a drive terminal's velocity
//           loop (force-limited: it stalls against a hard stop) and read by encoders;
//   Signal  a generator (sine, square, ramp, constant, noise) or a sensor (stage position, a diode
//           under the beam) on an analog input, in volts;
//   Beam    the photon beam at a monitor (beam.hpp): optics, slit, quadrant diode;
//   Wire    an output copied to an input of the same width (a cable).
// Plant::step runs after every frame on the segment's thread (the RT thread for in-process
// links): it advances the mechanics to the segment's time in sub-steps of at most 100 us and
// never allocates. Units: positions in stage units (mm unless you say otherwise), s, kg, N.
#pragma once

#include "ethercat/sim/beam.hpp"
#include "ethercat/sim/bridge.hpp"
#include "ethercat/sim/io_point.hpp"
#include "ethercat/sim/terminals.hpp"

#include <cstdint>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace beamctl::ethercat::sim {

class Segment;
struct Fault;

struct StageParams {
    std::string name;
    double mass = 1.0;        // moving mass [kg]; the stage unit is read as mm for F = m a
    double friction = 1.0;    // Coulomb (dry) friction [N]; also the breakaway force
    double damping = 0.0;     // viscous friction [N per unit/s]
    double min = -std::numeric_limits<double>::infinity(); // hard stops [units]
    double max = std::numeric_limits<double>::infinity();
    double start = 0;         // position at power-up [units]
};

// A switch on a stage: active beyond a limit (forward: position >= at, backward: position <= at)
// or, for a home switch, within [at - width/2, at + width/2]. A normally closed switch (the
// default for limits, fail-safe) reads 1 while NOT active.
struct SwitchModel {
    enum class Kind : uint8_t { Forward, Backward, Home };
    Kind kind = Kind::Forward;
    IoPoint input;
    double at = 0, width = 1;
    bool normally_closed = true;
    bool active(double position) const noexcept;
    void update(Segment& seg, double position) const noexcept;
};

class Stage {
public:
    Stage(StageParams p, std::unique_ptr<DriveTerminal> drive);
    // Advances the mechanics by dt under the drive's command: the drive's velocity loop (PI,
    // critically damped at 100 Hz) pushes with at most its force limit against friction.
    void integrate(const DriveCommand& c, double dt) noexcept;
    double position() const { return x_; }
    double velocity() const { return v_; }
    bool saturated() const { return saturated_; }
    bool at_hard_stop() const { return x_ <= p_.min || x_ >= p_.max; }
    const StageParams& params() const { return p_; }
    DriveTerminal* drive() { return drive_.get(); }
    // Moves the stage by hand (tests, demo set-up); velocity becomes 0.
    void set_position(double x) noexcept;

    std::vector<EncoderChannel> encoders;
    std::vector<SwitchModel> switches;

private:
    StageParams p_;
    std::unique_ptr<DriveTerminal> drive_;
    double x_, v_ = 0;
    double lag_ = 0; // drive following error: integral of the velocity error [units]
    bool saturated_ = false;
};

struct SignalModel {
    enum class Shape : uint8_t { Constant, Sine, Square, Ramp, Noise, StagePosition, Beam };
    Shape shape = Shape::Constant;
    double amplitude = 0, offset = 0; // [V]
    double frequency = 1, phase = 0;  // [Hz], [deg]
    double gain = 1;                  // sensor: volts per stage unit
    double noise = 0;                 // added Gaussian noise, standard deviation [V]
    const Stage* stage = nullptr;     // sensor: the stage it reads
    const Beam* beam = nullptr;       // diode: the beam it sees (gain: volts per flux unit)
    int diode = 0;                    //   0 the whole beam, 1..4 a quadrant (beam.hpp)
    std::unique_ptr<AnalogInputChannel> channel;
    double volts(double t, std::mt19937_64& rng) const noexcept;
};

struct WireModel {
    IoPoint from, to; // same width; an output that is not valid (slave not in OP) reads 0
    const TimedOutputs* timed = nullptr; // from an EL2252 pin: the pin, not the process data
    int timed_channel = 0;
};

class Plant {
public:
    // Called after every frame: advances to the segment's time and refreshes every input.
    void step(Segment& seg) noexcept;

    Stage* find_stage(const std::string& name);
    // Plant faults (faults.hpp): an encoder glitch, a drive fault at a slave. False if the plant
    // has no encoder / drive there.
    bool apply_fault(const Fault& f) noexcept;
    std::vector<std::unique_ptr<Stage>>& stages() { return stages_; }

    std::vector<std::unique_ptr<Stage>> stages_;
    std::vector<SignalModel> signals;
    std::vector<WireModel> wires;
    std::vector<CycleCounter> cycle_counters;
    std::vector<LatchInput> latches;
    std::vector<std::unique_ptr<TimedOutputs>> timed_outputs; // EL2252s
    std::vector<std::unique_ptr<BridgeSide>> bridges;         // EL6692 sides
    std::unique_ptr<Beam> beam;                               // beam: (nullptr: none)
    uint64_t steps = 0; // frames that advanced time
    double time() const { return t_; } // simulated seconds since the first frame

    static constexpr double kMaxSubstep = 100e-6; // [s]
    static constexpr double kMaxGap = 1.0;        // a longer pause is not simulated [s]

private:
    void entered_op(Segment& seg);
    uint64_t last_ns_ = 0;
    bool started_ = false;
    double t_ = 0; // simulated seconds since the first frame
    std::vector<uint8_t> was_op_; // per drive stage: its slave was in OP last frame
    std::mt19937_64 rng_{7};
};

} // namespace beamctl::ethercat::sim
