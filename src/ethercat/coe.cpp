#include "ethercat/coe.hpp"

namespace beamctl::ethercat::coe {

// clang-format off
const char* abort_text(uint32_t code) {
    switch (code) {
    case 0x05030000: return "toggle bit not changed";
    case 0x05040000: return "SDO protocol timeout";
    case 0x05040001: return "client/server command specifier not valid or unknown";
    case 0x05040005: return "out of memory";
    case 0x06010000: return "unsupported access to an object";
    case 0x06010001: return "attempt to read a write-only object";
    case 0x06010002: return "attempt to write a read-only object";
    case 0x06010003: return "subindex cannot be written, subindex 0 must be 0 for write access";
    case 0x06010004: return "complete access not supported for objects of variable length";
    case 0x06010005: return "object length exceeds mailbox size";
    case 0x06010006: return "object mapped to RxPDO, SDO download blocked";
    case 0x06020000: return "object does not exist";
    case 0x06040041: return "object cannot be mapped to the PDO";
    case 0x06040042: return "the mapped objects would exceed the PDO length";
    case 0x06040043: return "general parameter incompatibility";
    case 0x06040047: return "general internal incompatibility in the device";
    case 0x06060000: return "access failed due to a hardware error";
    case 0x06070010: return "data type does not match, length of service parameter does not match";
    case 0x06070012: return "data type does not match, length of service parameter too high";
    case 0x06070013: return "data type does not match, length of service parameter too low";
    case 0x06090011: return "subindex does not exist";
    case 0x06090030: return "value range of parameter exceeded";
    case 0x06090031: return "value of parameter written too high";
    case 0x06090032: return "value of parameter written too low";
    case 0x06090036: return "maximum value is less than minimum value";
    case 0x08000000: return "general error";
    case 0x08000020: return "data cannot be transferred or stored to the application";
    case 0x08000021: return "data cannot be transferred or stored because of local control";
    case 0x08000022: return "data cannot be transferred or stored in the present device state";
    case 0x08000023: return "no object dictionary present";
    default: return "unknown abort code";
    }
}

const char* mailbox_error_text(uint16_t detail) {
    switch (detail) {
    case 0x0001: return "syntax error in the mailbox header";
    case 0x0002: return "unsupported protocol";
    case 0x0003: return "invalid channel";
    case 0x0004: return "service not supported";
    case 0x0005: return "invalid mailbox header";
    case 0x0006: return "mailbox data too short";
    case 0x0007: return "no more memory in the slave";
    case 0x0008: return "inconsistent mailbox data size";
    default: return "unknown mailbox error";
    }
}

// clang-format on

} // namespace beamctl::ethercat::coe
