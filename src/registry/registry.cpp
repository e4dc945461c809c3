#include "registry/registry.hpp"

#include "core/error.hpp"
#include "core/glob.hpp"

#include <algorithm>
#include <iomanip>

namespace beamctl::registry {

const char* direction_name(Direction d) {
    switch (d) {
    case Direction::Input: return "input";
    case Direction::Output: return "output";
    case Direction::Variable: return "variable";
    }
    return "?";
}

const char* owner_kind_name(OwnerKind k) {
    switch (k) {
    case OwnerKind::Bus: return "bus";
    case OwnerKind::Axis: return "axis";
    case OwnerKind::Plc: return "plc";
    case OwnerKind::Bridge: return "bridge";
    case OwnerKind::Record: return "record";
    case OwnerKind::Engine: return "engine";
    }
    return "?";
}

const Signal& Registry::declare(Signal s) {
    if (frozen_) throw Error(SB() << "signal '" << s.name << "' declared by " << s.owner << " after the registry was frozen");
    return insert(std::move(s));
}

const Signal& Registry::declare_runtime(Signal s) {
    if (!s.loop_only)
        throw Error(SB() << "signal '" << s.name << "' of " << s.owner << ": only a signal of the IOC loop may be declared while the IOC runs");
    s.runtime = true;
    return insert(std::move(s));
}

const Signal& Registry::insert(Signal s) {
    if (s.name.empty()) throw Error(SB() << s.owner << " declared a signal without a name");
    auto [it, fresh] = signals_.try_emplace(s.name, s);
    if (!fresh) throw Error(SB() << "signal '" << s.name << "' of " << s.owner << " is already declared by " << it->second.owner);
    return it->second;
}

void Registry::withdraw(std::string_view name) {
    auto it = signals_.find(name);
    if (it != signals_.end() && it->second.runtime) signals_.erase(it);
}

void Registry::set_binder(std::string prefix, Binder b) { binders_.emplace_back(std::move(prefix), std::move(b)); }

const Signal* Registry::find(std::string_view name) const {
    auto it = signals_.find(name);
    return it == signals_.end() ? nullptr : &it->second;
}

Signal* Registry::find_mut(std::string_view name) {
    auto it = signals_.find(name);
    return it == signals_.end() ? nullptr : &it->second;
}

const Signal* Registry::find_with_bit(std::string_view name, int& bit) const {
    bit = -1;
    if (const Signal* s = find(name)) return s;
    std::size_t dot = name.rfind('.');
    if (dot == std::string_view::npos || dot + 1 == name.size() || name.size() - dot > 3) return nullptr;
    std::string_view digits = name.substr(dot + 1);
    if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) return nullptr;
    const Signal* s = find(name.substr(0, dot));
    if (s) bit = std::stoi(std::string(digits));
    return s;
}

BoundSignal Registry::bind(std::string_view name, std::string& why) const {
    int bit = -1;
    const Signal* s = find_with_bit(name, bit);
    if (!s) {
        why = SB() << "no signal '" << name << "'";
        return {};
    }
    for (const auto& [prefix, b] : binders_) {
        if (s->name.rfind(prefix, 0) != 0) continue;
        BoundSignal bs = b(*s, bit, why);
        if (bs.bound() && bit >= int(bs.bits)) {
            why = SB() << "'" << s->name << "' has " << int(bs.bits) << " bits, no bit " << bit;
            return {};
        }
        return bs;
    }
    why = SB() << "'" << s->name << "' (" << s->owner << ") has no place in a process image";
    return {};
}

bool Registry::claim(std::string_view name, const std::string& writer, std::string& why) {
    Signal* s = find_mut(name);
    if (!s) {
        why = SB() << "no signal '" << name << "'";
        return false;
    }
    if (s->direction != Direction::Output) {
        why = SB() << "'" << name << "' is an " << direction_name(s->direction) << " of " << s->owner << "; only outputs are written";
        return false;
    }
    if (!s->writer.empty() && s->writer != writer) {
        why = SB() << "'" << name << "' is already written by " << s->writer << " (one writer per output)";
        return false;
    }
    s->writer = writer;
    return true;
}

void Registry::release(std::string_view name, const std::string& writer) {
    if (Signal* s = find_mut(name); s && s->writer == writer) s->writer.clear();
}

void Registry::set_pv(std::string_view name, std::string pv) {
    if (Signal* s = find_mut(name)) s->pv = std::move(pv);
}

std::vector<const Signal*> Registry::match(std::string_view pattern) const {
    std::vector<const Signal*> v;
    for (const auto& [name, s] : signals_)
        if (pattern.empty() || beamctl::glob_match(pattern, name)) v.push_back(&s);
    return v;
}

void Registry::print(std::ostream& os, std::string_view pattern) const {
    std::vector<const Signal*> v = match(pattern);
    std::size_t wn = 4, wt = 4, wo = 5, ww = 6;
    for (const Signal* s : v) {
        wn = std::max(wn, s->name.size());
        wt = std::max(wt, s->type.size());
        wo = std::max(wo, s->owner.size());
        ww = std::max(ww, s->writer.size());
    }
    auto row = [&](std::string_view n, std::string_view t, std::string_view d, std::string_view o, std::string_view w,
                   std::string_view pv) {
        os << std::left << std::setw(int(wn)) << n << "  " << std::setw(int(wt)) << t << "  " << std::setw(8) << d << "  "
           << std::setw(int(wo)) << o << "  " << std::setw(int(ww)) << w << "  " << pv;
        os << "\n";
    };
    row("NAME", "TYPE", "DIR", "OWNER", "WRITER", "PV");
    for (const Signal* s : v) {
        std::string writer = s->writer;
        if (writer.empty() && s->direction == Direction::Output) writer = s->pv.empty() ? "-" : "CA (its PV)";
        if (writer.empty()) writer = "-";
        row(s->name, s->type, direction_name(s->direction), s->owner, writer, s->pv.empty() ? "-" : s->pv);
    }
}

} // namespace beamctl::registry
