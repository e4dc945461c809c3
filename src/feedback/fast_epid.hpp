// The EPID controller in the engine's cycle (devEpidFast's loop, in the cycle instead of a
// driver's data callback): each cycle gives it one sample of its input; every `n` samples it
// averages them and takes one step of feedback::epid_step with dt = n cycles, and writes the output
// while feedback is on. n = int(0.5 + DT/cycle), at least 1; DT reports back as n cycles.
// Its interface is an epid record with DTYP "Fast Epid" (epid_record.hpp): each processing of the
// record calls exchange(), which hands the loop the record's parameters (KP KI KD VAL FBON DRVH
// DRVL DT) and returns the state of its last step (CVAL ERR OVAL P I D DT).
// Unlike synApps' devEpidFast (which integrates with dt = one sample interval even when it
// averages), the integral and derivative use the time a step really spans, so KI and KD mean
// the same at every DT.
// A cycle whose input or output is not valid (its bus is down) takes no step and writes nothing;
// the first step after it starts again bumplessly from the output's readback.
// Threading: cycle() on the RT thread (noexcept, no allocation); exchange() on the IOC loop.
#pragma once

#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"
#include "feedback/epid.hpp"
#include "feedback/epid_record.hpp"

#include <atomic>
#include <cstdint>

namespace beamctl::feedback {

class FastEpidLoop {
public:
    using Params = FastEpidDevice::Params;
    using State = FastEpidDevice::State;

    // `cycle_s`: the period of the cycle that calls cycle(); `initial`: the parameters until the
    // first exchange().
    FastEpidLoop(double cycle_s, const Params& initial);

    // IOC loop: the record's parameters (the latest wins); the state after the loop's last step.
    State exchange(const Params& p);

    // RT: one cycle. `valid`: the input and the output can be used this cycle; `sample`: the input
    // [its units]; `readback`: the output's present value. Returns true with `out` when the output
    // must be written this cycle.
    bool cycle(bool valid, double sample, double readback, double& out) noexcept;

    // RT side, for tests and benchmarks.
    const EpidTerms& terms() const noexcept { return terms_; }
    uint64_t steps() const noexcept { return steps_; }
    int samples_per_step() const noexcept { return n_; }

private:
    void apply(const Params& p) noexcept;
    int samples_for(double dt) const noexcept; // n = int(0.5 + dt/cycle), 1 .. 1e6

    double cycle_s_;
    // RT state
    Params prm_;
    int n_ = 1;           // samples per step
    int accumulated_ = 0; // samples in sum_
    double sum_ = 0;
    bool fbop_ = false;   // feedback at the previous step
    bool have_step_ = false;
    EpidTerms terms_;
    uint64_t steps_ = 0;
    bool valid_ = true;
    State pub_; // what the last step (or loss of input) published
    // IOC loop <-> RT
    SpscQueue<Params> params_{16};
    TripleBuffer<State> state_;
    State last_; // IOC loop: the last state read
};

} // namespace beamctl::feedback
