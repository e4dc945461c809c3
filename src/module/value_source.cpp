#include "module/value_source.hpp"

#include "core/error.hpp"
#include "motion/axis_variables.hpp"

#include <cstdio>
#include <cstring>

namespace beamctl::module {

double ValueSource::read(uint64_t t_ns) const noexcept {
    switch (kind) {
    case Kind::None: return 0;
    case Kind::Time: return double(t_ns) * 1e-9;
    case Kind::Cell: return *cell;
    case Kind::Integer: return double(entry.get());
    case Kind::Uint64Bits: {
        const uint64_t raw = entry.get_raw();
        double d;
        std::memcpy(&d, &raw, sizeof d);
        return d;
    }
    case Kind::Float32: {
        uint32_t raw = uint32_t(entry.get_raw());
        float f;
        std::memcpy(&f, &raw, sizeof f);
        return f;
    }
    case Kind::Float64: {
        uint64_t raw = entry.get_raw();
        double d;
        std::memcpy(&d, &raw, sizeof d);
        return d;
    }
    case Kind::PcompOut: return pcomp->out() ? 1 : 0;
    case Kind::PcompActive: return pcomp->active() ? 1 : 0;
    case Kind::PcompProduced: return double(pcomp->produced());
    case Kind::PcompRose: return pcomp->rose() ? 1 : 0;
    }
    return 0;
}

ValueSource resolve_value(const registry::Registry& reg, motion::AxisGroup* axes, const std::string& name, std::string& why) {
    ValueSource v;
    if (name == "time") {
        v.kind = ValueSource::Kind::Time;
        return v;
    }
    int bit = -1;
    const registry::Signal* s = reg.find_with_bit(name, bit);
    if (!s) {
        why = SB() << "no signal '" << name << "' in this IOC (`beamctl signals` lists them; or time)";
        return v;
    }
    if (s->loop_only) {
        why = SB() << "'" << name << "' is a value of the IOC loop, not of the cycle";
        return v;
    }
    if (s->owner_kind == registry::OwnerKind::Axis) {
        int id = 0;
        char rest[128] = {};
        if (std::sscanf(name.c_str(), "ax%d.%127s", &id, rest) == 2 && axes) {
            if (const motion::AxisVariableInfo* info = motion::find_axis_variable(rest))
                for (std::size_t i = 0; i < axes->size(); ++i)
                    if (axes->axis(i).params().id == id) {
                        v.kind = ValueSource::Kind::Cell;
                        v.cell = motion::axis_variable(axes->axis(i).variables(), *info);
                        return v;
                    }
        }
        why = SB() << "'" << name << "' is an axis item the cycle does not hold as a variable (ax<n>.enc.actpos, ax<n>.traj.setpos, ...)";
        return v;
    }
    if (s->owner_kind == registry::OwnerKind::Bus) {
        v.entry = reg.bind(name, why);
        if (!v.entry.bound()) return v;
        const uint8_t real = bit < 0 ? registry::datatype_float_bits(s->type) : 0;
        v.kind = real == 32 ? ValueSource::Kind::Float32 : real == 64 ? ValueSource::Kind::Float64 : ValueSource::Kind::Integer;
        std::sscanf(name.c_str(), "ec%d.", &v.bus);
        return v;
    }
    if (s->owner_kind == registry::OwnerKind::Engine && s->type == "LREAL" && bit < 0) { // a value of an engine block (qe1.posy)
        std::string w;
        v.entry = reg.bind(name, w);
        if (v.entry.bound()) {
            v.kind = ValueSource::Kind::Float64;
            return v;
        }
    }
    why = SB() << "'" << name << "' is a signal of " << s->owner << "; the cycle reads bus entries, axis variables, pcomp<n>.*, quadem values and time";
    return v;
}


} // namespace beamctl::module
