// synApps' epid record (std's epidRecord.c, docs/epidRecord.md; specs/records.md §5): a PID
// controller with the fields of its .dbd, processed by its SCAN, with three device supports:
//   "Soft Channel"       (devEpidSoft): CVAL read through INP, OVAL written through OUTL, the
//                        setpoint through STPL when SMSL is closed_loop; dt from the database clock
//   "Async Soft Channel" (devEpidSoftCallback): the same, after writing TVAL through TRIG (a
//                        readback trigger; here it does not wait for a CA link's completion)
//   "Fast Epid"          (devEpidFast): the controller runs in the engine's cycle (an IOC's
//                        `feedback:` loop, INP "@<name>"); each processing pushes KP KI KD VAL
//                        FBON DRVH DRVL DT to it and pulls back CVAL ERR OVAL P I D DT.
// The step itself is feedback::epid_step, shared with the fast loop.
// Threading: the database thread, as every record.
#pragma once

#include "pv/link.hpp"
#include "pv/record.hpp"

namespace beamctl::feedback {

// What "Fast Epid" device support binds INP's "@name" to: the loop in the cycle.
class FastEpidDevice : public pv::LinkDevice {
public:
    struct Params {
        double setpoint = 0, kp = 0, ki = 0, kd = 0, drvh = 0, drvl = 0;
        double dt = 0; // requested time per step [s] (averaging over the samples in it)
        bool fbon = false;
    };
    struct State {
        double cval = 0, err = 0, oval = 0, p = 0, i = 0, d = 0;
        double dt = 0; // actual time per step [s]: a whole number of cycles
        bool ok = true; // false: the loop cannot read its input or write its output (INVALID)
    };
    // Gives the loop the record's parameters; returns the loop's state after its last step.
    virtual State exchange(const Params& p) = 0;
    bool read(double&) override { return false; }
    bool write(double) override { return false; }
};

// Adds the record type "epid" (idempotent: a second call finds it there).
void register_feedback_records(pv::RecordTypes& types);

} // namespace beamctl::feedback
