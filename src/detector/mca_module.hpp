// The MCA module (docs/detectors.md): the simulated energy-dispersive detectors of
// `detectors.mca`, each element behind synApps' mca record $(P)<name> (DTYP asynMCA, INP
// "@<name>") with the PVs of mca's mca.db around it: $(P)<name>Start, Stop, Erase, EraseStart
// (acquisition commands), Read (reads the spectrum every second while acquiring) and Status (every
// 0.1 s while acquiring); its pulse processor's parameters and statistics under $(P)dxp<n>: with
// dxp's names (dxpHighLevel.template: outputs with OUT "@<name>.<Param>", read-backs and
// statistics SCAN I/O Intr). A detector with several elements also has the sum of their spectra
// ($(P)<stem>Sum, an mca record whose commands and presets go to every element) and dxpMED's PVs
// ($(P)StartAll, EraseStart, StopAll, PresetMode, PresetReal, Acquiring, ElapsedReal, AcquireBusy,
// ...), made of links and fan-outs over the elements' records. The detectors acquire on the IOC
// loop's clock.
// Threading: the IOC loop (records and the simulated detectors alike).
#pragma once

#include "config/ioc_config.hpp"
#include "detector/mca_sum.hpp"
#include "detector/sim_mca.hpp"
#include "ethercat/sim/beam.hpp"
#include "module/module.hpp"
#include "pv/database.hpp"

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::detector {

class McaModule : public module::Module {
public:
    // Makes the records (loaded into `ctx.db`) and the simulated detectors on the IOC loop's clock.
    McaModule(std::vector<config::McaEntry> section, module::BuildContext& ctx);
    ~McaModule() override;
    std::string_view name() const override { return "detectors.mca"; }
    // Whether a hardware address is one of the detectors' ("<element>" or "<element>.<Param>").
    bool owns(std::string_view address) const;
    // Device support of an mca record's INP "@<name>" or a DXP record's "@<name>.<Param>"; nullptr
    // with `why` if no detector has it.
    std::unique_ptr<pv::LinkDevice> make_device(std::string_view address, std::string& why);
    // The contract's: an mca record, or a record at one of the detectors' addresses.
    bool owns_device(std::string_view record_type, std::string_view address) const override {
        return record_type == "mca" || owns(address);
    }
    std::unique_ptr<pv::LinkDevice> make_device(const module::DeviceRequest& rq, std::string& why) override {
        return make_device(rq.address, why);
    }
    // The beam each detector's sample sees: `beam_of(bus)` (bus -1: the first with one), or nullptr
    // (the configured rates as they are). The rates follow the beam's transmission through the
    // slit. Throws Error naming the entry whose bus has no beam.
    void bind(module::BindContext& ctx) override;
    // The IOC loop, every 10 ms after init_records: an mca record whose detector acquires without
    // the record knowing (started through the sum or another element) is processed, so that it
    // follows the acquisition (reads its status and, at the end, the spectrum).
    void publish(double now_s) override;
    std::size_t mcas() const { return elements_.size(); }
    SimMca& mca(std::size_t i) { return *elements_.at(i).sim; }

private:
    class McaRef;
    class DxpOut;
    class DxpIn;
    // An mca record poll() keeps in step with its device.
    struct Watch {
        pv::Record* record = nullptr; // found once
        pv::Address acqg, read;
        uint64_t starts = 0;          // the device's starts the record has seen
    };
    struct Element {
        std::string name;                      // the mca record after $(P)
        std::unique_ptr<SimMca> sim;
        std::size_t entry = 0;                 // in entries_
        Watch watch;
    };
    struct Sum {
        std::string name;
        std::unique_ptr<McaSum> dev;
        std::vector<std::size_t> elements;
        Watch watch;
    };
    void add_records(const config::McaEntry& e, const std::string& prefix, pv::DbFile& f);
    void add_med_records(const config::McaEntry& e, const std::string& prefix, pv::DbFile& f);
    void follow(Watch& w, const std::string& name, uint64_t starts, bool acquiring);

    pv::Database& db_;
    std::string prefix_;
    std::vector<config::McaEntry> entries_;
    std::vector<Element> elements_;
    std::vector<Sum> sums_;
};

} // namespace beamctl::detector
