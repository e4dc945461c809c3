// A database on a virtual clock for automation's unit tests: run() steps it as the IOC loop does
// (every 10 ms: the periodic scans, where motor records poll their drivers, then the automation
// under test), put()/get() a field as a double.
#pragma once

#include "pv/database.hpp"

#include <functional>
#include <stdexcept>
#include <string>

namespace beamctl::test {

struct DbRig {
    pv::Database db;
    double now = 0;              // virtual time [s]
    std::function<void()> poll;  // the automation under test, every 10 ms

    void run(double seconds) {
        for (double end = now + seconds; now < end;) {
            now += 0.01;
            db.scan_periodic(now);
            if (poll) poll();
        }
    }
    pv::Address addr(const std::string& n) const {
        pv::Address a;
        if (!db.resolve(n, a)) throw std::runtime_error("no PV " + n);
        return a;
    }
    pv::PutStatus put(const std::string& n, double v, pv::PutCallback cb = {}) {
        return db.put(addr(n), pv::Prim::Double, &v, 1, std::move(cb));
    }
    double get(const std::string& n) const {
        double x = 0;
        db.get(addr(n), pv::Prim::Double, &x, 1);
        return x;
    }
};

} // namespace beamctl::test
