#include <algorithm>
#include "motion/axis_setup.hpp"

#include "core/error.hpp"
#include "core/paths.hpp"

#include <cstdlib>
#include <filesystem>

namespace beamctl::motion {

namespace {
std::string at(const SourceLoc& w) { return SB() << w.file << ":" << w.line << ":" << w.col; }

const EncoderConfig* primary(const AxisConfig& c) {
    return c.encoders.empty() ? nullptr : &c.encoders[c.primary_encoder()];
}

// A drive error input: a bit of the status word (the common case) -> its bit number.
int status_bit(const DriveConfig& d, const SignalRef& e) {
    if (e.bus == d.status.bus && e.slave == d.status.slave && e.entry == d.status.entry && e.bit >= 0) return e.bit;
    throw Error(SB() << at(e.where) << ": drive error input '" << e.text
                     << "' is not a bit of drive.status; only status-word bits are supported");
}
} // namespace

AxisParams make_axis_params(const AxisConfig& c) {
    AxisParams p;
    p.id = c.axis.id.value_or(1);
    p.name = c.epics.name;
    p.virtual_axis = c.is_virtual();
    p.csp = c.drive && (c.axis.mode == DriveMode::CSP || c.axis.mode == DriveMode::CSP_PC);
    if (c.drive && c.axis.mode == DriveMode::CSP_PC) {
        p.csp_pc = true;
        for (std::size_t k = 0; k < c.encoders.size(); ++k)
            if (c.encoders[k].use_as_csp_drive_encoder) p.csp_drive_encoder = int(k);
        if (p.csp_drive_encoder < 0)
            throw Error(SB() << c.file << ": axis.mode CSP_PC needs the drive's own encoder marked "
                                          "encoder.useAsCSPDrvEnc: true (its frame is the drive's)");
    }
    // PLC connection: sources, external commands, switches written by PLC code
    p.trajectory_source = c.trajectory.source == TrajectorySource::PLC ? 1 : 0;
    p.external_commands = c.plc && c.plc->external_commands;
    p.allow_source_change = c.axis.features.allow_src_change_when_enabled;
    p.block_com = c.axis.features.block_com;
    if (const auto& am = c.axis.auto_mode) {
        p.auto_mode_motion = am->mode_cmd_motion ? int(*am->mode_cmd_motion) : -1;
        p.auto_mode_home = am->mode_cmd_home ? int(*am->mode_cmd_home) : -1;
    }
    p.allow_positioning = c.axis.features.allow_positioning;
    p.allow_constant_velocity = c.axis.features.allow_constant_velocity;
    p.allow_homing = c.axis.features.allow_homing;
    p.limit_fwd_plc = c.input.limit_forward.plc_override;
    p.limit_bwd_plc = c.input.limit_backward.plc_override;
    p.home_plc = c.input.home && c.input.home->plc_override;
    auto enc_params = [](const EncoderConfig& e) {
        EncoderParams q;
        q.numerator = e.numerator;
        q.denominator = double(e.denominator);
        q.absolute = e.type == EncoderType::Absolute;
        q.bits = e.bits;
        q.abs_bits = e.abs_bits; // the wrap width of an absolute encoder; homing 21/22's single-turn bits for any
        q.abs_offset = e.abs_offset;
        if (!e.mask.empty()) q.mask = std::strtoull(e.mask.c_str(), nullptr, 0);
        q.ref_at_home = e.homing && e.homing->ref_at_home != 0;
        if (e.velocity_filter && e.velocity_filter->enable)
            q.filter_size = int(std::min<int64_t>(e.velocity_filter->size, EncoderParams::kMaxFilter));
        if (const auto& t = e.lookuptable; t && t->enable) { // the file next to the encoder's file
            std::string f = resolve_beside(std::filesystem::path(e.where.file).parent_path(), t->filename);
            try {
                q.correction = std::make_shared<const LookupTable>(LookupTable::load(f));
            } catch (const Error& x) {
                throw Error(SB() << at(e.where) << ": encoder.lookuptable: " << x.what());
            }
            q.correction_range = t->range.value_or(0);
            q.correction_scale = t->scale.value_or(1);
        }
        return q;
    };
    for (const auto& e : c.encoders) p.encoders.push_back(enc_params(e));
    p.primary_encoder = int(c.primary_encoder());
    if (const EncoderConfig* e = primary(c)) {
        p.encoder_source = e->source == EncoderSource::PLC ? 1 : 0;
        p.encoder = enc_params(*e);
        if (const auto& h = e->homing) {
            p.homing_sequence = h->type;
            p.homing_position = h->position.value_or(0);
            p.homing_velocity_to = h->velocity_to.value_or(0);
            p.homing_velocity_from = h->velocity_from.value_or(p.homing_velocity_to);
            p.homing_acceleration = h->acceleration.value_or(0);
            p.homing_post_move_enable = h->post_move_enable;
            p.homing_latch_count = int(h->latch_count.value_or(1));
            p.homing_post_move_position = h->post_move_position;
        }
    }
    if (const auto& d = c.drive) {
        p.drive.type = d->type == DriveType::DS402 ? DriveParams::Type::Ds402 : DriveParams::Type::Stepper;
        p.drive.position_mode = p.csp;
        p.drive.numerator = d->numerator;
        p.drive.denominator = double(d->denominator);
        p.drive.enable_bit = d->enable_bit;
        p.drive.enabled_bit = d->enabled_bit;
        p.drive.reset_bit = d->reset_bit.value_or(-1);
        p.drive.warning_bit = d->warning_bit.value_or(-1);
        p.drive.reduce_torque_bit = d->reduce_torque_enable ? d->reduce_torque_bit.value_or(-1) : -1;
        for (std::size_t i = 0; i < d->errors.size() && i < 3; ++i) p.drive.error_bits[i] = status_bit(*d, d->errors[i]);
        if (d->brake && d->brake->enable) {
            p.brake_open_delay_cycles = int(d->brake->open_delay_cycles);
            p.brake_close_ahead_cycles = int(d->brake->close_ahead_cycles);
        }
    }
    const auto& k = c.controller;
    p.controller.kp = k.kp;
    p.controller.ki = k.ki;
    p.controller.kd = k.kd;
    p.controller.kff = k.kff;
    if (k.limits.max_output > k.limits.min_output) {
        p.controller.min_output = k.limits.min_output;
        p.controller.max_output = k.limits.max_output;
    }
    if (k.limits.max_integral > k.limits.min_integral) {
        p.controller.min_integral = k.limits.min_integral;
        p.controller.max_integral = k.limits.max_integral;
    }
    if (k.deadband) {
        p.controller.deadband = k.deadband->tol;
        p.controller.deadband_cycles = int(k.deadband->time_cycles);
    }
    const auto& t = c.trajectory;
    p.trajectory.velocity = t.axis.velocity;
    p.trajectory.acceleration = t.axis.acceleration;
    p.trajectory.deceleration = t.axis.deceleration > 0 ? t.axis.deceleration : t.axis.acceleration;
    p.trajectory.jerk = t.type == TrajectoryType::SCurve ? t.axis.jerk : 0;
    p.emergency_deceleration = t.axis.emergency_deceleration;
    p.jog_velocity = t.jog.velocity;
    if (t.modulo) {
        p.modulo_range = t.modulo->range;
        p.modulo_type = int(t.modulo->type);
    }
    p.limit_fwd_polarity = c.input.limit_forward_polarity;
    p.limit_bwd_polarity = c.input.limit_backward_polarity;
    p.home_polarity = c.input.home_polarity;
    p.interlock_polarity = c.input.interlock_polarity;
    p.soft_fwd_enable = c.softlimits.enable && c.softlimits.forward_enable;
    p.soft_bwd_enable = c.softlimits.enable && c.softlimits.backward_enable;
    p.soft_fwd = c.softlimits.forward;
    p.soft_bwd = c.softlimits.backward;
    const auto& m = c.monitoring;
    p.lag_enable = m.lag.enable;
    p.lag_tolerance = m.lag.tolerance;
    p.lag_time_cycles = int(m.lag.time_cycles);
    p.target_enable = m.target.enable;
    p.target_tolerance = m.target.tolerance;
    p.target_time_cycles = int(m.target.time_cycles);
    p.velocity_enable = m.velocity.enable;
    p.velocity_max = m.velocity.max;
    if (m.velocity.trajectory_cycles > 0) p.velocity_time_traj_cycles = int(m.velocity.trajectory_cycles);
    if (m.velocity.drive_cycles) p.velocity_time_drive_cycles = int(*m.velocity.drive_cycles);
    p.stall_enable = !m.stall || m.stall->enable;
    p.enable_at_startup = c.axis.auto_enable && c.axis.auto_enable->at_startup;
    if (c.axis.auto_enable) {
        p.auto_enable_timeout_s = c.axis.auto_enable->enable_timeout_s;
        p.auto_disable_timeout_s = c.axis.auto_enable->disable_timeout_s;
    }
    return p;
}

std::vector<SignalRef> axis_signal_refs(const AxisConfig& c) {
    std::vector<SignalRef> v;
    for (const auto& other : c.encoders)
        if (&other != primary(c) && other.position && other.source == EncoderSource::EtherCAT) v.push_back(*other.position);
    if (const EncoderConfig* e = primary(c)) {
        if (e->position && e->source == EncoderSource::EtherCAT) v.push_back(*e->position);
        if (e->latch && e->control && e->status) {
            v.push_back(e->latch->position);
            v.push_back(*e->control);
            v.push_back(*e->status);
        }
    }
    if (const EncoderConfig* e = primary(c); e && e->homing && e->homing->trigg && e->homing->ready) {
        v.push_back(*e->homing->trigg);
        v.push_back(*e->homing->ready);
    }
    if (const auto& am = c.axis.auto_mode) {
        if (am->mode_set) v.push_back(*am->mode_set);
        if (am->mode_act) v.push_back(*am->mode_act);
    }
    if (c.drive) {
        v.push_back(c.drive->control);
        v.push_back(c.drive->status);
        v.push_back(c.drive->setpoint);
        if (c.drive->brake && c.drive->brake->enable) v.push_back(c.drive->brake->output);
    }
    if (!c.input.limit_forward.plc_override && !c.input.limit_forward.signal.text.empty()) v.push_back(c.input.limit_forward.signal);
    if (!c.input.limit_backward.plc_override && !c.input.limit_backward.signal.text.empty()) v.push_back(c.input.limit_backward.signal);
    if (c.input.home && !c.input.home->plc_override && !c.input.home->signal.text.empty()) v.push_back(c.input.home->signal);
    if (c.input.interlock && !c.input.interlock->text.empty()) v.push_back(*c.input.interlock);
    return v;
}

AxisIo bind_axis_io(const AxisConfig& c, const SignalResolver& resolve) {
    AxisIo io;
    if (c.is_virtual()) return io;
    const EncoderConfig* e = primary(c);
    if (e && e->position) io.encoder = resolve(*e->position);
    for (const auto& other : c.encoders)
        io.encoders.push_back(other.position && other.source == EncoderSource::EtherCAT ? resolve(*other.position)
                                                                                      : registry::BoundSignal{});
    if (e && e->latch && e->control && e->status) {
        io.latch_position = resolve(e->latch->position);
        io.latch_arm = resolve(e->control->with_bit(e->latch->control_bit));
        io.latch_valid = resolve(e->status->with_bit(e->latch->status_bit));
    }
    if (e && e->homing && e->homing->trigg && e->homing->ready) {
        io.homing_trigg = resolve(*e->homing->trigg);
        io.homing_ready = resolve(*e->homing->ready);
    }
    if (const auto& am = c.axis.auto_mode) {
        if (am->mode_set) io.mode_set = resolve(*am->mode_set);
        if (am->mode_act) io.mode_act = resolve(*am->mode_act);
    }
    if (c.drive) {
        io.drive_control = resolve(c.drive->control);
        io.drive_status = resolve(c.drive->status);
        io.drive_setpoint = resolve(c.drive->setpoint);
        if (c.drive->brake && c.drive->brake->enable) io.brake = resolve(c.drive->brake->output);
    }
    auto sw = [&](const SwitchInput& s) {
        return s.plc_override || s.signal.text.empty() ? registry::BoundSignal{} : resolve(s.signal);
    };
    io.limit_fwd = sw(c.input.limit_forward);
    io.limit_bwd = sw(c.input.limit_backward);
    if (c.input.home) io.home = sw(*c.input.home);
    if (c.input.interlock && !c.input.interlock->text.empty()) io.interlock = resolve(*c.input.interlock);
    SignalRef status;
    status.bus = c.drive ? c.drive->status.bus : (e && e->position ? e->position->bus : 0);
    status.entry = "masterstatus";
    status.text = SB() << "ec" << status.bus << ".masterstatus";
    status.slave = -2; // the master itself
    io.bus_status = resolve(status);
    // The slaves it uses: the axis runs only while every one of them is in the cycle, in OP.
    std::vector<std::pair<int, int>> slaves;
    for (const SignalRef& r : axis_signal_refs(c))
        if (r.slave >= 0 && !r.is_constant() && std::find(slaves.begin(), slaves.end(), std::pair{r.bus, r.slave}) == slaves.end())
            slaves.emplace_back(r.bus, r.slave);
    for (auto [b, k] : slaves) {
        SignalRef v;
        v.bus = b;
        v.slave = k;
        v.entry = "valid";
        v.text = SB() << "ec" << b << ".s" << k << ".valid";
        registry::BoundSignal bs = resolve(v);
        if (bs.bound()) io.slave_valid.push_back(bs);
    }
    return io;
}

} // namespace beamctl::motion
