// libFuzzer: arbitrary bytes into a CA TCP circuit (all commands, all DBR types, puts that
// process records, monitors, flow control). Any crash, leak or UB report is a bug.
#include "ca/circuit.hpp"
#include "fuzz_db.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace beamctl;
    static ca::ServerContext ctx{fuzz_database(), ca::AccessSecurity(), 5064, 1u << 20, 64, 1u << 16, {}};
    ca::Circuit c(ctx, 0x7F000001, 40000);
    // Feed in irregular chunks so partial headers and payloads are exercised too.
    size_t off = 0, step = 1;
    while (off < size) {
        size_t n = std::min(size - off, step);
        c.receive(data + off, n);
        off += n;
        step = step * 3 % 97 + 1;
        c.fill_events(4096);
        c.consume_output(c.output_size() / 2);
    }
    c.fill_events(1u << 20);
    c.consume_output(c.output_size());
    return 0;
}
