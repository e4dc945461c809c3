#include "ioc/ioc.hpp"

#include "pv/db_shell.hpp"
#include "plc/program.hpp"
#include "pv/ioc_stats.hpp"
#include "pv/shell_server.hpp"
#include "pv/substitutions.hpp"

#include "automation/line_server.hpp"

#include "ioc/bus_pvs.hpp"
#include "ioc/modules.hpp"
#include "ioc/pv_util.hpp"
#include "motion/axis_setup.hpp"

#include "bridge/rcp/bridge.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ioc/rcp_signals.hpp"
#include "core/signals.hpp"
#include "detector/mca_record.hpp"
#include "feedback/epid_record.hpp"
#include "ethercat/sim/faults.hpp"
#include "ethercat/sim/local_bus.hpp"
#include "scanner/client.hpp"
#include "pv/convert.hpp"
#include "pv/db_file.hpp"

#include <algorithm>
#include <cerrno>
#include <deque>
#include <cinttypes>
#include <csignal>
#include <cstdio>
#include <map>
#include <sys/epoll.h>
#include <unistd.h>

namespace beamctl::ioc {
namespace {
log::Logger lg("ioc");


// Device support "beamctl": a record's "@ec0.s3.positionActual01" (or "...Input01.2", a bit) link
// reads the entry from the bus snapshot of the IOC loop and writes an output through the bus's
// write queue, as the entry's own PV does. For SCAN "I/O Intr" the bus watches the entry in the
// cycle (`watch` >= 0): the record is processed after any cycle in which it changed, even if it
// changed back before the IOC loop looked. IOC loop thread only.
class EcLinkDevice : public pv::LinkDevice {
public:
    EcLinkDevice(ethercat::Bus& bus, const ethercat::SignalInfo& sig, int bit, int watch)
        : bus_(bus), sig_(sig), bit_(bit), watch_(watch) {
        const auto& sl = bus.slaves();
        for (std::size_t i = 0; i < sl.size() && sig.bit_offset / 8 < bus.bus_bytes(); ++i)
            if (sl[i].position == sig.slave) slave_ = int(i); // an entry exchanged on the bus
    }
    bool read(double& v) override {
        const ethercat::BusSnapshot& s = bus_.looked();
        alarm_ = s.scanner_bus && !s.scanner_attached ? pv::kStatComm : pv::kStatLink;
        if (!s.link_up || !s.wkc_ok) return false; // no fresh data: LINK/INVALID (COMM/INVALID: no scanner)
        if (!slave_ok(s)) { // its slave is missing, lost or not in OP: COMM/INVALID (as ECMC)
            alarm_ = pv::kStatComm;
            return false;
        }
        v = value(s);
        last_ = v;
        return true;
    }
    uint16_t read_alarm() const override { return alarm_; }
    bool write(double v) override {
        if (!sig_.output || !std::isfinite(v)) return false;
        if (bit_ >= 0) { // one bit of a wider output: the others as last sent
            const ethercat::BusSnapshot& s = bus_.looked();
            if (!in_image(s)) return false; // the bits beside it are not known yet
            uint64_t raw = ethercat::Bus::get(s.image, sig_);
            raw = v != 0 ? raw | (uint64_t(1) << bit_) : raw & ~(uint64_t(1) << bit_);
            return bus_.write(sig_, raw);
        }
        return bus_.write(sig_, registry::double_to_raw(v, sig_.entry()));
    }
    std::string describe() const override {
        return bit_ >= 0 ? std::string(SB() << sig_.name << "." << bit_) : sig_.name;
    }
    // Called when the record's link is replaced or the record removed (gives back the output).
    std::function<void()> on_release;
    void release() override {
        if (on_release) on_release();
        on_release = nullptr;
    }
    bool changed() override {
        const ethercat::BusSnapshot& s = bus_.looked();
        int ok = s.link_up && s.wkc_ok && slave_ok(s) ? 1 : 0;
        if (ok != last_ok_) { // the bus or the slave went down (LINK or COMM/INVALID) or came back;
            last_ok_ = ok;    // also at the first look, so a slave missing from the start shows it
            if (watch_ >= 0 && std::size_t(watch_) < s.changes.size()) seen_ = s.changes[std::size_t(watch_)];
            last_ = value(s);
            return true;
        }
        if (watch_ >= 0 && std::size_t(watch_) < s.changes.size()) {
            // the entry changed in some cycle since the last look (a bit record: only if its bit
            // differs now or the entry changed more than once, i.e. it may have pulsed)
            uint32_t n = s.changes[std::size_t(watch_)];
            uint32_t since = n - seen_;
            seen_ = n;
            if (since == 0) return false;
            if (bit_ < 0 || since > 1) return true;
        }
        double v = value(s);
        bool c = !(v == last_);
        last_ = v;
        return c;
    }

private:
    bool slave_ok(const ethercat::BusSnapshot& s) const {
        return slave_ < 0 || (std::size_t(slave_) < s.slave_valid.size() && s.slave_valid[std::size_t(slave_)]);
    }
    bool in_image(const ethercat::BusSnapshot& s) const { // false before the first cycle published
        return (std::size_t(sig_.bit_offset) + sig_.bits + 7) / 8 <= s.image.size();
    }
    double value(const ethercat::BusSnapshot& s) const {
        if (!in_image(s)) return NAN;
        uint64_t raw = ethercat::Bus::get(s.image, sig_);
        if (bit_ >= 0) return double(raw >> bit_ & 1);
        return registry::raw_to_double(raw, sig_.entry());
    }
    ethercat::Bus& bus_;
    const ethercat::SignalInfo& sig_;
    int bit_;
    int watch_;         // index of the bus's change watch, -1: compare values at each look
    uint32_t seen_ = 0; // the watch's change count at the last look
    double last_ = NAN;
    int last_ok_ = -1;     // the bus's data was valid at the last look (-1: no look yet)
    int slave_ = -1;       // index of the entry's slave (-1: the master's own memory)
    uint16_t alarm_ = pv::kStatLink;
};

// An entry PV whose entry the slave's PDO assignment does not have: reads and writes fail
// (LINK/INVALID), instead of keeping the IOC from starting.
class MissingEntryDevice : public pv::LinkDevice {
public:
    explicit MissingEntryDevice(std::string name) : name_(std::move(name)) {}
    bool read(double&) override { return false; }
    bool write(double) override { return false; }
    std::string describe() const override { return name_ + " (not in the slave's PDO assignment)"; }

private:
    std::string name_;
};

// ecmccfg's asyn addresses ("asyn(MC_CPU1,0,1)T_SMP_MS=10/TYPE=asynInt32/ec0.s3.positionActual01?",
// "asynMask(MC_CPU1,0,0x4,1)T_SMP_MS=10/TYPE=asynUInt32Digital/ec0.s1.binaryInput01?") as the
// signal name and bit they read or write. The port, address, timeout, sample time and type say how
// ECMC's asyn layer moves the value; here the record reads the bus snapshot, so they are accepted
// and not used. False with `why` when the text is not such an address or the mask is not one bit.
bool parse_asyn_address(std::string_view a, std::string& name, int& bit, std::string& why) {
    bool mask = a.rfind("asynMask(", 0) == 0;
    if (!mask && a.rfind("asyn(", 0) != 0) return false;
    std::size_t close = a.find(')');
    if (close == std::string_view::npos) {
        why = "no ')' after the asyn port";
        return false;
    }
    if (mask) { // asynMask(PORT,ADDR,MASK[,TIMEOUT])
        std::string args(a.substr(9, close - 9));
        std::vector<std::string> v;
        std::size_t at = 0;
        for (std::size_t c; (c = args.find(',', at)) != std::string::npos; at = c + 1) v.push_back(args.substr(at, c - at));
        v.push_back(args.substr(at));
        if (v.size() < 3) {
            why = "asynMask(PORT,ADDR,MASK[,TIMEOUT]) needs a MASK";
            return false;
        }
        char* end = nullptr;
        unsigned long long m = std::strtoull(v[2].c_str(), &end, 0);
        if (!end || *end || m == 0 || (m & (m - 1)) != 0) {
            why = SB() << "MASK '" << v[2] << "': only a mask of one bit is supported (a bit of the entry)";
            return false;
        }
        bit = 0;
        while (!(m >> bit & 1)) ++bit;
    }
    std::string_view info = a.substr(close + 1); // T_SMP_MS=10/TYPE=asynInt32/ec0.s3.entry?
    std::size_t slash = info.rfind('/');
    std::string_view n = slash == std::string_view::npos ? info : info.substr(slash + 1);
    while (!n.empty() && (n.back() == '?' || n.back() == '=' || n.back() == ' ')) n.remove_suffix(1);
    if (n.empty()) {
        why = "no signal name after the asyn port (T_SMP_MS=10/TYPE=asynInt32/ec0.s3.entry?)";
        return false;
    }
    name = std::string(n);
    return true;
}


// A driver parameter that is only kept (asyn_motor.db's MOTOR_REC_*): writes are taken, reads
// give the last one.
class KeptValueDevice : public pv::LinkDevice {
public:
    explicit KeptValueDevice(std::string name) : name_(std::move(name)) {}
    bool read(double& v) override {
        v = value_;
        return true;
    }
    bool write(double v) override {
        value_ = v;
        return true;
    }
    std::string describe() const override { return name_ + " (kept by the driver)"; }

private:
    std::string name_;
    double value_ = 0;
};

// Sets an array record's elements (and NORD) and processes it, if they differ from `v`.
void set_array_if_changed(pv::Database& db, pv::Record& r, const double* v, uint32_t n) {
    const pv::FieldDesc* f = r.type().find("VAL");
    pv::Elements e = r.elements(*f);
    n = std::min(n, e.capacity);
    bool same = !r.udf && e.count == n;
    for (uint32_t i = 0; same && i < n; ++i) {
        double cur = 0;
        pv::get_element(r, *f, e, i, pv::Prim::Double, &cur);
        same = cur == v[i];
    }
    if (!same) set_array(db, r, v, n);
}

} // namespace

std::string entry_pv_suffix(const std::string& e) {
    struct Map {
        const char* prefix;
        const char* pv;
    };
    static const Map maps[] = {{"binaryInput", "BI"}, {"binaryOutput", "BO"}, {"analogInput", "AI"},
                               {"analogOutput", "AO"}};
    for (auto& m : maps) {
        std::string p = m.prefix;
        if (e.size() > p.size() && e.compare(0, p.size(), p) == 0 &&
            e.find_first_not_of("0123456789", p.size()) == std::string::npos)
            return std::string(m.pv) + e.substr(p.size());
    }
    return e;
}

Ioc::Ioc(config::IocConfig cfg, rt::Clock& clock)
    : cfg_(std::move(cfg)), clock_(clock), catalog_(ethercat::Catalog::builtin()) {
    feedback::register_feedback_records(pv::RecordTypes::global()); // epid (its .db files, `feedback:`)
    detector::register_detector_records(pv::RecordTypes::global()); // mca
    rt::EngineConfig ec;
    ec.rate_hz = cfg_.rate_hz;
    ec.cpu = cfg_.cpu;
    ec.priority = cfg_.priority;
    engine_ = std::make_unique<rt::Engine>(ec, clock_);
    for (auto& bc : cfg_.buses) // a scanner link naming only link.slaves: the scanner says what they are
        if (bc.link.type == "scanner" && !bc.link.attach.empty()) {
            try {
                for (const auto& c : scanner::ClientBackend::resolve(bc.link.socket, bc.id, bc.link.attach, bc.link.resolve_timeout_s)) {
                    config::SlaveEntry se;
                    se.position = c.position;
                    se.type = c.type;
                    se.name = c.name;
                    se.oversampling = c.oversampling;
                    se.type_where = bc.link.attach_where;
                    bc.slaves.push_back(se);
                }
            } catch (const Error& e) {
                throw Error(SB() << bc.link.attach_where << ": " << e.what()
                                 << "; link.slaves are named by the scanner when the IOC starts: start the scanner first, or "
                                    "list the slaves with their types in the bus's slaves:");
            }
        }
    for (auto& bc : cfg_.buses) // the master keeps its slaves in position order; so do the PVs
        std::sort(bc.slaves.begin(), bc.slaves.end(),
                  [](const auto& a, const auto& b) { return a.position < b.position; });
    for (const auto& bc : cfg_.buses) {
        BusRt b;
        if (bc.link.type == "scanner") { // the bus is run by `beamctl scanner`; this IOC attaches to it
            scanner::ClientConfig cc;
            cc.socket = bc.link.socket;
            cc.bus = bc.id;
            cc.ioc = cfg_.name;
            for (const auto& s : bc.slaves) cc.slaves.push_back(s.name.empty() ? std::to_string(s.position) : s.name);
            if (bc.link.claim_all)
                for (const auto& s : cc.slaves) cc.claims.push_back({s, "*"});
            for (const auto& [slave, entry] : bc.link.claims) cc.claims.push_back({slave, entry});
            cc.tick_timeout_s = bc.link.tick_timeout_s;
            b.bus = std::make_unique<ethercat::Bus>(bc.id, std::make_unique<scanner::ClientBackend>(cc));
        } else {
            ethercat::sim::LocalBus lb = ethercat::sim::make_local_bus(bc, catalog_, cfg_.path);
            b.segment = std::move(lb.segment);
            b.plant = std::move(lb.plant);
            b.sim_stage = std::move(lb.sim_stage);
            b.bus = std::move(lb.bus);
        }
        if (bc.dc_follow) { // an EL6692 side whose other segment's time base this bus's DC follows
            const config::SlaveEntry* se = nullptr;
            for (const auto& s : bc.slaves) se = s.position == *bc.dc_follow ? &s : se;
            const ethercat::DeviceDesc* d = se ? catalog_.find(se->type) : nullptr;
            if (!d || !(d->vendor == 0x2 && d->product == 0x1a243052))
                throw Error(SB() << bc.dc_follow_where << ": dc_follow: " << *bc.dc_follow << " should be the position of an EL6692 side on bus "
                                 << bc.id << (se ? " (it is a " + se->type + ")" : std::string(" (no slave there)")));
            try {
                b.bus->follow_dc(SB() << "ec" << bc.id << ".s" << *bc.dc_follow << ".");
            } catch (const Error& e) {
                throw Error(SB() << bc.dc_follow_where << ": " << e.what());
            }
        }
        rt::Engine* e = engine_.get();
        if (bc.rate_hz) { // its own cycle, on its own RT thread
            rt::EngineConfig own = ec;
            own.rate_hz = *bc.rate_hz;
            own_cycles_.push_back(std::make_unique<rt::Engine>(own, clock_));
            e = own_cycles_.back().get();
            b.cycle = own_cycles_.size();
        }
        if (b.sim_stage) e->add_stage(rt::StageOrder::BusSend, *b.sim_stage);
        b.bus->add_stages(*e);
        buses_.push_back(std::move(b));
    }
    cycle_stats_.resize(cycle_count());
    declare_bus_signals();
    declare_engine_items(registry_);
    for (std::size_t i = 0; i < buses_.size(); ++i) make_bus_pvs(buses_[i], cfg_.buses[i]);
    // Every error of every subsystem, in one run (`check` and `run` report the same set): each
    // step keeps its errors and the build goes on; what depends on a failed step is not built.
    ErrorList errors;
    auto step = [&errors](auto&& f) {
        try {
            f();
            return true;
        } catch (const plc::CompileError& e) {
            for (const auto& m : e.errors()) errors.add(m);
        } catch (const MultiError& e) {
            for (const auto& m : e.errors()) errors.add(m);
        } catch (const Error& e) {
            errors.add(e);
        }
        return false;
    };
    axes_ = std::make_unique<IocAxes>(cfg_.axes, cfg_.prefix, registry_, db_, errors);
    std::vector<motion::AxisConfig> axis_configs;
    for (std::size_t i = 0; i < axes_->size(); ++i) axis_configs.push_back(axes_->config(i));
    step([&] { storages_ = std::make_unique<IocStorages>(cfg_, db_); });
    step([&] { memmaps_ = std::make_unique<IocMemMaps>(cfg_, catalog_, db_); });
    step([&] { plcs_ = std::make_unique<IocPlcs>(cfg_, axis_configs, registry_, db_); });
    step([&] { flyscan_ = std::make_unique<IocFlyScan>(cfg_, registry_, db_, memmaps_.get()); });
    module::BuildContext build{cfg_.prefix, cfg_.path, registry_, db_, EventLoop::now_s};
    for (const ModuleEntry& m : module_table())
        step([&] {
            if (auto mod = m.make(cfg_, build)) modules_.push_back(std::move(mod));
        });
    step([&] { area_ = std::make_unique<IocAreaDetector>(cfg_, db_, EventLoop::now_s); });
    auto engine_clock = [this] { return double(clock_.now_ns()) * 1e-9; }; // automation's clock: virtual in tests
    if (cfg_.smart_control)
        step([&] { smart_ = std::make_unique<automation::SmartControl>(*cfg_.smart_control, cfg_.prefix, db_, engine_clock); });
    if (!cfg_.compound_motors.empty())
        step([&] { compound_ = std::make_unique<automation::CompoundMotors>(cfg_.compound_motors, cfg_.prefix, db_); });
    if (!cfg_.state_machines.empty())
        step([&] { fsms_ = std::make_unique<automation::StateMachines>(cfg_.state_machines, cfg_.prefix, db_, engine_clock); });
    if (!cfg_.collision_zones.empty())
        step([&] { zones_ = std::make_unique<automation::CollisionZones>(cfg_.collision_zones, cfg_.prefix, db_, engine_clock); });
    if (cfg_.notify && step([&] { notifier_ = std::make_unique<automation::Notifier>(*cfg_.notify, cfg_.prefix, db_, engine_clock); }))
        if (fsms_) fsms_->on_latch([this](const std::string& m, const std::string& why) { notifier_->latched(m, why); });
    if (!cfg_.plans.empty() && step([&] { plans_ = std::make_unique<automation::Plans>(cfg_.plans, cfg_.prefix, cfg_.name, db_, engine_clock); }))
        plans_->set_state_machines(fsms_.get());
    registry_.freeze(); // every name the cycle will know is declared
    step([&] { kinematics_ = std::make_unique<IocKinematics>(cfg_, *axes_, db_); });
    step([&] { pvt_ = std::make_unique<IocPvt>(cfg_, *axes_, db_); });
    if (!cfg_.stats.empty()) // devIocStats's record set: $(IOC):HEARTBEAT, UPTIME, IOC_CPU_LOAD, ...
        step([&] {
            db_.load(pv::parse_db(pv::IocStats::database_text(), cfg_.path + ": ioc.stats (devIocStats's records)",
                                  {{"IOC", cfg_.stats}}));
        });
    for (const auto& d : cfg_.db) // a .db / .template file, or a substitution file's templates
        if (step([&] {
                for (const pv::DbFile& f : pv::load_records_file(d.file, d.macros)) db_.load(f);
            }))
            step([&] {
                try {
                    axes_->attach_asyn_motors(); // synApps asyn_motor.db: DTYP asynMotor, @asyn(PORT,ADDR)
                } catch (const Error& e) {
                    throw Error(SB() << d.file_where << ": " << d.file << ": " << e.what());
                }
            });
    errors.throw_if_any();
}

bool Ioc::ethercat_report(const std::vector<std::string>& argv, std::ostream& os) {
    bool any = false;
    for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
        ethercat::Bus& bus = *buses_[bi].bus;
        if (argv.size() > 1 && argv[1] != std::to_string(bus.id())) continue;
        any = true;
        ethercat::Bus& m = bus;
        const ethercat::BusSnapshot& s = bus.looked();
        int valid = 0;
        for (uint8_t v : s.slave_valid) valid += v;
        os << "ec" << bus.id() << ": " << m.slaves().size() << " slave(s) configured, " << std::max(s.responding, 0)
           << " answering, " << valid << " in OP with valid data; cycle " << (s.wkc_ok ? "consistent" : "NOT consistent")
           << ", WKC " << s.wkc << " (all slaves: " << s.expected_wkc << ")\n";
        for (std::size_t i = 0; i < m.slaves().size(); ++i) {
            ethercat::SlaveHealth h = m.slave_health(i);
            std::string err = m.slave_last_error(i);
            os << "  s" << m.slaves()[i].position << " " << m.slaves()[i].type << ": " << ethercat::slave_state_name(h.state)
               << (i < s.slave_valid.size() && s.slave_valid[i] ? ", valid" : ", not valid") << ", lost " << h.lost
               << ", configured again " << h.reconfigured << ", refused " << h.refused;
            if (h.error_id) os << ", error 0x" << std::hex << h.error_id << std::dec;
            if (!err.empty()) os << "; last: " << err;
            os << "\n";
        }
    }
    if (!any) os << (argv.size() > 1 ? "no bus " + argv[1] : std::string("no EtherCAT bus")) << "\n";
    return any;
}

bool Ioc::sim_fault(const std::vector<std::string>& argv, std::ostream& os) {
    if (argv.size() < 3) throw Error(SB() << "usage: sim BUS FAULT ... (faults: " << ethercat::sim::fault_usage() << ")");
    for (auto& b : buses_) {
        if (argv[1] != std::to_string(b.bus->id())) continue;
        if (!b.segment) throw Error(SB() << "bus " << argv[1] << " is not simulated in this IOC (link type " << b.bus->link_kind() << "); use beamctl sim fault");
        std::string text;
        for (std::size_t k = 2; k < argv.size(); ++k) text += (k > 2 ? " " : "") + argv[k];
        ethercat::sim::Fault f = ethercat::sim::parse_fault(text, catalog_, b.segment->size());
        if (!b.segment->post(f)) throw Error("sim: too many faults queued; try again");
        LOG_WARN(lg, "ec" << argv[1] << ": simulated fault injected: " << ethercat::sim::describe(f));
        os << "ec" << argv[1] << ": " << ethercat::sim::describe(f) << " (applied at the next frame)\n";
        return true;
    }
    throw Error(SB() << "no bus " << argv[1]);
}

bool Ioc::sdo_command(const std::vector<std::string>& argv, std::ostream& os) {
    const char* usage = "usage: sdo BUS POSITION INDEX SUB [VALUE SIZE] (numbers decimal or 0x hex; SIZE 1, 2, 4 or 8 bytes)";
    if (argv.size() != 5 && argv.size() != 7) throw Error(usage);
    auto num = [&](const std::string& t, uint64_t max, const char* what) {
        char* end = nullptr;
        errno = 0;
        unsigned long long v = std::strtoull(t.c_str(), &end, 0);
        if (t.empty() || *end || errno || v > max || t[0] == '-')
            throw Error(SB() << "sdo: " << what << " '" << t << "' should be a number from 0 to " << max << "; " << usage);
        return uint64_t(v);
    };
    const uint64_t bus_id = num(argv[1], 15, "BUS"), pos = num(argv[2], 65535, "POSITION");
    const uint16_t index = uint16_t(num(argv[3], 0xFFFF, "INDEX"));
    const uint8_t sub = uint8_t(num(argv[4], 0xFF, "SUB"));
    for (auto& b : buses_) {
        if (uint64_t(b.bus->id()) != bus_id) continue;
        char obj[16];
        std::snprintf(obj, sizeof obj, "0x%04X:%02X", index, sub);
        if (argv.size() == 7) {
            const uint64_t size = num(argv[6], 8, "SIZE");
            if (size != 1 && size != 2 && size != 4 && size != 8) throw Error(SB() << "sdo: SIZE " << size << " should be 1, 2, 4 or 8");
            const uint64_t value = num(argv[5], size == 8 ? UINT64_MAX : (uint64_t(1) << (8 * size)) - 1, "VALUE");
            std::vector<uint8_t> data(size);
            for (uint64_t k = 0; k < size; ++k) data[k] = uint8_t(value >> (8 * k));
            b.bus->sdo_write(int(pos), index, sub, data);
            LOG_INFO(lg, "ec" << bus_id << " s" << pos << ": SDO " << obj << " written: " << value << " (" << size << " bytes), from the shell");
            os << "ec" << bus_id << " s" << pos << " " << obj << " := " << value << " (" << size << " bytes)\n";
            return true;
        }
        std::vector<uint8_t> data = b.bus->sdo_read(int(pos), index, sub);
        uint64_t v = 0;
        for (std::size_t k = 0; k < data.size() && k < 8; ++k) v |= uint64_t(data[k]) << (8 * k);
        os << "ec" << bus_id << " s" << pos << " " << obj << " = " << v << " (" << data.size() << " bytes:";
        for (uint8_t x : data) {
            char h[4];
            std::snprintf(h, sizeof h, " %02x", x);
            os << h;
        }
        os << ")\n";
        return true;
    }
    throw Error(SB() << "no bus " << bus_id);
}

void Ioc::declare_bus_signals() {
    // The names the masters will register (the catalog's default assignment), ONE/ZERO and
    // masterstatus; bound to the image once the bus is up.
    for (std::size_t i = 0; i < cfg_.buses.size(); ++i) {
        const config::BusConfig& bc = cfg_.buses[i];
        std::string bus = SB() << "ec" << bc.id;
        auto declare = [&](std::string name, std::string type, bool output) {
            registry::Signal s;
            s.name = std::move(name);
            s.type = std::move(type);
            s.direction = output ? registry::Direction::Output : registry::Direction::Input;
            s.owner_kind = registry::OwnerKind::Bus;
            s.owner = bus;
            registry_.declare(std::move(s));
        };
        declare(bus + ".masterstatus", "UDINT", false);
        std::vector<int> positions;
        for (const auto& sc : bc.slaves) positions.push_back(sc.position);
        declare_bus_items(registry_, bc.id, positions); // ec0.ok, ec0.s3.slavestatus, ...: the IOC loop's
        for (const auto& sc : bc.slaves) {
            std::string pre = SB() << bus << ".s" << sc.position << ".";
            declare(pre + "ONE", "UDINT", false);
            declare(pre + "ZERO", "UDINT", false);
            declare(pre + "valid", "UDINT", false);
            const ethercat::DeviceDesc* base = catalog_.find(sc.type);
            if (!base) continue;
            const ethercat::DeviceDesc os = base->with_oversampling(sc.oversampling); // every sample's entry
            const ethercat::DeviceDesc* d = &os;
            std::set<std::string> seen; // an entry in two alternative PDOs is one signal
            for (bool out : {true, false})
                for (const auto& pd : out ? d->rx_pdos : d->tx_pdos)
                    for (const auto& e : pd.entries)
                        if (!e.name.empty() && seen.insert(e.name).second) declare(pre + e.name, e.datatype, out);
        }
        ethercat::Bus* busp = buses_[i].bus.get();
        const int cycle = int(buses_[i].cycle);
        registry_.set_binder(bus + ".", [this, busp, cycle](const registry::Signal& s, int bit, std::string& why) {
            if (binding_cycle_ >= 0 && cycle != binding_cycle_) {
                why = SB() << "'" << s.name << "' is on bus " << busp->id() << ", which runs its own cycle (buses[].rate_hz): axes, "
                           << "position compare and capture run in the IOC's cycle, and read the buses of that cycle only";
                return registry::BoundSignal{};
            }
            const ethercat::SignalInfo* si = busp->find_signal(s.name);
            if (!si) {
                why = SB() << "no signal '" << s.name << "' on bus " << busp->id()
                           << " after bring-up (not in the PDO assignment the slave reported)";
                return registry::BoundSignal{};
            }
            if (bit >= int(si->bits)) {
                why = SB() << "'" << s.name << "' has " << int(si->bits) << " bits, no bit " << bit;
                return registry::BoundSignal{};
            }
            return busp->bind(s.name, bit);
        });
    }
}

Ioc::~Ioc() {
    for (auto& b : buses_) b.bus->stop_health();
    engine_->stop();
    for (auto& e : own_cycles_) e->stop();
}

void Ioc::run_cycles(uint64_t n) {
    for (uint64_t i = 0; i < n; ++i) {
        for (;;) { // the other cycles that fall due before the IOC's next one, earliest first
            rt::Engine* first = nullptr;
            for (auto& e : own_cycles_)
                if (e->next_due_ns() <= engine_->next_due_ns() &&
                    (!first || e->next_due_ns() < first->next_due_ns()))
                    first = e.get();
            if (!first) break;
            first->run_cycles(1);
        }
        engine_->run_cycles(1);
    }
}

void Ioc::make_bus_pvs(BusRt& b, const config::BusConfig& bc) {
    std::string m = SB() << cfg_.prefix << "m" << bc.id;
    module::PvInstance bus{m, "", {{"BUS", SB() << "ec" << bc.id << "."}, {"NB", std::to_string(rt::kLatencyBuckets)}}};
    pv::DbFile f = make_records(bus_table(), bus, registry_);
    name_pvs(bus_table(), bus, registry_);
    if (bc.link.type == "scanner") {
        pv::merge_db(f, make_records(scanner_table(), bus, registry_));
        name_pvs(scanner_table(), bus, registry_);
    }
    for (const auto& s : bc.slaves) {
        char sp[16];
        std::snprintf(sp, sizeof sp, "s%03d", s.position);
        std::string p = m + sp;
        const ethercat::DeviceDesc* d = catalog_.find(s.type);
        module::PvInstance slave{p, SB() << "ec" << bc.id << ".s" << s.position << ".", {{"TYPE", s.type}, {"NAME", d->name.substr(0, 40)}}};
        pv::merge_db(f, make_records(slave_table(), slave, registry_));
        name_pvs(slave_table(), slave, registry_);
        // Process-data entries of the default PDO assignment: a table made from the catalog,
        // one row per entry (inputs read with I/O Intr, outputs written; an output follows the
        // image, which shows what its writer sends when an axis, a PLC or a record drives it).
        std::deque<std::string> text; // the rows' strings
        auto keep = [&](std::string x) { return text.emplace_back(std::move(x)).c_str(); };
        module::PvTable entries{"bus entries", {}};
        for (const auto& sm : d->sms) {
            if (sm.type != ethercat::SmType::Outputs && sm.type != ethercat::SmType::Inputs) continue;
            bool out = sm.type == ethercat::SmType::Outputs;
            for (auto& [smi, pdo] : d->pdo_assign) {
                if (smi != sm.index) continue;
                for (const auto& pd : out ? d->rx_pdos : d->tx_pdos) {
                    if (pd.index != pdo) continue;
                    for (const auto& e : pd.entries) {
                        if (e.name.empty() || e.index == 0) continue;
                        bool analog = e.name.rfind("analog", 0) == 0 || e.bits > 32 || registry::datatype_float_bits(e.datatype) != 0;
                        const char* type = e.bits == 1 ? (out ? "bo" : "bi") : analog ? (out ? "ao" : "ai") : (out ? "longout" : "longin");
                        module::PvRow row{keep("-" + entry_pv_suffix(e.name)), type, keep(e.name),
                                  {{"DESC", keep((s.type + " " + e.name).substr(0, 40))}}, out};
                        if (e.bits == 1) row.fields.insert(row.fields.end(), {{"ZNAM", "0"}, {"ONAM", "1"}});
                        entries.rows.push_back(std::move(row));
                    }
                }
            }
        }
        pv::merge_db(f, make_records(entries, slave, registry_));
        name_pvs(entries, slave, registry_);
        for (const module::PvRow& row : entries.rows) entry_pvs_[p + row.suffix] = slave.signal_prefix + row.signal;
        auto has = [d](const char* name) {
            for (const auto& pd : d->tx_pdos)
                for (const auto& e : pd.entries)
                    if (e.name == name) return true;
            return false;
        };
        if (has("internalTimestamp01") && has("externalTimestamp01")) { // an EL6692 side
            f.records.push_back(record("ai", p + "-DcSkew", {{"DESC", "DC time: other segment - this"}, {"EGU", "ns"}, {"PREC", "0"}}));
            f.records.push_back(record("ai", p + "-DcDrift", {{"DESC", "DC skew rate, last second"}, {"EGU", "ppm"}, {"PREC", "3"}}));
            b.dc_skews.push_back(BusRt::DcSkew{slave.signal_prefix, p});
        }
    }
    db_.load(f);
    for (auto& d : b.dc_skews) {
        d.skew = db_.find(d.pv + "-DcSkew");
        d.drift = db_.find(d.pv + "-DcDrift");
        d.skew->val_read_only = d.drift->val_read_only = true;
    }
    b.lat_hist = db_.find(m + "-ThdLatHist");
    b.lat_edges = db_.find(m + "-ThdLatHistEdges");
    for (const auto& s : bc.slaves) {
        char sp[32];
        std::snprintf(sp, sizeof sp, "s%03d-ErrMsg", s.position);
        pv::Record* r = db_.find(m + sp);
        if (r) r->val_read_only = true;
        b.err_msg.push_back(r);
    }
}

// One writer per output: CA may only read it, the PV shows what is sent on the bus, and DESC
// names the owner.
void Ioc::own_output(EntryPv& e, const std::string& owner) {
    if (!e.rec->val_read_only) e.desc = e.rec->desc;
    e.rec->val_read_only = true;
    set_desc(*e.rec, ("set by " + owner).substr(0, 39));
}

// The writer let go of it (its record was relinked or removed): the PV writes it again.
void Ioc::free_output(EntryPv& e) {
    if (!e.rec->val_read_only) return;
    e.rec->val_read_only = false;
    set_desc(*e.rec, e.desc);
}

void Ioc::set_desc(pv::Record& r, const std::string& text) {
    const pv::FieldDesc* fd = r.type().find("DESC");
    pv::Elements el = r.elements(*fd);
    pv::put_element(r, *fd, el, 0, pv::Prim::String, text.c_str());
    r.post(fd, pv::kDbeValue | pv::kDbeLog);
}

pv::LinkDevice* Ioc::bind_device(pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why) {
    auto fail = [&](std::string m) -> pv::LinkDevice* {
        if (why) *why = std::move(m);
        return nullptr;
    };
    std::string name = l.s().address;
    // an object of a module ("Fast Epid": a loop of feedback:; an mca record, a DXP parameter "@mca1.PeakingTime")
    for (auto& m : modules_)
        if (m->owns_device(r.type().name(), name)) {
            std::string reason;
            auto dev = m->make_device(module::DeviceRequest{r, name, f.dbf == pv::Dbf::OutLink}, reason);
            if (!dev) return fail(reason);
            devices_.push_back(std::move(dev));
            return devices_.back().get();
        }
    int bit = -1;
    const registry::Signal* sig = nullptr;
    std::string asyn_name, asyn_why;
    int asyn_bit = -1;
    if (parse_asyn_address(name, asyn_name, asyn_bit, asyn_why) && asyn_name.rfind("MOTOR_REC_", 0) == 0) {
        // asyn_motor.db's MOTOR_REC_DIRECTION/OFFSET/RESOLUTION: the motor record converts user
        // and dial units itself, so the driver only keeps them
        devices_.push_back(std::make_unique<KeptValueDevice>(asyn_name));
        return devices_.back().get();
    }
    if (parse_asyn_address(name, asyn_name, asyn_bit, asyn_why)) { // an ecmccfg record
        sig = registry_.find_with_bit(asyn_name, bit);
        if (sig && asyn_bit >= 0) {
            if (bit >= 0) return fail(SB() << "'" << name << "': a MASK and a bit in the name");
            bit = asyn_bit;
        }
        name = asyn_name;
    } else if (!asyn_why.empty()) {
        return fail(SB() << "'" << name << "': " << asyn_why);
    } else {
        sig = registry_.find_with_bit(name, bit);
    }
    if (!sig) {
        // the entries of the same slave, if the name got that far
        std::string slave = name.substr(0, name.rfind('.') + 1), have;
        int shown = 0;
        if (slave.rfind("ec", 0) == 0 && std::count(slave.begin(), slave.end(), '.') == 2)
            for (const registry::Signal* s : registry_.match(slave + "*"))
                if (shown++ < 12) have += (have.empty() ? "" : ", ") + s->name.substr(slave.size());
        return fail(SB() << "no signal '" << name << "' in this IOC"
                         << (have.empty() ? std::string(" (ec<bus>.s<slave>.<entry>[.<bit>]; `beamctl signals` lists them)")
                                          : " (" + slave + "* has: " + have + (shown > 12 ? ", ..." : "") + ")"));
    }
    bool output = f.dbf == pv::Dbf::OutLink;
    if (sig->owner_kind == registry::OwnerKind::Bridge)
        return fail(SB() << "'" << name << "' is an object of the RCP bridge: link to its PV instead (\""
                         << sig->pv << (output ? " PP" : " CP") << "\")");
    if (sig->loop_only) { // a bus's counters or the engine's statistics
        ethercat::Bus* bus = nullptr;
        std::vector<int> positions;
        std::size_t k = 0; // the cycle whose statistics it shows: its bus's
        for (std::size_t i = 0; i < buses_.size(); ++i)
            if (sig->owner == std::string(SB() << "ec" << buses_[i].bus->id())) {
                bus = buses_[i].bus.get();
                k = buses_[i].cycle;
                for (const auto& sc : cfg_.buses[i].slaves) positions.push_back(sc.position);
            }
        std::string reason;
        auto dev = make_bus_item_device(sig->name, bit, output, bus, positions, cycle(k), cycle_stats_.at(k), reason);
        if (!dev) return fail(reason);
        devices_.push_back(std::move(dev));
        return devices_.back().get();
    }
    if (sig->owner_kind == registry::OwnerKind::Axis) { // an axis data item: the snapshot, commands
        const std::string& t = r.type().name();
        std::string reason;
        auto dev = axes_->make_device(sig->name, bit, output, t == "bi" || t == "bo", reason);
        if (!dev) return fail(reason);
        devices_.push_back(std::move(dev));
        return devices_.back().get();
    }
    if (sig->owner_kind == registry::OwnerKind::Plc) { // a PLC's enable, error, counts
        std::string reason;
        auto dev = plcs_->make_device(sig->name, bit, output, reason);
        if (!dev) return fail(reason);
        devices_.push_back(std::move(dev));
        return devices_.back().get();
    }
    if (sig->owner_kind == registry::OwnerKind::Engine && sig->owner.rfind("pcomp", 0) == 0) { // a PCOMP block's out, active, produced
        std::string reason;
        auto dev = flyscan_->make_device(sig->name, bit, output, reason);
        if (!dev) return fail(reason);
        devices_.push_back(std::move(dev));
        return devices_.back().get();
    }
    if (sig->owner_kind != registry::OwnerKind::Bus)
        return fail(SB() << "'" << name << "' is a signal of " << sig->owner << "; device support reads and writes bus entries, axis, PLC and PCOMP items");
    std::string reason;
    auto entry = entry_pvs_.find(r.name());
    bool entry_pv = entry != entry_pvs_.end() && entry->second == sig->name; // the entry's own PV
    if (!registry_.bind(name, reason).bound()) {
        if (!entry_pv) return fail(reason);
        // a slave whose PDO assignment lacks an entry of the catalog's: its PV reads LINK/INVALID
        LOG_WARN(lg, r.name() << ": " << reason);
        devices_.push_back(std::make_unique<MissingEntryDevice>(sig->name));
        return devices_.back().get();
    }
    for (auto& b : buses_)
        for (const auto& si : b.bus->signals()) {
            if (si.name != sig->name) continue;
            if (output && !si.output) return fail(SB() << "'" << sig->name << "' is an input; an output link cannot write it");
            if (entry_pv && !output) r.val_read_only = true; // an input's PV: the bus writes it
            if (output && entry_pv) {
                // the entry's PV writes it while nobody else does (its writer: "CA (its PV)")
                b.entries.push_back(EntryPv{&r, &si});
                if (!sig->writer.empty()) own_output(b.entries.back(), sig->writer);
            }
            std::string writer;
            if (output && !entry_pv) { // this record becomes the output's one writer
                writer = SB() << "record " << r.name();
                if (!registry_.claim(sig->name, writer, reason)) return fail(reason);
                for (auto& e : b.entries)
                    if (e.sig == &si) own_output(e, writer);
            }
            // an I/O Intr input is watched in the cycle (before the cycle starts; later: by value)
            int watch = f.dbf == pv::Dbf::InLink && r.scan == 2 ? b.bus->watch(si) : -1;
            auto dev = std::make_unique<EcLinkDevice>(*b.bus, si, bit, watch);
            if (!writer.empty()) // relinked or removed: the output is free again, its PV writable
                dev->on_release = [this, &b, &si, writer, name = sig->name] {
                    registry_.release(name, writer);
                    for (auto& e : b.entries)
                        if (e.sig == &si) free_output(e);
                };
            devices_.push_back(std::move(dev));
            return devices_.back().get();
        }
    return fail(SB() << "no signal '" << sig->name << "' on its bus after bring-up");
}

void Ioc::bring_up() {
    for (std::size_t bi = 0; bi < buses_.size(); ++bi) {
        ethercat::Bus& bus = *buses_[bi].bus;
        bus.bring_up();
        // A scanner's slaves are what its chain says: the IOC file's types must be theirs.
        const config::BusConfig& bc = cfg_.buses[bi];
        if (bc.link.type == "scanner")
            for (std::size_t i = 0; i < bc.slaves.size() && i < bus.slaves().size(); ++i)
                if (bc.slaves[i].type != bus.slaves()[i].type)
                    throw Error(SB() << bc.slaves[i].type_where << ": ec" << bc.id << " s" << bc.slaves[i].position << " is "
                                     << bc.slaves[i].type << " in this file, " << bus.slaves()[i].type << " in the scanner's chain");
    }
    for (auto& b : buses_)
        for (auto& d : b.dc_skews) { // the time stamps, if the side's 0x1A02 is assigned
            d.int_ts = b.bus->find_signal(d.slave + "internalTimestamp01");
            d.ext_ts = b.bus->find_signal(d.slave + "externalTimestamp01");
            d.not_connected = b.bus->find_signal(d.slave + "externalDeviceNotConnected01");
        }
    binding_cycle_ = 0; // axes, profile moves, storages, position compare and capture: the IOC's cycle
    axes_->bind(
        [this](const motion::SignalRef& r) {
            std::string name = r.entry == "masterstatus" ? std::string(SB() << "ec" << r.bus << ".masterstatus")
                                                         : std::string(SB() << "ec" << r.bus << ".s" << r.slave << "." << r.entry);
            if (r.bit >= 0) name += SB() << "." << r.bit;
            std::string why;
            registry::BoundSignal s = registry_.bind(name, why);
            if (!s.bound()) throw Error(SB() << r.where.file << ":" << r.where.line << ":" << r.where.col << ": " << why);
            return s;
        },
        *engine_);
    kinematics_->bind();
    pvt_->bind(*engine_, registry_);
    std::vector<registry::BoundSignal> bus_ok;
    for (auto& b : buses_) {
        std::string why;
        bus_ok.push_back(registry_.bind(std::string(SB() << "ec" << b.bus->id() << ".masterstatus"), why));
    }
    storages_->bind(*engine_);
    std::vector<ethercat::Bus*> buses;
    for (auto& b : buses_) buses.push_back(b.bus.get());
    binding_cycle_ = -1; // the PLCs check their buses themselves; memory maps are read in the IOC loop
    memmaps_->bind(registry_, buses);
    // The PLCs of each cycle see that cycle's buses and memory maps only.
    const std::vector<registry::MemMap*> maps = memmaps_->memmaps();
    std::vector<PlcCycle> plc_cycles(cycle_count());
    for (std::size_t k = 0; k < plc_cycles.size(); ++k) {
        plc_cycles[k].engine = &cycle(k);
        plc_cycles[k].memmaps.assign(maps.size(), nullptr);
    }
    for (std::size_t m = 0; m < maps.size(); ++m) plc_cycles[buses_.at(memmaps_->bus_index(m)).cycle].memmaps[m] = maps[m];
    for (std::size_t i = 0; i < buses_.size(); ++i) {
        PlcCycle& pc = plc_cycles[buses_[i].cycle];
        pc.buses.push_back(buses_[i].bus->id());
        pc.bus_ok.push_back(bus_ok[i]);
    }
    plcs_->bind(std::move(plc_cycles), axes_->group(), storages_->storages(),
                [this](const std::string& name) { return flyscan_->plc_cell(name); });
    binding_cycle_ = 0;
    flyscan_->bind(*engine_, axes_->group(), buses, storages_->storages());
    // the cameras see the plant's beam of a simulated bus in this process (bus -1: the first with one)
    auto beam_of = [this](int bus) -> IocAreaDetector::BeamSource {
        for (std::size_t i = 0; i < buses_.size(); ++i) {
            ethercat::sim::Plant* p = buses_[i].plant.get();
            if (!p || !p->beam || (bus >= 0 && cfg_.buses[i].id != bus)) continue;
            ethercat::sim::Beam* beam = p->beam.get();
            return [beam] { return beam->tally(); };
        }
        return {};
    };
    module::BindContext bind{*engine_, registry_, axes_->group(), beam_of};
    for (auto& m : modules_) m->bind(bind);
    binding_cycle_ = -1;
    area_->bind(beam_of);
    db_.set_clock(EventLoop::now_s); // delays (calcout ODLY, seq DLYn) on the scan clock
    // Device support "beamctl" for records of the db: files ("@ec0.s3.entry[.bit]").
    db_.set_link_binder([this](pv::Record& r, const pv::FieldDesc& f, pv::Link& l, std::string* why) -> pv::LinkDevice* {
        return bind_device(r, f, l, why);
    });
    // Links with CA/CP/CPP to records of other servers (EPICS_CA_ADDR_LIST etc.), as dbCa.
    if (!ca_links_) ca_links_ = std::make_unique<ca::CaLinks>(db_);
    // Autosave (ioc.yaml autosave:): the info-tagged fields, restored after init, before PINI.
    if (cfg_.autosave && !autosave_) {
        autosave_ = std::make_unique<pv::Autosave>(db_, [](const std::string& m) {
            std::fprintf(stderr, "%s\n", m.c_str());
            std::fflush(stderr);
        });
        try {
            pv::autosave_defaults_before_init(*autosave_, cfg_.autosave->dir);
        } catch (const Error& e) {
            throw Error(SB() << cfg_.autosave->where << ": autosave: " << e.what());
        }
        db_.set_restore_hook([this] { autosave_->restore(); });
    }
    db_.init_records();
    area_->start();
    for (auto& m : modules_) m->start();
    if (smart_) smart_->start(); // its motors, shutter, trigger and scaler: records of this IOC
    if (compound_) compound_->start(); // their reals and inputs: here, or other IOCs' (run() connects those)
    if (fsms_) fsms_->start();
    if (notifier_) notifier_->start();
    if (zones_) zones_->start(); // after the compound motors: their puts to the reals are checked too
    if (plans_) plans_->start();
    plcs_->set_epics_state(12); // initHookAfterIocBuilt
    brought_up_ = true;
}

void Ioc::publish() {
    axes_->publish();
    kinematics_->publish();
    pvt_->publish();
    plcs_->publish();
    storages_->publish();
    flyscan_->publish();
    for (auto& m : modules_) m->publish(EventLoop::now_s());
    area_->poll(EventLoop::now_s());
    if (smart_) smart_->poll();
    if (compound_) compound_->poll();
    if (fsms_) fsms_->poll();
    if (notifier_) notifier_->poll();
    if (zones_) zones_->poll();
    if (plans_) plans_->poll();
    for (std::size_t k = 0; k < cycle_stats_.size(); ++k) cycle_stats_[k] = cycle(k).stats(); // the engine items' devices read them
    for (auto& b : buses_) {
        b.bus->snapshot(); // this look's cycle: what bus-entry records read (Bus::looked)
        for (auto& d : b.dc_skews) publish_dc_skew(b, d, b.bus->looked());
    }
    memmaps_->publish(EventLoop::now_s());
    for (auto& b : buses_) {
        const rt::EngineStats& es = cycle_stats_[b.cycle];
        // the status PVs read their items (scan_io_intr below); the histogram is an array
        double hist[rt::kLatencyBuckets], edges[rt::kLatencyBuckets];
        for (std::size_t i = 0; i < rt::kLatencyBuckets; ++i) {
            hist[i] = clamp_long(es.latency_hist[i]);
            edges[i] = rt::kLatencyEdgesUs[i];
        }
        set_array_if_changed(db_, *b.lat_hist, hist, rt::kLatencyBuckets);
        set_array_if_changed(db_, *b.lat_edges, edges, rt::kLatencyBuckets);
        // the slaves' last errors in words (-ErrMsg), when the health pass changed any
        ethercat::Bus& m = *b.bus;
        if (uint64_t v = m.health_version(); v != b.health_seen) {
            b.health_seen = v;
            for (std::size_t i = 0; i < b.err_msg.size() && i < m.slaves().size(); ++i) {
                pv::Record* r = b.err_msg[i];
                if (!r) continue;
                char t[pv::kStringSize] = "";
                std::snprintf(t, sizeof t, "%s", m.slave_last_error(i).c_str()); // 39 characters of it
                const pv::FieldDesc* f = r->type().find("VAL");
                pv::Elements e = r->elements(*f);
                char cur[pv::kStringSize] = "";
                pv::get_element(*r, *f, e, 0, pv::Prim::String, cur);
                if (std::strncmp(cur, t, sizeof t) == 0 && r->udf == 0) continue;
                pv::put_element(*r, *f, e, 0, pv::Prim::String, t);
                r->udf = 0;
                db_.process(*r);
            }
        }
    }
    db_.scan_io_intr(); // records on engine signals (axis items, bus entries) that changed since the last look
}

// An EL6692 side's two DC time stamps, latched together: the skew between the two segments' time
// bases, and how fast it moves (over the last second of time stamps).
void Ioc::publish_dc_skew(BusRt&, BusRt::DcSkew& d, const ethercat::BusSnapshot& s) {
    if (!d.int_ts || !d.ext_ts || s.image.empty()) return;
    const bool gone = !s.link_up || (d.not_connected && ethercat::Bus::get(s.image, *d.not_connected));
    if (gone) { // the last values stay, INVALID
        if (d.skew->sevr != pv::kInvalid) {
            set_value(db_, *d.skew, get_value(*d.skew), true);
            set_value(db_, *d.drift, get_value(*d.drift), true);
        }
        d.history.clear();
        return;
    }
    const uint64_t in = ethercat::Bus::get(s.image, *d.int_ts), ex = ethercat::Bus::get(s.image, *d.ext_ts);
    if (in == 0 || in == d.last_stamp) return; // no new latch since the last look
    d.last_stamp = in;
    const int64_t skew = int64_t(ex - in);
    d.history.emplace_back(in, skew);
    while (d.history.size() > 2 && in - d.history[1].first >= 1'000'000'000ull) d.history.pop_front();
    const auto& [t0, k0] = d.history.front();
    const double drift = in > t0 ? double(skew - k0) / double(in - t0) * 1e6 : 0.0;
    set_value(db_, *d.skew, double(skew), false);
    set_value(db_, *d.drift, drift, false);
}

void Ioc::bus_changed(std::size_t i) {
    ethercat::Bus& bus = *buses_.at(i).bus;
    bus.drain_changes();
    bus.snapshot(); // the cycle that woke the loop: what its records read (Bus::looked)
    db_.scan_io_intr();
}

int Ioc::run() {
    block_stop_signals(); // before any thread starts: only the loop's signalfd sees them
    if (!brought_up_) bring_up();
    EventLoop loop;
    struct StopCaLinks { // the CA client closes before its loop goes
        ca::CaLinks* links;
        ~StopCaLinks() {
            if (links) links->stop();
        }
    } stop_ca_links{ca_links_.get()};
    if (ca_links_) ca_links_->start(loop);
    // automation's CA client (compound motors and state machines over other IOCs' PVs); goes
    // before the loop
    std::unique_ptr<ca::Client> automation_client;
    if ((compound_ && compound_->needs_client()) || (fsms_ && fsms_->needs_client()) || (plans_ && plans_->needs_client())) {
        automation_client = std::make_unique<ca::Client>(loop, ca::ClientConfig::from_env());
        if (compound_) compound_->connect(*automation_client);
        if (fsms_) fsms_->connect(*automation_client);
        if (plans_) plans_->connect(*automation_client);
    }
    // A plan steps on at once when a motion or a dwell ends, not at the next 10 ms poll. A timer
    // outlives nothing: the loop (and its timers) goes before the plans. 50 us late, so that the
    // engine clock the plan compares with has surely passed the dwell's end.
    if (plans_) plans_->set_scheduler([this, &loop](double delay_s) { loop.call_after(delay_s > 0 ? delay_s + 50e-6 : 0, [this] { plans_->poll(); }); });
    ca::ServerConfig sc = ca::ServerConfig::from_env();
    if (cfg_.ca_port) sc.set_port(*cfg_.ca_port, cfg_.path + ": ca: port");
    ca::Server server(loop, db_, sc);
    if (!cfg_.acf.empty()) server.set_access_security(ca::AccessSecurity::load_file(cfg_.acf));
    server.start();
    db_.ioc_stats().set_ca_counts([&server] { // $(IOC):CA_CLNT_CNT, CA_CONN_CNT
        return pv::IocStats::CaCounts{unsigned(server.client_count()), unsigned(server.channel_count())};
    });
    std::unique_ptr<bridge::rcp::RcpBridge> rcp;
    if (cfg_.rcp) {
        bridge::rcp::BridgeConfig bc;
        bc.listen_address = cfg_.rcp->listen;
        bc.port = cfg_.rcp->port;
        bc.prefix = cfg_.rcp->prefix;
        bc.timeout_s = cfg_.rcp->timeout_s;
        for (const auto& [name, addr] : cfg_.rcp->machines) bc.machines.push_back({name, addr});
        bc.allow = cfg_.rcp->allow;
        bc.max_applications = cfg_.rcp->max_applications;
        bc.max_applications_per_address = cfg_.rcp->max_applications_per_address;
        bc.max_objects = cfg_.rcp->max_objects;
        bc.max_model_changes_per_minute = cfg_.rcp->max_model_changes_per_minute;
        bc.db_out = cfg_.rcp->db_out;
        if (!cfg_.rcp->pv_pattern.empty()) bc.pv_pattern = cfg_.rcp->pv_pattern;
        for (const auto& fv : cfg_.rcp->motor_fields) { // replaces a default of the same field
            const std::string& field = fv.first;
            auto same = [&field](const auto& f) { return f.first == field; };
            bc.motor_fields.erase(std::remove_if(bc.motor_fields.begin(), bc.motor_fields.end(), same), bc.motor_fields.end());
            bc.motor_fields.push_back(fv);
        }
        bc.on_object = [this](const bridge::rcp::BridgeConfig::ObjectEvent& e) { on_rcp_object(registry_, e); };
        try {
            rcp = std::make_unique<bridge::rcp::RcpBridge>(db_, loop, bc);
        } catch (const Error& e) {
            throw Error(SB() << cfg_.rcp->where << ": bridges.rcp: " << e.what());
        }
    }
    for (auto& b : buses_) { // I/O Intr records: processed as soon as a cycle saw their entry change
        b.bus->freeze_watches();
        if (b.bus->watch_count() == 0) continue;
        std::size_t i = std::size_t(&b - buses_.data());
        loop.add_fd(b.bus->change_fd(), EPOLLIN, [this, i](uint32_t) { bus_changed(i); });
    }
    engine_->start();
    for (auto& e : own_cycles_) e->start();
    for (auto& b : buses_) b.bus->start_health();
    std::string acf = cfg_.acf;
    LoopSignals signals(loop, acf.empty() ? std::function<void()>() : [&] { server.reload_access_security(acf); });
    // devIocStats's READACF re-reads the ACF as SIGHUP does; SYSRESET stops as SIGTERM does
    pv::IocStats::set_admin_hooks(acf.empty() ? std::function<bool()>() : [&] { return server.reload_access_security(acf); },
                                  [&loop] { loop.call_after(0, [&loop] { loop.stop(); }); });
    loop.call_every(0.01, [this] { publish(); });
    loop.call_every(0.01, [this] { db_.scan_periodic(EventLoop::now_s()); });
    if (autosave_) {
        pv::autosave_defaults_after_init(*autosave_, db_, cfg_.autosave->period_s);
        autosave_->tick(EventLoop::now_s());
        loop.call_every(0.1, [this] { autosave_->tick(EventLoop::now_s()); });
    }
    // `beamctl shell`: introspection on a local UNIX socket, served on this loop.
    pv::DbShellHooks shell_hooks;
    shell_hooks.casr = [&server](int level, std::ostream& os) { server.report(level, os); };
    shell_hooks.signals = [this](const std::string& pattern, std::ostream& os) {
        registry_.print(os, pattern);
        return !registry_.match(pattern).empty();
    };
    shell_hooks.commands["ethercat"] = {
        "ethercat [BUS]                         slaves: state, data valid, times lost and configured, last error",
        [this](const std::vector<std::string>& argv, std::ostream& os) { return ethercat_report(argv, os); }};
    shell_hooks.commands["sdo"] = {
        "sdo BUS POSITION INDEX SUB [VALUE SIZE]  read (or write) a CoE object of a slave, through its master or scanner",
        [this](const std::vector<std::string>& argv, std::ostream& os) { return sdo_command(argv, os); }};
    shell_hooks.commands["sim"] = {
        "sim BUS FAULT ...                      inject a fault into a simulated segment (docs/ethercat.md)",
        [this](const std::vector<std::string>& argv, std::ostream& os) { return sim_fault(argv, os); }};
    pv::DbShell db_shell(db_, shell_hooks);
    auto shell_server = pv::start_shell_server(loop, db_shell, cfg_.name, shell_socket_);
    // smartControl's line protocol on TCP and/or a pseudo-terminal
    std::unique_ptr<automation::LineServer> smart_server;
    std::string smart_text;
    if (smart_) {
        const config::SmartControlEntry& sc = *cfg_.smart_control;
        smart_server = std::make_unique<automation::LineServer>(
            loop, [this](std::string_view line, const automation::LineServer::Reply& reply) { smart_->command(line, reply); },
            [this](int n) { smart_->set_clients(n); }, [this](const std::string& why) { smart_->count_error(why); });
        try {
            if (sc.port) smart_server->listen_tcp(sc.bind, sc.port);
            if (!sc.pty.empty()) smart_server->open_pty(sc.pty);
        } catch (const Error& e) {
            throw Error(SB() << sc.where << ": smart_control: " << e.what());
        }
        smart_text = SB() << ", smartControl on" << (sc.port ? std::string(SB() << " tcp " << sc.bind << ":" << smart_server->port()) : "")
                          << (sc.pty.empty() ? "" : " pty " + sc.pty);
    }
    plcs_->set_epics_state(16); // initHookAfterIocRunning: epics_get_started()
    std::string rcp_text = rcp ? std::string(SB() << ", RCP bridge on udp " << cfg_.rcp->listen << ":" << rcp->port()) : std::string();
    std::string own_text; // the buses on their own cycles
    for (std::size_t i = 0; i < buses_.size(); ++i)
        if (buses_[i].cycle)
            own_text += SB() << "; bus " << buses_[i].bus->id() << " its own cycle, " << *cfg_.buses[i].rate_hz << " Hz ("
                             << cycle(buses_[i].cycle).rt_setup() << ")";
    std::printf("ready: CA on %s, %zu PVs, %zu bus(es), RT %g Hz (%s)%s%s%s\n", server.listen_description().c_str(),
                db_.size(), buses_.size(), cfg_.rate_hz, engine_->rt_setup().c_str(), own_text.c_str(), rcp_text.c_str(),
                smart_text.c_str());
    std::fflush(stdout);
    loop.run();
    if (autosave_) autosave_->flush(); // a clean stop saves what changed since the last save
    shutdown(&signals);
    // The stopped state reaches the clients before the server closes: a few more rounds of the
    // loop publish the last snapshot, the motor records' polls (0.1 s) end their moves (DMOV 1,
    // the stopped RBV) and the CA server sends it; then the log has the final positions.
    loop.call_after(0.35, [&loop] { loop.stop(); });
    loop.run();
    for (std::size_t i = 0; i < axes_->size(); ++i) {
        const motion::AxisStatus& st = axes_->status(i);
        LOG_INFO(lg, "stopped: axis " << axes_->name(i) << " at " << st.act_pos << (st.enabled ? " (enabled)" : " (disabled)"));
    }
    if (plans_) plans_->set_scheduler({}); // the loop goes now
    db_.ioc_stats().set_ca_counts({});    // and the server
    pv::IocStats::set_admin_hooks({}, {});
    return 0;
}

// A clean stop (the first SIGTERM/SIGINT): every moving axis stops with its emergency
// deceleration (virtual axes first, so that the PLCs ramp the real axes down with them), then the
// PLCs stop, the drives are disabled, the cycle stops and the buses go to SAFEOP. A second signal
// meanwhile exits at once.
void Ioc::shutdown(LoopSignals* signals) {
    std::printf("stopping: stopping axes, disabling drives, buses to SAFEOP\n");
    std::fflush(stdout);
    LOG_INFO(lg, "stopping: stopping axes, disabling drives, buses to SAFEOP");
    if (plans_) plans_->abort_all("the IOC is stopping"); // their motors stop, their files are written
    auto again = [&] {
        if (signals && signals->stop_pending()) {
            std::fprintf(stderr, "second signal: exiting at once\n");
            std::_Exit(1);
        }
    };
    auto wait_until = [&](auto done, double timeout_s) {
        double end = EventLoop::now_s() + timeout_s;
        while (!done() && EventLoop::now_s() < end) {
            again();
            ::usleep(2000);
        }
        return done();
    };
    IocAxes& ax = *axes_;
    if (ax.group() && engine_->running()) {
        double longest = 0; // [s] the longest emergency stop
        for (std::size_t i = 0; i < ax.size(); ++i) {
            const motion::AxisParams& p = ax.params(i);
            double d = p.emergency_deceleration > 0 ? p.emergency_deceleration : 3 * (p.trajectory.deceleration > 0 ? p.trajectory.deceleration : p.trajectory.acceleration);
            if (d > 0) longest = std::max(longest, std::fabs(ax.status(i).set_vel) / d);
        }
        for (bool virtual_pass : {true, false})
            for (std::size_t i = 0; i < ax.size(); ++i)
                if (ax.params(i).virtual_axis == virtual_pass && ax.status(i).busy) ax.send(i, motion::AxisCommand{motion::CommandType::Stop});
        auto still = [&] {
            for (std::size_t i = 0; i < ax.size(); ++i) {
                const motion::AxisStatus& s = ax.status(i);
                if (s.busy || (s.following && s.ext_moving)) return false;
            }
            return true;
        };
        if (!wait_until(still, longest + 2.0)) LOG_WARN(lg, "stopping: some axes still moved after " << longest + 2.0 << " s");
        for (std::size_t i = 0; i < plcs_->size(); ++i) plcs_->request_enable(i, false);
        for (std::size_t i = 0; i < ax.size(); ++i) {
            motion::AxisCommand off{motion::CommandType::Power};
            off.on = false;
            ax.send(i, off);
        }
        auto disabled = [&] {
            for (std::size_t i = 0; i < ax.size(); ++i)
                if (ax.status(i).enabled) return false;
            return true;
        };
        if (!wait_until(disabled, 2.0)) LOG_WARN(lg, "stopping: some drives still enabled after 2 s");
    }
    // A running capture ends and its file is completed while the cycle still runs.
    if (flyscan_->capture() && engine_->running()) {
        flyscan_->stop();
        if (!wait_until([&] { return !flyscan_->writer()->status().busy; }, 5.0))
            LOG_WARN(lg, "stopping: the capture file was still being written after 5 s");
    }
    // SAFEOP while the cycle still runs (the requests ride in it), after the health thread that
    // would take the slaves back to OP has stopped.
    for (auto& b : buses_) b.bus->stop_health();
    again();
    for (auto& b : buses_) {
        try {
            if (cycle(b.cycle).running()) b.bus->to_safe_op();
        } catch (const Error& e) {
            LOG_WARN(lg, "stopping: ec" << b.bus->id() << ": " << e.what());
        }
    }
    engine_->stop();
    for (auto& e : own_cycles_) e->stop();
    LOG_INFO(lg, "stopped");
}

} // namespace beamctl::ioc
