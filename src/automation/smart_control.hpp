// smartControl (seed 004; docs/goniometer.md): an external control program (Bruker's SMART, or
// anything that speaks the line protocol of smart_command.hpp) drives up to four of this IOC's
// motors, a shutter, a detector trigger and a scaler. The setup table of smartControl's screen is
// served as PVs under $(P)<name>: (per axis: Exists, Offset, Sign, LowCut, HighCut; the client's
// view: Position, Velocity, LowLimit, HighLimit) and read at each command, so an operator can
// change it live. Moves go through the motor records with a put-callback: a move that is refused,
// ends short or stops on a limit is answered with ERR, never OK.
//
// Replies are one line each and start with the command's keyword ("MOVE OK OMEGA=140.000").
// MOVE, SCAN and COUNT answer when they end; the other commands answer at once, also while one of
// those is under way (STOP ends it: its answer is ERR). One of MOVE/SCAN/COUNT at a time.
// Threading: the IOC loop (it owns the database).
#pragma once

#include "automation/smart_command.hpp"
#include "config/ioc_config.hpp"
#include "pv/database.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::automation {

class SmartControl {
public:
    using Reply = std::function<void(const std::string& line)>;

    // Makes the setup table's records (loaded into `db`; call before init_records).
    SmartControl(const config::SmartControlEntry& cfg, const std::string& prefix, pv::Database& db, std::function<double()> clock);
    // After init_records: finds the motors, shutter, trigger and scaler. Throws Error naming the
    // configuration entry whose PV is missing or is not what it should be.
    void start();
    // One line from a client; `reply` is called once (now, or when the command ends) unless the
    // client is gone (the transport drops replies to closed connections).
    void command(std::string_view line, const Reply& reply);
    // The IOC loop, every 10 ms: counting, the scan's steps, the table's read-backs.
    void poll();
    void set_clients(int n);
    // Bad input the transport refused (a line too long): counted and logged with the others.
    void count_error(const std::string& why);

    uint64_t commands() const { return commands_; }
    uint64_t errors() const { return errors_; }
    bool busy() const { return op_.kind != Op::None; }

private:
    struct Axis {
        config::SmartControlEntry::Axis cfg;
        std::string part;              // TwoTheta, Omega, ...
        pv::Address val, rbv, velo, hlm, llm, stop, dmov, vmax, cnen, lvio, rdbd, mres;
    };
    struct Op {
        enum Kind { None, Move, Count, ScanToStart, ScanExposing } kind = None;
        Reply reply;
        std::string keyword;
        uint64_t id = 0;
        int outstanding = 0;
        std::vector<std::string> failures;
        std::vector<std::pair<int, double>> targets; // (axis, smart position)
        std::vector<double> motor_target;            // per axis: where its move should end [motor units]
        double t_end = 0, t_last = 0, counts = 0, t_start = 0;
        int axis = -1;
        double motor_end = 0, saved_velo = 0, end = 0;
    };
    SmartAxisSetup setup(const Axis& a) const;
    int find_axis(const std::string& name) const;
    double get(const pv::Address& a) const;
    bool put(const pv::Address& a, double v, pv::PutCallback cb = {});
    double pv_value(const std::string& rec) const;
    void finish(const std::string& line);
    void fail(const Reply& reply, const std::string& keyword, const std::string& why);
    bool check_motor_target(const Axis& a, double motor, std::string& why) const;
    void start_moves(const std::vector<std::pair<int, double>>& motor_targets, uint64_t id);
    void on_move_done(uint64_t id, int axis, pv::PutStatus s);
    void begin_exposure();
    void end_scan(bool ok, const std::string& why);
    void set_output(const pv::Address* a, double v);
    std::string positions(const std::vector<int>& axes) const;
    void publish_table();

    config::SmartControlEntry cfg_;
    std::string p_;                    // $(P)<name>:
    pv::Database& db_;
    std::function<double()> clock_;
    std::vector<Axis> axes_;
    pv::Address shutter_, trigger_, scaler_;
    bool has_shutter_ = false, has_trigger_ = false, has_scaler_ = false;
    bool started_ = false;
    Op op_;
    uint64_t next_id_ = 1;
    uint64_t commands_ = 0, errors_ = 0;
    double last_table_ = -1e9;
};

} // namespace beamctl::automation
