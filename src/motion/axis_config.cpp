#include "motion/axis_config.hpp"

#include "config/yaml_reader.hpp"
#include "core/error_list.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

namespace beamctl::motion {
namespace {

constexpr const char* kSignalForm =
    "the form is ec<master>.s<slave>.<entry>[.<bit>], e.g. ec0.s3.driveStatus01.3";

using config::above;
using config::at_least;
using config::between;
using config::Range;

bool is_ident_start(char c) {
    return std::isalpha(static_cast<unsigned char>(c)) || c == '_';
}
bool is_ident_char(char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
}

std::string trim(std::string_view s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
    return std::string(s);
}

// Reads up to 6 decimal digits at s[i]; false when there are none.
bool read_number(std::string_view s, std::size_t& i, int& out) {
    const std::size_t start = i;
    out = 0;
    while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i])) && i - start < 6)
        out = out * 10 + (s[i++] - '0');
    if (i > start && !(i < s.size() && std::isdigit(static_cast<unsigned char>(s[i])))) return true;
    i = start;
    return false;
}

// Fills `r` from `s`; returns "" or what is wrong.
std::string parse_signal(std::string_view s, SignalRef& r) {
    const auto upto = [&](std::size_t i) { return std::string(s.substr(0, i)); };
    std::size_t i = 0;
    if (s.substr(0, 2) != "ec") return "it should start with ec<master>";
    i = 2;
    if (!read_number(s, i, r.bus)) return "expected the master number after 'ec'";
    if (i >= s.size() || s[i] != '.') return SB() << "expected '.' after '" << upto(i) << "'";
    ++i;
    if (i >= s.size() || s[i] != 's') return SB() << "expected s<slave> after '" << upto(i) << "'";
    ++i;
    const bool neg = i < s.size() && s[i] == '-';
    if (neg) ++i;
    if (!read_number(s, i, r.slave))
        return SB() << "expected the slave number after '" << upto(neg ? i - 1 : i) << "'";
    if (neg) {
        if (r.slave != 1) return "the slave should be >= -1 (-1 is the simulation slave)";
        r.slave = -1;
    }
    if (i >= s.size() || s[i] != '.')
        return SB() << "expected '.<entry>' after '" << upto(i) << "'";
    ++i;
    const std::size_t entry_start = i;
    if (i >= s.size() || !is_ident_start(s[i]))
        return SB() << "expected an entry name after '" << upto(i) << "'";
    while (i < s.size() && is_ident_char(s[i])) ++i;
    r.entry = std::string(s.substr(entry_start, i - entry_start));
    r.bit = -1;
    if (i < s.size() && s[i] == '.') {
        ++i;
        const std::size_t bit_start = i;
        if (!read_number(s, i, r.bit))
            return SB() << "expected a bit number after '" << upto(i) << "'";
        if (r.bit > 63)
            return SB() << "bit " << s.substr(bit_start, i - bit_start) << " should be 0..63";
    }
    if (i != s.size())
        return SB() << "unexpected '" << s.substr(i) << "' after '" << upto(i) << "'";
    r.text = std::string(s);
    return {};
}

const Range kBit = between(0, 63);

// A value as written, macros expanded, with the place of its first character.
struct Scalar {
    std::string text;
    SourceLoc at;
};

// ---- one file: the shared reader, with ECMC's macro and var expansion and link syntax ---------

class Reader {
public:
    // `yr` outlives the Reader; every scalar it reads is expanded by expand().
    Reader(config::YamlReader& yr, const MacroMap& macros)
        : yr_(yr)
        , macros_(macros) {
        yr_.set_expander([this](const std::string& raw, const SourceLoc& at,
                                const std::string& path) { return expand(raw, at, path); });
    }
    Reader(const Reader&) = delete;
    Reader& operator=(const Reader&) = delete;

    config::YamlReader& yaml() { return yr_; }
    const std::string& file() const { return yr_.file(); }
    SourceLoc top() const { return yr_.top(); }
    SourceLoc loc(const YAML::Node& n) const { return yr_.loc(n); }
    void problem(const SourceLoc& at, const std::string& msg) { yr_.error(at, msg); }
    void warn(const SourceLoc& at, const std::string& msg) { yr_.warn(at, msg); }

    void set_vars(std::map<std::string, std::string> vars) { vars_ = std::move(vars); }

    // The value of a scalar: `{{ var.X }}` substituted, then macros expanded.
    std::optional<std::string> expand(const std::string& raw, const SourceLoc& at,
                                      const std::string& path) {
        std::string s = raw;
        if (s.find("{{") != std::string::npos || s.find("{%") != std::string::npos) {
            auto v = substitute_vars(s, at, path);
            if (!v) return std::nullopt;
            s = std::move(*v);
        }
        if (s.find('$') == std::string::npos && s.find('\\') == std::string::npos) return s;
        try {
            return expand_macros(s, macros_, at, MacroEscapes::unescape);
        } catch (const Error& e) {
            macro_problem(e.what(), at, path);
            return std::nullopt;
        }
    }

    // The scalar text of `n` (expanded) with its place, or a problem; nullopt if absent.
    std::optional<Scalar> scalar(const config::YamlNode& n, std::string_view what) {
        auto text = n.scalar(what);
        if (!text) return std::nullopt;
        return Scalar{std::move(*text), n.loc()};
    }

    std::optional<double> number(const Scalar& s, const std::string& path, Range r = {}) {
        const auto v = config::parse_number(s.text);
        if (!v) {
            problem(s.at, SB() << path << " should be a number, got '" << s.text << "'");
            return std::nullopt;
        }
        if (!r.ok(*v)) {
            problem(s.at, SB() << path << " should be " << r.str() << ", got " << s.text);
            return std::nullopt;
        }
        return v;
    }
    std::optional<int64_t> integer(const Scalar& s, const std::string& path, Range r = {}) {
        const auto v = config::parse_integer(s.text);
        if (!v) {
            problem(s.at, SB() << path << " should be an integer, got '" << s.text << "'");
            return std::nullopt;
        }
        if (!r.ok(double(*v))) {
            problem(s.at, SB() << path << " should be " << r.str() << ", got " << s.text);
            return std::nullopt;
        }
        return v;
    }
    std::optional<bool> boolean(const Scalar& s, const std::string& path) {
        const auto v = config::parse_boolean(s.text);
        if (!v) problem(s.at, SB() << path << " should be true or false, got '" << s.text << "'");
        return v;
    }
    // A link; '' is "not linked" (as ecmccfg renders it) and gives nullopt.
    std::optional<SignalRef> signal(const Scalar& s, const std::string& path) {
        if (s.text.empty()) return std::nullopt;
        if (s.text == "plcOverride") {
            problem(s.at, SB() << path
                               << ": plcOverride is only possible for input.limit.forward, "
                                  "input.limit.backward and input.home");
            return std::nullopt;
        }
        SignalRef r;
        const std::string why = parse_signal(s.text, r);
        if (!why.empty()) {
            problem(s.at, SB() << path << ": '" << s.text << "' is not a signal link: " << why
                               << "; " << kSignalForm);
            return std::nullopt;
        }
        r.where = s.at;
        return r;
    }

private:
    std::optional<std::string> substitute_vars(const std::string& s, const SourceLoc& at,
                                               const std::string& path) {
        std::string out;
        std::size_t i = 0;
        while (i < s.size()) {
            if (s.compare(i, 2, "{%") == 0) {
                problem(at, SB() << path
                                 << ": jinja2 statements ({% ... %}) are not supported, "
                                    "only {{ var.NAME }}");
                return std::nullopt;
            }
            if (s.compare(i, 2, "{{") != 0) {
                out += s[i++];
                continue;
            }
            const std::size_t end = s.find("}}", i + 2);
            if (end == std::string::npos) {
                problem(at, SB() << path << ": '{{' without '}}'");
                return std::nullopt;
            }
            const std::string expr = trim(std::string_view(s).substr(i + 2, end - i - 2));
            const std::string name = expr.rfind("var.", 0) == 0 ? expr.substr(4) : std::string();
            if (name.empty() || !std::all_of(name.begin(), name.end(), is_ident_char)) {
                problem(at, SB() << path << ": only {{ var.NAME }} is supported, got '{{ " << expr
                                 << " }}'");
                return std::nullopt;
            }
            const auto it = vars_.find(name);
            if (it == vars_.end()) {
                problem(at, SB() << path << ": '" << name << "' is not a value in var:");
                return std::nullopt;
            }
            out += it->second;
            i = end + 2;
        }
        return out;
    }

    // expand_macros says "file:line:col: msg"; put the key path in front of msg.
    void macro_problem(const std::string& what, const SourceLoc& at, const std::string& path) {
        SourceLoc where = at;
        std::string msg = what;
        const std::string prefix = at.file + ":";
        if (what.rfind(prefix, 0) == 0) {
            std::size_t i = prefix.size();
            int line = 0, col = 0;
            if (read_number(what, i, line) && i < what.size() && what[i] == ':' &&
                read_number(what, ++i, col) && what.compare(i, 2, ": ") == 0) {
                where.line = line;
                where.col = col;
                msg = what.substr(i + 2);
            }
        }
        problem(where, SB() << path << ": " << msg);
    }

    config::YamlReader& yr_;
    const MacroMap& macros_;
    std::map<std::string, std::string> vars_;
};

// ---- one YAML mapping of ECMC's schema: allowed keys, typed values, links ---------------------

using Keys = std::initializer_list<std::string_view>;
using KnownKeys = std::initializer_list<config::KnownKey>;

class Map {
public:
    // `node` is the value (a mapping, or null for an empty section), maybe absent.
    Map(Reader& rd, config::YamlNode node, Keys allowed = {}, KnownKeys known = {})
        : rd_(&rd)
        , node_(std::move(node)) {
        if (node_.present()) bad_ = !node_.keys(allowed, known);
    }

    bool present() const { return node_.present(); }
    const std::string& path() const { return node_.path(); }
    SourceLoc loc() const { return node_.key_loc(); } // where the section's key is
    bool has(std::string_view key) const { return !bad_ && node_.has(key); }
    std::string sub(std::string_view key) const {
        return path().empty() ? std::string(key) : std::string(SB() << path() << "." << key);
    }
    SourceLoc key_loc(std::string_view key) const { return node_[key].key_loc(); }

    // A required key that is missing is a problem (not for a section that is itself wrong).
    void require(std::string_view key, std::string_view hint = {}) const {
        if (present() && !bad_) node_.required(key, hint);
    }
    // The schema's `dependencies`: when `key` is given, `needs` must be given too.
    void depends(std::string_view key, Keys needs) const {
        if (!has(key)) return;
        for (auto n : needs)
            if (!has(n))
                rd_->problem(key_loc(key), SB() << sub(key) << " needs " << sub(n) << " as well");
    }

    Map map(std::string_view key, Keys allowed, KnownKeys known = {}) const {
        return Map(*rd_, child(key), allowed, known);
    }
    // The value of `key`; absent when not given (or when this section is not a mapping).
    config::YamlNode child(std::string_view key) const {
        return bad_ ? config::YamlNode() : node_[key];
    }

    std::optional<Scalar> scalar(std::string_view key, std::string_view what) const {
        return rd_->scalar(child(key), what);
    }
    std::optional<std::string> string(std::string_view key) const {
        auto s = scalar(key, "a text");
        if (!s) return std::nullopt;
        return std::move(s->text);
    }
    std::optional<double> number(std::string_view key, Range r = {}) const {
        auto s = scalar(key, "a number");
        return s ? rd_->number(*s, sub(key), r) : std::nullopt;
    }
    std::optional<int64_t> integer(std::string_view key, Range r = {}) const {
        auto s = scalar(key, "an integer");
        return s ? rd_->integer(*s, sub(key), r) : std::nullopt;
    }
    std::optional<int> bit(std::string_view key) const {
        auto v = integer(key, kBit);
        return v ? std::optional<int>(int(*v)) : std::nullopt;
    }
    // An integer from `allowed`, `names` describing them ("0 (stepper) or 1 (DS402)").
    std::optional<int64_t> choice(std::string_view key, std::initializer_list<int64_t> allowed,
                                  std::string_view names) const {
        auto s = scalar(key, "an integer");
        if (!s) return std::nullopt;
        const auto v = config::parse_integer(s->text);
        if (!v || std::find(allowed.begin(), allowed.end(), *v) == allowed.end()) {
            rd_->problem(s->at, SB() << sub(key) << " should be " << names << ", got " << s->text);
            return std::nullopt;
        }
        return v;
    }
    std::optional<bool> boolean(std::string_view key) const {
        auto s = scalar(key, "true or false");
        return s ? rd_->boolean(*s, sub(key)) : std::nullopt;
    }
    // An optional link ('' = not linked).
    std::optional<SignalRef> signal(std::string_view key) const {
        auto s = scalar(key, "a signal link");
        return s ? rd_->signal(*s, sub(key)) : std::nullopt;
    }
    // A required link: missing or '' is a problem.
    SignalRef required_signal(std::string_view key) const {
        require(key);
        if (auto s = scalar(key, "a signal link")) {
            if (s->text.empty())
                rd_->problem(s->at, SB() << sub(key) << " should be a signal link, got ''; "
                                         << kSignalForm);
            else if (auto r = rd_->signal(*s, sub(key)))
                return *r;
        }
        return {};
    }
    // A limit or home switch: a link or plcOverride.
    std::optional<SwitchInput> switch_input(std::string_view key) const {
        auto s = scalar(key, "a signal link or plcOverride");
        if (!s) return std::nullopt;
        if (s->text == "plcOverride") return SwitchInput{true, {}};
        if (s->text.empty()) {
            rd_->problem(s->at, SB()
                                    << sub(key) << " should be a signal link or plcOverride, got ''"
                                    << " (an unused input is ec0.s<slave>.ONE.0)");
            return std::nullopt;
        }
        auto r = rd_->signal(*s, sub(key));
        if (!r) return std::nullopt;
        return SwitchInput{false, std::move(*r)};
    }

private:
    Reader* rd_;
    config::YamlNode node_;
    bool bad_ = false; // present but not a mapping
};


// ---- sections ---------------------------------------------------------------------------------

std::string lower_no_space(std::string_view s) {
    std::string out;
    for (char c : s)
        if (!std::isspace(static_cast<unsigned char>(c)))
            out += char(std::tolower(static_cast<unsigned char>(c)));
    return out;
}

// The type is needed before the other sections: a virtual axis has no drive.
AxisSection parse_axis_section(Reader& rd, const Map& m) {
    AxisSection a;
    if (auto v = m.integer("id", between(0, kMaxAxisId))) a.id = int(*v);
    if (auto s = m.scalar("type", "an axis type")) {
        const std::string t = lower_no_space(s->text);
        if (t == "1" || t == "j" || t == "joint" || t == "physical" || t == "motor" || t == "real")
            a.type = AxisType::Joint;
        else if (t == "2" || t == "e" || t == "ee" || t == "end_effector" || t == "endeffector" ||
                 t == "virtual")
            a.type = AxisType::Virtual;
        else if (t == "0" || t == "debug")
            rd.problem(s->at,
                       "axis.type debug (0) is not supported (ecmccfg renders no axis for it)");
        else
            rd.problem(s->at, SB() << "axis.type should be joint (1) or virtual (2), got '"
                                   << s->text << "'");
    }
    if (auto s = m.scalar("mode", "CSV, CSP or CSP_PC")) {
        std::string t = s->text;
        for (char& c : t) c = char(std::toupper(static_cast<unsigned char>(c)));
        if (t == "CSV")
            a.mode = DriveMode::CSV;
        else if (t == "CSP")
            a.mode = DriveMode::CSP;
        else if (t == "CSP_PC")
            a.mode = DriveMode::CSP_PC;
        else
            rd.problem(s->at,
                       SB() << "axis.mode should be CSV, CSP or CSP_PC, got '" << s->text << "'");
    }
    a.parameters = m.string("parameters").value_or("");
    a.health_output = m.signal("healthOutput");
    a.feed_switches_output = m.signal("feedSwitchesOutput");
    a.feed_switches_value = m.integer("feedSwitchesValue").value_or(1);
    a.group = m.string("group").value_or("");
    a.tweak_dist = m.number("tweakDist").value_or(1.0);
    if (const Map ae = m.map("autoEnable", {"enableTimeout", "disableTimeout", "atStartup"});
        ae.present()) {
        AxisSection::AutoEnable x;
        x.enable_timeout_s = ae.number("enableTimeout").value_or(-1);
        x.disable_timeout_s = ae.number("disableTimeout").value_or(-1);
        x.at_startup = ae.boolean("atStartup").value_or(false);
        a.auto_enable = x;
    }
    if (const Map am = m.map("autoMode", {"modeSet", "modeAct", "modeCmdMotion", "modeCmdHome"});
        am.present()) {
        AxisSection::AutoMode x;
        x.mode_set = am.signal("modeSet");
        x.mode_act = am.signal("modeAct");
        x.mode_cmd_motion = am.integer("modeCmdMotion");
        x.mode_cmd_home = am.integer("modeCmdHome");
        a.auto_mode = x;
    }
    const Map f = m.map("features", {"disableOnReset", "alarmAtHardLimits", "blockCom",
                                     "allowSrcChangeWhenEnabled", "allowedFunctions"});
    a.features.disable_on_reset = f.boolean("disableOnReset").value_or(false);
    a.features.alarm_at_hard_limits = f.boolean("alarmAtHardLimits").value_or(false);
    a.features.block_com = f.boolean("blockCom").value_or(false);
    a.features.allow_src_change_when_enabled =
        f.boolean("allowSrcChangeWhenEnabled").value_or(false);
    const Map af = f.map("allowedFunctions", {"positioning", "constantVelocity", "homing"});
    a.features.allow_positioning = af.boolean("positioning").value_or(true);
    a.features.allow_constant_velocity = af.boolean("constantVelocity").value_or(true);
    a.features.allow_homing = af.boolean("homing").value_or(true);
    return a;
}

EpicsConfig parse_epics(Reader& rd, const Map& m) {
    EpicsConfig e;
    if (auto s = m.scalar("name", "a name")) {
        if (s->text.empty() || std::any_of(s->text.begin(), s->text.end(), [](char c) {
                return std::isspace(static_cast<unsigned char>(c)) || c == '"' || c == '\'';
            }))
            rd.problem(s->at, SB() << "epics.name should be a PV name part without spaces or "
                                      "quotes, got '"
                                   << s->text << "'");
        else
            e.name = s->text;
    }
    e.precision = int(m.integer("precision", between(0, 17)).value_or(3));
    e.unit = m.string("unit").value_or("mm");
    e.description = m.string("description").value_or("");
    const Map mr =
        m.map("motorRecord", {"enable", "fieldInit", "description", "pvt", "syncSoftLimits"});
    e.motor_record.enable = mr.boolean("enable").value_or(true);
    e.motor_record.field_init = mr.string("fieldInit").value_or("");
    e.motor_record.description = mr.string("description").value_or("");
    e.motor_record.sync_soft_limits = mr.boolean("syncSoftLimits").value_or(false);
    if (const Map pvt = mr.map("pvt", {"npoints", "nreadback"}); pvt.present()) {
        EpicsConfig::MotorRecord::Pvt p;
        p.npoints = pvt.integer("npoints", at_least(0)).value_or(0);
        p.nreadback = pvt.integer("nreadback", at_least(0)).value_or(0);
        e.motor_record.pvt = p;
    }
    return e;
}

// drive.error / encoder.error: up to 3 bits of `status` or links.
// A bit of a status that is given but bad (reported already) is skipped without a word.
std::vector<SignalRef> parse_error_list(Reader& rd, const Map& m,
                                        const std::optional<SignalRef>& status) {
    std::vector<SignalRef> out;
    const config::YamlNode n = m.child("error");
    if (!n) return out;
    const std::string path = m.sub("error");
    if (!n.is_list()) {
        rd.problem(n.is_null() ? m.key_loc("error") : n.loc(),
                   SB() << path << " should be a list of status bits or links, got "
                        << config::describe(n.yaml()));
        return out;
    }
    const auto items = n.list();
    if (items.size() > kMaxErrorBits)
        rd.problem(items[kMaxErrorBits].loc(), SB() << path << " should have at most "
                                                    << kMaxErrorBits << " entries, got "
                                                    << items.size());
    for (std::size_t k = 0; k < items.size() && k < kMaxErrorBits; ++k) {
        const std::string item_path = items[k].path();
        auto s = rd.scalar(items[k], "a status bit or a link");
        if (!s) continue;
        if (config::parse_integer(s->text)) {
            const auto b = rd.integer(*s, item_path, kBit);
            if (!b) continue;
            if (!status) {
                if (!m.has("status"))
                    rd.problem(s->at, SB() << item_path << " is a bit of " << m.sub("status")
                                           << ", which is not given");
                continue;
            }
            SignalRef r = status->with_bit(int(*b));
            r.where = s->at;
            out.push_back(std::move(r));
        } else if (auto r = rd.signal(*s, item_path)) {
            out.push_back(std::move(*r));
        }
    }
    return out;
}

DriveConfig parse_drive(Reader& rd, const Map& m) {
    DriveConfig d;
    m.require("numerator", " (the schema's default 0 would give no motion)");
    if (auto s = m.scalar("numerator", "a number")) {
        if (auto v = rd.number(*s, m.sub("numerator"))) {
            if (*v == 0)
                rd.problem(s->at, "drive.numerator should not be 0 (it scales the setpoint)");
            d.numerator = *v;
        }
    }
    d.denominator = m.integer("denominator", at_least(1)).value_or(1);
    d.type = DriveType(m.choice("type", {0, 1}, "0 (stepper) or 1 (DS402)").value_or(0));
    d.setpoint = m.required_signal("setpoint");
    d.control = m.required_signal("control");
    d.status = m.required_signal("status");
    m.depends("reduceTorqueEnable", {"reduceTorque"});
    m.depends("reduceTorque", {"reduceTorqueEnable"});
    d.enable_bit = m.bit("enable").value_or(0);
    d.enabled_bit = m.bit("enabled").value_or(1);
    if (d.type == DriveType::DS402)
        for (const char* k : {"enable", "enabled"})
            if (m.has(k))
                rd.warn(m.key_loc(k), SB() << "drive." << k << " is not used by a DS402 drive");
    d.reset_bit = m.bit("reset");
    d.warning_bit = m.bit("warning");
    d.reduce_torque_bit = m.bit("reduceTorque");
    d.reduce_torque_enable = m.boolean("reduceTorqueEnable").value_or(false);
    d.errors = parse_error_list(
        rd, m, d.status.text.empty() ? std::nullopt : std::optional<SignalRef>(d.status));
    if (Map b = m.map("brake", {"enable", "output", "openDelay", "closeAhead"}); b.present()) {
        DriveConfig::Brake br;
        b.require("enable");
        br.enable = b.boolean("enable").value_or(false);
        br.output = b.required_signal("output");
        br.open_delay_cycles = b.integer("openDelay", at_least(0)).value_or(0);
        br.close_ahead_cycles = b.integer("closeAhead", at_least(0)).value_or(0);
        d.brake = br;
    }
    return d;
}

HomingConfig parse_homing(Reader& rd, const Map& m) {
    HomingConfig h;
    h.type =
        int(m.choice("type", {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14, 15, 21, 22, 25, 26},
                     "a homing sequence: 0..12, 14, 15, 21, 22, 25 or 26")
                .value_or(0));
    h.position = m.number("position");
    m.depends("postMoveEnable", {"postMovePosition"});
    h.post_move_enable = m.boolean("postMoveEnable").value_or(false);
    h.post_move_position = m.number("postMovePosition").value_or(0);
    h.latch_count = m.integer("latchCount", at_least(0));
    const Map v = m.map("velocity", {"to", "from"});
    h.velocity_to = v.number("to");
    h.velocity_from = v.number("from");
    h.acceleration = m.number("acceleration", above(0));
    h.deceleration = m.number("deceleration", above(0));
    h.timeout_s = m.integer("timeout", at_least(0));
    h.ref_to_enc_id_at_startup =
        m.integer("refToEncIDAtStartup", between(-1, double(kMaxEncoders))).value_or(-1);
    h.ref_at_home = m.integer("refAtHome").value_or(0);
    h.tol_to_prim = m.number("tolToPrim", at_least(0)).value_or(0);
    h.trigg = m.signal("trigg");
    h.ready = m.signal("ready");
    m.depends("trigg", {"ready"});
    m.depends("ready", {"trigg"});
    if (h.type == 26 && !(m.has("trigg") && m.has("ready")))
        rd.problem(m.key_loc("type"), SB() << m.sub("type") << " 26 (drive-internal homing) needs "
                                           << m.sub("trigg") << " and " << m.sub("ready"));
    return h;
}

const Keys kHomingKeys = {"type",           "position",
                          "postMoveEnable", "postMovePosition",
                          "latchCount",     "velocity",
                          "acceleration",   "deceleration",
                          "timeout",        "refToEncIDAtStartup",
                          "refAtHome",      "tolToPrim",
                          "trigg",          "ready"};
const KnownKeys kHomingKnown = {{"switchPolarity", "is ignored by ecmccfg (use input.homePolarity)"}};

std::optional<FilterConfig> parse_filter(const Map& m, FilterConfig defaults) {
    if (!m.present()) return std::nullopt;
    FilterConfig f;
    f.enable = m.boolean("enable").value_or(defaults.enable);
    f.size = m.integer("size", at_least(1)).value_or(defaults.size);
    return f;
}

EncoderConfig parse_encoder(Reader& rd, const Map& m) {
    EncoderConfig e;
    e.where = m.loc();
    e.source = EncoderSource(m.choice("source", {0, 1}, "0 (EtherCAT) or 1 (PLC)").value_or(0));
    bool numerator_ok = true; // absent (default 0) or a number
    if (auto s = m.scalar("numerator", "a number")) {
        const auto v = rd.number(*s, m.sub("numerator"));
        numerator_ok = v.has_value();
        e.numerator = v.value_or(0);
    } else {
        numerator_ok = !m.has("numerator");
    }
    e.denominator = m.integer("denominator", at_least(1)).value_or(1);
    e.type = EncoderType(m.choice("type", {0, 1}, "0 (incremental) or 1 (absolute)").value_or(0));
    e.mask = m.string("mask").value_or("");
    e.bits = int(m.integer("bits", between(0, 64)).value_or(16));
    e.abs_bits = int(m.integer("absBits", between(0, 64)).value_or(25));
    if (e.type == EncoderType::Absolute && e.abs_bits > e.bits)
        rd.problem(m.key_loc(m.has("absBits") ? "absBits" : "type"),
                   SB() << m.sub("absBits") << " (" << e.abs_bits << ") should be <= "
                        << m.sub("bits") << " (" << e.bits << ") for an absolute encoder");
    e.abs_offset = m.number("absOffset").value_or(0);
    if (Map lut = m.map("lookuptable", {"filename", "range", "scale", "enable"}); lut.present()) {
        EncoderConfig::LookupTable t;
        lut.require("filename");
        t.filename = lut.string("filename").value_or("");
        t.range = lut.number("range", at_least(0));
        t.scale = lut.number("scale");
        t.enable = lut.boolean("enable").value_or(true);
        e.lookuptable = t;
    }
    e.unit = m.string("unit").value_or("");
    e.desc = m.string("desc").value_or("");
    if (Map dc = m.map("delayComp", {"time", "enable"}); dc.present()) {
        EncoderConfig::DelayComp x;
        dc.require("time");
        x.time_cycles = dc.number("time", at_least(0)).value_or(0);
        x.enable = dc.boolean("enable").value_or(true);
        e.delay_comp = x;
    }
    e.allow_over_under_flow = m.boolean("allowOverUnderFlow");
    e.position = m.signal("position");
    if (e.source == EncoderSource::EtherCAT && numerator_ok && e.numerator == 0)
        rd.problem(
            m.key_loc(m.has("numerator") ? "numerator" : "position"),
            SB() << m.sub("numerator")
                 << " should not be 0 for an encoder read from "
                    "EtherCAT (source 0)"
                 << (m.has("numerator") ? "" : "; it is missing and ecmccfg's default is 0"));
    if (e.source == EncoderSource::EtherCAT && !e.position)
        rd.problem(m.key_loc("position"),
                   SB() << m.path() << ": an encoder read from EtherCAT (source 0) needs "
                        << m.sub("position") << "; for a value written by a PLC set "
                        << m.sub("source") << ": 1");
    e.control = m.signal("control");
    e.status = m.signal("status");
    m.depends("warning", {"status"});
    m.depends("ready", {"status"});
    m.depends("reset", {"control"});
    e.warning_bit = m.bit("warning");
    e.ready_bit = m.bit("ready");
    e.reset_bit = m.bit("reset");
    e.errors = parse_error_list(rd, m, e.status);
    if (const Map f = m.map("filter", {"velocity", "trajectory", "position"}); f.present()) {
        e.velocity_filter = parse_filter(f.map("velocity", {"enable", "size"}), {true, 100});
        if (f.has("trajectory"))
            rd.warn(f.key_loc("trajectory"),
                    SB() << f.sub("trajectory") << " is the legacy name of " << f.sub("position"));
        e.position_filter = parse_filter(f.map("trajectory", {"enable", "size"}), {true, 10});
        if (auto p = parse_filter(f.map("position", {"enable", "size"}), {true, 10}))
            e.position_filter = p;
    }
    if (Map l = m.map("latch", {"position", "control", "armCmd", "armBits", "status"});
        l.present()) {
        EncoderConfig::Latch x;
        x.position = l.required_signal("position");
        x.control_bit = l.bit("control").value_or(0);
        x.status_bit = l.bit("status").value_or(0);
        x.arm_cmd = l.integer("armCmd").value_or(1);
        x.arm_bits = l.integer("armBits", between(1, 64)).value_or(1);
        m.depends("latch", {"control", "status"});
        e.latch = x;
    }
    if (auto s = m.scalar("primary", "true or false"))
        e.primary = rd.boolean(*s, m.sub("primary")).value_or(false);
    if (auto s = m.scalar("useAsCSPDrvEnc", "true or false"))
        e.use_as_csp_drive_encoder = rd.boolean(*s, m.sub("useAsCSPDrvEnc")).value_or(false);
    if (const Map h = m.map("homing", kHomingKeys, kHomingKnown); h.present())
        e.homing = parse_homing(rd, h);
    return e;
}

const Keys kEncoderKeys = {
    "source",        "numerator", "denominator", "type",   "mask",      "bits",
    "absBits",       "absOffset", "lookuptable", "unit",   "delayComp", "allowOverUnderFlow",
    "desc",          "position",  "control",     "status", "warning",   "ready",
    "reset",         "error",     "filter",      "latch",  "primary",   "homing",
    "useAsCSPDrvEnc"};
const KnownKeys kEncoderKnown = {
    {"velocityFilterSize", "is ignored by ecmccfg (use encoder.filter.velocity.size)"},
    {"positionFilterSize", "is ignored by ecmccfg (use encoder.filter.position.size)"},
    {"positionFilterEnable", "is ignored by ecmccfg (use encoder.filter.position.enable)"}};

ControllerConfig parse_controller(const Map& m) {
    ControllerConfig c;
    c.kp = m.number("Kp", at_least(0)).value_or(1);
    c.ki = m.number("Ki", at_least(0)).value_or(0);
    c.kd = m.number("Kd", at_least(0)).value_or(0);
    c.kff = m.number("Kff", at_least(0)).value_or(1);
    if (const Map in = m.map("inner", {"Kp", "Ki", "Kd", "tol"}); in.present()) {
        ControllerConfig::Inner x;
        x.kp = in.number("Kp", at_least(0)).value_or(1);
        x.ki = in.number("Ki", at_least(0)).value_or(0);
        x.kd = in.number("Kd", at_least(0)).value_or(0);
        x.tol = in.number("tol", at_least(0)).value_or(0);
        c.inner = x;
    }
    const Map l = m.map("limits", {"minOutput", "maxOutput", "minIntegral", "maxIntegral"});
    c.limits.min_output = l.number("minOutput").value_or(0);
    c.limits.max_output = l.number("maxOutput").value_or(0);
    c.limits.min_integral = l.number("minIntegral").value_or(0);
    c.limits.max_integral = l.number("maxIntegral").value_or(0);
    if (Map db = m.map("deadband", {"tol", "time"}); db.present()) {
        ControllerConfig::Deadband x;
        db.require("tol");
        db.require("time");
        x.tol = db.number("tol", at_least(0)).value_or(0);
        x.time_cycles = db.integer("time", at_least(0)).value_or(0);
        c.deadband = x;
    }
    return c;
}

TrajectoryConfig parse_trajectory(const Map& m) {
    TrajectoryConfig t;
    t.source = TrajectorySource(
        m.choice("source", {0, 1}, "0 (internal trajectory) or 1 (PLC)").value_or(0));
    t.type = TrajectoryType(m.choice("type", {0, 1}, "0 (trapezoid) or 1 (S-curve)").value_or(0));
    m.require("axis", " (with velocity and acceleration)");
    Map a = m.map("axis",
                  {"velocity", "acceleration", "jerk", "deceleration", "emergencyDeceleration"});
    a.require("velocity");
    a.require("acceleration");
    t.axis.velocity = a.number("velocity", above(0)).value_or(1);
    t.axis.acceleration = a.number("acceleration", above(0)).value_or(1);
    const auto dec = a.number("deceleration", above(0));
    t.axis.deceleration = dec.value_or(t.axis.acceleration);
    t.axis.jerk = a.number("jerk", above(0)).value_or(t.axis.acceleration);
    // As trajectory.jinja2: 10 x deceleration if it is given and above acceleration.
    t.axis.emergency_deceleration =
        a.number("emergencyDeceleration", above(0))
            .value_or(10.0 * (dec && *dec > t.axis.acceleration ? *dec : t.axis.acceleration));
    const Map j = m.map("jog", {"velocity", "acceleration"});
    t.jog.velocity = j.number("velocity", above(0)).value_or(t.axis.velocity);
    t.jog.acceleration = j.number("acceleration", above(0)).value_or(t.axis.acceleration);
    if (const Map mod = m.map("modulo", {"range", "type"}); mod.present()) {
        TrajectoryConfig::Modulo x;
        x.range = mod.number("range", at_least(0)).value_or(0);
        x.type = ModuloType(
            mod.choice("type", {0, 1, 2, 3}, "0 (normal), 1 (forward), 2 (backward) or 3 (closest)")
                .value_or(0));
        t.modulo = x;
    }
    return t;
}

int polarity(const Map& m, std::string_view key) {
    return int(m.choice(key, {0, 1}, "0 or 1").value_or(0));
}

InputConfig parse_input(const Map& m) {
    InputConfig in;
    m.require("limit", " (with forward and backward)");
    Map l = m.map("limit",
                  {"forward", "forwardPolarity", "backward", "backwardPolarity", "latchInput"});
    l.require("forward", " (an unused input is ec0.s<slave>.ONE.0)");
    l.require("backward", " (an unused input is ec0.s<slave>.ONE.0)");
    if (auto f = l.switch_input("forward")) in.limit_forward = std::move(*f);
    if (auto b = l.switch_input("backward")) in.limit_backward = std::move(*b);
    in.limit_forward_polarity = polarity(l, "forwardPolarity");
    in.limit_backward_polarity = polarity(l, "backwardPolarity");
    in.latch_limits = l.boolean("latchInput");
    in.home = m.switch_input("home");
    in.home_polarity = polarity(m, "homePolarity");
    in.interlock = m.signal("interlock");
    in.interlock_polarity = polarity(m, "interlockPolarity");
    if (const Map a = m.map("analog", {"interlock", "rawLimit", "interlockPolarity", "enable"});
        a.present()) {
        InputConfig::Analog x;
        x.raw_limit = a.number("rawLimit");
        x.interlock_polarity = polarity(a, "interlockPolarity");
        x.enable = a.boolean("enable").value_or(true);
        if (auto s = a.signal("interlock")) {
            x.interlock = std::move(*s);
            in.analog = std::move(x);
        }
    }
    return in;
}

SoftLimitsConfig parse_softlimits(Reader& rd, const Map& m) {
    SoftLimitsConfig s;
    m.depends("forwardEnable", {"forward", "enable"});
    m.depends("forward", {"forwardEnable"});
    m.depends("backwardEnable", {"backward", "enable"});
    m.depends("backward", {"backwardEnable"});
    s.enable = m.boolean("enable").value_or(false);
    s.forward = m.number("forward").value_or(0);
    s.forward_enable = m.boolean("forwardEnable").value_or(false);
    s.backward = m.number("backward").value_or(0);
    s.backward_enable = m.boolean("backwardEnable").value_or(false);
    if (s.enable && s.forward_enable && s.backward_enable && !(s.backward < s.forward))
        rd.problem(m.key_loc("backward"), SB() << "softlimits.backward (" << s.backward
                                               << ") should be below softlimits.forward ("
                                               << s.forward << ")");
    return s;
}

MonitoringConfig::Window parse_window(const Map& m, MonitoringConfig::Window def) {
    if (!m.present()) return def;
    MonitoringConfig::Window w;
    m.require("enable");
    m.depends("enable", {"tolerance", "time"});
    w.enable = m.boolean("enable").value_or(false);
    w.tolerance = m.number("tolerance", at_least(0)).value_or(0);
    w.time_cycles = m.integer("time", at_least(0)).value_or(0);
    return w;
}

MonitoringConfig::Velocity parse_velocity_mon(const Map& m) {
    MonitoringConfig::Velocity v;
    if (!m.present()) return v;
    m.require("enable");
    m.depends("enable", {"max", "time"});
    v.enable = m.boolean("enable").value_or(false);
    v.max = m.number("max", at_least(0)).value_or(0);
    const Map t = m.map("time", {"trajectory", "drive"});
    t.require("trajectory");
    v.trajectory_cycles = t.integer("trajectory", at_least(0)).value_or(0);
    v.drive_cycles = t.integer("drive", at_least(0));
    return v;
}

MonitoringConfig parse_monitoring(const Map& m) {
    MonitoringConfig mon;
    const Keys window = {"enable", "tolerance", "time"};
    mon.lag = parse_window(m.map("lag", window), mon.lag);
    mon.target = parse_window(m.map("target", window), mon.target);
    const Keys velocity = {"enable", "max", "time"};
    mon.velocity = parse_velocity_mon(m.map("velocity", velocity));
    mon.velocity_difference = parse_velocity_mon(m.map("velocityDifference", velocity));
    const Map st = m.map("stall", {"enable", "time"});
    const Map st_time = st.map("time", {"timeout", "factor"});
    MonitoringConfig::Stall stall;
    stall.enable = st.boolean("enable").value_or(false);
    stall.timeout_cycles = st_time.integer("timeout", at_least(0));
    stall.factor = st_time.number("factor", at_least(0));
    if (st.has("enable")) mon.stall = stall; // as monitoring.jinja2: nothing without enable
    return mon;
}

AxisPlcConfig parse_plc(Reader& rd, const Map& m) {
    AxisPlcConfig p;
    m.require("enable");
    p.enable = m.boolean("enable").value_or(false);
    p.external_commands = m.boolean("externalCommands").value_or(false);
    p.file = m.string("file").value_or("");
    p.macros = m.string("macros").value_or("");
    if (const config::YamlNode code = m.child("code")) {
        if (!code.is_list()) {
            rd.problem(code.is_null() ? m.key_loc("code") : code.loc(),
                       SB() << code.path() << " should be a list of PLC lines, got "
                            << config::describe(code.yaml()));
        } else {
            for (const config::YamlNode& line : code.list())
                if (auto s = rd.scalar(line, "a line of PLC code"))
                    p.code.push_back(std::move(s->text));
        }
    }
    const Keys filter_keys = {"enable", "size"};
    const FilterConfig off{false, 1}; // axisSynchronization.jinja2 defaults
    const Map vf = m.map("velocity_filter", {"trajectory", "encoder"});
    const Map legacy = m.map("filter", {"velocity", "trajectory", "position"});
    if (legacy.present())
        rd.warn(m.key_loc("filter"),
                SB() << m.sub("filter") << " is the legacy form of " << m.sub("velocity_filter"));
    auto enc = parse_filter(vf.map("encoder", filter_keys), off);
    auto legacy_enc = parse_filter(legacy.map("velocity", filter_keys), off);
    p.encoder_velocity_filter = enc ? *enc : legacy_enc.value_or(off);
    auto traj = parse_filter(vf.map("trajectory", filter_keys), off);
    auto legacy_pos = parse_filter(legacy.map("position", filter_keys), off);
    auto legacy_traj = parse_filter(legacy.map("trajectory", filter_keys), off);
    p.trajectory_velocity_filter = traj         ? *traj
                                   : legacy_pos ? *legacy_pos
                                                : legacy_traj.value_or(off);
    return p;
}

std::map<std::string, std::string> parse_meta(const Map& m) {
    std::map<std::string, std::string> out;
    for (const char* k : {"author", "facility", "device", "date", "md5", "ecb", "ecbBuild",
                          "ecbVersion", "schemaNumber"})
        if (auto s = m.string(k)) out[k] = *s;
    return out;
}

// `var:` values that {{ var.NAME }} can use (scalars only).
void read_vars(Reader& rd, const YAML::Node& root) {
    std::map<std::string, std::string> vars;
    for (auto it = root.begin(); it != root.end(); ++it) {
        if (!it->first.IsScalar() || it->first.Scalar() != "var") continue;
        const YAML::Node v = it->second;
        if (v.IsNull()) continue;
        if (!v.IsMap()) {
            rd.problem(rd.loc(v), SB() << "var should be a mapping, got " << config::describe(v));
            continue;
        }
        for (auto kv = v.begin(); kv != v.end(); ++kv)
            if (kv->first.IsScalar() && kv->second.IsScalar())
                vars[kv->first.Scalar()] = kv->second.Scalar();
    }
    rd.set_vars(std::move(vars));
}

// The root mapping, or nullopt after a problem (syntax error, empty file, not a mapping).
std::optional<config::YamlNode> load_root(Reader& rd, std::string_view needs) {
    config::YamlNode root = rd.yaml().root();
    if (!root) return std::nullopt; // the reader said why
    if (root.is_null()) {
        rd.problem(rd.top(), SB() << "the file is empty; it needs " << needs);
        return std::nullopt;
    }
    if (!root.is_map()) {
        rd.problem(root.loc(), SB() << "the file should be a mapping of sections (" << needs
                                    << "), got " << config::describe(root.yaml()));
        return std::nullopt;
    }
    return root;
}

const Keys kTopKeys = {"axis",       "epics", "drive",  "encoder",    "controller",
                       "trajectory", "input", "homing", "softlimits", "monitoring",
                       "plc",        "var",   "meta"};
const Keys kMetaKeys = {"author", "facility", "device",     "date",        "md5",
                        "ecb",    "ecbBuild", "ecbVersion", "schemaNumber"};

void parse_axis_file(Reader& rd, AxisConfig& cfg) {
    const auto root = load_root(rd, "axis:, encoder:, trajectory:, input: and, for a joint "
                                    "axis, drive:");
    if (!root) return;
    read_vars(rd, root->yaml());
    Map top(rd, *root, kTopKeys,
            {{"output", "is ignored by ecmccfg (use axis.healthOutput and drive.brake.output)"},
             {"motorRecord",
              "ecmccfg ignores it here; it is the old form of epics: and epics.motorRecord:",
              true}});
    for (const char* k : {"axis", "encoder", "trajectory", "input"}) top.require(k);

    const Map axis = top.map("axis", {"id", "type", "mode", "parameters", "healthOutput",
                                      "feedSwitchesOutput", "feedSwitchesValue", "group",
                                      "tweakDist", "autoEnable", "autoMode", "features"});
    cfg.axis = parse_axis_section(rd, axis);
    cfg.epics = parse_epics(rd, top.map("epics",
                                        {"name", "precision", "unit", "description", "motorRecord"},
                                        {{"fieldInit",
                                          "ecmccfg ignores it here; use epics.motorRecord.fieldInit",
                                          true}}));
    const Keys drive_keys = {"numerator",
                             "denominator",
                             "type",
                             "setpoint",
                             "control",
                             "status",
                             "reduceTorqueEnable",
                             "reduceTorque",
                             "enable",
                             "enabled",
                             "brake",
                             "warning",
                             "reset",
                             "error"};
    if (cfg.is_virtual()) {
        for (const char* k : {"drive", "controller"})
            if (top.has(k))
                rd.problem(top.key_loc(k), SB() << "a virtual axis (axis.type virtual) has no " << k
                                                << "; remove it or make the axis a joint");
    } else {
        top.require("drive");
        if (Map d = top.map("drive", drive_keys); d.present()) cfg.drive = parse_drive(rd, d);
    }

    Map enc = top.map("encoder", kEncoderKeys, kEncoderKnown);
    if (enc.present()) cfg.encoders.push_back(parse_encoder(rd, enc));
    if (const Map h = top.map("homing", kHomingKeys, kHomingKnown); h.present()) {
        HomingConfig legacy = parse_homing(rd, h);
        if (!cfg.encoders.empty() && cfg.encoders[0].homing)
            rd.problem(top.key_loc("homing"), "homing and encoder.homing are both given; ecmccfg "
                                              "allows only one (use encoder.homing)");
        else if (!cfg.encoders.empty()) {
            rd.warn(top.key_loc("homing"), "top-level homing is the legacy form of encoder.homing");
            cfg.encoders[0].homing = legacy;
        }
    }
    if (!cfg.is_virtual())
        cfg.controller = parse_controller(
            top.map("controller", {"Kp", "Ki", "Kd", "Kff", "inner", "limits", "deadband"}));
    if (Map t = top.map("trajectory", {"source", "type", "axis", "jog", "modulo"}); t.present())
        cfg.trajectory = parse_trajectory(t);
    if (Map in = top.map(
            "input", {"limit", "home", "homePolarity", "interlock", "interlockPolarity", "analog"});
        in.present())
        cfg.input = parse_input(in);
    Map sl =
        top.map("softlimits", {"enable", "forwardEnable", "forward", "backwardEnable", "backward"});
    cfg.softlimits = parse_softlimits(rd, sl);
    const Map mon =
        top.map("monitoring", {"lag", "target", "velocity", "velocityDifference", "stall"});
    if (!mon.present())
        rd.warn(rd.top(), "no monitoring section: lag and at-target monitoring are off (the "
                          "ecmccfg manual asks for the key in every axis file)");
    cfg.monitoring = parse_monitoring(mon);
    if (Map plc = top.map("plc", {"enable", "externalCommands", "filter", "velocity_filter", "file",
                                  "macros", "code"});
        plc.present())
        cfg.plc = parse_plc(rd, plc);
    cfg.meta = parse_meta(top.map("meta", kMetaKeys));
}

void parse_encoder_file(Reader& rd, EncoderConfig& enc) {
    const auto root = load_root(rd, "encoder:");
    if (!root) return;
    read_vars(rd, root->yaml());
    Map top(rd, *root, {"encoder", "meta", "var"},
            {{"homing", "ecmccfg ignores it here; use encoder.homing", true}});
    top.require("encoder");
    Map e = top.map("encoder", kEncoderKeys, kEncoderKnown);
    if (e.present()) enc = parse_encoder(rd, e);
    parse_meta(top.map("meta", kMetaKeys));
}

std::optional<std::string> read_file(const std::string& path, std::string& error) {
    std::ifstream f(path, std::ios::binary);
    if (!f) {
        error = SB() << path << ": cannot open: " << std::strerror(errno);
        return std::nullopt;
    }
    std::ostringstream ss;
    ss << f.rdbuf();
    return ss.str();
}

// The reader's errors (sorted by position) appended to `out`.
void take_errors(config::YamlReader& yr, std::vector<Error>& out) {
    const ErrorList errors = yr.take_errors();
    for (const auto& m : errors.messages()) out.emplace_back(m);
}

// One MultiError with every error, if there is one.
void throw_all(const std::vector<Error>& errors) {
    ErrorList l;
    for (const auto& e : errors) l.add(std::string(e.what()));
    l.throw_if_any();
}

} // namespace

// ---- public -----------------------------------------------------------------------------------

SignalRef SignalRef::with_bit(int b) const {
    SignalRef r = *this;
    r.bit = b;
    r.text = SB() << "ec" << bus << ".s" << slave << "." << entry << "." << b;
    return r;
}

SignalRef parse_signal_ref(std::string_view text, const SourceLoc& where) {
    SignalRef r;
    const std::string why = parse_signal(text, r);
    if (!why.empty())
        throw Error(SB() << where.str() << ": '" << text << "' is not a signal link: " << why
                         << "; " << kSignalForm);
    r.where = where;
    return r;
}

std::size_t AxisConfig::primary_encoder() const {
    std::size_t p = 0;
    for (std::size_t i = 0; i < encoders.size(); ++i)
        if (encoders[i].primary) p = i;
    return p;
}

AxisConfig parse_axis_config(std::string_view text, const std::string& filename,
                             const MacroMap& macros) {
    std::vector<Error> errors;
    AxisConfig cfg = parse_axis_config(text, filename, macros, errors);
    throw_all(errors);
    return cfg;
}

AxisConfig parse_axis_config(std::string_view text, const std::string& filename,
                             const MacroMap& macros, std::vector<Error>& errors) {
    config::YamlReader yr(filename, std::string(text));
    yr.set_unknown_keys_ignored(true); // ECMC's loader drops them
    Reader rd(yr, macros);
    AxisConfig cfg;
    cfg.file = filename;
    parse_axis_file(rd, cfg);
    cfg.warnings = yr.take_warnings();
    take_errors(yr, errors);
    return cfg;
}

AxisConfig load_axis_config(const std::string& path, const MacroMap& macros) {
    std::vector<Error> errors;
    AxisConfig cfg = load_axis_config(path, macros, errors);
    throw_all(errors);
    return cfg;
}

AxisConfig load_axis_config(const std::string& path, const MacroMap& macros,
                            std::vector<Error>& errors) {
    std::string error;
    const auto text = read_file(path, error);
    if (!text) {
        errors.emplace_back(error);
        AxisConfig cfg;
        cfg.file = path;
        return cfg;
    }
    return parse_axis_config(*text, path, macros, errors);
}

EncoderConfig parse_encoder_config(std::string_view text, const std::string& filename,
                                   const MacroMap& macros) {
    std::vector<Error> errors;
    EncoderConfig enc = parse_encoder_config(text, filename, macros, errors);
    throw_all(errors);
    return enc;
}

EncoderConfig parse_encoder_config(std::string_view text, const std::string& filename,
                                   const MacroMap& macros, std::vector<Error>& errors) {
    config::YamlReader yr(filename, std::string(text));
    yr.set_unknown_keys_ignored(true); // ECMC's loader drops them
    Reader rd(yr, macros);
    EncoderConfig enc;
    parse_encoder_file(rd, enc);
    enc.warnings = yr.take_warnings();
    take_errors(yr, errors);
    return enc;
}

EncoderConfig load_encoder_config(const std::string& path, const MacroMap& macros) {
    std::vector<Error> errors;
    EncoderConfig enc = load_encoder_config(path, macros, errors);
    throw_all(errors);
    return enc;
}

EncoderConfig load_encoder_config(const std::string& path, const MacroMap& macros,
                                  std::vector<Error>& errors) {
    std::string error;
    const auto text = read_file(path, error);
    if (!text) {
        errors.emplace_back(error);
        return {};
    }
    return parse_encoder_config(*text, path, macros, errors);
}

void add_encoder(AxisConfig& axis, EncoderConfig encoder) {
    if (axis.encoders.size() >= kMaxEncoders)
        throw Error(SB() << encoder.where.str() << ": axis "
                         << (axis.axis.id ? std::to_string(*axis.axis.id) : axis.epics.name)
                         << " already has " << kMaxEncoders << " encoders (ECMC's limit)");
    for (auto& w : encoder.warnings) axis.warnings.push_back(std::move(w));
    encoder.warnings.clear();
    axis.encoders.push_back(std::move(encoder));
}

} // namespace beamctl::motion
