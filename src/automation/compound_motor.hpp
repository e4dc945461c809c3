// Compound (pseudo) motors: motors whose position is a function of other motors, served as motor
// records (seed 003's virtual motors E1, E2 and Delay over the split-and-delay towers; ophyd's
// PseudoPositioner, built into the IOC). A group (config::CompoundMotorEntry) drives a set of real
// motors (motor records of this IOC, or of other IOCs through Channel Access) and serves one or
// more virtual motors:
//   forward: each virtual's position from the reals' readbacks and the read-only inputs;
//   inverse: each driven real's target from the virtuals (the one being moved at its target, the
//            others where they are) and the inputs.
// Both are compiled from the PLC's expression language once, at start-up.
//
// A move of a virtual motor (its record's VAL, with or without put-callback) computes every real
// target first and is refused (the record's LVIO, put-callback failure) when a target is not a
// number or is outside that real's soft limits; nothing moves then. Otherwise every driven real
// is moved (put-callback on its VAL); the virtual's move succeeds only if every real's move did
// and the virtual's readback ends within the reals' deadbands (propagated through `forward`) of
// the target. A stop stops every driven real, and the move reports failure (it ended short).
// The virtual's soft limits (HLM/LLM) follow the reals' limits: the range around the current
// position over which every driven real stays within its own limits.
// One move per group at a time: a move asked for while one is under way starts after it.
//
// Threading: the IOC loop (the database's thread), polled every 10 ms.
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

class CompoundMotors {
public:
    // Compiles every group's expressions and loads the virtual motor records into `db` (before
    // init_records). Throws Error naming the configuration entry (file:line:col) that is wrong.
    CompoundMotors(const std::vector<config::CompoundMotorEntry>& cfg, const std::string& prefix, pv::Database& db);
    ~CompoundMotors();
    CompoundMotors(const CompoundMotors&) = delete;
    CompoundMotors& operator=(const CompoundMotors&) = delete;

    // After init_records: finds every real and input in this database (throws Error naming the
    // entry when a real here is not a motor record); those not here are other IOCs' PVs, reached
    // through Channel Access once connect() gives a client (until then: not connected).
    void start();
    bool needs_client() const;
    void connect(ca::Client& client); // the IOC loop's client
    // The IOC loop, every 10 ms: readbacks, moves, limits.
    void poll();

    std::size_t groups() const;
    std::size_t virtual_count() const;
    // Cost figures for the benchmark: one forward evaluation of group g at its current readbacks.
    double evaluate_forward(std::size_t g);

    struct Group; // internal
private:
    pv::Database& db_;
    std::vector<std::unique_ptr<Group>> groups_;
};

} // namespace beamctl::automation
