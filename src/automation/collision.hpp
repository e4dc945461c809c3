// Collision zones (seed 003: "the air bearings the delay arms glide on can run off the granite
// table at certain stage position combinations"; the Aerotech tasks keep the axes in safe zones):
// forbidden regions of the joint positions of several motor records of this IOC, an expression in
// the PLC's language that is true inside the region.
//   - A move that would enter one is refused before anything moves: a client's put to VAL, RLV,
//     TWF or TWR of one of the zone's motors is checked along the straight path in joint space from
//     where the motors are to where they are going (the others at their targets when moving); a
//     put that crosses the region is refused (PUTFAIL), counted, logged, and the motor never starts.
//   - A moving motor about to enter is stopped: every 10 ms the positions extrapolated by
//     `lookahead_s` at the measured velocities are checked; if they are inside, every moving motor
//     of the zone is stopped (jogs, homing, moves the put check cannot see: another IOC's client
//     writing DVAL).
// PVs $(P)<name>: Refused, Stopped (longin), Inside (bi: the positions now are in the region,
// MAJOR), Message (the last refusal or stop).
// The check runs in the IOC loop at 100 Hz on the motor records' readbacks; with the lookahead it
// covers axes up to lookahead / 10 ms times faster than one poll's travel.
// Threading: the IOC loop (which owns the database).
#pragma once

#include "config/ioc_config.hpp"
#include "pv/database.hpp"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::automation {

class CollisionZones {
public:
    // Compiles the expressions and loads the zones' records (before init_records). Throws Error
    // naming the entry.
    CollisionZones(const std::vector<config::CollisionZoneEntry>& cfg, const std::string& prefix, pv::Database& db,
                   std::function<double()> clock);
    ~CollisionZones();
    CollisionZones(const CollisionZones&) = delete;
    CollisionZones& operator=(const CollisionZones&) = delete;
    // After init_records: hooks the motors' puts. Throws Error naming the entry when an axis is not
    // a motor record of this IOC.
    void start();
    void poll();

    uint64_t refused() const;
    uint64_t stopped() const;
    struct Zone; // internal
private:
    std::vector<std::unique_ptr<Zone>> zones_;
    pv::Database& db_;
    std::function<double()> clock_;
};

} // namespace beamctl::automation
