#include "pv/link.hpp"

#include "pv/convert.hpp"
#include "pv/record.hpp"

#include <cctype>
#include <cstring>

namespace beamctl::pv {
namespace {

std::string_view trim(std::string_view s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
    return s;
}

bool fail(std::string* why, std::string msg) {
    if (why) *why = std::move(msg);
    return false;
}

// A tiny reader for the JSON link forms we accept ({const: ...}, [..]); keys may be bare words.
struct Json {
    std::string_view s;
    std::size_t i = 0;
    void ws() {
        while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
    }
    bool eat(char c) {
        ws();
        if (i < s.size() && s[i] == c) {
            ++i;
            return true;
        }
        return false;
    }
    bool string(std::string& out) {
        ws();
        if (i >= s.size() || s[i] != '"') return false;
        ++i;
        out.clear();
        while (i < s.size() && s[i] != '"') {
            if (s[i] == '\\' && i + 1 < s.size()) ++i;
            out.push_back(s[i++]);
        }
        if (i >= s.size()) return false;
        ++i;
        return true;
    }
    bool word(std::string& out) {
        ws();
        if (i < s.size() && s[i] == '"') return string(out);
        out.clear();
        while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) out.push_back(s[i++]);
        return !out.empty();
    }
    bool number(double& v) {
        ws();
        std::size_t b = i;
        while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '.' || s[i] == '-' ||
                                s[i] == '+'))
            ++i;
        return i > b && parse_double(s.substr(b, i - b), v);
    }
};

// The value of a JSON constant: a number, a string, or an array of numbers (or strings: the first).
bool json_constant(Json& j, Link& out, std::string* why) {
    j.ws();
    if (j.i < j.s.size() && j.s[j.i] == '[') {
        ++j.i;
        if (j.eat(']')) return true;
        do {
            double v;
            std::string str;
            if (j.string(str)) {
                if (!out.state->spec->is_string_constant) out.state->spec->string_constant = str;
                out.state->spec->is_string_constant = true;
            } else if (j.number(v)) {
                out.state->spec->numbers.push_back(v);
            } else {
                return fail(why, "bad array element in a JSON constant");
            }
        } while (j.eat(','));
        if (!j.eat(']')) return fail(why, "expected ']' in a JSON array constant");
        return true;
    }
    std::string str;
    if (j.string(str)) {
        out.state->spec->string_constant = str;
        out.state->spec->is_string_constant = true;
        return true;
    }
    double v;
    if (j.number(v)) {
        out.state->spec->numbers.push_back(v);
        return true;
    }
    return fail(why, "expected a number, a string or an array in a JSON constant");
}

bool parse_json(std::string_view text, Link& out, std::string* why) {
    Json j{text};
    out.kind = Link::Kind::Constant;
    if (text[0] == '[') {
        if (!json_constant(j, out, why)) return false;
    } else {
        j.eat('{');
        std::string key;
        if (!j.word(key)) return fail(why, "expected a link type in JSON link " + std::string(text));
        if (key != "const")
            return fail(why, "JSON link type '" + key + "' is not supported (supported: const)");
        if (!j.eat(':')) return fail(why, "expected ':' after \"const\"");
        if (!json_constant(j, out, why)) return false;
        if (!j.eat('}')) return fail(why, "expected '}' at the end of the JSON link");
    }
    j.ws();
    if (j.i != text.size()) return fail(why, "unexpected text after the JSON link: " + std::string(text.substr(j.i)));
    return true;
}

bool valid_record_char(char c) {
    return !(std::isspace(static_cast<unsigned char>(c)) || c == '"' || c == '\'' || c == '$' || c == '{' ||
             c == '}' || c < 32);
}

} // namespace

const char* link_proc_name(uint8_t proc) {
    static const char* n[] = {"NPP", "PP", "CA", "CP", "CPP"};
    return proc < 5 ? n[proc] : "?";
}

const char* link_ms_name(uint8_t ms) {
    static const char* n[] = {"NMS", "MS", "MSS", "MSI"};
    return ms < 4 ? n[ms] : "?";
}

std::string_view Link::record_name() const {
    if (state && !state->spec && state->target) return state->target->name();
    return s().record;
}

std::string_view Link::field_name() const {
    if (state && !state->spec && state->target_field) return state->field_written ? state->target_field->name : "";
    return s().field;
}

void Link::forget_spec() {
    if (kind != Kind::Db || !state || !state->spec || !state->target || !state->target_field) return;
    const LinkSpec& sp = *state->spec;
    if (!sp.field.empty() && sp.field != state->target_field->name) return;
    if (sp.record != state->target->name()) return; // reached through an alias: keep the name written
    state->field_written = !sp.field.empty();
    state->spec.reset();
}

void Link::restore_spec() {
    if (kind != Kind::Db || !state || state->spec) return;
    auto sp = std::make_unique<LinkSpec>();
    sp->record = std::string(record_name());
    sp->field = std::string(field_name());
    sp->text = canonical();
    state->spec = std::move(sp);
}

std::string Link::canonical() const {
    const LinkSpec& sp = s();
    switch (kind) {
    case Kind::Empty: return {};
    case Kind::Constant: return sp.text;
    case Kind::Hw: return "@" + sp.address;
    case Kind::Db: {
        std::string r(record_name());
        if (std::string_view f = field_name(); !f.empty()) (r += '.') += f;
        return r + " " + link_proc_name(proc) + " " + link_ms_name(ms);
    }
    }
    return sp.text;
}

bool parse_link(std::string_view text, Dbf type, Link& out, std::string* why) {
    Link l;
    std::string_view t = trim(text);
    if (t.empty()) {
        out = std::move(l);
        return true;
    }
    l.state = std::make_unique<LinkState>();
    l.state->spec = std::make_unique<LinkSpec>();
    LinkSpec& spec = *l.state->spec;
    spec.text = std::string(t);
    t = spec.text;
    if (t[0] == '@') {
        if (type == Dbf::FwdLink) return fail(why, "a forward link cannot be a hardware address (@...)");
        l.kind = Link::Kind::Hw;
        spec.address = std::string(trim(t.substr(1)));
        out = std::move(l);
        return true;
    }
    if (t[0] == '{' || t[0] == '[') {
        if (!parse_json(t, l, why)) return false;
        if (type != Dbf::InLink) return fail(why, "a constant link can only be an input link");
        out = std::move(l);
        return true;
    }
    double v;
    if (parse_double(t, v) || (t.size() > 2 && t[0] == '0' && (t[1] == 'x' || t[1] == 'X'))) {
        int64_t iv;
        if (!parse_double(t, v)) {
            if (!parse_int(t, iv)) return fail(why, "'" + std::string(t) + "' is not a number");
            v = double(iv);
        }
        if (type == Dbf::FwdLink) { // EPICS treats a numeric FLNK as no link
            l.kind = Link::Kind::Empty;
            l.state.reset();
        } else {
            l.kind = Link::Kind::Constant;
            spec.numbers.push_back(v);
        }
        out = std::move(l);
        return true;
    }
    // "rec[.FIELD] [modifiers]"
    std::size_t end = 0;
    while (end < t.size() && !std::isspace(static_cast<unsigned char>(t[end])) && t[end] != ',') ++end;
    std::string_view name = t.substr(0, end);
    std::size_t dot = name.find('.');
    spec.record = std::string(name.substr(0, dot));
    if (dot != std::string_view::npos) spec.field = std::string(name.substr(dot + 1));
    if (spec.record.empty()) return fail(why, "link '" + std::string(t) + "' names no record");
    for (char c : spec.record)
        if (!valid_record_char(c))
            return fail(why, std::string("record name in link '") + std::string(t) + "' contains '" + c + "'");
    for (char c : spec.field)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_')
            return fail(why, "field '" + spec.field + "' in link '" + std::string(t) +
                                 "': field modifiers, array ranges and filters are not supported");
    bool have_proc = false, have_ms = false;
    std::string_view rest = t.substr(end);
    while (true) {
        while (!rest.empty() && (std::isspace(static_cast<unsigned char>(rest[0])) || rest[0] == ','))
            rest.remove_prefix(1);
        if (rest.empty()) break;
        std::size_t n = 0;
        while (n < rest.size() && !std::isspace(static_cast<unsigned char>(rest[n])) && rest[n] != ',') ++n;
        std::string_view m = rest.substr(0, n);
        rest.remove_prefix(n);
        static const char* procs[] = {"NPP", "PP", "CA", "CP", "CPP"};
        static const char* mss[] = {"NMS", "MS", "MSS", "MSI"};
        bool known = false;
        for (uint8_t k = 0; k < 5 && !known; ++k)
            if (m == procs[k]) {
                if (have_proc && l.proc != k)
                    return fail(why, "link '" + std::string(t) + "' has two process modifiers");
                l.proc = k;
                have_proc = known = true;
            }
        for (uint8_t k = 0; k < 4 && !known; ++k)
            if (m == mss[k]) {
                if (have_ms && l.ms != k)
                    return fail(why, "link '" + std::string(t) + "' has two alarm modifiers");
                l.ms = k;
                have_ms = known = true;
            }
        if (!known)
            return fail(why, "unknown link modifier '" + std::string(m) +
                                 "' (known: NPP PP CA CP CPP NMS MS MSS MSI)");
    }
    if ((l.proc == Link::kCp || l.proc == Link::kCpp) && type != Dbf::InLink)
        return fail(why, std::string(link_proc_name(l.proc)) + " is only for input links");
    l.kind = Link::Kind::Db;
    out = std::move(l);
    return true;
}

} // namespace beamctl::pv
