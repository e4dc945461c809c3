// The module contract (ARCHITECTURE.md §3, docs/architecture.md): every subsystem is one folder
// that exports one module, and the IOC only drives modules. A module
//   1. is built from its own configuration section (the one YAML reader read it; its errors carry
//      file:line:col) — never from the whole IOC file;
//   2. declares its signals in the registry while it is built and resolves the addresses of its
//      own names for device support (`@name` of a record's INP/OUT);
//   3. loads the records of its PV tables (module/pv_table.hpp) while it is built;
//   4. adds its cycle stages to the cycle it runs in when the IOC is bound (bring-up), and starts
//      its non-RT work once the records are initialised;
//   5. publishes into its records on the IOC loop when its change notification wakes the loop
//      (change_fd), or on each look of the loop while it has none yet.
// Adding a subsystem is one folder and one line of the module table (src/ioc/modules.cpp).
// Threading: construction, bind() and start() before the cycle runs; make_device() and publish()
// on the IOC loop; the stages a module adds run on the RT thread of their cycle.
#pragma once

#include "pv/link.hpp"
#include "pv/record.hpp"

#include <functional>
#include <memory>
#include <string>
#include <string_view>

namespace beamctl::pv {
class Database;
}
namespace beamctl::registry {
class Registry;
}
namespace beamctl::rt {
class Engine;
}
namespace beamctl::motion {
class AxisGroup;
}
namespace beamctl::ethercat::sim {
struct BeamTally;
}

namespace beamctl::module {

// What a module is built with (IOC construction, configure time).
struct BuildContext {
    std::string prefix;          // the IOC's PV prefix ("DEMO:")
    std::string ioc_path;        // the IOC file (a section's relative paths are resolved against it)
    registry::Registry& signals; // declares signals (before the registry is frozen), claims outputs
    pv::Database& db;            // takes the records of the module's PV tables
    std::function<double()> loop_clock; // the IOC loop's clock [s] (what its records' scans see)
};

// What a module binds to (bring-up, before the cycle starts).
struct BindContext {
    rt::Engine& cycle;                  // the IOC's cycle (cycle 0): its stages run there
    const registry::Registry& signals;  // binds names to image cells (frozen by now)
    motion::AxisGroup* axes;            // the axes' variables (ax<n>.enc.actpos, ...), or none
    // The simulated beam of a bus in this process (bus -1: the first that has one); an empty
    // function when there is none.
    std::function<std::function<ethercat::sim::BeamTally()>(int bus)> beam_of;
};

// A record's device-support address that names one of the module's objects: `@<address>` in the
// INP/OUT of a record of type `record_type`.
struct DeviceRequest {
    pv::Record& record;
    std::string_view address;
    bool output; // an OUT link (else INP)
};

class Module {
public:
    virtual ~Module() = default;
    // "feedback": the section it is built from, and how errors and `signals` name it.
    virtual std::string_view name() const = 0;

    // 2. Device support: whether `@address` of a record of this type is one of this module's
    // objects. If so, make_device gives the record its device, or nullptr with `why`.
    virtual bool owns_device(std::string_view record_type, std::string_view address) const {
        (void)record_type, (void)address;
        return false;
    }
    virtual std::unique_ptr<pv::LinkDevice> make_device(const DeviceRequest& rq, std::string& why) {
        (void)rq;
        why = std::string(name()) + " makes no device support";
        return nullptr;
    }

    // 4. Bring-up: resolves its inputs and outputs in the cycle and adds its stages. Throws Error
    // naming file:line:col of the configuration it could not bind.
    virtual void bind(BindContext& ctx) { (void)ctx; }
    // After the records are initialised (PINI done): starts its non-RT work.
    virtual void start() {}

    // 5. The IOC loop's look at the module: publishes what changed into its records. `now_s`: the
    // loop's clock [s]. change_fd(): a descriptor that becomes readable when the RT side marked a
    // change (-1: none; the loop then calls publish on each of its looks).
    virtual void publish(double now_s) { (void)now_s; }
    virtual int change_fd() const { return -1; }
};

} // namespace beamctl::module
