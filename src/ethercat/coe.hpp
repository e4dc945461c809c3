// Mailbox and CoE SDO wire format (ethercat.md §3), shared by the master's SDO client and the
// simulator's SDO server. A mailbox is a 6-byte header `length u16 | address u16 | channel u8 |
// type (bits 0-3) + counter (bits 4-6) u8` and `length` bytes of data; CoE data starts with a
// u16 header (service in bits 12-15), then the SDO part `command u8 | index u16 | sub u8 | 4 data
// bytes`, all little-endian. Pure constants and functions: safe from any thread.
#pragma once

#include <cstddef>
#include <cstdint>

namespace beamctl::ethercat::coe {

constexpr std::size_t kMailboxHeader = 6;
constexpr std::size_t kCoeHeader = 2;
constexpr std::size_t kSdoHeader = 8; // command, index, sub, 4 data bytes (expedited data or size)

// Mailbox types (header byte 5, bits 0-3).
constexpr uint8_t kMbxError = 0x00, kMbxEoE = 0x02, kMbxCoE = 0x03, kMbxFoE = 0x04, kMbxSoE = 0x05;
// Detail codes of a mailbox error reply (type 0: u16 service 0x0001, u16 detail).
constexpr uint16_t kMbxErrSyntax = 0x0001, kMbxErrUnsupportedProtocol = 0x0002,
                   kMbxErrServiceNotSupported = 0x0004, kMbxErrInvalidHeader = 0x0005,
                   kMbxErrSizeTooShort = 0x0006, kMbxErrInvalidSize = 0x0008;

// CoE services (CoE header bits 12-15).
constexpr uint8_t kCoeEmergency = 1, kCoeSdoRequest = 2, kCoeSdoResponse = 3, kCoeSdoInfo = 8;

// SDO command bytes.
constexpr uint8_t kSdoUploadRequest = 0x40;     // initiate upload request
constexpr uint8_t kSdoUploadNormal = 0x41;      // response: size indicated, data follow
constexpr uint8_t kSdoUploadExpedited = 0x43;   // | (4 - n) << 2 for n data bytes
constexpr uint8_t kSdoDownloadNormal = 0x21;    // request: size u32, data follow
constexpr uint8_t kSdoDownloadExpedited = 0x23; // | (4 - n) << 2 for n data bytes
constexpr uint8_t kSdoDownloadResponse = 0x60;
constexpr uint8_t kSdoAbort = 0x80;
constexpr uint8_t kSdoCompleteAccess = 0x10;

// SDO abort codes (ETG.1000.6 table 41).
constexpr uint32_t kAbortToggle = 0x05030000, kAbortTimeout = 0x05040000,
                   kAbortCommand = 0x05040001, kAbortOutOfMemory = 0x05040005,
                   kAbortUnsupportedAccess = 0x06010000, kAbortWriteOnly = 0x06010001,
                   kAbortReadOnly = 0x06010002, kAbortSubindex0NotZero = 0x06010003,
                   kAbortTooLongForMailbox = 0x06010005, kAbortNoObject = 0x06020000,
                   kAbortLength = 0x06070010, kAbortLengthHigh = 0x06070012,
                   kAbortLengthLow = 0x06070013, kAbortNoSubindex = 0x06090011,
                   kAbortValueRange = 0x06090030, kAbortGeneral = 0x08000000,
                   kAbortDeviceState = 0x08000022;

// "object does not exist" for 0x06020000; "unknown abort code" for codes not in the table.
const char* abort_text(uint32_t code);
// "unsupported protocol" for 0x0002; "unknown mailbox error" otherwise.
const char* mailbox_error_text(uint16_t detail);

// Object indices of the communication area.
constexpr uint16_t kObjDeviceType = 0x1000, kObjDeviceName = 0x1008, kObjIdentity = 0x1018,
                   kObjSmTypes = 0x1C00, kObjSmAssignBase = 0x1C10; // 0x1C10 + n: SM n's PDOs

} // namespace beamctl::ethercat::coe
