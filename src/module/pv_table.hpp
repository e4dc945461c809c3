// Declarative PV tables (ARCHITECTURE.md §3): a subsystem describes its PVs once, as rows of
// suffix, record type, signal and fields, and the IOC makes the records of each instance (an
// axis, a PLC) from the table. A row with a signal becomes a record with device support
// "beamctl", exactly what a user writes in a .db file:
//   input types  DTYP "beamctl", INP "@<signal>", SCAN "I/O Intr": processed when the signal
//                changes (the owner's snapshot, looked at by Database::scan_io_intr)
//   output types DTYP "beamctl", OUT "@<signal>": a put writes the signal; the write is the
//                command (ax1.control.0 enables the axis). A `readback` row also follows the
//                signal when its owner changes it: info(asyn:READBACK, "1"), as asyn's records.
// A row without a signal is a soft record: a value other records read (or its owner sets, such
// as the text of MsgTxt). Field values may name the instance's macros: $(PREC), $(EGU), ...
// Threading: configure time (IOC construction), no RT involvement.
#pragma once

#include "core/macros.hpp"
#include "pv/db_file.hpp"
#include "registry/registry.hpp"

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::module {

struct PvRow {
    const char* suffix; // after the instance's PV prefix: "-PosAct"
    const char* type;   // record type: "ai"
    const char* signal; // after the instance's signal prefix: "actpos", "status.1" (a bit); "": none
                        // (may name the instance's macros: "$(BUS)ok")
    std::vector<std::pair<const char*, const char*>> fields; // DESC, EGU, ... ($(NAME) of the instance)
    bool readback = false; // an output that follows its signal when the owner changes it:
                           // info(asyn:READBACK, "1"), as asyn's output records
};

struct PvTable {
    const char* name; // "axis": where generated records say they come from
    std::vector<PvRow> rows;
};

struct PvInstance {
    std::string pv_prefix;     // "BL:SampleX"
    std::string signal_prefix; // "ax1."
    MacroMap macros;           // PREC=3, EGU=mm, ...
};

// True for the record types whose device link is OUT (ao, bo, longout, mbbo, ...).
bool is_output_type(std::string_view type);

// The records of one instance, in row order. A row with a signal the registry does not know is
// a programming error (Error naming the table, row and signal).
pv::DbFile make_records(const PvTable& t, const PvInstance& in, const registry::Registry& signals);

// Names each row's PV as the PV of its signal (whole signals only, not bits) in the registry,
// for `beamctl signals` and the clients that look signals up by PV.
void name_pvs(const PvTable& t, const PvInstance& in, registry::Registry& signals);

// The table as .db text with $(P) for the PV prefix and $(S) for the signal prefix: what the
// IOC serves, in the form a user would write it (docs, `beamctl pvs`-style listings, tests).
std::string to_db_text(const PvTable& t);

} // namespace beamctl::module
