// libFuzzer: arbitrary bytes as what reaches an IOC from outside the CA port: the lines of a
// `beamctl shell` client (pv::DbShell::execute on the shared fuzz database; dbpf may change it,
// dbtr process it) and the text of an autosave .sav file (pv::parse_save_file, read at start from
// a file anybody with write access to the directory may have edited). Must never crash or hang;
// a .sav error names the file and a line inside the text.
#include "fuzz_db.hpp"
#include "pv/autosave.hpp"
#include "pv/db_shell.hpp"

#include <cstdint>
#include <cstring>
#include <sstream>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl;
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    static pv::DbShell shell(fuzz_database(), {[](int level, std::ostream& os) { os << level; }});
    std::size_t pos = 0;
    while (pos < text.size()) { // each line, as the socket server hands them over
        std::size_t nl = text.find('\n', pos);
        std::string_view line = text.substr(pos, nl == std::string_view::npos ? text.npos : nl - pos);
        pos = nl == std::string_view::npos ? text.size() : nl + 1;
        std::ostringstream os;
        shell.execute(line, os);
    }
    try {
        auto values = pv::parse_save_file(text, "fuzz.sav");
        for (const auto& v : values)
            if (v.name.empty() || v.line < 1) __builtin_trap();
    } catch (const Error& e) {
        if (std::strncmp(e.what(), "fuzz.sav:", 9) != 0) __builtin_trap();
    }
    return 0;
}
