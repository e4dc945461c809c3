#include "ethercat/device.hpp"

#include "core/error.hpp"

#include <algorithm>

namespace beamctl::ethercat {

const char* sm_type_name(SmType t) {
    switch (t) {
    case SmType::MailboxOut:
        return "MBoxOut";
    case SmType::MailboxIn:
        return "MBoxIn";
    case SmType::Outputs:
        return "Outputs";
    case SmType::Inputs:
        return "Inputs";
    case SmType::Unused:
        break;
    }
    return "Unused";
}

std::optional<SmType> sm_type_from_name(std::string_view s) {
    for (SmType t : {SmType::MailboxOut, SmType::MailboxIn, SmType::Outputs, SmType::Inputs, SmType::Unused})
        if (s == sm_type_name(t)) return t;
    return std::nullopt;
}

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

namespace {
// The channel name of a first sample entry ("analogInputArray01_1" -> "analogInputArray01").
std::string channel_of(const std::string& first) {
    return first.size() > 2 && first.compare(first.size() - 2, 2, "_1") == 0 ? first.substr(0, first.size() - 2) : first;
}
} // namespace

DeviceDesc DeviceDesc::with_oversampling(unsigned n) const {
    if (n == 1) return *this;
    if (oversampling.max == 0) throw Error(SB() << type << " does not oversample (no oversampling factor but 1)");
    if (n < 1 || n > oversampling.max)
        throw Error(SB() << type << ": oversampling factor " << n << " should be 1.." << oversampling.max);
    DeviceDesc d = *this;
    for (const auto& ch : oversampling.channels) {
        uint16_t first = ch.pdo;
        const Pdo* base = find_pdo(first);
        if (!base || base->entries.size() != 1) continue; // the catalog reader checked this
        bool out = first < 0x1A00;
        auto& list = out ? d.rx_pdos : d.tx_pdos;
        auto at = std::find_if(list.begin(), list.end(), [&](const Pdo& p) { return p.index == first; });
        std::vector<Pdo> more;
        const PdoEntry& e = base->entries[0];
        std::string channel = channel_of(e.name);
        for (unsigned k = 2; k <= n; ++k) {
            Pdo p;
            p.index = uint16_t(first + k - 1);
            p.name = base->name + " " + std::to_string(k);
            PdoEntry x = e;
            x.index = uint16_t(e.index + 0x10 * (k - 1));
            x.name = channel + "_" + std::to_string(k);
            p.entries.push_back(x);
            more.push_back(std::move(p));
        }
        list.insert(at + 1, more.begin(), more.end());
        auto a = std::find_if(d.pdo_assign.begin(), d.pdo_assign.end(), [&](const auto& x) { return x.second == first; });
        if (a == d.pdo_assign.end()) continue;
        uint8_t sm = a->first;
        std::vector<std::pair<uint8_t, uint16_t>> assign;
        for (unsigned k = 2; k <= n; ++k) assign.emplace_back(sm, uint16_t(first + k - 1));
        d.pdo_assign.insert(a + 1, assign.begin(), assign.end());
    }
    for (SyncManagerDesc& sm : d.sms)
        if ((sm.type == SmType::Outputs || sm.type == SmType::Inputs) && !sm.is_virtual)
            sm.default_size = uint16_t(d.sm_bytes(sm.index));
    return d;
}

unsigned DeviceDesc::oversampling_factor() const {
    if (oversampling.channels.empty()) return 1;
    uint16_t first = oversampling.channels[0].pdo;
    unsigned n = 0;
    for (auto& a : pdo_assign)
        if (a.second >= first && a.second < first + oversampling.max) ++n;
    return std::max(n, 1u);
}

std::vector<DeviceDesc::MemMap> DeviceDesc::memmaps() const {
    std::vector<MemMap> out;
    unsigned n = oversampling_factor();
    for (const auto& ch : oversampling.channels) {
        const Pdo* base = find_pdo(ch.pdo);
        if (!base || base->entries.size() != 1) continue;
        const PdoEntry& e = base->entries[0];
        out.push_back(MemMap{ch.memmap, e.name, uint16_t(n), e.bits, e.datatype, ch.pdo < 0x1A00});
    }
    return out;
}

} // namespace beamctl::ethercat
