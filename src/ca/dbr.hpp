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

} // namespace beamctl::ca
