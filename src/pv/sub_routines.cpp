#include "pv/sub_routines.hpp"

#include "core/error.hpp"

#include <dlfcn.h>

namespace beamctl::pv {

RecordRoutines& RecordRoutines::global() {
    static RecordRoutines* r = [] { // never destroyed: routines may run until exit
        auto* routines = new RecordRoutines;
        add_builtin_routines(*routines);
        return routines;
    }();
    return *r;
}

void RecordRoutines::load(const std::string& path) {
    for (const auto& l : libraries_)
        if (l == path) return;
    void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!h) {
        const char* e = dlerror();
        throw Error(SB() << path << ": cannot load: " << (e ? e : "dlopen failed"));
    }
    auto fail = [&](std::string msg) {
        dlclose(h);
        throw Error(SB() << path << ": " << msg);
    };
    dlerror();
    auto get = reinterpret_cast<beamctl_record_routines_get_fn>(dlsym(h, BEAMCTL_RECORD_ROUTINES_ENTRY));
    if (!get) fail(SB() << "exports no " << BEAMCTL_RECORD_ROUTINES_ENTRY << "() (not a library of sub/aSub routines)");
    const beamctl_record_routines* t = get();
    if (!t) fail(SB() << BEAMCTL_RECORD_ROUTINES_ENTRY << "() returned NULL");
    if (t->abi_version != BEAMCTL_RECORD_ROUTINES_ABI_VERSION)
        fail(SB() << "built for record routines ABI version " << t->abi_version << ", this beamctl has version "
                  << BEAMCTL_RECORD_ROUTINES_ABI_VERSION << " (rebuild it against include/beamctl/record_routines.h)");
    std::vector<Routine> fresh;
    for (const beamctl_record_routine* r = t->routines; r && r->name; ++r) {
        if (!*r->name || (!r->sub == !r->asub))
            fail(SB() << "routine '" << r->name << "' must have a name and exactly one of sub and asub");
        if (const Routine* old = find(r->name))
            fail(SB() << "routine '" << r->name << "' is already provided by "
                      << (old->library.empty() ? std::string("beamctl") : old->library));
        for (const auto& f : fresh)
            if (f.name == r->name) fail(SB() << "routine '" << r->name << "' is defined twice");
        fresh.push_back(Routine{r->name, r->sub, r->asub, path});
    }
    for (auto& r : fresh) routines_.push_back(std::move(r));
    libraries_.push_back(path);
}

void RecordRoutines::add(Routine r) {
    if (find(r.name)) throw Error(SB() << "record routine '" << r.name << "' is registered twice");
    routines_.push_back(std::move(r));
}

const RecordRoutines::Routine* RecordRoutines::find(std::string_view name) const {
    for (const auto& r : routines_)
        if (r.name == name) return &r;
    return nullptr;
}

std::string RecordRoutines::describe() const {
    if (routines_.empty() && libraries_.empty()) return "none loaded (load a library with dlload in the startup script)";
    SB sb;
    bool first_lib = true;
    auto list = [&](const std::string& lib) {
        if (!first_lib) sb << "; ";
        first_lib = false;
        sb << (lib.empty() ? std::string("built in") : lib) << " (";
        bool first = true;
        for (const auto& r : routines_)
            if (r.library == lib) {
                sb << (first ? "" : ", ") << r.name << (r.sub ? " sub" : " aSub");
                first = false;
            }
        sb << ")";
    };
    bool builtin = false;
    for (const auto& r : routines_) builtin |= r.library.empty();
    if (builtin) list("");
    for (const auto& l : libraries_) list(l);
    return sb;
}

std::string missing_routine_message(std::string_view field, std::string_view routine, std::string_view kind) {
    return SB() << field << " '" << routine << "': no loaded library provides a " << kind
                << " routine of that name; routines: " << RecordRoutines::global().describe();
}

} // namespace beamctl::pv
