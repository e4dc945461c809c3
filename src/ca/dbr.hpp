// DBR types 0..38 of Channel Access: sizes, value offsets (ca-protocol.md §5), encoding of a
// field's value and metadata into a big-endian payload, and decoding of put payloads.
#pragma once

#include "pv/database.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace beamctl::ca {

enum class DbrKind : uint8_t { Plain, Sts, Time, Gr, Ctrl, PutAck, StsAck, ClassName };

struct DbrInfo {
    pv::Prim prim;
    DbrKind kind;
    uint16_t size;         // dbr_size[t]: bytes for one element including metadata
    uint16_t value_offset; // dbr_value_offset[t]
};

constexpr uint16_t kDbrPutAckt = 35, kDbrPutAcks = 36, kDbrStsackString = 37, kDbrClassName = 38;
constexpr uint16_t kLastDbr = 38;

bool dbr_valid(uint16_t t);
const DbrInfo& dbr_info(uint16_t t);
// Payload bytes of `count` elements of type t (unpadded): dbr_size + (count-1) * element size.
std::size_t dbr_payload_size(uint16_t t, uint32_t count);

// Encodes `count` elements (and the metadata type t carries) of channel `a` into out, which must
// hold dbr_payload_size(t, count) bytes. Elements past the field's current count are zero.
// Returns the number of valid elements the field has now (for dynamic-size replies).
uint32_t encode_dbr(const pv::Database& db, const pv::Address& a, uint16_t t, uint32_t count,
                    uint8_t* out);

// Decodes a put payload of `count` elements of plain type t (0..6) into host-order elements in
// `host` (strings are char[40] each). Returns false if the payload is too short.
bool decode_put(uint16_t t, const uint8_t* payload, std::size_t len, uint32_t count,
                std::vector<char>& host);

// Converts n host-order elements of type prim at p to big-endian in place (a put's payload).
void host_to_wire(pv::Prim prim, uint8_t* p, uint32_t n);

// A DBR payload as a client receives it: the elements in host order and the metadata its type
// carries (alarm and time for STS/TIME; units, precision, limits, enum strings for GR/CTRL).
struct DbrValue {
    pv::Prim prim = pv::Prim::Double;
    uint32_t count = 0;
    std::vector<char> data; // count elements in host order; a string is char[40]
    uint16_t status = 0, severity = 0;
    pv::EpicsTime stamp;
    std::string units;
    int16_t precision = 0;
    double disp_hi = 0, disp_lo = 0, alarm_hihi = 0, alarm_high = 0, alarm_low = 0,
           alarm_lolo = 0, ctrl_hi = 0, ctrl_lo = 0;
    std::vector<std::string> enum_strings;
};

// Decodes `count` elements (0 counts as 1) of DBR type t (0..34) from a payload of len bytes.
// Returns false, leaving out in an unspecified state, if t is not a value type or the payload
// is shorter than the type and count need.
bool decode_dbr(uint16_t t, const uint8_t* payload, std::size_t len, uint32_t count,
                DbrValue& out);

} // namespace beamctl::ca
