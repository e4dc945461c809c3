#include "ethercat/sii.hpp"

#include "core/error.hpp"

#include <array>
#include <cstdio>
#include <map>

namespace beamctl::ethercat {

namespace {

struct DataType {
    std::string_view name;
    uint8_t code;
    unsigned bits;
};

// ETG.1020 basic data types.
constexpr std::array<DataType, 27> kDataTypes{{
    {"BOOL", 0x01, 1},    {"INT8", 0x02, 8},    {"INT16", 0x03, 16},  {"INT32", 0x04, 32},
    {"UINT8", 0x05, 8},   {"UINT16", 0x06, 16}, {"UINT32", 0x07, 32}, {"REAL32", 0x08, 32},
    {"INT24", 0x10, 24},  {"REAL64", 0x11, 64}, {"INT40", 0x12, 40},  {"INT48", 0x13, 48},
    {"INT56", 0x14, 56},  {"INT64", 0x15, 64},  {"UINT24", 0x16, 24}, {"UINT40", 0x18, 40},
    {"UINT48", 0x19, 48}, {"UINT56", 0x1A, 56}, {"UINT64", 0x1B, 64}, {"BIT1", 0x30, 1},
    {"BIT2", 0x31, 2},    {"BIT3", 0x32, 3},    {"BIT4", 0x33, 4},    {"BIT5", 0x34, 5},
    {"BIT6", 0x35, 6},    {"BIT7", 0x36, 7},    {"BIT8", 0x37, 8},
}};

std::string hex(uint32_t v, int digits = 4) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%0*X", digits, v);
    return buf;
}

std::string word_at(size_t w) {
    return "SII word " + hex(static_cast<uint32_t>(w));
}

// Little-endian byte buffer for one category.
class Bytes {
public:
    void u8(uint8_t v) { b_.push_back(v); }
    void u16(uint16_t v) {
        u8(v & 0xFF);
        u8(v >> 8);
    }
    void u32(uint32_t v) {
        u16(v & 0xFFFF);
        u16(v >> 16);
    }
    void zeros(size_t n) { b_.insert(b_.end(), n, 0); }
    std::vector<uint8_t>& data() { return b_; }

private:
    std::vector<uint8_t> b_;
};

// Strings category under construction: deduplicated, 1-based indices, 0 = no string.
class StringTable {
public:
    explicit StringTable(const std::string& device)
        : device_(device) {}
    uint8_t add(const std::string& s) {
        if (s.empty()) return 0;
        if (auto it = index_.find(s); it != index_.end()) return it->second;
        if (s.size() > 255)
            throw Error(SB() << device_ << ": SII string \"" << s << "\" has " << s.size()
                             << " bytes, SII allows at most 255");
        if (list_.size() >= 255)
            throw Error(SB() << device_
                             << ": more than 255 distinct names, SII strings "
                                "category allows at most 255");
        list_.push_back(s);
        uint8_t idx = static_cast<uint8_t>(list_.size());
        index_.emplace(s, idx);
        return idx;
    }
    const std::vector<std::string>& list() const { return list_; }

private:
    std::string device_;
    std::vector<std::string> list_;
    std::map<std::string, uint8_t> index_;
};

void append_category(std::vector<uint16_t>& img, uint16_t type, std::vector<uint8_t> bytes) {
    if (bytes.size() % 2) bytes.push_back(0);
    img.push_back(type);
    img.push_back(static_cast<uint16_t>(bytes.size() / 2));
    for (size_t i = 0; i < bytes.size(); i += 2)
        img.push_back(static_cast<uint16_t>(bytes[i] | (bytes[i + 1] << 8)));
}

uint8_t assigned_sm(const DeviceDesc& d, uint16_t pdo_index) {
    for (const auto& [sm, idx] : d.pdo_assign)
        if (idx == pdo_index) return sm;
    return 0xFF;
}

std::vector<uint8_t> pdo_category(const DeviceDesc& d, const std::vector<Pdo>& pdos,
                                  StringTable& strings) {
    Bytes b;
    for (const Pdo& p : pdos) {
        if (p.entries.size() > 255)
            throw Error(SB() << d.type << ": PDO " << hex(p.index) << " has " << p.entries.size()
                             << " entries, SII allows at most 255");
        b.u16(p.index);
        b.u8(static_cast<uint8_t>(p.entries.size()));
        b.u8(assigned_sm(d, p.index));
        b.u8(0); // DC sync
        b.u8(strings.add(p.name));
        b.u16(0); // flags
        for (const PdoEntry& e : p.entries) {
            b.u16(e.index);
            b.u8(e.sub);
            b.u8(strings.add(e.name));
            b.u8(coe_datatype_code(e.datatype));
            b.u8(e.bits);
            b.u16(0); // flags
        }
    }
    return std::move(b.data());
}

// FMMU usage: one per process-data SM that carries PDOs, then the mailbox-state FMMU.
std::vector<uint8_t> fmmu_usage(const DeviceDesc& d) {
    std::vector<uint8_t> f;
    bool mailbox = false;
    for (const SyncManagerDesc& sm : d.sms) {
        if (sm.type == SmType::MailboxIn) mailbox = true;
        bool has_pdos = false;
        for (const auto& a : d.pdo_assign) has_pdos |= a.first == sm.index;
        if (!has_pdos) continue;
        if (sm.type == SmType::Outputs) f.push_back(kSiiFmmuOutputs);
        if (sm.type == SmType::Inputs) f.push_back(kSiiFmmuInputs);
    }
    if (mailbox) f.push_back(kSiiFmmuMbxState);
    return f;
}

} // namespace

uint8_t coe_datatype_code(std::string_view name) {
    for (const DataType& t : kDataTypes)
        if (t.name == name) return t.code;
    return 0;
}

std::string_view coe_datatype_name(uint8_t code) {
    for (const DataType& t : kDataTypes)
        if (t.code == code) return t.name;
    return {};
}

unsigned coe_datatype_bits(std::string_view name) {
    for (const DataType& t : kDataTypes)
        if (t.name == name) return t.bits;
    return 0;
}

uint8_t sii_crc8(const uint16_t* config_words) {
    uint8_t crc = 0xFF;
    for (int i = 0; i < 14; ++i) {
        uint16_t w = config_words[i / 2];
        crc ^= static_cast<uint8_t>(i % 2 ? w >> 8 : w & 0xFF);
        for (int bit = 0; bit < 8; ++bit)
            crc = static_cast<uint8_t>(crc & 0x80 ? (crc << 1) ^ 0x07 : crc << 1);
    }
    return crc;
}

std::vector<uint16_t> build_sii(const DeviceDesc& d, uint32_t serial) {
    std::vector<uint16_t> img(kSiiFirstCategoryWord, 0);
    const SyncManagerDesc* mbx_out = nullptr;
    const SyncManagerDesc* mbx_in = nullptr;
    for (const SyncManagerDesc& sm : d.sms) {
        if (sm.type == SmType::MailboxOut && !mbx_out) mbx_out = &sm;
        if (sm.type == SmType::MailboxIn && !mbx_in) mbx_in = &sm;
    }
    const bool mailbox = mbx_out && mbx_in;
    const bool dc = d.dc_assign_activate != 0;

    // Config area (ESC registers 0x0140-0x014F): PDI type, ESC config, SYNC impulse length.
    uint16_t pdi_type = mailbox || dc ? 0x08 : 0x04;     // 16-bit async uC : digital I/O
    uint16_t esc_config = (mailbox || dc) ? 0x00 : 0x01; // device emulation without uC
    if (dc) esc_config |= 0x0C;                          // DC SYNC out + latch in units
    img[0] = static_cast<uint16_t>(pdi_type | esc_config << 8);
    img[2] = dc ? 1000 : 0; // SYNC impulse length [10 ns]
    img[kSiiAliasWord] = 0;
    img[kSiiChecksumWord] = sii_crc8(img.data());

    auto put32 = [&](uint16_t w, uint32_t v) {
        img[w] = static_cast<uint16_t>(v & 0xFFFF);
        img[w + 1] = static_cast<uint16_t>(v >> 16);
    };
    put32(kSiiVendorWord, d.vendor);
    put32(kSiiProductWord, d.product);
    put32(kSiiRevisionWord, d.revision);
    put32(kSiiSerialWord, serial);
    if (mailbox) {
        for (uint16_t base : {kSiiBootRxMbxWord, kSiiRxMbxOffsetWord}) {
            img[base] = mbx_out->start;
            img[base + 1] = mbx_out->default_size;
            img[base + 2] = mbx_in->start;
            img[base + 3] = mbx_in->default_size;
        }
    }
    img[kSiiProtocolsWord] = mailbox && d.coe ? kSiiProtocolCoE : 0;
    img[kSiiVersionWord] = 1;

    // Categories other than strings first, so the string table is complete.
    StringTable strings(d.type.empty() ? "device" : d.type);
    Bytes general;
    general.u8(0);                   // group
    general.u8(0);                   // image
    general.u8(strings.add(d.type)); // order
    general.u8(strings.add(d.name)); // name
    general.u8(0);
    general.u8(mailbox && d.coe ? 0x27 : 0); // CoE: SDO, SDO info, PDO assign, complete access
    general.zeros(5);                        // FoE, EoE, SoE, DS402, sysman class
    general.u8(0);                           // flags
    general.u16(d.ebus_current_ma);
    general.zeros(2);    // group (compatibility)
    general.u16(0x0033); // ports 0 and 1: E-bus
    general.zeros(14);

    std::vector<uint8_t> fmmus = fmmu_usage(d);
    Bytes syncm;
    for (const SyncManagerDesc& sm : d.sms) {
        syncm.u16(sm.start);
        syncm.u16(sm.default_size);
        syncm.u8(sm.control);
        syncm.u8(0);
        syncm.u8(static_cast<uint8_t>((sm.enable ? kSiiSmEnable : 0) |
                                      (sm.is_virtual ? kSiiSmVirtual : 0)));
        syncm.u8(static_cast<uint8_t>(sm.type));
    }
    std::vector<uint8_t> txpdo = pdo_category(d, d.tx_pdos, strings);
    std::vector<uint8_t> rxpdo = pdo_category(d, d.rx_pdos, strings);
    Bytes dcb;
    if (dc) {
        dcb.u32(0); // SYNC0 cycle (set by the master)
        dcb.u32(0); // SYNC0 shift
        dcb.u32(0); // SYNC1 shift
        dcb.u16(0); // SYNC1 cycle factor
        dcb.u16(d.dc_assign_activate);
        dcb.u16(1); // SYNC0 cycle factor
        dcb.u8(strings.add("DC"));
        dcb.u8(0); // description
        dcb.zeros(4);
    }

    Bytes str;
    str.u8(static_cast<uint8_t>(strings.list().size()));
    for (const std::string& s : strings.list()) {
        str.u8(static_cast<uint8_t>(s.size()));
        for (char c : s) str.u8(static_cast<uint8_t>(c));
    }
    append_category(img, kSiiCatStrings, std::move(str.data()));
    append_category(img, kSiiCatGeneral, std::move(general.data()));
    if (!fmmus.empty()) append_category(img, kSiiCatFmmu, fmmus);
    if (!d.sms.empty()) append_category(img, kSiiCatSyncM, std::move(syncm.data()));
    if (!d.tx_pdos.empty()) append_category(img, kSiiCatTxPdo, std::move(txpdo));
    if (!d.rx_pdos.empty()) append_category(img, kSiiCatRxPdo, std::move(rxpdo));
    if (dc) append_category(img, kSiiCatDc, std::move(dcb.data()));
    img.push_back(kSiiCatEnd);

    // Declared EEPROM size: smallest power of two in KBit (64 words) that holds the image.
    size_t kbit = 1;
    while (kbit * 64 < img.size()) kbit *= 2;
    img[kSiiSizeWord] = static_cast<uint16_t>(kbit - 1);
    img.resize(kbit * 64, 0xFFFF);
    return img;
}

SiiInfo parse_sii(const std::vector<uint16_t>& words) {
    const size_t n = words.size();
    if (n < kSiiFirstCategoryWord)
        throw Error(SB() << "SII image has " << n << " words, needs at least "
                         << kSiiFirstCategoryWord << " (header words 0x0000-0x003F)");
    const uint8_t crc = sii_crc8(words.data());
    if ((words[kSiiChecksumWord] & 0xFF) != crc)
        throw Error(SB() << word_at(kSiiChecksumWord) << ": config-area checksum "
                         << hex(words[kSiiChecksumWord] & 0xFF, 2) << " should be " << hex(crc, 2)
                         << " (CRC-8 of words 0x0000-0x0006)");

    SiiInfo info;
    auto get32 = [&](uint16_t w) { return words[w] | static_cast<uint32_t>(words[w + 1]) << 16; };
    info.alias = words[kSiiAliasWord];
    info.vendor = get32(kSiiVendorWord);
    info.product = get32(kSiiProductWord);
    info.revision = get32(kSiiRevisionWord);
    info.serial = get32(kSiiSerialWord);
    info.rx_mbx_offset = words[kSiiRxMbxOffsetWord];
    info.rx_mbx_size = words[kSiiRxMbxSizeWord];
    info.tx_mbx_offset = words[kSiiTxMbxOffsetWord];
    info.tx_mbx_size = words[kSiiTxMbxSizeWord];
    info.protocols = words[kSiiProtocolsWord];

    // Pass 1: locate categories, bounds-checked.
    struct Category {
        uint16_t type;
        size_t word; // first data word
        size_t len;  // data words
    };
    std::vector<Category> cats;
    size_t w = kSiiFirstCategoryWord;
    for (;;) {
        if (w >= n)
            throw Error(SB() << word_at(w)
                             << ": image ends without the end-of-categories "
                                "marker 0xFFFF");
        uint16_t type = words[w];
        if (type == kSiiCatEnd) break;
        if (w + 1 >= n)
            throw Error(SB() << word_at(w) << ": category " << type
                             << " header is cut off by the end of the image");
        size_t len = words[w + 1];
        if (w + 2 + len > n)
            throw Error(SB() << word_at(w) << ": category " << type << " of " << len
                             << " words runs past the end of the image (" << n << " words)");
        cats.push_back({type, w + 2, len});
        w += 2 + len;
    }
    auto bytes_of = [&](const Category& c) {
        std::vector<uint8_t> b;
        b.reserve(c.len * 2);
        for (size_t i = 0; i < c.len; ++i) {
            b.push_back(words[c.word + i] & 0xFF);
            b.push_back(words[c.word + i] >> 8);
        }
        return b;
    };
    auto at_byte = [](const Category& c, size_t byte) { return word_at(c.word + byte / 2); };

    // Pass 2: strings first, everything else refers to them.
    bool have_strings = false;
    for (const Category& c : cats) {
        if (c.type != kSiiCatStrings) continue;
        if (have_strings) throw Error(SB() << word_at(c.word - 2) << ": second strings category");
        have_strings = true;
        std::vector<uint8_t> b = bytes_of(c);
        if (b.empty()) continue;
        size_t count = b[0], pos = 1;
        for (size_t i = 0; i < count; ++i) {
            if (pos >= b.size() || pos + 1 + b[pos] > b.size())
                throw Error(SB() << at_byte(c, pos) << ": string " << i + 1 << " of " << count
                                 << " runs past the end of the strings category");
            info.strings.emplace_back(reinterpret_cast<const char*>(&b[pos + 1]), b[pos]);
            pos += 1 + b[pos];
        }
    }
    auto string_at = [&](uint8_t idx, const std::string& where) -> std::string {
        if (idx == 0) return {};
        if (idx > info.strings.size())
            throw Error(SB() << where << ": string index " << unsigned(idx) << " but the strings "
                             << "category has " << info.strings.size() << " strings");
        return info.strings[idx - 1];
    };

    std::vector<std::pair<uint8_t, uint16_t>> rx_assign, tx_assign;
    std::vector<std::pair<uint8_t, size_t>> assign_check; // {sm, word}
    bool have_general = false, have_dc = false;
    for (const Category& c : cats) {
        std::vector<uint8_t> b = bytes_of(c);
        switch (c.type) {
        case kSiiCatGeneral: {
            if (have_general)
                throw Error(SB() << word_at(c.word - 2) << ": second general category");
            have_general = true;
            if (b.size() < 14)
                throw Error(SB() << word_at(c.word - 2) << ": general category has " << c.len
                                 << " words, needs at least 7");
            info.type = string_at(b[2], at_byte(c, 2));
            info.name = string_at(b[3], at_byte(c, 3));
            info.coe_details = b[5];
            info.ebus_current_ma = static_cast<int16_t>(b[12] | b[13] << 8);
            break;
        }
        case kSiiCatFmmu:
            info.fmmus.insert(info.fmmus.end(), b.begin(), b.end());
            while (!info.fmmus.empty() && (info.fmmus.back() == 0 || info.fmmus.back() == 0xFF))
                info.fmmus.pop_back();
            break;
        case kSiiCatSyncM: {
            if (c.len % 4)
                throw Error(SB() << word_at(c.word - 2) << ": SyncM category of " << c.len
                                 << " words is not a multiple of 4 (8 bytes per SM)");
            for (size_t pos = 0; pos < b.size(); pos += 8) {
                SyncManagerDesc sm;
                sm.index = static_cast<uint8_t>(info.sms.size());
                sm.start = static_cast<uint16_t>(b[pos] | b[pos + 1] << 8);
                sm.default_size = static_cast<uint16_t>(b[pos + 2] | b[pos + 3] << 8);
                sm.control = b[pos + 4];
                sm.enable = b[pos + 6] & kSiiSmEnable;
                sm.is_virtual = b[pos + 6] & kSiiSmVirtual;
                if (b[pos + 7] > static_cast<uint8_t>(SmType::Inputs))
                    throw Error(SB()
                                << at_byte(c, pos + 7) << ": sync manager " << unsigned(sm.index)
                                << " has type " << unsigned(b[pos + 7]) << ", expected 0-4");
                sm.type = static_cast<SmType>(b[pos + 7]);
                info.sms.push_back(sm);
            }
            break;
        }
        case kSiiCatTxPdo:
        case kSiiCatRxPdo: {
            const bool tx = c.type == kSiiCatTxPdo;
            size_t pos = 0;
            while (pos < b.size()) {
                if (pos + 8 > b.size())
                    throw Error(SB() << at_byte(c, pos) << ": PDO header runs past the end of the "
                                     << (tx ? "TxPDO" : "RxPDO") << " category");
                Pdo p;
                p.index = static_cast<uint16_t>(b[pos] | b[pos + 1] << 8);
                size_t count = b[pos + 2];
                uint8_t sm = b[pos + 3];
                p.name = string_at(b[pos + 5], at_byte(c, pos + 5));
                if (pos + 8 + count * 8 > b.size())
                    throw Error(SB() << at_byte(c, pos) << ": PDO " << hex(p.index) << " with "
                                     << count << " entries runs past the end of the "
                                     << (tx ? "TxPDO" : "RxPDO") << " category");
                if (sm != 0xFF) {
                    (tx ? tx_assign : rx_assign).emplace_back(sm, p.index);
                    assign_check.emplace_back(sm, c.word + pos / 2);
                }
                pos += 8;
                for (size_t i = 0; i < count; ++i, pos += 8) {
                    PdoEntry e;
                    e.index = static_cast<uint16_t>(b[pos] | b[pos + 1] << 8);
                    e.sub = b[pos + 2];
                    e.name = string_at(b[pos + 3], at_byte(c, pos + 3));
                    e.datatype = std::string(coe_datatype_name(b[pos + 4]));
                    e.bits = b[pos + 5];
                    p.entries.push_back(std::move(e));
                }
                (tx ? info.tx_pdos : info.rx_pdos).push_back(std::move(p));
            }
            break;
        }
        case kSiiCatDc:
            if (have_dc) break; // first opmode only
            have_dc = true;
            if (b.size() < 24)
                throw Error(SB() << word_at(c.word - 2) << ": DC category has " << c.len
                                 << " words, needs at least 12");
            info.dc_assign_activate = static_cast<uint16_t>(b[14] | b[15] << 8);
            break;
        default:
            break; // strings done above; other categories are not needed by the master
        }
    }
    for (const auto& [sm, word] : assign_check)
        if (sm >= info.sms.size())
            throw Error(SB() << word_at(word) << ": PDO assigned to SM" << unsigned(sm)
                             << " but the SyncM category has " << info.sms.size()
                             << " sync managers");
    info.pdo_assign = std::move(rx_assign);
    info.pdo_assign.insert(info.pdo_assign.end(), tx_assign.begin(), tx_assign.end());
    return info;
}

} // namespace beamctl::ethercat
