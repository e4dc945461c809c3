// The signal registry (ARCHITECTURE.md §1, §3): every value of the engine under its one ECMC-style
// name (`ec0.s3.positionActual01`, `ax1.enc.actpos`, `plc0.enable`), with its data type, direction,
// owner, its one writer if it is an output, and the PV that serves it. Subsystems declare their
// signals while the IOC is built; the registry is then frozen, and PLC binding, device support
// of records, the PV tables and `beamctl signals` look names up here and nowhere else.
// Threading: declared, claimed and bound on the thread that builds the IOC (claims also on the IOC
// loop, when a record is relinked); nothing here is touched by the RT cycle.
#pragma once

#include "registry/signal.hpp"

#include <functional>
#include <map>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::registry {

enum class Direction : uint8_t {
    Input,    // produced by its owner every cycle (a bus input, an axis readback): anyone reads it
    Output,   // sent by its owner every cycle (a bus output): exactly one writer
    Variable, // a cell others may write between cycles (an axis command, a PLC's enable)
};
enum class OwnerKind : uint8_t { Bus, Axis, Plc, Bridge, Record, Engine };

const char* direction_name(Direction d);
const char* owner_kind_name(OwnerKind k);

struct Signal {
    std::string name;
    std::string type; // data type of a bus entry, ETG.1020 (UINT, DINT, REAL, ...) or the catalog's CoE name (INT32, REAL64, ...); LREAL for engine variables
    Direction direction = Direction::Input;
    OwnerKind owner_kind = OwnerKind::Bus;
    std::string owner;  // "ec0", "axis 1 (SampleX)", "plc0"
    std::string writer; // Output: who writes it ("axis 1 (SampleX)", "plc0", "record X"); empty: its PV (CA)
    std::string pv;     // the PV that serves it ("" if none)
    bool loop_only = false; // a value of the IOC loop (a bus's frame counters, the engine's
                            // statistics, an RCP object): records read it; the cycle (PLC code,
                            // axes) cannot
    bool runtime = false;   // declared while the IOC runs (declare_runtime), may be withdrawn
};

class Registry {
public:
    // Binds a declared signal (and a bit of it, -1 for the whole entry) to its place in the
    // process image; installed by the owner of a name prefix ("ec0."). Empty result with `why`
    // set when it cannot (the bus is not up yet, the layout differs from the catalog's).
    using Binder = std::function<BoundSignal(const Signal& s, int bit, std::string& why)>;

    // Adds a signal. Throws Error if the name is taken (naming both owners) or the registry is frozen.
    const Signal& declare(Signal s);
    void set_binder(std::string prefix, Binder b);
    // A signal of the IOC loop that appears and goes while the IOC runs (an object a prototyping
    // machine's beacon announced to the RCP bridge): allowed after freeze() because the cycle
    // never sees it (it must be loop_only). Throws Error if the name is taken or it is not loop_only.
    const Signal& declare_runtime(Signal s);
    // Removes a signal declared by declare_runtime (the bridge's object went); other names: no-op.
    void withdraw(std::string_view name);
    // No more declarations of signals the cycle sees: what the cycle will see is fixed.
    void freeze() { frozen_ = true; }
    bool frozen() const { return frozen_; }

    const Signal* find(std::string_view name) const;
    // A name with an optional bit suffix ("ec0.s3.binaryInput01.2" -> the entry, bit 2); nullptr
    // if the entry is not declared. `bit` is -1 without a suffix.
    const Signal* find_with_bit(std::string_view name, int& bit) const;
    // Binds "name[.bit]" through its owner's binder; unbound with `why` if it is not declared,
    // the bit is out of range or the owner cannot bind it.
    BoundSignal bind(std::string_view name, std::string& why) const;

    // One writer per output: makes `writer` the writer of the output `name`. False with `why`
    // naming the signal and its writer if another one has it (the same writer again is fine),
    // or if `name` is not a declared output.
    bool claim(std::string_view name, const std::string& writer, std::string& why);
    // Forgets the writer of `name` if it is `writer` (a record relinked elsewhere).
    void release(std::string_view name, const std::string& writer);
    void set_pv(std::string_view name, std::string pv);

    // Signals whose name matches a glob pattern (`*`, `?`; empty matches all), by name.
    std::vector<const Signal*> match(std::string_view pattern) const;
    std::size_t size() const { return signals_.size(); }
    // The `beamctl signals` table: name, type, direction, owner, writer, PV.
    void print(std::ostream& os, std::string_view pattern = {}) const;

private:
    Signal* find_mut(std::string_view name);
    const Signal& insert(Signal s); // declare and declare_runtime: a new name, or Error naming both owners
    std::map<std::string, Signal, std::less<>> signals_;
    std::vector<std::pair<std::string, Binder>> binders_;
    bool frozen_ = false;
};

} // namespace beamctl::registry
