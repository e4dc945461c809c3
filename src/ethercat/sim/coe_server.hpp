// The CoE object dictionary and SDO server of a simulated slave (ethercat.md §3), generated from
// its DeviceDesc: 0x1000 device type, 0x1008 device name, 0x1018 identity, 0x1C00 SM types,
// 0x1C10+n PDO assignment of each process-data SM n (writable in PREOP: sub0 = 0, entries,
// sub0 = n), 0x1600../0x1A00.. PDO mappings (read-only), and a parameter store in which any
// 0x8000-0x8FFF index:sub can be written (its first write fixes its size) and read back.
// Expedited and normal (size-indicated) transfers; no segmented transfers, no complete access.
// Threading: belongs to its ESC (the segment's thread).
#pragma once

#include "ethercat/device.hpp"

#include <cstddef>
#include <cstdint>
#include <map>
#include <vector>

namespace beamctl::ethercat::sim {

class CoeServer {
public:
    CoeServer(const DeviceDesc& desc, uint32_t serial);

    // Serves the CoE data of one mailbox request (CoE header + SDO, `len` bytes) in AL state
    // `al_state`. Writes the reply's CoE data to `reply` (capacity `cap`) and returns its length;
    // returns 0 with `mbx_error` set (coe::kMbxErr*) when the reply must be a mailbox error, and
    // 0 with mbx_error 0 when there is no reply (an abort from the master).
    std::size_t handle(const uint8_t* req, std::size_t len, uint8_t* reply, std::size_t cap,
                       uint8_t al_state, uint16_t& mbx_error);

    // What an SDO upload/download does, without the mailbox: 0 or the SDO abort code.
    uint32_t upload(uint16_t index, uint8_t sub, std::vector<uint8_t>& out) const;
    uint32_t download(uint16_t index, uint8_t sub, const uint8_t* data, std::size_t len,
                      uint8_t al_state);

    // Fault injection: downloads of index:sub abort with `code` (0: lift it; index 0: every one).
    void refuse_download(uint16_t index, uint8_t sub, uint32_t code);

    // Bytes of process data of SM `sm` under its current PDO assignment (the DeviceDesc default
    // if the SM has no assignment object).
    uint32_t sm_bytes(uint8_t sm) const;
    // The PDOs assigned to SM `sm` now, in order; false if the SM has no assignment object.
    bool assigned(uint8_t sm, std::vector<uint16_t>& pdos) const;

private:
    enum class Access : uint8_t { ReadOnly, ReadWrite, PdoAssign };
    struct Object {
        Access access = Access::ReadOnly;
        std::map<uint8_t, std::vector<uint8_t>> subs;
    };
    void add(uint16_t index, uint8_t sub, std::vector<uint8_t> value, Access a = Access::ReadOnly);
    uint32_t assign_write(uint16_t index, Object& o, uint8_t sub, const uint8_t* data,
                          std::size_t len, uint8_t al_state);

    DeviceDesc desc_;
    std::map<uint16_t, Object> objects_;
    std::map<uint32_t, uint32_t> refused_; // index << 8 | sub -> abort code
};

} // namespace beamctl::ethercat::sim
