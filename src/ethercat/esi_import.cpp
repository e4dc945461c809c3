#include "ethercat/esi_import.hpp"

#include "core/error.hpp"
#include "core/error_list.hpp"
#include "ethercat/catalog.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <ostream>
#include <set>
#include <sstream>
#include <tuple>
#include <unistd.h>

namespace fs = std::filesystem;

namespace beamctl::ethercat {

namespace {

std::string hx(uint64_t v, int digits) {
    char buf[24];
    std::snprintf(buf, sizeof buf, "0x%0*llx", digits, static_cast<unsigned long long>(v));
    return buf;
}

std::string quoted(const std::string& s) {
    std::string q = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') q += '\\';
        q += c;
    }
    return q + "\"";
}

// A string as a YAML scalar inside a flow mapping: plain where that reads back as the same
// string, else double-quoted.
std::string scalar(const std::string& s) {
    static const std::set<std::string> kSpecial{"true", "false", "yes", "no", "on",
                                                "off",  "null",  "y",   "n",  "~"};
    std::string lower = s;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    bool plain = !s.empty() && (std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_') &&
                 s.back() != ' ' && !kSpecial.count(lower) &&
                 std::all_of(s.begin(), s.end(), [](unsigned char c) {
                     return std::isalnum(c) ||
                            std::string_view(" _.()/+-").find(char(c)) != std::string_view::npos;
                 });
    return plain ? s : quoted(s);
}

std::string sub_str(uint8_t sub) {
    return sub <= 9 ? std::to_string(sub) : hx(sub, 2);
}

std::string entry_yaml(const PdoEntry& e) {
    if (e.index == 0) return SB() << "{index: 0, bits: " << unsigned(e.bits) << "}";
    return SB() << "{index: " << hx(e.index, 4) << ", sub: " << sub_str(e.sub)
                << ", bits: " << unsigned(e.bits) << ", name: " << scalar(e.name)
                << ", datatype: " << e.datatype << "}";
}

// An InitCmd as a comment line: the IOC file's sdo: form where the data is a 1/2/4/8-byte
// number, else the bytes.
std::string init_cmd_comment(const EsiInitCmd& c) {
    SB s;
    s << "#   " << c.transitions << ": ";
    const size_t n = c.data.size();
    if (!c.complete_access && (n == 1 || n == 2 || n == 4 || n == 8)) {
        uint64_t v = 0;
        for (size_t i = n; i-- > 0;) v = v << 8 | c.data[i];
        s << "{index: " << hx(c.index, 4) << ", sub: " << sub_str(c.sub) << ", value: " << v
          << ", size: " << n << "}";
    } else {
        s << hx(c.index, 4) << ":" << hx(c.sub, 2) << (c.complete_access ? " complete access" : "")
          << ", " << n << " bytes:";
        for (uint8_t b : c.data) s << " " << hx(b, 2);
    }
    if (!c.comment.empty()) s << "  (" << c.comment << ")";
    return s;
}

} // namespace

std::string catalog_yaml(const DeviceDesc& d, const std::string& header,
                         const std::vector<EsiInitCmd>& init_cmds) {
    std::ostringstream y;
    y << header;
    y << "type: " << scalar(d.type) << "\n";
    if (!d.variant_of.empty()) y << "variant_of: " << scalar(d.variant_of) << "\n";
    y << "name: " << quoted(d.name) << "\n";
    y << "vendor: " << hx(d.vendor, 8) << "\n";
    y << "product: " << hx(d.product, 8) << "\n";
    y << "revision: " << hx(d.revision, 8) << "\n";
    if (d.coe) y << "coe: true\n";
    if (d.dc_assign_activate) y << "dc_assign_activate: " << hx(d.dc_assign_activate, 4) << "\n";
    if (d.ebus_current_ma) y << "ebus_current_ma: " << d.ebus_current_ma << "\n";
    if (!d.sms.empty()) {
        y << "sync_managers:\n";
        for (const SyncManagerDesc& sm : d.sms) {
            const bool mailbox = sm.type == SmType::MailboxOut || sm.type == SmType::MailboxIn;
            const bool process = sm.type == SmType::Outputs || sm.type == SmType::Inputs;
            y << "  - {index: " << unsigned(sm.index) << ", start: " << hx(sm.start, 4);
            // process-data sizes follow from the PDOs; the others are given
            if (mailbox || ((!process || sm.is_virtual) && sm.default_size != 0))
                y << ", size: " << sm.default_size;
            y << ", control: " << hx(sm.control, 2) << ", type: " << sm_type_name(sm.type);
            if (!sm.enable) y << ", enable: false";
            if (sm.is_virtual) y << ", virtual: true";
            y << "}\n";
        }
    }
    for (bool rx : {true, false}) {
        const std::vector<Pdo>& pdos = rx ? d.rx_pdos : d.tx_pdos;
        if (pdos.empty()) continue;
        y << (rx ? "rx_pdos:\n" : "tx_pdos:\n");
        for (const Pdo& p : pdos) {
            std::string sm;
            for (const auto& [smi, idx] : d.pdo_assign)
                if (idx == p.index) sm = SB() << ", sm: " << unsigned(smi);
            if (p.entries.size() <= 1) {
                y << "  - {index: " << hx(p.index, 4) << ", name: " << scalar(p.name) << sm
                  << ", entries: [" << (p.entries.empty() ? "" : entry_yaml(p.entries[0]))
                  << "]}\n";
                continue;
            }
            y << "  - index: " << hx(p.index, 4) << "\n";
            y << "    name: " << scalar(p.name) << "\n";
            if (!sm.empty()) y << "    sm: " << sm.substr(6) << "\n";
            y << "    entries:\n";
            for (const PdoEntry& e : p.entries) y << "      - " << entry_yaml(e) << "\n";
        }
    }
    if (d.oversampling.max != 0) {
        y << "oversampling:\n  max: " << d.oversampling.max << "\n  channels: [";
        for (size_t i = 0; i < d.oversampling.channels.size(); ++i)
            y << (i ? ", " : "") << "{pdo: " << hx(d.oversampling.channels[i].pdo, 4)
              << ", memmap: " << scalar(d.oversampling.channels[i].memmap) << "}";
        y << "]\n";
    }
    if (!init_cmds.empty()) {
        y << "# The ESI's InitCmds (transition: SDO). beamctl does not apply them: give those "
             "this\n"
             "# setup needs as startup SDOs of the slave in the IOC file (sdo:, written in "
             "PREOP).\n";
        for (const EsiInitCmd& c : init_cmds) y << init_cmd_comment(c) << "\n";
    }
    return y.str();
}

std::string catalog_file_name(const DeviceDesc& d, bool with_revision) {
    std::string base = d.type;
    for (char& c : base)
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'))
            c = '_';
    if (with_revision) base += "_rev" + hx(d.revision, 8);
    return base + ".yaml";
}

namespace {

bool written_by_import(const std::string& path) {
    std::ifstream in(path);
    std::string first;
    std::getline(in, first);
    return first.rfind(kEsiImportHeader, 0) == 0;
}

// Writes `text` to a new file next to `path` and loads it as a catalog entry: the description
// must come back equal to `d`. Returns that file (the caller renames it or removes it).
std::string write_checked(const std::string& path, const std::string& text, const DeviceDesc& d) {
    std::string tmp = SB() << path << ".tmp" << ::getpid();
    {
        std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
        f << text;
        f.close();
        if (!f) {
            std::error_code ec;
            fs::remove(tmp, ec);
            throw Error(SB() << tmp << ": cannot write");
        }
    }
    try {
        Catalog c;
        c.load_yaml(tmp);
        if (!c.find(d.type) || !(*c.find(d.type) == d))
            throw Error("reads back as another description");
    } catch (const Error& e) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw Error(SB() << path << ": the generated entry does not load back (please report): "
                         << e.what());
    }
    return tmp;
}

struct Planned {
    EsiDevice dev;
    std::string path; // target file ("" when printing)
    std::string text;
    bool replaces_hand_written = false;
};

} // namespace

int run_esi_import(const EsiImportOptions& o, std::ostream& out, std::ostream& err) {
    bool failed = false;
    auto report = [&](const Error& e) {
        ErrorList l;
        l.add(e);
        for (const std::string& m : l.messages()) err << m << "\n";
        failed = true;
    };

    // The catalog the entries are for: its files decide the targets, its YAML devices the names.
    Catalog target;
    const Catalog* names = &target;
    std::unique_ptr<Catalog> builtin;
    if (!o.out.empty()) {
        std::error_code ec;
        if (fs::exists(o.out, ec) && !fs::is_directory(o.out, ec)) {
            err << o.out << ": --out should be a directory\n";
            return 1;
        }
        if (fs::is_directory(o.out, ec)) {
            std::vector<std::string> yaml;
            for (const auto& entry : fs::directory_iterator(o.out, ec)) {
                const std::string p = entry.path().string();
                if (entry.is_regular_file() && (p.ends_with(".yaml") || p.ends_with(".yml")))
                    yaml.push_back(p);
            }
            std::sort(yaml.begin(), yaml.end());
            for (const std::string& p : yaml) {
                try {
                    target.load_yaml(p);
                } catch (const Error&) {
                    // not a catalog entry we can read: never replaced without --force (below)
                }
            }
        }
    } else {
        try {
            builtin = std::make_unique<Catalog>();
            builtin->load_dir(Catalog::builtin_dir());
            names = builtin.get();
        } catch (const Error&) {
            names = &target; // no catalog: the ESI names
        }
    }

    // Read every file; a bad file is reported and left out.
    struct FileDevices {
        std::string file;
        std::vector<EsiDevice> devices;
    };
    std::vector<FileDevices> files;
    std::map<std::string, std::set<uint32_t>> revisions; // type -> revisions imported
    std::map<std::tuple<uint32_t, uint32_t, uint32_t>, SourceLoc> seen; // identity -> first
    for (const std::string& f : o.files) {
        try {
            FileDevices fd{f, read_esi(f)};
            ErrorList dup;
            for (const EsiDevice& d : fd.devices) {
                auto [it, fresh] = seen.emplace(
                    std::make_tuple(d.desc.vendor, d.desc.product, d.desc.revision), d.at);
                if (!fresh)
                    dup.add(d.at, SB() << "Device: " << d.desc.type << " revision "
                                       << hx(d.desc.revision, 8) << " is already imported from "
                                       << it->second.str());
            }
            dup.throw_if_any();
            for (const EsiDevice& d : fd.devices) revisions[d.desc.type].insert(d.desc.revision);
            files.push_back(std::move(fd));
        } catch (const Error& e) {
            report(e);
        }
    }

    // Plan each file's entries; a file with any error writes nothing.
    const bool printing = o.out.empty();
    size_t printed = 0, total = 0;
    for (const FileDevices& fd : files) total += fd.devices.size();
    for (FileDevices& fd : files) {
        std::vector<Planned> plan;
        ErrorList errors;
        for (EsiDevice& dev : fd.devices) {
            errors.capture([&] {
                DeviceDesc& d = dev.desc;
                names->ecmc_names(d);
                Planned p;
                // The file that has this identity already, else TYPE.yaml, or TYPE_rev... when
                // several revisions of the type are imported or TYPE.yaml holds another one.
                if (const DeviceDesc* have = target.find(d.vendor, d.product, d.revision))
                    p.path = target.source(have);
                else {
                    std::string name = catalog_file_name(d, revisions[d.type].size() > 1);
                    if (!printing && fs::exists(fs::path(o.out) / name)) // another device's file
                        name = catalog_file_name(d, true);
                    p.path = printing ? name : (fs::path(o.out) / name).string();
                }
                if (!printing && fs::exists(p.path) && !written_by_import(p.path)) {
                    if (!o.force)
                        throw Error(SB()
                                    << dev.at.str() << ": Device: " << d.type << " revision "
                                    << hx(d.revision, 8) << " would replace " << p.path
                                    << ", which beamctl esi import did not write: not replaced "
                                       "(--force replaces it)");
                    p.replaces_hand_written = true;
                }
                std::string header = SB()
                                     << kEsiImportHeader << " from "
                                     << fs::path(fd.file).filename().string() << ":" << dev.at.line
                                     << "; a later import of the same device replaces it.\n"
                                     << "# Remove these two lines before editing it by hand (the "
                                        "import leaves such files alone).\n";
                p.text = catalog_yaml(d, header, dev.init_cmds);
                p.dev = dev;
                plan.push_back(std::move(p));
            });
        }
        if (!errors.empty()) {
            report(MultiError(errors.messages()));
            continue;
        }
        if (printing) {
            for (const Planned& p : plan) {
                std::string tmp = (fs::temp_directory_path() /
                                   ("beamctl_esi_" + std::to_string(::getpid()) + ".yaml"))
                                      .string();
                try {
                    std::error_code ec;
                    fs::remove(write_checked(tmp, p.text, p.dev.desc), ec);
                } catch (const Error& e) {
                    report(e);
                    continue;
                }
                if (total > 1) out << (printed ? "\n" : "") << "# ==> " << p.path << " <==\n";
                out << p.text;
                ++printed;
            }
            continue;
        }
        // Write: every entry to a checked temporary file first, then all renamed in place.
        std::vector<std::pair<std::string, std::string>> ready; // tmp, path
        try {
            std::error_code ec;
            fs::create_directories(o.out, ec);
            if (ec) throw Error(SB() << o.out << ": cannot create: " << ec.message());
            for (const Planned& p : plan)
                ready.emplace_back(write_checked(p.path, p.text, p.dev.desc), p.path);
        } catch (const Error& e) {
            for (auto& [tmp, path] : ready) {
                std::error_code ec;
                fs::remove(tmp, ec);
            }
            report(e);
            continue;
        }
        for (size_t i = 0; i < plan.size(); ++i) {
            std::error_code ec;
            fs::rename(ready[i].first, ready[i].second, ec);
            if (ec) {
                report(Error(SB() << ready[i].second << ": cannot write: " << ec.message()));
                fs::remove(ready[i].first, ec);
                continue;
            }
            const DeviceDesc& d = plan[i].dev.desc;
            out << "wrote " << plan[i].path << " (" << d.type << " revision " << hx(d.revision, 8)
                << (plan[i].replaces_hand_written ? ", replaced a file the import did not write"
                                                  : "")
                << ")\n";
        }
    }
    if (printing && printed > 0)
        err << "nothing written: give --out DIR (e.g. --out catalog/) to write these entries\n";
    return failed ? 1 : 0;
}

} // namespace beamctl::ethercat
