// Unit tests of the ESI import (ethercat/esi.hpp, ethercat/esi_import.hpp): the ESI files in
// tests/fixtures/esi describe the catalog's terminals and must import to the hand-written
// catalog entries field by field; the emitted YAML loads back to the same description; the
// schema's edge cases give errors at file:line:col and write nothing; `beamctl esi import`'s
// rules for file names, overwriting and exit status.
#include "ethercat/esi_import.hpp"

#include "../temp_dir.hpp"
#include "core/error.hpp"
#include "core/error_list.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/esi.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using beamctl::Error;
using beamctl::test::TempDir;
using namespace beamctl::ethercat;

namespace {

const fs::path kSource = BEAMCTL_SOURCE_DIR;
const fs::path kFixtures = kSource / "tests" / "fixtures" / "esi";
const fs::path kCatalog = kSource / "catalog";

template <typename F> std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "no error";
}

std::string replaced(std::string s, const std::string& from, const std::string& to) {
    size_t pos = s.find(from);
    EXPECT_NE(pos, std::string::npos) << from;
    if (pos != std::string::npos) s.replace(pos, from.size(), to);
    return s;
}

std::string read_text(const std::string& path) {
    std::ifstream in(path);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

// "file:line:col" of the first occurrence of `marker` in `text`.
std::string loc_of(const std::string& file, const std::string& text, const std::string& marker) {
    size_t pos = text.find(marker);
    EXPECT_NE(pos, std::string::npos) << marker;
    size_t line_start = text.rfind('\n', pos);
    line_start = line_start == std::string::npos ? 0 : line_start + 1;
    int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + pos, '\n'));
    return file + ":" + std::to_string(line) + ":" + std::to_string(pos - line_start + 1);
}

std::string hex(uint32_t v) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%X", v);
    return buf;
}

// Every field that differs between two descriptions, one line each ("" when equal): the
// field-by-field comparison, with messages that say where.
std::string differences(const DeviceDesc& a, const DeviceDesc& b) {
    std::ostringstream d;
    auto field = [&](const std::string& what, const auto& x, const auto& y) {
        if (!(x == y)) d << what << ": " << x << " vs " << y << "\n";
    };
    field("type", a.type, b.type);
    field("variant_of", a.variant_of, b.variant_of);
    field("name", a.name, b.name);
    field("vendor", hex(a.vendor), hex(b.vendor));
    field("product", hex(a.product), hex(b.product));
    field("revision", hex(a.revision), hex(b.revision));
    field("coe", a.coe, b.coe);
    field("dc_assign_activate", hex(a.dc_assign_activate), hex(b.dc_assign_activate));
    field("ebus_current_ma", a.ebus_current_ma, b.ebus_current_ma);
    field("sms.size", a.sms.size(), b.sms.size());
    for (size_t i = 0; i < std::min(a.sms.size(), b.sms.size()); ++i) {
        const std::string at = "sms[" + std::to_string(i) + "].";
        field(at + "index", unsigned(a.sms[i].index), unsigned(b.sms[i].index));
        field(at + "start", hex(a.sms[i].start), hex(b.sms[i].start));
        field(at + "size", a.sms[i].default_size, b.sms[i].default_size);
        field(at + "control", hex(a.sms[i].control), hex(b.sms[i].control));
        field(at + "enable", a.sms[i].enable, b.sms[i].enable);
        field(at + "type", sm_type_name(a.sms[i].type), sm_type_name(b.sms[i].type));
        field(at + "virtual", a.sms[i].is_virtual, b.sms[i].is_virtual);
    }
    for (bool rx : {true, false}) {
        const auto& pa = rx ? a.rx_pdos : a.tx_pdos;
        const auto& pb = rx ? b.rx_pdos : b.tx_pdos;
        const std::string list = rx ? "rx_pdos" : "tx_pdos";
        field(list + ".size", pa.size(), pb.size());
        for (size_t i = 0; i < std::min(pa.size(), pb.size()); ++i) {
            const std::string at = list + "[" + std::to_string(i) + "].";
            field(at + "index", hex(pa[i].index), hex(pb[i].index));
            field(at + "name", pa[i].name, pb[i].name);
            field(at + "entries.size", pa[i].entries.size(), pb[i].entries.size());
            for (size_t k = 0; k < std::min(pa[i].entries.size(), pb[i].entries.size()); ++k) {
                const PdoEntry& x = pa[i].entries[k];
                const PdoEntry& y = pb[i].entries[k];
                const std::string e = at + "entries[" + std::to_string(k) + "].";
                field(e + "index", hex(x.index), hex(y.index));
                field(e + "sub", hex(x.sub), hex(y.sub));
                field(e + "bits", unsigned(x.bits), unsigned(y.bits));
                field(e + "name", x.name, y.name);
                field(e + "datatype", x.datatype, y.datatype);
            }
        }
    }
    field("pdo_assign.size", a.pdo_assign.size(), b.pdo_assign.size());
    for (size_t i = 0; i < std::min(a.pdo_assign.size(), b.pdo_assign.size()); ++i) {
        const std::string at = "pdo_assign[" + std::to_string(i) + "]";
        field(at + ".sm", unsigned(a.pdo_assign[i].first), unsigned(b.pdo_assign[i].first));
        field(at + ".pdo", hex(a.pdo_assign[i].second), hex(b.pdo_assign[i].second));
    }
    field("oversampling.max", a.oversampling.max, b.oversampling.max);
    field("oversampling.channels.size", a.oversampling.channels.size(),
          b.oversampling.channels.size());
    for (size_t i = 0; i < std::min(a.oversampling.channels.size(), b.oversampling.channels.size());
         ++i) {
        const std::string at = "oversampling.channels[" + std::to_string(i) + "].";
        field(at + "pdo", hex(a.oversampling.channels[i].pdo), hex(b.oversampling.channels[i].pdo));
        field(at + "memmap", a.oversampling.channels[i].memmap, b.oversampling.channels[i].memmap);
    }
    // a field added to DeviceDesc later and missed above still fails here
    if (d.str().empty() && !(a == b))
        d << "descriptions differ in a field this test does not list\n";
    return d.str();
}

std::vector<fs::path> fixtures() {
    std::vector<fs::path> out;
    for (const auto& e : fs::directory_iterator(kFixtures))
        if (e.path().extension() == ".xml") out.push_back(e.path());
    std::sort(out.begin(), out.end());
    return out;
}

// The hand-written catalog entry of a type, loaded on its own (no ESI, no other files).
DeviceDesc hand_written(const std::string& type) {
    Catalog c;
    c.load_yaml((kCatalog / (type + ".yaml")).string());
    return *c.find(type);
}

// The one device of an ESI file, as the import reads it (no catalog to take names from).
EsiDevice imported(const fs::path& file) {
    std::vector<EsiDevice> devs = read_esi(file.string());
    EXPECT_EQ(devs.size(), 1u) << file;
    return devs.at(0);
}

// A small valid ESI file for the edge cases: XD0001 with an output and an input PDO.
const std::string kTemplate = R"(<?xml version="1.0"?>
<EtherCATInfo Version="1.6">
  <Vendor><Id>#x00000002</Id><Name>Test</Name></Vendor>
  <Descriptions>
    <Devices>
      <Device>
        <Type ProductCode="#x00013052" RevisionNo="#x00100000">XD0001</Type>
        <Name>XD0001 test device</Name>
        <Sm StartAddress="#x0f00" ControlByte="#x44" Enable="1">Outputs</Sm>
        <Sm StartAddress="#x1000" ControlByte="#x00" Enable="1">Inputs</Sm>
        <RxPdo Sm="0" Fixed="1" Mandatory="1">
          <Index>#x1600</Index>
          <Name>Out</Name>
          <Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><Name>out1</Name><DataType>UINT</DataType></Entry>
        </RxPdo>
        <TxPdo Sm="1">
          <Index>#x1a00</Index>
          <Name>In</Name>
          <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>8</BitLen><Name>in1</Name><DataType>USINT</DataType></Entry>
        </TxPdo>
      </Device>
    </Devices>
  </Descriptions>
</EtherCATInfo>
)";

// A second device for the same file, inserted before </Devices>.
const std::string kSecondDevice = R"(      <Device>
        <Type ProductCode="#x00023052" RevisionNo="#x00110000">XD0002</Type>
        <Name>XD0002</Name>
      </Device>
)";

} // namespace

// ---------------------------------------------------------------------------------------------
// The catalog's terminals from ESI

TEST(EsiImportFixtures, EveryHandWrittenTerminalHasAFixture) {
    std::set<std::string> have;
    for (const fs::path& f : fixtures()) have.insert(f.stem().string());
    // at least these, and every base description (operating-mode variants are not ESI devices)
    for (const char* t :
         {"EK1100", "EL1008", "EL2008", "EL3102", "EL3702", "EL4732", "EL5101", "EL7041", "EL7211"})
        EXPECT_TRUE(have.count(t)) << t;
    Catalog all;
    all.load_dir(kCatalog.string());
    // (not the EL6692's sides: their user PDOs are declared by the user, the ESI has no entries)
    for (const std::string& t : all.types())
        if (all.find(t)->variant_of.empty() && t.rfind("EL6692", 0) != 0) {
            EXPECT_TRUE(have.count(t)) << "no ESI fixture for " << t;
        }
}

TEST(EsiImportFixtures, ImportMatchesTheHandWrittenEntryFieldByField) {
    ASSERT_GE(fixtures().size(), 9u);
    for (const fs::path& f : fixtures()) {
        SCOPED_TRACE(f.string());
        const EsiDevice dev = imported(f);
        EXPECT_EQ(dev.desc.type, f.stem().string());
        EXPECT_EQ(differences(dev.desc, hand_written(dev.desc.type)), "");
    }
}

TEST(EsiImportFixtures, EmittedYamlLoadsBackEqual) {
    TempDir dir;
    for (const fs::path& f : fixtures()) {
        SCOPED_TRACE(f.string());
        const EsiDevice dev = imported(f);
        const std::string text = catalog_yaml(dev.desc, "# header\n", dev.init_cmds);
        Catalog c;
        c.load_yaml(dir.write(f.stem().string() + ".yaml", text));
        ASSERT_NE(c.find(dev.desc.type), nullptr);
        EXPECT_EQ(differences(*c.find(dev.desc.type), dev.desc), "");
        // and the hand-written entry, emitted, loads back to itself
        const DeviceDesc hw = hand_written(dev.desc.type);
        Catalog c2;
        c2.load_yaml(dir.write("hw_" + f.stem().string() + ".yaml", catalog_yaml(hw)));
        EXPECT_EQ(differences(*c2.find(hw.type), hw), "");
    }
}

TEST(EsiImportFixtures, EmittedYamlIsWrittenLikeTheHandWrittenFiles) {
    // For the simple terminals the emitted text is the hand-written file without its comments.
    for (const char* t : {"EL1008", "EL2008", "EL2808", "EL4134"}) {
        SCOPED_TRACE(t);
        std::istringstream hw(read_text((kCatalog / (std::string(t) + ".yaml")).string()));
        std::string want, line;
        while (std::getline(hw, line))
            if (!line.starts_with("#")) want += line + "\n";
        EXPECT_EQ(catalog_yaml(imported(kFixtures / (std::string(t) + ".xml")).desc), want);
    }
}

TEST(EsiImportFixtures, OversamplingTerminalsBehaveLikeTheHandWrittenOnes) {
    const EsiDevice el3702 = imported(kFixtures / "EL3702.xml");
    // the file lists samples 2-4 of channel 1 (0x1A01-0x1A03); the description is factor 1
    EXPECT_EQ(el3702.desc.find_pdo(0x1A01), nullptr);
    EXPECT_EQ(el3702.desc.oversampling.max, 100);
    ASSERT_EQ(el3702.desc.oversampling.channels.size(), 2u);
    EXPECT_EQ(el3702.desc.oversampling.channels[0].memmap, "analogInputArray01");
    EXPECT_EQ(el3702.desc.oversampling_factor(), 1u);
    for (unsigned n : {2u, 10u, 100u})
        EXPECT_EQ(differences(el3702.desc.with_oversampling(n),
                              hand_written("EL3702").with_oversampling(n)),
                  "")
            << n;
    const EsiDevice el4732 = imported(kFixtures / "EL4732.xml");
    EXPECT_EQ(el4732.desc.memmaps().size(), 2u);
    EXPECT_EQ(el4732.desc.memmaps()[1].name, "analogOutputArray02");
    EXPECT_TRUE(el4732.desc.memmaps()[1].output);
}

TEST(EsiImportFixtures, InitCmdsAreReadAndListedAsComments) {
    const EsiDevice el3102 = imported(kFixtures / "EL3102.xml");
    ASSERT_EQ(el3102.init_cmds.size(), 3u);
    EXPECT_EQ(el3102.init_cmds[1].transitions, "PS");
    EXPECT_EQ(el3102.init_cmds[1].index, 0x1C13);
    EXPECT_TRUE(el3102.init_cmds[1].complete_access);
    EXPECT_EQ(el3102.init_cmds[1].data, (std::vector<uint8_t>{0x02, 0x00, 0x00, 0x1A, 0x02, 0x1A}));
    const std::string text = catalog_yaml(el3102.desc, "", el3102.init_cmds);
    EXPECT_NE(
        text.find("#   PS: {index: 0x8000, sub: 6, value: 1, size: 1}  (enable filter ch.1)\n"),
        std::string::npos)
        << text;
    EXPECT_NE(
        text.find("#   PS: 0x1c13:0x00 complete access, 6 bytes: 0x02 0x00 0x00 0x1a 0x02 0x1a  "
                  "(SM 3 PDO assignment)\n"),
        std::string::npos)
        << text;
    const EsiDevice el7041 = imported(kFixtures / "EL7041.xml");
    ASSERT_EQ(el7041.init_cmds.size(), 1u);
    EXPECT_NE(catalog_yaml(el7041.desc, "", el7041.init_cmds)
                  .find("#   PS: {index: 0x8010, sub: 1, value: 2500, size: 2}"),
              std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Names

TEST(EsiImportNames, VendorNamesOrEcmcNamesFromTheCatalog) {
    // EL2008 as Beckhoff names it: "Output" in every channel.
    std::string text = read_text((kFixtures / "EL2008.xml").string());
    for (int ch = 1; ch <= 8; ++ch)
        text = replaced(text, "<Name>binaryOutput0" + std::to_string(ch) + "</Name>",
                        "<Name>Output</Name>");
    TempDir dir;
    const std::string file = dir.write("EL2008.xml", text);
    DeviceDesc d = read_esi(file).at(0).desc;
    EXPECT_EQ(d.rx_pdos[0].entries[0].name, "Channel1_Output"); // repeated: <Pdo>_<Entry>
    EXPECT_EQ(d.rx_pdos[7].entries[0].name, "Channel8_Output");
    // with the catalog: ecmc names by index:sub
    Catalog names;
    names.load_dir(kCatalog.string());
    names.ecmc_names(d);
    EXPECT_EQ(differences(d, hand_written("EL2008")), "");

    // a name used once that is an identifier is kept; one with spaces gets the PDO's name
    std::string one = replaced(kTemplate, "<Name>out1</Name>", "<Name>Target value</Name>");
    DeviceDesc x = read_esi(dir.write("one.xml", one)).at(0).desc;
    EXPECT_EQ(x.rx_pdos[0].entries[0].name, "Out_Targetvalue");
    EXPECT_EQ(x.tx_pdos[0].entries[0].name, "in1");
    // only letters, digits and '_' (the name is part of signal and PV names)
    one = replaced(kTemplate, "<Name>out1</Name>", "<Name>Value (Ch.1) &#xb0;C</Name>");
    x = read_esi(dir.write("odd.xml", one)).at(0).desc;
    EXPECT_EQ(x.rx_pdos[0].entries[0].name, "Out_ValueCh1C");
}

TEST(EsiImportNames, UnknownTypeErrorSaysHowToImport) {
    Catalog c;
    c.load_dir(kCatalog.string());
    EXPECT_EQ(c.unknown_type_error("EL7014"),
              "unknown device type 'EL7014'; close matches in the catalog: EL7041, EL3104, EL7211; "
              "to add a device, "
              "import its vendor's ESI file: beamctl esi import VENDOR.xml --out " +
                  kCatalog.string() +
                  " (BEAMCTL_CATALOG selects the catalog directory; docs/esi.md)");
    EXPECT_NE(Catalog().unknown_type_error("X").find("--out CATALOG_DIR"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// The schema's edge cases: each a clear error at file:line:col

TEST(EsiImportEdges, TemplateIsValid) {
    TempDir dir;
    auto devs = read_esi(dir.write("t.xml", kTemplate));
    ASSERT_EQ(devs.size(), 1u);
    EXPECT_EQ(devs[0].desc.type, "XD0001");
    EXPECT_EQ(devs[0].at.line, 6);
    EXPECT_EQ(devs[0].desc.sm_bytes(0), 2u);
    EXPECT_EQ(devs[0].desc.tx_pdos[0].entries[0].datatype, "UINT8");
}

TEST(EsiImportEdges, HexAndDecimalForms) {
    TempDir dir;
    for (const char* form : {"#x1A00", "#X1a00", "6656", " #x1a00 "}) {
        SCOPED_TRACE(form);
        std::string text = replaced(kTemplate, "<Index>#x1a00</Index>",
                                    std::string("<Index>") + form + "</Index>");
        EXPECT_NE(read_esi(dir.write("h.xml", text)).at(0).desc.find_pdo(0x1A00), nullptr);
    }
    std::string text = replaced(kTemplate, "<Index>#x1a00</Index>", "<Index>0x1A00</Index>");
    std::string file = dir.write("c.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Index>0x1A00") +
                  ": Index: PDO Index '0x1A00' is not a number (ESI writes hex as #x..)");
    text = replaced(kTemplate, "<Index>#x1a00</Index>", "<Index>#x</Index>");
    file = dir.write("e.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Index>#x<") + ": Index: PDO Index '#x' is not a number");
    text = replaced(kTemplate, "RevisionNo=\"#x00100000\"", "RevisionNo=\"#x100000000\"");
    file = dir.write("r.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Type ") +
                  ": Type: RevisionNo #x100000000 is out of range (maximum 4294967295)");
}

TEST(EsiImportEdges, MissingProductCode) {
    TempDir dir;
    std::string text = replaced(kTemplate, " ProductCode=\"#x00013052\"", "");
    std::string file = dir.write("p.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Type ") + ": Type: missing attribute ProductCode");
}

TEST(EsiImportEdges, IndexZeroEntriesArePadding) {
    TempDir dir;
    // a gap of 4 bits, written once bare and once with the subindex, name and type tools add
    std::string text =
        replaced(kTemplate, "<DataType>USINT</DataType></Entry>",
                 "<DataType>USINT</DataType></Entry>\n"
                 "          <Entry><Index>0</Index><BitLen>4</BitLen></Entry>\n"
                 "          <Entry><Index>#x0</Index><SubIndex>0</SubIndex><BitLen>4</BitLen>"
                 "<Name>gap</Name><DataType>BIT4</DataType></Entry>");
    DeviceDesc d = read_esi(dir.write("pad.xml", text)).at(0).desc;
    ASSERT_EQ(d.tx_pdos[0].entries.size(), 3u);
    EXPECT_EQ(d.tx_pdos[0].entries[1], (PdoEntry{0, 0, 4, "", ""}));
    EXPECT_EQ(d.tx_pdos[0].entries[2], (PdoEntry{0, 0, 4, "", ""}));
    EXPECT_EQ(d.sm_bytes(1), 2u);
    // and they load back from the emitted YAML as padding
    Catalog c;
    c.load_yaml(dir.write("pad.yaml", catalog_yaml(d)));
    EXPECT_EQ(*c.find("XD0001"), d);
}

TEST(EsiImportEdges, PdoTwiceOrInTheWrongSm) {
    TempDir dir;
    // the same PDO index twice (a PDO in two SMs)
    std::string text =
        replaced(kTemplate, "        <TxPdo Sm=\"1\">",
                 "        <TxPdo Sm=\"1\"><Index>#x1a00</Index><Name>Again</Name></TxPdo>\n"
                 "        <TxPdo Sm=\"1\">");
    std::string file = dir.write("dup.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<TxPdo Sm=\"1\">\n") +
                  ": TxPdo: PDO 0x1A00 is already defined at " +
                  loc_of(file, text, "<TxPdo Sm=\"1\"><Index>") +
                  " (one PDO, one default Sm; AlternativeSmMapping for others)");
    // an RxPdo assigned to an Inputs SM
    text = replaced(kTemplate, "<RxPdo Sm=\"0\"", "<RxPdo Sm=\"1\"");
    file = dir.write("wrong.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<RxPdo") + ": RxPdo: PDO 0x1600 is assigned to SM1, a Inputs "
                                             "sync manager; an RxPdo needs Outputs");
    // an RxPdo with a TxPdo index
    text = replaced(kTemplate, "<Index>#x1600</Index>", "<Index>#x1a05</Index>");
    file = dir.write("range.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Index>#x1a05") +
                  ": Index: 0x1A05 should be in 0x1600-0x17FF (RxPdo, outputs)");
    // a mandatory PDO that is not assigned
    text = replaced(kTemplate, "<RxPdo Sm=\"0\" Fixed=\"1\" Mandatory=\"1\">",
                    "<RxPdo Mandatory=\"true\">");
    file = dir.write("mand.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<RxPdo") + ": RxPdo: mandatory PDO 0x1600 has no Sm attribute "
                                             "(the sync manager it is assigned to)");
}

TEST(EsiImportEdges, ExcludedAndOptionalPdos) {
    TempDir dir;
    // an optional PDO (no Sm) that excludes the assigned one: listed, not assigned
    const std::string optional = "        <TxPdo>\n"
                                 "          <Index>#x1a01</Index>\n"
                                 "          <Name>In long</Name>\n"
                                 "          <Exclude>#x1a00</Exclude>\n"
                                 "          "
                                 "<Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>16</"
                                 "BitLen><Name>in1long</Name><DataType>UINT</DataType></Entry>\n"
                                 "        </TxPdo>\n";
    std::string text = replaced(kTemplate, "      </Device>", optional + "      </Device>");
    DeviceDesc d = read_esi(dir.write("opt.xml", text)).at(0).desc;
    ASSERT_NE(d.find_pdo(0x1A01), nullptr);
    using Assign = std::vector<std::pair<uint8_t, uint16_t>>;
    EXPECT_EQ(d.pdo_assign, (Assign{{0, 0x1600}, {1, 0x1A00}}));
    EXPECT_EQ(d.sm_bytes(1), 1u);
    const std::string yaml = catalog_yaml(d);
    EXPECT_NE(
        yaml.find("  - {index: 0x1a01, name: In long, entries: [{index: 0x6000, sub: 1, bits: 16, "
                  "name: in1long, datatype: UINT16}]}\n"),
        std::string::npos)
        << yaml;
    // both assigned by default although one excludes the other
    text = replaced(text, "        <TxPdo>\n", "        <TxPdo Sm=\"1\">\n");
    std::string file = dir.write("ex.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Exclude>") +
                  ": Exclude: PDO 0x1A01 excludes 0x1A00, but both are assigned by default (Sm)");
}

TEST(EsiImportEdges, SeveralDevicesAndRevisionsInOneFile) {
    TempDir dir;
    std::string rev2 = replaced(replaced(kTemplate, "</Devices>", "</Devices>"),
                                "RevisionNo=\"#x00100000\"", "RevisionNo=\"#x00110000\"");
    // XD0001 in revisions 0x00100000 and 0x00110000, and XD0002
    size_t a = rev2.find("      <Device>"), b = rev2.find("    </Devices>");
    std::string text = replaced(kTemplate, "    </Devices>",
                                rev2.substr(a, b - a) + kSecondDevice + "    </Devices>");
    std::string file = dir.write("multi.xml", text);
    auto devs = read_esi(file);
    ASSERT_EQ(devs.size(), 3u);
    EXPECT_EQ(devs[0].desc.revision, 0x00100000u);
    EXPECT_EQ(devs[1].desc.revision, 0x00110000u);
    EXPECT_EQ(devs[2].desc.type, "XD0002");
    EXPECT_EQ(devs[2].desc.revision, 0x00110000u);

    EsiImportOptions o{{file}, (dir.path / "cat").string(), false};
    std::ostringstream out, err;
    EXPECT_EQ(run_esi_import(o, out, err), 0) << err.str();
    EXPECT_EQ(out.str(), "wrote " + o.out +
                             "/XD0001_rev0x00100000.yaml (XD0001 revision 0x00100000)\n"
                             "wrote " +
                             o.out +
                             "/XD0001_rev0x00110000.yaml (XD0001 revision 0x00110000)\n"
                             "wrote " +
                             o.out + "/XD0002.yaml (XD0002 revision 0x00110000)\n");
    Catalog c;
    c.load_dir(o.out);
    EXPECT_EQ(c.size(), 3u);
    EXPECT_EQ(c.find("XD0001")->revision, 0x00110000u);
    EXPECT_EQ(*c.find(2, 0x00013052, 0x00100000), devs[0].desc);
}

TEST(EsiImportEdges, DataTypes) {
    TempDir dir;
    std::string text =
        replaced(kTemplate, "<DataType>USINT</DataType>", "<DataType>FOO16</DataType>");
    std::string file = dir.write("dt.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<DataType>FOO16") +
                  ": DataType: unknown DataType 'FOO16' (BOOL/BIT, BIT2-BIT8, SINT/INT/DINT/LINT, "
                  "USINT/UINT/UDINT/ULINT, BYTE/WORD/DWORD, BITARR8-32, REAL/LREAL, INT8-INT64, "
                  "UINT8-UINT64, REAL32, REAL64)");
    text = replaced(kTemplate, "<BitLen>8</BitLen>", "<BitLen>16</BitLen>");
    file = dir.write("bl.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<BitLen>16</BitLen><Name>in1") +
                  ": BitLen: BitLen 16 should be 8 for DataType USINT");
    text = replaced(kTemplate, "<DataType>USINT</DataType>", "");
    file = dir.write("nodt.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<Entry><Index>#x6000") +
                  ": Entry: entry 0x6000:1 has no <DataType> (only padding, Index 0, may omit it)");
    // CoE names and IEC names alike; a bit array is read as an unsigned word of its width
    for (const char* t : {"UINT8", "BYTE", "BITARR8"}) {
        text = replaced(kTemplate, "<DataType>USINT</DataType>",
                        std::string("<DataType>") + t + "</DataType>");
        EXPECT_EQ(read_esi(dir.write("coe.xml", text)).at(0).desc.tx_pdos[0].entries[0].datatype,
                  "UINT8")
            << t;
    }
}

TEST(EsiImportEdges, NotEsiOrNotXml) {
    TempDir dir;
    std::string file = dir.write("root.xml", "<?xml version=\"1.0\"?>\n<EtherCATConfig/>\n");
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              file + ":2:1: root element should be <EtherCATInfo>, got <EtherCATConfig>");
    std::string text = replaced(kTemplate, "</Name>\n        <Sm", "</Nme>\n        <Sm");
    file = dir.write("bad.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }).substr(0, file.size() + 3), file + ":8:")
        << error_of([&] { read_esi(file); });
    EXPECT_NE(error_of([&] { read_esi(file); }).find(": XML error"), std::string::npos);
    EXPECT_EQ(error_of([&] { read_esi(dir.file("none.xml")); }),
              dir.file("none.xml") + ": cannot open");
    text = replaced(kTemplate, "  <Vendor><Id>#x00000002</Id><Name>Test</Name></Vendor>\n", "");
    file = dir.write("novendor.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<EtherCATInfo") + ": EtherCATInfo: missing <Vendor>");
}

TEST(EsiImportEdges, EveryBadDeviceIsReported) {
    TempDir dir;
    std::string text = replaced(
        kTemplate, "    </Devices>",
        replaced(kSecondDevice, "<Type ProductCode=\"#x00023052\"", "<Type") + "    </Devices>");
    text = replaced(text, "<DataType>USINT</DataType>", "<DataType>USINTX</DataType>");
    std::string file = dir.write("two.xml", text);
    try {
        read_esi(file);
        FAIL() << "no error";
    } catch (const beamctl::MultiError& e) {
        ASSERT_EQ(e.errors().size(), 2u) << e.what();
        EXPECT_TRUE(e.errors()[0].starts_with(loc_of(file, text, "<DataType>USINTX") +
                                              ": DataType: unknown DataType"));
        EXPECT_EQ(e.errors()[1],
                  loc_of(file, text, "<Type RevisionNo") + ": Type: missing attribute ProductCode");
    }
}

TEST(EsiImportEdges, Oversampling) {
    TempDir dir;
    std::string os = replaced(kTemplate, "<TxPdo Sm=\"1\">",
                              "<TxPdo Sm=\"1\" OSFac=\"1\" OSMax=\"4\" OSIndexInc=\"16\">");
    DeviceDesc d = read_esi(dir.write("os.xml", os)).at(0).desc;
    EXPECT_EQ(d.oversampling.max, 4);
    ASSERT_EQ(d.oversampling.channels.size(), 1u);
    EXPECT_EQ(d.oversampling.channels[0].memmap, "inArray1"); // ECMC's <signal>Array<channel>
    EXPECT_EQ(d.tx_pdos[0].entries[0].name, "in1_1");         // the first sample
    EXPECT_EQ(d.with_oversampling(4).sm_bytes(1), 4u);

    std::string text = replaced(os, "OSIndexInc=\"16\"", "OSIndexInc=\"1\"");
    std::string file = dir.write("inc.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<TxPdo") +
                  ": TxPdo: OSIndexInc 1 is not supported (sample k's entry index is the first's + "
                  "16*(k-1): OSIndexInc 16)");
    // a PDO where sample 3 goes that is something else
    const std::string other =
        "        <TxPdo><Index>#x1a02</Index><Name>Other</Name>"
        "<Entry><Index>#x6100</Index><SubIndex>1</SubIndex><BitLen>8</BitLen><Name>other</"
        "Name><DataType>USINT</DataType></Entry></TxPdo>\n";
    text = replaced(os, "      </Device>", other + "      </Device>");
    file = dir.write("clash.xml", text);
    EXPECT_EQ(error_of([&] { read_esi(file); }),
              loc_of(file, text, "<TxPdo><Index>#x1a02") +
                  ": TxPdo: PDO 0x1A02 is where sample 3 of oversampled PDO 0x1A00 goes (OSMax 4), "
                  "but it is "
                  "not that sample (one entry 0x6020:1, UINT8)");
    // the repeated sample itself is dropped
    text = replaced(other, "#x6100", "#x6020");
    text = replaced(os, "      </Device>", text + "      </Device>");
    d = read_esi(dir.write("rep.xml", text)).at(0).desc;
    EXPECT_EQ(d.find_pdo(0x1A02), nullptr);
}

// ---------------------------------------------------------------------------------------------
// beamctl esi import

TEST(EsiImportRun, WritesOneFilePerDeviceThatTheCatalogLoads) {
    TempDir dir;
    EsiImportOptions o;
    for (const char* t : {"EL1008", "EL3702", "EL7211"})
        o.files.push_back((kFixtures / (std::string(t) + ".xml")).string());
    o.out = (dir.path / "catalog").string(); // created
    std::ostringstream out, err;
    ASSERT_EQ(run_esi_import(o, out, err), 0) << err.str();
    EXPECT_EQ(err.str(), "");
    EXPECT_EQ(out.str(), "wrote " + o.out +
                             "/EL1008.yaml (EL1008 revision 0x00120000)\n"
                             "wrote " +
                             o.out +
                             "/EL3702.yaml (EL3702 revision 0x00030000)\n"
                             "wrote " +
                             o.out + "/EL7211.yaml (EL7211 revision 0x00180000)\n");
    Catalog c;
    c.load_dir(o.out);
    for (const char* t : {"EL1008", "EL3702", "EL7211"})
        EXPECT_EQ(differences(*c.find(t), hand_written(t)), "") << t;
    const std::string text = read_text(o.out + "/EL3702.yaml");
    EXPECT_TRUE(text.starts_with(std::string(kEsiImportHeader) + " from EL3702.xml:12;")) << text;

    // a second import replaces its own files
    std::ostringstream out2, err2;
    EXPECT_EQ(run_esi_import(o, out2, err2), 0) << err2.str();
    EXPECT_EQ(fs::directory_iterator(o.out) == fs::directory_iterator(), false);
    size_t n = std::distance(fs::directory_iterator(o.out), fs::directory_iterator());
    EXPECT_EQ(n, 3u); // no temporary files left
}

TEST(EsiImportRun, LeavesHandWrittenFilesAloneWithoutForce) {
    TempDir dir;
    fs::create_directories(dir.path / "cat");
    const std::string hw = read_text((kCatalog / "EL1008.yaml").string());
    const std::string mine =
        dir.write("cat/my_el1008.yaml", hw); // same identity, another file name
    const std::string el2008 =
        dir.write("cat/EL2008.yaml", "# mine\n" + read_text((kCatalog / "EL2008.yaml").string()));
    EsiImportOptions o{{(kFixtures / "EL1008.xml").string(), (kFixtures / "EL2008.xml").string(),
                        (kFixtures / "EL5101.xml").string()},
                       (dir.path / "cat").string(),
                       false};
    std::ostringstream out, err;
    EXPECT_EQ(run_esi_import(o, out, err), 1);
    EXPECT_EQ(err.str(),
              (kFixtures / "EL1008.xml").string() +
                  ":12:7: Device: EL1008 revision 0x00120000 would replace " + mine +
                  ", which beamctl esi import did not write: not replaced (--force replaces it)\n" +
                  (kFixtures / "EL2008.xml").string() +
                  ":12:7: Device: EL2008 revision 0x00100000 would replace " + el2008 +
                  ", which beamctl esi import did not write: not replaced (--force replaces it)\n");
    EXPECT_EQ(out.str(),
              "wrote " + o.out + "/EL5101.yaml (EL5101 revision 0x03fd0000)\n"); // the good file
    EXPECT_EQ(read_text(mine), hw);
    EXPECT_TRUE(read_text(el2008).starts_with("# mine\n"));

    o.force = true;
    std::ostringstream out2, err2;
    EXPECT_EQ(run_esi_import(o, out2, err2), 0) << err2.str();
    EXPECT_NE(
        out2.str().find("wrote " + mine +
                        " (EL1008 revision 0x00120000, replaced a file the import did not write)"),
        std::string::npos)
        << out2.str();
    EXPECT_TRUE(read_text(mine).starts_with(kEsiImportHeader));
    Catalog c;
    c.load_dir(o.out); // still one file per identity
    EXPECT_EQ(c.size(), 3u);
}

TEST(EsiImportRun, ABadFileWritesNothingAndTheOthersStillImport) {
    TempDir dir;
    std::string text = replaced(read_text((kFixtures / "EL3102.xml").string()),
                                "<DataType>INT</DataType>", "<DataType>INT17</DataType>");
    const std::string bad = dir.write("EL3102.xml", text);
    EsiImportOptions o{{bad, (kFixtures / "EL4134.xml").string(), dir.file("missing.xml")},
                       (dir.path / "cat").string(),
                       false};
    std::ostringstream out, err;
    EXPECT_EQ(run_esi_import(o, out, err), 1);
    EXPECT_EQ(err.str(),
              loc_of(bad, text, "<DataType>INT17") +
                  ": DataType: unknown DataType 'INT17' (BOOL/BIT, BIT2-BIT8, SINT/INT/DINT/LINT, "
                  "USINT/UINT/UDINT/ULINT, BYTE/WORD/DWORD, BITARR8-32, REAL/LREAL, INT8-INT64, "
                  "UINT8-UINT64, "
                  "REAL32, REAL64)\n" +
                  dir.file("missing.xml") + ": cannot open\n");
    EXPECT_EQ(out.str(), "wrote " + o.out + "/EL4134.yaml (EL4134 revision 0x03f90000)\n");
    EXPECT_FALSE(fs::exists(o.out + "/EL3102.yaml"));

    // the same identity in two files: the second file writes nothing
    EsiImportOptions twice{
        {(kFixtures / "EL4134.xml").string(), (kFixtures / "EL4134.xml").string()},
        (dir.path / "cat2").string(),
        false};
    std::ostringstream out2, err2;
    EXPECT_EQ(run_esi_import(twice, out2, err2), 1);
    EXPECT_EQ(err2.str(), (kFixtures / "EL4134.xml").string() +
                              ":12:7: Device: EL4134 revision 0x03f90000 is already "
                              "imported from " +
                              (kFixtures / "EL4134.xml").string() + ":12:7\n");
}

TEST(EsiImportRun, WithoutOutPrintsTheEntries) {
    EsiImportOptions o{{(kFixtures / "EL1008.xml").string()}, "", false};
    std::ostringstream out, err;
    EXPECT_EQ(run_esi_import(o, out, err), 0);
    EXPECT_TRUE(out.str().starts_with(std::string(kEsiImportHeader) + " from EL1008.xml:12;"))
        << out.str();
    EXPECT_NE(out.str().find("\ntype: EL1008\n"), std::string::npos);
    EXPECT_EQ(err.str(),
              "nothing written: give --out DIR (e.g. --out catalog/) to write these entries\n");
    o.files.push_back((kFixtures / "EL2008.xml").string());
    std::ostringstream out2, err2;
    EXPECT_EQ(run_esi_import(o, out2, err2), 0);
    EXPECT_TRUE(out2.str().starts_with("# ==> EL1008.yaml <==\n")) << out2.str();
    EXPECT_NE(out2.str().find("\n\n# ==> EL2008.yaml <==\n"), std::string::npos);
}
