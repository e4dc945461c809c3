// An engine value read as a double in the cycle, by name: what position compare, capture and fast
// feedback take as their input. Names are the registry's (`beamctl signals`): a bus entry (integer,
// REAL or LREAL; a bit of it), an axis variable (ax1.enc.actpos), or "time" (the engine clock [s]).
// Position compare's own outputs (pcomp<n>.out, ...) are resolved by IocFlyScan, which owns them.
// Threading: resolved while the IOC is bound; read on the RT thread (no allocation).
#pragma once

#include "daq/pcomp.hpp"
#include "motion/axis_group.hpp"
#include "registry/registry.hpp"

#include <cstdint>
#include <string>

namespace beamctl::module {

// An engine value read as a double in the cycle: an axis variable, a process-data entry (integer
// or REAL/LREAL), the engine clock [s], or a position-compare block's output.
struct ValueSource {
    // Uint64Bits: a UINT64 entry (a DC time stamp, ns) carried exactly as its bit pattern in the
    // double (capture "value" columns only; the file gets a uint64 dataset).
    enum class Kind : uint8_t { None, Time, Cell, Integer, Uint64Bits, Float32, Float64, PcompOut, PcompActive, PcompProduced, PcompRose } kind = Kind::None;
    const double* cell = nullptr;
    registry::BoundSignal entry;
    const daq::Pcomp* pcomp = nullptr;
    int bus = -1; // a bus entry's bus id (ec<bus>.), else -1
    double read(uint64_t t_ns) const noexcept;
};

// Resolves `name` (bus entry, axis variable, time); kind None with `why` when it cannot.
ValueSource resolve_value(const registry::Registry& reg, motion::AxisGroup* axes, const std::string& name, std::string& why);

} // namespace beamctl::module
