// The fast EPID loop (see fast_epid.hpp).
#include "feedback/fast_epid.hpp"

#include <cmath>

namespace beamctl::feedback {

FastEpidLoop::FastEpidLoop(double cycle_s, const Params& initial) : cycle_s_(cycle_s > 0 ? cycle_s : 1e-3) {
    apply(initial);
    pub_.dt = n_ * cycle_s_;
    state_.init([&](State& s) { s = pub_; });
    last_ = pub_;
}

int FastEpidLoop::samples_for(double dt) const noexcept {
    const double n = std::floor(0.5 + dt / cycle_s_);
    if (!(n >= 1)) return 1; // also NaN
    return n > 1e6 ? 1000000 : int(n);
}

void FastEpidLoop::apply(const Params& p) noexcept {
    prm_ = p;
    const int n = samples_for(p.dt);
    if (n != n_) { // a new averaging length: start a fresh average
        n_ = n;
        accumulated_ = 0;
        sum_ = 0;
    }
}

FastEpidLoop::State FastEpidLoop::exchange(const Params& p) {
    params_.push(p); // full (the cycle stopped): the parameters wait for the next exchange
    if (state_.update()) last_ = state_.read_buffer();
    State s = last_;
    s.dt = samples_for(p.dt) * cycle_s_; // what the loop makes of this DT (devEpidFast: at once)
    return s;
}

bool FastEpidLoop::cycle(bool valid, double sample, double readback, double& out) noexcept {
    for (Params p; params_.pop(p);) apply(p);
    if (!valid || !std::isfinite(sample)) {
        if (valid_) { // publish the loss once; the next good step is a fresh (bumpless) start
            valid_ = false;
            fbop_ = false;
            accumulated_ = 0;
            sum_ = 0;
            pub_.ok = false;
            state_.write_buffer() = pub_;
            state_.publish();
        }
        return false;
    }
    valid_ = true;
    sum_ += sample;
    if (++accumulated_ < n_) return false;
    EpidInput in;
    in.cval = sum_ / accumulated_;
    accumulated_ = 0;
    sum_ = 0;
    in.setpoint = prm_.setpoint;
    in.dt = have_step_ ? n_ * cycle_s_ : 0;
    in.kp = prm_.kp, in.ki = prm_.ki, in.kd = prm_.kd;
    in.drvh = prm_.drvh, in.drvl = prm_.drvl;
    in.fbon = prm_.fbon, in.fbop = fbop_;
    in.have_readback = true, in.readback = readback;
    terms_.oval = epid_step(in, terms_);
    fbop_ = prm_.fbon;
    have_step_ = true;
    ++steps_;
    pub_.cval = in.cval, pub_.err = terms_.err, pub_.oval = terms_.oval;
    pub_.p = terms_.p, pub_.i = terms_.i, pub_.d = terms_.d;
    pub_.dt = n_ * cycle_s_;
    pub_.ok = true;
    state_.write_buffer() = pub_;
    state_.publish();
    if (!prm_.fbon) return false;
    out = terms_.oval;
    return true;
}

} // namespace beamctl::feedback
