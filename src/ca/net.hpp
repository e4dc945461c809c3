// Helpers the CA server and client share: the broadcast addresses of this host's interfaces, and
// the EPICS environment variables they read.
#pragma once

#include <cstdint>
#include <netinet/in.h>
#include <vector>

namespace beamctl::ca {

// The broadcast address of every IPv4 interface that is up and not loopback (EPICS's automatic
// address list for searches and beacons).
std::vector<in_addr> interface_broadcasts();

// The value of an environment variable, nullptr if unset or empty (as EPICS's envGetConfigParam).
const char* env(const char* name);
// A port number from the environment (`def` if unset); Error naming the variable if it is not one.
uint16_t env_port(const char* name, uint16_t def);

} // namespace beamctl::ca
