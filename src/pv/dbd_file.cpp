#include "pv/dbd_file.hpp"

#include "pv/convert.hpp"

#include <algorithm>
#include <ostream>

namespace beamctl::pv {

void write_dbd(std::ostream& os, const RecordTypes& types) {
    std::vector<std::string> names = types.names();
    std::sort(names.begin(), names.end());
    for (const std::string& n : names) {
        const RecordType* t = types.find(n);
        auto def = t->create(); // the type's initial values
        os << "recordtype(" << n << ") {\n";
        for (const FieldDesc& f : t->fields()) {
            os << "    field(" << f.name << "," << dbf_name(f.dbf) << ")";
            std::string attrs;
            if (f.menu) attrs += std::string(" menu(") + f.menu->name + ")";
            if (f.flags & kReadOnly) attrs += " special(SPC_NOMOD)";
            else if (f.flags & kInitOnly) attrs += " special(SPC_NOMOD) # settable in a .db file";
            if (f.flags & kProcess) attrs += " pp(TRUE)";
            if (!(f.flags & kArray) && !is_link(f.dbf)) {
                std::string v = format_field(*def, f);
                if (!v.empty() && v != "0" && !(f.dbf == Dbf::Double && v == "0.0")) {
                    std::string q;
                    for (char c : v) {
                        if (c == '"' || c == '\\') q += '\\';
                        q += c;
                    }
                    attrs = " initial(\"" + q + "\")" + attrs;
                }
            }
            if (!attrs.empty()) os << " {" << attrs << " }";
            os << "\n";
        }
        os << "}\n";
    }
}

} // namespace beamctl::pv
