#include "bridge/rcp/bridge_core.hpp"

#include "bridge/rcp/motor_driver.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "pv/convert.hpp"
#include "pv/motor_record.hpp"

#include <algorithm>
#include <bitset>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

namespace beamctl::bridge::rcp {
namespace {

log::Logger lg("rcp");

constexpr std::size_t kMaxRecordName = 60;

// Object and application names may contain '.', which EPICS record names may not.
std::string pv_safe(std::string_view s) {
    std::string out(s);
    std::replace(out.begin(), out.end(), '.', '_');
    return out;
}

std::string truncated(std::string s, std::size_t n) {
    if (s.size() > n) s.resize(n);
    return s;
}

// Reasons that get a Malformed-<Reason> PV: NotWritable never happens on the IOC side, and
// UnknownApplication is never attributed to an application (bridge-wide PV only).
bool has_pv(Malformed m, bool per_app) {
    return m != Malformed::None && m != Malformed::NotWritable &&
           !(per_app && m == Malformed::UnknownApplication);
}

// Refusals with a Refused-<Reason> PV: every one bridge-wide; per application those that can be
// told to one (a source not allowed, or an application beyond the limit, is not one of them).
bool has_refusal_pv(Refusal r, bool per_app) {
    return !per_app || (r != Refusal::NotAllowed && r != Refusal::TooManyApplications);
}

pv::DbRecord make_record(const char* type, std::string name,
                         std::vector<std::pair<std::string, std::string>> fields) {
    pv::DbRecord r;
    r.type = type;
    r.name = std::move(name);
    r.loc = SourceLoc{"<rcp bridge>", 1, 1};
    for (auto& [k, v] : fields) r.fields.push_back(pv::DbField{k, v, r.loc});
    return r;
}

void write_record(std::ostream& os, const pv::DbRecord& r) {
    auto quoted = [&](const std::string& v) {
        os << '"';
        for (char c : v) {
            if (c == '"' || c == '\\') os << '\\';
            os << c;
        }
        os << '"';
    };
    os << "record(" << r.type << ", ";
    quoted(r.name);
    os << ") {\n";
    for (const auto& f : r.fields) {
        os << "    field(" << f.name << ", ";
        quoted(f.value);
        os << ")\n";
    }
    for (const auto& i : r.infos) {
        os << "    info(" << i.name << ", ";
        quoted(i.value);
        os << ")\n";
    }
    os << "}\n";
}

double read_val(pv::Record& r, const pv::FieldDesc* f, uint32_t i = 0) {
    double v = 0;
    pv::Elements e = r.elements(*f);
    pv::get_element(r, *f, e, i, pv::Prim::Double, &v);
    return v;
}

double read_field(pv::Record& r, const char* field) {
    const pv::FieldDesc* f = r.type().find(field);
    return f ? read_val(r, f) : 0;
}

} // namespace

std::string Endpoint::str() const {
    return ipv4_to_string(ip) + ":" + std::to_string(port);
}

bool parse_ipv4_net(std::string_view text, Ipv4Net& out) {
    std::size_t slash = text.find('/');
    uint32_t ip = 0;
    if (!parse_ipv4(text.substr(0, slash), ip)) return false;
    int bits = 32;
    if (slash != std::string_view::npos) {
        std::string_view b = text.substr(slash + 1);
        if (b.empty() || b.size() > 2 || b.find_first_not_of("0123456789") != std::string_view::npos) return false;
        bits = std::stoi(std::string(b));
        if (bits > 32) return false;
    }
    out.mask = bits == 0 ? 0 : ~uint32_t(0) << (32 - bits);
    out.ip = ip & out.mask;
    return true;
}

std::string Ipv4Net::str() const {
    int bits = 0;
    for (uint32_t m = mask; m; m <<= 1) ++bits;
    return ipv4_to_string(ip) + "/" + std::to_string(bits);
}

const char* to_string(Refusal r) {
    switch (r) {
    case Refusal::NotAllowed: return "NotAllowed";
    case Refusal::ForeignWriteAddress: return "ForeignWriteAddress";
    case Refusal::TooManyApplications: return "TooManyApplications";
    case Refusal::TooManyObjects: return "TooManyObjects";
    case Refusal::TooManyChanges: return "TooManyChanges";
    }
    return "?";
}

void BridgeConfig::validate() const {
    uint32_t ip;
    if (!listen_address.empty() && !parse_ipv4(listen_address, ip))
        throw Error(SB() << "rcp bridge: listen address '" << listen_address
                         << "' should be an IPv4 address such as 0.0.0.0");
    if (!(timeout_s > 0) || !std::isfinite(timeout_s))
        throw Error(SB() << "rcp bridge: timeout_s should be > 0 (got " << timeout_s << ")");
    if (!(continuation_window_s >= 0) || !std::isfinite(continuation_window_s))
        throw Error(SB() << "rcp bridge: continuation_window_s should be >= 0 (got "
                         << continuation_window_s << ")");
    if (!(motor_ack_timeout_s > 0) || !std::isfinite(motor_ack_timeout_s))
        throw Error(SB() << "rcp bridge: motor_ack_timeout_s should be > 0 (got "
                         << motor_ack_timeout_s << ")");
    if (max_applications == 0) throw Error("rcp bridge: max_applications should be >= 1");
    if (max_objects == 0 || max_objects > 255) throw Error(SB() << "rcp bridge: max_objects should be 1..255 (got " << max_objects << ")");
    if (max_model_changes_per_minute == 0) throw Error("rcp bridge: max_model_changes_per_minute should be >= 1");
    if (max_applications_per_address == 0) throw Error("rcp bridge: max_applications_per_address should be >= 1");
    Ipv4Net net;
    for (std::size_t i = 0; i < machines.size(); ++i) {
        if (machines[i].name.empty()) throw Error(SB() << "rcp bridge: machines[" << i << "]: name (the application's name) is empty");
        if (!parse_ipv4_net(machines[i].address, net))
            throw Error(SB() << "rcp bridge: machines[" << i << "] (" << machines[i].name << "): address '" << machines[i].address
                             << "' should be an IPv4 address or network such as 10.0.3.7 or 10.0.3.0/24");
    }
    for (std::size_t i = 0; i < allow.size(); ++i)
        if (!parse_ipv4_net(allow[i], net))
            throw Error(SB() << "rcp bridge: allow[" << i << "]: '" << allow[i] << "' should be an IPv4 network such as 10.0.3.0/24");
    if (pv_pattern.find("<name>") == std::string::npos)
        throw Error(SB() << "rcp bridge: pv_pattern '" << pv_pattern << "' should contain <name>");
}

// ------------------------------------------------------------------------------------------------

struct BridgeCore::Impl {
    struct App;

    struct Object {
        App* app = nullptr;
        BeaconObject desc;
        std::string pv;      // main record
        Endpoint write_to;   // ip_rcp:port_rcp (0 replaced by the beacon's source)
        uint16_t count = 0;  // learned from the first data entry (MOTOR: 5); 0 = not yet
        bool failed = false; // records could not be created: data is accepted and ignored
        bool waveform = false;
        bool valued = false;     // a value arrived (input main, output readback, motor)
        bool out_valued = false; // the output record has a value (written or initialised)
        // Back from offline: the next readback becomes the setpoint (output VAL, motor VAL).
        bool take_readback = false;
        pv::Record *main = nullptr, *rb = nullptr, *pos_err = nullptr, *err_code = nullptr;
        const pv::FieldDesc *main_val = nullptr, *rb_val = nullptr, *pos_err_val = nullptr,
                            *err_code_val = nullptr;
        pv::MotorRecord* motor = nullptr;
        std::shared_ptr<RcpMotorDriver> driver;
        std::vector<pv::DbRecord> defs; // what was loaded (also the .db file's text)
    };

    // Diagnostic records of one application or of the whole bridge.
    struct Diag {
        pv::Record *rx = nullptr, *tx = nullptr, *age = nullptr, *online = nullptr,
                   *count = nullptr, *before_beacon = nullptr;
        std::array<pv::Record*, kMalformedReasons> malformed{};
        std::array<pv::Record*, kRefusals> refused{};
        std::vector<pv::DbRecord> defs;
    };

    struct App {
        std::string name;
        std::string pv_name; // name with '.' -> '_'
        uint32_t ip = 0;     // part of the identity (name, source address)
        Endpoint beacon_from;
        std::array<std::unique_ptr<Object>, 256> objects; // by id
        std::size_t object_count = 0;
        bool assembling = false;
        double assembly_start_s = 0;
        std::vector<BeaconObject> pending;
        double last_rx_s = 0, last_beacon_s = 0;
        double model_time = 0; // latest RCP timestamp [s], written into our packets
        std::vector<double> changes_s; // when beacons changed the model, the last minute [s]
        bool online = true;
        Counters counters;
        Diag diag;
    };

    struct LogLimit {
        double next_s = -1e300;
        uint64_t suppressed = 0;
    };

    struct Fault {
        Malformed reason = Malformed::None;
        uint16_t offset = 0;
        const DataEntry* entry = nullptr;
        const Object* obj = nullptr;
    };

    pv::Database& db;
    BridgeConfig cfg;
    SendFn send;
    Clock clock;
    std::vector<std::unique_ptr<App>> apps;
    Diag global;
    Counters totals;
    std::array<LogLimit, kMalformedReasons> limits;
    std::array<LogLimit, kRefusals> refusal_limits;
    // Who may talk to the bridge (BridgeConfig::machines/allow): parsed once.
    std::vector<std::pair<std::string, Ipv4Net>> machines;
    std::vector<Ipv4Net> allow;
    bool loopback_only = true;
    LogLimit send_limit, refused_limit, early_limit;
    // Data before a beacon: since when it has gone on (-1: not now), and the latest [s].
    double early_first_s = -1, early_last_s = -1;
    // Scratch space of the packet path (no allocation per packet).
    Beacon beacon;
    DataPacket data;
    Packet tx{};
    std::array<double, kMaxValues> scratch{};
    std::array<bool, kMaxDataEntries> skip{}; // entries of `data` validate() set aside
    std::vector<uint16_t> ports;
    uint64_t ports_version = 0;
    double now = 0;
    double next_diag_s = 0;
    bool db_dirty = false;

    Impl(pv::Database& d, BridgeConfig c, SendFn s, Clock k)
        : db(d)
        , cfg(std::move(c))
        , send(std::move(s))
        , clock(std::move(k)) {
        for (const auto& m : cfg.machines) {
            Ipv4Net n;
            parse_ipv4_net(m.address, n); // validated
            machines.emplace_back(m.name, n);
        }
        for (const auto& a : cfg.allow) {
            Ipv4Net n;
            parse_ipv4_net(a, n);
            allow.push_back(n);
        }
        loopback_only = machines.empty() && allow.empty();
    }

    static bool is_loopback(uint32_t ip) { return (ip >> 24) == 127; }
    // The source may send anything at all (a machine's address, an allowed network, loopback
    // when nothing is configured).
    bool source_allowed(const Endpoint& from) const {
        if (loopback_only) return is_loopback(from.ip);
        for (const Ipv4Net& n : allow)
            if (n.contains(from.ip)) return true;
        for (const auto& [name, n] : machines)
            if (n.contains(from.ip)) return true;
        return false;
    }
    // A beacon of `app` from `from`: an allowed network, or a machine of that name there.
    bool beacon_allowed(std::string_view app, const Endpoint& from) const {
        if (loopback_only) return is_loopback(from.ip);
        for (const Ipv4Net& n : allow)
            if (n.contains(from.ip)) return true;
        for (const auto& [name, n] : machines)
            if (name == app && n.contains(from.ip)) return true;
        return false;
    }

    void refuse(App* a, Refusal r, const Endpoint& from, std::string_view why) {
        totals.refused[std::size_t(r)]++;
        if (a) a->counters.refused[std::size_t(r)]++;
        LogLimit& l = refusal_limits[std::size_t(r)];
        if (now < l.next_s) {
            ++l.suppressed;
            return;
        }
        if (lg.enabled(log::Level::warn)) {
            SB m;
            m << "refused a packet from " << from.str() << " (" << to_string(r) << "): " << why;
            if (l.suppressed) m << " (" << l.suppressed << " more refused for this reason in the last second)";
            lg.write(log::Level::warn, m.str());
        }
        l.next_s = now + 1;
        l.suppressed = 0;
    }

    ~Impl() {
        for (auto& a : apps) {
            for (auto& o : a->objects)
                if (o) unbuild(*o);
            for (auto& d : a->diag.defs) db.remove(d.name);
        }
        for (auto& d : global.defs) db.remove(d.name);
    }

    std::string expand(std::string_view app, std::string_view name) const {
        std::string out;
        const std::string& p = cfg.pv_pattern;
        for (std::size_t i = 0; i < p.size();) {
            auto tag = [&](const char* t) { return p.compare(i, std::strlen(t), t) == 0; };
            if (tag("<prefix>")) {
                out += cfg.prefix;
                i += 8;
            } else if (tag("<application>")) {
                out += pv_safe(app);
                i += 13;
            } else if (tag("<name>")) {
                out += pv_safe(name);
                i += 6;
            } else {
                out += p[i++];
            }
        }
        return out;
    }

    // ---------------------------------------------------------------- records
    // Loads new records; false (nothing added, logged) if a name is taken or a record refused.
    bool load(const std::vector<pv::DbRecord>& defs, const std::string& what) {
        for (const auto& d : defs) {
            if (d.name.size() > kMaxRecordName) {
                LOG_ERR(lg, what << ": PV name " << d.name << " is longer than " << kMaxRecordName
                                 << " characters; not created");
                return false;
            }
            if (db.find(d.name)) {
                LOG_ERR(lg, what << ": PV " << d.name << " already exists; not created");
                return false;
            }
        }
        pv::DbFile f;
        f.records = defs;
        try {
            db.load(f);
        } catch (const Error& e) {
            LOG_ERR(lg, what << ": " << e.what());
            return false;
        }
        return true;
    }

    std::string describe(const App& a, const BeaconObject& d) const {
        return SB() << "application " << a.name << " object " << int(d.id) << " '" << d.name << "'";
    }

    void build(Object& o) {
        App& a = *o.app;
        const BeaconObject& d = o.desc;
        ObjectType t = d.type;
        bool is_float = d.data_type == DataType::Float32 || d.data_type == DataType::Float64;
        std::string prec = is_float ? "4" : "0";
        std::string desc =
            truncated(SB() << "RCP " << a.name << " " << to_string(t) << " " << int(d.id), 40);
        std::string info = SB() << a.name << " " << int(d.id) << " " << to_string(t) << " "
                                << to_string(d.data_type);
        o.defs.clear();
        auto rec = [&](const char* type, std::string name,
                       std::vector<std::pair<std::string, std::string>> fields) {
            pv::DbRecord r = make_record(type, std::move(name), std::move(fields));
            r.infos.push_back(pv::DbInfo{"rcp", info, r.loc});
            o.defs.push_back(std::move(r));
        };
        std::string rb = o.pv + "_RBV";
        o.waveform = t != ObjectType::Motor && o.count > 1;
        if (t == ObjectType::Motor) {
            std::vector<std::pair<std::string, std::string>> f = {
                {"DESC", desc},
                {"DTYP", "asynMotor"},
                {"OUT", SB() << "@rcp(" << a.name << "," << int(d.id) << ")"}};
            for (const auto& kv : cfg.motor_fields) f.push_back(kv);
            rec("motor", o.pv, f);
            rec("ai", o.pv + "_PosErr", {{"DESC", "Position error"}, {"PREC", "4"}});
            rec("longin", o.pv + "_ErrCode", {{"DESC", "Error code"}});
        } else if (o.waveform) {
            const char* ftvl = (t == ObjectType::AI || t == ObjectType::AO)   ? "DOUBLE"
                               : (t == ObjectType::LI || t == ObjectType::LO) ? "LONG"
                                                                              : "UCHAR";
            std::vector<std::pair<std::string, std::string>> f = {
                {"DESC", desc}, {"FTVL", ftvl}, {"NELM", std::to_string(o.count)}, {"PREC", prec}};
            rec("waveform", o.pv, f);
            if (is_output(t)) {
                f[0].second = truncated(desc + " readback", 40);
                rec("waveform", rb, f);
            }
        } else {
            std::vector<std::pair<std::string, std::string>> analog = {{"DESC", desc},
                                                                       {"PREC", prec}};
            std::vector<std::pair<std::string, std::string>> binary = {
                {"DESC", desc}, {"ZNAM", "Off"}, {"ONAM", "On"}};
            std::vector<std::pair<std::string, std::string>> integer = {{"DESC", desc}};
            auto readback = [&](std::vector<std::pair<std::string, std::string>> f) {
                f[0].second = truncated(desc + " readback", 40);
                return f;
            };
            switch (t) {
            case ObjectType::AI:
                rec("ai", o.pv, analog);
                break;
            case ObjectType::AO:
                rec("ao", o.pv, analog);
                rec("ai", rb, readback(analog));
                break;
            case ObjectType::BI:
                rec("bi", o.pv, binary);
                break;
            case ObjectType::BO:
                rec("bo", o.pv, binary);
                rec("bi", rb, readback(binary));
                break;
            case ObjectType::LI:
                rec("longin", o.pv, integer);
                break;
            case ObjectType::LO:
                rec("longout", o.pv, integer);
                rec("longin", rb, readback(integer));
                break;
            case ObjectType::Motor:
                break;
            }
        }
        o.valued = o.out_valued = false;
        if (!load(o.defs, describe(a, d))) {
            o.failed = true;
            o.defs.clear();
            return;
        }
        o.failed = false;
        auto val = [](pv::Record* r) { return r->type().find("VAL"); };
        o.main = db.find(o.pv);
        o.main_val = val(o.main);
        if (t == ObjectType::Motor) {
            o.pos_err = db.find(o.pv + "_PosErr");
            o.err_code = db.find(o.pv + "_ErrCode");
            o.pos_err_val = val(o.pos_err);
            o.err_code_val = val(o.err_code);
            o.pos_err->val_read_only = o.err_code->val_read_only = true;
            o.motor = pv::MotorRecord::from(o.main);
            Object* op = &o;
            o.driver = std::make_shared<RcpMotorDriver>(
                o.pv, [this, op](const RcpMotorDriver::Command& c) { return send_motor(*op, c); },
                clock ? clock : Clock([this] { return now; }), cfg.motor_ack_timeout_s);
            o.driver->set_comm_error(!a.online);
            o.motor->set_driver(o.driver);
        } else if (is_output(t)) {
            o.rb = db.find(rb);
            o.rb_val = val(o.rb);
            o.rb->val_read_only = true;
            Object* op = &o;
            o.main->put_hook = [this, op](pv::Record& r, const pv::FieldDesc& f) {
                return on_put(*op, r, f);
            };
        } else {
            o.main->val_read_only = true;
        }
        if (cfg.on_object) cfg.on_object({true, a.name, d.name, o.pv, t, d.data_type, uint16_t(o.count)});
    }

    void unbuild(Object& o) {
        if (cfg.on_object && o.main)
            cfg.on_object({false, o.app->name, o.desc.name, o.pv, o.desc.type, o.desc.data_type, uint16_t(o.count)});
        if (o.driver) o.driver->detach();
        for (const auto& d : o.defs) db.remove(d.name);
        o.defs.clear();
        o.main = o.rb = o.pos_err = o.err_code = nullptr;
        o.motor = nullptr;
        o.driver.reset();
    }

    bool make_diag(Diag& d, const std::string& base, bool per_app, const std::string& what) {
        auto counter = [&](const std::string& n, const std::string& desc) {
            d.defs.push_back(
                make_record("ai", base + n, {{"DESC", truncated(desc, 40)}, {"PREC", "0"}}));
        };
        counter("RxCount", "Packets received");
        counter("TxCount", "Packets sent");
        if (per_app) {
            d.defs.push_back(
                make_record("ai", base + "BeaconAge",
                            {{"DESC", "Time since the last beacon"}, {"PREC", "1"}, {"EGU", "s"}}));
            d.defs.push_back(make_record("bi", base + "Online",
                                         {{"DESC", "Beacon or data within the timeout"},
                                          {"ZNAM", "Offline"},
                                          {"ONAM", "Online"},
                                          {"ZSV", "MAJOR"}}));
            d.defs.push_back(
                make_record("longin", base + "Objects", {{"DESC", "Objects announced"}}));
        } else {
            d.defs.push_back(
                make_record("longin", base + "Applications", {{"DESC", "RCP applications"}}));
            counter("DataBeforeBeacon", "Data before a beacon (ignored)");
        }
        for (std::size_t m = 0; m < kMalformedReasons; ++m)
            if (has_pv(Malformed(m), per_app))
                counter(std::string("Malformed-") + to_string(Malformed(m)),
                        std::string("Malformed: ") + to_string(Malformed(m)));
        for (std::size_t r = 0; r < kRefusals; ++r)
            if (has_refusal_pv(Refusal(r), per_app))
                counter(std::string("Refused-") + to_string(Refusal(r)), std::string("Refused: ") + to_string(Refusal(r)));
        // Names too long for a record are left out (the counters stay in totals()/the log);
        // RxCount, the shortest, decides whether the application gets diagnostics at all.
        std::string skipped;
        for (auto it = d.defs.begin(); it != d.defs.end();) {
            if (it->name.size() <= kMaxRecordName) {
                ++it;
                continue;
            }
            skipped += (skipped.empty() ? "" : ", ") + it->name;
            it = d.defs.erase(it);
        }
        if (!skipped.empty())
            LOG_WARN(lg, what << ": diagnostic PV names longer than " << kMaxRecordName
                              << " characters left out: " << skipped);
        if (!load(d.defs, what)) {
            d.defs.clear();
            return false;
        }
        d.rx = db.find(base + "RxCount");
        d.tx = db.find(base + "TxCount");
        if (per_app) {
            d.age = db.find(base + "BeaconAge");
            d.online = db.find(base + "Online");
            d.count = db.find(base + "Objects");
        } else {
            d.count = db.find(base + "Applications");
            d.before_beacon = db.find(base + "DataBeforeBeacon");
        }
        for (std::size_t m = 0; m < kMalformedReasons; ++m)
            if (has_pv(Malformed(m), per_app))
                d.malformed[m] = db.find(base + "Malformed-" + to_string(Malformed(m)));
        for (std::size_t r = 0; r < kRefusals; ++r)
            if (has_refusal_pv(Refusal(r), per_app))
                d.refused[r] = db.find(base + "Refused-" + to_string(Refusal(r)));
        for (const auto& r : d.defs) db.find(r.name)->val_read_only = true;
        return true;
    }

    // ---------------------------------------------------------------- values
    void set_scalar(pv::Record& r, const pv::FieldDesc* f, double v) {
        pv::Elements e = r.elements(*f);
        pv::put_element(r, *f, e, 0, pv::Prim::Double, &v);
        r.udf = 0;
        db.process(r);
    }

    // Publishes a counter-like value, processing only when it changed.
    void set_if_changed(pv::Record* r, double v) {
        if (!r) return;
        const pv::FieldDesc* f = r->type().find("VAL");
        if (!r->udf && read_val(*r, f) == v) return;
        set_scalar(*r, f, v);
    }

    void set_values(pv::Record& r, const pv::FieldDesc* f, bool waveform, std::span<const double> v,
                    bool binary) {
        if (!waveform) return set_scalar(r, f, binary ? double(v[0] != 0) : v[0]);
        pv::Elements e = r.elements(*f);
        uint32_t n = uint32_t(std::min<std::size_t>(v.size(), e.capacity));
        if (e.type == pv::Dbf::Double && !binary) {
            std::memcpy(e.data, v.data(), std::size_t(n) * sizeof(double));
        } else {
            for (uint32_t i = 0; i < n; ++i) {
                double x = binary ? double(v[i] != 0) : v[i];
                pv::put_element(r, *f, e, i, pv::Prim::Double, &x);
            }
        }
        r.set_count(*f, n);
        r.udf = 0;
        db.process(r);
    }

    // Alarm without a new value (recGblSetSevr + monitor): used for COMM and back to UDF.
    void alarm_only(pv::Record* r, uint16_t stat, uint16_t sevr) {
        if (!r) return;
        r->set_sevr(stat, sevr);
        r->stamp_time();
        if (unsigned m = r->reset_alarms()) r->post(r->type().find("VAL"), m);
    }

    void restore(pv::Record* r, bool valued) {
        if (!r) return;
        if (valued)
            db.process(*r);
        else
            alarm_only(r, pv::kStatUdf, pv::kInvalid);
    }

    // ---------------------------------------------------------------- output
    bool send_packet(App& a, const Endpoint& to) {
        if (to.ip == 0 || to.port == 0 || !send || !send(to, std::span<const uint8_t>(tx))) {
            if (now >= send_limit.next_s) {
                LOG_WARN(lg, "application " << a.name << ": cannot send to " << to.str() << " ("
                                            << send_limit.suppressed
                                            << " more failures since the last report)");
                send_limit.next_s = now + 1;
                send_limit.suppressed = 0;
            } else {
                ++send_limit.suppressed;
            }
            return false;
        }
        a.counters.tx++;
        totals.tx++;
        return true;
    }

    pv::PutStatus on_put(Object& o, pv::Record& r, const pv::FieldDesc& f) {
        if (&f != o.main_val) return pv::PutStatus::Ok;
        if (!o.app->online) {
            if (now >= refused_limit.next_s) {
                LOG_WARN(lg, "put to " << o.pv << " refused: application " << o.app->name
                                       << " is offline (" << refused_limit.suppressed
                                       << " more refused since the last report)");
                refused_limit.next_s = now + 1;
                refused_limit.suppressed = 0;
            } else {
                ++refused_limit.suppressed;
            }
            return pv::PutStatus::Failed;
        }
        uint16_t n = 1;
        pv::Elements e = r.elements(f);
        if (o.waveform) {
            n = uint16_t(std::min<uint32_t>(e.capacity, o.count));
            for (uint16_t i = 0; i < n; ++i)
                pv::get_element(r, f, e, i, pv::Prim::Double, &scratch[i]);
        } else {
            double v = 0;
            pv::get_element(r, f, e, 0, pv::Prim::Double, &v);
            if (o.desc.type != ObjectType::BO) { // the drive limits processing will apply
                double hi = read_field(r, "DRVH"), lo = read_field(r, "DRVL");
                if (hi > lo) v = std::clamp(v, lo, hi);
            }
            scratch[0] = v;
        }
        DataEntry d{o.desc.id, o.desc.type, o.desc.data_type,
                    n,         o.desc.name, std::span<const double>(scratch.data(), n)};
        WriteResult w = write_data(tx, o.app->model_time, std::span<const DataEntry>(&d, 1));
        if (!w) {
            LOG_WARN(lg, "put to " << o.pv << " refused: " << to_string(w.status) << " ("
                                   << to_string(o.desc.data_type) << ")");
            return pv::PutStatus::BadValue;
        }
        if (!send_packet(*o.app, o.write_to)) return pv::PutStatus::Failed;
        o.out_valued = true;
        o.take_readback = false; // the operator's value, sent, wins over an older readback
        return pv::PutStatus::Ok;
    }

    bool send_motor(Object& o, const RcpMotorDriver::Command& c) {
        DataEntry d{o.desc.id,         ObjectType::Motor,
                    DataType::Float64, kMotorValueCount,
                    o.desc.name,       std::span<const double>(c.data(), c.size())};
        if (!write_data(tx, o.app->model_time, std::span<const DataEntry>(&d, 1))) return false;
        if (!send_packet(*o.app, o.write_to)) return false;
        if (o.app->online) o.take_readback = false; // the record has a new target
        return true;
    }

    // ---------------------------------------------------------------- malformed input
    void report(App* a, const Fault& f, const Endpoint& from, std::string_view note = {}) {
        totals.malformed[std::size_t(f.reason)]++;
        if (a) a->counters.malformed[std::size_t(f.reason)]++;
        LogLimit& l = limits[std::size_t(f.reason)];
        if (now < l.next_s) {
            ++l.suppressed;
            return;
        }
        if (lg.enabled(log::Level::warn)) {
            SB m;
            m << "malformed packet from " << from.str();
            if (a) m << " (application " << a->name << ")";
            m << ": " << to_string(f.reason) << " at byte " << f.offset;
            if (f.entry) {
                m << ": entry object " << int(f.entry->id) << " '" << f.entry->name << "' "
                  << to_string(f.entry->type) << "/" << to_string(f.entry->data_type) << " count "
                  << f.entry->count;
                if (f.obj) {
                    m << ", the beacon has '" << f.obj->desc.name << "' "
                      << to_string(f.obj->desc.type) << "/" << to_string(f.obj->desc.data_type);
                    if (f.obj->count) m << " count " << f.obj->count;
                } else {
                    m << ", not in the application's beacon";
                }
            }
            if (!note.empty()) m << ": " << note;
            if (l.suppressed) m << " (" << l.suppressed << " more since the last report)";
            lg.write(log::Level::warn, m.str());
        }
        l.next_s = now + 1;
        l.suppressed = 0;
    }

    App* app_by_source(const Endpoint& from) {
        App* by_ip = nullptr;
        int n = 0;
        for (auto& a : apps) {
            if (a->beacon_from == from) return a.get();
            if (a->ip == from.ip) {
                by_ip = a.get();
                ++n;
            }
        }
        return n == 1 ? by_ip : nullptr;
    }

    App* find_app(std::string_view name, uint32_t ip) {
        for (auto& a : apps)
            if (a->ip == ip && a->name == name) return a.get();
        return nullptr;
    }

    // ---------------------------------------------------------------- beacons
    App* create_app(const std::string& name, const Endpoint& from) {
        if (apps.size() >= cfg.max_applications) {
            refuse(nullptr, Refusal::TooManyApplications, from,
                   (SB() << "application " << name << ": the limit of " << cfg.max_applications
                         << " applications (bridges.rcp.max_applications) is reached")
                       .str());
            return nullptr;
        }
        std::size_t same_address = 0;
        for (const auto& x : apps) same_address += x->ip == from.ip;
        if (same_address >= cfg.max_applications_per_address) {
            refuse(nullptr, Refusal::TooManyApplications, from,
                   (SB() << "application " << name << ": " << same_address << " applications from " << ipv4_to_string(from.ip)
                         << " already (bridges.rcp.max_applications_per_address)")
                       .str());
            return nullptr;
        }
        auto a = std::make_unique<App>();
        a->name = name;
        a->pv_name = pv_safe(name);
        a->ip = from.ip;
        a->beacon_from = from;
        a->last_rx_s = a->last_beacon_s = now;
        std::string what = SB() << "application " << name << " from " << from.str();
        if (!make_diag(a->diag, cfg.prefix + a->pv_name + ":", true, what)) {
            report(
                nullptr, {Malformed::UnknownApplication, 9}, from,
                (SB() << "application " << name
                      << " refused: its PV names are taken (the same name from another address?)")
                    .str());
            return nullptr;
        }
        db.init_records();
        LOG_INFO(lg, "application " << name << " announced from " << from.str());
        early_first_s = -1; // data before a beacon: explained, maybe
        apps.push_back(std::move(a));
        App* app = apps.back().get();
        set_if_changed(global.count, double(apps.size()));
        publish(app->diag, app->counters, app);
        db_dirty = true;
        return app;
    }

    void on_beacon(std::span<const uint8_t> p, const Endpoint& from) {
        ParseResult r = parse_beacon(p, beacon);
        if (!r) {
            App* a = !beacon.application.empty() ? find_app(beacon.application, from.ip)
                                                 : app_by_source(from);
            return report(a, {r.reason, r.offset}, from);
        }
        // Who may announce what, and how much: refused before anything changes.
        if (!beacon_allowed(beacon.application, from))
            return refuse(nullptr, Refusal::NotAllowed, from,
                          (SB() << "application " << beacon.application << " is not configured for this address "
                                << "(bridges.rcp.machines / allow)")
                              .str());
        App* a = find_app(beacon.application, from.ip);
        for (const BeaconObject& o : beacon.objects)
            if (o.ip_rcp != 0 && o.ip_rcp != from.ip)
                return refuse(a, Refusal::ForeignWriteAddress, from,
                              (SB() << "application " << beacon.application << ": object '" << o.name
                                    << "' asks for writes to " << Endpoint{o.ip_rcp, o.port_rcp}.str()
                                    << ", not the address its beacons come from")
                                  .str());
        std::size_t announced = beacon.objects.size() +
                                (beacon.continuation && a && a->assembling ? a->pending.size() : 0);
        if (announced > cfg.max_objects)
            return refuse(a, Refusal::TooManyObjects, from,
                          (SB() << "application " << beacon.application << ": " << announced << " objects, more than "
                                << cfg.max_objects << " (bridges.rcp.max_objects)")
                              .str());
        if (a && changes_model(*a)) {
            auto& c = a->changes_s;
            c.erase(std::remove_if(c.begin(), c.end(), [&](double t) { return now - t >= 60; }), c.end());
            if (c.size() >= cfg.max_model_changes_per_minute)
                return refuse(a, Refusal::TooManyChanges, from,
                              (SB() << "application " << a->name << ": " << c.size()
                                    << " beacons changed its objects in the last minute (bridges.rcp.max_model_changes_per_minute)")
                                  .str());
            c.push_back(now);
        }
        if (!a && !(a = create_app(beacon.application, from))) return;
        if (a->changes_s.empty()) a->changes_s.push_back(now); // its first model
        bool use = true;
        if (beacon.continuation) {
            if (!a->assembling || now - a->assembly_start_s > cfg.continuation_window_s) {
                LOG_DEBUG(lg, "application " << a->name << ": continuation beacon without a beacon "
                                             << "in the last " << cfg.continuation_window_s
                                             << " s ignored");
                use = false;
            } else {
                for (std::size_t i = 0; i < beacon.objects.size(); ++i)
                    for (const BeaconObject& q : a->pending)
                        if (q.id == beacon.objects[i].id || q.name == beacon.objects[i].name)
                            return report(
                                a,
                                {Malformed::DuplicateObject,
                                 uint16_t(kBeaconHeaderSize + i * kBeaconObjectSize)},
                                from, "object id or name already in this beacon's earlier packet");
            }
        }
        a->counters.rx++;
        a->beacon_from = from;
        a->last_beacon_s = now;
        a->model_time = beacon.timestamp;
        mark_alive(*a);
        if (!use) return;
        if (beacon.continuation) {
            a->pending.insert(a->pending.end(), beacon.objects.begin(), beacon.objects.end());
            apply_model(*a, false);
        } else {
            if (a->assembling) apply_model(*a, true);
            a->pending = beacon.objects;
            a->assembling = true;
            a->assembly_start_s = now;
            apply_model(*a, cfg.continuation_window_s <= 0);
        }
    }

    // The beacon in `beacon` lists an object that the application does not have as listed.
    bool changes_model(const App& a) const {
        for (const BeaconObject& n : beacon.objects) {
            const auto& cur = a.objects[n.id];
            if (!cur || cur->desc.type != n.type || cur->desc.data_type != n.data_type || cur->desc.name != n.name)
                return true;
        }
        return false;
    }

    Endpoint resolve(const BeaconObject& d, const Endpoint& from) const {
        return Endpoint{d.ip_rcp ? d.ip_rcp : from.ip, d.port_rcp ? d.port_rcp : from.port};
    }

    // The union of a beacon and its continuations (a.pending). While the window is open
    // (final == false) objects are only added, into free ids and free PV names, so that the
    // first beacon of an application and new objects need not wait; when it closes
    // (final == true) the model is exactly the union: objects not in it, or changed (type,
    // data type or name), are retired, the rest created, addresses updated.
    void apply_model(App& a, bool final) {
        std::bitset<256> keep;
        for (const auto& n : a.pending) {
            const auto& cur = a.objects[n.id];
            if (cur && cur->desc.type == n.type && cur->desc.data_type == n.data_type &&
                cur->desc.name == n.name)
                keep[n.id] = true;
        }
        std::size_t created = 0, retired = 0;
        if (final) {
            std::bitset<256> listed;
            for (const auto& n : a.pending) listed[n.id] = true;
            for (std::size_t id = 1; id < 256; ++id) {
                auto& cur = a.objects[id];
                if (!cur || keep[id]) continue;
                LOG_INFO(lg, describe(a, cur->desc) << (listed[id] ? " changed" : " retired"));
                unbuild(*cur);
                cur.reset();
                ++retired;
            }
        }
        for (const auto& n : a.pending) {
            if (keep[n.id]) {
                Object& o = *a.objects[n.id];
                o.desc = n;
                o.write_to = resolve(n, a.beacon_from);
                continue;
            }
            if (a.objects[n.id]) continue; // changed: when the window closes
            std::string pv = expand(a.name, n.name);
            if (!final && (db.find(pv) || db.find(pv + "_RBV") || db.find(pv + "_PosErr") ||
                           db.find(pv + "_ErrCode")))
                continue; // maybe a retiring object's name: when the window closes
            auto o = std::make_unique<Object>();
            o->app = &a;
            o->desc = n;
            o->pv = std::move(pv);
            o->write_to = resolve(n, a.beacon_from);
            o->count = n.type == ObjectType::Motor ? kMotorValueCount : 0;
            build(*o);
            if (!o->failed)
                LOG_DEBUG(lg, describe(a, n) << ": " << to_string(n.type) << " " << o->pv);
            a.objects[n.id] = std::move(o);
            ++created;
        }
        if (final) {
            a.assembling = false;
            a.pending.clear();
        }
        a.object_count = 0;
        for (const auto& o : a.objects) a.object_count += o != nullptr;
        if (created || retired) {
            db.init_records();
            if (!a.online)
                for (auto& o : a.objects)
                    if (o) go_offline_object(*o);
            db_dirty = true;
            LOG_INFO(lg, "application " << a.name << " (" << a.beacon_from.str()
                                        << "): " << a.object_count << " objects; " << created
                                        << " new, " << retired << " retired");
        }
        set_if_changed(a.diag.count, double(a.object_count));
        std::vector<uint16_t> p;
        for (const auto& app : apps)
            for (const auto& o : app->objects)
                if (o && o->desc.port_ioc && o->desc.port_ioc != cfg.port)
                    p.push_back(o->desc.port_ioc);
        std::sort(p.begin(), p.end());
        p.erase(std::unique(p.begin(), p.end()), p.end());
        if (p != ports) {
            ports = std::move(p);
            ++ports_version;
        }
    }

    // True if entry e describes an object of the beacon being assembled (data may arrive for a
    // new or changed object before the window closes: dropped, not malformed).
    static bool in_pending(const App& a, const DataEntry& e) {
        if (!a.assembling) return false;
        for (const auto& n : a.pending)
            if (n.id == e.id && n.type == e.type && n.data_type == e.data_type && n.name == e.name)
                return true;
        return false;
    }

    // ---------------------------------------------------------------- data
    // Checks every entry of `data` against the application's model; entries for objects of a
    // beacon still being assembled are marked in `skip`.
    Fault validate(const App& a, std::span<const uint8_t> p) {
        auto view = data.view();
        for (std::size_t i = 0; i < view.size(); ++i) {
            const DataEntry& e = view[i];
            auto at = uint16_t(reinterpret_cast<const uint8_t*>(e.name.data()) - p.data() - 5);
            const Object* o = a.objects[e.id].get();
            bool same = o && e.type == o->desc.type && e.data_type == o->desc.data_type &&
                        e.name == o->desc.name;
            skip[i] = !same && in_pending(a, e);
            if (skip[i]) continue;
            if (!o) return {Malformed::UnknownObject, at, &e, nullptr};
            if (e.type != o->desc.type) return {Malformed::TypeMismatch, uint16_t(at + 1), &e, o};
            if (e.data_type != o->desc.data_type)
                return {Malformed::TypeMismatch, uint16_t(at + 2), &e, o};
            if (e.name != o->desc.name) return {Malformed::NameMismatch, uint16_t(at + 5), &e, o};
            uint16_t expect = o->count;
            for (std::size_t j = 0; j < i && !expect; ++j)
                if (view[j].id == e.id && !skip[j]) expect = view[j].count;
            if (expect && e.count != expect)
                return {Malformed::CountMismatch, uint16_t(at + 3), &e, o};
        }
        return {};
    }

    void on_data(std::span<const uint8_t> p, const Endpoint& from) {
        ParseResult r = parse_data(p, data);
        if (!r) return report(app_by_source(from), {r.reason, r.offset}, from);
        // Attribution: applications whose beacon came from this very endpoint first, then the
        // others from the same address; the first one the whole packet is consistent with.
        App* fault_app = nullptr;
        Fault fault{Malformed::UnknownApplication, 8};
        for (int pass = 0; pass < 2; ++pass)
            for (auto& a : apps) {
                bool exact = a->beacon_from == from;
                if (pass == 0 ? !exact : (exact || a->ip != from.ip)) continue;
                Fault f = validate(*a, p);
                if (f.reason == Malformed::None) return apply(*a);
                if (!fault_app) {
                    fault_app = a.get();
                    fault = f;
                }
            }
        if (!fault_app) return data_before_beacon(from);
        report(fault_app, fault, from);
    }

    // Well-formed data from an address no application has announced itself from: usually the
    // machine started before the IOC (or the IOC restarted) and its next beacon is on the way.
    // Counted, ignored, logged at debug; at warn once it has gone on for timeout_s (beacons sent
    // elsewhere?).
    void data_before_beacon(const Endpoint& from) {
        totals.before_beacon++;
        if (early_first_s < 0 || now - early_last_s > cfg.timeout_s) early_first_s = now;
        early_last_s = now;
        if (now < early_limit.next_s) {
            ++early_limit.suppressed;
            return;
        }
        double since = now - early_first_s;
        log::Level level = since >= cfg.timeout_s ? log::Level::warn : log::Level::debug;
        if (lg.enabled(level)) {
            SB m;
            m << "data from " << from.str() << " before any beacon from that address: ignored";
            if (level == log::Level::warn)
                m << " for " << since << " s (are its beacons sent to udp port " << cfg.port
                  << "?)";
            if (early_limit.suppressed)
                m << " (" << early_limit.suppressed << " more since the last report)";
            lg.write(level, m.str());
        }
        early_limit.next_s = now + 1;
        early_limit.suppressed = 0;
    }

    void learn(Object& o, uint16_t count) {
        o.count = count;
        if (count <= 1 || o.failed || o.desc.type == ObjectType::Motor) return;
        unbuild(o);
        build(o);
        db.init_records();
        if (!o.app->online) go_offline_object(o);
        db_dirty = true;
        LOG_INFO(lg, describe(*o.app, o.desc) << ": " << count << " values, now a waveform");
    }

    void apply(App& a) {
        a.counters.rx++;
        a.model_time = data.timestamp;
        mark_alive(a);
        auto view = data.view();
        for (std::size_t i = 0; i < view.size(); ++i) {
            if (skip[i]) continue;
            const DataEntry& e = view[i];
            Object& o = *a.objects[e.id];
            if (o.count == 0) learn(o, e.count);
            if (o.failed) continue;
            ObjectType t = o.desc.type;
            bool binary = t == ObjectType::BI || t == ObjectType::BO;
            switch (t) {
            case ObjectType::AI:
            case ObjectType::BI:
            case ObjectType::LI:
                set_values(*o.main, o.main_val, o.waveform, e.values, binary);
                o.valued = true;
                break;
            case ObjectType::AO:
            case ObjectType::BO:
            case ObjectType::LO:
                set_values(*o.rb, o.rb_val, o.waveform, e.values, binary);
                o.valued = true;
                // Bumpless: the setpoint starts at the RCP's value, and takes it again once
                // after the application was offline (it may have restarted). Nothing is sent.
                if (!o.out_valued || o.take_readback) {
                    set_values(*o.main, o.main_val, o.waveform, e.values, binary);
                    o.out_valued = true;
                    o.take_readback = false;
                }
                break;
            case ObjectType::Motor: {
                bool changed = o.driver->on_readback(e.values.data(), now);
                set_scalar(*o.pos_err, o.pos_err_val, e.values[3]);
                set_scalar(*o.err_code, o.err_code_val, e.values[4]);
                o.valued = true;
                if (o.take_readback) {
                    o.take_readback = false;
                    // Back from offline and at rest: targets := readback (VAL = RBV), as when
                    // the driver was attached. Nothing is sent.
                    if (o.driver->phase() == RcpMotorDriver::Phase::Idle &&
                        read_field(*o.main, "DMOV") == 1) {
                        o.motor->set_driver(o.driver);
                        break;
                    }
                }
                if (changed) o.motor->poll();
                break;
            }
            }
        }
    }

    // ---------------------------------------------------------------- liveness
    void mark_alive(App& a) {
        a.last_rx_s = now;
        if (!a.online) recover(a);
    }

    void go_offline_object(Object& o) {
        if (o.failed) return;
        o.take_readback = is_output(o.desc.type) || o.driver != nullptr;
        if (o.driver) {
            o.driver->set_comm_error(true);
            o.motor->poll();
            alarm_only(o.pos_err, pv::kStatComm, pv::kInvalid);
            alarm_only(o.err_code, pv::kStatComm, pv::kInvalid);
        } else {
            alarm_only(o.main, pv::kStatComm, pv::kInvalid);
            alarm_only(o.rb, pv::kStatComm, pv::kInvalid);
        }
    }

    void go_offline(App& a) {
        a.online = false;
        for (auto& o : a.objects)
            if (o) go_offline_object(*o);
        set_if_changed(a.diag.online, 0);
        LOG_WARN(lg, "application " << a.name << " (" << a.beacon_from.str()
                                    << "): no beacon or data for " << cfg.timeout_s
                                    << " s; its PVs are INVALID/COMM");
    }

    void recover(App& a) {
        a.online = true;
        for (auto& op : a.objects) {
            if (!op || op->failed) continue;
            Object& o = *op;
            if (o.driver) {
                o.driver->set_comm_error(false);
                o.motor->poll();
                restore(o.pos_err, o.valued);
                restore(o.err_code, o.valued);
            } else {
                restore(o.main, is_output(o.desc.type) ? o.out_valued : o.valued);
                restore(o.rb, o.valued);
            }
        }
        set_if_changed(a.diag.online, 1);
        LOG_INFO(lg, "application " << a.name << " (" << a.beacon_from.str() << ") is back");
    }

    // ---------------------------------------------------------------- diagnostics, .db
    void publish(Diag& d, const Counters& c, const App* a) {
        set_if_changed(d.rx, double(c.rx));
        set_if_changed(d.tx, double(c.tx));
        for (std::size_t m = 0; m < kMalformedReasons; ++m)
            set_if_changed(d.malformed[m], double(c.malformed[m]));
        for (std::size_t r = 0; r < kRefusals; ++r) set_if_changed(d.refused[r], double(c.refused[r]));
        if (a) {
            set_if_changed(d.age, now - a->last_beacon_s);
            set_if_changed(d.online, a->online ? 1 : 0);
            set_if_changed(d.count, double(a->object_count));
        } else {
            set_if_changed(d.count, double(apps.size()));
            set_if_changed(d.before_beacon, double(c.before_beacon));
        }
    }

    void write_db_file() {
        db_dirty = false;
        if (cfg.db_out.empty()) return;
        std::ostringstream os;
        os << "# Generated by the beamctl RCP bridge; rewritten whenever a beacon changes the "
              "PVs.\n";
        for (const auto& r : global.defs) write_record(os, r);
        for (const auto& a : apps) {
            os << "\n# application " << a->name << " from " << a->beacon_from.str() << ": "
               << a->object_count << " objects\n";
            for (const auto& r : a->diag.defs) write_record(os, r);
            for (const auto& o : a->objects)
                if (o)
                    for (const auto& r : o->defs) write_record(os, r);
        }
        std::string tmp = cfg.db_out + ".tmp";
        {
            std::ofstream f(tmp, std::ios::trunc);
            f << os.str();
            f.close();
            if (!f) {
                LOG_ERR(lg, "cannot write " << tmp << ": " << std::strerror(errno));
                return;
            }
        }
        if (std::rename(tmp.c_str(), cfg.db_out.c_str()) != 0)
            LOG_ERR(lg, "cannot rename " << tmp << " to " << cfg.db_out << ": "
                                         << std::strerror(errno));
    }

    void tick(double t) {
        now = t;
        for (auto& a : apps) {
            if (a->assembling && now - a->assembly_start_s >= cfg.continuation_window_s)
                apply_model(*a, true);
            if (a->online && now - a->last_rx_s >= cfg.timeout_s) go_offline(*a);
            // Sent: the acknowledge time-out; offline: a refused command ends at once.
            for (auto& o : a->objects)
                if (o && o->driver &&
                    (!a->online || o->driver->phase() == RcpMotorDriver::Phase::Sent))
                    o->motor->poll();
        }
        if (now >= next_diag_s) {
            for (auto& a : apps) publish(a->diag, a->counters, a.get());
            publish(global, totals, nullptr);
            next_diag_s = now + 1;
        }
        if (db_dirty) write_db_file();
    }

    void handle(std::span<const uint8_t> p, const Endpoint& from, double t) {
        now = t;
        totals.rx++;
        if (!source_allowed(from))
            return refuse(nullptr, Refusal::NotAllowed, from,
                          loopback_only ? "only loopback is accepted (set bridges.rcp.machines or bridges.rcp.allow)"
                                        : "not a configured machine or allowed network");
        if (classify(p) == PacketKind::Beacon)
            on_beacon(p, from);
        else
            on_data(p, from);
        if (db_dirty) write_db_file();
    }
};

BridgeCore::BridgeCore(pv::Database& db, BridgeConfig cfg, SendFn send, Clock clock) {
    cfg.validate();
    impl_ = std::make_unique<Impl>(db, std::move(cfg), std::move(send), std::move(clock));
    if (!impl_->make_diag(impl_->global, impl_->cfg.prefix, false, "rcp bridge"))
        throw Error(SB() << "rcp bridge: cannot create its diagnostic PVs under prefix '"
                         << impl_->cfg.prefix << "' (names taken or invalid; see the log)");
    db.init_records();
    impl_->now = impl_->clock ? impl_->clock() : 0;
    impl_->publish(impl_->global, impl_->totals, nullptr);
}

BridgeCore::~BridgeCore() = default;

void BridgeCore::handle_packet(std::span<const uint8_t> packet, const Endpoint& from,
                               double now_s) {
    impl_->handle(packet, from, now_s);
}

void BridgeCore::tick(double now_s) {
    impl_->tick(now_s);
}

const std::vector<uint16_t>& BridgeCore::data_ports() const {
    return impl_->ports;
}
uint64_t BridgeCore::ports_version() const {
    return impl_->ports_version;
}
const BridgeCore::Counters& BridgeCore::totals() const {
    return impl_->totals;
}
const BridgeConfig& BridgeCore::config() const {
    return impl_->cfg;
}

std::vector<BridgeCore::AppInfo> BridgeCore::applications() const {
    std::vector<AppInfo> v;
    for (const auto& a : impl_->apps)
        v.push_back(AppInfo{a->name, a->beacon_from, a->online, a->object_count, a->last_beacon_s,
                            a->counters});
    return v;
}

std::string BridgeCore::pv_name(std::string_view application, std::string_view object_name) const {
    return impl_->expand(application, object_name);
}

} // namespace beamctl::bridge::rcp
