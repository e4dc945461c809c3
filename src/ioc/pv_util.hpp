// Small helpers the IOC uses to generate records and to publish values into them (IOC loop).
#pragma once

#include "pv/convert.hpp"
#include "pv/database.hpp"
#include "pv/db_file.hpp"

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

namespace beamctl::ioc {

// A generated record definition.
inline pv::DbRecord record(const std::string& type, const std::string& name,
                           const std::vector<std::pair<std::string, std::string>>& fields) {
    return pv::generated_record(type, name, fields);
}

// Sets a record's VAL from the owner of the value (bypasses the client put hook) and processes.
inline void set_value(pv::Database& db, pv::Record& r, double v, bool comm_alarm) {
    const pv::FieldDesc* f = r.type().find("VAL");
    pv::Elements e = r.elements(*f);
    pv::put_element(r, *f, e, 0, pv::Prim::Double, &v);
    r.udf = 0;
    if (comm_alarm) r.set_sevr(pv::kStatComm, pv::kInvalid);
    db.process(r);
}

// Sets an array record's elements (and NORD) from the owner of the values, and processes it.
inline void set_array(pv::Database& db, pv::Record& r, const double* v, uint32_t n) {
    const pv::FieldDesc* f = r.type().find("VAL");
    pv::Elements e = r.elements(*f);
    n = n < e.capacity ? n : e.capacity;
    for (uint32_t i = 0; i < n; ++i) pv::put_element(r, *f, e, i, pv::Prim::Double, &v[i]);
    r.set_count(*f, n);
    r.udf = 0;
    db.process(r);
}

// Sets an array record's elements from raw values of its own element type (n elements of
// FTVL's size at `data`: a camera's pixels into an image waveform) and processes it.
inline void set_array_raw(pv::Database& db, pv::Record& r, const void* data, uint32_t n) {
    const pv::FieldDesc* f = r.type().find("VAL");
    pv::Elements e = r.elements(*f);
    n = n < e.capacity ? n : e.capacity;
    std::memcpy(e.data, data, std::size_t(n) * e.stride);
    r.set_count(*f, n);
    r.udf = 0;
    db.process(r);
}

// A CHAR waveform's text (up to its first NUL) and setting it (the owner's write; processes).
inline std::string get_text(const pv::Record& r) {
    const pv::FieldDesc* f = r.type().find("VAL");
    pv::Elements e = const_cast<pv::Record&>(r).elements(*f);
    std::string s;
    for (uint32_t i = 0; i < e.count; ++i) {
        double v = 0;
        pv::get_element(r, *f, e, i, pv::Prim::Double, &v);
        if (v == 0) break;
        s += char(int(v));
    }
    return s;
}

inline void set_text(pv::Database& db, pv::Record& r, const std::string& t) {
    std::vector<double> c(t.begin(), t.end());
    c.push_back(0);
    set_array(db, r, c.data(), uint32_t(c.size()));
}

// An instance number as ecmccfg's PV names write it: "03" (PLC03-..., DS03-...).
inline std::string two_digits(int id) {
    char b[16];
    std::snprintf(b, sizeof b, "%02d", id);
    return b;
}

// A counter as a 32-bit LONG PV value: saturates instead of wrapping.
inline double clamp_long(uint64_t v) { return double(v < 0x7FFFFFFFu ? v : 0x7FFFFFFFu); }

// A record's VAL as a double.
inline double get_value(const pv::Record& r) {
    const pv::FieldDesc* f = r.type().find("VAL");
    double v = 0;
    pv::Elements e = const_cast<pv::Record&>(r).elements(*f);
    pv::get_element(r, *f, e, 0, pv::Prim::Double, &v);
    return v;
}

} // namespace beamctl::ioc
