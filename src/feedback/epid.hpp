// The EPID controller step of synApps' epid record (specs/records.md §5; std's devEpidSoft.c and
// devEpidFast.c), once, for both the soft record (database links, IOC loop) and the fast loop in
// the engine's cycle. The record computes the output as an absolute value:
//   e = VAL - CVAL;  P = KP*e;  dI = KP*KI*e*dt;  D = KP*KD*(e - e_prev)/dt
//   OVAL = clamp(P + I + D, DRVL, DRVH)
// with the integral's sanity checks (anti-windup): I changes only while feedback is on, and only
// when the previous output was inside (DRVL, DRVH) or dI points back into the range; I is kept
// within [DRVL, DRVH]; KI = 0 makes I = 0. When feedback turns on, I starts at the output's present
// value (bumpless transfer). Max/Min mode (FMOD 1) steps the output by KP in the direction that
// raised (KP > 0) or lowered (KP < 0) the controlled value last time.
// Units: KI in repeats per second, KD in seconds, dt in seconds.
// Threading: plain data and a pure function; noexcept, no allocation (safe on the RT thread).
#pragma once

#include <cstdint>

namespace beamctl::feedback {

enum class EpidMode : uint8_t { Pid = 0, MaxMin = 1 };

// One step's inputs.
struct EpidInput {
    double setpoint = 0, cval = 0; // VAL, CVAL (the new controlled value)
    double dt = 0;                 // seconds since the previous step
    double kp = 0, ki = 0, kd = 0;
    double drvh = 0, drvl = 0;
    bool fbon = false, fbop = false; // feedback now, and at the previous step
    EpidMode mode = EpidMode::Pid;
    // The output's present value (read back at an off -> on transition), if it could be read.
    bool have_readback = false;
    double readback = 0;
};

// The controller's state: the previous step's values going in, this step's coming out.
struct EpidTerms {
    double err = 0;  // ERR
    double p = 0, i = 0, d = 0;
    double oval = 0; // OVAL of the previous step (the anti-windup looks at it)
    double cval = 0; // CVAL of the previous step (Max/Min compares with it)
};

// Advances `t` by one step and returns the new output, within [DRVL, DRVH]. The caller stores it
// in t.oval (the record only when it moved by more than ODEL); MDT is also the caller's.
double epid_step(const EpidInput& in, EpidTerms& t) noexcept;

} // namespace beamctl::feedback
