#include "motion/axis.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace beamctl::motion {

const char* error_id::text(uint32_t id) noexcept {
    switch (id) {
    case kNone: return "";
    case kBusNotOk: return "EtherCAT not OK: axis disabled";
    case kNotEnabled: return "Axis not enabled";
    case kBusy: return "Axis busy";
    case kBlockCom: return "Commands blocked (blockcom)";
    case kAutoEnableTimeout: return "Auto enable timeout: axis not enabled in time";
    case kMotionNotAllowed: return "Motion function not allowed (features.allowedFunctions)";
    case kNotAllowedWhenEnabled: return "Not allowed while enabled (source change)";
    case kSlavedAxisInError: return "An axis of its group is in error";
    case kSlavedAxisInterlock: return "An axis of its group is interlocked";
    case kDriveAlarm0: return "Drive alarm 0";
    case kDriveAlarm0 + 1: return "Drive alarm 1";
    case kDriveAlarm0 + 2: return "Drive alarm 2";
    case kDriveTimeout: return "Drive not enabled within the time-out";
    case kDs402Timeout: return "DS402 drive not operation-enabled within the time-out";
    case kDs402Fault: return "DS402 drive in fault state";
    case kMaxVelocity: return "Velocity above the monitoring maximum";
    case kLag: return "Position lag exceeded";
    case kExternalInterlock: return "External hardware interlock";
    case kBothLimits: return "Both limit switches active";
    case kStall: return "Axis stalled: not at target in time";
    case kSeqFailed: return "Homing failed: unexpected limit switch";
    case kSeqCmdData: return "Unknown homing sequence";
    case kLatchCount: return "Homing: no encoder latch or latch count < 1";
    case kNoHomeFlank: return "Homing failed: no home switch edge";
    case kNoSecondHomeFlank: return "Homing failed: no second home switch edge";
    case kVelocityZero: return "Velocity, acceleration or target not valid";
    case kHomeNotAllowed: return "Homing sequence 0 not allowed";
    case kEnableLost: return "Drive enable lost";
    case kHardLimitFwd: return "Hard limit forward";
    case kHardLimitBwd: return "Hard limit backward";
    case kSoftLimitFwd: return "Soft limit forward";
    case kSoftLimitBwd: return "Soft limit backward";
    }
    return "Unknown error";
}

uint32_t AxisStatus::stat_word() const noexcept {
    uint32_t w = 0;
    auto bit = [&](int n, bool on) { w |= on ? 1u << n : 0u; };
    bit(0, enable_cmd);
    bit(1, enabled);
    bit(2, busy && command != CommandType::None);
    bit(3, busy);
    bit(4, at_target);
    bit(5, moving);
    bit(6, !limit_fwd);
    bit(7, !limit_bwd);
    bit(8, home_sensor);
    bit(9, homed);
    bit(10, true); // in real time
    bit(14, soft_fwd_enabled);
    bit(15, soft_bwd_enabled);
    bit(17, ilock_fwd);
    bit(18, ilock_bwd);
    bit(19, soft_limit_fwd);
    bit(20, soft_limit_bwd);
    bit(21, busy);
    w |= uint32_t(sequence_state & 7) << 24;
    w |= uint32_t(uint8_t(last_interlock) & 0x1F) << 27;
    return w;
}

Axis::Axis(const AxisParams& p, const AxisIo& io)
    : p_(p), io_(io), enc_(p.encoder, io.encoder), drive_(p.drive, io.drive_control, io.drive_status, io.drive_setpoint),
      ctrl_(p.controller) {
    if (p_.trajectory.deceleration <= 0) p_.trajectory.deceleration = p_.trajectory.acceleration;
    st_.homed = p_.encoder.absolute && !p_.virtual_axis; // an absolute encoder is referenced
    for (std::size_t k = 0; k < p_.encoders.size() && k < io_.encoders.size() && k < AxisStatus::kMaxEncoders; ++k)
        if (int(k) != p_.primary_encoder) {
            other_index_[others_.size()] = int(k);
            others_.emplace_back(p_.encoders[k], io_.encoders[k]);
        }
    st_.enc_count = int(std::min<std::size_t>(p_.encoders.size(), AxisStatus::kMaxEncoders));
    traj_source_ = p_.trajectory_source;
    enc_source_ = p_.virtual_axis && p_.encoder_source == 0 ? 0 : p_.encoder_source;
    vars_.traj.source = traj_source_;
    vars_.enc.source = enc_source_;
    vars_.mon.lowsoftlim = p_.soft_bwd;
    vars_.mon.highsoftlim = p_.soft_fwd;
    vars_.mon.lowsoftlimenable = p_.soft_bwd_enable;
    vars_.mon.highsoftlimenable = p_.soft_fwd_enable;
    vars_.ctrl.kp = p_.controller.kp;
    vars_.ctrl.ki = p_.controller.ki;
    vars_.ctrl.kd = p_.controller.kd;
    vars_.ctrl.kff = p_.controller.kff;
    vars_.traj.targetvel = p_.trajectory.velocity;
    vars_.traj.targetacc = p_.trajectory.acceleration;
    vars_.traj.targetdec = p_.trajectory.deceleration;
    vars_.id = p_.id;
    vars_.blockcom = p_.block_com;
    vars_.enc.homepos = p_.homing_position;
    seen_ = vars_;
    st_.soft_fwd_enabled = p_.soft_fwd_enable;
    st_.soft_bwd_enabled = p_.soft_bwd_enable;
    traj_.reset({});
}

double Axis::decel() const noexcept { return p_.trajectory.deceleration; }

double Axis::emergency_decel() const noexcept {
    return p_.emergency_deceleration > 0 ? p_.emergency_deceleration : 3 * decel();
}

void Axis::finish(uint64_t tag) noexcept {
    if (tag) st_.done_tag = tag;
}

// Ramps the trajectory down; the command finishes when it stands still.
void Axis::start_stop(double d) noexcept {
    if (seq_ == Seq::Homing) {
        homing_.abort();
        seq_ = Seq::Stopping;
    }
    if (seq_ == Seq::Pvt) { // a profile stopped is one that ended short; ramp down from where it is
        st_.move_failed = true;
        pvt_ = nullptr;
        const TrajectoryState here = traj_.state();
        TrajectoryLimits l = p_.trajectory;
        l.velocity = std::fabs(here.velocity);
        seq_ = Seq::Stopping;
        if (!(l.velocity > 0) || !(l.acceleration > 0) || traj_.move_velocity(here.velocity, l) == TrajectoryResult::InvalidLimits)
            traj_.reset({here.position, 0, 0});
    }
    if (!traj_.busy()) {
        if (seq_ != Seq::Idle) {
            st_.target_pos = traj_.state().position;
            seq_ = Seq::Idle;
            finish(tag_);
        }
        return;
    }
    double jerk = p_.trajectory.jerk > 0 ? std::max(p_.trajectory.jerk, 10 * d) : 0;
    (void)traj_.stop(d, jerk);
    seq_ = Seq::Stopping;
}

// An external (PLC) setpoint is held where it would cross an enabled soft limit or go further
// into an active limit switch (the axis raises the interlock warning and reports ext_limited):
// whatever the PLC computes, a real axis does not follow it past its limits.
double Axis::hold_at_limits(double x) noexcept {
    const double cur = traj_.state().position;
    auto held = [&](double at, uint32_t warning, Interlock why) {
        st_.ext_limited = true;
        st_.warning_id = warning;
        st_.last_interlock = why;
        return at;
    };
    if (!std::isfinite(x)) return held(cur, error_id::kSoftLimitFwd, Interlock::Plc);
    if (x > cur) {
        if (st_.limit_fwd && !p_.virtual_axis) return held(cur, error_id::kHardLimitFwd, Interlock::HardFwd);
        if (p_.soft_fwd_enable && x > p_.soft_fwd) return held(std::max(cur, p_.soft_fwd), error_id::kSoftLimitFwd, Interlock::SoftFwd);
    } else if (x < cur) {
        if (st_.limit_bwd && !p_.virtual_axis) return held(cur, error_id::kHardLimitBwd, Interlock::HardBwd);
        if (p_.soft_bwd_enable && x < p_.soft_bwd) return held(std::min(cur, p_.soft_bwd), error_id::kSoftLimitBwd, Interlock::SoftBwd);
    }
    return x;
}

// A limit or interlock stops the motion in progress: it ends short (move_failed).
void Axis::interlock_stop() noexcept {
    if (seq_ == Seq::Moving || seq_ == Seq::Homing || seq_ == Seq::Pvt) st_.move_failed = true;
    start_stop(decel());
}

// Latches an error (the first one stays until reset), stops with the emergency deceleration and,
// for the drive-level interlocks, disables the drive at once.
void Axis::fault(uint32_t id, bool disable) noexcept {
    if (st_.error_id == 0) st_.error_id = id;
    if (seq_ != Seq::Idle) st_.move_failed = true;
    start_stop(emergency_decel());
    if (disable) {
        enable_req_ = false;
        st_.enable_cmd = false;
    }
}

void Axis::read_inputs() noexcept {
    // polarity 0 (NC): the signal reads 1 while OK; unbound inputs are always OK
    auto engaged = [](const registry::BoundSignal& s, int polarity) {
        if (!s.bound()) return false;
        bool v = s.get() != 0;
        return polarity == 0 ? !v : v;
    };
    st_.limit_fwd = p_.limit_fwd_plc ? vars_.mon.highlim == 0 : engaged(io_.limit_fwd, p_.limit_fwd_polarity);
    st_.limit_bwd = p_.limit_bwd_plc ? vars_.mon.lowlim == 0 : engaged(io_.limit_bwd, p_.limit_bwd_polarity);
    st_.home_sensor = p_.home_plc ? vars_.mon.homesensor != 0
                                  : io_.home.bound() && ((io_.home.get() != 0) != (p_.home_polarity != 0));
}

uint32_t Axis::check_target(double target) const noexcept {
    double pos = st_.set_pos;
    if (target > pos) {
        if (st_.limit_fwd) return error_id::kHardLimitFwd;
        if (p_.soft_fwd_enable && target > p_.soft_fwd) return error_id::kSoftLimitFwd;
    } else if (target < pos) {
        if (st_.limit_bwd) return error_id::kHardLimitBwd;
        if (p_.soft_bwd_enable && target < p_.soft_bwd) return error_id::kSoftLimitBwd;
    }
    return 0;
}

uint32_t Axis::refuse(const AxisCommand& c, uint32_t id) noexcept {
    finish(c.tag);
    if (id && c.tag) st_.refused_tag = c.tag;
    if (id && c.type != CommandType::None && c.type < CommandType::Halt) st_.move_failed = true;
    if (id && error_id::is_warning(id)) st_.warning_id = id;
    else if (id && id != st_.error_id) fault(id, false);
    return id;
}

void Axis::abort_motion(uint32_t id, Interlock why) noexcept {
    if (seq_ == Seq::Idle) return;
    st_.move_failed = true;
    st_.last_interlock = why;
    if (id && !error_id::is_warning(id)) return fault(id, false); // latches, emergency stop
    if (id) st_.warning_id = id;
    start_stop(emergency_decel());
}

uint32_t Axis::start_pvt(const PvtPath* path, double offset) noexcept {
    bool enabled = p_.virtual_axis ? enable_req_ : drive_.enabled();
    if (!path || path->points().size() < 2 || !std::isfinite(offset)) return error_id::kVelocityZero;
    if (st_.error_id) return st_.error_id;
    if (!enabled || !enable_req_) return error_id::kNotEnabled;
    if (seq_ != Seq::Idle || has_pending_) return error_id::kBusy;
    if (traj_source_ != 0) return error_id::kTrajSourceNotInternal;
    if (vars_.blockcom != 0) return error_id::kBlockCom;
    pvt_ = path;
    pvt_t_ = 0;
    pvt_seg_ = 0;
    pvt_offset_ = offset;
    seq_ = Seq::Pvt;
    tag_ = 0;
    st_.command = CommandType::MovePvt;
    st_.target_pos = path->points().back().p + offset;
    st_.move_failed = false;
    st_.warning_id = 0;
    st_.last_interlock = Interlock::None;
    st_.busy = true;
    st_.at_target = false;
    move_time_ = 0;
    stall_wait_ = -1;
    return 0;
}

uint32_t Axis::command(const AxisCommand& c) noexcept {
    // A refused command finishes at once; its reason is the axis warning, or for error ids
    // (ECMC setErrorID) the latched axis error, which also stops a running move.
    auto refuse = [&](uint32_t id) { return this->refuse(c, id); };
    switch (c.type) {
    case CommandType::None: return refuse(0);
    case CommandType::Power:
        if (c.on && !enable_req_ && vars_.blockcom != 0) return refuse(error_id::kBlockCom);
        if (c.on && !enable_req_) { // enabling also resets errors (ECMC enableAutoResetError)
            st_.error_id = 0;
            st_.warning_id = 0;
            drive_.reset();
            lag_cycles_ = overspeed_cycles_ = overspeed_drive_cycles_ = 0;
            stall_wait_ = -1;
        }
        enable_req_ = c.on;
        st_.enable_cmd = c.on;
        if (!c.on && seq_ != Seq::Idle) { // disabling drops the command at once (no ramp)
            if (seq_ == Seq::Pvt) st_.move_failed = true, pvt_ = nullptr;
            seq_ = Seq::Idle;
            finish(tag_);
        }
        return refuse(0);
    case CommandType::Reset:
        st_.error_id = 0;
        st_.warning_id = 0;
        st_.last_interlock = Interlock::None;
        drive_.reset();
        lag_cycles_ = overspeed_cycles_ = overspeed_drive_cycles_ = 0;
        stall_wait_ = -1;
        return refuse(0);
    case CommandType::Halt:
        start_stop(c.deceleration > 0 ? c.deceleration : decel());
        return refuse(0);
    case CommandType::Stop:
        start_stop(emergency_decel());
        return refuse(0);
    case CommandType::SetSoftLimits: // the PLC variables are what the monitor takes every cycle
        if (std::isfinite(c.soft_fwd)) vars_.mon.highsoftlim = c.soft_fwd;
        if (std::isfinite(c.soft_bwd)) vars_.mon.lowsoftlim = c.soft_bwd;
        if (c.soft_fwd_on >= 0) vars_.mon.highsoftlimenable = c.soft_fwd_on;
        if (c.soft_bwd_on >= 0) vars_.mon.lowsoftlimenable = c.soft_bwd_on;
        return refuse(0);
    case CommandType::SetGain: // the PLC variables are what the controller takes every cycle
        if (!std::isfinite(c.position)) return refuse(0);
        (c.gain == 0 ? vars_.ctrl.kp : c.gain == 1 ? vars_.ctrl.ki : vars_.ctrl.kd) = c.position;
        return refuse(0);
    case CommandType::SetPosition:
        if (seq_ != Seq::Idle) return refuse(error_id::kBusy);
        if (!std::isfinite(c.position)) return refuse(error_id::kVelocityZero);
        if (p_.virtual_axis) {
            traj_.reset({c.position, 0, 0});
        } else { // bumpless: the setpoint moves with the actual position
            double delta = c.position - enc_.position();
            enc_.set_position(c.position);
            traj_.reset({traj_.state().position + delta, 0, 0});
            ctrl_.reset();
        }
        st_.set_pos = st_.target_pos = traj_.state().position;
        st_.act_pos = p_.virtual_axis ? st_.set_pos : enc_.position();
        st_.homed = true;
        enc_.set_homed(true);
        return refuse(0);
    default: break;
    }
    // Motion commands. Homing 15/25 (set position) works without enable.
    if (seq_ == Seq::Pvt) { // a profile runs (Halt/Stop end it): refused without touching it
        finish(c.tag);
        if (c.tag) st_.refused_tag = c.tag;
        return error_id::kBusy;
    }
    if (vars_.blockcom != 0) return refuse(error_id::kBlockCom); // ECMC: latched as the axis error
    if (st_.error_id) return refuse(st_.error_id);
    bool allowed = c.type == CommandType::Home           ? p_.allow_homing
                 : c.type == CommandType::MoveVelocity   ? p_.allow_constant_velocity
                                                         : p_.allow_positioning;
    if (!allowed) return refuse(error_id::kMotionNotAllowed); // features.allowedFunctions
    if (c.type == CommandType::Home) {
        int seq = c.homing_sequence < 0 || c.homing_sequence == 14 ? p_.homing_sequence : c.homing_sequence;
        if (seq == 25) seq = 15;
        if (seq == 0) return refuse(error_id::kHomeNotAllowed);
        if (seq_ != Seq::Idle) return refuse(error_id::kBusy);
        if (seq == 15) {
            if (c.set_home_position && std::isfinite(c.position)) p_.homing_position = vars_.enc.homepos = c.position;
            AxisCommand set{CommandType::SetPosition, p_.homing_position};
            (void)command(set);
            return refuse(0);
        }
        if (!Homing::supported(seq)) return refuse(error_id::kSeqCmdData);
        if ((seq == 11 || seq == 12) && (!io_.latch_arm.bound() || !io_.latch_valid.bound() || !io_.latch_position.bound() ||
                                         p_.homing_latch_count < 1))
            return refuse(error_id::kLatchCount);
    }
    // ECMC autoEnable: a motion command enables the axis (homing 15 was handled above).
    if (!enable_req_ && p_.auto_enable_timeout_s > 0 && auto_enable_on_) {
        AxisCommand on{CommandType::Power};
        on.on = true;
        (void)command(on);
        auto_enabling_ = !p_.virtual_axis;
        auto_enable_time_ = 0;
    }
    bool enabled = p_.virtual_axis ? enable_req_ : drive_.enabled();
    if (!enabled && enable_req_ && !p_.virtual_axis) { // still enabling: run it once enabled
        if (has_pending_) finish(pending_.tag);
        pending_ = c;
        has_pending_ = true;
        st_.busy = true;
        st_.at_target = false;
        return 0;
    }
    if (!enabled) return refuse(error_id::kNotEnabled);
    if (traj_source_ == 1) { // the PLC gives the setpoint
        if (!p_.allow_source_change) {
            finish(c.tag);
            if (c.tag) st_.refused_tag = c.tag;
            st_.move_failed = true;
            return error_id::kTrajSourceNotInternal; // returned, not latched (as ECMC)
        }
        traj_source_ = 0; // bumpless: the trajectory holds the PLC's last setpoint and velocity
        vars_.traj.source = 0;
        last_ext_set_ = NAN;
    }
    has_pending_ = false;
    st_.warning_id = 0;
    st_.last_interlock = Interlock::None;
    st_.move_failed = false;
    if (c.type == CommandType::Home) {
        if (c.set_home_position && std::isfinite(c.position)) p_.homing_position = vars_.enc.homepos = c.position;
        int seq = c.homing_sequence < 0 || c.homing_sequence == 14 ? p_.homing_sequence : c.homing_sequence;
        homing_.start(seq);
        tag_ = c.tag;
        seq_ = Seq::Homing;
        st_.homed = false;
        enc_.set_homed(false);
        st_.command = CommandType::Home;
        st_.busy = true;
        st_.at_target = false;
        move_time_ = 0;
        stall_wait_ = -1;
        homing_.step();
        return 0;
    }
    if (p_.auto_mode_motion >= 0 && io_.mode_set.bound()) io_.mode_set.set(p_.auto_mode_motion); // axis.autoMode
    TrajectoryLimits l = p_.trajectory;
    if (c.velocity != 0 && c.type != CommandType::MoveVelocity) l.velocity = std::fabs(c.velocity);
    if (c.acceleration > 0) l.acceleration = c.acceleration;
    if (c.deceleration > 0) l.deceleration = c.deceleration;
    else if (c.acceleration > 0) l.deceleration = c.acceleration;
    if (p_.velocity_enable && p_.velocity_max > 0) l.velocity = std::min(l.velocity, p_.velocity_max);
    if (!(l.velocity > 0) || !(l.acceleration > 0) || !std::isfinite(c.position) || !std::isfinite(c.velocity))
        return refuse(error_id::kVelocityZero);
    double target = 0;
    TrajectoryResult r;
    if (c.type == CommandType::MoveVelocity) {
        double v = c.velocity;
        if (v == 0) return refuse(error_id::kVelocityZero);
        if (v > 0 && st_.limit_fwd) return refuse(error_id::kHardLimitFwd);
        if (v < 0 && st_.limit_bwd) return refuse(error_id::kHardLimitBwd);
        l.velocity = std::fabs(v);
        if (p_.velocity_enable && p_.velocity_max > 0) l.velocity = std::min(l.velocity, p_.velocity_max);
        // Towards an enabled soft limit a velocity move ends at that limit (ECMC brakes only once
        // the setpoint has passed it and overshoots; stopping at the limit is what users expect).
        if (v > 0 && p_.soft_fwd_enable) {
            if (st_.set_pos >= p_.soft_fwd) return refuse(error_id::kSoftLimitFwd);
            r = traj_.move_to(p_.soft_fwd, l);
            target = p_.soft_fwd;
        } else if (v < 0 && p_.soft_bwd_enable) {
            if (st_.set_pos <= p_.soft_bwd) return refuse(error_id::kSoftLimitBwd);
            r = traj_.move_to(p_.soft_bwd, l);
            target = p_.soft_bwd;
        } else {
            r = traj_.move_velocity(v, l);
            target = st_.set_pos;
        }
    } else {
        // relative moves add to the previous target while a relative move runs (as ECMC)
        bool chained = c.type == CommandType::MoveRelative && seq_ == Seq::Moving && st_.command == CommandType::MoveRelative;
        target = c.type == CommandType::MoveAbsolute ? c.position : (chained ? st_.target_pos : st_.set_pos) + c.position;
        if (p_.modulo_range > 0 && c.type == CommandType::MoveAbsolute)
            target = modulo_target(st_.set_pos, c.position, p_.modulo_range, p_.modulo_type);
        if (uint32_t w = check_target(target)) return refuse(w);
        r = traj_.move_to(target, l);
    }
    if (r == TrajectoryResult::InvalidLimits || r == TrajectoryResult::InvalidTarget)
        return refuse(error_id::kVelocityZero);
    if (seq_ != Seq::Idle && tag_ != c.tag) finish(tag_); // the previous command is superseded
    tag_ = c.tag;
    seq_ = traj_.busy() ? Seq::Moving : Seq::Idle;
    st_.target_pos = target;
    st_.command = c.type;
    move_time_ = 0;
    stall_wait_ = -1;
    target_cycles_ = 0;
    if (seq_ == Seq::Idle) finish(tag_); // already there
    st_.busy = seq_ != Seq::Idle;
    st_.at_target = false;
    return 0;
}

void Axis::rereference_others() noexcept {
    for (std::size_t i = 0; i < others_.size(); ++i) {
        if (!others_[i].params().ref_at_home) continue;
        others_[i].set_position(enc_.position()); // ECMC refAtHome: the primary's new position
        others_[i].set_homed(true);
    }
}

double Axis::csp_drive_frame_offset() const noexcept {
    for (std::size_t i = 0; i < others_.size(); ++i)
        if (other_index_[i] == p_.csp_drive_encoder) return others_[i].frame_offset();
    return enc_.frame_offset();
}

bool Axis::encoder_homed(int index) const noexcept {
    if (index == p_.primary_encoder) return st_.homed;
    for (std::size_t i = 0; i < others_.size(); ++i)
        if (other_index_[i] == index) return others_[i].homed();
    return false;
}

bool Axis::set_encoder_homed(int index, bool homed) noexcept {
    if (index == p_.primary_encoder) {
        enc_.set_homed(homed);
        st_.homed = enc_.homed();
        return true;
    }
    for (std::size_t i = 0; i < others_.size(); ++i)
        if (other_index_[i] == index) {
            others_[i].set_homed(homed);
            return true;
        }
    return false;
}

uint32_t Axis::select_primary_encoder(int index) noexcept {
    if (index == p_.primary_encoder) return 0;
    int k = -1;
    for (std::size_t i = 0; i < others_.size(); ++i)
        if (other_index_[i] == index) k = int(i);
    if (k < 0) return error_id::kPrimaryEncoderOutOfRange;
    if (st_.busy) return error_id::kPrimaryEncoderWhileBusy;
    std::swap(enc_, others_[std::size_t(k)]);
    other_index_[std::size_t(k)] = p_.primary_encoder;
    p_.primary_encoder = index;
    p_.encoder = enc_.params();
    for (std::size_t i = 1; i < others_.size(); ++i) // keep others_ in encoder order
        for (std::size_t j = i; j > 0 && other_index_[j - 1] > other_index_[j]; --j) {
            std::swap(others_[j - 1], others_[j]);
            std::swap(other_index_[j - 1], other_index_[j]);
        }
    st_.homed = enc_.homed();
    if (!p_.virtual_axis && enc_source_ == 0) { // the setpoint starts at the new encoder's position
        st_.act_pos = enc_.position();
        traj_.reset({st_.act_pos, 0, 0});
        ctrl_.reset();
        st_.set_pos = st_.target_pos = st_.act_pos;
    }
    return 0;
}

void Axis::set_trajectory_limits(double v, double a, double d, double j) noexcept {
    auto take = [](double x, double& into) {
        if (std::isfinite(x) && x > 0) into = x;
    };
    take(v, p_.trajectory.velocity);
    take(a, p_.trajectory.acceleration);
    take(d, p_.trajectory.deceleration);
    if (p_.trajectory.jerk > 0) take(j, p_.trajectory.jerk); // a trapezoid axis stays one
    vars_.traj.targetvel = p_.trajectory.velocity;
    vars_.traj.targetacc = p_.trajectory.acceleration;
    vars_.traj.targetdec = p_.trajectory.deceleration;
}

uint32_t Axis::set_traj_source(int source) noexcept {
    int w = source != 0 ? 1 : 0;
    if (w == traj_source_) return 0;
    if (st_.enabled && !p_.allow_source_change) return error_id::kNotAllowedWhenEnabled;
    traj_source_ = w;
    vars_.traj.source = w; // what take_variables compares with
    return 0;
}

uint32_t Axis::set_enc_source(int source) noexcept {
    int w = source != 0 ? 1 : 0;
    if (w == enc_source_) return 0;
    if (st_.enabled && !p_.allow_source_change) return error_id::kNotAllowedWhenEnabled;
    enc_source_ = w;
    vars_.enc.source = w;
    return 0;
}

void Axis::take_variables() noexcept {
    AxisVariables& v = vars_;
    AxisVariables& was = seen_;
    if (v.reset != was.reset && v.reset != 0) (void)command(AxisCommand{CommandType::Reset});
    if (v.drv.enable != was.drv.enable) {
        AxisCommand c{CommandType::Power};
        c.on = v.drv.enable != 0;
        (void)command(c);
    }
    // sources: switch only when disabled unless allowed while enabled (ECMC)
    auto source = [&](double want, int& cur) {
        int w = want != 0 ? 1 : 0;
        if (w != cur && (!st_.enabled || p_.allow_source_change)) cur = w;
    };
    source(v.traj.source, traj_source_);
    source(v.enc.source, enc_source_);
    if (v.traj.execute != was.traj.execute && p_.external_commands && v.allowplccmd != 0) {
        AxisCommand c;
        if (v.traj.execute != 0) {
            int code = int(v.traj.command);
            c.type = code == 1 ? CommandType::MoveVelocity : code == 2 ? CommandType::MoveRelative
                   : code == 3 ? CommandType::MoveAbsolute : code == 10 ? CommandType::Home : CommandType::None;
            c.position = v.traj.targetpos;
            c.velocity = v.traj.targetvel;
            c.acceleration = v.traj.targetacc;
            c.homing_sequence = int(v.traj.cmddata);
        } else {
            c.type = CommandType::Halt;
        }
        if (c.type != CommandType::None) (void)command(c);
    }
    // ECMC: a write to enc.actpos stores the external actual position, one to traj.setpos the
    // external setpoint (used while the source is the PLC); writes only when allowplccmd.
    auto written = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) != 0; };
    if (written(v.enc.actpos, was.enc.actpos) && v.allowplccmd != 0) v.enc.extactpos = v.enc.actpos;
    if (written(v.traj.setpos, was.traj.setpos) && v.allowplccmd != 0) v.traj.extsetpos = v.traj.setpos;
    p_.homing_position = v.enc.homepos;
    if (v.traj.targetdec > 0) p_.trajectory.deceleration = v.traj.targetdec;
    plc_ilock_fwd_ = v.mon.ilock == 0 || v.mon.ilockfwd == 0;
    plc_ilock_bwd_ = v.mon.ilock == 0 || v.mon.ilockbwd == 0;
    p_.soft_fwd = v.mon.highsoftlim;
    p_.soft_bwd = v.mon.lowsoftlim;
    p_.soft_fwd_enable = v.mon.highsoftlimenable != 0;
    p_.soft_bwd_enable = v.mon.lowsoftlimenable != 0;
    st_.soft_fwd_enabled = p_.soft_fwd_enable;
    st_.soft_bwd_enabled = p_.soft_bwd_enable;
    st_.soft_fwd = p_.soft_fwd;
    st_.soft_bwd = p_.soft_bwd;
    ControllerParams& k = ctrl_.params();
    k.kp = v.ctrl.kp;
    k.ki = v.ctrl.ki;
    k.kd = v.ctrl.kd;
    k.kff = v.ctrl.kff;
    // remember only what is compared for edges (a whole copy costs more than the axis's work)
    was.reset = v.reset;
    was.drv.enable = v.drv.enable;
    was.traj.execute = v.traj.execute;
}

void Axis::publish_variables() noexcept {
    AxisVariables& v = vars_;
    v.error = st_.error_id;
    v.enc.actpos = st_.act_pos;
    v.enc.actvel = st_.act_vel;
    v.enc.homed = st_.homed;
    v.enc.source = enc_source_;
    v.traj.setpos = st_.set_pos;
    v.traj.source = traj_source_;
    v.traj.busy = st_.busy;
    v.drv.enable = st_.enable_cmd;
    v.drv.enabled = st_.enabled;
    v.mon.attarget = st_.at_target;
    if (!p_.limit_fwd_plc) v.mon.highlim = !st_.limit_fwd;
    if (!p_.limit_bwd_plc) v.mon.lowlim = !st_.limit_bwd;
    if (!p_.home_plc) v.mon.homesensor = st_.home_sensor;
    v.counter = double(st_.cycle);
    v.enc.rawpos = double(enc_.counts());
    v.traj.setvel = st_.set_vel;
    v.traj.setvelffraw = st_.set_vel * ctrl_.params().kff;
    v.traj.dir = !st_.enabled || st_.set_vel == 0 ? 0 : st_.set_vel > 0 ? 1 : -1;
    v.drv.setvelraw = st_.drive_output;
    v.cntrl.poserror = st_.pos_err;
    v.cntrl.output = st_.drive_output - v.traj.setvelffraw;
    v.seq.state = st_.sequence_state;
    seen_.drv.enable = v.drv.enable; // the axis's own change is not a PLC write
    seen_.enc.actpos = v.enc.actpos; // nor are these
    seen_.traj.setpos = v.traj.setpos;
}

void Axis::monitor(double dt) noexcept {
    const bool homing = seq_ == Seq::Homing;
    const double v = traj_.state().velocity;
    // Hard limits block their direction (normal deceleration) with a warning; both is an error
    // that disables the drive.
    if (st_.limit_fwd && st_.limit_bwd && !p_.virtual_axis) {
        st_.last_interlock = Interlock::BothLimits;
        fault(error_id::kBothLimits, true);
    }
    if (st_.limit_fwd && v > 0) {
        st_.warning_id = error_id::kHardLimitFwd;
        if (st_.last_interlock == Interlock::None) st_.last_interlock = Interlock::HardFwd;
        if (!homing) interlock_stop();
    }
    if (st_.limit_bwd && v < 0) {
        st_.warning_id = error_id::kHardLimitBwd;
        if (st_.last_interlock == Interlock::None) st_.last_interlock = Interlock::HardBwd;
        if (!homing) interlock_stop();
    }
    // Soft limits (not while homing): the setpoint beyond an enabled limit stops that direction.
    bool soft_fwd = p_.soft_fwd_enable && !homing && st_.set_pos > p_.soft_fwd;
    bool soft_bwd = p_.soft_bwd_enable && !homing && st_.set_pos < p_.soft_bwd;
    if (soft_fwd && v > 0) {
        st_.warning_id = error_id::kSoftLimitFwd;
        st_.last_interlock = Interlock::SoftFwd;
        interlock_stop();
    }
    if (soft_bwd && v < 0) {
        st_.warning_id = error_id::kSoftLimitBwd;
        st_.last_interlock = Interlock::SoftBwd;
        interlock_stop();
    }
    if (plc_ilock_fwd_ && v > 0) { // PLC interlocks (mon.ilock*) stop that direction
        st_.last_interlock = Interlock::PlcFwd;
        interlock_stop();
    }
    if (plc_ilock_bwd_ && v < 0) {
        st_.last_interlock = Interlock::PlcBwd;
        interlock_stop();
    }
    st_.soft_limit_fwd = p_.soft_fwd_enable && st_.set_pos >= p_.soft_fwd;
    st_.soft_limit_bwd = p_.soft_bwd_enable && st_.set_pos <= p_.soft_bwd;
    st_.ilock_fwd = st_.limit_fwd || st_.soft_limit_fwd || st_.error_id;
    st_.ilock_bwd = st_.limit_bwd || st_.soft_limit_bwd || st_.error_id;
    // External interlock (NC: active when the input reads 0): disables at once.
    if (io_.interlock.bound() && ((io_.interlock.get() != 0) == (p_.interlock_polarity != 0))) {
        st_.last_interlock = Interlock::External;
        if (st_.enabled || enable_req_) fault(error_id::kExternalInterlock, true);
    }
    // Lag: error and emergency stop after more than `time` cycles over tolerance, drive
    // disabled on the 2 x time-th.
    if (p_.lag_enable && st_.enabled && std::fabs(st_.pos_err) > p_.lag_tolerance) {
        lag_cycles_ = std::min(lag_cycles_ + 1, 2 * p_.lag_time_cycles + 1);
        if (lag_cycles_ > p_.lag_time_cycles) {
            st_.last_interlock = Interlock::Lag;
            fault(error_id::kLag, lag_cycles_ >= 2 * p_.lag_time_cycles);
        }
    } else {
        lag_cycles_ = 0;
    }
    // At target: monitoring enabled, idle, setpoint at the target and actual at the setpoint
    // for more than `time` cycles.
    bool in = p_.target_enable && !st_.busy && std::fabs(st_.target_pos - st_.set_pos) < std::max(p_.target_tolerance, 1e-12) &&
              std::fabs(st_.pos_err) < p_.target_tolerance;
    target_cycles_ = in ? std::min(target_cycles_ + 1, p_.target_time_cycles + 1) : 0;
    st_.at_target = in && target_cycles_ > p_.target_time_cycles;
    // Maximum velocity: stop after time.trajectory cycles, disable time.drive cycles later.
    if (p_.velocity_enable && p_.velocity_max > 0 && st_.enabled &&
        (std::fabs(st_.act_vel) > p_.velocity_max || std::fabs(st_.set_vel) > p_.velocity_max * (1 + 1e-9))) {
        if (++overspeed_cycles_ >= p_.velocity_time_traj_cycles) {
            st_.last_interlock = Interlock::MaxSpeed;
            fault(error_id::kMaxVelocity, false);
            if (++overspeed_drive_cycles_ >= p_.velocity_time_drive_cycles) fault(error_id::kMaxVelocity, true);
        }
    } else if (st_.error_id != error_id::kMaxVelocity) {
        overspeed_cycles_ = overspeed_drive_cycles_ = 0;
    }
    // Stall: after a move, not at target within max(15 s, 10 x the move's duration): disable.
    if (st_.busy) {
        move_time_ += dt;
    } else if (stall_wait_ >= 0 && p_.stall_enable && p_.target_enable && st_.enabled) {
        if (st_.at_target) {
            stall_wait_ = -1;
        } else if ((stall_wait_ -= dt) < 0) {
            st_.last_interlock = Interlock::Stall;
            fault(error_id::kStall, true);
        }
    }
}

void Axis::run(double dt) noexcept {
    ++st_.cycle;
    take_variables();
    bool bus_ok = !io_.bus_status.bound() || io_.bus_status.get() != 0;
    for (const registry::BoundSignal& v : io_.slave_valid) bus_ok = bus_ok && v.get() != 0;
    read_inputs();
    if (!p_.virtual_axis) {
        enc_.update(dt);
        if (p_.primary_encoder < st_.enc_count) st_.enc_pos[std::size_t(p_.primary_encoder)] = enc_.position();
        for (std::size_t o = 0; o < others_.size(); ++o) {
            others_[o].update(dt);
            if (other_index_[o] < st_.enc_count) st_.enc_pos[std::size_t(other_index_[o])] = others_[o].position();
        }
    }
    // The actual position is valid once the bus has been OK for a cycle (a PLC-fed one a cycle
    // later: the PLC writes extactpos after the axes, in the first cycle with the bus OK).
    ok_cycles_ = bus_ok ? std::min(ok_cycles_ + 1, 2) : 0;
    if (!st_.position_valid) st_.position_valid = ok_cycles_ >= (enc_source_ == 1 ? 2 : 1);
    bool enabled = p_.virtual_axis ? enable_req_ : drive_.enabled();
    bool drive_enable = enable_req_;
    if (io_.brake.bound() && !p_.virtual_axis) {
        // The brake opens openDelay cycles after the drive is enabled, and the axis counts as
        // enabled only then; on disable it closes at once while the drive stays enabled
        // closeAhead cycles more (holding the load at zero velocity).
        if (enable_req_ && enabled) {
            if (brake_cycles_ < p_.brake_open_delay_cycles) ++brake_cycles_;
            else st_.brake_open = true;
            close_ahead_left_ = p_.brake_close_ahead_cycles;
        } else {
            st_.brake_open = false;
            brake_cycles_ = 0;
            if (!enable_req_ && close_ahead_left_ > 0 && enabled) {
                --close_ahead_left_;
                drive_enable = true;
            }
        }
        io_.brake.set(st_.brake_open ? 1 : 0);
        enabled = enabled && enable_req_ && st_.brake_open;
    }
    if (!p_.virtual_axis) {
        if (!bus_ok) {
            st_.last_interlock = Interlock::BusNotOk;
            fault(error_id::kBusNotOk, true); // every cycle while not OK
        } else if (!bus_was_ok_ && p_.enable_at_startup) {
            // axis.autoEnable.atStartup: enabled again when its slaves are back (ECMC goes through
            // its start-up state after every loss); it holds its position, it never moves by itself.
            AxisCommand on{CommandType::Power};
            on.on = true;
            (void)command(on);
        }
        bus_was_ok_ = bus_ok;
        if (drive_.error()) {
            uint32_t id = p_.drive.type == DriveParams::Type::Ds402
                              ? error_id::kDs402Fault
                              : error_id::kDriveAlarm0 + uint32_t(std::max(drive_.error_input(), 0));
            fault(id, true);
        } else if (drive_.timed_out()) {
            fault(p_.drive.type == DriveParams::Type::Ds402 ? error_id::kDs402Timeout : error_id::kDriveTimeout, true);
        } else if (was_enabled_ && enable_req_ && !enabled && !drive_.enabled()) {
            st_.warning_id = error_id::kEnableLost; // the drive dropped out: enable is cleared
            enable_req_ = false;
            st_.enable_cmd = false;
        }
    }
    was_enabled_ = enabled;
    st_.enabled = enabled;
    if (has_pending_ && auto_enabling_ && !enabled) {
        auto_enable_time_ += dt;
        if (auto_enable_time_ > p_.auto_enable_timeout_s) fault(error_id::kAutoEnableTimeout, true);
    }
    if (has_pending_) {
        if (enabled) {
            has_pending_ = auto_enabling_ = false;
            (void)command(pending_);
        } else if (!enable_req_ || st_.error_id) { // the enable failed or was withdrawn
            auto_enabling_ = false;
            st_.move_failed = true; // the move never ran
            has_pending_ = false;
            finish(pending_.tag);
            st_.refused_tag = pending_.tag;
        }
    }
    st_.act_pos = p_.virtual_axis ? traj_.state().position : enc_.position();
    st_.act_vel = p_.virtual_axis ? traj_.state().velocity : enc_.velocity();
    if (enc_source_ == 1) { // the PLC computes the actual position (ax<n>.enc.extactpos)
        double x = vars_.enc.extactpos;
        st_.act_vel = std::isfinite(last_ext_act_) && dt > 0 ? (x - last_ext_act_) / dt : 0;
        st_.act_pos = x;
        last_ext_act_ = x;
    } else {
        last_ext_act_ = NAN;
    }

    // Sequencer and trajectory.
    if (seq_ == Seq::Homing) homing_.step();
    bool was_busy = seq_ != Seq::Idle;
    TrajectoryResult r = traj_.step(dt);
    if (r == TrajectoryResult::Finished && (seq_ == Seq::Moving || seq_ == Seq::Stopping)) {
        if (seq_ == Seq::Stopping) st_.target_pos = traj_.state().position; // as ECMC after a stop
        seq_ = Seq::Idle;
        finish(tag_);
    }
    if (seq_ == Seq::Pvt) { // the profile gives the setpoint, one cycle further each cycle
        pvt_t_ += dt;
        double p = 0, v = 0, a = 0;
        pvt_->eval(pvt_t_, pvt_seg_, p, v, a);
        traj_.reset({p + pvt_offset_, v, a});
        if (pvt_t_ >= pvt_->end_time()) {
            traj_.reset({p + pvt_offset_, 0, 0});
            st_.target_pos = p + pvt_offset_;
            seq_ = Seq::Idle;
            pvt_ = nullptr;
            finish(tag_);
        }
    }
    if (!enabled && seq_ != Seq::Idle) { // a disabled axis does not move: the command ends
        if (seq_ == Seq::Homing) homing_.abort();
        if (seq_ == Seq::Pvt) pvt_ = nullptr;
        if (seq_ != Seq::Stopping) st_.move_failed = true;
        seq_ = Seq::Idle;
        finish(tag_);
    }
    st_.following = traj_source_ == 1;
    st_.ext_moving = st_.ext_limited = false;
    if (traj_source_ == 1 && enabled) { // the PLC gives the setpoint (ax<n>.traj.extsetpos)
        double x = p_.virtual_axis ? vars_.traj.extsetpos : hold_at_limits(vars_.traj.extsetpos);
        if (ext_hold_ && std::isfinite(last_ext_set_)) x = last_ext_set_;
        double v = std::isfinite(last_ext_set_) && dt > 0 ? (x - last_ext_set_) / dt : 0;
        // moving while the setpoint changed within the last kExtSettleCycles cycles
        bool changed = std::isfinite(last_ext_set_) && std::fabs(x - last_ext_set_) > 1e-12 * std::max(1.0, std::fabs(x));
        ext_still_cycles_ = changed ? 0 : std::min(ext_still_cycles_ + 1, kExtSettleCycles);
        st_.ext_moving = ext_still_cycles_ < kExtSettleCycles;
        last_ext_set_ = x;
        if (seq_ != Seq::Idle) { // an own command ends when the source is external
            seq_ = Seq::Idle;
            finish(tag_);
        }
        traj_.reset({x, v, 0}); // bumpless when the source switches back
        st_.target_pos = x;
    } else {
        last_ext_set_ = NAN;
    }
    if (!enabled) {
        traj_.reset({st_.act_pos, 0, 0}); // the setpoint follows the actual position
        ctrl_.reset();
    }
    st_.set_pos = traj_.state().position;
    st_.set_vel = traj_.state().velocity;
    if (p_.virtual_axis && enc_source_ == 0) {
        st_.act_pos = st_.set_pos;
        st_.act_vel = st_.set_vel;
    }
    st_.pos_err = st_.set_pos - st_.act_pos;
    st_.busy = seq_ != Seq::Idle || has_pending_;
    if (was_busy && !st_.busy && st_.command != CommandType::Home)
        stall_wait_ = std::max(15.0, 10 * move_time_); // the stall check starts when busy ends
    if (!st_.busy && !enabled) st_.target_pos = st_.act_pos;
    st_.moving = st_.busy && std::fabs(st_.act_vel) > 0;
    monitor(dt);
    st_.busy = seq_ != Seq::Idle || has_pending_;
    // ECMC autoEnable.disableTimeout: idle (not busy, enabled, at target if monitored) this long
    if (p_.auto_disable_timeout_s > 0 && auto_disable_on_) {
        if (st_.busy || !enabled || (p_.target_enable && !st_.at_target)) {
            idle_time_ = 0;
        } else if (idle_time_ > p_.auto_disable_timeout_s && enable_req_) {
            AxisCommand off{CommandType::Power};
            (void)command(off);
            idle_time_ = 0;
        } else {
            idle_time_ += dt;
        }
    }
    last_home_ = st_.home_sensor;
    last_lim_fwd_ = st_.limit_fwd;
    last_lim_bwd_ = st_.limit_bwd;

    // Controller and drive.
    double out = 0;
    if (p_.csp && p_.csp_pc) { // CSP_PC: the setpoint plus the PID's correction from the primary encoder
        if (!enabled) csp_correction_ = 0;
        else if (st_.busy || !ctrl_.in_deadband()) csp_correction_ = ctrl_.step(st_.pos_err, 0, dt);
        else ctrl_.track(st_.pos_err); // holding the correction while within the deadband
        out = st_.set_pos + csp_correction_ - csp_drive_frame_offset();
    } else if (p_.csp) out = st_.set_pos - enc_.frame_offset(); // the drive's loop follows the position
    else if (enabled && !p_.virtual_axis) out = ctrl_.step(st_.pos_err, st_.set_vel, dt);
    st_.drive_output = out;
    if (!p_.virtual_axis) drive_.step(drive_enable, out, !st_.busy, dt);
    publish_variables();
}

} // namespace beamctl::motion
