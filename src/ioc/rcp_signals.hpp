// The RCP bridge's objects in the signal registry: each object a prototyping machine's beacon
// announces is declared, while the IOC runs, as `rcp.<application>.<object>` (owner kind Bridge,
// its PV, loop_only: records reach it through its PV; the cycle never sees it), and withdrawn when
// the object goes. `beamctl shell` → `signals rcp.*` lists them.
// Threading: the IOC loop (the bridge's thread).
#pragma once

#include "bridge/rcp/bridge_core.hpp"
#include "registry/registry.hpp"

#include <string>

namespace beamctl::ioc {

// The registry entry of an object (name, ETG type of its data type, direction, owner, PV).
registry::Signal rcp_signal(const bridge::rcp::BridgeConfig::ObjectEvent& e);
// Declares (e.added) or withdraws the object's signal; a clash with a name already declared is
// logged and the object keeps its PVs.
void on_rcp_object(registry::Registry& reg, const bridge::rcp::BridgeConfig::ObjectEvent& e);

} // namespace beamctl::ioc
