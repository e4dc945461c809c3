// IPv4 helpers the CA server and client share: the broadcast addresses of this host's interfaces.
#pragma once

#include <netinet/in.h>
#include <vector>

namespace beamctl::ca {

// The broadcast address of every IPv4 interface that is up and not loopback (EPICS's automatic
// address list for searches and beacons).
std::vector<in_addr> interface_broadcasts();

} // namespace beamctl::ca
