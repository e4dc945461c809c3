// State machines with an error latch (seed 003: the split-and-delay system's primary FSM, "normal
// operation", "online calibration", "parked", "error latch", with sub-states and auxiliary FSMs),
// declared in YAML (config::StateMachineEntry) and served as PVs under $(P)<name>:
//   State     mbbi   the current state (ZRST.. the states in file order)
//   Request   mbbo   a state to go to: starts the transition to it from the current state (or a
//                    parent of it); refused (PUTFAIL) when there is none, one is under way, or the
//                    machine is latched
//   Busy      bi     a transition is under way
//   Transition, Step stringin  its name; the step under way ("2/5 put SND:T1:AIR = 1")
//   Allowed   waveform CHAR  the states a request may name now, comma-separated
//   Error     waveform CHAR  the last error (why the machine latched)
//   Latched   bi     in the error latch
//   Ack       bo     write 1 to acknowledge the latch: the machine goes to `after_ack`; who (the
//                    CA client's user@host) and when are logged and served as AckBy, AckTime
// A transition runs the current state's exit steps, its own steps, the target's entry steps:
// put (with put-callback by default), wait_for an expression, delay. It fails on a step that
// fails, a time-out, or a false guard when requested; a state's invariant (or a parent's) that
// turns false while the machine rests there is a violation. A failure or violation moves the
// machine to its latch state (when it has one; else it stays where it was, with the error).
// Expressions (guards, invariants, wait_for) are the PLC's language over the machine's `names`
// (PVs here or through CA), each machine's state (`<machine>`: its state index) and state
// constants (`<machine>.<state>`), so auxiliary machines are guards like
// `bearing_t1 == bearing_t1.flying`.
// Threading: the IOC loop (which owns the database), polled every 10 ms; times from `clock`.
#pragma once

#include "config/ioc_config.hpp"
#include "pv/database.hpp"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ca {
class Client;
}

namespace beamctl::automation {

class StateMachines {
public:
    // Compiles every expression and loads the records into `db` (before init_records). Throws
    // Error naming the configuration entry (file:line:col) that is wrong.
    StateMachines(const std::vector<config::StateMachineEntry>& cfg, const std::string& prefix, pv::Database& db,
                  std::function<double()> clock);
    ~StateMachines();
    StateMachines(const StateMachines&) = delete;
    StateMachines& operator=(const StateMachines&) = delete;

    // After init_records: the names' PVs here (others: through CA once connect() is called), the
    // records' hooks, the initial states published.
    void start();
    bool needs_client() const;
    void connect(ca::Client& client);
    void poll();

    // Called when a machine latches (notification): machine name, error text.
    using LatchHook = std::function<void(const std::string& machine, const std::string& error)>;
    void on_latch(LatchHook hook);
    // Latches `machine` from outside (a failed alignment plan): as a failed transition does.
    // False when there is no such machine or it has no latch state.
    bool latch(const std::string& machine, const std::string& why);

    // What the PVs say, for tests and the command line: -1 when there is no such machine.
    int state(const std::string& machine) const;
    std::string state_name(const std::string& machine) const;
    bool latched(const std::string& machine) const;
    bool busy(const std::string& machine) const;
    std::string error(const std::string& machine) const;

    struct Machine; // internal
private:
    std::vector<std::unique_ptr<Machine>> machines_;
    std::vector<double> state_values_, constants_, names_; // what expressions read (never resized)
    pv::Database& db_;
    std::function<double()> clock_;
    LatchHook latch_hook_;
    Machine* find(const std::string& name) const;
    void latch(Machine& m, const std::string& why);
    void publish(Machine& m);
    pv::PutStatus request(Machine& m, int to);
    pv::PutStatus acknowledge(Machine& m);
    void run(Machine& m, double now);
};

} // namespace beamctl::automation
