#include "plc/plugin.hpp"

#include "core/error.hpp"

#include <dlfcn.h>

namespace beamctl::plc {

std::unique_ptr<Plugin> Plugin::load(const std::string& path, const std::string& config) {
    std::unique_ptr<Plugin> p(new Plugin);
    p->path_ = path;
    p->handle_ = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!p->handle_) {
        const char* e = dlerror();
        throw Error(SB() << path << ": cannot load plugin: " << (e ? e : "dlopen failed"));
    }
    dlerror();
    auto get = reinterpret_cast<beamctl_plugin_get_fn>(dlsym(p->handle_, BEAMCTL_PLUGIN_ENTRY));
    if (!get)
        throw Error(SB() << path << ": not a beamctl plugin: it exports no " << BEAMCTL_PLUGIN_ENTRY << "()");
    p->desc_ = get();
    if (!p->desc_) throw Error(SB() << path << ": " << BEAMCTL_PLUGIN_ENTRY << "() returned NULL");
    if (p->desc_->abi_version != BEAMCTL_PLUGIN_ABI_VERSION)
        throw Error(SB() << path << ": plugin '" << (p->desc_->name ? p->desc_->name : "?") << "' was built for plugin ABI version "
                         << p->desc_->abi_version << ", this beamctl has version " << BEAMCTL_PLUGIN_ABI_VERSION
                         << " (rebuild it against this beamctl's include/beamctl/plugin.h)");
    if (!p->desc_->name || !*p->desc_->name) throw Error(SB() << path << ": the plugin has no name");
    for (int i = 0; i < BEAMCTL_PLUGIN_MAX_FUNCTIONS && p->desc_->functions[i].name; ++i) {
        const beamctl_plugin_function& f = p->desc_->functions[i];
        if (!f.fn || f.nargs < 0 || f.nargs > BEAMCTL_PLUGIN_MAX_ARGS)
            throw Error(SB() << path << ": plugin function '" << f.name << "' should have a function pointer and 0.."
                             << BEAMCTL_PLUGIN_MAX_ARGS << " arguments (has " << f.nargs << ")");
        if (p->function(f.name)) throw Error(SB() << path << ": plugin function '" << f.name << "' is defined twice");
        p->functions_.push_back(Function{f.name, f.desc ? f.desc : "", f.nargs, f.fn});
    }
    for (int i = 0; i < BEAMCTL_PLUGIN_MAX_CONSTANTS && p->desc_->constants[i].name; ++i) {
        const beamctl_plugin_constant& c = p->desc_->constants[i];
        p->constants_.push_back(Constant{c.name, c.desc ? c.desc : "", c.value});
    }
    if (p->desc_->construct) {
        int rc = p->desc_->construct(config.c_str());
        if (rc != 0)
            throw Error(SB() << path << ": plugin '" << p->desc_->name << "' refused its configuration '" << config
                             << "' (construct returned " << rc << ")");
    }
    p->constructed_ = true;
    return p;
}

Plugin::~Plugin() {
    if (entered_) rt_exit();
    if (constructed_ && desc_ && desc_->destruct) desc_->destruct();
    if (handle_) dlclose(handle_);
}

const Plugin::Function* Plugin::function(std::string_view name) const {
    for (const auto& f : functions_)
        if (f.name == name) return &f;
    return nullptr;
}

std::optional<double> Plugin::constant(std::string_view name) const {
    for (const auto& c : constants_)
        if (c.name == name) return c.value;
    return std::nullopt;
}

int Plugin::rt_enter() {
    int rc = desc_->rt_enter ? desc_->rt_enter() : 0;
    entered_ = rc == 0;
    return rc;
}

int Plugin::rt_exit() {
    entered_ = false;
    return desc_->rt_exit ? desc_->rt_exit() : 0;
}

int Plugin::realtime(int error_code) noexcept { return desc_->realtime ? desc_->realtime(error_code) : 0; }

} // namespace beamctl::plc
