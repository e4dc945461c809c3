#include "ioc/detectors.hpp"

#include "core/error.hpp"
#include "ioc/pv_util.hpp"
#include "pv/db_file.hpp"

#include <cstdio>

namespace beamctl::ioc {
namespace {

std::string num(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

} // namespace

// The record's handle on a detector the IOC owns.
class IocDetectors::McaRef : public detector::McaDevice {
public:
    McaRef(detector::SimMca& d, std::string name) : d_(d), name_(std::move(name)) {}
    bool setup(const Setup& s) override { return d_.setup(s); }
    bool start() override { return d_.start(); }
    bool stop() override { return d_.stop(); }
    bool erase() override { return d_.erase(); }
    bool status(Status& s) override { return d_.status(s); }
    uint32_t read(int32_t* data, uint32_t n) override { return d_.read(data, n); }
    std::string describe() const override { return name_ + ": " + d_.describe(); }

private:
    detector::SimMca& d_;
    std::string name_;
};

IocDetectors::IocDetectors(const config::IocConfig& cfg, pv::Database& db, std::function<double()> clock) {
    pv::DbFile f;
    for (const config::McaEntry& e : cfg.mca) {
        detector::SimMcaConfig c;
        c.channels = e.channels;
        c.calo = e.offset;
        c.cals = e.slope;
        c.background = e.background;
        c.dead_time = e.dead_time;
        c.seed = 0x6D6361 + mcas_.size();
        for (const auto& l : e.lines) c.lines.push_back({l.name, l.energy, l.rate, l.fwhm});
        mcas_.push_back(std::make_unique<detector::SimMca>(c, clock));
        names_.push_back(e.name);
        entries_.push_back(e);
        const std::string m = cfg.prefix + e.name;
        const std::string n = std::to_string(e.channels);
        // mca's mca.db, with its names
        f.records.push_back(record("mca", m, {{"DTYP", "asynMCA"}, {"INP", "@" + e.name}, {"PINI", "YES"}, {"NMAX", n}, {"NUSE", n},
                                               {"PREC", "2"}, {"CALO", num(e.offset)}, {"CALS", num(e.slope)}, {"EGU", "keV"},
                                               {"HIHI", "70."}, {"HHSV", "MAJOR"}, {"HIGH", "40."}, {"HSV", "MINOR"}, {"HYST", "2."},
                                               {"DESC", "simulated MCA"}}));
        auto command = [&](const char* suffix, const char* field, const char* onam, const char* proc) {
            f.records.push_back(record("bo", m + suffix, {{"OMSL", "closed_loop"}, {"DOL", "1"}, {"OUT", m + "." + field + " " + proc},
                                                         {"ONAM", onam}, {"ZNAM", "Done"}}));
        };
        command("Erase", "ERAS", "Erase", "PP MS");
        command("EraseStart", "ERST", "EraseStart", "PP MS");
        command("Start", "STRT", "Start", "PP MS");
        command("Stop", "STOP", "Stop", "CA MS");
        f.records.push_back(record("bo", m + "Read", {{"SCAN", "1 second"}, {"DISV", "0"}, {"SDIS", m + ".ACQG NPP NMS"}, {"OMSL", "closed_loop"},
                                                      {"DOL", "1"}, {"OUT", m + ".READ CA NMS"}, {"ONAM", "Read"}, {"ZNAM", "Done"}}));
        f.records.push_back(record("bo", m + "Status", {{"SCAN", ".1 second"}, {"DISV", "0"}, {"SDIS", m + ".ACQG NPP NMS"},
                                                        {"OMSL", "closed_loop"}, {"DOL", "1"}, {"OUT", m + ".PROC CA NMS"}}));
    }
    if (!f.records.empty()) db.load(f);
}

IocDetectors::~IocDetectors() = default;

void IocDetectors::bind(const std::function<std::function<ethercat::sim::BeamTally()>(int bus)>& beam_of) {
    for (std::size_t i = 0; i < mcas_.size(); ++i) {
        const config::McaEntry& e = entries_[i];
        auto beam = beam_of ? beam_of(e.bus) : std::function<ethercat::sim::BeamTally()>{};
        if (!beam && e.bus >= 0)
            throw Error(SB() << e.where << ": mca " << e.name << ": bus " << e.bus
                             << " has no simulated beam in this IOC (a sim link whose plant has a beam: section)");
        if (beam) mcas_[i]->set_intensity([beam] { return beam().transmission; });
    }
}

std::unique_ptr<pv::LinkDevice> IocDetectors::make_device(std::string_view name, std::string& why) {
    for (std::size_t i = 0; i < mcas_.size(); ++i)
        if (names_[i] == name) return std::make_unique<McaRef>(*mcas_[i], names_[i]);
    std::string have;
    for (const std::string& n : names_) have += (have.empty() ? "" : ", ") + n;
    why = SB() << "no MCA '" << name << "' in this IOC (detectors.mca in the IOC file" << (have.empty() ? std::string(")") : "; it has " + have + ")");
    return nullptr;
}

} // namespace beamctl::ioc
