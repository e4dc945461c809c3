// `beamctl plan run ioc.yaml PLAN [NAME=VALUE ...]`: starts a plan of a running IOC through its
// PVs (Channel Access), follows it, and ends with the run: exit 0 when the run is Done, 1 when it
// was refused, failed or aborted, 2 when the IOC cannot be reached or the arguments are wrong.
// Ctrl-C (SIGINT/SIGTERM) aborts the run (a second one leaves at once). `beamctl plan list`:
// the plans of an IOC file with their arguments.
#pragma once

#include "config/ioc_config.hpp"

#include <ostream>
#include <string>
#include <vector>

namespace beamctl::automation {

struct PlanRunOptions {
    std::string plan;
    std::vector<std::string> args; // "name=value"
    double connect_timeout_s = 5;
    bool quiet = false;            // only the result
};

int run_plan_client(const config::IocConfig& cfg, const PlanRunOptions& o, std::ostream& out, std::ostream& err);
int list_plans(const config::IocConfig& cfg, std::ostream& out);

} // namespace beamctl::automation
