// Reader of vendor ESI XML (EtherCAT Slave Information, root <EtherCATInfo>): every
// Descriptions/Devices/Device as a DeviceDesc, checked so that it is also a valid catalog entry
// (docs/esi.md lists the rules). Used by Catalog::load_esi and by `beamctl esi import`.
// Configuration-time code; no shared state.
#pragma once

#include "core/error.hpp"
#include "ethercat/device.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::ethercat {

// One Mailbox/CoE/InitCmd: an SDO write the vendor's tools make at a state transition. beamctl
// does not apply these (startup SDOs come from the IOC file, `sdo:`); the import lists them.
struct EsiInitCmd {
    std::string transitions; // "PS", or several separated by spaces ("PS SO")
    uint16_t index = 0;
    uint8_t sub = 0;
    std::vector<uint8_t> data; // as sent (little-endian for numbers)
    bool complete_access = false;
    std::string comment;
};

struct EsiDevice {
    DeviceDesc desc;
    SourceLoc at; // its <Device> element
    std::vector<EsiInitCmd> init_cmds;
};

// The memory map name of an oversampled channel from its first sample's entry name, in
// ECMC's scheme <signal>Array<channel>: "analogOutput01_1" -> "analogOutputArray01"; a name
// that has "Array" already only loses its "_1" ("analogInputArray01_1" -> "analogInputArray01").
std::string esi_memmap_name(const std::string& first_sample);

// Every device of the EtherCATInfo file at `path`, in file order. Throws MultiError with every
// error found (at most one per <Device>), each "file:line:col: Element: what"; an unreadable
// file, malformed XML or another root element is one error.
std::vector<EsiDevice> read_esi(const std::string& path);
// The same for the text of a file named `path`.
std::vector<EsiDevice> read_esi_text(const std::string& path, const std::string& text);

} // namespace beamctl::ethercat
