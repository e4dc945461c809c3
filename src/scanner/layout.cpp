#include "scanner/layout.hpp"

#include <string_view>

namespace beamctl::scanner {

namespace {
struct Fnv {
    uint64_t h = 0xcbf29ce484222325ull;
    void bytes(const void* p, std::size_t n) {
        const auto* b = static_cast<const uint8_t*>(p);
        for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
    }
    template <class T> void num(T v) { bytes(&v, sizeof v); }
    void str(std::string_view s) {
        num(uint32_t(s.size()));
        bytes(s.data(), s.size());
    }
};
} // namespace

uint64_t layout_hash(const proto::Attached& a) {
    Fnv f;
    f.num(a.image_bytes);
    for (const auto& s : a.slaves) {
        f.num(s.slave.position);
        f.str(s.slave.type);
        f.num(s.slave.oversampling);
        f.num(s.out_offset), f.num(s.out_bytes), f.num(s.in_offset), f.num(s.in_bytes);
        for (const auto& e : s.entries) {
            f.str(e.name);
            f.num(e.bit_offset), f.num(e.bits), f.num(uint8_t(e.output));
            f.str(e.datatype);
        }
    }
    return f.h;
}

proto::ChainSlave chain_slave(const ethercat::SlaveInfo& s, const std::string& name) {
    proto::ChainSlave c;
    c.position = uint16_t(s.position);
    c.name = name;
    c.type = s.type;
    c.vendor = s.sii.vendor;
    c.product = s.sii.product;
    c.revision = s.sii.revision;
    c.oversampling = uint16_t(s.oversampling);
    return c;
}

proto::LayoutSlave layout_slave(const ethercat::Master& m, std::size_t i, const std::string& name) {
    const ethercat::SlaveInfo& s = m.slaves()[i];
    proto::LayoutSlave l;
    l.slave = chain_slave(s, name);
    l.out_offset = s.out_offset, l.out_bytes = s.out_bytes, l.in_offset = s.in_offset, l.in_bytes = s.in_bytes;
    const std::string pre = SB() << "ec" << m.bus_id() << ".s" << s.position << ".";
    for (const ethercat::SignalInfo& sig : m.signals()) {
        if (sig.slave != s.position || sig.name.compare(0, pre.size(), pre) != 0) continue;
        proto::LayoutEntry e;
        e.name = sig.name.substr(pre.size());
        e.bit_offset = sig.bit_offset;
        e.bits = sig.bits;
        e.datatype = sig.datatype;
        e.output = sig.output;
        // Index, subindex and PDO of the entry, from the PDOs in use.
        for (const auto* pdos : {&s.rx_pdos, &s.tx_pdos})
            for (const auto& p : *pdos)
                for (const auto& pe : p.entries)
                    if (pe.name == e.name) {
                        e.index = pe.index;
                        e.sub = pe.sub;
                        e.pdo = p.index;
                    }
        l.entries.push_back(std::move(e));
    }
    return l;
}

} // namespace beamctl::scanner
