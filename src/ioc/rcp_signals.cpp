#include "ioc/rcp_signals.hpp"

#include "core/error.hpp"
#include "core/log.hpp"

namespace beamctl::ioc {
namespace {
log::Logger lg("ioc.rcp");

const char* etg_type(bridge::rcp::DataType t) {
    using D = bridge::rcp::DataType;
    switch (t) {
    case D::Bool: return "BOOL";
    case D::Int8: return "SINT";
    case D::UInt8: return "USINT";
    case D::Int16: return "INT";
    case D::UInt16: return "UINT";
    case D::Int32: return "DINT";
    case D::UInt32: return "UDINT";
    case D::Float32: return "REAL";
    case D::Float64: return "LREAL";
    }
    return "?";
}
} // namespace

registry::Signal rcp_signal(const bridge::rcp::BridgeConfig::ObjectEvent& e) {
    registry::Signal s;
    s.name = "rcp." + e.application + "." + e.name;
    s.type = etg_type(e.data_type);
    const bool motor = e.type == bridge::rcp::ObjectType::Motor; // its data: 5 values of one axis
    if (e.count > 1 && !motor) s.type += "[" + std::to_string(e.count) + "]";
    // an input object is the machine's; an output or a motor is set by its PV's clients
    s.direction = bridge::rcp::is_output(e.type) || motor ? registry::Direction::Variable : registry::Direction::Input;
    s.owner_kind = registry::OwnerKind::Bridge;
    s.owner = std::string("rcp ") + e.application + " (" + bridge::rcp::to_string(e.type) + ")";
    s.pv = e.pv;
    s.loop_only = true;
    return s;
}

void on_rcp_object(registry::Registry& reg, const bridge::rcp::BridgeConfig::ObjectEvent& e) {
    registry::Signal s = rcp_signal(e);
    if (!e.added) {
        reg.withdraw(s.name);
        return;
    }
    try {
        reg.declare_runtime(std::move(s));
    } catch (const Error& err) {
        LOG_WARN(lg, "RCP object not in the signal registry: " << err.what());
    }
}

} // namespace beamctl::ioc
