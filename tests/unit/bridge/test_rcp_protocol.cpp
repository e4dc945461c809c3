// The RCP packet codec against packets written byte by byte from specs/rcp-udp.md (independent
// of the encoder), every malformed reason with its offset, value conversions, and seeded
// round-trip and mutation properties.
#include "bridge/rcp/protocol.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <random>
#include <string>
#include <vector>

using namespace beamctl::bridge::rcp;

namespace {

using Bytes = std::vector<uint8_t>;

// A zeroed 1000-byte packet with `bytes` written at `at`.
void put(Bytes& p, std::size_t at, std::initializer_list<uint8_t> bytes) {
    for (uint8_t b : bytes) p.at(at++) = b;
}
void put_name(Bytes& p, std::size_t at, const char* s) {
    for (; *s; ++s) p.at(at++) = uint8_t(*s);
}
std::span<const uint8_t> span(const Bytes& b) {
    return {b.data(), b.size()};
}
std::span<const uint8_t> span(const Packet& p) {
    return {p.data(), p.size()};
}

// The seed's AI example: 13.345 s, object 1 AI int32 "EPICS_ai1" = 42.
Bytes spec_data_packet() {
    Bytes p(1000, 0);
    put(p, 0, {0x71, 0x3d, 0x0a, 0xd7, 0xa3, 0xb0, 0x2a, 0x40}); // f64 13.345
    put(p, 8, {0x01, 0x01, 0x05, 0x01, 0x00});                   // id 1, AI, int32, count 1
    put_name(p, 13, "EPICS_ai1");
    put(p, 53, {0x2a, 0x00, 0x00, 0x00}); // 42
    // byte 57: object id 0 ends the list; the rest is padding
    return p;
}

// The seed's beacon: 7.314 s, sgDemo, AI int32 "EPICS_a1" and AO int32 "EPICS_a3".
Bytes spec_beacon() {
    Bytes p(1000, 0);
    put(p, 0, {0xa8, 0xc6, 0x4b, 0x37, 0x89, 0x41, 0x1d, 0x40}); // f64 7.314
    put(p, 8, {0x01});                                           // version 1
    put_name(p, 9, "sgDemo");
    put(p, 49, {0x01, 0x01, 0x05});       // id 1, AI, int32
    put(p, 52, {0x2a, 0xa7, 0xa8, 0xc0}); // 192.168.167.42
    put(p, 56, {0x91, 0x46});             // 18065
    put(p, 58, {0x29, 0xa7, 0xa8, 0xc0}); // 192.168.167.41
    put(p, 62, {0x91, 0x46});
    put_name(p, 64, "EPICS_a1");
    put(p, 104, {0x02, 0x02, 0x05}); // id 2, AO, int32
    put(p, 107, {0x2a, 0xa7, 0xa8, 0xc0});
    put(p, 111, {0x92, 0x46}); // 18066
    put(p, 113, {0x29, 0xa7, 0xa8, 0xc0});
    put(p, 117, {0x91, 0x46});
    put_name(p, 119, "EPICS_a3");
    // byte 159: object id 0
    return p;
}

BeaconObject object(uint8_t id, ObjectType t, DataType d, std::string name) {
    BeaconObject b;
    b.id = id;
    b.type = t;
    b.data_type = d;
    b.ip_rcp = 0x7F000001;
    b.port_rcp = 18066;
    b.ip_ioc = 0x7F000001;
    b.port_ioc = 18065;
    b.name = std::move(name);
    return b;
}

} // namespace

TEST(RcpProtocol, ParsesTheSpecDataPacket) {
    DataPacket d;
    Bytes p = spec_data_packet();
    ASSERT_TRUE(parse_data(span(p), d).ok());
    EXPECT_DOUBLE_EQ(d.timestamp, 13.345);
    ASSERT_EQ(d.entry_count, 1u);
    const DataEntry& e = d.entries[0];
    EXPECT_EQ(e.id, 1);
    EXPECT_EQ(e.type, ObjectType::AI);
    EXPECT_EQ(e.data_type, DataType::Int32);
    EXPECT_EQ(e.count, 1);
    EXPECT_EQ(e.name, "EPICS_ai1");
    ASSERT_EQ(e.values.size(), 1u);
    EXPECT_EQ(e.values[0], 42.0);
}

TEST(RcpProtocol, EncodesTheSpecDataPacketByteForByte) {
    double v = 42;
    DataEntry e{1, ObjectType::AI, DataType::Int32, 1, "EPICS_ai1", std::span<const double>(&v, 1)};
    Packet out;
    out.fill(0xEE); // everything must be overwritten
    ASSERT_TRUE(write_data(out, 13.345, std::span<const DataEntry>(&e, 1)).ok());
    Bytes want = spec_data_packet();
    EXPECT_EQ(Bytes(out.begin(), out.end()), want);
}

TEST(RcpProtocol, ParsesTheSpecBeacon) {
    Beacon b;
    Bytes p = spec_beacon();
    ASSERT_TRUE(parse_beacon(span(p), b).ok());
    EXPECT_DOUBLE_EQ(b.timestamp, 7.314);
    EXPECT_EQ(b.application, "sgDemo");
    EXPECT_FALSE(b.continuation);
    ASSERT_EQ(b.objects.size(), 2u);
    EXPECT_EQ(b.objects[0].id, 1);
    EXPECT_EQ(b.objects[0].type, ObjectType::AI);
    EXPECT_EQ(b.objects[0].data_type, DataType::Int32);
    EXPECT_EQ(b.objects[0].ip_rcp, 0xC0A8A72Au);
    EXPECT_EQ(b.objects[0].port_rcp, 18065);
    EXPECT_EQ(b.objects[0].ip_ioc, 0xC0A8A729u);
    EXPECT_EQ(b.objects[0].port_ioc, 18065);
    EXPECT_EQ(b.objects[0].name, "EPICS_a1");
    EXPECT_EQ(b.objects[1].id, 2);
    EXPECT_EQ(b.objects[1].type, ObjectType::AO);
    EXPECT_EQ(b.objects[1].port_rcp, 18066);
    EXPECT_EQ(b.objects[1].name, "EPICS_a3");
    EXPECT_EQ(ipv4_to_string(b.objects[0].ip_rcp), "192.168.167.42");
}

TEST(RcpProtocol, EncodesTheSpecBeaconByteForByte) {
    BeaconObject a = object(1, ObjectType::AI, DataType::Int32, "EPICS_a1");
    a.ip_rcp = 0xC0A8A72A;
    a.port_rcp = 18065;
    a.ip_ioc = 0xC0A8A729;
    BeaconObject b = a;
    b.id = 2;
    b.type = ObjectType::AO;
    b.port_rcp = 18066;
    b.name = "EPICS_a3";
    BeaconObject objs[] = {a, b};
    Packet out;
    out.fill(0xEE);
    ASSERT_TRUE(write_beacon(out, 7.314, "sgDemo", false, objs).ok());
    EXPECT_EQ(Bytes(out.begin(), out.end()), spec_beacon());
}

TEST(RcpProtocol, ContinuationBeaconHasTheFlagInTheVersionByte) {
    Bytes p = spec_beacon();
    p[8] = 0x81;
    Beacon b;
    ASSERT_TRUE(parse_beacon(span(p), b).ok());
    EXPECT_TRUE(b.continuation);
    Packet out;
    BeaconObject o = object(3, ObjectType::BI, DataType::Bool, "x");
    ASSERT_TRUE(write_beacon(out, 0, "sgDemo", true, std::span<const BeaconObject>(&o, 1)).ok());
    EXPECT_EQ(out[8], 0x81);
}

TEST(RcpProtocol, ClassifiesByTheNameCharacterAtByte9) {
    EXPECT_EQ(classify(span(spec_beacon())), PacketKind::Beacon);
    EXPECT_EQ(classify(span(spec_data_packet())), PacketKind::Data); // byte 8 = id 1 = version 1
    Bytes d = spec_data_packet();
    d[8] = 0x81; // an object id equal to the continuation version byte
    EXPECT_EQ(classify(span(d)), PacketKind::Data);
    Bytes empty(1000, 0);
    EXPECT_EQ(classify(span(empty)), PacketKind::Data);
    Bytes wrong = spec_beacon();
    wrong[8] = 2; // still a beacon, which parse_beacon refuses with WrongVersion
    EXPECT_EQ(classify(span(wrong)), PacketKind::Beacon);
    EXPECT_EQ(classify(std::span<const uint8_t>(wrong.data(), 9)), PacketKind::Data);
}

TEST(RcpProtocol, EmptyDataPacketIsValid) {
    Bytes p(1000, 0);
    DataPacket d;
    EXPECT_TRUE(parse_data(span(p), d).ok());
    EXPECT_EQ(d.entry_count, 0u);
}

// ------------------------------------------------------------------ malformed input
namespace {
ParseResult data_result(const Bytes& p) {
    DataPacket d;
    return parse_data(span(p), d);
}
ParseResult beacon_result(const Bytes& p) {
    Beacon b;
    return parse_beacon(span(p), b);
}
void expect(ParseResult r, Malformed why, uint16_t at) {
    EXPECT_EQ(r.reason, why) << "got " << to_string(r.reason) << " at " << r.offset;
    EXPECT_EQ(r.offset, at) << to_string(why);
}
} // namespace

TEST(RcpMalformed, ShortAndLong) {
    Bytes p = spec_data_packet();
    expect(data_result(Bytes(p.begin(), p.begin() + 999)), Malformed::Short, 999);
    expect(data_result(Bytes()), Malformed::Short, 0);
    Bytes longer = p;
    longer.push_back(0);
    expect(data_result(longer), Malformed::Long, 1000);
    Bytes b = spec_beacon();
    expect(beacon_result(Bytes(b.begin(), b.begin() + 500)), Malformed::Short, 500);
}

TEST(RcpMalformed, WrongVersion) {
    Bytes b = spec_beacon();
    b[8] = 2;
    expect(beacon_result(b), Malformed::WrongVersion, 8);
    b[8] = 0x80;
    expect(beacon_result(b), Malformed::WrongVersion, 8);
}

TEST(RcpMalformed, UnknownObjectOrDataType) {
    Bytes p = spec_data_packet();
    p[9] = 8;
    expect(data_result(p), Malformed::UnknownType, 9);
    p[9] = 0;
    expect(data_result(p), Malformed::UnknownType, 9);
    p = spec_data_packet();
    p[10] = 9;
    expect(data_result(p), Malformed::UnknownType, 10);
    Bytes b = spec_beacon();
    b[105] = 99; // second object's type
    expect(beacon_result(b), Malformed::UnknownType, 105);
    b = spec_beacon();
    b[51] = 200; // first object's data type
    expect(beacon_result(b), Malformed::UnknownType, 51);
}

TEST(RcpMalformed, UnterminatedAndBadNames) {
    Bytes p = spec_data_packet();
    for (int i = 0; i < 40; ++i) p[13 + i] = 'a';
    expect(data_result(p), Malformed::UnterminatedName, 13);
    p = spec_data_packet();
    p[16] = ' ';
    expect(data_result(p), Malformed::BadName, 16);
    p = spec_data_packet();
    std::memset(&p[13], 0, 40); // empty name
    expect(data_result(p), Malformed::BadName, 13);
    Bytes b = spec_beacon();
    for (int i = 0; i < 40; ++i) b[9 + i] = 'x';
    expect(beacon_result(b), Malformed::UnterminatedName, 9);
    b = spec_beacon();
    b[66] = '$';
    expect(beacon_result(b), Malformed::BadName, 66);
    b = spec_beacon();
    b[119 + 39] = 'q'; // the last byte of a name[40] may not be a character: no NUL left
    for (int i = 0; i < 39; ++i) b[119 + i] = 'q';
    expect(beacon_result(b), Malformed::UnterminatedName, 119);
}

TEST(RcpMalformed, ZeroCountAndCountOverflow) {
    Bytes p = spec_data_packet();
    p[11] = 0;
    p[12] = 0;
    expect(data_result(p), Malformed::ZeroCount, 11);
    p = spec_data_packet();
    p[11] = 0xE9; // 233 int32 = 932 bytes: 53 + 932 = 985, fits with the end byte
    p[12] = 0x00;
    EXPECT_TRUE(data_result(p).ok());
    p[11] = 0xEA; // 234 int32 = 936 bytes: ends at 989... still fits
    EXPECT_TRUE(data_result(p).ok());
    p[11] = 0xEC; // 236: values end at 997, terminator at 997 fits
    EXPECT_TRUE(data_result(p).ok());
    p[11] = 0xED; // 237: values end at 1001 > 1000
    expect(data_result(p), Malformed::CountOverflow, 11);
    p[11] = 0xFF;
    p[12] = 0xFF;
    expect(data_result(p), Malformed::CountOverflow, 11);
}

TEST(RcpMalformed, ValuesMustLeaveRoomForTheTerminator) {
    // One uint8 entry whose values end exactly at byte 1000: no room for the id 0.
    Bytes p(1000, 0);
    put(p, 8, {0x01, 0x05, 0x02});
    uint16_t count = 1000 - 8 - 45; // 947 values from 53 to 999
    p[11] = uint8_t(count & 0xFF);
    p[12] = uint8_t(count >> 8);
    put_name(p, 13, "n");
    expect(data_result(p), Malformed::CountOverflow, 11);
    --count; // 946: the terminator at 999
    p[11] = uint8_t(count & 0xFF);
    EXPECT_TRUE(data_result(p).ok());
}

TEST(RcpMalformed, TruncatedListWithoutTerminator) {
    // 18 beacon records: the 18th starts at 984 and cannot fit.
    std::vector<BeaconObject> objs;
    for (int i = 1; i <= 17; ++i)
        objs.push_back(
            object(uint8_t(i), ObjectType::AI, DataType::Float64, std::string("o").append(std::to_string(i))));
    Packet out;
    ASSERT_TRUE(write_beacon(out, 0, "app", false, objs).ok());
    Bytes b(out.begin(), out.end());
    EXPECT_TRUE(beacon_result(b).ok());
    b[984] = 18; // an 18th object id where the terminator must be
    expect(beacon_result(b), Malformed::Truncated, 984);
    // Data: entries are contiguous from byte 8; an entry header that cannot fit is Truncated.
    Bytes r(1000, 0);
    put(r, 8, {0x01, 0x05, 0x02, 0x8b, 0x03}); // LI uint8 count 907: values 53..959
    put_name(r, 13, "a");
    EXPECT_TRUE(data_result(r).ok());
    r[960] = 4; // a next entry at 960: its header 960..1004 does not fit
    expect(data_result(r), Malformed::Truncated, 960);
    r[960] = 0;
    r[11] = 0x8a; // count 906: the list ends at 959, whatever follows is padding
    r[959] = 9;
    expect(data_result(r), Malformed::Truncated, 959);
}

TEST(RcpMalformed, DuplicateObjects) {
    Bytes b = spec_beacon();
    b[104] = 1; // second object with id 1
    expect(beacon_result(b), Malformed::DuplicateObject, 104);
    b = spec_beacon();
    put_name(b, 119, "EPICS_a1"); // second object with the first one's name
    expect(beacon_result(b), Malformed::DuplicateObject, 119);
}

TEST(RcpMalformed, MotorObjectsAreFloat64WithFiveValues) {
    Bytes b = spec_beacon();
    b[50] = 7; // MOTOR int32
    expect(beacon_result(b), Malformed::BadMotor, 51);
    b[51] = 8;
    EXPECT_TRUE(beacon_result(b).ok());
    Bytes p(1000, 0);
    put(p, 8, {0x01, 0x07, 0x08, 0x04, 0x00}); // MOTOR float64 count 4
    put_name(p, 13, "m");
    expect(data_result(p), Malformed::BadMotor, 11);
    p[11] = 5;
    EXPECT_TRUE(data_result(p).ok());
    p[10] = 5; // int32
    expect(data_result(p), Malformed::BadMotor, 10);
}

TEST(RcpMalformed, EveryReasonHasAName) {
    for (std::size_t m = 0; m < kMalformedReasons; ++m) EXPECT_STRNE(to_string(Malformed(m)), "?");
    EXPECT_STREQ(to_string(Malformed::CountOverflow), "CountOverflow");
}

// ------------------------------------------------------------------ values
TEST(RcpProtocol, DecodesEveryDataType) {
    const uint8_t b1[] = {0xFF};
    EXPECT_EQ(decode_value(DataType::Bool, b1), 1.0);
    EXPECT_EQ(decode_value(DataType::Int8, b1), -1.0);
    EXPECT_EQ(decode_value(DataType::UInt8, b1), 255.0);
    const uint8_t b2[] = {0xFE, 0xFF};
    EXPECT_EQ(decode_value(DataType::Int16, b2), -2.0);
    EXPECT_EQ(decode_value(DataType::UInt16, b2), 65534.0);
    const uint8_t b4[] = {0xd6, 0xff, 0xff, 0xff};
    EXPECT_EQ(decode_value(DataType::Int32, b4), -42.0);
    EXPECT_EQ(decode_value(DataType::UInt32, b4), 4294967254.0);
    const uint8_t f4[] = {0x00, 0x00, 0xc0, 0x3f};
    EXPECT_EQ(decode_value(DataType::Float32, f4), 1.5);
    const uint8_t f8[] = {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0xc0};
    EXPECT_EQ(decode_value(DataType::Float64, f8), -2.25);
}

TEST(RcpProtocol, EncodesOnlyRepresentableValues) {
    uint8_t b[8] = {};
    EXPECT_TRUE(encode_value(DataType::Int8, -128, b));
    EXPECT_FALSE(encode_value(DataType::Int8, 128, b));
    EXPECT_TRUE(encode_value(DataType::UInt8, 254.6, b));
    EXPECT_EQ(b[0], 255); // rounded
    EXPECT_FALSE(encode_value(DataType::UInt8, -1, b));
    EXPECT_FALSE(encode_value(DataType::Int32, NAN, b));
    EXPECT_FALSE(encode_value(DataType::Int32, INFINITY, b));
    EXPECT_TRUE(encode_value(DataType::UInt32, 4294967295.0, b));
    EXPECT_FALSE(encode_value(DataType::UInt32, 4294967296.0, b));
    EXPECT_TRUE(encode_value(DataType::Bool, 1, b));
    EXPECT_FALSE(encode_value(DataType::Bool, 2, b));
    EXPECT_FALSE(encode_value(DataType::Float32, 1e39, b));
    EXPECT_TRUE(encode_value(DataType::Float32, INFINITY, b));
    EXPECT_TRUE(encode_value(DataType::Float64, NAN, b));
    EXPECT_TRUE(encode_value(DataType::Int16, -2, b));
    EXPECT_EQ(b[0], 0xFE);
    EXPECT_EQ(b[1], 0xFF);
}

TEST(RcpProtocol, WriterRefusesWhatItCannotEncode) {
    Packet out;
    double v[2] = {1, 2};
    DataEntry e{1, ObjectType::AO, DataType::Float64, 2, "a", std::span<const double>(v, 1)};
    EXPECT_EQ(write_data(out, 0, std::span<const DataEntry>(&e, 1)).status, WriteStatus::BadCount);
    e.values = std::span<const double>(v, 2);
    e.name = "bad name";
    EXPECT_EQ(write_data(out, 0, std::span<const DataEntry>(&e, 1)).status, WriteStatus::BadName);
    e.name = "a";
    e.data_type = DataType::Int8;
    v[1] = 300;
    WriteResult r = write_data(out, 0, std::span<const DataEntry>(&e, 1));
    EXPECT_EQ(r.status, WriteStatus::BadValue);
    EXPECT_EQ(std::count(out.begin(), out.end(), 0), 1000) << "a refused packet is all zeros";
    e.type = ObjectType::Motor;
    EXPECT_EQ(write_data(out, 0, std::span<const DataEntry>(&e, 1)).status, WriteStatus::BadType);
    // 21 one-byte entries fit (8 + 21 * 46 + 1 = 975), the 22nd does not.
    double one = 1;
    std::vector<DataEntry> many(
        22, DataEntry{1, ObjectType::BO, DataType::Bool, 1, "b", std::span<const double>(&one, 1)});
    EXPECT_TRUE(write_data(out, 0, std::span<const DataEntry>(many.data(), 21)).ok());
    r = write_data(out, 0, many);
    EXPECT_EQ(r.status, WriteStatus::NoRoom);
    EXPECT_EQ(r.index, 21u);
    std::vector<BeaconObject> objs(18, object(1, ObjectType::AI, DataType::Float64, "x"));
    EXPECT_EQ(write_beacon(out, 0, "app", false, objs).status, WriteStatus::NoRoom);
    EXPECT_EQ(write_beacon(out, 0, "", false, {}).status, WriteStatus::BadName);
}

TEST(RcpProtocol, Ipv4Text) {
    uint32_t ip = 0;
    EXPECT_TRUE(parse_ipv4("192.168.167.42", ip));
    EXPECT_EQ(ip, 0xC0A8A72Au);
    EXPECT_EQ(ipv4_to_string(ip), "192.168.167.42");
    EXPECT_FALSE(parse_ipv4("192.168.167", ip));
    EXPECT_FALSE(parse_ipv4("256.0.0.1", ip));
    EXPECT_FALSE(parse_ipv4("1.2.3.4 ", ip));
    EXPECT_FALSE(parse_ipv4("localhost", ip));
    EXPECT_FALSE(parse_ipv4("1.2.3.0004", ip));
}

// ------------------------------------------------------------------ properties
TEST(RcpProtocol, RandomDataPacketsRoundTrip) {
    std::mt19937 rng(20240601);
    auto random_value = [&](DataType dt) -> double {
        switch (dt) {
        case DataType::Bool:
            return double(rng() % 2);
        case DataType::Int8:
            return double(int(rng() % 256) - 128);
        case DataType::UInt8:
            return double(rng() % 256);
        case DataType::Int16:
            return double(int(rng() % 65536) - 32768);
        case DataType::UInt16:
            return double(rng() % 65536);
        case DataType::Int32:
            return double(int32_t(rng()));
        case DataType::UInt32:
            return double(uint32_t(rng()));
        case DataType::Float32:
            return double(float(int32_t(rng())) / 1024.0f);
        case DataType::Float64:
            return double(int32_t(rng())) / 3.0;
        }
        return 0;
    };
    DataPacket d;
    for (int round = 0; round < 5000; ++round) {
        struct Want {
            uint8_t id;
            ObjectType type;
            DataType dt;
            std::string name;
            std::vector<double> v;
        };
        std::vector<Want> want;
        std::size_t used = kDataHeaderSize + 1;
        int n = int(rng() % 10);
        for (int i = 0; i < n; ++i) {
            Want w;
            w.type = ObjectType(rng() % 7 + 1);
            w.dt = w.type == ObjectType::Motor ? DataType::Float64 : DataType(rng() % 9);
            uint16_t count = w.type == ObjectType::Motor ? 5 : uint16_t(rng() % 30 + 1);
            if (used + entry_wire_size(w.dt, count) > kPacketSize) break;
            used += entry_wire_size(w.dt, count);
            w.id = uint8_t(rng() % 255 + 1);
            w.name = std::string("n").append(std::to_string(rng() % 1000000)).append(rng() % 2 ? ":x.y-z_" : "");
            for (uint16_t k = 0; k < count; ++k) w.v.push_back(random_value(w.dt));
            want.push_back(std::move(w));
        }
        std::vector<DataEntry> entries;
        for (const Want& w : want)
            entries.push_back(DataEntry{w.id, w.type, w.dt, uint16_t(w.v.size()), w.name,
                                        std::span<const double>(w.v)});
        Packet out;
        double ts = double(round) * 0.001;
        ASSERT_TRUE(write_data(out, ts, entries).ok()) << "round " << round;
        ASSERT_TRUE(parse_data(span(out), d).ok()) << "round " << round;
        EXPECT_EQ(d.timestamp, ts);
        ASSERT_EQ(d.entry_count, want.size());
        for (std::size_t i = 0; i < want.size(); ++i) {
            const DataEntry& e = d.entries[i];
            EXPECT_EQ(e.id, want[i].id);
            EXPECT_EQ(e.type, want[i].type);
            EXPECT_EQ(e.data_type, want[i].dt);
            EXPECT_EQ(e.name, want[i].name);
            ASSERT_EQ(e.values.size(), want[i].v.size());
            for (std::size_t k = 0; k < e.values.size(); ++k)
                ASSERT_EQ(e.values[k], want[i].v[k]) << "round " << round;
        }
        // Bytes after the terminator are zero.
        std::size_t end = used - 1;
        for (std::size_t k = end; k < kPacketSize; ++k)
            ASSERT_EQ(out[k], 0) << "round " << round << " byte " << k;
    }
}

TEST(RcpProtocol, RandomMutationsAreRefusedOrReparsedConsistently) {
    // Flip bytes of valid packets: the parsers either refuse with an offset inside the packet
    // or accept, and what they accept re-encodes to a packet that parses to the same entries.
    std::mt19937 rng(7);
    Bytes base_data = spec_data_packet();
    Bytes base_beacon = spec_beacon();
    DataPacket d, d2;
    Beacon b, b2;
    for (int round = 0; round < 20000; ++round) {
        Bytes p = round % 2 ? base_data : base_beacon;
        int flips = int(rng() % 4) + 1;
        for (int i = 0; i < flips; ++i) p[rng() % 200] = uint8_t(rng());
        ParseResult r = parse_data(span(p), d);
        if (!r) {
            EXPECT_LT(r.offset, 1000);
        } else {
            std::vector<DataEntry> es(d.view().begin(), d.view().end());
            Packet out;
            ASSERT_TRUE(write_data(out, d.timestamp, es).ok());
            ASSERT_TRUE(parse_data(span(out), d2).ok());
            ASSERT_EQ(d2.entry_count, d.entry_count);
            for (std::size_t i = 0; i < d.entry_count; ++i) {
                EXPECT_EQ(d2.entries[i].name, d.entries[i].name);
                EXPECT_EQ(d2.entries[i].count, d.entries[i].count);
            }
        }
        r = parse_beacon(span(p), b);
        if (!r) {
            EXPECT_LT(r.offset, 1000);
        } else {
            Packet out;
            ASSERT_TRUE(
                write_beacon(out, b.timestamp, b.application, b.continuation, b.objects).ok());
            ASSERT_TRUE(parse_beacon(span(out), b2).ok());
            EXPECT_EQ(b2.application, b.application);
            EXPECT_EQ(b2.objects, b.objects);
        }
    }
}
