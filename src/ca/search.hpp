// UDP name search (ca-protocol.md §2): one request datagram in, reply datagrams out. Pure
// function of the database so it can be unit-tested and fuzzed without sockets.
#pragma once

#include "ca/circuit.hpp"

#include <string>
#include <vector>

namespace beamctl::ca {

// Answers the SEARCH messages of one datagram: each reply datagram starts with VERSION and holds
// the found names, at most kMaxUdpReply bytes. Unknown names get no reply (never NOT_FOUND).
// Malformed datagrams are counted in stats.udp_malformed; what parsed before the fault is answered.
void answer_search(const pv::Database& db, uint16_t tcp_port, const uint8_t* p, std::size_t n,
                   std::vector<std::string>& replies, ServerStats& stats);

} // namespace beamctl::ca
