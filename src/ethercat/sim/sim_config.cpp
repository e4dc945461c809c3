#include "ethercat/sim/sim_config.hpp"

#include "core/error.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <arpa/inet.h>
#include <cmath>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <netinet/in.h>
#include <poll.h>
#include <sstream>
#include <sys/socket.h>
#include <unistd.h>

namespace beamctl::ethercat::sim {
namespace {

// YAML reading with file:line:col in every error.
struct Reader {
    const std::string& file;

    std::string where(const YAML::Node& n) const {
        return SB() << file << ":" << n.Mark().line + 1 << ":" << n.Mark().column + 1;
    }
    [[noreturn]] void fail(const YAML::Node& n, const std::string& msg) const { throw Error(SB() << where(n) << ": " << msg); }

    void map(const YAML::Node& n, const char* what) const {
        if (!n.IsMap()) fail(n, SB() << what << " should be a mapping");
    }
    void only_keys(const YAML::Node& n, std::initializer_list<const char*> keys, const char* what) const {
        map(n, what);
        for (auto kv : n) {
            std::string k = kv.first.as<std::string>();
            bool ok = false;
            for (const char* a : keys) ok = ok || k == a;
            if (!ok) {
                std::string list;
                for (const char* a : keys) list += (list.empty() ? "" : ", ") + std::string(a);
                fail(kv.first, SB() << "unknown key '" << k << "' in " << what << " (expected " << list << ")");
            }
        }
    }
    double num(const YAML::Node& parent, const char* key, double def) const {
        YAML::Node n = parent[key];
        return n ? num(n, key) : def;
    }
    double num(const YAML::Node& n, const char* key) const {
        double v;
        try {
            v = n.as<double>();
        } catch (const YAML::Exception&) {
            fail(n, SB() << key << " should be a number");
        }
        if (!std::isfinite(v)) fail(n, SB() << key << " should be a finite number");
        return v;
    }
    double positive(const YAML::Node& parent, const char* key, double def) const {
        double v = num(parent, key, def);
        if (v <= 0) fail(parent[key], SB() << key << " should be > 0 (got " << v << ")");
        return v;
    }
    double non_negative(const YAML::Node& parent, const char* key, double def) const {
        double v = num(parent, key, def);
        if (v < 0) fail(parent[key], SB() << key << " should be >= 0 (got " << v << ")");
        return v;
    }
    bool flag(const YAML::Node& parent, const char* key, bool def) const {
        YAML::Node n = parent[key];
        if (!n) return def;
        try {
            return n.as<bool>();
        } catch (const YAML::Exception&) {
            fail(n, SB() << key << " should be true or false");
        }
    }
    std::string str(const YAML::Node& n, const char* what) const {
        if (!n.IsScalar()) fail(n, SB() << what << " should be a string");
        return n.as<std::string>();
    }
    // "s3" (a slave) or "s3.binaryOutput01" (an entry); "ec0." in front is allowed.
    EntryRef ref(const YAML::Node& n, bool want_entry) const {
        std::string s = str(n, want_entry ? "an entry" : "a slave");
        std::string orig = s;
        if (s.rfind("ec", 0) == 0 && s.find('.') != std::string::npos) s = s.substr(s.find('.') + 1);
        std::size_t dot = s.find('.');
        std::string head = dot == std::string::npos ? s : s.substr(0, dot);
        bool ok = head.size() >= 2 && head[0] == 's' &&
                  head.find_first_not_of("0123456789", 1) == std::string::npos && head.size() < 8;
        if (!ok || want_entry != (dot != std::string::npos) || (want_entry && dot + 1 >= s.size()))
            fail(n, SB() << "'" << orig << "' should look like "
                         << (want_entry ? "s<position>.<entry>, e.g. s1.binaryInput01" : "s<position>, e.g. s11"));
        EntryRef r;
        r.slave = std::stoi(head.substr(1));
        if (want_entry) r.entry = s.substr(dot + 1);
        r.where = where(n);
        return r;
    }
};

SignalModel::Shape parse_shape(const Reader& rd, const YAML::Node& n) {
    std::string s = rd.str(n, "shape");
    static const std::pair<const char*, SignalModel::Shape> shapes[] = {
        {"constant", SignalModel::Shape::Constant}, {"sine", SignalModel::Shape::Sine},
        {"square", SignalModel::Shape::Square},     {"ramp", SignalModel::Shape::Ramp},
        {"noise", SignalModel::Shape::Noise}};
    for (auto& [name, shape] : shapes)
        if (s == name) return shape;
    rd.fail(n, SB() << "unknown shape '" << s << "' (expected constant, sine, square, ramp, noise)");
}

StageConfig parse_stage(const Reader& rd, const YAML::Node& n) {
    rd.only_keys(n, {"name", "drive", "mass", "friction", "damping", "travel", "start", "pitch", "steps_per_rev",
                     "max_force", "velocity_scale", "quick_stop_decel", "overload_time", "feedback_counts_per_rev",
                     "encoders", "limits", "home"},
                 "a stage");
    StageConfig c;
    c.where = rd.where(n);
    if (!n["name"]) rd.fail(n, "a stage needs name:");
    if (!n["drive"]) rd.fail(n, "a stage needs drive: (the slave of its drive terminal, e.g. s11)");
    c.stage.name = rd.str(n["name"], "name");
    c.drive = rd.ref(n["drive"], false);
    c.stage.mass = rd.positive(n, "mass", c.stage.mass);
    c.stage.friction = rd.non_negative(n, "friction", c.stage.friction);
    c.stage.damping = rd.non_negative(n, "damping", c.stage.damping);
    if (auto t = n["travel"]) {
        if (!t.IsSequence() || t.size() != 2) rd.fail(t, "travel should be [min, max]");
        c.stage.min = rd.num(t[0], "travel min");
        c.stage.max = rd.num(t[1], "travel max");
        if (c.stage.min >= c.stage.max) rd.fail(t, SB() << "travel: min " << c.stage.min << " should be below max " << c.stage.max);
    }
    c.stage.start = rd.num(n, "start", 0);
    if (c.stage.start < c.stage.min || c.stage.start > c.stage.max)
        rd.fail(n["start"], SB() << "start " << c.stage.start << " is outside travel [" << c.stage.min << ", " << c.stage.max << "]");
    c.motor.units_per_rev = rd.positive(n, "pitch", c.motor.units_per_rev);
    c.motor.steps_per_rev = rd.positive(n, "steps_per_rev", c.motor.steps_per_rev);
    c.motor.max_force = rd.positive(n, "max_force", c.motor.max_force);
    c.motor.velocity_scale = rd.positive(n, "velocity_scale", c.motor.velocity_scale);
    c.motor.quick_stop_decel = rd.positive(n, "quick_stop_decel", c.motor.quick_stop_decel);
    c.motor.overload_time = rd.positive(n, "overload_time", c.motor.overload_time);
    c.feedback_counts_per_rev = rd.non_negative(n, "feedback_counts_per_rev", 0);
    if (auto es = n["encoders"]) {
        if (!es.IsSequence()) rd.fail(es, "encoders should be a list");
        for (auto e : es) {
            rd.only_keys(e, {"entry", "counts_per_unit", "absolute", "zero", "index_every", "index_offset"}, "an encoder");
            if (!e["entry"]) rd.fail(e, "an encoder needs entry: (e.g. s9.positionActual01)");
            StageConfig::Encoder enc;
            enc.entry = rd.ref(e["entry"], true);
            enc.counts_per_unit = rd.num(e, "counts_per_unit", enc.counts_per_unit);
            if (enc.counts_per_unit == 0) rd.fail(e["counts_per_unit"], "counts_per_unit should not be 0");
            enc.absolute = rd.flag(e, "absolute", false);
            enc.zero = rd.num(e, "zero", 0);
            enc.index_every = rd.non_negative(e, "index_every", 0);
            enc.index_offset = rd.num(e, "index_offset", 0);
            c.encoders.push_back(enc);
        }
    }
    auto sw = [&](const YAML::Node& s, SwitchModel::Kind kind, bool nc_default) {
        rd.only_keys(s, {"input", "at", "width", "normally_closed"}, kind == SwitchModel::Kind::Home ? "home" : "a limit");
        if (!s["input"]) rd.fail(s, "a switch needs input: (e.g. s1.binaryInput01)");
        if (!s["at"]) rd.fail(s, "a switch needs at: (its position in stage units)");
        StageConfig::Switch x;
        x.kind = kind;
        x.input = rd.ref(s["input"], true);
        x.at = rd.num(s, "at", 0);
        x.width = rd.positive(s, "width", 1);
        x.normally_closed = rd.flag(s, "normally_closed", nc_default);
        c.switches.push_back(x);
    };
    if (auto l = n["limits"]) {
        rd.only_keys(l, {"forward", "backward"}, "limits");
        if (l["forward"]) sw(l["forward"], SwitchModel::Kind::Forward, true);
        if (l["backward"]) sw(l["backward"], SwitchModel::Kind::Backward, true);
    }
    if (auto h = n["home"]) sw(h, SwitchModel::Kind::Home, false);
    return c;
}

SignalConfig parse_signal(const Reader& rd, const YAML::Node& n) {
    rd.only_keys(n, {"to", "shape", "amplitude", "offset", "frequency", "phase", "stage", "gain", "noise", "full_scale"},
                 "a signal");
    SignalConfig c;
    c.where = rd.where(n);
    if (!n["to"]) rd.fail(n, "a signal needs to: (an analog input, e.g. s5.analogInput01)");
    c.to = rd.ref(n["to"], true);
    if (n["stage"] && n["shape"]) rd.fail(n["shape"], "a signal is either a generator (shape:) or a sensor (stage:), not both");
    if (n["stage"]) {
        c.stage = rd.str(n["stage"], "stage");
        c.shape = SignalModel::Shape::StagePosition;
    } else if (n["shape"]) {
        c.shape = parse_shape(rd, n["shape"]);
    }
    c.amplitude = rd.num(n, "amplitude", 0);
    c.offset = rd.num(n, "offset", 0);
    c.frequency = rd.non_negative(n, "frequency", 1);
    c.phase = rd.num(n, "phase", 0);
    c.gain = rd.num(n, "gain", 1);
    c.noise = rd.non_negative(n, "noise", 0);
    c.full_scale = rd.positive(n, "full_scale", 10);
    return c;
}

} // namespace

DriveKind drive_kind(const DeviceDesc& d) {
    const std::string& t = d.type;
    bool family = t.size() >= 4 && (t.rfind("EL", 0) == 0 || t.rfind("EP", 0) == 0);
    bool entries = has_entry(d, "driveControl01") && has_entry(d, "driveStatus01") &&
                   (has_entry(d, "velocitySetpoint01") || has_entry(d, "positionSetpoint01"));
    if (!family || !entries) return DriveKind::None;
    if (t.compare(2, 2, "70") == 0) return DriveKind::Stepper;
    if (t.compare(2, 2, "72") == 0) return DriveKind::Cia402;
    return DriveKind::None;
}

SimConfig SimConfig::load(const std::string& path, const Catalog& catalog) {
    std::ifstream f(path);
    if (!f) throw Error(SB() << path << ": cannot open simulator configuration: " << std::strerror(errno));
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), path, catalog);
}

SimConfig SimConfig::parse(const std::string& text, const std::string& file, const Catalog& catalog) {
    YAML::Node root;
    try {
        root = YAML::Load(text);
    } catch (const YAML::ParserException& e) {
        throw Error(SB() << file << ":" << e.mark.line + 1 << ":" << e.mark.column + 1 << ": " << e.msg);
    }
    Reader rd{file};
    SimConfig c;
    if (!root || root.IsNull()) return c;
    if (!root.IsMap()) rd.fail(root, "expected a mapping with slaves:, wiring:, stages:, signals:");
    rd.only_keys(root, {"slaves", "wiring", "stages", "signals"}, "the simulator configuration");
    auto list = [&](const char* key) {
        YAML::Node n = root[key];
        if (n && !n.IsSequence()) rd.fail(n, SB() << key << ": should be a list");
        return n;
    };
    if (auto s = list("slaves")) {
        for (auto item : s) {
            rd.only_keys(item, {"position", "type"}, "a slave");
            if (!item["position"] || !item["type"]) rd.fail(item, "a slave needs position: and type:");
            int pos;
            try {
                pos = item["position"].as<int>();
            } catch (const YAML::Exception&) {
                rd.fail(item["position"], "position should be an integer");
            }
            std::string type = rd.str(item["type"], "type");
            if (!catalog.find(type)) rd.fail(item["type"], SB() << "unknown device type '" << type << "'");
            if (pos != int(c.slaves.size()))
                rd.fail(item["position"], SB() << "positions must be 0, 1, 2, ... in order (got " << pos << ", expected "
                                               << c.slaves.size() << ")");
            c.slaves.emplace_back(pos, type);
        }
    }
    if (auto w = list("wiring")) {
        for (auto item : w) {
            rd.only_keys(item, {"from", "to"}, "a wire");
            if (!item["from"] || !item["to"]) rd.fail(item, "a wire needs from: and to:");
            c.wiring.push_back(Wire{rd.ref(item["from"], true), rd.ref(item["to"], true)});
        }
    }
    if (auto st = list("stages"))
        for (auto item : st) {
            c.stages.push_back(parse_stage(rd, item));
            for (std::size_t i = 0; i + 1 < c.stages.size(); ++i)
                if (c.stages[i].stage.name == c.stages.back().stage.name)
                    rd.fail(item["name"], SB() << "stage '" << c.stages.back().stage.name << "' is defined twice (first at "
                                               << c.stages[i].where << ")");
        }
    if (auto sg = list("signals"))
        for (auto item : sg) c.signals.push_back(parse_signal(rd, item));
    if (!c.slaves.empty()) { // check the plant against the slaves now, with the file's places
        Segment scratch;
        c.build(scratch, catalog);
    }
    return c;
}

namespace {

// Binding with the configuration's place in every error; each input may have one driver.
struct Binder {
    Segment& seg;
    std::vector<std::pair<std::pair<int, std::string>, std::string>> driven; // {slave, entry} -> where

    IoPoint bind(const EntryRef& r) {
        try {
            return bind_io(seg, r.slave, r.entry);
        } catch (const Error& e) {
            throw Error(SB() << r.where << ": " << e.what());
        }
    }
    // An input some model writes: must be an input and not yet driven by another.
    IoPoint input(const EntryRef& r, const char* by) {
        IoPoint p = bind(r);
        if (p.loc.output) throw Error(SB() << r.where << ": " << r.entry << " of slave " << r.slave << " is an output; " << by << " drives an input");
        for (auto& [k, where] : driven)
            if (k.first == r.slave && k.second == r.entry)
                throw Error(SB() << r.where << ": s" << r.slave << "." << r.entry << " is already driven (by " << where << ")");
        driven.push_back({{r.slave, r.entry}, r.where});
        return p;
    }
    void claim(int slave, const std::string& entry, const std::string& where) { driven.push_back({{slave, entry}, where}); }
};

std::unique_ptr<Stage> make_stage(Binder& b, const DeviceDesc& d, int slave, const StageParams& sp, const MotorParams& mp,
                                  double feedback_counts_per_rev, const std::string& where) {
    DriveKind kind = drive_kind(d);
    std::unique_ptr<DriveTerminal> drive;
    if (kind == DriveKind::Stepper) {
        drive = std::make_unique<StepperTerminal>(b.seg, slave, mp);
    } else {
        MotorParams servo = mp; // CSP targets count in the drive's feedback frame
        if (feedback_counts_per_rev > 0) servo.position_scale = feedback_counts_per_rev;
        servo.position_start = 0; // the resolver is absolute from position 0
        drive = std::make_unique<Cia402Terminal>(b.seg, slave, servo);
    }
    auto st = std::make_unique<Stage>(sp, std::move(drive));
    b.claim(slave, "driveStatus01", where);
    if (has_entry(d, "velocityActual01")) b.claim(slave, "velocityActual01", where);
    if (has_entry(d, "positionActual01")) { // the drive's own feedback (encoder input, resolver)
        double cpr = feedback_counts_per_rev > 0 ? feedback_counts_per_rev
                                                 : kind == DriveKind::Stepper ? mp.steps_per_rev * 64 : 1048576.0;
        bool absolute = kind == DriveKind::Cia402; // resolver/motor encoder with multi-turn
        st->encoders.emplace_back(b.seg, slave, "positionActual01", cpr / mp.units_per_rev, absolute, 0.0, sp.start);
        b.claim(slave, "positionActual01", where);
        if (has_entry(d, "encoderStatus01")) b.claim(slave, "encoderStatus01", where);
    }
    return st;
}

} // namespace

std::shared_ptr<Plant> SimConfig::build(Segment& seg, const Catalog& catalog) const {
    for (auto& [pos, type] : slaves) seg.add(*catalog.find(type));
    auto plant = std::make_shared<Plant>();
    Binder b{seg, {}};
    std::vector<int> claimed_drives;
    for (const StageConfig& sc : stages) {
        const EntryRef& dr = sc.drive;
        if (dr.slave >= int(seg.size())) throw Error(SB() << dr.where << ": no slave at position " << dr.slave);
        const DeviceDesc& d = seg.slave(std::size_t(dr.slave)).desc();
        if (drive_kind(d) == DriveKind::None)
            throw Error(SB() << dr.where << ": slave " << dr.slave << " is a " << d.type
                             << ", not a drive terminal this simulator models (EL70x1 stepper, EL72x1 servo)");
        for (int c : claimed_drives)
            if (c == dr.slave) throw Error(SB() << dr.where << ": drive s" << dr.slave << " already moves another stage");
        claimed_drives.push_back(dr.slave);
        auto st = make_stage(b, d, dr.slave, sc.stage, sc.motor, sc.feedback_counts_per_rev, sc.where);
        for (const auto& e : sc.encoders) {
            b.input(e.entry, "an encoder");
            try {
                st->encoders.emplace_back(seg, e.entry.slave, e.entry.entry, e.counts_per_unit, e.absolute, e.zero, sc.stage.start,
                                          e.index_every, e.index_offset);
            } catch (const Error& err) {
                throw Error(SB() << e.entry.where << ": " << err.what());
            }
        }
        for (const auto& s : sc.switches) {
            SwitchModel m;
            m.kind = s.kind;
            m.input = b.input(s.input, "a switch");
            m.at = s.at;
            m.width = s.width;
            m.normally_closed = s.normally_closed;
            st->switches.push_back(m);
        }
        plant->stages_.push_back(std::move(st));
    }
    // Every other drive moves a default stage: 1 kg, 1 N friction, no hard stops, no switches.
    for (std::size_t p = 0; p < seg.size(); ++p) {
        const DeviceDesc& d = seg.slave(p).desc();
        if (drive_kind(d) == DriveKind::None ||
            std::find(claimed_drives.begin(), claimed_drives.end(), int(p)) != claimed_drives.end())
            continue;
        StageParams sp;
        sp.name = SB() << "s" << p;
        plant->stages_.push_back(make_stage(b, d, int(p), sp, MotorParams{}, 0, SB() << "the default stage of s" << p));
    }
    for (const SignalConfig& sc : signals) {
        IoPoint to = b.input(sc.to, "a signal");
        if (to.loc.bits != 16)
            throw Error(SB() << sc.to.where << ": " << sc.to.entry << " has " << int(to.loc.bits)
                             << " bits; a signal drives a 16-bit analog input");
        SignalModel m;
        m.shape = sc.shape;
        m.amplitude = sc.amplitude;
        m.offset = sc.offset;
        m.frequency = sc.frequency;
        m.phase = sc.phase;
        m.gain = sc.gain;
        m.noise = sc.noise;
        if (!sc.stage.empty()) {
            m.stage = plant->find_stage(sc.stage);
            if (!m.stage) throw Error(SB() << sc.where << ": no stage named '" << sc.stage << "'");
        }
        m.channel = std::make_unique<AnalogInputChannel>(seg, sc.to.slave, sc.to.entry, sc.full_scale);
        plant->signals.push_back(std::move(m));
    }
    for (const Wire& w : wiring) {
        WireModel m;
        m.from = b.bind(w.from);
        m.to = b.input(w.to, "a wire");
        if (m.from.loc.bits != m.to.loc.bits)
            throw Error(SB() << w.from.where << ": " << w.from.entry << " has " << int(m.from.loc.bits) << " bits but "
                             << w.to.entry << " has " << int(m.to.loc.bits));
        plant->wires.push_back(m);
    }
    // Terminal behaviour that needs no configuration: EL3702 sample counters, EL1252 latches.
    for (std::size_t p = 0; p < seg.size(); ++p) {
        for (std::string ch : {"01", "02", "03", "04"}) {
            IoPoint cc = bind_optional(seg, int(p), "cycleCounter" + ch);
            if (cc.bound() && !cc.loc.output) plant->cycle_counters.push_back(CycleCounter{cc});
            IoPoint pos = bind_optional(seg, int(p), "timestampLatchPositive" + ch);
            IoPoint in = bind_optional(seg, int(p), "binaryInput" + ch);
            if (pos.bound() && in.bound())
                plant->latches.push_back(LatchInput{in, pos, bind_optional(seg, int(p), "timestampLatchNegative" + ch)});
        }
    }
    plant->steps = 0;
    seg.on_frame = [plant](Segment& s) { plant->step(s); };
    return plant;
}

UdpServer::UdpServer(Segment& seg, const std::string& bind_addr, uint16_t port) : seg_(seg) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    if (inet_pton(AF_INET, bind_addr.c_str(), &a.sin_addr) != 1)
        throw Error(SB() << "sim: '" << bind_addr << "' is not an IPv4 address");
    fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0 || bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
        throw Error(SB() << "sim: cannot bind UDP " << bind_addr << ":" << port << ": " << std::strerror(errno));
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
}

UdpServer::~UdpServer() {
    if (fd_ >= 0) ::close(fd_);
}

bool UdpServer::serve_one(int timeout_ms) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) <= 0) return false;
    uint8_t buf[kMaxFrame + 64];
    sockaddr_in from{};
    socklen_t flen = sizeof from;
    ssize_t n = recvfrom(fd_, buf, sizeof buf, 0, reinterpret_cast<sockaddr*>(&from), &flen);
    if (n <= 0) return false;
    if (std::size_t(n) > kMaxFrame) {
        ++malformed;
        return true;
    }
    auto now = std::chrono::system_clock::now().time_since_epoch();
    int64_t ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count() - 946684800LL * 1000000000LL;
    seg_.set_time(uint64_t(ns));
    ++frames;
    if (!seg_.process(buf, std::size_t(n))) return true; // lost on purpose
    sendto(fd_, buf, std::size_t(n), 0, reinterpret_cast<sockaddr*>(&from), flen);
    return true;
}

void UdpServer::run(const volatile bool& stop, int poll_ms) {
    while (!stop) serve_one(poll_ms);
}

} // namespace beamctl::ethercat::sim
