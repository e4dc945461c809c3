#include "detector/mca_module.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "module/pv_util.hpp"
#include "pv/db_file.hpp"

#include <cmath>
#include <cstdio>
#include <functional>
#include <map>

namespace beamctl::detector {
using module::get_value;
using module::record;
using module::set_value;
namespace {

log::Logger lg("detectors");

std::string num(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}


// The processor's parameters that shape the spectrum (dxpHighLevel.template's outputs): name,
// member, units, precision, DRVL, DRVH.
struct DxpParam {
    const char* name;
    double DxpSettings::*field;
    const char* egu;
    int prec;
    double lo, hi;
};
constexpr DxpParam kDxpParams[] = {
    {"PeakingTime", &DxpSettings::peaking_time, "us", 3, 0.01, 100},
    {"GapTime", &DxpSettings::gap_time, "us", 2, 0, 100},
    {"TriggerThreshold", &DxpSettings::trigger_threshold, "keV", 3, 0, 1000},
    {"EnergyThreshold", &DxpSettings::energy_threshold, "keV", 3, 0, 1000},
    {"PreampGain", &DxpSettings::preamp_gain, "mV/keV", 4, 1e-6, 1e4},
    {"MaxEnergy", &DxpSettings::max_energy, "keV", 3, -1e4, 1e4},
    {"ADCPercentRule", &DxpSettings::adc_percent_rule, "%", 1, 1e-6, 100},
};

// Parameters of a real processor the simulation has no model for (baseline, pile-up inspection,
// trigger filter): held, and read back (name, units, precision, value at start).
struct HeldParam {
    const char* name;
    const char* egu;
    int prec;
    double value;
};
constexpr HeldParam kHeldParams[] = {
    {"BaselineThreshold", "keV", 3, 1.0}, {"BaselineCutPercent", "%", 3, 10.0}, {"MaxWidth", "us", 2, 1.0},
    {"TriggerPeakingTime", "us", 2, 0.1}, {"TriggerGapTime", "us", 2, 0.0},
};

const std::vector<std::pair<std::string, std::string>> kPresetModes = {
    {"ZRST", "No preset"}, {"ZRVL", "0"}, {"ONST", "Real time"}, {"ONVL", "1"}, {"TWST", "Live time"},
    {"TWVL", "2"},         {"THST", "Events"}, {"THVL", "3"}, {"FRST", "Triggers"}, {"FRVL", "4"}};

std::vector<std::pair<std::string, std::string>> with(std::vector<std::pair<std::string, std::string>> a,
                                                      const std::vector<std::pair<std::string, std::string>>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
}

} // namespace

// The record's handle on a detector (an element or the sum) the IOC owns.
class McaModule::McaRef : public McaDevice {
public:
    McaRef(McaDevice& d, std::string name) : d_(d), name_(std::move(name)) {}
    bool setup(const Setup& s) override { return d_.setup(s); }
    bool supports(McaMode m) const override { return d_.supports(m); }
    bool start() override { return d_.start(); }
    bool stop() override { return d_.stop(); }
    bool erase() override { return d_.erase(); }
    bool status(Status& s) override { return d_.status(s); }
    uint32_t read(int32_t* data, uint32_t n) override { return d_.read(data, n); }
    std::string describe() const override { return name_ + ": " + d_.describe(); }

private:
    McaDevice& d_;
    std::string name_;
};

// A DXP output ("@mca1.PeakingTime"): the value into the processor's settings; a value the
// processor refuses is logged and raises the record's LINK alarm (nothing changes).
class McaModule::DxpOut : public pv::LinkDevice {
public:
    using Apply = std::function<void(DxpSettings&, double)>;
    DxpOut(SimMca& sim, std::string address, Apply apply, std::function<void()> after)
        : sim_(sim), address_(std::move(address)), apply_(std::move(apply)), after_(std::move(after)) {}
    bool read(double&) override { return false; }
    bool write(double v) override {
        DxpSettings d = sim_.dxp();
        apply_(d, v);
        std::string why;
        if (!sim_.set_dxp(d, why)) {
            LOG_WARN(lg, address_ << ": " << why << "; refused");
            return false;
        }
        if (after_) after_();
        return true;
    }
    std::string describe() const override { return "DXP parameter " + address_; }

private:
    SimMca& sim_;
    std::string address_;
    Apply apply_;
    std::function<void()> after_;
};

// A DXP read-back or statistic ("@mca1.InputCountRate"), for SCAN I/O Intr.
class McaModule::DxpIn : public pv::LinkDevice {
public:
    DxpIn(std::string address, std::function<double()> value) : address_(std::move(address)), value_(std::move(value)) {}
    bool read(double& v) override {
        v = last_ = value_();
        return true;
    }
    bool write(double) override { return false; }
    bool changed() override { return !(value_() == last_); }
    std::string describe() const override { return "DXP read-back " + address_; }

private:
    std::string address_;
    std::function<double()> value_;
    double last_ = NAN;
};

McaModule::McaModule(std::vector<config::McaEntry> section, module::BuildContext& ctx)
    : db_(ctx.db), prefix_(ctx.prefix), entries_(std::move(section)) {
    const std::function<double()>& clock = ctx.loop_clock;
    pv::DbFile f;
    for (std::size_t k = 0; k < entries_.size(); ++k) {
        const config::McaEntry& e = entries_[k];
        Sum sum;
        for (int i = 0; i < e.elements; ++i) {
            SimMcaConfig c;
            c.channels = e.channels;
            c.calo = e.offset;
            c.cals = e.slope;
            c.background = e.background;
            c.dead_time = e.dead_time;
            c.noise_fwhm = e.noise_fwhm;
            c.dxp.peaking_time = e.dxp.peaking_time;
            c.dxp.gap_time = e.dxp.gap_time;
            c.dxp.trigger_threshold = e.dxp.trigger_threshold;
            c.dxp.energy_threshold = e.dxp.energy_threshold;
            c.dxp.preamp_gain = e.dxp.preamp_gain;
            c.dxp.max_energy = e.dxp.max_energy;
            c.dxp.adc_percent_rule = e.dxp.adc_percent_rule;
            c.dxp.calibration_energy = e.dxp.calibration_energy;
            c.true_preamp_gain = e.preamp_gains.empty() ? 0 : e.preamp_gains[std::size_t(i)];
            c.seed = 0x6D6361 + elements_.size();
            for (const auto& l : e.lines) c.lines.push_back({l.name, l.energy, l.rate, l.fwhm});
            sum.elements.push_back(elements_.size());
            elements_.push_back(Element{e.element_name(i), std::make_unique<SimMca>(c, clock), k, Watch{}});
        }
        add_records(e, ctx.prefix, f);
        if (e.elements > 1) {
            std::vector<McaDevice*> parts;
            for (std::size_t i : sum.elements) parts.push_back(elements_[i].sim.get());
            sum.name = e.sum_name();
            sum.dev = std::make_unique<McaSum>(parts, sum.name);
            sums_.push_back(std::move(sum));
            add_med_records(e, ctx.prefix, f);
        }
    }
    if (!f.records.empty()) db_.load(f);
}

McaModule::~McaModule() = default;

// mca.db's records for each element (and the sum), and each element's DXP records.
void McaModule::add_records(const config::McaEntry& e, const std::string& prefix, pv::DbFile& f) {
    std::vector<std::string> mcas;
    for (int i = 0; i < e.elements; ++i) mcas.push_back(e.element_name(i));
    if (e.elements > 1) mcas.push_back(e.sum_name());
    const SimMca& first = *elements_[elements_.size() - std::size_t(e.elements)].sim;
    for (const std::string& name : mcas) {
        const std::string m = prefix + name;
        const std::string n = std::to_string(e.channels);
        const bool is_sum = e.elements > 1 && name == e.sum_name();
        f.records.push_back(record("mca", m, {{"DTYP", "asynMCA"}, {"INP", "@" + name}, {"PINI", "YES"}, {"NMAX", n}, {"NUSE", n},
                                               {"PREC", "2"}, {"CALO", num(e.offset)}, {"CALS", num(first.cals())}, {"EGU", "keV"},
                                               {"HIHI", "70."}, {"HHSV", "MAJOR"}, {"HIGH", "40."}, {"HSV", "MINOR"}, {"HYST", "2."},
                                               {"DESC", is_sum ? "sum of the elements" : "simulated MCA"}}));
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
    // dxpHighLevel.template's records, for each element
    for (int i = 0; i < e.elements; ++i) {
        const std::string name = e.element_name(i), r = prefix + e.dxp_prefix(i);
        const SimMca& sim = *elements_[elements_.size() - std::size_t(e.elements) + std::size_t(i)].sim;
        auto rbv = [&](const std::string& type, const std::string& rec, std::vector<std::pair<std::string, std::string>> more) {
            f.records.push_back(record(type, r + rec, with({{"DTYP", type == "ai" ? "asynFloat64" : "asynInt32"}, {"SCAN", "I/O Intr"},
                                                            {"INP", "@" + name + "." + rec}},
                                                           more)));
        };
        for (const DxpParam& p : kDxpParams) {
            const std::vector<std::pair<std::string, std::string>> fmt = {{"EGU", p.egu}, {"PREC", std::to_string(p.prec)}};
            f.records.push_back(record("ao", r + p.name, with({{"DTYP", "asynFloat64"}, {"OUT", "@" + name + "." + p.name}, {"DRVL", num(p.lo)}, {"DRVH", num(p.hi)},
                                                               {"VAL", num(sim.dxp().*p.field)}},
                                                              fmt)));
            rbv("ai", std::string(p.name) + "_RBV", fmt);
        }
        f.records.push_back(record("mbbo", r + "PresetMode", with({{"DTYP", "asynInt32"}, {"OUT", "@" + name + ".PresetMode"}, {"VAL", "0"}}, kPresetModes)));
        rbv("mbbi", "PresetMode_RBV", kPresetModes);
        for (const char* p : {"PresetEvents", "PresetTriggers"}) {
            f.records.push_back(record("longout", r + p, {{"DTYP", "asynInt32"}, {"OUT", "@" + name + "." + p}, {"DRVL", "0"}, {"DRVH", "2147483647"}, {"VAL", "0"}}));
            rbv("longin", std::string(p) + "_RBV", {});
        }
        rbv("ai", "DynamicRange_RBV", {{"EGU", "keV"}, {"PREC", "3"}});
        rbv("ai", "MCABinWidth_RBV", {{"EGU", "eV/bin"}, {"PREC", "4"}});
        rbv("ai", "CalibrationEnergy_RBV", {{"EGU", "keV"}, {"PREC", "3"}});
        rbv("ai", "InputCountRate", {{"PREC", "1"}, {"EGU", "counts/s"}});
        rbv("ai", "OutputCountRate", {{"PREC", "1"}, {"EGU", "counts/s"}});
        for (const char* c : {"Triggers", "Events", "Overflows", "Underflows"}) rbv("longin", c, {});
        rbv("ai", "ElapsedRealTime", {{"PREC", "3"}, {"EGU", "s"}});
        rbv("ai", "ElapsedLiveTime", {{"PREC", "3"}, {"EGU", "s"}});
        rbv("ai", "ElapsedTriggerLiveTime", {{"PREC", "3"}, {"EGU", "s"}});
        for (const HeldParam& p : kHeldParams) {
            const std::vector<std::pair<std::string, std::string>> fmt = {{"EGU", p.egu}, {"PREC", std::to_string(p.prec)}};
            f.records.push_back(record("ao", r + p.name, with({{"VAL", num(p.value)}}, fmt)));
            f.records.push_back(record("ai", r + p.name + "_RBV", with({{"INP", r + p.name + " CP"}}, fmt)));
        }
        f.records.push_back(record("bo", r + "BaselineCutEnable", {{"ZNAM", "No"}, {"ONAM", "Yes"}, {"VAL", "1"}}));
        f.records.push_back(record("bi", r + "BaselineCutEnable_RBV", {{"ZNAM", "No"}, {"ONAM", "Yes"}, {"INP", r + "BaselineCutEnable CP"}}));
        f.records.push_back(record("longout", r + "BaselineFilterLength", {{"VAL", "128"}}));
        f.records.push_back(record("longin", r + "BaselineFilterLength_RBV", {{"INP", r + "BaselineFilterLength CP"}}));
    }
}

// dxpMED.template's PVs of a multi-element detector, over the elements' records: commands and
// presets fan out to every element and the sum; the state is the sum's.
void McaModule::add_med_records(const config::McaEntry& e, const std::string& p, pv::DbFile& f) {
    std::vector<std::string> mcas, dxps;
    for (int i = 0; i < e.elements; ++i) mcas.push_back(p + e.element_name(i)), dxps.push_back(p + e.dxp_prefix(i));
    mcas.push_back(p + e.sum_name());
    // a dfanout chain (15 outputs each, the 16th to the next) writing its value to `targets`
    auto fan = [&](const std::string& name, const std::vector<std::string>& targets, std::vector<std::pair<std::string, std::string>> more) {
        static const char* outs = "ABCDEFGHIJKLMNOP";
        for (std::size_t k = 0, part = 0; k < targets.size(); ++part) {
            const std::string rec = name + (part ? std::to_string(part + 1) : "");
            std::vector<std::pair<std::string, std::string>> fields = part ? std::vector<std::pair<std::string, std::string>>{} : more;
            for (int o = 0; o < 15 && k < targets.size(); ++o, ++k) fields.push_back({std::string("OUT") + outs[o], targets[k] + " PP MS"});
            if (k < targets.size()) fields.push_back({"OUTP", name + std::to_string(part + 2) + ".VAL PP MS"});
            f.records.push_back(record("dfanout", rec, fields));
        }
    };
    auto fields_of = [](const std::vector<std::string>& recs, const std::string& field) {
        std::vector<std::string> v;
        for (const std::string& r : recs) v.push_back(r + field);
        return v;
    };
    auto bo = [&](const std::string& name, const char* onam, std::vector<std::pair<std::string, std::string>> more) {
        f.records.push_back(record("bo", p + name, with({{"VAL", "1"}, {"ZNAM", "Done"}, {"ONAM", onam}}, more)));
    };
    bo("EraseAll", "Erase", {{"OUT", p + "EraseAllFan.VAL PP MS"}});
    bo("EraseStart", "Erase", {{"OUT", p + "EraseAllFan.VAL PP MS"}, {"FLNK", p + "StartAll"}});
    bo("StartAll", "Start", {{"OUT", p + "StartAllFan.VAL PP MS"}, {"FLNK", p + "SetAcquireBusy"}});
    bo("SetAcquireBusy", "Set", {{"OUT", p + "AcquireBusy PP MS"}});
    bo("StopAll", "Stop", {{"OUT", p + "StopAllFan.VAL PP MS"}});
    fan(p + "EraseAllFan", fields_of(mcas, ".ERAS"), {});
    fan(p + "StartAllFan", fields_of(mcas, ".STRT"), {});
    fan(p + "StopAllFan", fields_of(mcas, ".STOP"), {});
    f.records.push_back(record("busy", p + "AcquireBusy", {{"ZNAM", "Done"}, {"ONAM", "Busy"}}));
    // presets: PresetMode selects which of PresetReal / PresetLive the elements get (the other 0)
    f.records.push_back(record("mbbo", p + "PresetMode", with({{"DESC", "set preset type"}, {"FLNK", p + "PresetRealCalc"}}, kPresetModes)));
    f.records.push_back(record("ao", p + "PresetReal", {{"PREC", "2"}, {"EGU", "s"}, {"FLNK", p + "PresetRealCalc"}}));
    f.records.push_back(record("ao", p + "PresetLive", {{"PREC", "2"}, {"EGU", "s"}, {"FLNK", p + "PresetLiveCalc"}}));
    f.records.push_back(record("calcout", p + "PresetRealCalc", {{"INPA", p + "PresetMode NPP"}, {"INPB", p + "PresetReal NPP"}, {"CALC", "A=1?B:0"},
                                                                {"OUT", p + "PresetRealFan.VAL PP MS"}, {"FLNK", p + "PresetLiveCalc"}}));
    f.records.push_back(record("calcout", p + "PresetLiveCalc", {{"INPA", p + "PresetMode NPP"}, {"INPB", p + "PresetLive NPP"}, {"CALC", "A=2?B:0"},
                                                                {"OUT", p + "PresetLiveFan.VAL PP MS"}, {"FLNK", p + "PresetModeFan"}}));
    fan(p + "PresetRealFan", fields_of(mcas, ".PRTM"), {});
    fan(p + "PresetLiveFan", fields_of(mcas, ".PLTM"), {});
    fan(p + "PresetModeFan", fields_of(dxps, "PresetMode"), {{"OMSL", "closed_loop"}, {"DOL", p + "PresetMode NPP"}});
    f.records.push_back(record("longout", p + "PresetEvents", {{"DESC", "Preset events"}, {"OUT", p + "PresetEventsFan.VAL PP MS"}}));
    f.records.push_back(record("longout", p + "PresetTriggers", {{"DESC", "Preset triggers"}, {"OUT", p + "PresetTriggersFan.VAL PP MS"}}));
    fan(p + "PresetEventsFan", fields_of(dxps, "PresetEvents"), {});
    fan(p + "PresetTriggersFan", fields_of(dxps, "PresetTriggers"), {});
    // the state: the sum's
    const std::string s = p + e.sum_name();
    f.records.push_back(record("bi", p + "Acquiring", {{"INP", s + ".ACQG CP MS"}, {"ZNAM", "Done"}, {"ONAM", "Acquiring"}, {"FLNK", p + "ClearAcquireBusy"}}));
    f.records.push_back(record("calcout", p + "ClearAcquireBusy",
                               {{"INPA", p + "Acquiring NPP"}, {"CALC", "A"}, {"OOPT", "Transition To Zero"}, {"OUT", p + "AcquireBusy PP"}}));
    f.records.push_back(record("ai", p + "ElapsedReal", {{"INP", s + ".ERTM CP MS"}, {"PREC", "2"}, {"EGU", "s"}}));
    f.records.push_back(record("ai", p + "ElapsedLive", {{"INP", s + ".ELTM CP MS"}, {"PREC", "2"}, {"EGU", "s"}}));
    f.records.push_back(record("ai", p + "DeadTime", {{"INP", s + ".DTIM CP MS"}, {"PREC", "2"}, {"EGU", "%"}}));
    f.records.push_back(record("ai", p + "IDeadTime", {{"INP", s + ".IDTIM CP MS"}, {"PREC", "2"}, {"EGU", "%"}}));
}

void McaModule::bind(module::BindContext& ctx) {
    const auto& beam_of = ctx.beam_of;
    for (Element& el : elements_) {
        const config::McaEntry& e = entries_[el.entry];
        auto beam = beam_of ? beam_of(e.bus) : std::function<ethercat::sim::BeamTally()>{};
        if (!beam && e.bus >= 0)
            throw Error(SB() << e.where << ": mca " << e.name << ": bus " << e.bus
                             << " has no simulated beam in this IOC (a sim link whose plant has a beam: section)");
        if (beam) el.sim->set_intensity([beam] { return beam().transmission; });
    }
}

bool McaModule::owns(std::string_view address) const {
    const std::string_view head = address.substr(0, address.find('.'));
    for (const Element& el : elements_)
        if (el.name == head) return true;
    for (const Sum& s : sums_)
        if (s.name == head) return true;
    return false;
}

std::unique_ptr<pv::LinkDevice> McaModule::make_device(std::string_view address, std::string& why) {
    const std::size_t dot = address.find('.');
    const std::string head(address.substr(0, dot)), param(dot == std::string_view::npos ? "" : address.substr(dot + 1));
    for (Sum& s : sums_)
        if (s.name == head && param.empty()) return std::make_unique<McaRef>(*s.dev, s.name);
    for (std::size_t i = 0; i < elements_.size(); ++i) {
        Element& el = elements_[i];
        if (el.name != head) continue;
        SimMca& sim = *el.sim;
        if (param.empty()) return std::make_unique<McaRef>(sim, el.name);
        const std::string a(address);
        for (const DxpParam& p : kDxpParams) {
            if (param == p.name) {
                std::function<void()> after;
                if (param == "MaxEnergy") // the spectrum's calibration follows: CALS of the element (and the first's, of the sum)
                    after = [this, i] {
                        const Element& e2 = elements_[i];
                        std::vector<std::string> recs{prefix_ + e2.name + ".CALS"};
                        for (const Sum& s : sums_)
                            if (!s.elements.empty() && s.elements.front() == i) recs.push_back(prefix_ + s.name + ".CALS");
                        const double cals = e2.sim->cals();
                        for (const std::string& r : recs) {
                            pv::Address ad;
                            if (db_.resolve(r, ad)) db_.store_value(ad, pv::Prim::Double, &cals, 1);
                        }
                    };
                const auto field = p.field;
                return std::make_unique<DxpOut>(sim, a, [field](DxpSettings& d, double v) { d.*field = v; }, after);
            }
            if (param == std::string(p.name) + "_RBV") {
                const auto field = p.field;
                return std::make_unique<DxpIn>(a, [&sim, field] { return sim.dxp().*field; });
            }
        }
        if (param == "PresetMode")
            return std::make_unique<DxpOut>(sim, a, [](DxpSettings& d, double v) { d.preset_mode = DxpPresetMode(int(v)); }, nullptr);
        if (param == "PresetEvents")
            return std::make_unique<DxpOut>(sim, a, [](DxpSettings& d, double v) { d.preset_events = int64_t(v); }, nullptr);
        if (param == "PresetTriggers")
            return std::make_unique<DxpOut>(sim, a, [](DxpSettings& d, double v) { d.preset_triggers = int64_t(v); }, nullptr);
        const std::map<std::string, std::function<double()>> ins = {
            {"PresetMode_RBV", [&sim] { return double(sim.dxp().preset_mode); }},
            {"PresetEvents_RBV", [&sim] { return double(sim.dxp().preset_events); }},
            {"PresetTriggers_RBV", [&sim] { return double(sim.dxp().preset_triggers); }},
            {"DynamicRange_RBV", [&sim] { return sim.dynamic_range(); }},
            {"MCABinWidth_RBV", [&sim] { return 1000.0 * sim.cals(); }},
            {"CalibrationEnergy_RBV", [&sim] { return sim.dxp().calibration_energy; }},
            {"InputCountRate", [&sim] { return sim.counters().input_rate; }},
            {"OutputCountRate", [&sim] { return sim.counters().output_rate; }},
            {"Triggers", [&sim] { return double(sim.counters().triggers); }},
            {"Events", [&sim] { return double(sim.counters().events); }},
            {"Overflows", [&sim] { return double(sim.counters().overflows); }},
            {"Underflows", [&sim] { return double(sim.counters().underflows); }},
            {"ElapsedRealTime", [&sim] { return sim.counters().real; }},
            {"ElapsedLiveTime", [&sim] { return sim.counters().live; }},
            {"ElapsedTriggerLiveTime", [&sim] { return sim.counters().live; }},
        };
        if (auto it = ins.find(param); it != ins.end()) return std::make_unique<DxpIn>(a, it->second);
        why = SB() << "'" << address << "': " << el.name << " has no DXP parameter '" << param << "' (PeakingTime, GapTime, TriggerThreshold, "
                   << "EnergyThreshold, PreampGain, MaxEnergy, ADCPercentRule, PresetMode, PresetEvents, PresetTriggers, their _RBV, "
                   << "InputCountRate, OutputCountRate, Triggers, Events, Overflows, Underflows, ElapsedRealTime, ...)";
        return nullptr;
    }
    std::string have;
    for (const Element& el : elements_) have += (have.empty() ? "" : ", ") + el.name;
    for (const Sum& s : sums_) have += ", " + s.name;
    why = SB() << "no MCA '" << head << "' in this IOC (detectors.mca in the IOC file" << (have.empty() ? std::string(")") : "; it has " + have + ")");
    return nullptr;
}

// An acquisition the record did not start (the sum's, StartAll's, another element's): while it
// runs, the record is processed so that it shows it (ACQG, its Status and Read scans, the spectrum
// at the end); one already over is read.
void McaModule::follow(Watch& w, const std::string& name, uint64_t starts, bool acquiring) {
    if (starts == w.starts) return;
    if (!w.record) {
        w.record = db_.find(prefix_ + name);
        if (!w.record || !db_.resolve(prefix_ + name + ".ACQG", w.acqg) || !db_.resolve(prefix_ + name + ".READ", w.read)) {
            w.record = nullptr;
            return;
        }
    }
    double acqg = 0;
    db_.get(w.acqg, pv::Prim::Double, &acqg, 1);
    if (acqg != 0) { // the record knows
        w.starts = starts;
        return;
    }
    w.starts = starts;
    if (acquiring) {
        db_.scan_once(*w.record);
    } else {
        const double one = 1;
        db_.put(w.read, pv::Prim::Double, &one, 1);
    }
}

void McaModule::publish(double) {
    for (Element& el : elements_) follow(el.watch, el.name, el.sim->starts(), el.sim->acquiring());
    for (Sum& s : sums_) {
        uint64_t starts = 0;
        bool any = false;
        for (std::size_t i : s.elements) starts += elements_[i].sim->starts(), any = any || elements_[i].sim->acquiring();
        follow(s.watch, s.name, starts, any);
    }
}

} // namespace beamctl::detector
