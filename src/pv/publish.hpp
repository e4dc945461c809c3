// The owner's writes into records: the code that owns a record's value (a device, an IOC
// subsystem, automation) sets VAL, an array or a text, bypassing the client put rules, and
// processes the record (monitors, links). And reading a record's VAL back. Database thread only.
#pragma once

#include "pv/convert.hpp"
#include "pv/database.hpp"

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace beamctl::pv {

// Sets a record's VAL from the owner of the value (bypasses the client put hook) and processes.
inline void set_value(Database& db, Record& r, double v, bool comm_alarm) {
    const FieldDesc* f = r.type().find("VAL");
    Elements e = r.elements(*f);
    put_element(r, *f, e, 0, Prim::Double, &v);
    r.udf = 0;
    if (comm_alarm) r.set_sevr(kStatComm, kInvalid);
    db.process(r);
}

// Sets an array record's elements (and NORD) from the owner of the values, and processes it.
inline void set_array(Database& db, Record& r, const double* v, uint32_t n) {
    const FieldDesc* f = r.type().find("VAL");
    Elements e = r.elements(*f);
    n = n < e.capacity ? n : e.capacity;
    for (uint32_t i = 0; i < n; ++i) put_element(r, *f, e, i, Prim::Double, &v[i]);
    r.set_count(*f, n);
    r.udf = 0;
    db.process(r);
}

// Sets an array record's elements from raw values of its own element type (n elements of
// FTVL's size at `data`: a camera's pixels into an image waveform) and processes it.
inline void set_array_raw(Database& db, Record& r, const void* data, uint32_t n) {
    const FieldDesc* f = r.type().find("VAL");
    Elements e = r.elements(*f);
    n = n < e.capacity ? n : e.capacity;
    std::memcpy(e.data, data, std::size_t(n) * e.stride);
    r.set_count(*f, n);
    r.udf = 0;
    db.process(r);
}

// A CHAR waveform's text (up to its first NUL) and setting it (the owner's write; processes).
inline std::string get_text(const Record& r) {
    const FieldDesc* f = r.type().find("VAL");
    Elements e = const_cast<Record&>(r).elements(*f);
    std::string s;
    for (uint32_t i = 0; i < e.count; ++i) {
        double v = 0;
        get_element(r, *f, e, i, Prim::Double, &v);
        if (v == 0) break;
        s += char(int(v));
    }
    return s;
}

inline void set_text(Database& db, Record& r, const std::string& t) {
    std::vector<double> c(t.begin(), t.end());
    c.push_back(0);
    set_array(db, r, c.data(), uint32_t(c.size()));
}

// A record's VAL as a double.
inline double get_value(const Record& r) {
    const FieldDesc* f = r.type().find("VAL");
    double v = 0;
    Elements e = const_cast<Record&>(r).elements(*f);
    get_element(r, *f, e, 0, Prim::Double, &v);
    return v;
}

// A string record's (stringin/stringout) VAL, at most 39 characters, set by its owner; processes.
inline void set_string(Database& db, Record& r, const std::string& text) {
    char s[kStringSize] = {};
    std::strncpy(s, text.c_str(), sizeof s - 1);
    const FieldDesc* f = r.type().find("VAL");
    Elements e = r.elements(*f);
    put_element(r, *f, e, 0, Prim::String, s);
    r.udf = 0;
    db.process(r);
}

} // namespace beamctl::pv
