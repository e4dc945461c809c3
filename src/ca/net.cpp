#include "ca/net.hpp"

#include "core/error.hpp"

#include <cstdlib>

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

const char* env(const char* name) {
    const char* v = std::getenv(name);
    return v && *v ? v : nullptr;
}

uint16_t env_port(const char* name, uint16_t def) {
    const char* v = env(name);
    if (!v) return def;
    char* end;
    long p = std::strtol(v, &end, 10);
    if (*end || p <= 0 || p > 65535) throw Error(SB() << name << "='" << v << "' is not a port number");
    return uint16_t(p);
}

} // namespace beamctl::ca
