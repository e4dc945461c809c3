// The record types a database serves, printed as an EPICS .dbd (`beamctl db --dbd`): every
// field with its DBF type, menu, access (SPC_NOMOD, "init only") and initial value, so tools
// and users can compare beamctl's record types with EPICS base's.
#pragma once

#include "pv/record.hpp"

#include <iosfwd>

namespace beamctl::pv {

// Writes recordtype(NAME) { field(...) } blocks for every type of `types`, sorted by name.
void write_dbd(std::ostream& os, const RecordTypes& types);

} // namespace beamctl::pv
