// libFuzzer: arbitrary UDP datagrams into the CA name-search handler.
#include "ca/search.hpp"
#include "fuzz_db.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl;
    static ca::ServerStats stats;
    std::vector<std::string> replies;
    ca::answer_search(fuzz_database(), 5064, data, size, replies, stats);
    for (auto& r : replies)
        if (r.size() > ca::kMaxUdpReply || r.size() % 8) __builtin_trap();
    return 0;
}
