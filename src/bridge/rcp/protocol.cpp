#include "bridge/rcp/protocol.hpp"

#include <bitset>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace beamctl::bridge::rcp {
namespace {

// Little-endian field access, independent of the host byte order.
uint16_t rd16(const uint8_t* p) {
    return uint16_t(p[0] | (p[1] << 8));
}
uint32_t rd32(const uint8_t* p) {
    return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24);
}
uint64_t rd64(const uint8_t* p) {
    return uint64_t(rd32(p)) | (uint64_t(rd32(p + 4)) << 32);
}
double rdf64(const uint8_t* p) {
    uint64_t u = rd64(p);
    double d;
    std::memcpy(&d, &u, 8);
    return d;
}
void wr16(uint8_t* p, uint16_t v) {
    p[0] = uint8_t(v);
    p[1] = uint8_t(v >> 8);
}
void wr32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
void wr64(uint8_t* p, uint64_t v) {
    for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
void wrf64(uint8_t* p, double d) {
    uint64_t u;
    std::memcpy(&u, &d, 8);
    wr64(p, u);
}

bool valid_object_type(uint8_t t) {
    return t >= 1 && t <= 7;
}
bool valid_data_type(uint8_t t) {
    return t <= 8;
}

// Checks name[40] at p (offset `at` in the packet); on success sets `out` to its text.
ParseResult check_name(const uint8_t* p, std::size_t at, std::string_view& out) {
    const void* nul = std::memchr(p, 0, kNameSize);
    if (!nul) return {Malformed::UnterminatedName, uint16_t(at)};
    std::size_t len = std::size_t(static_cast<const uint8_t*>(nul) - p);
    if (len == 0) return {Malformed::BadName, uint16_t(at)};
    for (std::size_t i = 0; i < len; ++i)
        if (!is_name_char(p[i])) return {Malformed::BadName, uint16_t(at + i)};
    out = std::string_view(reinterpret_cast<const char*>(p), len);
    return {};
}

ParseResult check_size(std::size_t n) {
    if (n < kPacketSize) return {Malformed::Short, uint16_t(n)};
    if (n > kPacketSize) return {Malformed::Long, uint16_t(kPacketSize)};
    return {};
}

template <typename T> bool encode_int(double v, uint8_t* dst, std::size_t n) {
    if (!std::isfinite(v)) return false;
    double r = std::round(v);
    if (r < double(std::numeric_limits<T>::lowest()) || r > double(std::numeric_limits<T>::max()))
        return false;
    T x = T(r);
    using U = std::make_unsigned_t<T>;
    U u = U(x);
    for (std::size_t i = 0; i < n; ++i) dst[i] = uint8_t(uint64_t(u) >> (8 * i));
    return true;
}

} // namespace

const char* to_string(ObjectType t) {
    switch (t) {
    case ObjectType::AI:
        return "AI";
    case ObjectType::AO:
        return "AO";
    case ObjectType::BI:
        return "BI";
    case ObjectType::BO:
        return "BO";
    case ObjectType::LI:
        return "LI";
    case ObjectType::LO:
        return "LO";
    case ObjectType::Motor:
        return "MOTOR";
    }
    return "?";
}

const char* to_string(DataType t) {
    switch (t) {
    case DataType::Bool:
        return "bool";
    case DataType::Int8:
        return "int8";
    case DataType::UInt8:
        return "uint8";
    case DataType::Int16:
        return "int16";
    case DataType::UInt16:
        return "uint16";
    case DataType::Int32:
        return "int32";
    case DataType::UInt32:
        return "uint32";
    case DataType::Float32:
        return "float32";
    case DataType::Float64:
        return "float64";
    }
    return "?";
}

namespace {
bool iequal(std::string_view a, std::string_view b) {
    if (a.size() != b.size()) return false;
    for (std::size_t i = 0; i < a.size(); ++i) {
        char x = a[i], y = b[i];
        if (x >= 'A' && x <= 'Z') x = char(x - 'A' + 'a');
        if (y >= 'A' && y <= 'Z') y = char(y - 'A' + 'a');
        if (x != y) return false;
    }
    return true;
}
} // namespace

bool parse_object_type(std::string_view s, ObjectType& out) {
    for (uint8_t t = 1; t <= 7; ++t)
        if (iequal(s, to_string(ObjectType(t)))) {
            out = ObjectType(t);
            return true;
        }
    return false;
}

bool parse_data_type(std::string_view s, DataType& out) {
    for (uint8_t t = 0; t <= 8; ++t)
        if (iequal(s, to_string(DataType(t)))) {
            out = DataType(t);
            return true;
        }
    return false;
}

std::size_t data_type_size(DataType t) {
    switch (t) {
    case DataType::Bool:
    case DataType::Int8:
    case DataType::UInt8:
        return 1;
    case DataType::Int16:
    case DataType::UInt16:
        return 2;
    case DataType::Int32:
    case DataType::UInt32:
    case DataType::Float32:
        return 4;
    case DataType::Float64:
        return 8;
    }
    return 1;
}

const char* to_string(Malformed m) {
    switch (m) {
    case Malformed::None:
        return "None";
    case Malformed::Short:
        return "Short";
    case Malformed::Long:
        return "Long";
    case Malformed::WrongVersion:
        return "WrongVersion";
    case Malformed::UnknownType:
        return "UnknownType";
    case Malformed::UnterminatedName:
        return "UnterminatedName";
    case Malformed::BadName:
        return "BadName";
    case Malformed::ZeroCount:
        return "ZeroCount";
    case Malformed::CountOverflow:
        return "CountOverflow";
    case Malformed::Truncated:
        return "Truncated";
    case Malformed::DuplicateObject:
        return "DuplicateObject";
    case Malformed::BadMotor:
        return "BadMotor";
    case Malformed::UnknownApplication:
        return "UnknownApplication";
    case Malformed::UnknownObject:
        return "UnknownObject";
    case Malformed::TypeMismatch:
        return "TypeMismatch";
    case Malformed::NameMismatch:
        return "NameMismatch";
    case Malformed::CountMismatch:
        return "CountMismatch";
    case Malformed::NotWritable:
        return "NotWritable";
    }
    return "?";
}

const char* to_string(WriteStatus s) {
    switch (s) {
    case WriteStatus::Ok:
        return "ok";
    case WriteStatus::NoRoom:
        return "does not fit one packet";
    case WriteStatus::BadName:
        return "bad name";
    case WriteStatus::BadId:
        return "object id 0";
    case WriteStatus::BadType:
        return "bad object or data type";
    case WriteStatus::BadCount:
        return "bad value count";
    case WriteStatus::BadValue:
        return "value not representable in the data type";
    }
    return "?";
}

bool is_name_char(uint8_t c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
           c == ':' || c == '.' || c == '-';
}

bool valid_name(std::string_view name) {
    if (name.empty() || name.size() >= kNameSize) return false;
    for (char c : name)
        if (!is_name_char(uint8_t(c))) return false;
    return true;
}

std::size_t entry_wire_size(DataType t, uint16_t count) {
    return kEntryHeaderSize + std::size_t(count) * data_type_size(t);
}

PacketKind classify(std::span<const uint8_t> packet) noexcept {
    return packet.size() > 9 && is_name_char(packet[9]) ? PacketKind::Beacon : PacketKind::Data;
}

ParseResult parse_beacon(std::span<const uint8_t> packet, Beacon& out) {
    out.objects.clear();
    out.application.clear();
    if (ParseResult r = check_size(packet.size()); !r) return r;
    const uint8_t* p = packet.data();
    out.timestamp = rdf64(p);
    uint8_t version = p[8];
    if ((version & ~kContinuationFlag) != kVersion) return {Malformed::WrongVersion, 8};
    out.continuation = (version & kContinuationFlag) != 0;
    std::string_view app;
    if (ParseResult r = check_name(p + 9, 9, app); !r) return r;
    out.application.assign(app);
    std::bitset<256> ids;
    std::size_t at = kBeaconHeaderSize;
    for (;;) {
        if (at >= kPacketSize) return {Malformed::Truncated, uint16_t(kPacketSize - 1)};
        uint8_t id = p[at];
        if (id == 0) break;
        // The record and the terminating id 0 after it must fit.
        if (at + kBeaconObjectSize >= kPacketSize) return {Malformed::Truncated, uint16_t(at)};
        const uint8_t* o = p + at;
        if (!valid_object_type(o[1])) return {Malformed::UnknownType, uint16_t(at + 1)};
        if (!valid_data_type(o[2])) return {Malformed::UnknownType, uint16_t(at + 2)};
        std::string_view name;
        if (ParseResult r = check_name(o + 15, at + 15, name); !r) return r;
        if (ids[id]) return {Malformed::DuplicateObject, uint16_t(at)};
        for (const BeaconObject& prev : out.objects)
            if (prev.name == name) return {Malformed::DuplicateObject, uint16_t(at + 15)};
        ids[id] = true;
        BeaconObject b;
        b.id = id;
        b.type = ObjectType(o[1]);
        b.data_type = DataType(o[2]);
        if (b.type == ObjectType::Motor && b.data_type != DataType::Float64)
            return {Malformed::BadMotor, uint16_t(at + 2)};
        b.ip_rcp = rd32(o + 3);
        b.port_rcp = rd16(o + 7);
        b.ip_ioc = rd32(o + 9);
        b.port_ioc = rd16(o + 13);
        b.name.assign(name);
        out.objects.push_back(std::move(b));
        at += kBeaconObjectSize;
    }
    return {};
}

double decode_value(DataType t, const uint8_t* s) noexcept {
    switch (t) {
    case DataType::Bool:
        return s[0] ? 1.0 : 0.0;
    case DataType::Int8:
        return double(int8_t(s[0]));
    case DataType::UInt8:
        return double(s[0]);
    case DataType::Int16:
        return double(int16_t(rd16(s)));
    case DataType::UInt16:
        return double(rd16(s));
    case DataType::Int32:
        return double(int32_t(rd32(s)));
    case DataType::UInt32:
        return double(rd32(s));
    case DataType::Float32: {
        uint32_t u = rd32(s);
        float f;
        std::memcpy(&f, &u, 4);
        return double(f);
    }
    case DataType::Float64:
        return rdf64(s);
    }
    return 0;
}

bool encode_value(DataType t, double v, uint8_t* dst) noexcept {
    switch (t) {
    case DataType::Bool:
        if (v != 0 && v != 1) return false;
        dst[0] = v != 0 ? 1 : 0;
        return true;
    case DataType::Int8:
        return encode_int<int8_t>(v, dst, 1);
    case DataType::UInt8:
        return encode_int<uint8_t>(v, dst, 1);
    case DataType::Int16:
        return encode_int<int16_t>(v, dst, 2);
    case DataType::UInt16:
        return encode_int<uint16_t>(v, dst, 2);
    case DataType::Int32:
        return encode_int<int32_t>(v, dst, 4);
    case DataType::UInt32:
        return encode_int<uint32_t>(v, dst, 4);
    case DataType::Float32: {
        if (std::isfinite(v) && std::fabs(v) > double(std::numeric_limits<float>::max()))
            return false;
        float f = float(v);
        uint32_t u;
        std::memcpy(&u, &f, 4);
        wr32(dst, u);
        return true;
    }
    case DataType::Float64:
        wrf64(dst, v);
        return true;
    }
    return false;
}

ParseResult parse_data(std::span<const uint8_t> packet, DataPacket& out) noexcept {
    out.entry_count = 0;
    if (ParseResult r = check_size(packet.size()); !r) return r;
    const uint8_t* p = packet.data();
    out.timestamp = rdf64(p);
    std::size_t at = kDataHeaderSize;
    std::size_t used = 0; // values in out.values
    for (;;) {
        if (at >= kPacketSize) return {Malformed::Truncated, uint16_t(kPacketSize - 1)};
        uint8_t id = p[at];
        if (id == 0) break;
        if (at + kEntryHeaderSize >= kPacketSize) return {Malformed::Truncated, uint16_t(at)};
        const uint8_t* e = p + at;
        if (!valid_object_type(e[1])) return {Malformed::UnknownType, uint16_t(at + 1)};
        if (!valid_data_type(e[2])) return {Malformed::UnknownType, uint16_t(at + 2)};
        DataEntry d;
        d.id = id;
        d.type = ObjectType(e[1]);
        d.data_type = DataType(e[2]);
        d.count = rd16(e + 3);
        if (d.count == 0) return {Malformed::ZeroCount, uint16_t(at + 3)};
        if (ParseResult r = check_name(e + 5, at + 5, d.name); !r) return r;
        std::size_t size = data_type_size(d.data_type);
        std::size_t bytes = std::size_t(d.count) * size;
        std::size_t values_at = at + kEntryHeaderSize;
        // The values and the terminating id 0 after them must fit.
        if (values_at + bytes >= kPacketSize) return {Malformed::CountOverflow, uint16_t(at + 3)};
        if (d.type == ObjectType::Motor &&
            (d.data_type != DataType::Float64 || d.count != kMotorValueCount))
            return {Malformed::BadMotor,
                    uint16_t(d.data_type != DataType::Float64 ? at + 2 : at + 3)};
        // Cannot overflow: every entry takes at least 46 bytes and one byte per value.
        if (out.entry_count >= kMaxDataEntries || used + d.count > kMaxValues)
            return {Malformed::CountOverflow, uint16_t(at + 3)};
        double* v = out.values.data() + used;
        for (std::size_t i = 0; i < d.count; ++i)
            v[i] = decode_value(d.data_type, p + values_at + i * size);
        d.values = std::span<const double>(v, d.count);
        used += d.count;
        out.entries[out.entry_count++] = d;
        at = values_at + bytes;
    }
    return {};
}

WriteResult write_beacon(Packet& out, double timestamp, std::string_view application,
                         bool continuation, std::span<const BeaconObject> objects) noexcept {
    out.fill(0);
    if (!valid_name(application)) return {WriteStatus::BadName, 0};
    if (objects.size() > kMaxBeaconObjects) return {WriteStatus::NoRoom, kMaxBeaconObjects};
    uint8_t* p = out.data();
    wrf64(p, timestamp);
    p[8] = uint8_t(kVersion | (continuation ? kContinuationFlag : 0));
    std::memcpy(p + 9, application.data(), application.size());
    std::size_t at = kBeaconHeaderSize;
    for (std::size_t i = 0; i < objects.size(); ++i) {
        const BeaconObject& b = objects[i];
        if (b.id == 0) return out.fill(0), WriteResult{WriteStatus::BadId, i};
        if (!valid_object_type(uint8_t(b.type)) || !valid_data_type(uint8_t(b.data_type)) ||
            (b.type == ObjectType::Motor && b.data_type != DataType::Float64))
            return out.fill(0), WriteResult{WriteStatus::BadType, i};
        if (!valid_name(b.name)) return out.fill(0), WriteResult{WriteStatus::BadName, i};
        uint8_t* o = p + at;
        o[0] = b.id;
        o[1] = uint8_t(b.type);
        o[2] = uint8_t(b.data_type);
        wr32(o + 3, b.ip_rcp);
        wr16(o + 7, b.port_rcp);
        wr32(o + 9, b.ip_ioc);
        wr16(o + 13, b.port_ioc);
        std::memcpy(o + 15, b.name.data(), b.name.size());
        at += kBeaconObjectSize;
    }
    return {}; // p[at] is the terminating 0 (the packet was zeroed)
}

WriteResult write_data(Packet& out, double timestamp, std::span<const DataEntry> entries) noexcept {
    out.fill(0);
    uint8_t* p = out.data();
    wrf64(p, timestamp);
    std::size_t at = kDataHeaderSize;
    for (std::size_t i = 0; i < entries.size(); ++i) {
        const DataEntry& d = entries[i];
        auto fail = [&](WriteStatus s) {
            out.fill(0);
            return WriteResult{s, i};
        };
        if (d.id == 0) return fail(WriteStatus::BadId);
        if (!valid_object_type(uint8_t(d.type)) || !valid_data_type(uint8_t(d.data_type)))
            return fail(WriteStatus::BadType);
        if (d.count == 0 || d.values.size() != d.count) return fail(WriteStatus::BadCount);
        if (d.type == ObjectType::Motor) {
            if (d.data_type != DataType::Float64) return fail(WriteStatus::BadType);
            if (d.count != kMotorValueCount) return fail(WriteStatus::BadCount);
        }
        if (!valid_name(d.name)) return fail(WriteStatus::BadName);
        std::size_t size = data_type_size(d.data_type);
        if (at + kEntryHeaderSize + std::size_t(d.count) * size >= kPacketSize)
            return fail(WriteStatus::NoRoom);
        uint8_t* e = p + at;
        e[0] = d.id;
        e[1] = uint8_t(d.type);
        e[2] = uint8_t(d.data_type);
        wr16(e + 3, d.count);
        std::memcpy(e + 5, d.name.data(), d.name.size());
        uint8_t* v = e + kEntryHeaderSize;
        for (std::size_t k = 0; k < d.count; ++k)
            if (!encode_value(d.data_type, d.values[k], v + k * size))
                return fail(WriteStatus::BadValue);
        at += kEntryHeaderSize + std::size_t(d.count) * size;
    }
    return {};
}

std::string ipv4_to_string(uint32_t ip) {
    char b[16];
    std::snprintf(b, sizeof b, "%u.%u.%u.%u", unsigned(ip >> 24), unsigned((ip >> 16) & 255),
                  unsigned((ip >> 8) & 255), unsigned(ip & 255));
    return b;
}

bool parse_ipv4(std::string_view s, uint32_t& out) {
    uint32_t ip = 0;
    int parts = 0;
    std::size_t i = 0;
    while (parts < 4) {
        if (i >= s.size() || s[i] < '0' || s[i] > '9') return false;
        uint32_t v = 0;
        std::size_t digits = 0;
        while (i < s.size() && s[i] >= '0' && s[i] <= '9') {
            v = v * 10 + uint32_t(s[i] - '0');
            if (++digits > 3 || v > 255) return false;
            ++i;
        }
        ip = (ip << 8) | v;
        if (++parts < 4) {
            if (i >= s.size() || s[i] != '.') return false;
            ++i;
        }
    }
    if (i != s.size()) return false;
    out = ip;
    return true;
}

} // namespace beamctl::bridge::rcp
