#include "ioc/bus_pvs.hpp"

#include "core/error.hpp"
#include "ioc/pv_util.hpp"

#include <cmath>

namespace beamctl::ioc {

// $(P) = "<prefix>m<m>", $(BUS) = "ec<m>.", $(NB) = the histogram's buckets
const module::PvTable& bus_table() {
    static const module::PvTable t{"bus", {
        {"-Stat-OK", "bi", "$(BUS)ok", {{"DESC", "Bus OK: all slaves OP, data valid"}, {"ZNAM", "NOT_OK"}, {"ONAM", "OK"}, {"ZSV", "MAJOR"}}},
        {"-LinkUp", "bi", "$(BUS)linkup", {{"DESC", "Cyclic frames come back"}, {"ZNAM", "DOWN"}, {"ONAM", "UP"}, {"ZSV", "MAJOR"}}},
        {"-SlvCntr", "longin", "$(BUS)slavecounter", {{"DESC", "Slaves configured on the bus"}}},
        {"-SlvRsp", "longin", "$(BUS)slavesresponding", {{"DESC", "Slaves answering on the bus"}}},
        {"-SlvOP", "longin", "$(BUS)slavesop", {{"DESC", "Configured slaves in OP, data valid"}}},
        {"-Dom-WC", "longin", "$(BUS)dom0.wc", {{"DESC", "Working counter of the last cycle"}}},
        {"-Dom-WC-Exp", "longin", "$(BUS)dom0.wcexpected", {{"DESC", "Expected working counter"}}},
        {"-Dom-WC-Complete", "bi", "$(BUS)dom0.wccomplete", {{"DESC", "Working counter complete"}, {"ZNAM", "INCOMPLETE"}, {"ONAM", "COMPLETE"}, {"ZSV", "MAJOR"}}},
        {"-MissedFrames", "longin", "$(BUS)framesmissed", {{"DESC", "Cyclic frames that did not come back"}}},
        {"-LateFrames", "longin", "$(BUS)frameslate", {{"DESC", "Cyclic frames back after the time-out"}}},
        {"-WkcErrors", "longin", "$(BUS)wkcerrors", {{"DESC", "Cycles with a wrong working counter"}}},
        // the statistics of the cycle the bus runs in (the IOC's, or its own: buses[].rate_hz), as
        // ecmccfg's thread PVs
        {"-ThdLatMax", "ai", "$(BUS)thread.latency.max", {{"DESC", "RT wake-up latency max"}, {"EGU", "us"}, {"PREC", "1"}}},
        {"-ThdExeMax", "ai", "$(BUS)thread.execute.max", {{"DESC", "RT cycle execution time max"}, {"EGU", "us"}, {"PREC", "1"}}},
        {"-ThdLatMean", "ai", "$(BUS)thread.latency.mean", {{"DESC", "RT wake-up latency mean"}, {"EGU", "us"}, {"PREC", "1"}}},
        {"-ThdLatHist", "waveform", "", {{"DESC", "RT wake-up latency: cycles per bucket"}, {"FTVL", "LONG"}, {"NELM", "$(NB)"}}},
        {"-ThdLatHistEdges", "waveform", "", {{"DESC", "Lower edges of the ThdLatHist buckets"}, {"FTVL", "DOUBLE"}, {"NELM", "$(NB)"}, {"EGU", "us"}}},
        {"-ThdCycles", "longin", "$(BUS)thread.cycles", {{"DESC", "RT cycles measured since the reset"}}},
        {"-ThdMissedCycles", "longin", "$(BUS)thread.missed", {{"DESC", "RT cycle slots missed since the reset"}}},
        {"-ThdStat-Reset", "bo", "$(BUS)thread.reset", {{"DESC", "Clear RT max times, counters, histogram"}, {"ZNAM", "Done"}, {"ONAM", "Reset"}}, true},
    }};
    return t;
}

// A bus run by a scanner (link type scanner): the attachment, as seed 002's master port reports it.
const module::PvTable& scanner_table() {
    static const module::PvTable t{"scanner link", {
        {"-ScnConn", "bi", "$(BUS)scanner.attached", {{"DESC", "Attached to the bus scanner"}, {"ZNAM", "DETACHED"}, {"ONAM", "ATTACHED"}, {"ZSV", "MAJOR"}}},
        {"-ScnCycle", "ai", "$(BUS)scanner.cycle", {{"DESC", "Last scanner cycle seen"}, {"PREC", "0"}}},
        {"-ScnMissed", "longin", "$(BUS)scanner.missed", {{"DESC", "Scanner cycles this IOC never saw"}}},
        {"-ScnDrops", "longin", "$(BUS)scanner.drops", {{"DESC", "Cycles its queue lost (IOC too slow)"}}},
        {"-ScnAttaches", "longin", "$(BUS)scanner.attaches", {{"DESC", "Times attached (1 + reattaches)"}}},
    }};
    return t;
}

const module::PvTable& slave_table() {
    static const module::PvTable t{"bus slave", {
        {"-Online", "bi", "slavestatus.0", {{"DESC", "Slave answers"}, {"ZNAM", "OFFLINE"}, {"ONAM", "ONLINE"}, {"ZSV", "MAJOR"}}},
        {"-Operational", "bi", "slavestatus.1", {{"DESC", "Slave in OP"}, {"ZNAM", "NOT_OP"}, {"ONAM", "OP"}, {"ZSV", "MAJOR"}}},
        {"-HWType", "stringin", "", {{"VAL", "$(TYPE)"}, {"DESC", "$(NAME)"}}},
        {"-Valid", "bi", "slavestatus.6", {{"DESC", "Data valid: in the cycle, in OP"}, {"ZNAM", "INVALID"}, {"ONAM", "VALID"}, {"ZSV", "MAJOR"}}},
        {"-State", "mbbi", "state", {{"DESC", "Slave state (master's view)"}, {"ZRST", "OP"}, {"ONST", "MISSING"}, {"TWST", "WRONG_ID"},
                                   {"THST", "ERROR"}, {"FRST", "LOST"}, {"FVST", "CONFIGURING"},
                                   {"ONSV", "MAJOR"}, {"TWSV", "MAJOR"}, {"THSV", "MAJOR"}, {"FRSV", "MAJOR"}, {"FVSV", "MINOR"}}},
        {"-LostCntr", "longin", "lostcounter", {{"DESC", "Times lost or out of OP"}}},
        {"-ReconfCntr", "longin", "reconfigcounter", {{"DESC", "Times configured after the start"}}},
        {"-ErrId", "longin", "errorid", {{"DESC", "ECMC error id (0: none)"}}},
        {"-ErrMsg", "stringin", "", {{"DESC", "Last error (full text: ethercat command)"}}}, // text: set by the IOC
    }};
    return t;
}

namespace {

enum class Item { Ok, LinkUp, SlaveCounter, SlavesResponding, SlavesOp, Wc, WcExpected, WcComplete, FramesMissed,
                  FramesLate, WkcErrors, SlaveStatus, SlaveState, SlaveLost, SlaveReconf, SlaveErrorId, LatMax, ExeMax,
                  LatMean, Cycles, Missed, Reset, ScnConn, ScnCycle, ScnMissed, ScnDrops, ScnAttaches };
struct ItemName {
    const char* name; // after "ec<m>." (bus), "ec<m>.s<k>." (slave) or "ecmc.thread." and "ec<m>.thread." (engine)
    Item item;
};
constexpr ItemName kBus[] = {{"ok", Item::Ok}, {"linkup", Item::LinkUp}, {"slavecounter", Item::SlaveCounter},
                             {"slavesresponding", Item::SlavesResponding}, {"slavesop", Item::SlavesOp},
                             {"dom0.wc", Item::Wc}, {"dom0.wcexpected", Item::WcExpected},
                             {"dom0.wccomplete", Item::WcComplete}, {"framesmissed", Item::FramesMissed},
                             {"frameslate", Item::FramesLate}, {"wkcerrors", Item::WkcErrors},
                             {"scanner.attached", Item::ScnConn}, {"scanner.cycle", Item::ScnCycle},
                             {"scanner.missed", Item::ScnMissed}, {"scanner.drops", Item::ScnDrops},
                             {"scanner.attaches", Item::ScnAttaches}};
constexpr ItemName kSlave[] = {{"slavestatus", Item::SlaveStatus}, {"state", Item::SlaveState},
                               {"lostcounter", Item::SlaveLost}, {"reconfigcounter", Item::SlaveReconf},
                               {"errorid", Item::SlaveErrorId}};
constexpr ItemName kEngine[] = {{"latency.max", Item::LatMax}, {"execute.max", Item::ExeMax},
                                {"latency.mean", Item::LatMean}, {"cycles", Item::Cycles},
                                {"missed", Item::Missed}, {"reset", Item::Reset}};

void declare(registry::Registry& r, std::string name, registry::OwnerKind kind, std::string owner, bool writable) {
    registry::Signal s;
    s.name = std::move(name);
    s.type = "LREAL";
    s.direction = writable ? registry::Direction::Variable : registry::Direction::Input;
    s.owner_kind = kind;
    s.owner = std::move(owner);
    s.loop_only = true;
    r.declare(std::move(s));
}

class BusItemDevice : public pv::LinkDevice {
public:
    BusItemDevice(Item item, ethercat::Bus* bus, int slave, int bit, rt::Engine& engine, const rt::EngineStats& stats,
                  std::string name)
        : item_(item), bus_(bus), slave_(slave), bit_(bit), engine_(engine), stats_(stats), name_(std::move(name)) {}
    bool read(double& v) override {
        v = value();
        last_ = v;
        return true;
    }
    bool write(double v) override {
        if (item_ != Item::Reset) return false;
        if (v != 0) {
            engine_.request_reset(); // the RT thread clears its statistics in its next cycle
            asked_ = true;
        }
        return true;
    }
    bool changed() override {
        double v = value();
        bool c = !(v == last_);
        // a reset asked and done between two looks: pending read 0 both times
        if (item_ == Item::Reset && asked_ && v == 0) c = true, asked_ = false;
        last_ = v;
        return c;
    }
    std::string describe() const override { return name_; }

private:
    double value() const {
        const rt::EngineStats& es = stats_;
        switch (item_) {
        case Item::LatMax: return double(es.latency_max_ns) / 1000.0;
        case Item::ExeMax: return double(es.exec_max_ns) / 1000.0;
        case Item::LatMean: return es.latency_mean_ns() / 1000.0;
        case Item::Cycles: return clamp_long(es.latency_samples);
        case Item::Missed: return clamp_long(es.missed);
        case Item::Reset: return es.resets < engine_.resets_requested() ? 1 : 0;
        default: break;
        }
        const ethercat::BusSnapshot& s = bus_->looked();
        switch (item_) {
        case Item::Ok: {
            bool ok = s.link_up && s.wkc_ok;
            for (uint8_t v : s.slave_valid) ok = ok && v;
            return ok;
        }
        case Item::LinkUp: return s.link_up;
        case Item::SlaveCounter: return double(bus_->slaves().size());
        case Item::SlavesResponding: return s.link_up ? std::max(s.responding, 0) : 0;
        case Item::SlavesOp: {
            int n = 0;
            for (uint8_t v : s.slave_valid) n += v;
            return n;
        }
        case Item::SlaveState: return double(int(bus_->slave_health(std::size_t(slave_)).state));
        case Item::SlaveLost: return bus_->slave_health(std::size_t(slave_)).lost;
        case Item::SlaveReconf: return bus_->slave_health(std::size_t(slave_)).reconfigured;
        case Item::SlaveErrorId: return bus_->slave_health(std::size_t(slave_)).error_id;
        case Item::Wc: return s.wkc;
        case Item::WcExpected: return s.expected_wkc;
        case Item::WcComplete: return s.wkc_ok;
        case Item::FramesMissed: return clamp_long(s.frames_lost);
        case Item::FramesLate: return clamp_long(s.frames_late);
        case Item::WkcErrors: return clamp_long(s.wkc_errors);
        case Item::ScnConn: return s.scanner_attached;
        case Item::ScnCycle: return double(s.scanner_cycle); // ai: a cycle count outgrows a LONG in 25 days at 1 kHz
        case Item::ScnMissed: return clamp_long(s.scanner_missed);
        case Item::ScnDrops: return clamp_long(s.scanner_drops);
        case Item::ScnAttaches: return clamp_long(s.scanner_attaches);
        case Item::SlaveStatus: {
            std::size_t i = std::size_t(slave_);
            if (i >= s.slave_al.size() || i >= s.slave_online.size()) return 0;
            bool online = s.slave_online[i];
            uint32_t w = online ? 1u : 0u;
            uint8_t al = s.slave_al[i] & 0x0F;
            if (online && al == 8) w |= 2u;
            if (online) w |= (al == 1 ? 1u << 2 : al == 2 ? 1u << 3 : al == 4 ? 1u << 4 : al == 8 ? 1u << 5 : 0u);
            if (i < s.slave_valid.size() && s.slave_valid[i]) w |= 1u << 6;
            return bit_ >= 0 ? double(w >> bit_ & 1u) : double(w);
        }
        default: return 0;
        }
    }
    Item item_;
    ethercat::Bus* bus_;
    int slave_, bit_;
    rt::Engine& engine_;
    const rt::EngineStats& stats_;
    std::string name_;
    double last_ = NAN;
    bool asked_ = false;
};

} // namespace

void declare_bus_items(registry::Registry& r, int id, const std::vector<int>& slave_positions) {
    std::string bus = SB() << "ec" << id;
    for (const ItemName& n : kBus) declare(r, bus + "." + n.name, registry::OwnerKind::Bus, bus, false);
    for (const ItemName& n : kEngine) // ec0.thread.latency.max: the statistics of the bus's cycle
        declare(r, bus + ".thread." + n.name, registry::OwnerKind::Bus, bus, n.item == Item::Reset);
    for (int p : slave_positions)
        for (const ItemName& n : kSlave) declare(r, SB() << bus << ".s" << p << "." << n.name, registry::OwnerKind::Bus, bus, false);
}

void declare_engine_items(registry::Registry& r) {
    for (const ItemName& n : kEngine)
        declare(r, std::string("ecmc.thread.") + n.name, registry::OwnerKind::Engine, "engine", n.item == Item::Reset);
}

std::unique_ptr<pv::LinkDevice> make_bus_item_device(const std::string& name, int bit, bool output, ethercat::Bus* bus,
                                                     const std::vector<int>& slave_positions, rt::Engine& engine,
                                                     const rt::EngineStats& stats, std::string& why) {
    std::string full = bit >= 0 ? std::string(SB() << name << "." << bit) : name;
    auto make = [&](Item it, int slave) -> std::unique_ptr<pv::LinkDevice> {
        if (output && it != Item::Reset) {
            why = SB() << "'" << name << "' is a status of the IOC; an output link cannot write it";
            return nullptr;
        }
        if (bit >= 0 && it != Item::SlaveStatus) {
            why = SB() << "'" << name << "' is a number; it has no bit " << bit;
            return nullptr;
        }
        return std::make_unique<BusItemDevice>(it, bus, slave, bit, engine, stats, full);
    };
    const std::string thread = "ecmc.thread.";
    if (name.rfind(thread, 0) == 0) {
        for (const ItemName& n : kEngine)
            if (name.compare(thread.size(), std::string::npos, n.name) == 0) return make(n.item, -1);
    } else if (bus) {
        std::string pre = SB() << "ec" << bus->id() << ".";
        std::string rest = name.substr(std::min(name.size(), pre.size()));
        for (const ItemName& n : kBus)
            if (rest == n.name) return make(n.item, -1);
        for (const ItemName& n : kEngine)
            if (rest == std::string("thread.") + n.name) return make(n.item, -1);
        for (std::size_t i = 0; i < slave_positions.size(); ++i)
            for (const ItemName& n : kSlave)
                if (rest == std::string(SB() << "s" << slave_positions[i] << "." << n.name)) return make(n.item, int(i));
    }
    why = SB() << "no IOC-loop item '" << name << "'";
    return nullptr;
}

} // namespace beamctl::ioc
