#include "bridge/rcp/model.hpp"

#include "core/error.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>

namespace beamctl::bridge::rcp {
namespace {

// ---------------------------------------------------------------- YAML with file:line:col
struct Yaml {
    const std::string& file;

    std::string where(const YAML::Node& n) const {
        return SB() << file << ":" << n.Mark().line + 1 << ":" << n.Mark().column + 1;
    }
    [[noreturn]] void fail(const YAML::Node& n, const std::string& msg) const {
        throw Error(SB() << where(n) << ": " << msg);
    }
    void keys(const YAML::Node& n, std::initializer_list<const char*> allowed,
              const char* what) const {
        if (!n.IsMap()) fail(n, SB() << what << " should be a mapping");
        for (auto kv : n) {
            std::string k = kv.first.as<std::string>();
            if (std::none_of(allowed.begin(), allowed.end(),
                             [&](const char* a) { return k == a; })) {
                std::string list;
                for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
                fail(kv.first, SB() << "unknown key '" << k << "' in " << what << " (expected "
                                    << list << ")");
            }
        }
    }
    std::string str(const YAML::Node& n, const char* key) const {
        if (!n.IsScalar()) fail(n, SB() << key << " should be a string");
        return n.as<std::string>();
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
    double num(const YAML::Node& parent, const char* key, double def) const {
        YAML::Node n = parent[key];
        return n ? num(n, key) : def;
    }
    double positive(const YAML::Node& parent, const char* key, double def) const {
        double v = num(parent, key, def);
        if (!(v > 0)) fail(parent[key], SB() << key << " should be > 0 (got " << v << ")");
        return v;
    }
    int64_t integer(const YAML::Node& n, const char* key, int64_t lo, int64_t hi) const {
        int64_t v;
        try {
            v = n.as<int64_t>();
        } catch (const YAML::Exception&) {
            fail(n, SB() << key << " should be an integer");
        }
        if (v < lo || v > hi)
            fail(n, SB() << key << " should be in " << lo << ".." << hi << " (got " << v << ")");
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
    uint32_t ip(const YAML::Node& n, const char* key) const {
        std::string s = str(n, key);
        uint32_t v;
        if (!parse_ipv4(s, v))
            fail(n, SB() << key << " '" << s << "' should be an IPv4 address such as 127.0.0.1");
        return v;
    }
    // [lo, hi] with lo < hi
    std::pair<double, double> range(const YAML::Node& n, const char* key) const {
        if (!n.IsSequence() || n.size() != 2) fail(n, SB() << key << " should be [low, high]");
        double lo = num(n[0], key), hi = num(n[1], key);
        if (!(lo < hi)) fail(n, SB() << key << ": low " << lo << " should be below high " << hi);
        return {lo, hi};
    }
};

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

ObjectSpec parse_object(const Yaml& y, const YAML::Node& n) {
    y.keys(n,
           {"id", "name", "type", "data_type", "count", "signal", "plant", "within", "counter",
            "setpoint", "motor"},
           "an object");
    ObjectSpec o;
    o.where = y.where(n);
    if (!n["id"]) y.fail(n, "an object needs id: (1..255)");
    if (!n["name"]) y.fail(n, "an object needs name:");
    if (!n["type"]) y.fail(n, "an object needs type: (AI AO BI BO LI LO MOTOR)");
    o.id = uint8_t(y.integer(n["id"], "id", 1, 255));
    o.name = y.str(n["name"], "name");
    if (!valid_name(o.name))
        y.fail(n["name"],
               SB() << "name '" << o.name << "' should be 1..39 characters of [A-Za-z0-9_:.-]");
    std::string type = y.str(n["type"], "type");
    if (!parse_object_type(type, o.type))
        y.fail(n["type"],
               SB() << "unknown type '" << type << "' (expected AI AO BI BO LI LO MOTOR)");
    o.data_type = default_data_type(o.type);
    if (auto d = n["data_type"]) {
        std::string s = y.str(d, "data_type");
        if (!parse_data_type(s, o.data_type))
            y.fail(
                d,
                SB() << "unknown data_type '" << s
                     << "' (expected bool int8 uint8 int16 uint16 int32 uint32 float32 float64)");
        if (o.type == ObjectType::Motor && o.data_type != DataType::Float64)
            y.fail(d, "a MOTOR object is float64");
    }
    if (o.type == ObjectType::Motor) o.count = kMotorValueCount;
    if (auto c = n["count"]) {
        if (o.type == ObjectType::Motor)
            y.fail(c, "a MOTOR object has no count: (always 5 values)");
        o.count = uint16_t(y.integer(c, "count", 1, int64_t(kMaxValues)));
        if (kDataHeaderSize + entry_wire_size(o.data_type, o.count) + 1 > kPacketSize)
            y.fail(c, SB() << "count " << o.count << " of " << to_string(o.data_type)
                           << " does not fit one data packet (at most "
                           << (kPacketSize - kDataHeaderSize - kEntryHeaderSize - 1) /
                                  data_type_size(o.data_type)
                           << ")");
    }
    const char* kinds[] = {"signal", "plant", "within", "counter", "setpoint", "motor"};
    const char* kind = nullptr;
    for (const char* k : kinds)
        if (n[k]) {
            if (kind)
                y.fail(n[k], SB() << "an object has one behaviour, not both " << kind << ": and "
                                  << k << ":");
            kind = k;
        }
    auto allowed = [&](std::initializer_list<ObjectType> types) {
        if (std::find(types.begin(), types.end(), o.type) == types.end())
            y.fail(n[kind], SB() << kind << ": is not for a " << to_string(o.type) << " object");
    };
    if (!kind) {
        if (is_output(o.type))
            kind = "setpoint";
        else if (o.type == ObjectType::Motor)
            kind = "motor";
        else
            y.fail(n, SB() << "a " << to_string(o.type)
                           << " object needs a behaviour (signal:, plant:, within: or counter:)");
    }
    YAML::Node b = n[kind];
    std::string k = kind;
    if (k == "signal") {
        allowed({ObjectType::AI, ObjectType::BI, ObjectType::LI});
        y.keys(b, {"shape", "amplitude", "frequency_hz", "offset", "phase"}, "signal");
        SignalSpec s;
        if (auto sh = b["shape"]) {
            std::string v = y.str(sh, "shape");
            if (v == "sine")
                s.shape = SignalSpec::Shape::Sine;
            else if (v == "square")
                s.shape = SignalSpec::Shape::Square;
            else if (v == "ramp")
                s.shape = SignalSpec::Shape::Ramp;
            else if (v == "constant")
                s.shape = SignalSpec::Shape::Constant;
            else
                y.fail(sh, SB() << "unknown shape '" << v
                                << "' (expected sine, square, ramp, constant)");
        }
        s.amplitude = y.num(b, "amplitude", 1);
        s.frequency_hz = y.num(b, "frequency_hz", 1);
        if (s.frequency_hz < 0) y.fail(b["frequency_hz"], "frequency_hz should be >= 0");
        s.offset = y.num(b, "offset", 0);
        s.phase = y.num(b, "phase", 0);
        o.behaviour = s;
    } else if (k == "plant") {
        allowed({ObjectType::AI});
        y.keys(b, {"input", "time_constant_s", "gain", "initial", "enable"}, "plant");
        PlantSpec p;
        if (!b["input"]) y.fail(b, "plant: needs input: (the name of an AO object)");
        p.input = y.str(b["input"], "input");
        if (b["enable"]) p.enable = y.str(b["enable"], "enable");
        p.time_constant_s = y.positive(b, "time_constant_s", 1);
        p.gain = y.num(b, "gain", 1);
        p.initial = y.num(b, "initial", 0);
        o.behaviour = p;
    } else if (k == "within") {
        allowed({ObjectType::BI});
        y.keys(b, {"value", "target", "tolerance"}, "within");
        WithinSpec w;
        if (!b["value"] || !b["target"])
            y.fail(b, "within: needs value: and target: (object names)");
        w.value = y.str(b["value"], "value");
        w.target = y.str(b["target"], "target");
        w.tolerance = y.num(b, "tolerance", 0);
        if (w.tolerance < 0) y.fail(b["tolerance"], "tolerance should be >= 0");
        o.behaviour = w;
    } else if (k == "counter") {
        allowed({ObjectType::LI});
        y.keys(b, {"step", "enable"}, "counter");
        CounterSpec c;
        if (auto s = b["step"])
            c.step = y.integer(s, "step", -(int64_t(1) << 32), int64_t(1) << 32);
        if (b["enable"]) c.enable = y.str(b["enable"], "enable");
        if (!is_integer(o.data_type) || o.data_type == DataType::Bool)
            y.fail(n, SB() << "counter: needs an integer data_type (got " << to_string(o.data_type)
                           << ")");
        o.behaviour = c;
    } else if (k == "setpoint") {
        allowed({ObjectType::AO, ObjectType::BO, ObjectType::LO});
        SetpointSpec s;
        if (b) {
            y.keys(b, {"initial", "min", "max"}, "setpoint");
            s.initial = y.num(b, "initial", 0);
            s.min = y.num(b, "min", s.min);
            s.max = y.num(b, "max", s.max);
            if (!(s.min <= s.max))
                y.fail(b, SB() << "setpoint: min " << s.min << " should be <= max " << s.max);
        }
        if (representable(o.data_type, s.initial) != s.initial)
            y.fail(b ? b["initial"] : n, SB() << "initial " << s.initial << " is not a "
                                              << to_string(o.data_type) << " value");
        o.behaviour = s;
    } else {
        allowed({ObjectType::Motor});
        MotorSpec m;
        if (b) {
            y.keys(b,
                   {"position", "velocity", "max_velocity", "acceleration", "max_acceleration",
                    "soft_limits", "hard_limits", "home_position", "home_velocity", "enabled"},
                   "motor");
            m.position = y.num(b, "position", m.position);
            m.velocity = y.positive(b, "velocity", m.velocity);
            m.max_velocity = y.positive(b, "max_velocity", std::max(m.max_velocity, m.velocity));
            m.acceleration = y.positive(b, "acceleration", m.acceleration);
            m.max_acceleration =
                y.positive(b, "max_acceleration", std::max(m.max_acceleration, m.acceleration));
            if (m.velocity > m.max_velocity)
                y.fail(b["velocity"], SB() << "velocity " << m.velocity << " exceeds max_velocity "
                                           << m.max_velocity);
            if (m.acceleration > m.max_acceleration)
                y.fail(b["acceleration"], SB() << "acceleration " << m.acceleration
                                               << " exceeds max_acceleration "
                                               << m.max_acceleration);
            if (auto s = b["soft_limits"]) {
                std::tie(m.soft_low, m.soft_high) = y.range(s, "soft_limits");
                m.has_soft_limits = true;
            }
            if (auto h = b["hard_limits"]) {
                std::tie(m.hard_low, m.hard_high) = y.range(h, "hard_limits");
                m.has_hard_limits = true;
                if (m.position < m.hard_low || m.position > m.hard_high)
                    y.fail(b["position"] ? b["position"] : b,
                           SB() << "position " << m.position << " is outside hard_limits");
            }
            m.home_position = y.num(b, "home_position", m.home_position);
            m.home_velocity = y.positive(b, "home_velocity", m.home_velocity);
            if (m.has_hard_limits &&
                (m.home_position <= m.hard_low || m.home_position >= m.hard_high))
                y.fail(b["home_position"] ? b["home_position"] : b,
                       "home_position should be between the hard limits");
            m.enabled = y.flag(b, "enabled", true);
        }
        o.behaviour = m;
    }
    return o;
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
    YAML::Node root;
    try {
        root = YAML::Load(std::string(text));
    } catch (const YAML::ParserException& e) {
        throw Error(SB() << file << ":" << e.mark.line + 1 << ":" << e.mark.column + 1 << ": "
                         << e.msg);
    }
    Yaml y{file};
    if (!root || !root.IsMap())
        throw Error(SB() << file << ":1:1: expected a mapping with application:, objects:, ...");
    y.keys(root, {"application", "rate_hz", "beacon_period_s", "ioc", "listen", "objects"},
           "the model");
    ModelConfig c;
    if (!root["application"]) y.fail(root, "the model needs application: (its name)");
    c.application = y.str(root["application"], "application");
    if (!valid_name(c.application))
        y.fail(root["application"], SB() << "application '" << c.application
                                         << "' should be 1..39 characters of [A-Za-z0-9_:.-]");
    c.rate_hz = y.positive(root, "rate_hz", c.rate_hz);
    if (c.rate_hz > 100000)
        y.fail(root["rate_hz"], SB() << "rate_hz " << c.rate_hz << " should be <= 100000");
    c.beacon_period_s = y.positive(root, "beacon_period_s", c.beacon_period_s);
    if (auto n = root["ioc"]) {
        y.keys(n, {"host", "port", "data_port"}, "ioc");
        if (n["host"]) c.ioc_ip = y.ip(n["host"], "host");
        if (n["port"]) c.ioc_port = uint16_t(y.integer(n["port"], "port", 1, 65535));
        c.ioc_data_port = n["data_port"]
                              ? uint16_t(y.integer(n["data_port"], "data_port", 1, 65535))
                              : c.ioc_port;
    }
    if (auto n = root["listen"]) {
        y.keys(n, {"host", "port"}, "listen");
        if (n["host"]) c.listen_ip = y.ip(n["host"], "host");
        if (n["port"]) c.listen_port = uint16_t(y.integer(n["port"], "port", 0, 65535));
    }
    YAML::Node objs = root["objects"];
    if (!objs || !objs.IsSequence() || objs.size() == 0)
        y.fail(objs ? objs : root, "objects: should be a non-empty list");
    for (auto n : objs) c.objects.push_back(parse_object(y, n));
    Model check(c); // cross references, duplicates: the same errors the Model constructor throws
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
    by_id_.fill(-1);
    for (const ObjectSpec& s : cfg_.objects) {
        if (by_id_[s.id] >= 0)
            throw Error(SB() << s.where << ": object id " << int(s.id) << " is used twice");
        for (const Obj& o : objs_)
            if (o.spec.name == s.name)
                throw Error(SB() << s.where << ": object name '" << s.name << "' is used twice");
        by_id_[s.id] = int16_t(objs_.size());
        Obj o;
        o.spec = s;
        o.values.assign(s.count, 0.0);
        objs_.push_back(std::move(o));
    }
    auto ref = [&](const ObjectSpec& s, const std::string& name, const char* key, bool want_scalar,
                   std::initializer_list<ObjectType> types) {
        int i = index(name);
        if (i < 0)
            throw Error(SB() << s.where << ": " << key << ": no object named '" << name << "'");
        const ObjectSpec& t = objs_[std::size_t(i)].spec;
        if (types.size() && std::find(types.begin(), types.end(), t.type) == types.end())
            throw Error(SB() << s.where << ": " << key << ": '" << name << "' is a "
                             << to_string(t.type) << " object");
        if (want_scalar && t.count != 1)
            throw Error(SB() << s.where << ": " << key << ": '" << name << "' has " << t.count
                             << " values, not 1");
        return i;
    };
    for (Obj& o : objs_) {
        const ObjectSpec& s = o.spec;
        bool scalar_only = std::holds_alternative<PlantSpec>(s.behaviour) ||
                           std::holds_alternative<WithinSpec>(s.behaviour) ||
                           std::holds_alternative<CounterSpec>(s.behaviour);
        if (scalar_only && s.count != 1)
            throw Error(SB() << s.where << ": this behaviour has one value (count 1)");
        if (auto* p = std::get_if<PlantSpec>(&s.behaviour)) {
            o.input = ref(s, p->input, "plant input", true, {ObjectType::AO});
            if (!p->enable.empty())
                o.enable = ref(s, p->enable, "plant enable", true, {ObjectType::BO});
            o.plant_state = p->initial;
        } else if (auto* w = std::get_if<WithinSpec>(&s.behaviour)) {
            auto any = {ObjectType::AI, ObjectType::AO, ObjectType::BI,
                        ObjectType::BO, ObjectType::LI, ObjectType::LO};
            o.input = ref(s, w->value, "within value", true, any);
            o.target = ref(s, w->target, "within target", true, any);
        } else if (auto* c = std::get_if<CounterSpec>(&s.behaviour)) {
            if (!c->enable.empty())
                o.enable = ref(s, c->enable, "counter enable", true, {ObjectType::BO});
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
