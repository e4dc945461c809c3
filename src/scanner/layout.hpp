// What a client's cycle slot holds, and the layout the scanner hands a client at attach.
//
// A slot's data is the scanner master's whole process image for the bus (`image_bytes`: outputs
// as sent, inputs, the slaves' status bytes, then the master's own words ONE/ZERO/valid), then a
// CycleTail with the cycle's counters, then kSlaveStatusBytes per slave of the chain (in chain
// order). Offsets in the layout are offsets in that image, so a client binds its signals to the
// same places the scanner's master uses.
// Threading: none (plain data and pure functions).
#pragma once

#include "ethercat/master.hpp"
#include "scanner/protocol.hpp"

#include <cstdint>
#include <vector>

namespace beamctl::scanner {

struct CycleTail {
    uint16_t wkc = 0, expected_wkc = 0;
    int32_t responding = -1;
    uint64_t frames_lost = 0, frames_late = 0, wkc_errors = 0;
    uint64_t dc_time = 0; // the reference clock's time [ns], 0 without DC
};
static_assert(sizeof(CycleTail) == 40);

// Per chain slave after the tail: AL status byte, online, valid, ethercat::SlaveState.
constexpr std::size_t kSlaveStatusBytes = 4;

inline std::size_t slot_data_bytes(std::size_t image_bytes, std::size_t chain_slaves) {
    return image_bytes + sizeof(CycleTail) + kSlaveStatusBytes * chain_slaves;
}

// FNV-1a over everything of the layout a client binds to (image size, slaves, entries).
uint64_t layout_hash(const proto::Attached& a);

// The chain as the scanner describes it (its master's slaves, with the names of its file).
proto::ChainSlave chain_slave(const ethercat::SlaveInfo& s, const std::string& name);

// Scanner: the layout of chain slave `i` of `m` (its byte ranges and every signal of it,
// including the master's words ONE, ZERO, valid).
proto::LayoutSlave layout_slave(const ethercat::Master& m, std::size_t i, const std::string& name);

} // namespace beamctl::scanner
