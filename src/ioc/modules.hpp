// The module table: every subsystem the IOC drives through the module contract
// (module/module.hpp), in the order the IOC builds and binds them (a module may use the signals of
// the modules before it: the feedback loops read the electrometers' values). Adding a subsystem
// is its folder and one line of this table (modules.cpp).
#pragma once

#include "config/ioc_config.hpp"
#include "module/module.hpp"

#include <memory>
#include <span>

namespace beamctl::ioc {

struct ModuleEntry {
    const char* section; // its part of the IOC file
    // The module built from its section, or nullptr when the file has none.
    std::unique_ptr<module::Module> (*make)(const config::IocConfig& cfg, module::BuildContext& ctx);
};

std::span<const ModuleEntry> module_table();

} // namespace beamctl::ioc
