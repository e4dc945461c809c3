// SII (Slave Information Interface) EEPROM images, ETG.2010 layout: build_sii() turns a DeviceDesc
// into the word image the simulated ESC serves at registers 0x0500-0x050F; parse_sii() reads an
// image back the way a master does during bus scan (identity, mailbox, SMs, FMMUs, PDOs, names).
// Both are pure functions of their arguments: safe to call from any thread, never from the RT path.
#pragma once

#include "ethercat/device.hpp"

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace beamctl::ethercat {

// Word addresses of the fixed SII header (ETG.2010 table 2).
inline constexpr uint16_t kSiiAliasWord = 0x0004;
inline constexpr uint16_t kSiiChecksumWord = 0x0007;
inline constexpr uint16_t kSiiVendorWord = 0x0008;    // u32, words 0x08-0x09
inline constexpr uint16_t kSiiProductWord = 0x000A;   // u32
inline constexpr uint16_t kSiiRevisionWord = 0x000C;  // u32
inline constexpr uint16_t kSiiSerialWord = 0x000E;    // u32
inline constexpr uint16_t kSiiBootRxMbxWord = 0x0014; // offset, size, then tx offset, size
inline constexpr uint16_t kSiiRxMbxOffsetWord = 0x0018;
inline constexpr uint16_t kSiiRxMbxSizeWord = 0x0019;
inline constexpr uint16_t kSiiTxMbxOffsetWord = 0x001A;
inline constexpr uint16_t kSiiTxMbxSizeWord = 0x001B;
inline constexpr uint16_t kSiiProtocolsWord = 0x001C;
inline constexpr uint16_t kSiiSizeWord = 0x003E; // EEPROM size in KBit - 1
inline constexpr uint16_t kSiiVersionWord = 0x003F;
inline constexpr uint16_t kSiiFirstCategoryWord = 0x0040;

inline constexpr uint16_t kSiiProtocolCoE = 0x0004; // word 0x1C bit 2
inline constexpr uint16_t kSiiProtocolFoE = 0x0008; // word 0x1C bit 3

// Category types.
inline constexpr uint16_t kSiiCatStrings = 10;
inline constexpr uint16_t kSiiCatGeneral = 30;
inline constexpr uint16_t kSiiCatFmmu = 40;
inline constexpr uint16_t kSiiCatSyncM = 41;
inline constexpr uint16_t kSiiCatTxPdo = 50;
inline constexpr uint16_t kSiiCatRxPdo = 51;
inline constexpr uint16_t kSiiCatDc = 60;
inline constexpr uint16_t kSiiCatEnd = 0xFFFF;

// FMMU usage codes in the FMMU category.
inline constexpr uint8_t kSiiFmmuOutputs = 1;
inline constexpr uint8_t kSiiFmmuInputs = 2;
inline constexpr uint8_t kSiiFmmuMbxState = 3;

// SyncM category "enable" byte bits.
inline constexpr uint8_t kSiiSmEnable = 0x01;
inline constexpr uint8_t kSiiSmVirtual = 0x04;

// What a master learns from an SII image.
struct SiiInfo {
    uint32_t vendor = 0, product = 0, revision = 0, serial = 0;
    uint16_t alias = 0;                          // word 4
    uint16_t rx_mbx_offset = 0, rx_mbx_size = 0; // master -> slave mailbox (SM0), bytes
    uint16_t tx_mbx_offset = 0, tx_mbx_size = 0; // slave -> master mailbox (SM1), bytes
    uint16_t protocols = 0;                      // word 0x1C (kSiiProtocolCoE, ...)
    std::vector<std::string> strings;            // strings category; SII index i is strings[i-1]
    std::string type;                            // general OrderIdx, e.g. "EL1008"
    std::string name;                            // general NameIdx
    uint8_t coe_details = 0;                     // general byte 5
    int16_t ebus_current_ma = 0;                 // general bytes 12-13 (negative: supply)
    std::vector<uint8_t> fmmus;                  // FMMU usage codes, trailing unused dropped
    std::vector<SyncManagerDesc> sms;
    std::vector<Pdo> rx_pdos, tx_pdos;
    std::vector<std::pair<uint8_t, uint16_t>> pdo_assign; // {sm, pdo}: rx PDOs first, then tx
    uint16_t dc_assign_activate = 0;                      // first DC opmode; 0 if no DC category
};

// Complete SII image for `d` (config area with CRC, identity, mailbox, categories, 0xFFFF
// padding up to the declared EEPROM size). Throws Error if `d` cannot be expressed in SII
// (more than 255 strings, a string longer than 255 bytes, more than 255 entries in a PDO).
std::vector<uint16_t> build_sii(const DeviceDesc& d, uint32_t serial = 0);

// Reads an image as a master does. Throws Error naming the word offset on a malformed image
// (too short, bad config-area checksum, category running past the end, missing end marker,
// string index out of range, PDO assigned to a missing SM, ...).
SiiInfo parse_sii(const std::vector<uint16_t>& words);

// ETG.2010 CRC-8 (polynomial 0x07, initial value 0xFF) over the 14 bytes of words 0-6.
uint8_t sii_crc8(const uint16_t* config_words);

// CoE basic data types (ETG.1020), as used in SII PDO entries and in catalog files.
// Code of a data type name ("UINT16" -> 0x06, "BOOL" -> 0x01, "BIT2" -> 0x31); 0 if unknown.
uint8_t coe_datatype_code(std::string_view name);
// Name of a code ("" if unknown).
std::string_view coe_datatype_name(uint8_t code);
// Width in bits of a data type name; 0 if unknown.
unsigned coe_datatype_bits(std::string_view name);

} // namespace beamctl::ethercat
