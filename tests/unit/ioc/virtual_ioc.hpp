// A whole IOC built from an IOC file and brought up on a virtual clock: the unit tests' way to
// run the engine cycle by cycle (buses simulated in-process).
#pragma once

#include "config/ioc_config.hpp"
#include "ioc/ioc.hpp"
#include "motion/axis.hpp"
#include "plc/runtime.hpp"
#include "rt/engine.hpp"

#include <gtest/gtest.h>

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
    void cycles(int n) { ioc->engine().run_cycles(uint64_t(n)); }
    plc::PlcRuntime& plcs() { return *ioc->plcs().runtime(); }
    // A static variable of PLC `plc` (index in the runtime: general PLCs first).
    double stat(std::size_t plc, const std::string& name) {
        const double* v = plcs().static_variable(plc, name);
        if (!v) throw std::runtime_error("no static " + name);
        return *v;
    }
    motion::Axis& axis(const std::string& name) {
        int i = ioc->axes().find(name);
        if (i < 0) throw std::runtime_error("no axis " + name);
        return ioc->axes().group()->axis(std::size_t(i));
    }
    void send(const std::string& name, motion::AxisCommand c) {
        ASSERT_NE(ioc->axes().send(std::size_t(ioc->axes().find(name)), c), 0u);
    }
};

} // namespace beamctl::test
