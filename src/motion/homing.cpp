#include "motion/homing.hpp"

#include "motion/axis.hpp"

#include <algorithm>
#include <cmath>

namespace beamctl::motion {

void Homing::start(int seq) noexcept {
    seq_ = seq;
    step_ = 0;
    latch_count_ = 0;
    edge_ = edge2_ = 0;
    reference_ = a_.p_.homing_position;
    // 1, 3, 5, 7, 9, 11, 21: the first direction is backward (towards the low limit)
    bwd_ = seq == 1 || seq == 3 || seq == 5 || seq == 7 || seq == 9 || seq == 11 || seq == 21;
    v_to_ = a_.p_.homing_velocity_to > 0 ? a_.p_.homing_velocity_to : a_.p_.trajectory.velocity / 10;
    v_from_ = a_.p_.homing_velocity_from > 0 ? a_.p_.homing_velocity_from : v_to_ / 2;
    last_latch_valid_ = a_.io_.latch_valid.get() != 0;
    last_ready_ = a_.io_.homing_ready.get() != 0;
    if (a_.p_.auto_mode_home >= 0 && a_.io_.mode_set.bound()) a_.io_.mode_set.set(a_.p_.auto_mode_home);
}

void Homing::abort() noexcept {
    if (a_.io_.latch_arm.bound()) a_.io_.latch_arm.set(0);
    if (a_.io_.homing_trigg.bound()) a_.io_.homing_trigg.set(0);
    if (a_.p_.auto_mode_motion >= 0 && a_.io_.mode_set.bound()) a_.io_.mode_set.set(a_.p_.auto_mode_motion);
}

void Homing::go(double v) noexcept {
    TrajectoryLimits l = a_.p_.trajectory;
    if (a_.p_.homing_acceleration > 0) l.acceleration = l.deceleration = a_.p_.homing_acceleration;
    l.velocity = std::fabs(v);
    (void)a_.traj_.move_velocity(v, l);
}

void Homing::halt() noexcept {
    double d = a_.p_.homing_acceleration > 0 ? a_.p_.homing_acceleration : a_.p_.trajectory.deceleration;
    (void)a_.traj_.stop(d, 0);
}

// The cam's second edge: the reference is the middle of both; stop there.
void Homing::centre_reached() noexcept {
    edge2_ = a_.enc_.position();
    edge_ = (edge_ + edge2_) / 2;
    halt();
    step_ = 10;
}

void Homing::fail(uint32_t id) noexcept {
    a_.fault(id, false);
    a_.st_.last_interlock = Interlock::UnexpectedLimit;
    abort();
    step_ = 99;
}

bool Homing::motion_mode_reached() noexcept {
    if (a_.p_.auto_mode_motion < 0) return true;
    if (a_.io_.mode_set.bound()) a_.io_.mode_set.set(a_.p_.auto_mode_motion);
    return !a_.io_.mode_act.bound() || a_.io_.mode_act.get() == a_.p_.auto_mode_motion;
}

void Homing::step() noexcept {
    if (seq_ == 26) external();
    else if ((seq_ >= 1 && seq_ <= 6) || seq_ == 11 || seq_ == 12 || seq_ == 21 || seq_ == 22) limit_family();
    else cam_family();
    finish();
}

// 1-6, 11, 12, 21, 22: to the limit at "to", off it at "from", then the family member's reference.
void Homing::limit_family() noexcept {
    AxisStatus& st = a_.st_;
    const int s = seq_;
    const double dir = bwd_ ? -1 : 1;
    const bool far_limit = bwd_ ? st.limit_fwd : st.limit_bwd; // must never be reached
    const bool near_limit = bwd_ ? st.limit_bwd : st.limit_fwd;
    const bool near_last = bwd_ ? a_.last_lim_bwd_ : a_.last_lim_fwd_;
    const bool home_changed = st.home_sensor != a_.last_home_;
    const bool latch_valid = a_.io_.latch_valid.get() != 0;
    const bool latch_new = latch_valid && !last_latch_valid_;
    last_latch_valid_ = latch_valid;
    const bool index = s == 11 || s == 12, cam_centre = s == 5 || s == 6, abs_bits = s == 21 || s == 22;
    if (abs_bits && step_ == 0) { // ECMC: the absolute bits and the overflow count must make sense
        const EncoderParams& e = a_.enc_.params();
        if (e.abs_bits < 4 || e.abs_bits > e.bits) return fail(error_id::kAbsBitsOutOfRange);
        if (a_.p_.homing_latch_count < 1) return fail(error_id::kLatchCount);
    }
    switch (step_) {
    case 0: // towards the limit (or already on it)
        if (index) a_.io_.latch_arm.set(0);
        if (near_limit) {
            step_ = 2;
        } else {
            go(dir * v_to_);
            step_ = 1;
        }
        break;
    case 1:
        if (far_limit) return fail(error_id::kSeqFailed);
        if (near_limit) { // the hard-limit interlock ramps the move down
            halt();
            step_ = 2;
        }
        break;
    case 2:
        if (far_limit) return fail(error_id::kSeqFailed);
        if (!a_.traj_.busy()) {
            go(-dir * v_from_);
            step_ = 3;
        }
        break;
    case 3: // off the limit: the family member's first edge
        if (far_limit) return fail(s <= 2 || index || abs_bits ? error_id::kSeqFailed : error_id::kNoHomeFlank);
        if (index) {
            if (near_limit != near_last) { // left the switch: arm the latch
                a_.io_.latch_arm.set(1);
                latch_count_ = 0;
                step_ = 4;
            }
        } else if (s <= 2 || abs_bits ? near_limit != near_last : home_changed) {
            edge_ = a_.enc_.position();
            if (cam_centre) {
                step_ = 6; // on through the cam
            } else {
                halt();
                step_ = abs_bits ? 8 : 10;
            }
        }
        break;
    case 4: // index: count latched marks up to latchCount
        if (far_limit) return fail(error_id::kNoHomeFlank);
        if (latch_new) {
            a_.io_.latch_arm.set(0); // disarm; re-armed once the terminal saw it
            if (++latch_count_ >= a_.p_.homing_latch_count) {
                edge_ = a_.enc_.position_at_raw(uint64_t(a_.io_.latch_position.get_raw()));
                halt();
                step_ = 10;
            } else {
                step_ = 5;
            }
        }
        break;
    case 5:
        if (far_limit) return fail(error_id::kNoHomeFlank);
        if (!latch_valid) {
            a_.io_.latch_arm.set(1);
            step_ = 4;
        }
        break;
    case 6: // 5/6: the cam's second edge, then back
        if (far_limit) return fail(error_id::kNoSecondHomeFlank);
        if (home_changed) {
            halt();
            step_ = 7;
        }
        break;
    case 7:
        if (near_limit) return fail(error_id::kSeqFailed);
        if (!a_.traj_.busy()) {
            go(dir * v_from_);
            step_ = 9;
        }
        break;
    case 8: // 21/22: standing where the switch was left: the reference from the absolute bits
        if (!a_.traj_.busy()) {
            const EncoderParams& e = a_.enc_.params();
            double scale = e.numerator / e.denominator;
            double range = std::ldexp(std::fabs(scale), e.abs_bits);
            uint64_t mask = e.abs_bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << e.abs_bits) - 1;
            double raw_abs = std::fabs(double(a_.enc_.last_raw() & mask) * scale);
            double n = a_.p_.homing_latch_count - 1;
            edge_ = a_.enc_.position();
            if (s == 21) { // the distance forward to the next overflow of the absolute bits
                double dist = scale < 0 ? raw_abs : range - raw_abs;
                reference_ = a_.p_.homing_position - n * range - dist;
            } else { // backward to the previous one
                double dist = scale < 0 ? range - raw_abs : raw_abs;
                reference_ = a_.p_.homing_position + n * range + dist;
            }
            step_ = 10;
        }
        break;
    case 9: // 5/6: back into the cam: its centre is the middle of both edges
        if (near_limit) return fail(error_id::kNoSecondHomeFlank);
        if (home_changed) centre_reached();
        break;
    default: break;
    }
}

// 7-10: on the home cam at "from".
void Homing::cam_family() noexcept {
    AxisStatus& st = a_.st_;
    const double dir = bwd_ ? -1 : 1;
    const bool far_limit = bwd_ ? st.limit_fwd : st.limit_bwd;
    const bool near_limit = bwd_ ? st.limit_bwd : st.limit_fwd;
    const bool home_rising = st.home_sensor && !a_.last_home_;
    const bool centre = seq_ == 9 || seq_ == 10;
    switch (step_) {
    case 0:
        if (near_limit) return fail(error_id::kSeqFailed);
        go(dir * v_from_);
        step_ = 1;
        break;
    case 1:
        if (near_limit) return fail(centre ? error_id::kNoHomeFlank : error_id::kSeqFailed);
        if (home_rising) {
            edge_ = a_.enc_.position();
            if (centre) {
                step_ = 2;
            } else {
                halt();
                step_ = 10;
            }
        }
        break;
    case 2:
        if (near_limit) return fail(error_id::kNoSecondHomeFlank);
        if (!st.home_sensor) { // through the cam
            halt();
            step_ = 3;
        }
        break;
    case 3:
        if (!a_.traj_.busy()) {
            go(-dir * v_from_);
            step_ = 4;
        }
        break;
    case 4:
        if (far_limit) return fail(error_id::kNoSecondHomeFlank);
        if (home_rising) centre_reached();
        break;
    default: break;
    }
}

// 26: the drive homes itself.
void Homing::external() noexcept {
    const bool ready = a_.io_.homing_ready.get() != 0;
    switch (step_) {
    case 0: // the drive in its homing mode first (autoMode)
        if (!a_.io_.homing_trigg.bound() || !a_.io_.homing_ready.bound()) return fail(error_id::kHomeSeqNotSupported);
        if (a_.p_.auto_mode_home >= 0 && a_.io_.mode_act.bound() && a_.io_.mode_act.get() != a_.p_.auto_mode_home) break;
        a_.io_.homing_trigg.set(1);
        step_ = 1;
        break;
    case 1: // the drive moves: the setpoint follows the actual position (no following error)
        a_.traj_.reset({a_.enc_.position(), 0, 0});
        if (ready && !last_ready_) {
            a_.io_.homing_trigg.set(0);
            edge_ = a_.enc_.position();
            step_ = 10;
        }
        break;
    default: break;
    }
    last_ready_ = ready;
}

void Homing::finish() noexcept {
    AxisStatus& st = a_.st_;
    if (step_ == 10 && !a_.traj_.busy()) { // standing still past the edge: re-reference
        double delta = reference_ - edge_;
        a_.enc_.set_position(a_.enc_.position() + delta);
        a_.traj_.reset({a_.traj_.state().position + delta, 0, 0});
        a_.ctrl_.reset();
        st.set_pos = a_.traj_.state().position;
        st.act_pos = a_.enc_.position(); // this cycle's status already shows the new reference
        st.homed = true;
        a_.enc_.set_homed(true);
        st.target_pos = a_.traj_.state().position;
        a_.rereference_others();
        step_ = 11;
    }
    if (step_ == 11) { // the drive back in its motion mode (autoMode), then the post move
        if (!motion_mode_reached()) return;
        if (a_.p_.homing_post_move_enable) {
            TrajectoryLimits pl = a_.p_.trajectory;
            pl.velocity = v_to_;
            (void)a_.traj_.move_to(a_.p_.homing_post_move_position, pl);
            st.target_pos = a_.p_.homing_post_move_position;
            step_ = 12;
        } else {
            step_ = 13;
        }
    } else if (step_ == 12 && !a_.traj_.busy()) {
        step_ = 13;
    }
    st.sequence_state = std::min(step_, 7);
    if (step_ == 13) {
        a_.seq_ = Axis::Seq::Idle;
        st.sequence_state = 0;
        a_.finish(a_.tag_);
    }
}

} // namespace beamctl::motion
