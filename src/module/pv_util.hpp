// Small helpers modules use to generate records and to publish values into them (IOC loop).
#pragma once

#include "pv/db_file.hpp"
#include "pv/publish.hpp"

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::module {

// A generated record definition.
inline pv::DbRecord record(const std::string& type, const std::string& name,
                           const std::vector<std::pair<std::string, std::string>>& fields) {
    return pv::generated_record(type, name, fields);
}

// The owner's writes into records (set_value, set_array, set_text, ...): pv/publish.hpp.
using pv::get_text;
using pv::get_value;
using pv::set_array;
using pv::set_array_raw;
using pv::set_text;
using pv::set_value;

// An instance number as ecmccfg's PV names write it: "03" (PLC03-..., DS03-...).
inline std::string two_digits(int id) {
    char b[16];
    std::snprintf(b, sizeof b, "%02d", id);
    return b;
}

// A counter as a 32-bit LONG PV value: saturates instead of wrapping.
inline double clamp_long(uint64_t v) { return double(v < 0x7FFFFFFFu ? v : 0x7FFFFFFFu); }

} // namespace beamctl::module
