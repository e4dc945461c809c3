#include "ethercat/sim/io_point.hpp"

#include "core/error.hpp"
#include "ethercat/sim/coe_server.hpp"
#include "ethercat/sim/esc.hpp"
#include "ethercat/sim/segment.hpp"

#include <cstring>

namespace beamctl::ethercat::sim {

namespace {
// Every entry of the PDOs `assign` lists ({sm, pdo}, in order), where it lives.
template <class F>
bool for_each_entry(const DeviceDesc& d, const std::vector<std::pair<uint8_t, uint16_t>>& assign, F&& f) {
    for (const auto& sm : d.sms) {
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        bool out = sm.type == SmType::Outputs;
        uint32_t bit = 0;
        for (auto& [smi, pdo_index] : assign) {
            if (smi != sm.index) continue;
            for (const auto& p : out ? d.rx_pdos : d.tx_pdos) {
                if (p.index != pdo_index) continue;
                for (const auto& e : p.entries) {
                    if (f(e, EntryLocation{sm.index, bit, e.bits, out})) return true;
                    bit += e.bits;
                }
            }
        }
    }
    return false;
}
template <class F>
bool for_each_entry(const DeviceDesc& d, F&& f) {
    return for_each_entry(d, d.pdo_assign, f);
}
} // namespace

EntryLocation locate_entry(const DeviceDesc& d, std::string_view entry) {
    EntryLocation found;
    if (for_each_entry(d, [&](const PdoEntry& e, const EntryLocation& l) {
            if (e.name != entry) return false;
            found = l;
            return true;
        }))
        return found;
    throw Error(SB() << d.type << " has no process-data entry '" << entry << "'");
}

bool has_entry(const DeviceDesc& d, std::string_view entry) {
    return for_each_entry(d, [&](const PdoEntry& e, const EntryLocation&) { return e.name == entry; });
}

uint64_t read_bits(const uint8_t* p, uint32_t bit, uint8_t bits) noexcept {
    if ((bit & 7) == 0 && (bits & 7) == 0 && bits <= 64) { // byte aligned: little-endian bytes
        uint64_t v = 0;
        for (int i = bits / 8 - 1; i >= 0; --i) v = v << 8 | p[bit / 8 + unsigned(i)];
        return v;
    }
    uint64_t v = 0;
    for (uint32_t i = 0; i < bits; ++i) {
        uint32_t s = bit + i;
        v |= uint64_t(p[s >> 3] >> (s & 7) & 1) << i;
    }
    return v;
}

void write_bits(uint8_t* p, uint32_t bit, uint8_t bits, uint64_t v) noexcept {
    if ((bit & 7) == 0 && (bits & 7) == 0 && bits <= 64) {
        for (unsigned i = 0; i < bits / 8u; ++i) p[bit / 8 + i] = uint8_t(v >> (8 * i));
        return;
    }
    for (uint32_t i = 0; i < bits; ++i) {
        uint32_t d = bit + i;
        if (v >> i & 1) p[d >> 3] |= uint8_t(1u << (d & 7));
        else p[d >> 3] &= uint8_t(~(1u << (d & 7)));
    }
}

uint64_t IoPoint::get(Segment& seg) const noexcept {
    if (slave < 0) return 0;
    Esc& e = seg.slave(std::size_t(slave));
    if (loc.output && !e.outputs_valid()) return 0;
    return read_bits(e.sm_buffer(loc.sm), loc.bit, loc.bits);
}

int64_t IoPoint::get_signed(Segment& seg) const noexcept {
    uint64_t v = get(seg);
    if (loc.bits > 0 && loc.bits < 64 && (v >> (loc.bits - 1) & 1)) v |= ~uint64_t(0) << loc.bits;
    return int64_t(v);
}

void IoPoint::set(Segment& seg, uint64_t v) const noexcept {
    if (slave < 0) return;
    write_bits(seg.slave(std::size_t(slave)).sm_buffer(loc.sm), loc.bit, loc.bits, v);
}

unsigned IoPoint::samples(Segment& seg) const noexcept {
    return oversampled && slave >= 0 ? seg.slave(std::size_t(slave)).oversampling() : 1;
}

IoPoint bind_io(Segment& seg, int position, std::string_view entry) {
    if (position < 0 || std::size_t(position) >= seg.size())
        throw Error(SB() << "no slave at position " << position << " (the segment has " << seg.size() << ")");
    try {
        const DeviceDesc& d = seg.slave(std::size_t(position)).desc();
        IoPoint p{position, locate_entry(d, entry)};
        for (const auto& m : d.memmaps()) p.oversampled |= m.first == entry;
        return p;
    } catch (const Error& e) {
        throw Error(SB() << "slave " << position << ": " << e.what());
    }
}

IoPoint bind_optional(Segment& seg, int position, std::string_view entry) {
    if (position < 0 || std::size_t(position) >= seg.size()) return {};
    if (!has_entry(seg.slave(std::size_t(position)).desc(), entry)) return {};
    return bind_io(seg, position, entry);
}

IoPoint bind_assigned(Segment& seg, int position, std::string_view entry) {
    if (position < 0 || std::size_t(position) >= seg.size()) return {};
    Esc& esc = seg.slave(std::size_t(position));
    const DeviceDesc& d = esc.desc();
    if (!esc.coe()) return bind_optional(seg, position, entry);
    std::vector<std::pair<uint8_t, uint16_t>> assign;
    std::vector<uint16_t> pdos;
    for (const auto& sm : d.sms) {
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        if (esc.coe()->assigned(sm.index, pdos))
            for (uint16_t p : pdos) assign.emplace_back(sm.index, p);
        else
            for (const auto& a : d.pdo_assign)
                if (a.first == sm.index) assign.push_back(a);
    }
    IoPoint found;
    for_each_entry(d, assign, [&](const PdoEntry& e, const EntryLocation& l) {
        if (e.name != entry) return false;
        found = IoPoint{position, l};
        return true;
    });
    return found;
}

} // namespace beamctl::ethercat::sim
