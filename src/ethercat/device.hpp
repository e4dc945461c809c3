// Description of an EtherCAT slave device type: identity, sync managers, PDOs and their entries
// (with ecmccfg entry names). Filled from our catalog files (catalog/*.yaml) or from vendor ESI
// XML; turned into an SII EEPROM image for the simulator and read back from SII by the master.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::ethercat {

// One entry of a PDO. index 0 is padding.
struct PdoEntry {
    uint16_t index = 0;
    uint8_t sub = 0;
    uint8_t bits = 0;
    std::string name;     // ecmccfg name, e.g. "binaryInput01", "positionActual01" ("" for padding)
    std::string datatype; // "BOOL", "UINT16", "INT32", ... (ESI DataType)
    bool operator==(const PdoEntry&) const = default;
};

struct Pdo {
    uint16_t index = 0; // 0x1600.. (RxPDO, outputs) or 0x1A00.. (TxPDO, inputs)
    std::string name;
    std::vector<PdoEntry> entries;
    uint32_t bit_size() const;
    bool operator==(const Pdo&) const = default;
};

enum class SmType : uint8_t { Unused = 0, MailboxOut = 1, MailboxIn = 2, Outputs = 3, Inputs = 4 };
// The name of an SM type in catalog files and ESI: "MBoxOut", "MBoxIn", "Outputs", "Inputs", "Unused".
const char* sm_type_name(SmType t);
// The type of such a name; nullopt for another word.
std::optional<SmType> sm_type_from_name(std::string_view s);

struct SyncManagerDesc {
    uint8_t index = 0;
    uint16_t start = 0;        // physical start address in the ESC
    uint16_t default_size = 0; // bytes (mailboxes); process-data SMs are sized from their PDOs
    uint8_t control = 0;       // register 0x0804 value
    bool enable = true;
    SmType type = SmType::Unused;
    bool is_virtual = false;   // ESI Sm@Virtual: points at ESC registers (DC), not a buffer
    bool operator==(const SyncManagerDesc&) const = default;
};

struct DeviceDesc {
    std::string type;         // "EL1008"
    std::string variant_of;   // an operating-mode variant of this type ("EL7211-0010_CSP" of
                              // "EL7211"): same identity, other PDOs; "" for a base description
    std::string name;         // "EL1008 8Ch. Dig. Input 24V, 3ms"
    uint32_t vendor = 0;      // 0x00000002 = Beckhoff
    uint32_t product = 0;
    uint32_t revision = 0;
    std::vector<SyncManagerDesc> sms;
    std::vector<Pdo> rx_pdos; // outputs (master -> slave), assigned to an Outputs SM
    std::vector<Pdo> tx_pdos; // inputs (slave -> master), assigned to an Inputs SM
    // Default assignment: for each SM index, the PDO indices assigned to it (ESI Pdo@Sm).
    std::vector<std::pair<uint8_t, uint16_t>> pdo_assign; // {sm index, pdo index}
    bool coe = false;                 // CoE mailbox protocol supported
    uint16_t dc_assign_activate = 0;  // ESI Dc/OpMode/AssignActivate (0: no DC)
    uint16_t ebus_current_ma = 0;
    // Oversampling (ESI Pdo@OSFac; ecmccfg NELM): each listed sample PDO is repeated n times per
    // cycle, n = 1..max. Sample k (1-based) of a channel is PDO pdo+k-1 with entry index
    // entry+0x10*(k-1) (Beckhoff's numbering), named <channel>_<k>; the samples follow each other
    // in their SM. The description as loaded is factor 1 (one sample PDO per channel).
    struct Oversampling {
        struct Channel {
            uint16_t pdo = 0;       // its first sample PDO
            std::string memmap;     // ECMC's memory map name, "analogInputArray01"
            bool operator==(const Channel&) const = default;
        };
        uint16_t max = 0;           // 0: the device does not oversample
        std::vector<Channel> channels;
        bool operator==(const Oversampling&) const = default;
    } oversampling;

    // A run of equal entries read or written as one array: ECMC's memory map
    // (`ec<m>.s<k>.mm.<name>`), here one per oversampled channel.
    struct MemMap {
        std::string name;       // "analogInputArray01"
        std::string first;      // its first entry, "analogInputArray01_1"
        uint16_t count = 0;     // elements (the oversampling factor)
        uint8_t bits = 0;       // per element
        std::string datatype;   // CoE type of an element ("INT16")
        bool output = false;
    };

    const Pdo* find_pdo(uint16_t index) const;
    // Bytes of process data of the SM with the given index under the default assignment.
    uint32_t sm_bytes(uint8_t sm_index) const;
    // This description with oversampling factor n (1..oversampling.max): the sample PDOs 2..n of
    // every channel added after the first and assigned to its SM. Throws Error for a bad n.
    DeviceDesc with_oversampling(unsigned n) const;
    // The memory maps of this description (one per oversampled channel; none for other devices).
    std::vector<MemMap> memmaps() const;
    // The factor of this description: samples per channel (1 for a device that does not oversample).
    unsigned oversampling_factor() const;
    // Every field equal (what a catalog file and the ESI it was imported from must agree on).
    bool operator==(const DeviceDesc&) const = default;
};

} // namespace beamctl::ethercat
