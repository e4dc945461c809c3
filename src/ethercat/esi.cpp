#include "ethercat/esi.hpp"

#include "core/error_list.hpp"
#include "ethercat/sii.hpp"

#include <tinyxml2.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace beamctl::ethercat {

namespace {

using tinyxml2::XMLElement;

std::string hex(uint32_t v, int digits = 4) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%0*X", digits, v);
    return buf;
}

std::string without_spaces(std::string s) {
    s.erase(std::remove_if(s.begin(), s.end(), [](unsigned char c) { return std::isspace(c); }),
            s.end());
    return s;
}

std::string trimmed(const char* s) {
    std::string t = s ? s : "";
    t.erase(0, t.find_first_not_of(" \t\r\n"));
    t.erase(t.find_last_not_of(" \t\r\n") + 1);
    return t;
}

// The letters, digits and '_' of a name.
std::string name_part(const std::string& s) {
    std::string out;
    for (char c : s)
        if (std::isalnum(static_cast<unsigned char>(c)) || c == '_') out += c;
    return out;
}

bool is_identifier(const std::string& s) {
    if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
    return std::all_of(s.begin(), s.end(),
                       [](unsigned char c) { return std::isalnum(c) || c == '_'; });
}

bool truthy(const char* v) {
    return v && (std::string(v) == "1" || std::string(v) == "true");
}

class EsiReader {
public:
    EsiReader(std::string file, const std::string& text)
        : file_(std::move(file))
        , text_(text) {
        line_starts_.push_back(0);
        for (size_t i = 0; i < text_.size(); ++i)
            if (text_[i] == '\n') line_starts_.push_back(i + 1);
    }

    // file:line:col of an element: tinyxml2 gives the line; the column is where "<Name" starts.
    SourceLoc loc(const XMLElement* e) const {
        int line = e->GetLineNum();
        int col = 1;
        if (line >= 1 && static_cast<size_t>(line) <= line_starts_.size()) {
            size_t begin = line_starts_[line - 1];
            size_t end =
                static_cast<size_t>(line) < line_starts_.size() ? line_starts_[line] : text_.size();
            std::string tag = std::string("<") + e->Name();
            size_t pos = text_.find(tag, begin);
            if (pos != std::string::npos && pos < end) col = static_cast<int>(pos - begin) + 1;
        }
        return SourceLoc{file_, line, col};
    }
    std::string where(const XMLElement* e) const { return loc(e).str(); }

    [[noreturn]] void fail(const XMLElement* e, const std::string& what) const {
        throw Error(SB() << where(e) << ": " << e->Name() << ": " << what);
    }

    // ESI number (xs HexDecValue): "#x1A00" hex, or decimal (optionally negative when
    // `allow_negative`).
    int64_t number(const XMLElement* e, const char* what, const char* s,
                   bool allow_negative = false) const {
        std::string t = trimmed(s);
        bool neg = false;
        std::string digits = t;
        int base = 10;
        if (digits.size() > 2 && digits[0] == '#' && (digits[1] == 'x' || digits[1] == 'X')) {
            digits = digits.substr(2);
            base = 16;
        } else if (allow_negative && !digits.empty() && digits[0] == '-') {
            neg = true;
            digits = digits.substr(1);
        }
        if (digits.empty() || digits.size() > 16)
            fail(e, SB() << what << " '" << t << "' is not a number");
        int64_t v = 0;
        for (char c : digits) {
            c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
            int digit;
            if (c >= '0' && c <= '9')
                digit = c - '0';
            else if (base == 16 && c >= 'a' && c <= 'f')
                digit = c - 'a' + 10;
            else
                fail(e, SB() << what << " '" << t << "' is not a number"
                             << (t.size() > 1 && t[0] == '0' && (t[1] == 'x' || t[1] == 'X')
                                     ? " (ESI writes hex as #x..)"
                                     : ""));
            v = v * base + digit;
        }
        return neg ? -v : v;
    }

    uint64_t unsigned_in(const XMLElement* e, const char* what, const char* s, uint64_t max) const {
        int64_t v = number(e, what, s);
        if (v < 0 || static_cast<uint64_t>(v) > max)
            fail(e,
                 SB() << what << " " << trimmed(s) << " is out of range (maximum " << max << ")");
        return static_cast<uint64_t>(v);
    }

    // The required child element `name`.
    const XMLElement* child(const XMLElement* e, const char* name) const {
        const XMLElement* c = e->FirstChildElement(name);
        if (!c) fail(e, SB() << "missing <" << name << ">");
        return c;
    }
    // The number in the required child element `name`.
    uint64_t child_unsigned(const XMLElement* e, const char* name, const char* what,
                            uint64_t max) const {
        const XMLElement* c = child(e, name);
        return unsigned_in(c, what, c->GetText() ? c->GetText() : "", max);
    }

private:
    std::string file_;
    const std::string& text_;
    std::vector<size_t> line_starts_;
};

// First <Name> child, preferring LcId 1033 (English).
std::string esi_name(const XMLElement* e) {
    const XMLElement* first = nullptr;
    for (auto* n = e->FirstChildElement("Name"); n; n = n->NextSiblingElement("Name")) {
        if (!first) first = n;
        const char* lcid = n->Attribute("LcId");
        if (lcid && std::string(lcid) == "1033") return trimmed(n->GetText());
    }
    return first ? trimmed(first->GetText()) : "";
}

// ESI (IEC 61131) type names -> the CoE names used in the catalog; other names pass through
// (and are an error unless they are CoE names).
std::string normalize_datatype(std::string t) {
    static const std::map<std::string, std::string> kMap{
        {"BIT", "BOOL"},      {"BIT1", "BOOL"},       {"SINT", "INT8"},       {"INT", "INT16"},
        {"DINT", "INT32"},    {"LINT", "INT64"},      {"USINT", "UINT8"},     {"BYTE", "UINT8"},
        {"UINT", "UINT16"},   {"WORD", "UINT16"},     {"UDINT", "UINT32"},    {"DWORD", "UINT32"},
        {"ULINT", "UINT64"},  {"REAL", "REAL32"},     {"LREAL", "REAL64"},    {"FLOAT", "REAL32"},
        {"BITARR8", "UINT8"}, {"BITARR16", "UINT16"}, {"BITARR32", "UINT32"}, // bit arrays: words
    };
    t = without_spaces(t);
    if (auto it = kMap.find(t); it != kMap.end()) return it->second;
    return t;
}

// A PDO while its device is read: where its parts are, for errors after the first pass.
struct PdoSource {
    const XMLElement* pdo = nullptr;
    std::vector<const XMLElement*> entries; // one per entry
    std::vector<std::string> entry_names;   // ESI names (spaces kept), "" for padding
    std::vector<std::pair<uint16_t, const XMLElement*>> excludes;
    bool rx = false;
    int sm = -1; // default assignment, -1: none
    unsigned os_max = 0;
};

DeviceDesc parse_device(const EsiReader& r, const XMLElement* dev, uint32_t vendor,
                        std::vector<EsiInitCmd>& init_cmds) {
    DeviceDesc d;
    d.vendor = vendor;
    const XMLElement* type = r.child(dev, "Type");
    d.type = without_spaces(type->GetText() ? type->GetText() : "");
    if (d.type.empty()) r.fail(type, "empty device type");
    const char* pc = type->Attribute("ProductCode");
    if (!pc) r.fail(type, "missing attribute ProductCode");
    d.product = static_cast<uint32_t>(r.unsigned_in(type, "ProductCode", pc, 0xFFFFFFFF));
    if (const char* rev = type->Attribute("RevisionNo"))
        d.revision = static_cast<uint32_t>(r.unsigned_in(type, "RevisionNo", rev, 0xFFFFFFFF));
    d.name = esi_name(dev);

    // Sync managers, in element order.
    for (auto* sm = dev->FirstChildElement("Sm"); sm; sm = sm->NextSiblingElement("Sm")) {
        SyncManagerDesc s;
        s.index = static_cast<uint8_t>(d.sms.size());
        const char* start = sm->Attribute("StartAddress");
        if (!start) r.fail(sm, "missing attribute StartAddress");
        s.start = static_cast<uint16_t>(r.unsigned_in(sm, "StartAddress", start, 0xFFFF));
        if (const char* v = sm->Attribute("ControlByte"))
            s.control = static_cast<uint8_t>(r.unsigned_in(sm, "ControlByte", v, 0xFF));
        if (const char* v = sm->Attribute("DefaultSize"))
            s.default_size = static_cast<uint16_t>(r.unsigned_in(sm, "DefaultSize", v, 0xFFFF));
        uint64_t enable = 1;
        if (const char* v = sm->Attribute("Enable")) enable = r.unsigned_in(sm, "Enable", v, 0xFF);
        s.enable = enable & kSiiSmEnable;
        s.is_virtual = enable & kSiiSmVirtual;
        if (const char* v = sm->Attribute("Virtual")) s.is_virtual = truthy(v);
        std::string text = without_spaces(sm->GetText() ? sm->GetText() : "");
        if (text.empty())
            s.type = SmType::Unused;
        else if (auto t = sm_type_from_name(text))
            s.type = *t;
        else
            r.fail(sm, SB() << "'" << text << "' should be MBoxOut, MBoxIn, Outputs or Inputs");
        const bool mailbox = s.type == SmType::MailboxOut || s.type == SmType::MailboxIn;
        if (mailbox && s.default_size == 0)
            r.fail(sm, SB() << "a " << text << " sync manager needs DefaultSize > 0");
        if (mailbox && s.is_virtual) r.fail(sm, "a mailbox cannot be virtual");
        for (const SyncManagerDesc& other : d.sms)
            if (mailbox && other.type == s.type)
                r.fail(sm, SB() << "second " << text << " sync manager (SM" << unsigned(other.index)
                                << " is one already)");
        d.sms.push_back(s);
    }

    // PDOs, in element order per direction.
    std::map<uint16_t, PdoSource> src; // by PDO index
    std::vector<std::pair<uint8_t, uint16_t>> rx_assign, tx_assign;
    for (bool rx : {true, false}) {
        const char* tag = rx ? "RxPdo" : "TxPdo";
        for (auto* pe = dev->FirstChildElement(tag); pe; pe = pe->NextSiblingElement(tag)) {
            Pdo p;
            PdoSource ps;
            ps.pdo = pe;
            ps.rx = rx;
            const XMLElement* idx_el = r.child(pe, "Index");
            p.index = static_cast<uint16_t>(r.child_unsigned(pe, "Index", "PDO Index", 0xFFFF));
            const uint16_t lo = rx ? 0x1600 : 0x1A00, hi = rx ? 0x17FF : 0x1BFF;
            if (p.index < lo || p.index > hi)
                r.fail(idx_el, SB() << hex(p.index) << " should be in " << hex(lo) << "-" << hex(hi)
                                    << (rx ? " (RxPdo, outputs)" : " (TxPdo, inputs)"));
            if (auto it = src.find(p.index); it != src.end())
                r.fail(pe, SB() << "PDO " << hex(p.index) << " is already defined at "
                                << r.where(it->second.pdo)
                                << " (one PDO, one default Sm; AlternativeSmMapping for others)");
            p.name = esi_name(pe);
            if (const char* sm = pe->Attribute("Sm")) {
                uint64_t smi = r.unsigned_in(pe, "Sm", sm, 255);
                if (smi >= d.sms.size())
                    r.fail(pe, SB() << "PDO " << hex(p.index) << " is assigned to SM" << smi
                                    << " but the device has " << d.sms.size() << " <Sm> elements");
                const SmType want = rx ? SmType::Outputs : SmType::Inputs;
                if (d.sms[smi].type != want)
                    r.fail(pe, SB() << "PDO " << hex(p.index) << " is assigned to SM" << smi
                                    << ", a " << sm_type_name(d.sms[smi].type)
                                    << " sync manager; an " << tag << " needs "
                                    << sm_type_name(want));
                ps.sm = static_cast<int>(smi);
            } else if (truthy(pe->Attribute("Mandatory"))) {
                r.fail(pe, SB() << "mandatory PDO " << hex(p.index)
                                << " has no Sm attribute (the sync manager it is assigned to)");
            }
            for (auto* ex = pe->FirstChildElement("Exclude"); ex;
                 ex = ex->NextSiblingElement("Exclude"))
                ps.excludes.emplace_back(
                    static_cast<uint16_t>(r.unsigned_in(ex, "Exclude", ex->GetText(), 0xFFFF)), ex);
            if (const char* v = pe->Attribute("OSMax"))
                ps.os_max = static_cast<unsigned>(r.unsigned_in(pe, "OSMax", v, 1000));
            if (ps.os_max > 1) {
                uint64_t inc = 16;
                if (const char* v = pe->Attribute("OSIndexInc"))
                    inc = r.unsigned_in(pe, "OSIndexInc", v, 0xFFFF);
                if (inc != 16)
                    r.fail(pe, SB() << "OSIndexInc " << inc
                                    << " is not supported (sample k's entry index is the first's + "
                                       "16*(k-1): OSIndexInc 16)");
            }

            for (auto* en = pe->FirstChildElement("Entry"); en;
                 en = en->NextSiblingElement("Entry")) {
                PdoEntry e;
                e.index =
                    static_cast<uint16_t>(r.child_unsigned(en, "Index", "Entry Index", 0xFFFF));
                const XMLElement* bl = r.child(en, "BitLen");
                uint64_t bits =
                    r.unsigned_in(bl, "BitLen", bl->GetText() ? bl->GetText() : "", 255);
                if (bits == 0) r.fail(bl, "BitLen 0 should be > 0");
                e.bits = static_cast<uint8_t>(bits);
                std::string name;
                if (e.index != 0) { // index 0 is padding: only its BitLen counts
                    if (auto* sub = en->FirstChildElement("SubIndex"))
                        e.sub = static_cast<uint8_t>(r.unsigned_in(
                            sub, "SubIndex", sub->GetText() ? sub->GetText() : "", 255));
                    const XMLElement* dt = en->FirstChildElement("DataType");
                    if (!dt)
                        r.fail(en,
                               SB() << "entry " << hex(e.index) << ":" << unsigned(e.sub)
                                    << " has no <DataType> (only padding, Index 0, may omit it)");
                    const std::string raw = trimmed(dt->GetText());
                    e.datatype = normalize_datatype(raw);
                    unsigned width = coe_datatype_bits(e.datatype);
                    if (width == 0)
                        r.fail(dt, SB() << "unknown DataType '" << raw
                                        << "' (BOOL/BIT, BIT2-BIT8, SINT/INT/DINT/LINT, "
                                           "USINT/UINT/UDINT/ULINT, BYTE/WORD/DWORD, BITARR8-32, "
                                           "REAL/LREAL, "
                                           "INT8-INT64, UINT8-UINT64, REAL32, REAL64)");
                    if (width != e.bits)
                        r.fail(bl, SB() << "BitLen " << bits << " should be " << width
                                        << " for DataType " << raw);
                    name = esi_name(en);
                    if (name_part(name).empty())
                        r.fail(en, SB() << "entry " << hex(e.index) << ":" << unsigned(e.sub)
                                        << " has no <Name>");
                }
                p.entries.push_back(std::move(e));
                ps.entries.push_back(en);
                ps.entry_names.push_back(std::move(name));
            }
            if (ps.sm >= 0)
                (rx ? rx_assign : tx_assign).emplace_back(static_cast<uint8_t>(ps.sm), p.index);
            src.emplace(p.index, std::move(ps));
            (rx ? d.rx_pdos : d.tx_pdos).push_back(std::move(p));
        }
    }
    d.pdo_assign = std::move(rx_assign);
    d.pdo_assign.insert(d.pdo_assign.end(), tx_assign.begin(), tx_assign.end());
    auto assigned = [&](uint16_t pdo) {
        return std::any_of(d.pdo_assign.begin(), d.pdo_assign.end(),
                           [&](const auto& a) { return a.second == pdo; });
    };

    // Exclusions: two PDOs assigned by default must not exclude each other.
    for (const auto& [index, ps] : src)
        for (const auto& [other, ex] : ps.excludes)
            if (ps.sm >= 0 && other != index && assigned(other))
                r.fail(ex, SB() << "PDO " << hex(index) << " excludes " << hex(other)
                                << ", but both are assigned by default (Sm)");

    // Oversampling: a PDO with OSMax > 1 is a channel's first sample; samples 2..OSMax are
    // PDOs index+1.. with entry index +16 each. Those the file lists itself are dropped (the
    // description is factor 1); any other PDO in that range is an error.
    std::vector<uint16_t> channels;
    for (bool rx : {true, false})
        for (const Pdo& p : rx ? d.rx_pdos : d.tx_pdos) {
            const PdoSource& ps = src.at(p.index);
            if (ps.os_max < 2) continue;
            if (d.oversampling.max != 0 && d.oversampling.max != ps.os_max)
                r.fail(ps.pdo, SB() << "OSMax " << ps.os_max << " differs from OSMax "
                                    << d.oversampling.max << " of PDO " << hex(channels.front())
                                    << " (one maximum factor per device)");
            if (ps.sm < 0)
                r.fail(ps.pdo, SB() << "oversampled PDO " << hex(p.index)
                                    << " (OSMax) has no Sm: a channel's first sample is assigned "
                                       "by default");
            if (p.entries.size() != 1 || p.entries[0].index == 0)
                r.fail(ps.pdo, SB() << "oversampled PDO " << hex(p.index)
                                    << " (OSMax) should have one entry, the sample");
            d.oversampling.max = static_cast<uint16_t>(ps.os_max);
            channels.push_back(p.index);
        }
    std::set<uint16_t> repeats;
    for (uint16_t first : channels) {
        const PdoEntry& e = d.find_pdo(first)->entries[0];
        for (unsigned k = 2; k <= d.oversampling.max; ++k) {
            const uint16_t idx = static_cast<uint16_t>(first + k - 1);
            const Pdo* p = d.find_pdo(idx);
            if (!p) continue;
            const PdoEntry want{static_cast<uint16_t>(e.index + 16 * (k - 1)), e.sub, e.bits, "",
                                e.datatype};
            const bool sample = p->entries.size() == 1 && p->entries[0].index == want.index &&
                                p->entries[0].sub == want.sub && p->entries[0].bits == want.bits &&
                                p->entries[0].datatype == want.datatype &&
                                src.at(idx).rx == src.at(first).rx;
            if (!sample)
                r.fail(src.at(idx).pdo, SB() << "PDO " << hex(idx) << " is where sample " << k
                                             << " of oversampled PDO " << hex(first)
                                             << " goes (OSMax " << d.oversampling.max
                                             << "), but it is not that sample (one entry "
                                             << hex(want.index) << ":" << unsigned(want.sub) << ", "
                                             << e.datatype << ")");
            repeats.insert(idx);
        }
    }
    if (!repeats.empty()) {
        for (auto* list : {&d.rx_pdos, &d.tx_pdos})
            list->erase(std::remove_if(list->begin(), list->end(),
                                       [&](const Pdo& p) { return repeats.count(p.index) != 0; }),
                        list->end());
        d.pdo_assign.erase(
            std::remove_if(d.pdo_assign.begin(), d.pdo_assign.end(),
                           [&](const auto& a) { return repeats.count(a.second) != 0; }),
            d.pdo_assign.end());
    }

    // Entry names: the ESI name as it is when it is an identifier used once in the device,
    // else "<PdoName>_<EntryName>" with only the letters, digits and '_' of each (a name is part
    // of signal and PV names: no spaces, no dots). A channel's first sample is "<name>_1".
    std::map<std::string, int> uses;
    for (const auto& [index, ps] : src)
        if (!repeats.count(index))
            for (const std::string& n : ps.entry_names)
                if (!n.empty()) ++uses[n];
    std::map<std::string, const XMLElement*> named;
    for (auto* list : {&d.rx_pdos, &d.tx_pdos})
        for (Pdo& p : *list) {
            const PdoSource& ps = src.at(p.index);
            const std::string pdo_name = name_part(p.name);
            for (size_t i = 0; i < p.entries.size(); ++i) {
                PdoEntry& e = p.entries[i];
                const std::string& raw = ps.entry_names[i];
                if (e.index == 0) continue;
                if (is_identifier(raw) && uses[raw] == 1)
                    e.name = raw;
                else
                    e.name = pdo_name.empty() ? name_part(raw) : pdo_name + "_" + name_part(raw);
                if (std::find(channels.begin(), channels.end(), p.index) != channels.end() &&
                    !(e.name.size() > 2 && e.name.compare(e.name.size() - 2, 2, "_1") == 0))
                    e.name += "_1";
                if (auto [it, fresh] = named.emplace(e.name, ps.entries[i]); !fresh)
                    r.fail(ps.entries[i], SB() << "entry name '" << e.name
                                               << "' is already used by the entry at "
                                               << r.where(it->second));
            }
        }
    for (uint16_t first : channels)
        d.oversampling.channels.push_back(
            {first, esi_memmap_name(d.find_pdo(first)->entries[0].name)});

    // Process-data SM sizes follow from the PDOs assigned to them (virtual SMs keep theirs).
    for (SyncManagerDesc& sm : d.sms) {
        if ((sm.type != SmType::Outputs && sm.type != SmType::Inputs) || sm.is_virtual) continue;
        const uint32_t bytes = d.sm_bytes(sm.index);
        if (bytes > 0xFFFF)
            r.fail(dev, SB() << "the PDOs assigned to SM" << unsigned(sm.index) << " need " << bytes
                             << " bytes, more than an SM holds");
        sm.default_size = static_cast<uint16_t>(bytes);
    }

    // Mailbox: CoE and its InitCmds.
    if (auto* mbx = dev->FirstChildElement("Mailbox")) {
        if (auto* coe = mbx->FirstChildElement("CoE")) {
            d.coe = true;
            bool out = false, in = false;
            for (const SyncManagerDesc& sm : d.sms) {
                out |= sm.type == SmType::MailboxOut;
                in |= sm.type == SmType::MailboxIn;
            }
            if (!out || !in) r.fail(coe, "CoE needs an MBoxOut and an MBoxIn <Sm>");
            for (auto* ic = coe->FirstChildElement("InitCmd"); ic;
                 ic = ic->NextSiblingElement("InitCmd")) {
                EsiInitCmd c;
                for (auto* t = ic->FirstChildElement("Transition"); t;
                     t = t->NextSiblingElement("Transition")) {
                    std::string tr = trimmed(t->GetText());
                    static const std::set<std::string> kTransitions{"IP", "PS", "PI", "SP", "SO",
                                                                    "SI", "OS", "OP", "OI"};
                    if (!kTransitions.count(tr))
                        r.fail(t, SB() << "'" << tr
                                       << "' should be one of IP, PS, PI, SP, SO, SI, OS, OP, OI");
                    c.transitions += (c.transitions.empty() ? "" : " ") + tr;
                }
                if (c.transitions.empty()) r.fail(ic, "missing <Transition>");
                c.index = static_cast<uint16_t>(r.child_unsigned(ic, "Index", "Index", 0xFFFF));
                if (auto* sub = ic->FirstChildElement("SubIndex"))
                    c.sub = static_cast<uint8_t>(
                        r.unsigned_in(sub, "SubIndex", sub->GetText() ? sub->GetText() : "", 255));
                const XMLElement* data = r.child(ic, "Data");
                const std::string hexdata = without_spaces(data->GetText() ? data->GetText() : "");
                if (hexdata.empty() || hexdata.size() % 2 != 0 ||
                    !std::all_of(hexdata.begin(), hexdata.end(),
                                 [](unsigned char ch) { return std::isxdigit(ch); }))
                    r.fail(data, SB() << "'" << hexdata
                                      << "' should be hex bytes (an even number of hex digits)");
                for (size_t i = 0; i < hexdata.size(); i += 2)
                    c.data.push_back(
                        static_cast<uint8_t>(std::stoul(hexdata.substr(i, 2), nullptr, 16)));
                c.complete_access = truthy(ic->Attribute("CompleteAccess"));
                if (auto* cm = ic->FirstChildElement("Comment")) c.comment = trimmed(cm->GetText());
                init_cmds.push_back(std::move(c));
            }
        }
    }
    // DC: the first OpMode with a non-zero AssignActivate.
    if (auto* dc = dev->FirstChildElement("Dc")) {
        for (auto* om = dc->FirstChildElement("OpMode"); om;
             om = om->NextSiblingElement("OpMode")) {
            auto* aa = om->FirstChildElement("AssignActivate");
            if (!aa) continue;
            uint64_t v = r.unsigned_in(aa, "AssignActivate", aa->GetText(), 0xFFFF);
            if (v != 0 && d.dc_assign_activate == 0)
                d.dc_assign_activate = static_cast<uint16_t>(v);
        }
    }
    if (auto* el = dev->FirstChildElement("Electrical")) {
        if (auto* cur = el->FirstChildElement("EBusCurrent")) {
            int64_t ma = r.number(cur, "EBusCurrent", cur->GetText(), true);
            d.ebus_current_ma = static_cast<uint16_t>(std::clamp<int64_t>(ma, 0, 0xFFFF));
        }
    }
    return d;
}

std::vector<EsiDevice> parse_esi(const EsiReader& r, const tinyxml2::XMLDocument& doc) {
    const XMLElement* root = doc.RootElement();
    if (!root || std::string(root->Name()) != "EtherCATInfo")
        throw Error(SB() << (root ? r.where(root) : "") << ": root element should be "
                         << "<EtherCATInfo>, got <" << (root ? root->Name() : "") << ">");
    const XMLElement* vendor_el = r.child(root, "Vendor");
    const uint32_t vendor =
        static_cast<uint32_t>(r.child_unsigned(vendor_el, "Id", "Vendor Id", 0xFFFFFFFF));
    const XMLElement* descs = r.child(root, "Descriptions");
    const XMLElement* devices = r.child(descs, "Devices");

    std::vector<EsiDevice> out;
    ErrorList errors; // one per bad device; the others are still read
    for (auto* dev = devices->FirstChildElement("Device"); dev;
         dev = dev->NextSiblingElement("Device"))
        errors.capture([&] {
            EsiDevice d;
            d.at = r.loc(dev);
            d.desc = parse_device(r, dev, vendor, d.init_cmds);
            out.push_back(std::move(d));
        });
    errors.throw_if_any();
    return out;
}

} // namespace

std::string esi_memmap_name(const std::string& first_sample) {
    std::string n = first_sample;
    if (n.size() > 2 && n.compare(n.size() - 2, 2, "_1") == 0) n.resize(n.size() - 2);
    if (n.find("Array") != std::string::npos) return n;
    size_t digits = n.size();
    while (digits > 0 && std::isdigit(static_cast<unsigned char>(n[digits - 1]))) --digits;
    return n.substr(0, digits) + "Array" + n.substr(digits);
}

std::vector<EsiDevice> read_esi_text(const std::string& path, const std::string& text) {
    tinyxml2::XMLDocument doc;
    if (doc.Parse(text.data(), text.size()) != tinyxml2::XML_SUCCESS)
        throw Error(SB() << SourceLoc{path, doc.ErrorLineNum(), 1}.str()
                         << ": XML error: " << doc.ErrorStr());
    EsiReader r(path, text);
    return parse_esi(r, doc);
}

std::vector<EsiDevice> read_esi(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(SB() << path << ": cannot open");
    std::ostringstream ss;
    ss << in.rdbuf();
    return read_esi_text(path, ss.str());
}

} // namespace beamctl::ethercat
