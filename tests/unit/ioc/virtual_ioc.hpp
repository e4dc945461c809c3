// A whole IOC built from an IOC file and brought up on a virtual clock: the unit tests' way to
// run the engine cycle by cycle (buses simulated in-process).
#pragma once

#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "motion/axis.hpp"
#include "plc/runtime.hpp"
#include "pv/convert.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>

namespace beamctl::test {

struct VirtualIoc {
    rt::VirtualClock clock;
    std::unique_ptr<ioc::Ioc> ioc;
    explicit VirtualIoc(const std::string& path) {
        ioc = std::make_unique<ioc::Ioc>(config::IocConfig::load(path), clock);
        ioc->bring_up();
    }
    void cycles(int n) { ioc->run_cycles(uint64_t(n)); }
    plc::PlcRuntime& plcs() { return *ioc->plcs().runtime(); }
    // A static variable of PLC `plc` (index in the runtime: general PLCs first).
    double stat(std::size_t plc, const std::string& name) {
        const double* v = ioc->plcs().static_variable(plc, name);
        if (!v) throw std::runtime_error("no static " + name);
        return *v;
    }
    motion::Axis& axis(const std::string& name) {
        int i = ioc->axes().find(name);
        if (i < 0) throw std::runtime_error("no axis " + name);
        return ioc->axes().group()->axis(std::size_t(i));
    }
    // A PV's element i as a double, and a CHAR waveform as text (the IOC loop's view).
    double get(const std::string& name, uint32_t i = 0) {
        pv::Record* r = ioc->database().find(name);
        if (!r) throw std::runtime_error("no record " + name);
        const pv::FieldDesc* f = r->type().find("VAL");
        pv::Elements e = r->elements(*f);
        double x = 0;
        pv::get_element(*r, *f, e, i, pv::Prim::Double, &x);
        return x;
    }
    std::string text(const std::string& name) {
        std::string s;
        for (uint32_t i = 0; i < 512; ++i) {
            char c = char(get(name, i));
            if (!c) break;
            s += c;
        }
        return s;
    }
    // Cycles with the IOC loop's publish every 10 (as the running IOC's publisher, every 10 ms).
    void run(int n) {
        for (int k = 0; k < n; k += 10) {
            cycles(std::min(10, n - k));
            ioc->publish();
        }
    }
    void send(const std::string& name, motion::AxisCommand c) {
        ASSERT_NE(ioc->axes().send(std::size_t(ioc->axes().find(name)), c), 0u);
    }
};

} // namespace beamctl::test
