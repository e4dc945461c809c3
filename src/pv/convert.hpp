// Value conversions between record field storage and Channel Access primitive types, and between
// field values and .db text. Same rules as EPICS dbConvert/dbFastLinkConv: enums read as their
// state strings, strings written to enums match a state name or a number, numbers format with PREC.
#pragma once

#include "pv/record.hpp"

#include <string>
#include <string_view>

namespace beamctl::pv {

// Reads element i of e as type p into dest (host byte order; a string is char[40]).
void get_element(const Record& r, const FieldDesc& f, const Elements& e, uint32_t i, Prim p,
                 void* dest);
// Writes element i from src of type p. Returns false (element unchanged) if src can't be converted.
bool put_element(Record& r, const FieldDesc& f, const Elements& e, uint32_t i, Prim p,
                 const void* src);

// Field value from .db text; on failure returns false and sets *err (nothing changed).
bool parse_field(Record& r, const FieldDesc& f, std::string_view text, std::string* err);
// Field value as .db text (full precision, enum/menu fields as their choice string).
std::string format_field(Record& r, const FieldDesc& f);

// Number formatting as EPICS cvtDoubleToString: fixed with `prec` decimals, %g when huge/NaN.
void format_double(double v, int prec, char* out, std::size_t size);
// Strict number parsing: the whole text (surrounding blanks allowed) must be a number.
bool parse_double(std::string_view s, double& out);
bool parse_int(std::string_view s, int64_t& out); // decimal or 0x hex

} // namespace beamctl::pv
