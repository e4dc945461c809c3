// The IOC's motion axes: ECMC axis files loaded and checked when the IOC is built (their signal
// links against the configured buses, every error with file:line:col) together with their PVs;
// bound to the buses' process images at bring-up and run in the RT cycle by one AxisGroup
// stage; published into the PVs and commanded from them by the IOC loop.
//
// PVs, as ecmccfg's ecmcAxis.db names them ($(P) = the IOC prefix, AX = epics.name), made from
// one declarative table (axes.cpp, axis_table) on the axis's data items ax<n>.actpos, .status,
// .control, ...: $(P)AX-PosAct -VelAct -PosSet -PosErr (ai), -Stat -ErrId -WrnId -SeqState
// -LastIlock (longin), -EnaAct -Busy -AtTarget -Moving -LimFwd -LimBwd -HomeSwitch -Homed -Err
// (bi), -EnaCmd -ExeCmd -StpCmd -RstCmd (bo: bits 0-3 of ax<n>.control), -TgtPosCmd -TgtVelCmd
// (ao), -MtnCmd -MtnCmdData (longout), -MsgTxt (stringin), -Enc0N-PosAct (ai, every encoder);
// and the motor record $(P)AX (epics.motorRecord.enable, as ecmccfg), driven through
// AxisMotorDriver. Any record of a .db file can read and write the same items ("@ax1.actpos").
// Threading: everything here runs on the IOC loop thread except the AxisGroup's RT stage.
#pragma once

#include "core/error_list.hpp"

#include "config/ioc_config.hpp"
#include "motion/axis_config.hpp"
#include "motion/axis_group.hpp"
#include "pv/database.hpp"
#include "pv/link.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace beamctl::ioc {

// What the IOC keeps of an axis's commands between puts (ECMC's targpos, targvelo, command,
// cmddata and control items): ExeCmd runs `command` with them.
struct AxisCommandState {
    double targpos = 0, targvelo = 0;
    int command = 3, cmddata = 14; // absolute move; the configured homing sequence
    uint32_t control = 0;          // bits as last written: 1 execute, 2 stop, 3 reset (0 is the axis's)
};

class IocAxes {
public:
    // Loads the axis files and creates their PVs. Every bus signal an axis names must be in
    // `signals` (declared by the buses); each axis declares its ax<n>.* variables there and
    // becomes the one writer of the outputs it drives every cycle. Every error of every axis goes
    // to `errors` (file:line:col, after the IOC file's entry and its macros); an axis whose file
    // cannot be read is left out, one with a bad signal kept (the IOC is not run with errors).
    IocAxes(const std::vector<config::AxisEntry>& entries, const std::string& prefix,
            registry::Registry& signals, pv::Database& db, ErrorList& errors);

    // Bring-up: binds every axis to the process images and adds the axis stage to the engine.
    using Resolver = std::function<registry::BoundSignal(const motion::SignalRef&)>;
    void bind(const Resolver& resolve, rt::Engine& engine);
    // IOC loop: statuses into PVs (on change), command results.
    void publish();

    std::size_t size() const { return axes_.size(); }
    motion::AxisGroup* group() { return group_.get(); }
    const motion::AxisConfig& config(std::size_t i) const { return axes_.at(i).cfg; }
    // Index of the axis with this epics.name, or -1.
    int find(const std::string& name) const;
    // Sends a command to axis i (non-RT) with a new tag (returned; 0 if the queue is full).
    uint64_t send(std::size_t i, motion::AxisCommand c);
    // The latest status of axis i (default before bring-up).
    const motion::AxisStatus& status(std::size_t i);
    const motion::AxisParams& params(std::size_t i) const { return axes_.at(i).params; }
    const std::string& name(std::size_t i) const { return axes_.at(i).cfg.epics.name; }
    // "axis 1 (SampleX)": how errors and the registry name axis i as an owner or writer.
    std::string owner(std::size_t i) const;
    // Device support "beamctl" on an axis data item of the registry ("ax1.actpos", "ax1.status"
    // with bit 1, "ax1.control" bit 0, or a PLC name: "ax1.enc.actpos"): reads the latest snapshot,
    // writes become commands. `binary`: the record has two states (a non-zero value reads 1).
    // Null with `why` for an item the IOC loop does not see or cannot write.
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view name, int bit, bool output, bool binary, std::string& why);
    // A write of item `w` (bit `bit` of control, -1 the word) of axis i; false if refused.
    bool write_item(std::size_t i, int w, int bit, double v);
    const AxisCommandState& command_state(std::size_t i) const { return axes_.at(i).cmd; }
    // Axis i's status as the IOC loop's last look (publish) took it: what the records read, one
    // snapshot for all of them (status() takes the newest each call).
    const motion::AxisStatus& looked(std::size_t i) const { return i < look_.size() ? look_[i] : idle_; }
    // IOC loop: the soft limits of axis i's motor record (DLLM/DHLM, dial) become [lo, hi]: a
    // virtual axis's range as its kinematics group derives it. No-op without a motor record.
    void set_derived_limits(std::size_t i, double lo, double hi);
    // IOC loop: axis i's motor record's dial soft limits changed (a put to DHLM, DLLM, HLM, LLM):
    // the axis takes them, enabled, or disabled for DLLM = DHLM = 0 (the record's "no limits"), as
    // ECMC's driver with CfgSyncSftLim. One value both ways: PLC code moving the axis's limits
    // moves the record's (publish). Not for a derived (kinematics) axis.
    void set_record_limits(std::size_t i, double lo, double hi);
    // Motor records of the IOC's .db files with DTYP "asynMotor" and OUT "@asyn(PORT,ADDR)" (the
    // stock synApps asyn_motor.db, ECMC's port MC_CPU1): driven by axis ADDR (its id), as ECMC's
    // motor driver. Throws Error naming the record when there is no such axis.
    void attach_asyn_motors();

private:
    struct Axis {
        motion::AxisConfig cfg;
        motion::AxisParams params;
        std::string pv; // "$(P)AX"
        AxisCommandState cmd;
        pv::Record* msg = nullptr; // -MsgTxt: the text of the last error or refusal
        uint32_t last_error = ~0u;
        // soft limits as the motor record last got them from the axis (PLC code may move them,
        // as ecmccfg's slit include does); a kinematics group's derived limits take over
        double soft_fwd = NAN, soft_bwd = NAN;
        bool derived = false;
        // limits the record sent that the axis's status does not show yet: publish() leaves the
        // record alone until it does (or the command's tag is done)
        bool limits_pending = false;
        uint64_t limits_tag = 0;
        bool following_axis = false; // put_dial_limits is writing the record's limits
    };
    void make_pvs(Axis& a, registry::Registry& signals);
    void make_motor_record(Axis& a, pv::DbFile& f);
    void attach_motor_drivers();
    void set_message(Axis& a, const char* text);
    void put_dial_limits(std::size_t i, double lo, double hi); // DLLM/DHLM of axis i's motor record

    pv::Database& db_;
    std::string prefix_;
    std::vector<Axis> axes_;
    std::unique_ptr<motion::AxisGroup> group_;
    uint64_t next_tag_ = 1;
    motion::AxisStatus idle_; // status before bring-up
    std::vector<motion::AxisStatus> look_; // the snapshot of the last publish()
};

} // namespace beamctl::ioc
