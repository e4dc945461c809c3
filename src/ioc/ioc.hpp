// A running IOC (`beamctl run ioc.yaml`): builds the buses (simulated segments for `sim` links),
// brings them up, starts the RT engine, creates the PVs with ecmccfg names (master, engine, every
// slave and its process-data entries), publishes RT snapshots into them and forwards PV writes to
// the cycle. The IOC loop thread owns the PV database and the CA server.
#pragma once

#include "automation/collision.hpp"
#include "automation/compound_motor.hpp"
#include "automation/plan.hpp"
#include "automation/notifier.hpp"
#include "automation/smart_control.hpp"
#include "automation/state_machine.hpp"
#include "ca/ca_link.hpp"
#include "ca/server.hpp"
#include "config/ioc_config.hpp"
#include "core/event_loop.hpp"
#include "core/signals.hpp"
#include "ethercat/bus.hpp"
#include "ethercat/catalog.hpp"
#include "ioc/axes.hpp"
#include "ioc/area_detector.hpp"
#include "ioc/flyscan.hpp"
#include "ioc/kinematics.hpp"
#include "ioc/memmaps.hpp"
#include "module/module.hpp"
#include "ioc/plcs.hpp"
#include "ioc/pvt.hpp"
#include "ioc/storages.hpp"
#include "detector/mca_module.hpp"
#include "detector/quadem_module.hpp"
#include "feedback/feedback_module.hpp"
#include "ethercat/sim/plant.hpp"
#include "ethercat/sim/segment.hpp"
#include "pv/autosave.hpp"
#include "pv/database.hpp"
#include "registry/registry.hpp"
#include "rt/engine.hpp"

#include <deque>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace beamctl::ioc {

class Ioc {
public:
    // Builds everything from the configuration (nothing runs yet). Throws Error.
    Ioc(config::IocConfig cfg, rt::Clock& clock);
    ~Ioc();

    // Every PV this IOC serves, as .db text (`beamctl db ioc.yaml`). Works without bring-up.
    pv::Database& database() { return db_; }
    // Brings the buses to OP (non-RT). Throws Error.
    void bring_up();
    // Publishes the latest RT snapshots into the PVs (IOC loop thread).
    void publish();
    // A cycle woke the loop through bus i's change_fd: drains it, takes the bus's newest snapshot
    // and processes the I/O Intr records whose entries changed (IOC loop thread).
    void bus_changed(std::size_t i);
    // The IOC's cycle: axes, general PLCs, position compare, capture, and every bus without a
    // rate_hz of its own.
    rt::Engine& engine() { return *engine_; }
    // Cycles: 0 the IOC's (engine()), k >= 1 that of a bus with its own rate_hz (own RT thread).
    std::size_t cycle_count() const { return 1 + own_cycles_.size(); }
    rt::Engine& cycle(std::size_t k) { return k == 0 ? *engine_ : *own_cycles_.at(k - 1); }
    // The cycle bus i runs in.
    std::size_t cycle_of_bus(std::size_t i) const { return buses_.at(i).cycle; }
    // Virtual time (tests): n cycles of the IOC's cycle, the other cycles run in between in the
    // order they fall due, on the one clock.
    void run_cycles(uint64_t n);
    ethercat::Bus& bus(std::size_t i) { return *buses_.at(i).bus; }
    std::size_t bus_count() const { return buses_.size(); }
    ethercat::sim::Segment* segment(std::size_t i) { return buses_.at(i).segment.get(); }
    ethercat::sim::Plant* plant(std::size_t i) { return buses_.at(i).plant.get(); }
    const config::IocConfig& config() const { return cfg_; }
    IocAxes& axes() { return *axes_; }
    IocPlcs& plcs() { return *plcs_; }
    IocStorages& storages() { return *storages_; }
    IocKinematics& kinematics() { return *kinematics_; }
    IocPvt& pvt() { return *pvt_; }
    IocFlyScan& flyscan() { return *flyscan_; }
    feedback::FeedbackModule& feedback() { return module<feedback::FeedbackModule>("feedback"); }
    // The modules of the module table (ioc/modules.cpp) this IOC's file has, in their order.
    const std::vector<std::unique_ptr<module::Module>>& modules() const { return modules_; }
    // Its module of type M; Error naming `section` if the file has none.
    template <class M>
    M& module(const char* section) {
        for (auto& m : modules_)
            if (auto* p = dynamic_cast<M*>(m.get())) return *p;
        throw Error(SB() << "this IOC has no " << section << ": section");
    }
    detector::McaModule& detectors() { return module<detector::McaModule>("detectors.mca"); }
    detector::QuadEmModule& quadem() { return module<detector::QuadEmModule>("detectors.quadem"); }
    IocAreaDetector& area_detectors() { return *area_; }
    automation::SmartControl* smart_control() { return smart_.get(); } // smart_control: (or none)
    automation::CompoundMotors* compound_motors() { return compound_.get(); } // compound_motors: (or none)
    automation::StateMachines* state_machines() { return fsms_.get(); }         // state_machines: (or none)
    automation::Notifier* notifier() { return notifier_.get(); }                // notify: (or none)
    automation::CollisionZones* collision_zones() { return zones_.get(); }      // collision_zones: (or none)
    automation::Plans* plans() { return plans_.get(); }                         // plans: (or none)
    // Every signal of this IOC: bus entries, axis and PLC variables, with owners and writers
    // (`beamctl signals`). Frozen once the IOC is built.
    const registry::Registry& signals() const { return registry_; }

    // Runs the IOC: engine on its RT thread, CA server and publisher on the calling thread,
    // until SIGINT/SIGTERM. Prints the ready line.
    int run();
    // The UNIX socket of `beamctl shell` (default: pv::start_shell_server's, by the IOC's name).
    void set_shell_socket(std::string path) { shell_socket_ = std::move(path); }
    // The clean stop run() ends with (public for tests in virtual time); `signals` (may be null)
    // is watched for a second signal, which exits at once.
    void shutdown(LoopSignals* signals = nullptr);

private:
    struct EntryPv { // an output entry's own PV (read-only once an axis, a PLC or a record writes it)
        pv::Record* rec;
        const ethercat::SignalInfo* sig;
        std::string desc; // its DESC while CA writes it
    };
    void own_output(EntryPv& e, const std::string& owner);
    void free_output(EntryPv& e);
    static void set_desc(pv::Record& r, const std::string& text);
    pv::LinkDevice* bind_device(pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why);
    std::vector<std::unique_ptr<pv::LinkDevice>> devices_; // device support of "@..." links
    struct BusRt {
        std::unique_ptr<ethercat::sim::Segment> segment;
        std::shared_ptr<ethercat::sim::Plant> plant; // runs in the segment's on_frame
        std::unique_ptr<ethercat::Bus> bus;
        std::unique_ptr<rt::Stage> sim_stage;
        std::vector<EntryPv> entries;
        pv::Record *lat_hist = nullptr, *lat_edges = nullptr; // arrays the IOC publishes
        std::vector<pv::Record*> err_msg; // per slave $(P)m0s003-ErrMsg: its last error in words
        uint64_t health_seen = ~uint64_t(0); // Master::health_version() at the last publish
        std::size_t cycle = 0; // the cycle it runs in (cycle(k))
        // An EL6692 side's distributed-clock skew (its 0x1A02 time stamps): $(P)m<b>s<kkk>-DcSkew
        // [ns, the other segment's DC time - this one's] and -DcDrift [ppm, over the last second].
        struct DcSkew {
            std::string slave; // "ec1.s1."
            std::string pv;    // "$(P)m1s001"
            pv::Record *skew = nullptr, *drift = nullptr;
            const ethercat::SignalInfo *int_ts = nullptr, *ext_ts = nullptr; // null: 0x1A02 not assigned
            const ethercat::SignalInfo* not_connected = nullptr;
            uint64_t last_stamp = ~uint64_t(0);
            std::deque<std::pair<uint64_t, int64_t>> history; // (internal time stamp, skew), a second of it
        };
        std::vector<DcSkew> dc_skews;
    };
    void publish_dc_skew(BusRt& b, BusRt::DcSkew& d, const ethercat::BusSnapshot& s);
    void declare_bus_signals();
    // Shell commands (IOC loop): `ethercat [BUS]`, `sim BUS FAULT ...`.
    bool ethercat_report(const std::vector<std::string>& argv, std::ostream& os);
    bool sim_fault(const std::vector<std::string>& argv, std::ostream& os);
    // `sdo BUS POSITION INDEX SUB [VALUE SIZE]`: a CoE object read or written through the bus (its
    // master, or the scanner it is attached to).
    bool sdo_command(const std::vector<std::string>& argv, std::ostream& os);
    void make_bus_pvs(BusRt& b, const config::BusConfig& bc);
    std::map<std::string, std::string, std::less<>> entry_pvs_; // entry PV name -> its signal

    config::IocConfig cfg_;
    rt::Clock& clock_;
    const ethercat::Catalog& catalog_;
    pv::Database db_;
    std::unique_ptr<ca::CaLinks> ca_links_; // CA links of db_ to other servers (run() connects them)
    std::unique_ptr<rt::Engine> engine_;
    std::vector<std::unique_ptr<rt::Engine>> own_cycles_; // buses with their own rate_hz, one each
    // While RT consumers bind (bring_up): the cycle they run in; a bus signal of another cycle is
    // refused by the registry's binder. -1: any (the IOC loop's readers).
    int binding_cycle_ = -1;
    // Per cycle, as publish() last read them (the engine items' devices); sized at bring-up, kept.
    std::vector<rt::EngineStats> cycle_stats_;
    std::vector<BusRt> buses_;
    registry::Registry registry_;
    std::unique_ptr<IocAxes> axes_;
    std::unique_ptr<IocStorages> storages_; // before plcs_: the PLCs' storages outlive them
    std::unique_ptr<IocMemMaps> memmaps_;   // before plcs_ too
    std::unique_ptr<IocPlcs> plcs_;
    std::unique_ptr<IocKinematics> kinematics_;
    std::unique_ptr<IocPvt> pvt_; // profile moves of the axes with epics.motorRecord.pvt
    std::vector<std::unique_ptr<module::Module>> modules_; // the module table's, in its order
    std::unique_ptr<IocAreaDetector> area_;   // simulated cameras (detectors.area_detector)
    std::unique_ptr<automation::SmartControl> smart_; // the goniometer protocol (smart_control:)
    std::unique_ptr<automation::CompoundMotors> compound_; // virtual motors over motor records (compound_motors:)
    std::unique_ptr<automation::StateMachines> fsms_;      // state machines with an error latch (state_machines:)
    std::unique_ptr<automation::Notifier> notifier_;       // email and webhooks (notify:)
    std::unique_ptr<automation::CollisionZones> zones_;    // forbidden joint regions (collision_zones:)
    std::unique_ptr<automation::Plans> plans_;             // scans, alignments, sequences (plans:)
    std::unique_ptr<IocFlyScan> flyscan_; // position compare and capture (pcomp:, capture:)
    bool brought_up_ = false;
    std::unique_ptr<pv::Autosave> autosave_; // ioc.yaml autosave:
    std::string shell_socket_;
};

// PV name suffix of a process-data entry, as ecmccfg names them: binaryInput01 -> BI01,
// binaryOutput01 -> BO01, analogInput01 -> AI01, analogOutput01 -> AO01; others keep their name.
std::string entry_pv_suffix(const std::string& entry);

} // namespace beamctl::ioc
