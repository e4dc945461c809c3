// The module helpers (module/pv_util.hpp) by their short names, for the IOC's own record code.
#pragma once

#include "module/pv_util.hpp"

namespace beamctl::ioc {
using module::clamp_long;
using module::get_text;
using module::get_value;
using module::record;
using module::set_array;
using module::set_array_raw;
using module::set_text;
using module::set_value;
using module::two_digits;
} // namespace beamctl::ioc
