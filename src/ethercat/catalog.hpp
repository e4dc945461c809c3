// Catalog of EtherCAT device descriptions: our own catalog/*.yaml files (with ecmccfg entry
// names) and vendor ESI XML files. Threading: load_* must not run concurrently with anything
// else on the same Catalog; once loaded, the const functions are safe from any thread and the
// returned pointers stay valid for the Catalog's lifetime (a later load of the same identity
// updates the description in place).
//
// YAML format (one device per file; unknown keys are errors; numbers decimal or 0x-hex):
//   type: EL1008                         # order name, required
//   name: "EL1008 8Ch. Dig. Input 24V, 3ms"
//   vendor: 0x00000002                   # required, as are product and revision
//   product: 0x03f03052
//   revision: 0x00120000
//   coe: false                           # CoE over the mailbox (needs MBoxOut/MBoxIn SMs)
//   dc_assign_activate: 0x0000           # ESI Dc/OpMode/AssignActivate, 0 = no DC
//   ebus_current_ma: 90                  # optional
//   sync_managers:                       # listed in SM order, index must match the position
//     - {index: 0, start: 0x1000, control: 0x00, type: Inputs}   # MBoxOut|MBoxIn|Outputs|Inputs
//   tx_pdos:                             # inputs, 0x1A00-0x1BFF; rx_pdos: outputs, 0x1600-0x17FF
//     - index: 0x1a00
//       name: Channel 1
//       sm: 0                            # default assignment; omit for an unassigned PDO
//       entries:
//         - {index: 0x6000, sub: 1, bits: 1, name: binaryInput01, datatype: BOOL}
//         - {index: 0, bits: 7}          # padding
// SM keys: size (bytes; required for mailboxes; for non-virtual process-data SMs computed from
// the assigned PDOs and checked if given; virtual SMs keep the given size, default 0), enable
// (default true), virtual (default false: ESI Sm@Virtual, an SM pointing at ESC registers such
// as the DC latch or SYNC registers). Entry datatype is a CoE type name (BOOL, BIT2..BIT8,
// INT8..INT64, UINT8..UINT64, REAL32, REAL64) whose width must equal bits; padding entries
// (index 0) have only bits. Entry names must be unique within a device.
// Oversampling terminals (EL3702, EL4732) add
//   oversampling: {max: 100, channels: [{pdo: 0x1a00, memmap: analogInputArray01}, ...]}
// where each channel's first sample PDO (one entry named <channel>_1) is repeated n times for
// factor n (DeviceDesc::with_oversampling), and the memmap names ECMC's memory map of the samples.
#pragma once

#include "ethercat/device.hpp"

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ethercat {

class Catalog {
public:
    Catalog();
    ~Catalog();
    Catalog(Catalog&&) noexcept;
    Catalog& operator=(Catalog&&) noexcept;

    // Loads every *.yaml / *.yml file (sorted by name), then every *.xml file as ESI; a bad file
    // does not stop the others: one MultiError at the end lists every error of every file.
    void load_dir(const std::string& dir);
    // One device per file, read with config::YamlReader: one MultiError lists every error of the
    // file (file:line:col, the key and what is wrong), and a bad file changes nothing. Defining
    // an identity (vendor, product, revision) that another YAML file already defined is an error.
    void load_yaml(const std::string& path);
    // EtherCATInfo XML (ethercat/esi.hpp); every Descriptions/Devices/Device; a bad file changes
    // nothing. An ESI device replaces an earlier device of the same identity. Entry names are
    // the ESI entry name where that is an identifier used once in the device, else
    // "<PdoName>_<EntryName>" of their letters, digits and '_'; then ecmc_names().
    void load_esi(const std::string& path);
    // Gives d's entries the ecmc names that this catalog's YAML devices of the same vendor and
    // product use for the same index:sub (the same revision first, then the highest), each name
    // to one entry (default-assigned PDOs first); an oversampled channel's memory map follows
    // its first sample's name (<memmap>_1).
    void ecmc_names(DeviceDesc& d) const;
    // "unknown device type 'X'; close matches in the catalog: ...; to add a device, import its
    // vendor's ESI file: beamctl esi import VENDOR.xml --out DIR ...": the one message for a
    // type this catalog lacks (IOC check and run, master, simulator).
    std::string unknown_type_error(std::string_view type) const;

    // By type name ("EL7041"); the highest revision if several are loaded. nullptr if none.
    const DeviceDesc* find(std::string_view type) const;
    // Exact identity. nullptr if none.
    const DeviceDesc* find(uint32_t vendor, uint32_t product, uint32_t revision) const;
    // Highest revision of a product. nullptr if none.
    const DeviceDesc* find_latest(uint32_t vendor, uint32_t product) const;
    // Sorted, unique type names.
    std::vector<std::string> types() const;
    // The file a device was loaded from ("" if `d` is not from this catalog).
    std::string source(const DeviceDesc* d) const;
    size_t size() const;

    // The catalog/ directory of this installation or source tree, loaded once (thread-safe).
    static const Catalog& builtin();
    // Where builtin() loads from: env BEAMCTL_CATALOG, then <exe dir>/../../catalog,
    // <exe dir>/../catalog, <exe dir>/catalog, then BEAMCTL_SOURCE_CATALOG_DIR (compile time).
    // Throws Error listing the places tried if none is a directory.
    static std::string builtin_dir();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace beamctl::ethercat
