// libFuzzer: arbitrary bytes into the scanner's control-protocol decoder, as a connection's stream
// arriving in pieces. The first input byte sets the piece size (1..256). Every message decoded
// must encode again and decode to the same message; an error must stop the decoder for good and
// name a stream offset inside what was fed; nothing may crash, hang or allocate without bound.
#include "scanner/protocol.hpp"

#include <cstdint>
#include <string>
#include <vector>

using namespace beamctl::scanner::proto;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (size == 0) return 0;
    std::size_t piece = std::size_t(data[0]) + 1;
    ++data, --size;
    Decoder d;
    std::size_t fed = 0;
    bool failed = false;
    while (fed < size && !failed) {
        std::size_t n = std::min(piece, size - fed);
        d.feed(data + fed, n);
        fed += n;
        Message m;
        for (;;) {
            Decoder::Result r = d.next(m);
            if (r == Decoder::Result::NeedMore) break;
            if (r == Decoder::Result::Error) {
                if (d.error().find("stream byte ") == std::string::npos) __builtin_trap();
                failed = true;
                break;
            }
            std::vector<uint8_t> again;
            encode(m, again);
            Decoder d2;
            d2.feed(again.data(), again.size());
            Message m2;
            if (d2.next(m2) != Decoder::Result::Message || !(m2 == m) || d2.buffered() != 0) __builtin_trap();
        }
    }
    if (failed) { // a decoder in error stays there
        Message m;
        d.feed(data, size);
        if (d.next(m) != Decoder::Result::Error) __builtin_trap();
    }
    return 0;
}
