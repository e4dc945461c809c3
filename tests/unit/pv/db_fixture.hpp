// A database test fixture: load .db text, then put and get through the database as a client would.
#pragma once

#include "pv/database.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace beamctl::pv {

struct DbTest : ::testing::Test {
    Database db;
    void load(const char* text, const char* file = "test.db") {
        db.load(parse_db(text, file, {}));
        db.init_records();
    }
    Address addr(const char* n) {
        Address a;
        EXPECT_TRUE(db.resolve(n, a)) << n;
        return a;
    }
    PutStatus put(const char* n, double v, PutCallback cb = {}) {
        return db.put(addr(n), Prim::Double, &v, 1, std::move(cb));
    }
    PutStatus put_str(const char* n, const char* s) {
        char buf[40] = {};
        std::strncpy(buf, s, 39);
        return db.put(addr(n), Prim::String, buf, 1);
    }
    double getd(const char* n) {
        double d = 0;
        db.get(addr(n), Prim::Double, &d, 1);
        return d;
    }
    std::string gets(const char* n) {
        char s[40];
        db.get(addr(n), Prim::String, s, 1);
        return s;
    }
    // The error that loading and initialising `text` gives, in a database of its own.
    static std::string load_error(const char* text) {
        Database fresh;
        try {
            fresh.load(parse_db(text, "bad.db", {}));
            fresh.init_records();
        } catch (const Error& e) {
            return e.what();
        }
        return "(no error)";
    }
};

} // namespace beamctl::pv
