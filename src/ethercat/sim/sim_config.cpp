#include "ethercat/sim/sim_config.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"

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

using config::above;
using config::at_least;
using config::between;
using config::Range;
using config::YamlNode;
using config::YamlReader;

// "s3" (a slave) or "s3.binaryOutput01" (an entry); "ec0." in front is allowed. nullopt after an
// error (or when absent).
std::optional<EntryRef> ref(const YamlNode& n, bool want_entry) {
    auto text = n.string();
    if (!text) return std::nullopt;
    std::string s = *text;
    if (s.rfind("ec", 0) == 0 && s.find('.') != std::string::npos) s = s.substr(s.find('.') + 1);
    std::size_t dot = s.find('.');
    std::string head = dot == std::string::npos ? s : s.substr(0, dot);
    bool ok = head.size() >= 2 && head[0] == 's' &&
              head.find_first_not_of("0123456789", 1) == std::string::npos && head.size() < 8;
    if (!ok || want_entry != (dot != std::string::npos) || (want_entry && dot + 1 >= s.size())) {
        n.error(SB() << "'" << *text << "' should look like "
                     << (want_entry ? "s<position>.<entry>, e.g. s1.binaryInput01"
                                    : "s<position>, e.g. s11"));
        return std::nullopt;
    }
    EntryRef r;
    r.slave = std::stoi(head.substr(1));
    if (want_entry) r.entry = s.substr(dot + 1);
    r.where = n.where();
    return r;
}

double num(const YamlNode& n, const char* key, double def, Range r = {}) {
    return n[key].number(r).value_or(def);
}

// A stage; nullopt when it cannot be built (no name or drive).
std::optional<StageConfig> parse_stage(const YamlNode& n) {
    if (!n.keys({"name", "drive", "mass", "friction", "damping", "travel", "start", "pitch",
                 "steps_per_rev", "max_force", "velocity_scale", "quick_stop_decel",
                 "overload_time", "feedback_counts_per_rev", "encoders", "limits", "home"}))
        return std::nullopt;
    StageConfig c;
    c.where = n.where();
    auto name = n.required("name").string();
    auto drive = ref(n.required("drive", " (the slave of its drive terminal, e.g. s11)"), false);
    c.stage.name = name.value_or("");
    c.stage.mass = num(n, "mass", c.stage.mass, above(0));
    c.stage.friction = num(n, "friction", c.stage.friction, at_least(0));
    c.stage.damping = num(n, "damping", c.stage.damping, at_least(0));
    if (YamlNode t = n["travel"]) {
        auto items = t.list();
        if (t.is_list() && items.size() != 2) t.error("should be [min, max]");
        if (items.size() == 2) {
            auto lo = items[0].number(), hi = items[1].number();
            if (lo && hi && *lo >= *hi)
                t.error(SB() << "min " << *lo << " should be below max " << *hi);
            else if (lo && hi)
                c.stage.min = *lo, c.stage.max = *hi;
        }
    }
    if (auto start = n["start"].number()) {
        if (*start < c.stage.min || *start > c.stage.max)
            n["start"].error(SB() << *start << " is outside travel [" << c.stage.min << ", "
                                  << c.stage.max << "]");
        else
            c.stage.start = *start;
    }
    c.motor.units_per_rev = num(n, "pitch", c.motor.units_per_rev, above(0));
    c.motor.steps_per_rev = num(n, "steps_per_rev", c.motor.steps_per_rev, above(0));
    c.motor.max_force = num(n, "max_force", c.motor.max_force, above(0));
    c.motor.velocity_scale = num(n, "velocity_scale", c.motor.velocity_scale, above(0));
    c.motor.quick_stop_decel = num(n, "quick_stop_decel", c.motor.quick_stop_decel, above(0));
    c.motor.overload_time = num(n, "overload_time", c.motor.overload_time, above(0));
    c.feedback_counts_per_rev = num(n, "feedback_counts_per_rev", 0, at_least(0));
    for (const YamlNode& e : n["encoders"].list()) {
        if (!e.keys({"entry", "counts_per_unit", "absolute", "zero", "index_every",
                     "index_offset"}))
            continue;
        StageConfig::Encoder enc;
        auto entry = ref(e.required("entry", " (e.g. s9.positionActual01)"), true);
        if (auto cpu = e["counts_per_unit"].number()) {
            if (*cpu == 0)
                e["counts_per_unit"].error("should not be 0");
            else
                enc.counts_per_unit = *cpu;
        }
        enc.absolute = e["absolute"].boolean().value_or(false);
        enc.zero = num(e, "zero", 0);
        enc.index_every = num(e, "index_every", 0, at_least(0));
        enc.index_offset = num(e, "index_offset", 0);
        if (entry) {
            enc.entry = *entry;
            c.encoders.push_back(enc);
        }
    }
    auto sw = [&](const YamlNode& s, SwitchModel::Kind kind, bool nc_default) {
        if (!s.keys({"input", "at", "width", "normally_closed"})) return;
        StageConfig::Switch x;
        x.kind = kind;
        auto input = ref(s.required("input", " (e.g. s1.binaryInput01)"), true);
        x.at = s.required("at", " (its position in stage units)").number().value_or(0);
        x.width = num(s, "width", 1, above(0));
        x.normally_closed = s["normally_closed"].boolean().value_or(nc_default);
        if (input) {
            x.input = *input;
            c.switches.push_back(x);
        }
    };
    if (YamlNode l = n["limits"]; l.keys({"forward", "backward"})) {
        if (l["forward"]) sw(l["forward"], SwitchModel::Kind::Forward, true);
        if (l["backward"]) sw(l["backward"], SwitchModel::Kind::Backward, true);
    }
    if (n["home"]) sw(n["home"], SwitchModel::Kind::Home, false);
    if (!name || !drive) return std::nullopt;
    c.drive = *drive;
    return c;
}

std::optional<SignalConfig> parse_signal(const YamlNode& n) {
    if (!n.keys({"to", "shape", "amplitude", "offset", "frequency", "phase", "stage", "beam", "gain",
                 "noise", "full_scale"}))
        return std::nullopt;
    SignalConfig c;
    c.where = n.where();
    auto to = ref(n.required("to", " (an analog input, e.g. s5.analogInput01)"), true);
    if (int(n.has("stage")) + int(n.has("shape")) + int(n.has("beam")) > 1)
        n["shape"].error("a signal is one of a generator (shape:), a sensor (stage:) or a diode (beam:)");
    if (YamlNode b = n["beam"]) {
        if (auto d = b.integer(between(0, 4))) {
            c.beam = int(*d);
            c.shape = SignalModel::Shape::Beam;
        }
    } else if (auto stage = n["stage"].string()) {
        c.stage = *stage;
        c.shape = SignalModel::Shape::StagePosition;
    } else if (auto shape = n["shape"].string()) {
        static const std::pair<const char*, SignalModel::Shape> shapes[] = {
            {"constant", SignalModel::Shape::Constant}, {"sine", SignalModel::Shape::Sine},
            {"square", SignalModel::Shape::Square},     {"ramp", SignalModel::Shape::Ramp},
            {"noise", SignalModel::Shape::Noise}};
        bool found = false;
        for (auto& [name, sh] : shapes)
            if (*shape == name) c.shape = sh, found = true;
        if (!found)
            n["shape"].error(SB() << "unknown shape '" << *shape
                                  << "' (expected constant, sine, square, ramp, noise)");
    }
    c.amplitude = num(n, "amplitude", 0);
    c.offset = num(n, "offset", 0);
    c.frequency = num(n, "frequency", 1, at_least(0));
    c.phase = num(n, "phase", 0);
    c.gain = num(n, "gain", 1);
    c.noise = num(n, "noise", 0, at_least(0));
    c.full_scale = num(n, "full_scale", 10, above(0));
    if (!to) return std::nullopt;
    c.to = *to;
    return c;
}

// [a, b] into x, y.
void pair(const YamlNode& n, double& x, double& y, Range r = {}) {
    if (!n) return;
    auto items = n.list();
    if (items.size() != 2) {
        n.error("should be [x, y]");
        return;
    }
    auto a = items[0].number(r), b = items[1].number(r);
    if (a && b) x = *a, y = *b;
}

std::optional<BeamConfig> parse_beam(const YamlNode& n) {
    if (!n || !n.keys({"flux", "centre", "size", "vibration", "drift", "optics", "slit"})) return std::nullopt;
    BeamConfig c;
    c.where = n.where();
    BeamParams& p = c.params;
    p.flux = num(n, "flux", p.flux, above(0));
    pair(n["centre"], p.x0, p.y0);
    pair(n["size"], p.sigma_x, p.sigma_y, above(0));
    if (YamlNode v = n["vibration"]; v && v.keys({"amplitude", "frequency"})) {
        pair(v["amplitude"], p.vibration_x, p.vibration_y, at_least(0));
        p.vibration_hz = num(v, "frequency", 0, at_least(0));
    }
    pair(n["drift"], p.drift_x, p.drift_y);
    for (const YamlNode& item : n["optics"].list()) {
        if (!item.keys({"stage", "output", "x", "y", "full_scale"})) continue;
        BeamConfig::Lever l;
        l.where = item.where();
        if (item.has("stage") == item.has("output")) {
            item.error("a lever names a stage (stage:) or an analog output (output:), one of them");
            continue;
        }
        if (auto st = item["stage"].string()) l.stage = *st;
        if (YamlNode o = item["output"]) {
            auto r = ref(o, true);
            if (!r) continue;
            l.output = *r;
        }
        l.x = num(item, "x", 0);
        l.y = num(item, "y", 0);
        l.full_scale = num(item, "full_scale", 10, above(0));
        c.optics.push_back(std::move(l));
    }
    if (YamlNode s = n["slit"]; s && s.keys({"top", "bottom", "left", "right"})) {
        c.top = s["top"].string().value_or("");
        c.bottom = s["bottom"].string().value_or("");
        c.left = s["left"].string().value_or("");
        c.right = s["right"].string().value_or("");
    }
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
    ErrorList errors;
    SimConfig c = load(path, catalog, errors);
    errors.throw_if_any();
    return c;
}

SimConfig SimConfig::load(const std::string& path, const Catalog& catalog, ErrorList& errors) {
    std::ifstream f(path);
    if (!f) {
        errors.add(SB() << path << ": cannot open simulator configuration: " << std::strerror(errno));
        return {};
    }
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), path, catalog, errors);
}

SimConfig SimConfig::parse(const std::string& text, const std::string& file, const Catalog& catalog) {
    ErrorList errors;
    SimConfig c = parse(text, file, catalog, errors);
    errors.throw_if_any();
    return c;
}

SimConfig SimConfig::parse(const std::string& text, const std::string& file, const Catalog& catalog,
                           ErrorList& errors) {
    YamlReader rd(file, text, "the simulator configuration");
    SimConfig c;
    YamlNode root = rd.root();
    if (root && !root.is_null() && !root.is_map())
        rd.error(rd.loc(root.yaml()), "expected a mapping with slaves:, wiring:, stages:, signals:, beam:, bridges:, clock:");
    else if (root.keys({"slaves", "wiring", "stages", "signals", "beam", "bridges", "clock"}) && !root.is_null()) {
        c.beam = parse_beam(root["beam"]);
        if (YamlNode k = root["clock"]; k.keys({"offset_us", "drift_ppm"}) && k) {
            c.clock_offset_us = k["offset_us"].number(between(-1e9, 1e9)).value_or(0);
            c.clock_drift_ppm = k["drift_ppm"].number(between(-1000, 1000)).value_or(0);
        }
        for (const YamlNode& item : root["slaves"].list()) {
            if (!item.keys({"position", "type"})) continue;
            auto pos = item.required("position").integer(between(0, 65534));
            auto type = item.required("type").string();
            if (type && !catalog.find(*type)) {
                item["type"].error(catalog.unknown_type_error(*type));
                type.reset();
            }
            if (pos && *pos != int64_t(c.slaves.size()))
                item["position"].error(SB() << "positions must be 0, 1, 2, ... in order (got "
                                            << *pos << ", expected " << c.slaves.size() << ")");
            if (pos && type && *pos == int64_t(c.slaves.size())) c.slaves.emplace_back(int(*pos), *type);
        }
        for (const YamlNode& item : root["wiring"].list()) {
            if (!item.keys({"from", "to"})) continue;
            auto from = ref(item.required("from"), true);
            auto to = ref(item.required("to"), true);
            if (from && to) c.wiring.push_back(Wire{*from, *to});
        }
        for (const YamlNode& item : root["stages"].list()) {
            auto st = parse_stage(item);
            if (!st) continue;
            for (const StageConfig& other : c.stages)
                if (other.stage.name == st->stage.name)
                    item["name"].error(SB() << "stage '" << st->stage.name
                                            << "' is defined twice (first at " << other.where << ")");
            c.stages.push_back(std::move(*st));
        }
        for (const YamlNode& item : root["signals"].list())
            if (auto sg = parse_signal(item)) c.signals.push_back(std::move(*sg));
        for (const YamlNode& item : root["bridges"].list()) {
            if (!item.keys({"slave", "pair"})) continue;
            auto slave = item.required("slave").integer(between(0, 65534));
            auto pair = item.required("pair", " (the name both sides' plants give the EL6692)").string();
            if (pair && pair->empty()) item["pair"].error("should name the pair");
            for (const BridgeConfig& other : c.bridges)
                if (slave && other.slave == *slave) item["slave"].error(SB() << "slave " << *slave << " is bridged twice (first at " << other.where << ")");
            if (slave && pair && !pair->empty()) c.bridges.push_back(BridgeConfig{int(*slave), *pair, item.where()});
        }
    }
    const bool ok = rd.ok();
    rd.take_errors(errors);
    if (ok && !c.slaves.empty()) { // the plant against the slaves now, with the file's places
        Segment scratch;
        c.build(scratch, catalog, errors);
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
    ErrorList errors;
    auto plant = build(seg, catalog, errors);
    errors.throw_if_any();
    return plant;
}

std::shared_ptr<Plant> SimConfig::build(Segment& seg, const Catalog& catalog, ErrorList& errors) const {
    for (auto& [pos, type] : slaves) seg.add(*catalog.find(type));
    auto plant = std::make_shared<Plant>();
    Binder b{seg, {}};
    std::vector<int> claimed_drives;
    for (const StageConfig& sc : stages) {
        std::unique_ptr<Stage> st;
        errors.capture([&] {
            const EntryRef& dr = sc.drive;
            if (dr.slave >= int(seg.size())) throw Error(SB() << dr.where << ": no slave at position " << dr.slave);
            const DeviceDesc& d = seg.slave(std::size_t(dr.slave)).desc();
            if (drive_kind(d) == DriveKind::None)
                throw Error(SB() << dr.where << ": slave " << dr.slave << " is a " << d.type
                                 << ", not a drive terminal this simulator models (EL70x1 stepper, EL72x1 servo)");
            for (int c : claimed_drives)
                if (c == dr.slave) throw Error(SB() << dr.where << ": drive s" << dr.slave << " already moves another stage");
            claimed_drives.push_back(dr.slave);
            st = make_stage(b, d, dr.slave, sc.stage, sc.motor, sc.feedback_counts_per_rev, sc.where);
        });
        if (!st) continue;
        for (const auto& e : sc.encoders)
            errors.capture([&] {
                b.input(e.entry, "an encoder");
                try {
                    st->encoders.emplace_back(seg, e.entry.slave, e.entry.entry, e.counts_per_unit, e.absolute, e.zero,
                                              sc.stage.start, e.index_every, e.index_offset);
                } catch (const Error& err) {
                    throw Error(SB() << e.entry.where << ": " << err.what());
                }
            });
        for (const auto& s : sc.switches)
            errors.capture([&] {
                SwitchModel m;
                m.kind = s.kind;
                m.input = b.input(s.input, "a switch");
                m.at = s.at;
                m.width = s.width;
                m.normally_closed = s.normally_closed;
                st->switches.push_back(m);
            });
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
        errors.capture([&] {
            plant->stages_.push_back(make_stage(b, d, int(p), sp, MotorParams{}, 0, SB() << "the default stage of s" << p));
        });
    }
    if (beam)
        errors.capture([&] {
            auto bm = std::make_unique<Beam>(beam->params);
            auto stage = [&](const std::string& name, const std::string& where, const char* what) -> const Stage* {
                if (name.empty()) return nullptr;
                const Stage* st = plant->find_stage(name);
                if (!st) throw Error(SB() << where << ": beam " << what << ": no stage named '" << name << "'");
                return st;
            };
            for (const BeamConfig::Lever& l : beam->optics) {
                BeamLever lv;
                lv.x = l.x, lv.y = l.y;
                if (!l.stage.empty()) {
                    lv.stage = stage(l.stage, l.where, "lever");
                } else {
                    lv.output = b.bind(l.output);
                    if (!lv.output.loc.output || lv.output.loc.bits != 16)
                        throw Error(SB() << l.output.where << ": beam lever: s" << l.output.slave << "." << l.output.entry
                                         << " is not a 16-bit analog output");
                    lv.volts_per_digit = l.full_scale / 32767.0;
                }
                bm->levers.push_back(lv);
            }
            bm->top = stage(beam->top, beam->where, "slit top");
            bm->bottom = stage(beam->bottom, beam->where, "slit bottom");
            bm->left = stage(beam->left, beam->where, "slit left");
            bm->right = stage(beam->right, beam->where, "slit right");
            plant->beam = std::move(bm);
        });
    for (const SignalConfig& sc : signals)
        errors.capture([&] {
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
            if (sc.beam >= 0) {
                if (!plant->beam) throw Error(SB() << sc.where << ": a diode (beam: " << sc.beam << ") needs the plant's beam: section");
                m.beam = plant->beam.get();
                m.diode = sc.beam;
            }
            if (!sc.stage.empty()) {
                m.stage = plant->find_stage(sc.stage);
                if (!m.stage) throw Error(SB() << sc.where << ": no stage named '" << sc.stage << "'");
            }
            m.channel = std::make_unique<AnalogInputChannel>(seg, sc.to.slave, sc.to.entry, sc.full_scale);
            plant->signals.push_back(std::move(m));
        });
    // EL2252s (a startTime entry beside binaryOutput01/02): pins switched by DC time.
    auto same = [](const IoPoint& a, const IoPoint& b) {
        return a.slave == b.slave && a.loc.sm == b.loc.sm && a.loc.bit == b.loc.bit && a.loc.output == b.loc.output;
    };
    for (std::size_t p = 0; p < seg.size(); ++p) {
        IoPoint st = bind_optional(seg, int(p), "startTime"), act = bind_optional(seg, int(p), "activate");
        if (!st.bound() || !act.bound() || !st.loc.output) continue;
        auto t = std::make_unique<TimedOutputs>();
        t->start_time = st;
        t->activate = act;
        t->outputs[0] = bind_optional(seg, int(p), "binaryOutput01");
        t->outputs[1] = bind_optional(seg, int(p), "binaryOutput02");
        plant->timed_outputs.push_back(std::move(t));
    }
    for (const Wire& w : wiring)
        errors.capture([&] {
            WireModel m;
            m.from = b.bind(w.from);
            for (auto& t : plant->timed_outputs)
                for (int ch = 0; ch < 2; ++ch)
                    if (t->outputs[ch].bound() && same(t->outputs[ch], m.from)) {
                        m.timed = t.get();
                        m.timed_channel = ch;
                    }
            m.to = b.input(w.to, "a wire");
            if (m.from.loc.bits != m.to.loc.bits)
                throw Error(SB() << w.from.where << ": " << w.from.entry << " has " << int(m.from.loc.bits) << " bits but "
                                 << w.to.entry << " has " << int(m.to.loc.bits));
            plant->wires.push_back(m);
        });
    // Terminal behaviour that needs no configuration: EL3702 sample counters, EL1252 latches.
    for (std::size_t p = 0; p < seg.size(); ++p) {
        for (std::string ch : {"01", "02", "03", "04"}) {
            IoPoint cc = bind_optional(seg, int(p), "cycleCounter" + ch);
            if (cc.bound() && !cc.loc.output) plant->cycle_counters.push_back(CycleCounter{cc});
            IoPoint pos = bind_optional(seg, int(p), "timestampLatchPositive" + ch);
            IoPoint in = bind_optional(seg, int(p), "binaryInput" + ch);
            if (pos.bound() && in.bound()) {
                LatchInput l{in, pos, bind_optional(seg, int(p), "timestampLatchNegative" + ch)};
                for (const WireModel& w : plant->wires)
                    if (w.timed && same(w.to, in)) {
                        l.timed = w.timed;
                        l.timed_channel = w.timed_channel;
                    }
                plant->latches.push_back(l);
            }
        }
    }
    // EL6692 sides: joined to their pair by name; one not in bridges: has no other side
    auto is_el6692 = [](const DeviceDesc& d) { return d.vendor == 0x2 && d.product == 0x1a243052; };
    std::vector<bool> bridged(seg.size(), false);
    for (const BridgeConfig& bc : bridges)
        errors.capture([&] {
            if (bc.slave < 0 || std::size_t(bc.slave) >= seg.size())
                throw Error(SB() << bc.where << ": no slave " << bc.slave << " on this segment (" << seg.size() << " slaves)");
            const DeviceDesc& d = seg.slave(std::size_t(bc.slave)).desc();
            if (!is_el6692(d)) throw Error(SB() << bc.where << ": slave " << bc.slave << " is a " << d.type << ", not an EL6692 side");
            try {
                plant->bridges.push_back(std::make_unique<BridgeSide>(seg, bc.slave, bc.pair, BridgeSide::side_of(d.revision)));
            } catch (const Error& e) {
                throw Error(SB() << bc.where << ": " << e.what());
            }
            bridged[std::size_t(bc.slave)] = true;
        });
    for (std::size_t p = 0; p < seg.size(); ++p)
        if (!bridged[p] && is_el6692(seg.slave(p).desc()))
            plant->bridges.push_back(std::make_unique<BridgeSide>(seg, int(p), "", BridgeSide::side_of(seg.slave(p).desc().revision)));
    seg.set_clock(int64_t(std::llround(clock_offset_us * 1000)), clock_drift_ppm);
    plant->steps = 0;
    seg.on_frame = [plant](Segment& s) { plant->step(s); };
    seg.on_plant_fault = [plant](const Fault& f) { return plant->apply_fault(f); };
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

namespace {
int64_t steady_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
} // namespace

void UdpServer::send_due(int64_t now_ns) {
    while (!held_.empty() && held_.front().due_ns <= now_ns) {
        Held& h = held_.front();
        sendto(fd_, h.frame.data(), h.frame.size(), 0, reinterpret_cast<sockaddr*>(&h.to), h.to_len);
        held_.pop_front();
    }
}

bool UdpServer::serve_one(int timeout_ms) {
    send_due(steady_ns());
    if (!held_.empty()) // wake for the next held answer
        timeout_ms = std::min<int64_t>(timeout_ms, std::max<int64_t>(0, (held_.front().due_ns - steady_ns()) / 1'000'000));
    pollfd p{fd_, POLLIN, 0};
    int ready = poll(&p, 1, timeout_ms);
    send_due(steady_ns());
    if (ready <= 0) return false;
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
    if (uint32_t d = seg_.answer_delay_us()) {
        Held h{steady_ns() + int64_t(d) * 1000, std::vector<uint8_t>(buf, buf + n), {}, flen};
        std::memcpy(&h.to, &from, flen);
        held_.push_back(std::move(h));
        return true;
    }
    sendto(fd_, buf, std::size_t(n), 0, reinterpret_cast<sockaddr*>(&from), flen);
    return true;
}

void UdpServer::run(const volatile bool& stop, int poll_ms) {
    while (!stop) serve_one(poll_ms);
}

} // namespace beamctl::ethercat::sim
