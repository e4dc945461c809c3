#include "ethercat/device.hpp"

namespace beamctl::ethercat {

uint32_t Pdo::bit_size() const {
    uint32_t bits = 0;
    for (const PdoEntry& e : entries) bits += e.bits;
    return bits;
}

const Pdo* DeviceDesc::find_pdo(uint16_t index) const {
    for (const Pdo& p : rx_pdos)
        if (p.index == index) return &p;
    for (const Pdo& p : tx_pdos)
        if (p.index == index) return &p;
    return nullptr;
}

uint32_t DeviceDesc::sm_bytes(uint8_t sm_index) const {
    uint32_t bits = 0;
    for (const auto& [sm, pdo_index] : pdo_assign) {
        if (sm != sm_index) continue;
        if (const Pdo* p = find_pdo(pdo_index)) bits += p->bit_size();
    }
    return (bits + 7) / 8;
}

} // namespace beamctl::ethercat
