// Description of an EtherCAT slave device type: identity, sync managers, PDOs and their entries
// (with ecmccfg entry names). Filled from our catalog files (catalog/*.yaml) or from vendor ESI
// XML; turned into an SII EEPROM image for the simulator and read back from SII by the master.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::ethercat {

// One entry of a PDO. index 0 is padding.
struct PdoEntry {
    uint16_t index = 0;
    uint8_t sub = 0;
    uint8_t bits = 0;
    std::string name;     // ecmccfg name, e.g. "binaryInput01", "positionActual01" ("" for padding)
    std::string datatype; // "BOOL", "UINT16", "INT32", ... (ESI DataType)
};

struct Pdo {
    uint16_t index = 0; // 0x1600.. (RxPDO, outputs) or 0x1A00.. (TxPDO, inputs)
    std::string name;
    std::vector<PdoEntry> entries;
    uint32_t bit_size() const;
};

enum class SmType : uint8_t { Unused = 0, MailboxOut = 1, MailboxIn = 2, Outputs = 3, Inputs = 4 };

struct SyncManagerDesc {
    uint8_t index = 0;
    uint16_t start = 0;        // physical start address in the ESC
    uint16_t default_size = 0; // bytes (mailboxes); process-data SMs are sized from their PDOs
    uint8_t control = 0;       // register 0x0804 value
    bool enable = true;
    SmType type = SmType::Unused;
    bool is_virtual = false;   // ESI Sm@Virtual: points at ESC registers (DC), not a buffer
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

    const Pdo* find_pdo(uint16_t index) const;
    // Bytes of process data of the SM with the given index under the default assignment.
    uint32_t sm_bytes(uint8_t sm_index) const;
};

} // namespace beamctl::ethercat
