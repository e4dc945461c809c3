// A process-data entry of a simulated slave as its terminal firmware sees it: a bit range inside
// one sync-manager buffer of the slave at a segment position. It holds the position, not the ESC,
// so it keeps working after a replug replaces the ESC. The layout is the device's default PDO
// assignment, which is what the master configures (it selects no other PDOs).
// Threading: used on the segment's thread only; get/set never allocate.
#pragma once

#include "ethercat/device.hpp"

#include <cstdint>
#include <string>
#include <string_view>

namespace beamctl::ethercat::sim {

class Segment;

// Where an entry lives in a simulated slave: bit range inside one SM buffer (default PDOs).
struct EntryLocation {
    uint8_t sm = 0;
    uint32_t bit = 0;
    uint8_t bits = 0;
    bool output = false; // RxPDO (master -> slave)
};
// Throws Error naming the device and entry if it has no such entry.
EntryLocation locate_entry(const DeviceDesc& d, std::string_view entry);
// True if the device has a process-data entry of that name (default assignment).
bool has_entry(const DeviceDesc& d, std::string_view entry);

struct IoPoint {
    int slave = -1; // segment position; -1: not bound (get() is 0, set() does nothing)
    EntryLocation loc;
    bool oversampled = false; // the first sample of an oversampling channel (EL3702, EL4732)

    bool bound() const noexcept { return slave >= 0; }
    // Raw value, zero-extended. An output reads 0 unless its slave is in OP (outputs valid):
    // the terminal holds its safe state otherwise.
    uint64_t get(Segment& seg) const noexcept;
    int64_t get_signed(Segment& seg) const noexcept; // sign-extended from loc.bits
    bool bit(Segment& seg, unsigned n) const noexcept { return get(seg) >> n & 1; }
    void set(Segment& seg, uint64_t v) const noexcept; // truncated to loc.bits
    // Samples per cycle behind this point: the terminal's factor for an oversampling channel, else 1.
    unsigned samples(Segment& seg) const noexcept;
    // Sample k (0-based) of an oversampling channel: the samples follow each other in the SM.
    IoPoint sample(unsigned k) const noexcept {
        IoPoint p = *this;
        p.loc.bit += k * loc.bits;
        return p;
    }
};

// Binds `entry` of the slave at `position`; throws Error naming both if there is no such entry.
IoPoint bind_io(Segment& seg, int position, std::string_view entry);
// Same, but returns an unbound point when the slave has no such entry (optional entries).
IoPoint bind_optional(Segment& seg, int position, std::string_view entry);

// Same, under the slave's PDO assignment as it is now (its CoE 0x1C1n objects, which startup SDOs
// may have changed; the default without CoE): unbound when no assigned PDO has the entry.
IoPoint bind_assigned(Segment& seg, int position, std::string_view entry);
// Bit copies between process-data buffers (LSB-first bit order, as EtherCAT maps them).
uint64_t read_bits(const uint8_t* p, uint32_t bit, uint8_t bits) noexcept;
void write_bits(uint8_t* p, uint32_t bit, uint8_t bits, uint64_t v) noexcept;

} // namespace beamctl::ethercat::sim
