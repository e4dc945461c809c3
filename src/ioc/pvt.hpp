// PVT profile moves served as ECMC serves them (ecmccfg's ecmcProfileMoveController.template and
// ecmcProfileMoveAxis.template, the motor module's profile-move PVs): made when an axis file has
// `epics.motorRecord.pvt: {npoints, nreadback}`. $(P) is the IOC prefix, <Axis> the axis name.
//   $(P)PVT-NumPoints, -NumPulses, -StartPulses, -EndPulses (longout), -TimeMode (bo Fixed/Array),
//   -FixedTime, -Acceleration (ao, s), -Times (waveform, s), -MoveMode (bo Absolute/Relative),
//   -Build, -Execute, -Abort, -Readback (bo: a put acts), -BuildState/-Status/-Message,
//   -ExecuteState/-Status/-Message, -ReadbackState/-Status/-Message (mbbi, 256-char waveform),
//   -CurrentPoint, -NumActualPulses, -SftTrg, -MaxSize, -NumAxes (longin/longout)
//   $(P)<Axis>-PVT-UseAxis (bo No/Yes), -Positions (waveform), -Readbacks, -FollowingErrors
// Build makes the paths on the IOC loop and checks them (points, times, pulses, each used axis's
// soft limits and maximum velocity); Execute hands them to the RT controller (motion::PvtController),
// which runs them; ExecuteStatus is Success only when every used axis ran its whole path.
// Deliberate differences from ECMC (docs/motion.md): only UseAxis axes are built and checked; a
// build or execute that fails says Failure with a message; Acceleration must be > 0; an axis
// that is stopped, interlocked or in error ends the profile as Failure with its name and id.
// Threading: construction and bind before the cycle starts; puts and publish() on the IOC loop.
#pragma once

#include "config/ioc_config.hpp"
#include "ioc/axes.hpp"
#include "motion/pvt.hpp"
#include "pv/database.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <atomic>
#include <deque>
#include <memory>
#include <string>
#include <vector>

namespace beamctl::ioc {

class IocPvt {
public:
    // The records of every PVT-enabled axis and of the controller (none if no axis has pvt:).
    IocPvt(const config::IocConfig& cfg, IocAxes& axes, pv::Database& db);
    IocPvt(const IocPvt&) = delete;
    IocPvt& operator=(const IocPvt&) = delete;

    // Bring-up: the RT controller (after the axes) and its trigger output, if configured.
    void bind(rt::Engine& engine, registry::Registry& reg);
    // IOC loop: the controller's state into the PVs.
    void publish();
    bool enabled() const { return !axes_.empty(); }
    motion::PvtController* controller() { return ctrl_.get(); }

private:
    struct AxisPvt {
        std::size_t index = 0; // in IocAxes
        std::string name;
        uint32_t npoints = 0, nreadback = 0;
        pv::Record *use = nullptr, *positions = nullptr, *readbacks = nullptr, *ferrors = nullptr;
        motion::PvtPath built, running;
        bool has_built = false;
        std::vector<double> rb, fe; // readback buffers the RT thread fills
        std::atomic<uint32_t> count{0};
    };
    void invalidate(const std::string& why);
    void build();
    void execute();
    void abort();
    void readback();
    void set_text(pv::Record* r, const std::string& text);
    void set_num(pv::Record* r, double v);
    double num(pv::Record* r) const;
    std::vector<double> array(pv::Record* r) const;
    std::string axis_name(int index) const;

    const config::IocConfig& cfg_;
    IocAxes& iaxes_;
    pv::Database& db_;
    std::deque<AxisPvt> axes_;
    std::unique_ptr<motion::PvtController> ctrl_;
    uint32_t max_size_ = 0;
    bool built_ = false, build_relative_ = false;
    uint64_t runs_seen_ = 0;
    bool running_ = false; // a profile was executed (readback has something to give)
    bool started_ = false;
    motion::PvtController::Job built_job_;
    // controller records
    pv::Record *num_points_ = nullptr, *num_pulses_ = nullptr, *start_pulses_ = nullptr, *end_pulses_ = nullptr,
               *time_mode_ = nullptr, *fixed_time_ = nullptr, *times_ = nullptr, *accel_ = nullptr, *move_mode_ = nullptr,
               *build_state_ = nullptr, *build_status_ = nullptr, *build_msg_ = nullptr, *exec_state_ = nullptr,
               *exec_status_ = nullptr, *exec_msg_ = nullptr, *rb_state_ = nullptr, *rb_status_ = nullptr, *rb_msg_ = nullptr,
               *current_point_ = nullptr, *actual_pulses_ = nullptr, *soft_trigger_ = nullptr;
};

} // namespace beamctl::ioc
