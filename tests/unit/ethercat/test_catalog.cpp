// Unit tests of the device catalog (beamctl::ethercat::Catalog): the catalog/*.yaml files
// against the spec's terminal table and ecmccfg names, YAML validation with file:line:col
// errors, and ESI XML loading (including ecmc names taken over from our catalog).
#include "ethercat/catalog.hpp"

#include "core/error.hpp"
#include "ethercat/sii.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using beamctl::Error;
using namespace beamctl::ethercat;

namespace {

// A fresh directory under the system temp dir, removed at the end of the test.
class TempDir {
public:
    TempDir() {
        std::string tmpl = (fs::temp_directory_path() / "beamctl_catalog_XXXXXX").string();
        path_ = mkdtemp(tmpl.data());
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    std::string write(const std::string& name, const std::string& text) const {
        std::string p = (fs::path(path_) / name).string();
        std::ofstream(p) << text;
        return p;
    }
    const std::string& path() const { return path_; }

private:
    std::string path_;
};

// The message of the Error thrown by `f`, or "no error".
template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

// "file:line:col" of the first occurrence of `marker` in `text` (1-based line and column).
std::string loc_of(const std::string& file, const std::string& text, const std::string& marker) {
    size_t pos = text.find(marker);
    EXPECT_NE(pos, std::string::npos) << marker;
    size_t line_start = text.rfind('\n', pos);
    line_start = line_start == std::string::npos ? 0 : line_start + 1;
    int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + pos, '\n'));
    return file + ":" + std::to_string(line) + ":" + std::to_string(pos - line_start + 1);
}

struct SpecTerminal {
    const char* type;
    uint32_t product;
};

// Spec §7 terminal table (vendor 0x2).
const std::vector<SpecTerminal> kSpecTable = {
    {"EK1100", 0x044C2C52}, {"EL1008", 0x03F03052}, {"EL1252", 0x04E43052}, {"EL2008", 0x07D83052},
    {"EL2808", 0x0AF83052}, {"EL2252", 0x08CC3052}, {"EL3102", 0x0C1E3052}, {"EL3104", 0x0C203052},
    {"EL3702", 0x0E763052}, {"EL4102", 0x10063052}, {"EL4134", 0x10263052}, {"EL4732", 0x127C3052},
    {"EL5042", 0x13B23052}, {"EL5101", 0x13ED3052}, {"EL7041", 0x1B813052}, {"EL7211", 0x1C2B3052},
    {"EL6692", 0x1A243052},
};

const Catalog& builtin() {
    return Catalog::builtin();
}

const DeviceDesc& device(const char* type) {
    const DeviceDesc* d = builtin().find(type);
    if (!d) throw Error(std::string("catalog has no ") + type);
    return *d;
}

std::vector<const PdoEntry*> entries_of(const std::vector<Pdo>& pdos) {
    std::vector<const PdoEntry*> out;
    for (const Pdo& p : pdos)
        for (const PdoEntry& e : p.entries) out.push_back(&e);
    return out;
}

const PdoEntry* entry_named(const DeviceDesc& d, const std::string& name) {
    for (const auto* list : {&d.rx_pdos, &d.tx_pdos})
        for (const Pdo& p : *list)
            for (const PdoEntry& e : p.entries)
                if (e.name == name) return &e;
    return nullptr;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// DeviceDesc helpers

TEST(DeviceDesc, SmBytesSumsBitsOfAssignedPdosThenRoundsUp) {
    DeviceDesc d;
    d.tx_pdos = {{0x1A00, "a", {{0x6000, 1, 3, "x01", "BIT3"}}},
                 {0x1A01, "b", {{0x6010, 1, 1, "x02", "BOOL"}, {0, 0, 5, "", ""}}},
                 {0x1A02, "c", {{0x6020, 1, 1, "x03", "BOOL"}}},
                 {0x1A03, "d", {{0x6030, 1, 16, "x04", "UINT16"}}}};
    d.rx_pdos = {{0x1600, "o", {{0x7000, 1, 1, "y01", "BOOL"}}}};
    d.pdo_assign = {{0, 0x1A00}, {0, 0x1A01}, {0, 0x1A02}, {1, 0x1600}, {2, 0x1FFF}};
    EXPECT_EQ(d.tx_pdos[1].bit_size(), 6u);
    EXPECT_EQ(d.tx_pdos[3].bit_size(), 16u);
    EXPECT_EQ(d.sm_bytes(0), 2u); // 3 + 6 + 1 = 10 bits
    EXPECT_EQ(d.sm_bytes(1), 1u); // 1 bit
    EXPECT_EQ(d.sm_bytes(2), 0u); // unknown PDO
    EXPECT_EQ(d.sm_bytes(3), 0u); // nothing assigned; 0x1A03 is not in any SM
    d.pdo_assign.push_back({1, 0x1A02});
    EXPECT_EQ(d.sm_bytes(1), 1u); // 2 bits share one byte
    EXPECT_EQ(d.find_pdo(0x1600), &d.rx_pdos[0]);
    EXPECT_EQ(d.find_pdo(0x1A03), &d.tx_pdos[3]);
    EXPECT_EQ(d.find_pdo(0x1A04), nullptr);
}

// ---------------------------------------------------------------------------------------------
// The shipped catalog

TEST(CatalogFiles, EveryFileLoadsOnItsOwn) {
    std::string dir = Catalog::builtin_dir();
    std::set<std::string> types;
    int files = 0;
    for (const auto& entry : fs::directory_iterator(dir)) {
        if (entry.path().extension() != ".yaml") continue;
        ++files;
        Catalog c;
        ASSERT_NO_THROW(c.load_yaml(entry.path().string())) << entry.path();
        ASSERT_EQ(c.size(), 1u) << entry.path();
        std::string type = c.types().at(0);
        EXPECT_EQ(entry.path().stem().string(), type) << "one file per terminal, named by type";
        types.insert(type);
    }
    // the 17 terminals of the spec table, plus operating-mode variants (ecmccfg HW_DESC names) and
    // the EL6692's secondary side (the same product, another revision)
    EXPECT_EQ(files, 19);
    std::set<std::string> expected;
    for (const SpecTerminal& t : kSpecTable) expected.insert(t.type);
    expected.insert("EL7211-0010_CSP");
    expected.insert("EL6692-0002");
    EXPECT_EQ(types, expected);
}

TEST(CatalogFiles, BuiltinHasEveryTerminalOnce) {
    EXPECT_EQ(builtin().size(), kSpecTable.size() + 2); // + EL7211-0010_CSP (a variant), EL6692-0002
    EXPECT_EQ(builtin().types().size(), kSpecTable.size() + 2);
    for (const std::string& t : builtin().types())
        EXPECT_EQ(builtin().source(builtin().find(t)),
                  (fs::path(Catalog::builtin_dir()) / (t + ".yaml")).string());
}

TEST(CatalogFiles, IdentitiesMatchSpecTable) {
    for (const SpecTerminal& t : kSpecTable) {
        SCOPED_TRACE(t.type);
        const DeviceDesc& d = device(t.type);
        EXPECT_EQ(d.type, t.type);
        EXPECT_EQ(d.vendor, 0x2u);
        EXPECT_EQ(d.product, t.product);
        EXPECT_NE(d.revision, 0u);
        EXPECT_FALSE(d.name.empty());
        EXPECT_EQ(d.name.rfind(t.type, 0), 0u) << "name starts with the type: " << d.name;
        EXPECT_EQ(builtin().find(d.vendor, d.product, d.revision), &d);
        // (the EL6692's two sides share the product: the latest revision is its secondary side)
        EXPECT_EQ(builtin().find_latest(d.vendor, d.product), t.type == std::string("EL6692") ? &device("EL6692-0002") : &d);
        // Product code = model number << 16 | 0x3052 (EL) or 0x2C52 (EK).
        int model = std::stoi(std::string(t.type).substr(2));
        EXPECT_EQ(d.product >> 16, static_cast<uint32_t>(model));
        EXPECT_EQ(d.product & 0xFFFF, t.type[1] == 'K' ? 0x2C52u : 0x3052u);
    }
    EXPECT_EQ(builtin().find("EL9999"), nullptr);
    EXPECT_EQ(builtin().find(2, 0x1B813052, 0x12345678), nullptr);
}

TEST(CatalogFiles, El1008HasEightOneBitInputsInSm0) {
    const DeviceDesc& d = device("EL1008");
    EXPECT_FALSE(d.coe);
    ASSERT_EQ(d.sms.size(), 1u);
    EXPECT_EQ(d.sms[0].type, SmType::Inputs);
    EXPECT_EQ(d.sms[0].start, 0x1000);
    EXPECT_EQ(d.sms[0].control, 0x00);
    EXPECT_EQ(d.sms[0].default_size, 1);
    EXPECT_TRUE(d.rx_pdos.empty());
    ASSERT_EQ(d.tx_pdos.size(), 8u);
    for (int i = 0; i < 8; ++i) {
        const Pdo& p = d.tx_pdos[i];
        EXPECT_EQ(p.index, 0x1A00 + i);
        ASSERT_EQ(p.entries.size(), 1u);
        EXPECT_EQ(p.entries[0].index, 0x6000 + 0x10 * i);
        EXPECT_EQ(p.entries[0].sub, 1);
        EXPECT_EQ(p.entries[0].bits, 1);
        EXPECT_EQ(p.entries[0].datatype, "BOOL");
        char name[32];
        std::snprintf(name, sizeof name, "binaryInput%02d", i + 1);
        EXPECT_EQ(p.entries[0].name, name);
        EXPECT_EQ(p.bit_size(), 1u);
        EXPECT_EQ(d.find_pdo(p.index), &p);
    }
    ASSERT_EQ(d.pdo_assign.size(), 8u);
    for (const auto& [sm, pdo] : d.pdo_assign) EXPECT_EQ(sm, 0);
    EXPECT_EQ(d.sm_bytes(0), 1u);
    EXPECT_EQ(d.sm_bytes(1), 0u);
    EXPECT_EQ(d.find_pdo(0x1600), nullptr);
}

TEST(CatalogFiles, El2008OutputsAt0x0F00WithWatchdog) {
    for (const char* type : {"EL2008", "EL2808"}) {
        SCOPED_TRACE(type);
        const DeviceDesc& d = device(type);
        ASSERT_EQ(d.sms.size(), 1u);
        EXPECT_EQ(d.sms[0].type, SmType::Outputs);
        EXPECT_EQ(d.sms[0].start, 0x0F00);
        EXPECT_EQ(d.sms[0].control, 0x44);
        EXPECT_EQ(d.sm_bytes(0), 1u);
        ASSERT_EQ(d.rx_pdos.size(), 8u);
        EXPECT_EQ(d.rx_pdos[7].entries.at(0).name, "binaryOutput08");
        EXPECT_EQ(d.rx_pdos[7].entries.at(0).index, 0x7070);
    }
}

TEST(CatalogFiles, DrivePdoSizes) {
    const DeviceDesc& el7211 = device("EL7211");
    EXPECT_EQ(el7211.sm_bytes(2), 6u);  // control word 16 + target velocity 32
    EXPECT_EQ(el7211.sm_bytes(3), 10u); // position 32 + status word 16 + velocity 32
    EXPECT_EQ(el7211.find_pdo(0x1601)->bit_size(), 32u);
    EXPECT_EQ(el7211.find_pdo(0x1A00)->bit_size(), 32u);
    EXPECT_EQ(el7211.dc_assign_activate, 0x0700);
    EXPECT_EQ(entry_named(el7211, "positionActual01")->index, 0x6000);
    EXPECT_EQ(entry_named(el7211, "positionActual01")->sub, 0x11);
    EXPECT_EQ(entry_named(el7211, "driveStatus01")->index, 0x6010);
    EXPECT_EQ(entry_named(el7211, "driveControl01")->index, 0x7010);
    EXPECT_EQ(entry_named(el7211, "velocitySetpoint01")->sub, 0x06);
    EXPECT_EQ(entry_named(el7211, "velocitySetpoint01")->bits, 32);

    const DeviceDesc& el7041 = device("EL7041");
    EXPECT_EQ(el7041.sm_bytes(2), 8u);  // enc control 32 + STM control 16 + velocity 16
    EXPECT_EQ(el7041.sm_bytes(3), 12u); // enc status 48 + STM status 16 + info data 32
    EXPECT_EQ(el7041.sms[2].default_size, 8);
    EXPECT_EQ(el7041.sms[3].default_size, 12);
    EXPECT_EQ(entry_named(el7041, "velocitySetpoint01")->index, 0x7010);
    EXPECT_EQ(entry_named(el7041, "velocitySetpoint01")->sub, 0x21);
    EXPECT_EQ(entry_named(el7041, "velocitySetpoint01")->bits, 16);
    EXPECT_EQ(entry_named(el7041, "encoderValue01")->sub, 0x11);
    EXPECT_EQ(entry_named(el7041, "positionActual01")->index, 0x6000);
    EXPECT_EQ(entry_named(el7041, "driveStatus01")->index, 0x6010);
}

TEST(CatalogFiles, OtherProcessImages) {
    EXPECT_EQ(device("EL3104").sm_bytes(3), 16u);
    EXPECT_EQ(device("EL3102").sm_bytes(3), 8u);
    EXPECT_EQ(device("EL3104").sm_bytes(2), 0u);
    EXPECT_EQ(device("EL4134").sm_bytes(2), 8u);
    EXPECT_EQ(device("EL4102").sm_bytes(2), 4u);
    EXPECT_EQ(device("EL5042").sm_bytes(3), 20u);
    EXPECT_EQ(device("EL5101").sm_bytes(2), 3u);
    EXPECT_EQ(device("EL5101").sm_bytes(3), 5u);
    EXPECT_EQ(device("EL1252").sm_bytes(0), 1u);
    EXPECT_EQ(device("EL1252").sm_bytes(1), 34u); // latch registers 0x09AE-0x09CF
    EXPECT_EQ(device("EL2252").sm_bytes(0), 1u);
    EXPECT_EQ(device("EL2252").sm_bytes(1), 8u);
    EXPECT_EQ(device("EL2252").sm_bytes(2), 1u);
    EXPECT_EQ(device("EL3702").sm_bytes(0), 4u);
    EXPECT_EQ(device("EL4732").sm_bytes(1), 4u);
    EXPECT_EQ(device("EK1100").sm_bytes(0), 0u);
    EXPECT_TRUE(device("EK1100").sms.empty());
}

TEST(CatalogFiles, VirtualSmsPointAtDcRegisters) {
    EXPECT_EQ(device("EL1252").sms.at(1).start, 0x09AE);
    EXPECT_TRUE(device("EL1252").sms.at(1).is_virtual);
    EXPECT_EQ(device("EL2252").sms.at(0).start, 0x0981);
    EXPECT_EQ(device("EL2252").sms.at(1).start, 0x0990);
    EXPECT_EQ(device("EL4732").sms.at(2).start, 0x0998);
    EXPECT_TRUE(device("EL4732").sms.at(2).is_virtual);
    EXPECT_FALSE(device("EL4732").sms.at(0).is_virtual);
    EXPECT_EQ(device("EL3702").dc_assign_activate, 0x0730);
    EXPECT_EQ(device("EL4732").dc_assign_activate, 0x0730);
    EXPECT_EQ(device("EL2252").dc_assign_activate, 0x0300);
    EXPECT_EQ(device("EL5042").dc_assign_activate, 0x0300);
}

TEST(CatalogFiles, MailboxLayout) {
    for (const SpecTerminal& t : kSpecTable) {
        SCOPED_TRACE(t.type);
        const DeviceDesc& d = device(t.type);
        bool mbx = !d.sms.empty() && d.sms[0].type == SmType::MailboxOut;
        EXPECT_EQ(mbx, d.coe);
        if (!mbx) continue;
        ASSERT_GE(d.sms.size(), 4u);
        if (t.type == std::string("EL6692")) { // spec table: mbx 0x1000/0x1400, PDO 0x1800/0x1E00 (both sides)
            for (const DeviceDesc* side : {&d, &device("EL6692-0002")}) {
                EXPECT_EQ(side->sms[0].start, 0x1000);
                EXPECT_EQ(side->sms[0].default_size, 256);
                EXPECT_EQ(side->sms[1].start, 0x1400);
                EXPECT_EQ(side->sms[2].start, 0x1800);
                EXPECT_EQ(side->sms[3].start, 0x1e00);
                EXPECT_EQ(side->revision & 0xFFFF, side == &d ? 0x0000u : 0x0002u); // primary / secondary
            }
            continue;
        }
        EXPECT_EQ(d.sms[0].start, 0x1000);
        EXPECT_EQ(d.sms[0].control, 0x26);
        EXPECT_EQ(d.sms[0].default_size, 128);
        EXPECT_EQ(d.sms[1].type, SmType::MailboxIn);
        EXPECT_EQ(d.sms[1].start, 0x1080);
        EXPECT_EQ(d.sms[1].control, 0x22);
        EXPECT_EQ(d.sms[1].default_size, 128);
        EXPECT_EQ(d.sms[2].type, SmType::Outputs);
        EXPECT_EQ(d.sms[2].start, 0x1100);
        EXPECT_EQ(d.sms[2].control, d.sm_bytes(2) ? 0x64 : 0x24);
        EXPECT_EQ(d.sms[3].type, SmType::Inputs);
        EXPECT_EQ(d.sms[3].start, 0x1180);
        EXPECT_EQ(d.sms[3].control, 0x20);
    }
}

TEST(CatalogFiles, EntriesAreConsistentAndNamedLikeEcmc) {
    const std::regex ecmc_name("[a-z][A-Za-z0-9]*[0-9](_[0-9]+)?|nextSyncTime|activate|startTime");
    for (const SpecTerminal& t : kSpecTable) {
        SCOPED_TRACE(t.type);
        const DeviceDesc& d = device(t.type);
        std::map<std::string, const PdoEntry*> names; // one name, one object (alternative PDOs share objects)
        for (const auto* list : {&d.rx_pdos, &d.tx_pdos})
            for (const PdoEntry* e : entries_of(*list)) {
                if (e->index == 0) {
                    EXPECT_TRUE(e->name.empty());
                    continue;
                }
                EXPECT_TRUE(std::regex_match(e->name, ecmc_name)) << e->name;
                auto [it, fresh] = names.emplace(e->name, e);
                EXPECT_TRUE(fresh || (it->second->index == e->index && it->second->sub == e->sub && it->second->bits == e->bits))
                    << "duplicate " << e->name;
                EXPECT_EQ(coe_datatype_bits(e->datatype), e->bits) << e->name;
            }
        for (const Pdo& p : d.rx_pdos) EXPECT_TRUE(p.index >= 0x1600 && p.index <= 0x17FF);
        for (const Pdo& p : d.tx_pdos) EXPECT_TRUE(p.index >= 0x1A00 && p.index <= 0x1BFF);
        // Every assignment refers to an SM of the right direction.
        for (const auto& [sm, idx] : d.pdo_assign) {
            ASSERT_LT(sm, d.sms.size());
            bool rx = idx < 0x1A00;
            EXPECT_EQ(d.sms[sm].type, rx ? SmType::Outputs : SmType::Inputs);
        }
    }
}

TEST(CatalogFiles, EcmcNamesOfAnalogAndEncoderTerminals) {
    EXPECT_EQ(entry_named(device("EL3104"), "analogInput04")->index, 0x6030);
    EXPECT_EQ(entry_named(device("EL3104"), "status01")->sub, 0x01);
    EXPECT_EQ(entry_named(device("EL4134"), "analogOutput03")->index, 0x7020);
    EXPECT_EQ(entry_named(device("EL5042"), "positionActual02")->bits, 64);
    EXPECT_EQ(entry_named(device("EL5101"), "encoderLatchPostion01")->sub, 3);
    EXPECT_EQ(entry_named(device("EL3702"), "analogInputArray02_1")->sub, 2);
    EXPECT_EQ(entry_named(device("EL4732"), "cycleCounter01")->index, 0x7800);
    EXPECT_EQ(entry_named(device("EL1252"), "timestampLatchNegative02")->sub, 0xC8);
    EXPECT_EQ(entry_named(device("EL2252"), "triState02")->index, 0x7010);
}

// ---------------------------------------------------------------------------------------------
// YAML loading and errors

namespace {

const std::string kGoodYaml = R"(type: XT0001
name: "XT0001 test terminal"
vendor: 2
product: 0x00013052
revision: 0x00100000
sync_managers:
  - {index: 0, start: 0x1000, control: 0x00, type: Inputs}
tx_pdos:
  - index: 0x1a00
    name: Channel 1
    sm: 0
    entries:
      - {index: 0x6000, sub: 1, bits: 1, name: binaryInput01, datatype: BOOL}
      - {index: 0, bits: 7}
)";

std::string replaced(std::string text, const std::string& from, const std::string& to) {
    size_t pos = text.find(from);
    EXPECT_NE(pos, std::string::npos) << from;
    return text.replace(pos, from.size(), to);
}

} // namespace

TEST(CatalogYaml, MinimalDeviceLoads) {
    TempDir dir;
    Catalog c;
    c.load_yaml(dir.write("XT0001.yaml", kGoodYaml));
    const DeviceDesc* d = c.find("XT0001");
    ASSERT_NE(d, nullptr);
    EXPECT_EQ(d->product, 0x00013052u);
    EXPECT_EQ(d->revision, 0x00100000u);
    EXPECT_FALSE(d->coe);
    EXPECT_EQ(d->sms.at(0).default_size, 1); // computed from the PDOs
    EXPECT_TRUE(d->sms.at(0).enable);
    EXPECT_EQ(d->tx_pdos.at(0).entries.at(1).index, 0);
    EXPECT_EQ(d->tx_pdos.at(0).bit_size(), 8u);

    // A process-data SM is sized from its PDOs, rounded up to whole bytes.
    Catalog c9;
    c9.load_yaml(dir.write("nine.yaml", replaced(kGoodYaml, "bits: 7}", "bits: 8}")));
    EXPECT_EQ(c9.find("XT0001")->sms.at(0).default_size, 2);
}

TEST(CatalogYaml, ErrorsNameFileLineColumnKeyAndProblem) {
    TempDir dir;
    struct Case {
        std::string from, to; // edit of kGoodYaml
        std::string marker;   // where the error points in the edited text
        std::string message;  // after "file:line:col: "
    };
    const std::vector<Case> cases = {
        {"sub: 1, bits: 1, name: binaryInput01, datatype: BOOL",
         "sub: 1, bits: 1, name: binaryInput01, datatyp: BOOL", "datatyp",
         "unknown key 'datatyp' in tx_pdos[0].entries[0] (did you mean 'datatype'?)"},
        {"name: \"XT0001", "nmae: \"XT0001", "nmae",
         "unknown key 'nmae' in the device (did you mean 'name'?)"},
        {"bits: 1, name", "bits: 2, name", "2, name",
         "tx_pdos[0].entries[0].bits: 2 should be 1 for datatype BOOL"},
        {"product: 0x00013052", "product: 0x0001G052", "0x0001G052",
         "product should be an unsigned integer, got '0x0001G052'"},
        {"vendor: 2", "vendor: 0x100000000", "0x100000000",
         "vendor should be from 0 to 4294967295, got 0x100000000"},
        {"    sm: 0", "    sm: 1", "1\n    entries", "tx_pdos[0].sm: SM1 does not exist"},
        {"type: Inputs}", "type: Input}", "Input}",
         "sync_managers[0].type: 'Input' should be one of"},
        {"control: 0x00, type", "size: 2, control: 0x00, type", "2, control",
         "sync_managers[0].size: 2 should be 1 (bytes of the PDOs assigned to SM0)"},
        {"index: 0x1a00", "index: 0x1600", "0x1600",
         "tx_pdos[0].index: 0x1600 should be in 0x1A00-0x1BFF (TxPDO, inputs)"},
        {"datatype: BOOL", "datatype: BOOLEAN", "BOOLEAN",
         "tx_pdos[0].entries[0].datatype: unknown datatype 'BOOLEAN'"},
        {"{index: 0, bits: 7}", "{index: 0, bits: 7, name: gap}", "gap",
         "tx_pdos[0].entries[1].name: padding (index 0) has no name"},
        {"index: 0, start", "index: 1, start", "1, start", "sync_managers[0].index: 1 should be 0"},
        {"revision: 0x00100000\n", "", "type", "the device: missing required key 'revision'"},
        {"vendor: 2\n", "vendor: 2\ncoe: true\n", "true", "coe: true needs an MBoxOut"},
        {"    entries:\n      - {index: 0x6000, sub: 1, bits: 1, name: binaryInput01, datatype: "
         "BOOL}\n      - {index: 0, bits: 7}\n",
         "    entries: 3\n", "3\n", "tx_pdos[0].entries should be a list, got a single value"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.to);
        std::string text = replaced(kGoodYaml, c.from, c.to);
        std::string file = dir.write("bad.yaml", text);
        Catalog cat;
        std::string err = error_of([&] { cat.load_yaml(file); });
        std::string expected = loc_of(file, text, c.marker) + ": " + c.message;
        EXPECT_EQ(err.substr(0, expected.size()), expected) << err;
        EXPECT_EQ(cat.size(), 0u) << "a bad file changes nothing";
    }
}

TEST(CatalogYaml, DuplicateEntryNameAndDuplicatePdo) {
    TempDir dir;
    std::string text = replaced(kGoodYaml, "{index: 0, bits: 7}",
                                "{index: 0x6000, sub: 2, bits: 1, name: binaryInput01, "
                                "datatype: BOOL}\n      - {index: 0, bits: 6}");
    std::string file = dir.write("dup.yaml", text);
    std::string err = error_of([&] { Catalog().load_yaml(file); });
    EXPECT_NE(err.find("tx_pdos[0].entries[1].name: 'binaryInput01' is already used by "
                       "tx_pdos[0].entries[0]"),
              std::string::npos)
        << err;
    EXPECT_EQ(err.rfind(file + ":14:", 0), 0u) << err;
}

TEST(CatalogYaml, SyntaxErrorHasLocation) {
    TempDir dir;
    std::string file = dir.write("syntax.yaml", "type: X\nsync_managers:\n  - {index: 0, start\n");
    std::string err = error_of([&] { Catalog().load_yaml(file); });
    EXPECT_TRUE(
        std::regex_search(err, std::regex("^" + file + ":[0-9]+:[0-9]+: YAML syntax error")))
        << err;
}

TEST(CatalogYaml, EmptyAndMissingFiles) {
    TempDir dir;
    std::string empty = dir.write("empty.yaml", "# nothing\n");
    EXPECT_EQ(error_of([&] { Catalog().load_yaml(empty); }),
              empty + ":1:1: empty file, expected a device");
    std::string missing = dir.path() + "/nope.yaml";
    EXPECT_EQ(error_of([&] { Catalog().load_yaml(missing); }),
              missing + ": cannot open: No such file or directory");
}

TEST(CatalogYaml, SameIdentityTwiceIsAnError) {
    TempDir dir;
    Catalog c;
    std::string a = dir.write("a.yaml", kGoodYaml);
    std::string b = dir.write("b.yaml", kGoodYaml);
    c.load_yaml(a);
    std::string err = error_of([&] { c.load_yaml(b); });
    EXPECT_EQ(err.rfind(b + ":1:1: XT0001", 0), 0u) << err;
    EXPECT_NE(err.find("already defined in " + a), std::string::npos) << err;
    EXPECT_EQ(c.size(), 1u);
}

TEST(CatalogYaml, FindByTypeReturnsHighestRevision) {
    TempDir dir;
    Catalog c;
    c.load_yaml(dir.write("r1.yaml", kGoodYaml));
    c.load_yaml(dir.write("r3.yaml", replaced(kGoodYaml, "0x00100000", "0x00120000")));
    c.load_yaml(dir.write("r2.yaml", replaced(kGoodYaml, "0x00100000", "0x00110000")));
    ASSERT_NE(c.find("XT0001"), nullptr);
    EXPECT_EQ(c.find("XT0001")->revision, 0x00120000u);
    EXPECT_EQ(c.find_latest(2, 0x00013052)->revision, 0x00120000u);
    EXPECT_EQ(c.find(2, 0x00013052, 0x00110000)->revision, 0x00110000u);
    EXPECT_EQ(c.types(), std::vector<std::string>{"XT0001"});
    EXPECT_EQ(c.size(), 3u);
}

// ---------------------------------------------------------------------------------------------
// ESI

namespace {

const std::string kEsi = R"(<?xml version="1.0" encoding="UTF-8"?>
<EtherCATInfo Version="1.6">
  <Vendor>
    <Id>#x00000002</Id>
    <Name>Beckhoff Automation GmbH &amp; Co. KG</Name>
  </Vendor>
  <Descriptions>
    <Groups><Group><Type>DigIn</Type><Name LcId="1033">Digital Inputs</Name></Group></Groups>
    <Devices>
      <Device Physics="YY">
        <Type ProductCode="#x03f03052" RevisionNo="#x00130000">EL1008</Type>
        <Name LcId="1031">EL1008 8K. Dig. Eingang 24V, 3ms</Name>
        <Name LcId="1033">EL1008 8Ch. Dig. Input 24V, 3ms</Name>
        <Fmmu>Inputs</Fmmu>
        <Sm StartAddress="#x1000" ControlByte="#x00" DefaultSize="1" Enable="1">Inputs</Sm>
        <TxPdo Sm="0" Fixed="1" Mandatory="1">
          <Index>#x1a00</Index>
          <Name>Channel 1</Name>
          <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Input</Name><DataType>BOOL</DataType></Entry>
        </TxPdo>
        <TxPdo Sm="0" Fixed="1" Mandatory="1">
          <Index>#x1a01</Index>
          <Name>Channel 2</Name>
          <Entry><Index>#x6010</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Input</Name><DataType>BOOL</DataType></Entry>
          <Entry><Index>0</Index><BitLen>6</BitLen></Entry>
        </TxPdo>
      </Device>
      <Device Physics="YY">
        <Type ProductCode="#x12343052" RevisionNo="#x00010000">XD1234</Type>
        <Name>XD1234 test drive</Name>
        <Sm StartAddress="#x1000" ControlByte="#x26" DefaultSize="128" Enable="1">MBoxOut</Sm>
        <Sm StartAddress="#x1080" ControlByte="#x22" DefaultSize="128" Enable="1">MBoxIn</Sm>
        <Sm StartAddress="#x1100" ControlByte="#x64" DefaultSize="6" Enable="1">Outputs</Sm>
        <Sm StartAddress="#x1180" ControlByte="#x20" DefaultSize="4" Enable="1">Inputs</Sm>
        <Sm StartAddress="#x0998" ControlByte="#x00" Enable="4" Virtual="true">Inputs</Sm>
        <RxPdo Sm="2" Fixed="1">
          <Index>#x1600</Index>
          <Name>DRV Controlword</Name>
          <Entry><Index>#x7010</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><Name>Controlword</Name><DataType>UINT</DataType></Entry>
          <Entry><Index>#x7010</Index><SubIndex>#x06</SubIndex><BitLen>32</BitLen><Name>Target velocity</Name><DataType>DINT</DataType></Entry>
        </RxPdo>
        <RxPdo>
          <Index>#x1601</Index>
          <Name>DRV Target position</Name>
          <Entry><Index>#x7010</Index><SubIndex>5</SubIndex><BitLen>32</BitLen><Name>Target position</Name><DataType>UDINT</DataType></Entry>
        </RxPdo>
        <TxPdo Sm="3">
          <Index>#x1a00</Index>
          <Name>FB Position</Name>
          <Entry><Index>#x6000</Index><SubIndex>#x11</SubIndex><BitLen>32</BitLen><Name>Position</Name><DataType>UDINT</DataType></Entry>
        </TxPdo>
        <Mailbox DataLinkLayer="true"><CoE SdoInfo="true" PdoAssign="true"/></Mailbox>
        <Dc>
          <OpMode><Name>FreeRun</Name><AssignActivate>#x0000</AssignActivate></OpMode>
          <OpMode><Name>DcSync</Name><AssignActivate>#x0700</AssignActivate></OpMode>
        </Dc>
        <Electrical><EBusCurrent>120</EBusCurrent></Electrical>
      </Device>
    </Devices>
  </Descriptions>
</EtherCATInfo>
)";

} // namespace

TEST(CatalogEsi, LoadsDevicesSmsPdosAndDc) {
    TempDir dir;
    Catalog c;
    c.load_esi(dir.write("Test.xml", kEsi));
    EXPECT_EQ(c.size(), 2u);

    const DeviceDesc* el1008 = c.find("EL1008");
    ASSERT_NE(el1008, nullptr);
    EXPECT_EQ(el1008->vendor, 2u);
    EXPECT_EQ(el1008->product, 0x03F03052u);
    EXPECT_EQ(el1008->revision, 0x00130000u);
    EXPECT_EQ(el1008->name, "EL1008 8Ch. Dig. Input 24V, 3ms");
    ASSERT_EQ(el1008->tx_pdos.size(), 2u);
    EXPECT_EQ(el1008->tx_pdos[0].entries.at(0).name, "Channel1_Input");
    EXPECT_EQ(el1008->tx_pdos[1].entries.at(0).name, "Channel2_Input");
    EXPECT_EQ(el1008->tx_pdos[1].entries.at(1).index, 0);
    EXPECT_EQ(el1008->tx_pdos[1].entries.at(1).bits, 6);
    EXPECT_EQ(el1008->tx_pdos[1].entries.at(1).name, "");
    EXPECT_EQ(el1008->sm_bytes(0), 1u);
    EXPECT_FALSE(el1008->coe);

    const DeviceDesc* xd = c.find(2, 0x12343052, 0x00010000);
    ASSERT_NE(xd, nullptr);
    EXPECT_EQ(xd->type, "XD1234");
    EXPECT_TRUE(xd->coe);
    EXPECT_EQ(xd->dc_assign_activate, 0x0700);
    EXPECT_EQ(xd->ebus_current_ma, 120);
    ASSERT_EQ(xd->sms.size(), 5u);
    EXPECT_EQ(xd->sms[0].type, SmType::MailboxOut);
    EXPECT_EQ(xd->sms[0].default_size, 128);
    EXPECT_EQ(xd->sms[2].control, 0x64);
    EXPECT_TRUE(xd->sms[4].is_virtual);
    EXPECT_FALSE(xd->sms[4].enable);
    EXPECT_EQ(xd->sms[4].start, 0x0998);
    const PdoEntry& vel = xd->find_pdo(0x1600)->entries.at(1);
    EXPECT_EQ(vel.name, "DRVControlword_Targetvelocity");
    EXPECT_EQ(vel.sub, 6);
    EXPECT_EQ(vel.datatype, "INT32");
    EXPECT_EQ(xd->find_pdo(0x1600)->entries.at(0).datatype, "UINT16");
    EXPECT_EQ(xd->find_pdo(0x1A00)->entries.at(0).sub, 0x11);
    using Assign = std::vector<std::pair<uint8_t, uint16_t>>;
    EXPECT_EQ(xd->pdo_assign, (Assign{{2, 0x1600}, {3, 0x1A00}})); // 0x1601 not assigned
    EXPECT_NE(xd->find_pdo(0x1601), nullptr);
    EXPECT_EQ(xd->sm_bytes(2), 6u);
    EXPECT_EQ(xd->sm_bytes(3), 4u);
}

TEST(CatalogEsi, TakesEcmcNamesFromOurCatalog) {
    TempDir dir;
    Catalog c;
    c.load_dir(Catalog::builtin_dir());
    const DeviceDesc* yaml_el1008 = c.find("EL1008");
    ASSERT_NE(yaml_el1008, nullptr);
    const uint32_t yaml_rev = yaml_el1008->revision;

    // A newer revision from ESI: its entries get the ecmc names of the same index:sub.
    c.load_esi(dir.write("Test.xml", kEsi));
    const DeviceDesc* esi_el1008 = c.find("EL1008");
    ASSERT_NE(esi_el1008, nullptr);
    EXPECT_EQ(esi_el1008->revision, 0x00130000u);
    EXPECT_EQ(esi_el1008->tx_pdos[0].entries[0].name, "binaryInput01");
    EXPECT_EQ(esi_el1008->tx_pdos[1].entries[0].name, "binaryInput02");
    EXPECT_EQ(c.find(2, 0x03F03052, yaml_rev), yaml_el1008);

    // Same identity as a YAML device: the ESI replaces it in place, names kept.
    char rev[32];
    std::snprintf(rev, sizeof rev, "RevisionNo=\"#x%08X\"", yaml_rev);
    std::string esi = replaced(kEsi, "RevisionNo=\"#x00130000\"", rev);
    size_t before = c.size();
    std::string file = dir.write("Same.xml", esi);
    c.load_esi(file);
    EXPECT_EQ(c.size(), before);
    const DeviceDesc* replaced_dev = c.find(2, 0x03F03052, yaml_rev);
    EXPECT_EQ(replaced_dev, yaml_el1008) << "pointer stays valid";
    EXPECT_EQ(c.source(replaced_dev), file);
    EXPECT_EQ(replaced_dev->tx_pdos.size(), 2u);
    EXPECT_EQ(replaced_dev->tx_pdos[1].entries[0].name, "binaryInput02");
}

TEST(CatalogEsi, LoadDirReadsYamlAndXml) {
    TempDir dir;
    dir.write("XT0001.yaml", kGoodYaml);
    dir.write("Beckhoff Test.XML", kEsi);
    dir.write("README.txt", "not a device");
    Catalog c;
    c.load_dir(dir.path());
    EXPECT_EQ(c.types(), (std::vector<std::string>{"EL1008", "XD1234", "XT0001"}));
    EXPECT_EQ(error_of([&] { c.load_dir(dir.path() + "/missing"); }),
              dir.path() + "/missing: not a directory");
}

TEST(CatalogEsi, ErrorsHaveLocation) {
    TempDir dir;
    std::string text = replaced(kEsi, "ProductCode=\"#x12343052\"", "ProductCode=\"#x1234Z052\"");
    std::string file = dir.write("bad.xml", text);
    Catalog c;
    std::string err = error_of([&] { c.load_esi(file); });
    std::string type_loc = loc_of(file, text, "<Type ProductCode=\"#x1234Z");
    EXPECT_EQ(err, type_loc + ": Type: ProductCode '#x1234Z052' is not a number");
    EXPECT_EQ(c.size(), 0u);

    text = replaced(kEsi, "<RxPdo Sm=\"2\" Fixed=\"1\">", "<RxPdo Sm=\"7\" Fixed=\"1\">");
    file = dir.write("badsm.xml", text);
    err = error_of([&] { Catalog().load_esi(file); });
    EXPECT_EQ(err, loc_of(file, text, "<RxPdo Sm=\"7\"") +
                       ": RxPdo: PDO 0x1600 is assigned to SM7 but the device has 5 <Sm> elements");

    file = dir.write("syntax.xml", "<EtherCATInfo>\n  <Vendor>\n</EtherCATInfo>\n");
    err = error_of([&] { Catalog().load_esi(file); });
    EXPECT_TRUE(std::regex_search(err, std::regex("^" + file + ":[0-9]+:1: XML error"))) << err;

    file = dir.write("root.xml", "<?xml version=\"1.0\"?>\n<Foo/>\n");
    err = error_of([&] { Catalog().load_esi(file); });
    EXPECT_EQ(err, file + ":2:1: root element should be <EtherCATInfo>, got <Foo>");
}

TEST(CatalogBuiltin, FindsTheSourceCatalog) {
    std::string dir = Catalog::builtin_dir();
    EXPECT_TRUE(fs::exists(fs::path(dir) / "EL7041.yaml")) << dir;
    EXPECT_NE(Catalog::builtin().find("EL7041"), nullptr);
    EXPECT_EQ(&Catalog::builtin(), &Catalog::builtin());

    // The environment variable wins, and a wrong one is reported rather than ignored.
    const char* old_env = std::getenv("BEAMCTL_CATALOG");
    const std::string saved = old_env ? old_env : "";
    TempDir tmp;
    setenv("BEAMCTL_CATALOG", tmp.path().c_str(), 1);
    EXPECT_EQ(Catalog::builtin_dir(), tmp.path());
    setenv("BEAMCTL_CATALOG", (tmp.path() + "/none").c_str(), 1);
    EXPECT_EQ(error_of([] { Catalog::builtin_dir(); }),
              "BEAMCTL_CATALOG=" + tmp.path() + "/none is not a directory");
    if (old_env)
        setenv("BEAMCTL_CATALOG", saved.c_str(), 1);
    else
        unsetenv("BEAMCTL_CATALOG");
}

TEST(CatalogFiles, OperatingModeVariantSharesTheIdentity) {
    const DeviceDesc* csp = builtin().find("EL7211-0010_CSP");
    const DeviceDesc* base = builtin().find("EL7211");
    ASSERT_TRUE(csp && base);
    EXPECT_EQ(csp->variant_of, "EL7211");
    EXPECT_EQ(csp->product, base->product);
    EXPECT_EQ(csp->revision, base->revision);
    // lookups by identity give the base description
    EXPECT_EQ(builtin().find(base->vendor, base->product, base->revision), base);
    EXPECT_EQ(builtin().find_latest(base->vendor, base->product), base);
}
