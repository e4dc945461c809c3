// From an ECMC axis file (AxisConfig) to a running axis: its parameters in the runtime's units
// and its signals bound to process-image addresses. Configuration time, non-RT.
#pragma once

#include "motion/axis.hpp"
#include "motion/axis_config.hpp"

#include <functional>
#include <vector>

namespace beamctl::motion {

// Parameters of the axis; throws Error (with the file's place) for what the runtime cannot do
// yet (e.g. CSP mode, a PLC trajectory source).
AxisParams make_axis_params(const AxisConfig& c);

// Every signal link of the axis file that the runtime uses, for checking names before bring-up.
std::vector<SignalRef> axis_signal_refs(const AxisConfig& c);

// Resolves a link to its bound signal; throws Error naming ref.where when there is no such signal.
using SignalResolver = std::function<registry::BoundSignal(const SignalRef&)>;
AxisIo bind_axis_io(const AxisConfig& c, const SignalResolver& resolve);

} // namespace beamctl::motion
