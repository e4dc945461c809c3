// Plugins (include/beamctl/plugin.h, a C ABI): loaded with dlopen, the ABI version checked, then
// constructed with their configuration; their functions and constants are found by name (PLC
// code binds the ones its text uses) and their RT callbacks are called by the engine.
// Threading: load/unload and rt_enter/rt_exit on a non-RT thread; realtime() and the functions on
// the RT thread.
#pragma once

#include "beamctl/plugin.h"

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::plc {

class Plugin {
public:
    struct Function {
        std::string name, desc;
        int nargs = 0;
        double (*fn)(const double* args) = nullptr;
    };
    struct Constant {
        std::string name, desc;
        double value = 0;
    };

    // Loads, checks and constructs. Throws Error naming the file and what is wrong: it cannot be
    // opened (dlerror), has no beamctl_plugin_get, was built for another ABI version (both
    // numbers), construct() failed (its code), or a function entry is malformed.
    static std::unique_ptr<Plugin> load(const std::string& path, const std::string& config = "");
    ~Plugin(); // destruct() (after rt_exit() if still entered), then dlclose

    const std::string& path() const { return path_; }
    std::string name() const { return desc_->name ? desc_->name : ""; }
    std::string description() const { return desc_->description ? desc_->description : ""; }
    uint32_t version() const { return desc_->version; }
    const std::vector<Function>& functions() const { return functions_; }
    const std::vector<Constant>& constants() const { return constants_; }
    const Function* function(std::string_view name) const;
    std::optional<double> constant(std::string_view name) const;

    int rt_enter();                      // 0 or the plugin's code
    int rt_exit();
    int realtime(int error_code) noexcept; // RT, once per cycle

private:
    Plugin() = default;
    std::string path_;
    void* handle_ = nullptr;
    const beamctl_plugin* desc_ = nullptr;
    std::vector<Function> functions_;
    std::vector<Constant> constants_;
    bool entered_ = false, constructed_ = false;
};

} // namespace beamctl::plc
