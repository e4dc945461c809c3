#include "module/pv_table.hpp"

#include "core/error.hpp"

#include <sstream>

namespace beamctl::module {

bool is_output_type(std::string_view type) {
    for (std::string_view t : {"ao", "bo", "longout", "mbbo", "mbboDirect", "stringout", "int64out", "lso"})
        if (type == t) return true;
    return false;
}

namespace {

bool has_field(const PvRow& r, std::string_view name) {
    for (const auto& [k, v] : r.fields)
        if (name == k) return true;
    return false;
}

// The fields a row's record gets: device support for a row with a signal, then the row's own,
// with the instance's macros expanded (`macros` null: as written, for to_db_text).
std::vector<std::pair<std::string, std::string>> row_fields(const PvRow& r, const std::string& signal_prefix,
                                                            const MacroMap* macros) {
    auto text = [&](const char* v) { return macros ? expand_macros(v, *macros, MacroEscapes::unescape) : std::string(v); };
    std::vector<std::pair<std::string, std::string>> f;
    if (*r.signal) {
        bool out = is_output_type(r.type);
        f.emplace_back("DTYP", "beamctl");
        f.emplace_back(out ? "OUT" : "INP", "@" + signal_prefix + text(r.signal));
        if (!out && !has_field(r, "SCAN")) f.emplace_back("SCAN", "I/O Intr");
    }
    for (const auto& [k, v] : r.fields) f.emplace_back(k, text(v));
    return f;
}

} // namespace

pv::DbFile make_records(const PvTable& t, const PvInstance& in, const registry::Registry& signals) {
    pv::DbFile file;
    for (const PvRow& row : t.rows) {
        if (*row.signal) {
            int bit = -1;
            std::string name = in.signal_prefix + expand_macros(row.signal, in.macros, MacroEscapes::unescape);
            if (!signals.find_with_bit(name, bit))
                throw Error(SB() << "PV table '" << t.name << "', row " << row.suffix << ": no signal '" << name << "'");
        }
        pv::DbRecord r;
        r.type = row.type;
        r.name = in.pv_prefix + row.suffix;
        r.loc = SourceLoc{std::string("<table ") + t.name + ">", 1, 1};
        for (auto& [k, v] : row_fields(row, in.signal_prefix, &in.macros)) r.fields.push_back(pv::DbField{k, v, r.loc});
        if (row.readback) r.infos.push_back(pv::DbInfo{"asyn:READBACK", "1", r.loc});
        file.records.push_back(std::move(r));
    }
    return file;
}

void name_pvs(const PvTable& t, const PvInstance& in, registry::Registry& signals) {
    for (const PvRow& row : t.rows) {
        if (!*row.signal) continue;
        std::string name = in.signal_prefix + expand_macros(row.signal, in.macros, MacroEscapes::unescape);
        const registry::Signal* s = signals.find(name); // a bit ("status.1") is not the signal's PV
        if (s && s->pv.empty()) signals.set_pv(name, in.pv_prefix + row.suffix);
    }
}

std::string to_db_text(const PvTable& t) {
    std::ostringstream os;
    for (const PvRow& row : t.rows) {
        os << "record(" << row.type << ", \"$(P)" << row.suffix << "\") {\n";
        auto f = row_fields(row, "$(S)", nullptr);
        for (const auto& [k, v] : f) os << "  field(" << k << ", \"" << v << "\")\n";
        if (row.readback) os << "  info(asyn:READBACK, \"1\")\n";
        os << "}\n";
    }
    return os.str();
}

} // namespace beamctl::module
