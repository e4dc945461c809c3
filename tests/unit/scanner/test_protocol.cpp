// The scanner's control protocol (src/scanner/protocol.hpp): every message round-trips byte for
// byte through the stream decoder in any piece sizes; the frame layout is the documented one; and
// each kind of malformed frame is an error that names the frame's stream offset and what is wrong.
#include "core/error.hpp"
#include "scanner/protocol.hpp"

#include <gtest/gtest.h>

#include <cstring>

using namespace beamctl;
using namespace beamctl::scanner::proto;

namespace {

std::vector<Message> every_message() {
    Attached at;
    at.client_id = 3, at.image_bytes = 96, at.layout_hash = 0x1234567890ABCDEFull, at.depth = 16;
    LayoutSlave ls;
    ls.slave = ChainSlave{3, "M1", "EL7041", 2, 0x1b813052, 0x00190000, 1};
    ls.out_offset = 0, ls.out_bytes = 8, ls.in_offset = 40, ls.in_bytes = 12;
    ls.entries = {LayoutEntry{"driveControl01", 0x7010, 1, 0x1602, 0, 16, "UINT16", true},
                  LayoutEntry{"positionActual01", 0x6000, 0x11, 0x1a03, 320, 16, "UINT16", false}};
    at.slaves = {ls};
    Status st;
    st.cycle = 1234567, st.frames_lost = 2, st.wkc_errors = 1;
    st.clients = {ClientStatus{"SCA", 4711, 2, 1, 0, 3}, ClientStatus{"SCB", 4712, 1, 0, 17, 0}};
    return {
        Message{1, Hello{1, 1, "beamctl 0.9", "SCA", 4711}},
        Message{1, Welcome{1, "beamctl 0.9", 0xFEEDull, {BusInfo{0, 100000, 12}, BusInfo{1, 1000000, 3}}}},
        Message{2, Describe{0}},
        Message{2, Chain{0, {ChainSlave{1, "OUT0", "EL2008", 2, 0x07d83052, 0x00100000, 1},
                             ChainSlave{2, "RF0", "EL3702", 2, 0x0e763052, 0x00030000, 10}}}},
        Message{3, Attach{0, {"M1", "3"}, {Claim{"M1", "*"}, Claim{"OUT0", "binaryOutput01"}}, 16, 0}},
        Message{3, at},
        Message{3, ErrorMsg{ErrorCode::ClaimConflict, "ec0.s3.driveControl01 (M1): claimed by SCA (pid 4711)", 0}},
        Message{4, Detach{}},
        Message{5, SdoRead{0, 3, 0x8010, 1, false}},
        Message{6, SdoWrite{0, 3, 0x8010, 1, false, {0xb0, 0x04}}},
        Message{5, SdoData{{1, 2, 3, 4}}},
        Message{6, Ok{}},
        Message{7, AlInfoRequest{0, 3}},
        Message{7, AlInfo{0x08, 0, 0, 1, 1, 0, 0, ""}},
        Message{8, StatusRequest{}},
        Message{8, st},
        Message{0, Goodbye{"scanner stopping (SIGTERM)"}},
    };
}

} // namespace

TEST(ScannerProtocol, EveryMessageRoundTripsInAnyPieceSize) {
    std::vector<Message> all = every_message();
    ASSERT_EQ(all.size(), std::size_t(kLastType)); // one of each type
    std::vector<uint8_t> stream;
    for (const Message& m : all) encode(m, stream);
    for (std::size_t piece : {std::size_t(1), std::size_t(7), std::size_t(16), std::size_t(4096)}) {
        Decoder d;
        std::vector<Message> got;
        for (std::size_t at = 0; at < stream.size(); at += piece) {
            d.feed(stream.data() + at, std::min(piece, stream.size() - at));
            Message m;
            while (d.next(m) == Decoder::Result::Message) got.push_back(m);
        }
        ASSERT_EQ(got.size(), all.size()) << "piece " << piece << ": " << d.error();
        for (std::size_t i = 0; i < all.size(); ++i) EXPECT_TRUE(got[i] == all[i]) << to_string(all[i].type());
        EXPECT_EQ(d.buffered(), 0u);
    }
}

TEST(ScannerProtocol, FrameLayoutAsDocumented) {
    std::vector<uint8_t> f;
    encode(Message{0x01020304, Describe{0x0A0B}}, f);
    const uint8_t want[] = {'B', 'C', 'S', 'P', 1, 0, 3, 0, 2, 0, 0, 0, 4, 3, 2, 1, 0x0B, 0x0A};
    ASSERT_EQ(f.size(), sizeof want);
    EXPECT_EQ(std::memcmp(f.data(), want, sizeof want), 0);
    f.clear();
    encode(Message{9, Goodbye{"bye"}}, f);
    EXPECT_EQ(f.size(), kHeaderSize + 2 + 3); // u16 length + bytes
    EXPECT_EQ(f[16], 3);
    EXPECT_EQ(f[17], 0);
    EXPECT_EQ(std::string(f.begin() + 18, f.end()), "bye");
}

TEST(ScannerProtocol, MalformedFramesAreErrorsNamingWhereAndWhat) {
    auto error_of = [](std::vector<uint8_t> bytes, std::size_t prefix_frames = 0) {
        std::vector<uint8_t> s;
        for (std::size_t i = 0; i < prefix_frames; ++i) encode(Message{1, Ok{}}, s);
        s.insert(s.end(), bytes.begin(), bytes.end());
        Decoder d;
        d.feed(s.data(), s.size());
        Message m;
        Decoder::Result r;
        while ((r = d.next(m)) == Decoder::Result::Message) {}
        if (r != Decoder::Result::Error) return std::string("(no error)");
        // an error sticks
        d.feed(s.data(), s.size());
        if (d.next(m) != Decoder::Result::Error) return std::string("(error did not stick)");
        return d.error();
    };
    std::vector<uint8_t> good;
    encode(Message{1, Hello{1, 1, "c", "i", 1}}, good);
    auto with = [&](std::size_t at, std::vector<uint8_t> bytes) {
        std::vector<uint8_t> b = good;
        std::copy(bytes.begin(), bytes.end(), b.begin() + std::ptrdiff_t(at));
        return b;
    };
    EXPECT_EQ(error_of(with(0, {'X'}), 2), "scanner protocol: frame at stream byte 32: not a frame (no BCSP magic)");
    EXPECT_EQ(error_of(with(4, {2, 0})), "scanner protocol: frame at stream byte 0: protocol version 2 (this side speaks 1..1)");
    EXPECT_EQ(error_of(with(6, {99, 0})), "scanner protocol: frame at stream byte 0: unknown message type 99");
    EXPECT_EQ(error_of(with(8, {0, 0, 0x20, 0})),
              "scanner protocol: frame at stream byte 0: Hello: body of 2097152 bytes, at most 1048576");
    // a string longer than the body
    EXPECT_NE(error_of(with(kHeaderSize + 4, {0xFF, 0x00})).find("Hello: client: a string of 255 bytes"), std::string::npos);
    // trailing bytes after the fields
    std::vector<uint8_t> tail;
    encode(Message{1, Ok{}}, tail);
    tail[8] = 2, tail.push_back(0), tail.push_back(0);
    EXPECT_EQ(error_of(tail), "scanner protocol: frame at stream byte 0: Ok: 2 byte(s) after the end of the body's fields");
    // a list count the body cannot hold, a bad boolean, a bad error code
    std::vector<uint8_t> chain;
    encode(Message{1, Chain{0, {}}}, chain);
    chain[kHeaderSize + 2] = 0xFF, chain[kHeaderSize + 3] = 0xFF;
    EXPECT_NE(error_of(chain).find("Chain: slaves: 65535 elements, 0 bytes left in the body"), std::string::npos) << error_of(chain);
    std::vector<uint8_t> sdo;
    encode(Message{1, SdoRead{0, 1, 2, 3, false}}, sdo);
    sdo.back() = 7;
    EXPECT_NE(error_of(sdo).find("SdoRead: complete_access: 7 is not a boolean"), std::string::npos);
    std::vector<uint8_t> err;
    encode(Message{1, ErrorMsg{ErrorCode::Busy, "x", 0}}, err);
    err[kHeaderSize] = 77;
    EXPECT_NE(error_of(err).find("Error: code: unknown error code 77"), std::string::npos);
    // encoding what cannot be framed is refused by name
    std::vector<uint8_t> out;
    EXPECT_THROW(encode(Message{1, SdoWrite{0, 1, 2, 3, false, std::vector<uint8_t>(513)}}, out), Error);
    EXPECT_THROW(encode(Message{1, Goodbye{std::string(70000, 'x')}}, out), Error);
}

TEST(ScannerProtocol, AWholeMessageWaitsForItsLastByte) {
    std::vector<uint8_t> f;
    encode(Message{5, Attach{0, {"M1"}, {}, 16, 0}}, f);
    Decoder d;
    Message m;
    d.feed(f.data(), f.size() - 1);
    EXPECT_EQ(d.next(m), Decoder::Result::NeedMore);
    d.feed(f.data() + f.size() - 1, 1);
    ASSERT_EQ(d.next(m), Decoder::Result::Message);
    EXPECT_EQ(m.type(), Type::Attach);
    EXPECT_EQ(m.request_id, 5u);
    EXPECT_EQ(std::get<Attach>(m.body).slaves, std::vector<std::string>{"M1"});
}
