// The routines of sub and aSub records (include/beamctl/record_routines.h, a C ABI): shared
// libraries loaded with `dlload` (or `beamctl softioc -P`) register named routines here; a record
// finds its INAM/SNAM by name when it is initialised (EPICS: registryFunctionFind).
// Threading: loading and lookups happen while databases are loaded (one thread); libraries stay
// loaded until the process ends, as EPICS's dlload.
#pragma once

#include "beamctl/record_routines.h"

#include <string>
#include <string_view>
#include <vector>

namespace beamctl::pv {

class RecordRoutines {
public:
    struct Routine {
        std::string name;
        beamctl_sub_routine sub = nullptr;
        beamctl_asub_routine asub = nullptr;
        std::string library; // the path it came from ("" when added by code)
    };
    static RecordRoutines& global();

    // Loads a library and registers its routines. Throws Error naming the path and what is wrong
    // (cannot be opened, exports no beamctl_record_routines_get, another ABI version, a malformed
    // entry, a name another library already registered); a library that fails adds nothing. Loading
    // the same path twice does nothing.
    void load(const std::string& path);
    // Registers a routine directly (built-in or test routines).
    void add(Routine r);
    const Routine* find(std::string_view name) const;
    // For errors: "lib.so (r1, r2); other.so (r3)" or "none loaded".
    std::string describe() const;

private:
    std::vector<Routine> routines_;
    std::vector<std::string> libraries_;
};

// Registers the routines beamctl provides itself (devIocStats's asSubInit, asSubProcess and
// rebootProc: pv/ioc_stats.cpp); RecordRoutines::global() calls it when it is made.
void add_builtin_routines(RecordRoutines& routines);

// The error message for a routine name no library provides (INAM/SNAM of record `record`).
std::string missing_routine_message(std::string_view field, std::string_view routine, std::string_view kind);

} // namespace beamctl::pv
