#include "daq/pcomp.hpp"

#include <cmath>

namespace beamctl::daq {

const char* to_string(PcompState s) noexcept {
    switch (s) {
    case PcompState::WaitEnable: return "WAIT_ENABLE";
    case PcompState::WaitDir: return "WAIT_DIR";
    case PcompState::WaitPreStart: return "WAIT_PRE_START";
    case PcompState::WaitRising: return "WAIT_RISING";
    case PcompState::WaitFalling: return "WAIT_FALLING";
    }
    return "?";
}

const char* to_string(PcompHealth h) noexcept {
    switch (h) {
    case PcompHealth::Ok: return "OK";
    case PcompHealth::JumpError: return "Error: Position jumped by more than STEP";
    case PcompHealth::GuessError: return "Error: Can't guess DIR when RELATIVE and PRE_START=0 and START=0";
    }
    return "?";
}

// PandA's jumped_more_than_step: the input went past the compare point after the next one.
bool Pcomp::jumped(double p) const noexcept {
    double too_far = last_ + pulse_step();
    return (last_ <= next_ && next_ <= too_far && too_far <= p) || (last_ >= next_ && next_ >= too_far && too_far >= p);
}

void Pcomp::edge(bool up, double crossing, double p) noexcept {
    out_ = up;
    (up ? rose_ : fell_) = true;
    double moved = p - prev_posn_;
    edge_fraction_ = have_prev_ && moved != 0 ? std::fmin(1.0, std::fmax(0.0, (crossing - prev_posn_) / moved)) : 1.0;
    edge_position_ = params.relative ? crossing + latched_ : crossing;
}

bool Pcomp::step(bool enable, double inp) noexcept {
    rose_ = fell_ = false;
    const bool enabled_now = enable && !enable_, disabled_now = !enable && enable_;
    enable_ = enable;
    if (disabled_now) {
        if (out_) edge(false, posn(inp), posn(inp));
        active_ = false;
        state_ = PcompState::WaitEnable;
        prev_posn_ = posn(inp);
        return out_;
    }
    if (enabled_now && state_ == PcompState::WaitEnable) {
        active_ = true;
        health_ = PcompHealth::Ok;
        produced_ = 0;
        latched_ = inp;
        have_prev_ = false;
        if (params.dir == PcompDir::Either) {
            state_ = PcompState::WaitDir;
        } else {
            dir_pos_ = params.dir == PcompDir::Positive;
            next_ = dir_pos_ ? params.width : -params.width;
            if (params.relative && params.pre_start == 0 && params.start == 0) { // the first pulse at once
                last_ = 0;
                produced_ = 1;
                edge(true, 0, 0);
                state_ = PcompState::WaitFalling;
                prev_posn_ = 0;
                have_prev_ = true;
                return out_;
            }
            state_ = PcompState::WaitPreStart;
        }
    }
    const double p = posn(inp);
    // Follow transitions within this cycle until OUT moves (at most one edge per cycle).
    for (int settle = 0; settle < 4 && !rose_ && !fell_; ++settle) {
        const PcompState before = state_;
        switch (state_) {
        case PcompState::WaitEnable: break;
        case PcompState::WaitDir:
            if (params.relative) {
                const double thresh = params.start + params.pre_start;
                if (thresh <= 0) {
                    health_ = PcompHealth::GuessError;
                    active_ = false;
                    state_ = PcompState::WaitEnable;
                } else if (std::fabs(p) >= thresh) {
                    if (params.pre_start > 0) {
                        dir_pos_ = p < 0;
                        state_ = PcompState::WaitPreStart;
                    } else {
                        dir_pos_ = p > 0;
                        last_ = dir_pos_ ? params.start : -params.start;
                        next_ = last_ + (dir_pos_ ? params.width : -params.width);
                        ++produced_;
                        edge(true, last_, p);
                        state_ = PcompState::WaitFalling;
                    }
                }
            } else if (params.start != p) {
                dir_pos_ = p < params.start;
                state_ = PcompState::WaitPreStart;
            }
            break;
        case PcompState::WaitPreStart:
            if (dir_pos_ ? p < pulse_start() - params.pre_start : p > pulse_start() + params.pre_start) {
                // PandA approaches the first compare point from one count before it (integer
                // positions); here from just before it, so that a jump error needs INP past the
                // second point (START + STEP), not one count short of it.
                const double before = params.step != 0 ? std::fabs(params.step) * 1e-9 : 1e-12 * std::fmax(1.0, std::fabs(params.start));
                last_ = dir_pos_ ? pulse_start() - before : pulse_start() + before;
                next_ = pulse_start();
                state_ = PcompState::WaitRising;
            }
            break;
        case PcompState::WaitRising:
            if (reached(p)) {
                if (jumped(p)) {
                    active_ = false;
                    health_ = PcompHealth::JumpError;
                    state_ = PcompState::WaitEnable;
                } else {
                    ++produced_;
                    edge(true, next_, p);
                    last_ = next_;
                    next_ = next_ + pulse_width();
                    state_ = PcompState::WaitFalling;
                }
            }
            break;
        case PcompState::WaitFalling:
            if (reached(p)) {
                edge(false, next_, p);
                if (params.pulses != 0 && produced_ == params.pulses) {
                    active_ = false;
                    state_ = PcompState::WaitEnable;
                } else if (jumped(p)) {
                    active_ = false;
                    health_ = PcompHealth::JumpError;
                    state_ = PcompState::WaitEnable;
                } else {
                    double rise = last_ + pulse_step();
                    last_ = next_;
                    next_ = rise;
                    state_ = PcompState::WaitRising;
                }
            }
            break;
        }
        if (state_ == before) break;
    }
    prev_posn_ = p;
    have_prev_ = true;
    return out_;
}

} // namespace beamctl::daq
