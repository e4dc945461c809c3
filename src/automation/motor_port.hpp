// A motor record as automation sees it: what compound motors and plans need of a real motor,
// whether the record is in this IOC's database (LocalMotorPort) or served by another IOC
// (through Channel Access: CaMotorPort). Positions are the record's USER units (VAL, RBV,
// HLM, LLM). A move is a put to VAL with a put-callback; it succeeded only if the callback says so
// AND the readback ended within the record's deadband (max(RDBD, |MRES|)) of the target: a motor
// record completes the put-callback of a stopped move normally, and a stop is not a success.
// Threading: the IOC loop (which owns the database and the CA client); callbacks run there.
#pragma once

#include "pv/database.hpp"

#include <functional>
#include <memory>
#include <string>

namespace beamctl::ca {
class Client;
}

namespace beamctl::automation {

class MotorPort {
public:
    struct State {
        bool connected = false;
        double rbv = 0, val = 0;      // readback, setpoint [user units]
        double hlm = 0, llm = 0;      // soft limits (equal: none, as the record treats DHLM = DLLM = 0)
        double deadband = 0;          // max(RDBD, |MRES|)
        bool dmov = true;             // done moving
        bool hls = false, lls = false; // at a limit switch
    };
    // ok, and why not ("T1:TH1 ended at 3.2 (target 3.5)", "refused by its soft limits").
    using Done = std::function<void(bool ok, const std::string& why)>;

    virtual ~MotorPort() = default;
    virtual const std::string& name() const = 0; // the record's name
    virtual State state() const = 0;
    // Puts VAL with a callback; `done` is called once (possibly at once, when the put is refused).
    virtual void move(double target, Done done) = 0;
    virtual void stop() = 0;                      // STOP = 1
};

// A motor record of this IOC. Throws Error if `record` is not a motor record of `db`.
std::unique_ptr<MotorPort> make_local_motor(pv::Database& db, const std::string& record);
// A motor record of another server, through `client` (on the IOC loop). Connects in the background:
// state().connected says when it is there.
std::unique_ptr<MotorPort> make_ca_motor(ca::Client& client, const std::string& record);

// A PV read by automation (an input of a compound motor, a detector of a plan): here or elsewhere.
class PvReader {
public:
    virtual ~PvReader() = default;
    virtual const std::string& name() const = 0;
    virtual bool read(double& v) const = 0; // false: not connected / no value
};
std::unique_ptr<PvReader> make_local_reader(pv::Database& db, const std::string& channel); // nullptr if not here
std::unique_ptr<PvReader> make_ca_reader(ca::Client& client, const std::string& channel);

// A PV written by automation (a state machine's step): here or elsewhere. With `wait`, `done`
// comes when the put-callback completes (processing ended: a motor arrived); without, when the
// put was sent. `done` is called once.
class PvWriter {
public:
    virtual ~PvWriter() = default;
    virtual const std::string& name() const = 0;
    virtual void put(double v, bool wait, MotorPort::Done done) = 0;
};
std::unique_ptr<PvWriter> make_local_writer(pv::Database& db, const std::string& channel); // nullptr if not here
std::unique_ptr<PvWriter> make_ca_writer(ca::Client& client, const std::string& channel);

} // namespace beamctl::automation
