// `beamctl rcp-sim MODEL.yaml`: a stand-in for an RCP machine. Runs the model (model.hpp) at its
// rate on the monotonic clock, sends its beacons every beacon_period_s (with continuation
// packets beyond 17 objects) and its data after every step, and applies the writes it receives.
// Stops cleanly on SIGINT/SIGTERM (or after duration_s) and prints a summary.
// Threading: runs on the calling thread; blocks SIGINT and SIGTERM for it while running.
#pragma once

#include <string>

namespace beamctl::bridge::rcp {

struct RcpSimOptions {
    std::string ioc_host;  // overrides ioc.host when not empty (IPv4)
    int ioc_port = -1;     // overrides ioc.port (and ioc.data_port when it equals ioc.port)
    int listen_port = -1;  // overrides listen.port (0: any free port)
    double rate_hz = 0;    // overrides rate_hz when > 0
    double duration_s = 0; // [s] stop after this long; 0: until a signal
};

// Returns the process exit code. Throws Error for a bad model file or a socket that cannot be
// opened; prints "ready: ..." on stdout once it serves.
int run_rcp_sim(const std::string& model_file, const RcpSimOptions& options = {});

} // namespace beamctl::bridge::rcp
