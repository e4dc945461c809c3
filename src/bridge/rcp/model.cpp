#include "bridge/rcp/model.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <numbers>
#include <sstream>

namespace beamctl::bridge::rcp {
namespace {

using config::above;
using config::at_least;
using config::between;
using config::Range;
using config::YamlNode;
using config::YamlReader;

DataType default_data_type(ObjectType t) {
    switch (t) {
    case ObjectType::BI:
    case ObjectType::BO:
        return DataType::Bool;
    case ObjectType::LI:
    case ObjectType::LO:
        return DataType::Int32;
    default:
        return DataType::Float64;
    }
}

bool is_integer(DataType t) {
    return t != DataType::Float32 && t != DataType::Float64;
}

// Range of an integer data type.
void int_range(DataType t, double& lo, double& hi) {
    switch (t) {
    case DataType::Bool:
        lo = 0, hi = 1;
        return;
    case DataType::Int8:
        lo = -128, hi = 127;
        return;
    case DataType::UInt8:
        lo = 0, hi = 255;
        return;
    case DataType::Int16:
        lo = -32768, hi = 32767;
        return;
    case DataType::UInt16:
        lo = 0, hi = 65535;
        return;
    case DataType::Int32:
        lo = -2147483648.0, hi = 2147483647.0;
        return;
    case DataType::UInt32:
        lo = 0, hi = 4294967295.0;
        return;
    default:
        lo = -std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::max();
    }
}

// The value as the data type can carry it (rounded and clamped integers; bool 0/1).
double representable(DataType t, double v) {
    if (t == DataType::Float64) return v;
    if (t == DataType::Float32) {
        double m = double(std::numeric_limits<float>::max());
        return std::isfinite(v) ? std::clamp(v, -m, m) : v;
    }
    if (std::isnan(v)) return 0;
    if (t == DataType::Bool) return v != 0 ? 1 : 0;
    double lo, hi;
    int_range(t, lo, hi);
    return std::clamp(std::round(v), lo, hi);
}

// A number of `n`'s key (finite); `def` when absent or bad.
double num(const YamlNode& n, const char* key, double def, Range r = {}) {
    return n[key].number(r).value_or(def);
}

uint32_t ip(const YamlNode& n, uint32_t def) {
    auto s = n.string();
    if (!s) return def;
    uint32_t v;
    if (!parse_ipv4(*s, v)) {
        n.error(SB() << "'" << *s << "' should be an IPv4 address such as 127.0.0.1");
        return def;
    }
    return v;
}

// [lo, hi] with lo < hi; nullopt if absent or bad.
std::optional<std::pair<double, double>> range(const YamlNode& n) {
    if (!n) return std::nullopt;
    auto items = n.list();
    if (!n.is_list()) return std::nullopt;
    if (items.size() != 2) {
        n.error("should be [low, high]");
        return std::nullopt;
    }
    auto lo = items[0].number(), hi = items[1].number();
    if (!lo || !hi) return std::nullopt;
    if (!(*lo < *hi)) {
        n.error(SB() << "low " << *lo << " should be below high " << *hi);
        return std::nullopt;
    }
    return std::pair(*lo, *hi);
}

ObjectSpec parse_object(const YamlNode& n) {
    ObjectSpec o;
    o.where = n.where();
    if (!n.keys({"id", "name", "type", "data_type", "count", "signal", "plant", "within", "counter",
                 "setpoint", "motor"}))
        return o;
    o.id = uint8_t(n.required("id", " (1..255)").integer(between(1, 255)).value_or(0));
    if (auto name = n.required("name").string()) {
        if (valid_name(*name))
            o.name = *name;
        else
            n["name"].error(SB() << "'" << *name
                                 << "' should be 1..39 characters of [A-Za-z0-9_:.-]");
    }
    bool type_ok = false;
    if (auto type = n.required("type", " (AI AO BI BO LI LO MOTOR)").string()) {
        type_ok = parse_object_type(*type, o.type);
        if (!type_ok)
            n["type"].error(SB() << "unknown type '" << *type
                                 << "' (expected AI AO BI BO LI LO MOTOR)");
    }
    o.data_type = default_data_type(o.type);
    if (auto s = n["data_type"].string()) {
        if (!parse_data_type(*s, o.data_type))
            n["data_type"].error(
                SB() << "unknown data_type '" << *s
                     << "' (expected bool int8 uint8 int16 uint16 int32 uint32 float32 float64)");
        else if (o.type == ObjectType::Motor && o.data_type != DataType::Float64)
            n["data_type"].error("a MOTOR object is float64");
    }
    if (o.type == ObjectType::Motor) o.count = kMotorValueCount;
    if (YamlNode c = n["count"]) {
        if (o.type == ObjectType::Motor) {
            c.error("a MOTOR object has no count: (always 5 values)");
        } else if (auto v = c.integer(between(1, double(kMaxValues)))) {
            o.count = uint16_t(*v);
            if (kDataHeaderSize + entry_wire_size(o.data_type, o.count) + 1 > kPacketSize) {
                c.error(SB() << o.count << " of " << to_string(o.data_type)
                             << " does not fit one data packet (at most "
                             << (kPacketSize - kDataHeaderSize - kEntryHeaderSize - 1) /
                                    data_type_size(o.data_type)
                             << ")");
                o.count = 1;
            }
        }
    }
    const char* kinds[] = {"signal", "plant", "within", "counter", "setpoint", "motor"};
    const char* kind = nullptr;
    for (const char* k : kinds)
        if (n.has(k)) {
            if (kind)
                n[k].error(SB() << "an object has one behaviour, not both " << kind << ": and "
                                << k << ":");
            else
                kind = k;
        }
    if (!type_ok && n.has("type")) return o; // the behaviour cannot be checked against it
    if (kind) {
        const std::string_view k = kind;
        std::vector<ObjectType> types; // the object types the behaviour is for
        if (k == "signal") types = {ObjectType::AI, ObjectType::BI, ObjectType::LI};
        if (k == "plant") types = {ObjectType::AI};
        if (k == "within") types = {ObjectType::BI};
        if (k == "counter") types = {ObjectType::LI};
        if (k == "setpoint") types = {ObjectType::AO, ObjectType::BO, ObjectType::LO};
        if (k == "motor") types = {ObjectType::Motor};
        if (std::find(types.begin(), types.end(), o.type) == types.end()) {
            n[kind].error(SB() << "is not for a " << to_string(o.type) << " object");
            return o;
        }
    } else if (is_output(o.type)) {
        kind = "setpoint";
    } else if (o.type == ObjectType::Motor) {
        kind = "motor";
    } else {
        n.error(SB() << "a " << to_string(o.type)
                     << " object needs a behaviour (signal:, plant:, within: or counter:)");
        return o;
    }
    const YamlNode b = n[kind];
    const std::string k = kind;
    if (k == "signal") {
        b.keys({"shape", "amplitude", "frequency_hz", "offset", "phase"});
        SignalSpec s;
        if (auto sh = b["shape"].one_of({"sine", "square", "ramp", "constant"})) {
            if (*sh == "sine") s.shape = SignalSpec::Shape::Sine;
            if (*sh == "square") s.shape = SignalSpec::Shape::Square;
            if (*sh == "ramp") s.shape = SignalSpec::Shape::Ramp;
            if (*sh == "constant") s.shape = SignalSpec::Shape::Constant;
        }
        s.amplitude = num(b, "amplitude", 1);
        s.frequency_hz = num(b, "frequency_hz", 1, at_least(0));
        s.offset = num(b, "offset", 0);
        s.phase = num(b, "phase", 0);
        o.behaviour = s;
    } else if (k == "plant") {
        b.keys({"input", "time_constant_s", "gain", "initial", "enable"});
        PlantSpec p;
        p.input = b.required("input", " (the name of an AO object)").string().value_or("");
        p.enable = b["enable"].string().value_or("");
        p.time_constant_s = num(b, "time_constant_s", 1, above(0));
        p.gain = num(b, "gain", 1);
        p.initial = num(b, "initial", 0);
        o.behaviour = p;
    } else if (k == "within") {
        b.keys({"value", "target", "tolerance"});
        WithinSpec w;
        w.value = b.required("value", " (an object name)").string().value_or("");
        w.target = b.required("target", " (an object name)").string().value_or("");
        w.tolerance = num(b, "tolerance", 0, at_least(0));
        o.behaviour = w;
    } else if (k == "counter") {
        b.keys({"step", "enable"});
        CounterSpec c;
        c.step = b["step"]
                     .integer(between(-double(int64_t(1) << 32), double(int64_t(1) << 32)))
                     .value_or(1);
        c.enable = b["enable"].string().value_or("");
        if (!is_integer(o.data_type) || o.data_type == DataType::Bool)
            n.error(SB() << "counter: needs an integer data_type (got " << to_string(o.data_type)
                         << ")");
        o.behaviour = c;
    } else if (k == "setpoint") {
        SetpointSpec s;
        if (b.keys({"initial", "min", "max"}) && b) {
            s.initial = num(b, "initial", 0);
            s.min = num(b, "min", s.min);
            s.max = num(b, "max", s.max);
            if (!(s.min <= s.max)) {
                b.error(SB() << "min " << s.min << " should be <= max " << s.max);
                s.min = -1e300, s.max = 1e300;
            }
        }
        if (representable(o.data_type, s.initial) != s.initial)
            b["initial"].error(SB() << s.initial << " is not a " << to_string(o.data_type)
                                    << " value");
        o.behaviour = s;
    } else {
        MotorSpec m;
        if (b.keys({"position", "velocity", "max_velocity", "acceleration", "max_acceleration",
                    "soft_limits", "hard_limits", "home_position", "home_velocity", "enabled"}) &&
            b) {
            m.position = num(b, "position", m.position);
            m.velocity = num(b, "velocity", m.velocity, above(0));
            m.max_velocity = num(b, "max_velocity", std::max(m.max_velocity, m.velocity), above(0));
            m.acceleration = num(b, "acceleration", m.acceleration, above(0));
            m.max_acceleration = num(b, "max_acceleration",
                                     std::max(m.max_acceleration, m.acceleration), above(0));
            if (m.velocity > m.max_velocity)
                b["velocity"].error(SB() << m.velocity << " exceeds max_velocity "
                                         << m.max_velocity);
            if (m.acceleration > m.max_acceleration)
                b["acceleration"].error(SB() << m.acceleration << " exceeds max_acceleration "
                                             << m.max_acceleration);
            if (auto s = range(b["soft_limits"])) {
                std::tie(m.soft_low, m.soft_high) = *s;
                m.has_soft_limits = true;
            }
            if (auto h = range(b["hard_limits"])) {
                std::tie(m.hard_low, m.hard_high) = *h;
                m.has_hard_limits = true;
                if (m.position < m.hard_low || m.position > m.hard_high)
                    (b["position"] ? b["position"] : b)
                        .error(SB() << (b["position"] ? "" : "position ") << m.position
                                    << " is outside hard_limits");
            }
            m.home_position = num(b, "home_position", m.home_position);
            m.home_velocity = num(b, "home_velocity", m.home_velocity, above(0));
            if (m.has_hard_limits &&
                (m.home_position <= m.hard_low || m.home_position >= m.hard_high))
                (b["home_position"] ? b["home_position"] : b)
                    .error(SB() << (b["home_position"] ? "" : "home_position ") << m.home_position
                                << " should be between the hard limits");
            m.enabled = b["enabled"].boolean().value_or(true);
        }
        o.behaviour = m;
    }
    return o;
}

// Duplicate ids and names, references between objects and one-value behaviours: every problem
// goes to report(index of the object, what). Objects without an id (0) or a name are not compared.
void check_objects(const std::vector<ObjectSpec>& objs,
                   const std::function<void(std::size_t, std::string)>& report) {
    auto find = [&](const std::string& name) -> const ObjectSpec* {
        for (const ObjectSpec& o : objs)
            if (o.name == name) return &o;
        return nullptr;
    };
    for (std::size_t i = 0; i < objs.size(); ++i) {
        const ObjectSpec& s = objs[i];
        for (std::size_t j = 0; j < i; ++j)
            if (s.id != 0 && objs[j].id == s.id) {
                report(i, SB() << "object id " << int(s.id) << " is used twice");
                break;
            }
        for (std::size_t j = 0; j < i; ++j)
            if (!s.name.empty() && objs[j].name == s.name) {
                report(i, SB() << "object name '" << s.name << "' is used twice");
                break;
            }
    }
    for (std::size_t i = 0; i < objs.size(); ++i) {
        const ObjectSpec& s = objs[i];
        auto ref = [&](const std::string& name, const char* key,
                       std::initializer_list<ObjectType> types) {
            const ObjectSpec* t = find(name);
            if (!t)
                report(i, SB() << key << ": no object named '" << name << "'");
            else if (std::find(types.begin(), types.end(), t->type) == types.end())
                report(i, SB() << key << ": '" << name << "' is a " << to_string(t->type)
                               << " object");
            else if (t->count != 1)
                report(i, SB() << key << ": '" << name << "' has " << t->count
                               << " values, not 1");
        };
        bool scalar_only = std::holds_alternative<PlantSpec>(s.behaviour) ||
                           std::holds_alternative<WithinSpec>(s.behaviour) ||
                           std::holds_alternative<CounterSpec>(s.behaviour);
        if (scalar_only && s.count != 1) report(i, "this behaviour has one value (count 1)");
        if (auto* p = std::get_if<PlantSpec>(&s.behaviour)) {
            if (!p->input.empty()) ref(p->input, "plant input", {ObjectType::AO});
            if (!p->enable.empty()) ref(p->enable, "plant enable", {ObjectType::BO});
        } else if (auto* w = std::get_if<WithinSpec>(&s.behaviour)) {
            auto any = {ObjectType::AI, ObjectType::AO, ObjectType::BI,
                        ObjectType::BO, ObjectType::LI, ObjectType::LO};
            if (!w->value.empty()) ref(w->value, "within value", any);
            if (!w->target.empty()) ref(w->target, "within target", any);
        } else if (auto* c = std::get_if<CounterSpec>(&s.behaviour)) {
            if (!c->enable.empty()) ref(c->enable, "counter enable", {ObjectType::BO});
        }
    }
}

double signal_value(const SignalSpec& s, double t, double shift) {
    double turns = s.frequency_hz * t + s.phase + shift;
    double frac = turns - std::floor(turns);
    switch (s.shape) {
    case SignalSpec::Shape::Sine:
        return s.offset + s.amplitude * std::sin(2 * std::numbers::pi * turns);
    case SignalSpec::Shape::Square:
        return s.offset + (frac < 0.5 ? s.amplitude : -s.amplitude);
    case SignalSpec::Shape::Ramp:
        return s.offset + s.amplitude * frac;
    case SignalSpec::Shape::Constant:
        return s.offset + s.amplitude;
    }
    return 0;
}

} // namespace

// ---------------------------------------------------------------- configuration
ModelConfig ModelConfig::load(const std::string& file) {
    std::ifstream f(file);
    if (!f)
        throw Error(SB() << file << ": cannot open the rcp-sim model: " << std::strerror(errno));
    std::stringstream ss;
    ss << f.rdbuf();
    return parse(ss.str(), file);
}

ModelConfig ModelConfig::parse(std::string_view text, const std::string& file) {
    YamlReader rd(file, std::string(text), "the model");
    ModelConfig c;
    YamlNode root = rd.root();
    if (root.is_null() || (root && !root.is_map()))
        rd.error(rd.top(), "expected a mapping with application:, objects:, ...");
    else if (root.keys({"application", "rate_hz", "beacon_period_s", "ioc", "listen", "objects"})) {
        if (auto app = root.required("application", " (its name)").string()) {
            if (valid_name(*app))
                c.application = *app;
            else
                root["application"].error(SB() << "'" << *app
                                               << "' should be 1..39 characters of [A-Za-z0-9_:.-]");
        }
        c.rate_hz = root["rate_hz"].number(Range{0, 100000, true}).value_or(c.rate_hz);
        c.beacon_period_s = root["beacon_period_s"].number(above(0)).value_or(c.beacon_period_s);
        if (YamlNode n = root["ioc"]; n.keys({"host", "port", "data_port"}) && n) {
            c.ioc_ip = ip(n["host"], c.ioc_ip);
            c.ioc_port = uint16_t(n["port"].integer(between(1, 65535)).value_or(c.ioc_port));
            c.ioc_data_port =
                uint16_t(n["data_port"].integer(between(1, 65535)).value_or(c.ioc_port));
        }
        if (YamlNode n = root["listen"]; n.keys({"host", "port"}) && n) {
            c.listen_ip = ip(n["host"], c.listen_ip);
            c.listen_port = uint16_t(n["port"].integer(between(0, 65535)).value_or(c.listen_port));
        }
        YamlNode objs = root.required("objects", " (a non-empty list)");
        std::vector<SourceLoc> places;
        if (objs && (!objs.is_list() || objs.yaml().size() == 0))
            objs.error("should be a non-empty list");
        else
            for (const YamlNode& n : objs.list()) {
                c.objects.push_back(parse_object(n));
                places.push_back(n.loc());
            }
        // the checks the Model constructor makes, with every error
        check_objects(c.objects, [&](std::size_t i, std::string what) {
            rd.error(places[i], SB() << "objects[" << i << "]: " << what);
        });
    }
    rd.throw_if_errors();
    return c;
}

// ---------------------------------------------------------------- model
uint32_t MotorState::status_bits() const {
    uint32_t b = 0;
    bool busy = mode != Mode::Idle || busy_steps > 0;
    if (!busy) b |= motor_status::kDone;
    if (mode != Mode::Idle || velocity != 0) b |= motor_status::kMoving;
    if (high_limit) b |= motor_status::kHighLimit;
    if (low_limit) b |= motor_status::kLowLimit;
    if (homed) b |= motor_status::kHomed;
    if (error_code != 0) b |= motor_status::kError;
    if (enabled) b |= motor_status::kEnabled;
    return b;
}

Model::Model(ModelConfig cfg)
    : cfg_(std::move(cfg)) {
    if (cfg_.objects.empty()) throw Error("rcp-sim model: no objects");
    check_objects(cfg_.objects, [&](std::size_t i, const std::string& what) {
        throw Error(SB() << cfg_.objects[i].where << ": " << what);
    });
    by_id_.fill(-1);
    for (const ObjectSpec& s : cfg_.objects) {
        by_id_[s.id] = int16_t(objs_.size());
        Obj o;
        o.spec = s;
        o.values.assign(s.count, 0.0);
        objs_.push_back(std::move(o));
    }
    for (Obj& o : objs_) { // every reference names an object of the right kind (checked above)
        const ObjectSpec& s = o.spec;
        if (auto* p = std::get_if<PlantSpec>(&s.behaviour)) {
            o.input = index(p->input);
            if (!p->enable.empty()) o.enable = index(p->enable);
            o.plant_state = p->initial;
        } else if (auto* w = std::get_if<WithinSpec>(&s.behaviour)) {
            o.input = index(w->value);
            o.target = index(w->target);
        } else if (auto* c = std::get_if<CounterSpec>(&s.behaviour)) {
            if (!c->enable.empty()) o.enable = index(c->enable);
        } else if (auto* sp = std::get_if<SetpointSpec>(&s.behaviour)) {
            std::fill(o.values.begin(), o.values.end(), std::clamp(sp->initial, sp->min, sp->max));
        } else if (auto* m = std::get_if<MotorSpec>(&s.behaviour)) {
            o.motor.position = m->position;
            o.motor.target = m->position;
            o.motor.enabled = m->enabled;
            o.values.assign(kMotorValueCount, 0.0);
        }
    }
    step(0); // the values at time 0
}

int Model::index(std::string_view name) const {
    for (std::size_t i = 0; i < objs_.size(); ++i)
        if (objs_[i].spec.name == name) return int(i);
    return -1;
}

std::span<const double> Model::values(std::string_view name) const {
    int i = index(name);
    if (i < 0) return {};
    return objs_[std::size_t(i)].values;
}

double Model::value(std::string_view name) const {
    auto v = values(name);
    return v.empty() ? std::numeric_limits<double>::quiet_NaN() : v[0];
}

const MotorState* Model::motor(std::string_view name) const {
    int i = index(name);
    if (i < 0 || objs_[std::size_t(i)].spec.type != ObjectType::Motor) return nullptr;
    return &objs_[std::size_t(i)].motor;
}

void Model::step(double dt) {
    if (dt < 0 || !std::isfinite(dt)) return;
    t_ += dt;
    auto enabled = [&](int i) { return i < 0 || objs_[std::size_t(i)].values[0] != 0; };
    // Pass 1: everything but comparisons (they read this step's values).
    for (Obj& o : objs_) {
        const ObjectSpec& s = o.spec;
        if (auto* sg = std::get_if<SignalSpec>(&s.behaviour)) {
            for (std::size_t k = 0; k < o.values.size(); ++k) {
                double v = signal_value(*sg, t_, double(k) / double(o.values.size()));
                if (s.type == ObjectType::BI) v = v > 0 ? 1 : 0;
                o.values[k] = representable(s.data_type, v);
            }
        } else if (auto* p = std::get_if<PlantSpec>(&s.behaviour)) {
            if (enabled(o.enable) && dt > 0) {
                double u = objs_[std::size_t(o.input)].values[0];
                o.plant_state +=
                    (p->gain * u - o.plant_state) * (1 - std::exp(-dt / p->time_constant_s));
            }
            o.values[0] = representable(s.data_type, o.plant_state);
        } else if (auto* c = std::get_if<CounterSpec>(&s.behaviour)) {
            if (dt > 0 && enabled(o.enable)) {
                double lo, hi;
                int_range(s.data_type, lo, hi);
                int64_t l = int64_t(lo), span = int64_t(hi) - l + 1;
                int64_t v = o.counter + c->step - l;
                v %= span;
                if (v < 0) v += span;
                o.counter = v + l;
            }
            o.values[0] = double(o.counter);
        } else if (std::holds_alternative<MotorSpec>(s.behaviour)) {
            if (dt > 0) step_motor(o, dt);
            refresh_motor_values(o);
            // a command shows done=0 in the values of at least the first step after it
            if (dt > 0 && o.motor.busy_steps > 0) --o.motor.busy_steps;
        }
    }
    for (Obj& o : objs_)
        if (auto* w = std::get_if<WithinSpec>(&o.spec.behaviour)) {
            double a = objs_[std::size_t(o.input)].values[0],
                   b = objs_[std::size_t(o.target)].values[0];
            o.values[0] = std::fabs(a - b) <= w->tolerance ? 1 : 0;
        }
}

void Model::refresh_motor_values(Obj& o) {
    const MotorState& m = o.motor;
    o.values[0] = m.position;
    o.values[1] = m.velocity;
    o.values[2] = double(m.status_bits());
    o.values[3] = 0;
    o.values[4] = m.error_code;
}

namespace {
// One step of a move toward `target` at up to vmax with acceleration a; true when arrived.
bool drive_toward(MotorState& m, double target, double vmax, double a, double dt) {
    double d = target - m.position;
    double dir = d >= 0 ? 1 : -1;
    double v_allowed = std::min(vmax, std::sqrt(2 * a * std::fabs(d)));
    double dv = std::clamp(dir * v_allowed - m.velocity, -a * dt, a * dt);
    m.velocity += dv;
    double next = m.position + m.velocity * dt;
    if (d == 0 || (target - next) * dir <= 0) {
        m.position = target;
        m.velocity = 0;
        return true;
    }
    m.position = next;
    return false;
}
} // namespace

void Model::step_motor(Obj& o, double dt) {
    MotorState& m = o.motor;
    const MotorSpec& spec = std::get<MotorSpec>(o.spec.behaviour);
    switch (m.mode) {
    case MotorState::Mode::Idle:
        break;
    case MotorState::Mode::Moving:
        if (drive_toward(m, m.target, m.v_max, m.accel, dt)) m.mode = MotorState::Mode::Idle;
        break;
    case MotorState::Mode::Stopping:
        if (std::fabs(m.velocity) <= m.accel * dt) {
            m.position += 0.5 * m.velocity * dt;
            m.velocity = 0;
            m.mode = MotorState::Mode::Idle;
        } else {
            m.velocity -= (m.velocity > 0 ? 1 : -1) * m.accel * dt;
            m.position += m.velocity * dt;
        }
        break;
    case MotorState::Mode::Jogging:
        if (spec.has_soft_limits) {
            if (drive_toward(m, m.direction > 0 ? spec.soft_high : spec.soft_low, m.v_max, m.accel,
                             dt))
                m.mode = MotorState::Mode::Idle;
        } else {
            m.velocity +=
                std::clamp(m.direction * m.v_max - m.velocity, -m.accel * dt, m.accel * dt);
            m.position += m.velocity * dt;
        }
        break;
    case MotorState::Mode::Homing: {
        double before = m.position - spec.home_position;
        m.velocity += std::clamp(m.direction * m.v_max - m.velocity, -m.accel * dt, m.accel * dt);
        m.position += m.velocity * dt;
        double after = m.position - spec.home_position;
        if (before == 0 || (before < 0) != (after < 0) || after == 0)
            m.mode = MotorState::Mode::HomeFinal;
        break;
    }
    case MotorState::Mode::HomeFinal:
        if (drive_toward(m, spec.home_position, m.v_max, m.accel, dt)) {
            m.mode = MotorState::Mode::Idle;
            m.homed = true;
        }
        break;
    }
    m.high_limit = m.low_limit = false;
    if (spec.has_hard_limits) {
        if (m.position >= spec.hard_high) {
            m.position = spec.hard_high;
            m.high_limit = true;
        } else if (m.position <= spec.hard_low) {
            m.position = spec.hard_low;
            m.low_limit = true;
        }
        if ((m.high_limit && m.velocity > 0) || (m.low_limit && m.velocity < 0)) {
            m.velocity = 0;
            if (m.mode == MotorState::Mode::Homing)
                m.direction = -m.direction; // search back
            else if (m.mode != MotorState::Mode::Idle)
                m.mode = MotorState::Mode::Idle;
        }
    }
}

void Model::motor_command(Obj& o, std::span<const double> v) {
    MotorState& m = o.motor;
    const MotorSpec& spec = std::get<MotorSpec>(o.spec.behaviour);
    if (std::equal(v.begin(), v.end(), m.last_command.begin())) return; // a repeated datagram
    std::copy(v.begin(), v.end(), m.last_command.begin());
    double cmd = v[0];
    auto refuse = [&](double code) { m.error_code = code; };
    if (!(cmd >= 0 && cmd <= 8) || cmd != std::floor(cmd)) return refuse(3);
    auto c = MotorCommand(uint8_t(cmd));
    double vel = v[2], acc = v[3];
    m.v_max = (vel > 0 && std::isfinite(vel)) ? std::min(vel, spec.max_velocity) : spec.velocity;
    m.accel =
        (acc > 0 && std::isfinite(acc)) ? std::min(acc, spec.max_acceleration) : spec.acceleration;
    switch (c) {
    case MotorCommand::None:
        return;
    case MotorCommand::Enable:
        m.enabled = true;
        m.error_code = 0;
        return;
    case MotorCommand::Disable:
        m.enabled = false;
        m.velocity = 0;
        m.mode = MotorState::Mode::Idle;
        return;
    case MotorCommand::Stop:
        m.error_code = 0;
        if (m.mode != MotorState::Mode::Idle) m.mode = MotorState::Mode::Stopping;
        return;
    default:
        break;
    }
    if (!m.enabled) return refuse(2);
    switch (c) {
    case MotorCommand::MoveAbsolute: {
        double target = v[1];
        if (!std::isfinite(target)) return refuse(4);
        if (spec.has_soft_limits && (target < spec.soft_low || target > spec.soft_high))
            return refuse(1);
        m.target = target;
        m.mode = MotorState::Mode::Moving;
        break;
    }
    case MotorCommand::HomeForward:
    case MotorCommand::HomeReverse:
        m.direction = c == MotorCommand::HomeForward ? 1 : -1;
        m.v_max =
            (vel > 0 && std::isfinite(vel)) ? std::min(vel, spec.max_velocity) : spec.home_velocity;
        m.homed = false;
        m.mode = m.position == spec.home_position ? MotorState::Mode::HomeFinal
                                                  : MotorState::Mode::Homing;
        break;
    case MotorCommand::JogForward:
    case MotorCommand::JogReverse:
        m.direction = c == MotorCommand::JogForward ? 1 : -1;
        m.mode = MotorState::Mode::Jogging;
        break;
    default:
        break;
    }
    m.error_code = 0;
    m.busy_steps = 1;
}

Malformed Model::check_write(const DataEntry& e) const {
    int16_t i = by_id_[e.id];
    if (i < 0) return Malformed::UnknownObject;
    const ObjectSpec& s = objs_[std::size_t(i)].spec;
    if (e.type != s.type || e.data_type != s.data_type) return Malformed::TypeMismatch;
    if (e.name != s.name) return Malformed::NameMismatch;
    if (e.count != s.count || e.values.size() != e.count) return Malformed::CountMismatch;
    if (s.type != ObjectType::Motor && !std::holds_alternative<SetpointSpec>(s.behaviour))
        return Malformed::NotWritable;
    return Malformed::None;
}

Malformed Model::apply_write(const DataEntry& e) {
    if (Malformed m = check_write(e); m != Malformed::None) return m;
    Obj& o = objs_[std::size_t(by_id_[e.id])];
    const ObjectSpec& s = o.spec;
    if (s.type == ObjectType::Motor) {
        motor_command(o, e.values);
        refresh_motor_values(o);
        return Malformed::None;
    }
    auto* sp = std::get_if<SetpointSpec>(&s.behaviour);
    for (std::size_t k = 0; k < o.values.size(); ++k)
        o.values[k] = representable(s.data_type, std::clamp(e.values[k], sp->min, sp->max));
    return Malformed::None;
}

std::vector<Packet> Model::beacon_packets() const {
    std::vector<BeaconObject> all;
    for (const Obj& o : objs_) {
        BeaconObject b;
        b.id = o.spec.id;
        b.type = o.spec.type;
        b.data_type = o.spec.data_type;
        b.ip_rcp = cfg_.listen_ip;
        b.port_rcp = cfg_.listen_port;
        b.ip_ioc = cfg_.ioc_ip;
        b.port_ioc = cfg_.ioc_data_port;
        b.name = o.spec.name;
        all.push_back(std::move(b));
    }
    std::vector<Packet> out;
    for (std::size_t at = 0; at < all.size(); at += kMaxBeaconObjects) {
        std::size_t n = std::min(kMaxBeaconObjects, all.size() - at);
        Packet p;
        WriteResult r = write_beacon(p, t_, cfg_.application, at > 0,
                                     std::span<const BeaconObject>(all.data() + at, n));
        if (!r) throw Error(SB() << "rcp-sim: cannot encode a beacon: " << to_string(r.status));
        out.push_back(p);
    }
    return out;
}

void Model::data_packets(std::vector<Packet>& out) const {
    out.clear();
    std::array<DataEntry, kMaxDataEntries> batch;
    std::size_t n = 0, bytes = kDataHeaderSize + 1;
    auto flush = [&] {
        if (n == 0) return;
        out.emplace_back();
        write_data(out.back(), t_, std::span<const DataEntry>(batch.data(), n));
        n = 0;
        bytes = kDataHeaderSize + 1;
    };
    for (const Obj& o : objs_) {
        std::size_t size = entry_wire_size(o.spec.data_type, uint16_t(o.values.size()));
        if (n == batch.size() || bytes + size > kPacketSize) flush();
        batch[n++] = DataEntry{o.spec.id,        o.spec.type,
                               o.spec.data_type, uint16_t(o.values.size()),
                               o.spec.name,      std::span<const double>(o.values)};
        bytes += size;
    }
    flush();
}

} // namespace beamctl::bridge::rcp
