// libFuzzer: arbitrary bytes from a "server" into the CA client's socket-free core: a TCP circuit
// (ClientCircuit, whose value replies are decoded with decode_dbr as ca::Client does) and, for
// inputs starting with 'U', a UDP datagram (search replies, beacons).
#include "ca/client_circuit.hpp"
#include "ca/dbr.hpp"

#include <cstring>

namespace {
using namespace beamctl;

struct Handler : ca::ClientCircuitHandler {
    void value(uint32_t status, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) {
        if (status != ca::kEcaNormal) return;
        ca::DbrValue v;
        // The core checked the type and the size: decoding must succeed and stay in bounds.
        if (!ca::decode_dbr(t, p, len, n, v)) __builtin_trap();
        if (v.data.size() != std::size_t(v.count) * pv::prim_size(v.prim)) __builtin_trap();
    }
    void on_server_version(uint16_t) override {}
    void on_access_rights(uint32_t, uint32_t) override {}
    void on_create_chan(uint32_t, uint32_t, uint16_t t, uint32_t) override {
        if (t > 6) __builtin_trap();
    }
    void on_create_fail(uint32_t) override {}
    void on_server_disconn(uint32_t) override {}
    void on_read(uint32_t, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) override {
        value(st, t, n, p, len);
    }
    void on_event(uint32_t, uint32_t st, uint16_t t, uint32_t n, const uint8_t* p, std::size_t len) override {
        value(st, t, n, p, len);
    }
    void on_event_cancelled(uint32_t) override {}
    void on_write_notify(uint32_t, uint32_t) override {}
    void on_error(uint32_t, uint32_t eca, const ca::Header&, std::string_view text) override {
        (void)ca::eca_message(eca);
        if (std::memchr(text.data(), 0, text.size())) __builtin_trap();
    }
    void on_echo() override {}
};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl;
    static ca::ClientStats stats;
    if (size > 0 && data[0] == 'U') {
        std::vector<ca::SearchReply> replies;
        std::vector<ca::Beacon> beacons;
        ca::parse_client_datagram(data + 1, size - 1, 0x7F000001, replies, beacons, stats);
        for (auto& r : replies)
            if (r.server_port == 0) __builtin_trap();
        return 0;
    }
    Handler h;
    ca::ClientCircuit c(h, stats, 1u << 20);
    // In two pieces, so that messages split across reads are exercised too.
    std::size_t cut = size / 3;
    c.receive(data, cut);
    c.receive(data + cut, size - cut);
    c.create_chan(1, "x");
    c.read_notify(1, 2, 20, 0);
    return 0;
}
