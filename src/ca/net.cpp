#include "ca/net.hpp"

#include <ifaddrs.h>
#include <net/if.h>

namespace beamctl::ca {

std::vector<in_addr> interface_broadcasts() {
    std::vector<in_addr> out;
    ifaddrs* ifs = nullptr;
    if (getifaddrs(&ifs) != 0) return out;
    for (ifaddrs* i = ifs; i; i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET) continue;
        if (!(i->ifa_flags & IFF_UP) || !(i->ifa_flags & IFF_BROADCAST) || !i->ifa_broadaddr) continue;
        if (i->ifa_flags & IFF_LOOPBACK) continue;
        out.push_back(reinterpret_cast<sockaddr_in*>(i->ifa_broadaddr)->sin_addr);
    }
    freeifaddrs(ifs);
    return out;
}

} // namespace beamctl::ca
