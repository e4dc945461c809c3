// Unit tests of SII EEPROM images (build_sii / parse_sii): round trip of every catalog device,
// the ETG.2010 layout as a master walks it (independently of parse_sii), the config-area CRC,
// and rejection of malformed images with the offending word offset.
#include "ethercat/sii.hpp"

#include "core/error.hpp"
#include "ethercat/catalog.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

using beamctl::Error;
using namespace beamctl::ethercat;

namespace {

template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

struct Cat {
    uint16_t type;
    size_t word; // first data word
    size_t len;  // data words
};

// Walks the categories from word 0x40 the way SOEM's ecx_siifind does.
std::vector<Cat> walk(const std::vector<uint16_t>& img) {
    std::vector<Cat> cats;
    size_t w = 0x40;
    while (w + 1 < img.size() && img[w] != 0xFFFF) {
        cats.push_back({img[w], w + 2, img[w + 1]});
        w += 2 + img[w + 1];
    }
    EXPECT_LT(w, img.size());
    EXPECT_EQ(img.at(w), 0xFFFF);
    return cats;
}

const Cat* find_cat(const std::vector<Cat>& cats, uint16_t type) {
    for (const Cat& c : cats)
        if (c.type == type) return &c;
    return nullptr;
}

uint8_t byte_at(const std::vector<uint16_t>& img, const Cat& c, size_t byte) {
    uint16_t w = img.at(c.word + byte / 2);
    return byte % 2 ? w >> 8 : w & 0xFF;
}

// CRC-8 x^8+x^2+x+1 in the augmented form (message bits shifted in, then 8 zero bits; initial
// register 0x48 is equivalent to the direct form's 0xFF).
uint8_t crc_augmented(const std::vector<uint16_t>& img) {
    uint8_t crc = 0x48;
    auto step = [&](int in_bit) {
        bool top = crc & 0x80;
        crc = static_cast<uint8_t>((crc << 1) | in_bit);
        if (top) crc ^= 0x07;
    };
    for (int i = 0; i < 14; ++i) {
        uint8_t b = i % 2 ? img[i / 2] >> 8 : img[i / 2] & 0xFF;
        for (int bit = 7; bit >= 0; --bit) step((b >> bit) & 1);
    }
    for (int i = 0; i < 8; ++i) step(0);
    return crc;
}

// Bits per SM from the PDO categories, read the way SOEM's ecx_siiPDO sums them.
std::map<uint8_t, uint32_t> sm_bits_from_pdo_categories(const std::vector<uint16_t>& img) {
    std::map<uint8_t, uint32_t> bits;
    for (const Cat& c : walk(img)) {
        if (c.type != 50 && c.type != 51) continue;
        size_t pos = 0;
        while (pos < c.len * 2) {
            uint8_t n = byte_at(img, c, pos + 2);
            uint8_t sm = byte_at(img, c, pos + 3);
            pos += 8;
            for (int e = 0; e < n; ++e, pos += 8)
                if (sm != 0xFF) bits[sm] += byte_at(img, c, pos + 5);
        }
    }
    return bits;
}

const Catalog& catalog() {
    return Catalog::builtin();
}

std::string entry_str(const PdoEntry& e) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%04X:%02X/%u %s %s", e.index, e.sub, e.bits, e.name.c_str(),
                  e.datatype.c_str());
    return buf;
}

void expect_same_pdos(const std::vector<Pdo>& a, const std::vector<Pdo>& b) {
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
        SCOPED_TRACE(a[i].index);
        EXPECT_EQ(a[i].index, b[i].index);
        EXPECT_EQ(a[i].name, b[i].name);
        ASSERT_EQ(a[i].entries.size(), b[i].entries.size());
        for (size_t j = 0; j < a[i].entries.size(); ++j)
            EXPECT_EQ(entry_str(a[i].entries[j]), entry_str(b[i].entries[j]));
    }
}

} // namespace

TEST(Sii, RoundTripEveryCatalogDevice) {
    ASSERT_EQ(catalog().types().size(), 19u); // 17 terminals + the EL7211 CSP variant + the EL6692's secondary side
    uint32_t serial = 1000;
    for (const std::string& type : catalog().types()) {
        SCOPED_TRACE(type);
        const DeviceDesc& d = *catalog().find(type);
        std::vector<uint16_t> img = build_sii(d, ++serial);
        SiiInfo info = parse_sii(img);

        EXPECT_EQ(info.vendor, d.vendor);
        EXPECT_EQ(info.product, d.product);
        EXPECT_EQ(info.revision, d.revision);
        EXPECT_EQ(info.serial, serial);
        EXPECT_EQ(info.alias, 0);
        EXPECT_EQ(info.type, d.type);
        EXPECT_EQ(info.name, d.name);
        EXPECT_EQ(info.dc_assign_activate, d.dc_assign_activate);
        EXPECT_EQ(info.ebus_current_ma, d.ebus_current_ma);
        EXPECT_EQ((info.protocols & kSiiProtocolCoE) != 0, d.coe);
        EXPECT_EQ(info.coe_details != 0, d.coe);

        ASSERT_EQ(info.sms.size(), d.sms.size());
        for (size_t i = 0; i < d.sms.size(); ++i) {
            SCOPED_TRACE(i);
            EXPECT_EQ(info.sms[i].index, d.sms[i].index);
            EXPECT_EQ(info.sms[i].start, d.sms[i].start);
            EXPECT_EQ(info.sms[i].default_size, d.sms[i].default_size);
            EXPECT_EQ(info.sms[i].control, d.sms[i].control);
            EXPECT_EQ(info.sms[i].enable, d.sms[i].enable);
            EXPECT_EQ(info.sms[i].is_virtual, d.sms[i].is_virtual);
            EXPECT_EQ(info.sms[i].type, d.sms[i].type);
        }
        expect_same_pdos(info.rx_pdos, d.rx_pdos);
        expect_same_pdos(info.tx_pdos, d.tx_pdos);
        EXPECT_EQ(info.pdo_assign, d.pdo_assign);

        // Mailbox words come from SM0/SM1.
        if (d.coe) {
            EXPECT_EQ(info.rx_mbx_offset, d.sms[0].start);
            EXPECT_EQ(info.rx_mbx_size, d.sms[0].default_size);
            EXPECT_EQ(info.tx_mbx_offset, d.sms[1].start);
            EXPECT_EQ(info.tx_mbx_size, d.sms[1].default_size);
        } else {
            EXPECT_EQ(info.rx_mbx_size, 0);
            EXPECT_EQ(info.tx_mbx_size, 0);
        }

        // Every entry name is in the strings category.
        for (const auto* list : {&d.rx_pdos, &d.tx_pdos})
            for (const Pdo& p : *list)
                for (const PdoEntry& e : p.entries) {
                    if (e.name.empty()) continue;
                    EXPECT_NE(std::find(info.strings.begin(), info.strings.end(), e.name),
                              info.strings.end())
                        << e.name;
                }

        // A master summing bit lengths per SM from the raw categories gets the catalog's sizes.
        auto bits = sm_bits_from_pdo_categories(img);
        for (const SyncManagerDesc& sm : d.sms)
            EXPECT_EQ((bits[sm.index] + 7) / 8, d.sm_bytes(sm.index)) << "SM" << int(sm.index);
    }
}

TEST(Sii, HeaderLayout) {
    const DeviceDesc& d = *catalog().find("EL7041");
    std::vector<uint16_t> img = build_sii(d, 0xA1B2C3D4);
    EXPECT_EQ(img[0x08], 0x0002);
    EXPECT_EQ(img[0x09], 0x0000);
    EXPECT_EQ(img[0x0A], 0x3052);
    EXPECT_EQ(img[0x0B], 0x1B81);
    EXPECT_EQ(img[0x0C], d.revision & 0xFFFF);
    EXPECT_EQ(img[0x0D], d.revision >> 16);
    EXPECT_EQ(img[0x0E], 0xC3D4);
    EXPECT_EQ(img[0x0F], 0xA1B2);
    EXPECT_EQ(img[0x18], 0x1000); // rx mailbox offset
    EXPECT_EQ(img[0x19], 128);
    EXPECT_EQ(img[0x1A], 0x1080);
    EXPECT_EQ(img[0x1B], 128);
    EXPECT_EQ(img[0x1C], 0x0004); // CoE
    EXPECT_EQ(img[0x04], 0);      // alias
    EXPECT_EQ(img[0x3F], 1);      // version
    // Declared size (KBit - 1) matches the image, a power of two of 64-word KBits.
    EXPECT_EQ(img.size() % 64, 0u);
    EXPECT_EQ(img[0x3E] + 1u, img.size() / 64);
    EXPECT_EQ((img[0x3E] + 1) & img[0x3E], 0) << "power of two";

    // Category order and sizes: strings, general (16 words), FMMU, SyncM (4 words per SM),
    // TxPDO, RxPDO, DC (12 words).
    std::vector<Cat> cats = walk(img);
    std::vector<uint16_t> types;
    for (const Cat& c : cats) types.push_back(c.type);
    EXPECT_EQ(types, (std::vector<uint16_t>{10, 30, 40, 41, 50, 51, 60}));
    EXPECT_EQ(find_cat(cats, 30)->len, 16u);
    EXPECT_EQ(find_cat(cats, 41)->len, 4u * d.sms.size());
    EXPECT_EQ(find_cat(cats, 60)->len, 12u);
    EXPECT_EQ(cats[0].word, 0x42u) << "strings start right after the first header";

    // SyncM entry 2: start 0x1100, length 8, control 0x64, enable 1, type 3 (outputs).
    const Cat& sm = *find_cat(cats, 41);
    EXPECT_EQ(img[sm.word + 8], 0x1100);
    EXPECT_EQ(img[sm.word + 9], 8);
    EXPECT_EQ(byte_at(img, sm, 16 + 4), 0x64);
    EXPECT_EQ(byte_at(img, sm, 16 + 6), 0x01);
    EXPECT_EQ(byte_at(img, sm, 16 + 7), 3);
    // DC AssignActivate at bytes 14-15 of the opmode.
    EXPECT_EQ(img[find_cat(cats, 60)->word + 7], d.dc_assign_activate);
}

TEST(Sii, FmmusAndOptionalCategories) {
    EXPECT_EQ(parse_sii(build_sii(*catalog().find("EL7041"))).fmmus,
              (std::vector<uint8_t>{kSiiFmmuOutputs, kSiiFmmuInputs, kSiiFmmuMbxState}));
    EXPECT_EQ(parse_sii(build_sii(*catalog().find("EL1008"))).fmmus,
              (std::vector<uint8_t>{kSiiFmmuInputs}));
    EXPECT_EQ(parse_sii(build_sii(*catalog().find("EL3104"))).fmmus,
              (std::vector<uint8_t>{kSiiFmmuInputs, kSiiFmmuMbxState}));
    EXPECT_EQ(parse_sii(build_sii(*catalog().find("EL2252"))).fmmus,
              (std::vector<uint8_t>{kSiiFmmuOutputs, kSiiFmmuOutputs, kSiiFmmuOutputs}));

    // The coupler has no SMs, FMMUs, PDOs or DC: only strings and general.
    std::vector<uint16_t> img = build_sii(*catalog().find("EK1100"));
    std::vector<uint16_t> types;
    for (const Cat& c : walk(img)) types.push_back(c.type);
    EXPECT_EQ(types, (std::vector<uint16_t>{10, 30}));
    SiiInfo info = parse_sii(img);
    EXPECT_TRUE(info.sms.empty());
    EXPECT_TRUE(info.fmmus.empty());
    EXPECT_EQ(info.protocols, 0);
    EXPECT_EQ(info.type, "EK1100");
}

TEST(Sii, PaddingAndEmptyPdosSurvive) {
    SiiInfo info = parse_sii(build_sii(*catalog().find("EL1252")));
    ASSERT_EQ(info.tx_pdos.size(), 4u);
    const Pdo& ch2 = info.tx_pdos[1];
    ASSERT_EQ(ch2.entries.size(), 2u);
    EXPECT_EQ(ch2.entries[1].index, 0);
    EXPECT_EQ(ch2.entries[1].bits, 6);
    EXPECT_EQ(ch2.entries[1].name, "");
    EXPECT_TRUE(info.tx_pdos[2].entries.empty());
    EXPECT_EQ(info.tx_pdos[3].entries.at(2).name, "timestampLatchPositive01");
    EXPECT_EQ(info.tx_pdos[3].entries.at(2).datatype, "UINT64");
    EXPECT_TRUE(info.sms.at(1).is_virtual);
    EXPECT_FALSE(info.sms.at(1).enable);
}

TEST(Sii, ConfigAreaCrc) {
    for (const std::string& type : catalog().types()) {
        SCOPED_TRACE(type);
        std::vector<uint16_t> img = build_sii(*catalog().find(type));
        EXPECT_EQ(img[7] & 0xFF, crc_augmented(img));
        EXPECT_EQ(img[7] >> 8, 0);
        EXPECT_EQ(sii_crc8(img.data()), img[7]);
    }
    // Independent of the image: all-zero config area, and one bit flipped anywhere changes it.
    std::vector<uint16_t> zero(8, 0);
    EXPECT_EQ(sii_crc8(zero.data()), crc_augmented(zero));
    for (int bit = 0; bit < 14 * 8; ++bit) {
        std::vector<uint16_t> w = zero;
        w[bit / 16] ^= static_cast<uint16_t>(1u << (bit % 16));
        EXPECT_NE(sii_crc8(w.data()), sii_crc8(zero.data())) << bit;
        EXPECT_EQ(sii_crc8(w.data()), crc_augmented(w)) << bit;
    }
}

TEST(Sii, RejectsMalformedImages) {
    const DeviceDesc& d = *catalog().find("EL7211");
    const std::vector<uint16_t> good = build_sii(d);
    const std::vector<Cat> cats = walk(good);
    auto hex4 = [](size_t w) {
        char b[16];
        std::snprintf(b, sizeof b, "0x%04zX", w);
        return std::string(b);
    };

    // Too short for the header.
    std::vector<uint16_t> img(good.begin(), good.begin() + 40);
    EXPECT_EQ(error_of([&] { parse_sii(img); }),
              "SII image has 40 words, needs at least 64 (header words 0x0000-0x003F)");

    // Config area changed without a new checksum.
    img = good;
    img[2] ^= 0x0100;
    EXPECT_EQ(error_of([&] { parse_sii(img); }).rfind("SII word 0x0007: config-area checksum", 0),
              0u);

    // A category whose length runs past the end.
    const Cat& tx = *find_cat(cats, 50);
    img = good;
    img[tx.word - 1] = 0x7FFF;
    EXPECT_EQ(error_of([&] { parse_sii(img); }),
              "SII word " + hex4(tx.word - 2) +
                  ": category 50 of 32767 words runs past the end "
                  "of the image (" +
                  std::to_string(img.size()) + " words)");

    // No end marker: the categories run into zeros until the image ends.
    img = good;
    size_t end = walk(good).back().word + walk(good).back().len;
    std::fill(img.begin() + end, img.end(), 0);
    EXPECT_NE(error_of([&] { parse_sii(img); }).find("without the end-of-categories marker"),
              std::string::npos);

    // A PDO entry naming string 200 of a smaller table.
    img = good;
    size_t entry0 = tx.word + 4; // first entry of the first TxPDO: bytes 8..15 of the category
    img[entry0 + 1] = static_cast<uint16_t>((img[entry0 + 1] & 0x00FF) | (200 << 8));
    EXPECT_EQ(error_of([&] { parse_sii(img); })
                  .rfind("SII word " + hex4(entry0 + 1) +
                             ": string index 200 but the strings "
                             "category has ",
                         0),
              0u)
        << error_of([&] { parse_sii(img); });

    // A PDO assigned to a sync manager that does not exist.
    img = good;
    img[tx.word + 1] = static_cast<uint16_t>((img[tx.word + 1] & 0x00FF) | (9 << 8));
    EXPECT_EQ(error_of([&] { parse_sii(img); }),
              "SII word " + hex4(tx.word) +
                  ": PDO assigned to SM9 but the SyncM category has 4 sync managers");

    // A PDO whose entry count runs past its category.
    img = good;
    img[tx.word + 1] = static_cast<uint16_t>((img[tx.word + 1] & 0xFF00) | 200);
    EXPECT_NE(error_of([&] { parse_sii(img); })
                  .find("with 200 entries runs past the end of the "
                        "TxPDO category"),
              std::string::npos);

    // SyncM category with a bad SM type.
    const Cat& sm = *find_cat(cats, 41);
    img = good;
    img[sm.word + 3] = static_cast<uint16_t>((img[sm.word + 3] & 0x00FF) | (7 << 8));
    EXPECT_EQ(error_of([&] { parse_sii(img); }),
              "SII word " + hex4(sm.word + 3) + ": sync manager 0 has type 7, expected 0-4");

    EXPECT_NO_THROW(parse_sii(good));
}

TEST(Sii, BuildRejectsWhatSiiCannotHold) {
    DeviceDesc d;
    d.type = "XT9999";
    d.sms.push_back({0, 0x1000, 0, 0x00, true, SmType::Inputs, false});
    Pdo p;
    p.index = 0x1A00;
    for (int i = 0; i < 256; ++i)
        p.entries.push_back(
            {0x6000, static_cast<uint8_t>(i % 200 + 1), 1, "input" + std::to_string(i), "BOOL"});
    d.tx_pdos.push_back(p);
    d.pdo_assign.push_back({0, 0x1A00});
    EXPECT_EQ(error_of([&] { build_sii(d); }),
              "XT9999: PDO 0x1A00 has 256 entries, SII allows at most 255");
    d.tx_pdos[0].entries.resize(255);
    EXPECT_EQ(error_of([&] { build_sii(d); }),
              "XT9999: more than 255 distinct names, SII strings category allows at most 255");
    d.tx_pdos[0].entries.resize(100);
    SiiInfo info = parse_sii(build_sii(d));
    EXPECT_EQ(info.tx_pdos.at(0).entries.size(), 100u);
    EXPECT_EQ(info.tx_pdos.at(0).entries.at(99).name, "input99");
}

TEST(Sii, DataTypeCodes) {
    EXPECT_EQ(coe_datatype_code("BOOL"), 0x01);
    EXPECT_EQ(coe_datatype_code("INT16"), 0x03);
    EXPECT_EQ(coe_datatype_code("UINT16"), 0x06);
    EXPECT_EQ(coe_datatype_code("UINT32"), 0x07);
    EXPECT_EQ(coe_datatype_code("INT64"), 0x15);
    EXPECT_EQ(coe_datatype_code("UINT64"), 0x1B);
    EXPECT_EQ(coe_datatype_code("BIT2"), 0x31);
    EXPECT_EQ(coe_datatype_code("NOPE"), 0x00);
    EXPECT_EQ(coe_datatype_name(0x07), "UINT32");
    EXPECT_EQ(coe_datatype_name(0xEE), "");
    EXPECT_EQ(coe_datatype_bits("REAL64"), 64u);
    EXPECT_EQ(coe_datatype_bits("BIT3"), 3u);
    EXPECT_EQ(coe_datatype_bits("NOPE"), 0u);
}
