// The EPID step (see epid.hpp): devEpidSoft.c's do_pid, term by term.
#include "feedback/epid.hpp"

namespace beamctl::feedback {

double epid_step(const EpidInput& in, EpidTerms& t) noexcept {
    double oval = t.oval;
    double e = 0;
    if (in.mode == EpidMode::Pid) {
        e = in.setpoint - in.cval;
        const double de = e - t.err;
        t.p = in.kp * e;
        const double di = in.kp * in.ki * e * in.dt;
        if (in.fbon) {
            if (!in.fbop) {
                if (in.have_readback) t.i = in.readback; // bumpless: continue from where the output is
            } else if ((t.oval > in.drvl && t.oval < in.drvh) || (t.oval >= in.drvh && di < 0) ||
                       (t.oval <= in.drvl && di > 0)) {
                t.i += di;
                if (t.i < in.drvl) t.i = in.drvl;
                if (t.i > in.drvh) t.i = in.drvh;
            }
        }
        if (in.ki == 0) t.i = 0;
        t.d = in.dt > 0 ? in.kp * in.kd * (de / in.dt) : 0;
        oval = t.p + t.i + t.d;
    } else if (in.fbon) { // Max/Min: D carries the last step's direction
        if (!in.fbop) {
            if (in.have_readback) oval = in.readback;
        } else {
            e = in.cval - t.cval;
            double sign = t.d > 0 ? 1 : -1;
            if ((in.kp > 0 && e < 0) || (in.kp < 0 && e > 0)) sign = -sign;
            t.d = in.kp * sign;
            oval = t.oval + t.d;
        }
    }
    if (oval > in.drvh) oval = in.drvh;
    if (oval < in.drvl) oval = in.drvl;
    t.err = e;
    t.cval = in.cval;
    return oval;
}

} // namespace beamctl::feedback
