// The RCP UDP protocol, version 1 (specs/rcp-udp.md): constants, object and data types, and the
// codec of beacon and data packets. Parsers never throw on bad input, never read outside the
// packet, and report the first fault with its reason and byte offset; parse_data allocates
// nothing. Encoders write whole zero-padded 1000-byte packets. Pure functions: any thread.
//
// Telling a beacon from a data packet on one port (the spec puts beacons on the IOC's beacon port
// and data on port_ioc, which may be the same port): byte 9 decides. In a beacon it is the first
// character of the application name, which must be one of [A-Za-z0-9_:.-] (all >= 0x2D); in a
// data packet it is the object_type of the first entry (1..7) or, in a packet without entries,
// padding (0). So classify() says Beacon exactly when byte 9 is a name character; the version
// byte (8) is then checked by parse_beacon (WrongVersion) rather than used to classify, because
// byte 8 of a data packet is an object id, and ids 1 and 0x81 are legal there.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace beamctl::bridge::rcp {

inline constexpr std::size_t kPacketSize = 1000;     // every packet, exactly [bytes]
inline constexpr uint8_t kVersion = 1;               // beacon byte 8
inline constexpr uint8_t kContinuationFlag = 0x80;   // beacon byte 8 = 1 | 0x80
inline constexpr std::size_t kNameSize = 40;         // name[40]: at most 39 characters + NUL
inline constexpr std::size_t kBeaconHeaderSize = 49; // timestamp, version, application
inline constexpr std::size_t kBeaconObjectSize = 55; // one object record in a beacon
inline constexpr std::size_t kDataHeaderSize = 8;    // timestamp
inline constexpr std::size_t kEntryHeaderSize = 45;  // id, type, data type, count, name
inline constexpr std::size_t kMaxBeaconObjects = 17; // per beacon packet
inline constexpr std::size_t kMaxDataEntries = 21;   // (1000 - 8 - 1) / (45 + 1)
inline constexpr std::size_t kMaxValues = 946;       // 1000 - 8 - 45 - 1 one-byte values
inline constexpr uint16_t kMotorValueCount = 5;      // MOTOR entries, both directions
inline constexpr uint16_t kDefaultPort = 18065;      // the IOC's beacon port

using Packet = std::array<uint8_t, kPacketSize>;

enum class ObjectType : uint8_t { AI = 1, AO = 2, BI = 3, BO = 4, LI = 5, LO = 6, Motor = 7 };
enum class DataType : uint8_t {
    Bool = 0,
    Int8 = 1,
    UInt8 = 2,
    Int16 = 3,
    UInt16 = 4,
    Int32 = 5,
    UInt32 = 6,
    Float32 = 7,
    Float64 = 8,
};

const char* to_string(ObjectType t); // "AI" ... "MOTOR"; "?" for values outside the enum
const char* to_string(DataType t);   // "bool" ... "float64"
bool parse_object_type(std::string_view s, ObjectType& out); // "AI" ... "MOTOR" (any case)
bool parse_data_type(std::string_view s, DataType& out);     // "bool" ... "float64" (any case)
std::size_t data_type_size(DataType t);                      // bytes of one value
inline bool is_output(ObjectType t) {
    return t == ObjectType::AO || t == ObjectType::BO || t == ObjectType::LO;
}

// MOTOR command (IOC -> RCP, value [0]).
enum class MotorCommand : uint8_t {
    None = 0,
    MoveAbsolute = 1,
    Stop = 2,
    HomeForward = 3,
    HomeReverse = 4,
    JogForward = 5,
    JogReverse = 6,
    Enable = 7,
    Disable = 8,
};
// MOTOR status bits (RCP -> IOC, value [2]).
namespace motor_status {
inline constexpr uint32_t kDone = 1u << 0, kMoving = 1u << 1, kHighLimit = 1u << 2,
                          kLowLimit = 1u << 3, kHomed = 1u << 4, kError = 1u << 5,
                          kEnabled = 1u << 6;
}

// Why a packet was refused. The codec reports Short..BadMotor; the bridge and the simulator
// add the rest, which need the announced model.
enum class Malformed : uint8_t {
    None = 0,
    Short,              // fewer than 1000 bytes
    Long,               // more than 1000 bytes
    WrongVersion,       // beacon version byte not 1 or 1|0x80
    UnknownType,        // object_type not 1..7 or data_type not 0..8
    UnterminatedName,   // name[40] without a NUL
    BadName,            // empty name or a character outside [A-Za-z0-9_:.-]
    ZeroCount,          // data entry with value_count 0
    CountOverflow,      // the values of an entry run past the packet (room for the end byte)
    Truncated,          // a record/entry header runs past the packet: no terminating id 0
    DuplicateObject,    // an object id or name twice in one beacon (or beacon + continuation)
    BadMotor,           // MOTOR object not float64, or a MOTOR entry with count != 5
    UnknownApplication, // a beacon refused: name used by another address, or too many
                        // applications (data before any beacon is counted apart, not here)
    UnknownObject,      // data entry for an id the application's beacon does not list
    TypeMismatch,       // entry object/data type differs from the beacon's
    NameMismatch,       // entry name differs from the beacon's name for that id
    CountMismatch,      // entry count differs from the count learned from the first data
    NotWritable,        // a write for an object the receiver does not accept writes for
};
inline constexpr std::size_t kMalformedReasons = std::size_t(Malformed::NotWritable) + 1;
const char* to_string(Malformed m); // "Short", "WrongVersion", ... ("None" for None)

// Outcome of a parse: the first fault and where it is (byte offset from the packet start).
struct ParseResult {
    Malformed reason = Malformed::None;
    uint16_t offset = 0; // [bytes]
    bool ok() const { return reason == Malformed::None; }
    explicit operator bool() const { return ok(); }
};

struct BeaconObject {
    uint8_t id = 0; // 1..255
    ObjectType type = ObjectType::AI;
    DataType data_type = DataType::Float64;
    uint32_t ip_rcp = 0; // IPv4 as a number (192.168.167.42 = 0xC0A8A72A); where writes go
    uint16_t port_rcp = 0;
    uint32_t ip_ioc = 0; // where the RCP sends this object's data
    uint16_t port_ioc = 0;
    std::string name; // PV name suffix, 1..39 characters of [A-Za-z0-9_:.-]
    bool operator==(const BeaconObject&) const = default;
};

struct Beacon {
    double timestamp = 0; // [s] RCP model time
    std::string application;
    bool continuation = false; // version byte 1|0x80
    std::vector<BeaconObject> objects;
};

// One object entry of a data packet. After parse_data, `name` and `values` point into the
// parsed input and the DataPacket respectively; for write_data the caller provides both.
struct DataEntry {
    uint8_t id = 0;
    ObjectType type = ObjectType::AI;
    DataType data_type = DataType::Float64;
    uint16_t count = 0; // value_count (>= 1)
    std::string_view name;
    std::span<const double> values; // `count` values, converted from/to the wire type
};

// A parsed data packet with fixed storage (no allocation). Not copyable: entries point into it.
struct DataPacket {
    double timestamp = 0; // [s] RCP model time
    std::size_t entry_count = 0;
    std::array<DataEntry, kMaxDataEntries> entries{};
    std::array<double, kMaxValues> values{};

    DataPacket() = default;
    DataPacket(const DataPacket&) = delete;
    DataPacket& operator=(const DataPacket&) = delete;
    std::span<const DataEntry> view() const { return {entries.data(), entry_count}; }
};

enum class PacketKind : uint8_t { Beacon, Data };
// Which parser a datagram goes to (see the top of this file). Any size.
PacketKind classify(std::span<const uint8_t> packet) noexcept;

// Parses a beacon packet into `out` (its vectors keep their capacity). On failure `out` is
// unspecified.
ParseResult parse_beacon(std::span<const uint8_t> packet, Beacon& out);
// Parses a data packet into `out`. Entry names point into `packet`.
ParseResult parse_data(std::span<const uint8_t> packet, DataPacket& out) noexcept;

// Encoder results: the first entry/object (index) that could not be written, and why.
enum class WriteStatus : uint8_t {
    Ok,
    NoRoom,   // the objects/entries do not fit one packet (with the terminating id 0)
    BadName,  // application or object name not 1..39 characters of [A-Za-z0-9_:.-]
    BadId,    // object id 0
    BadType,  // object/data type outside the enums, or a MOTOR object that is not float64
    BadCount, // count 0, values.size() != count, or a MOTOR entry with count != 5
    BadValue, // a value the data type cannot represent (out of range, NaN for an integer)
};
const char* to_string(WriteStatus s);
struct WriteResult {
    WriteStatus status = WriteStatus::Ok;
    std::size_t index = 0; // of the offending object/entry
    bool ok() const { return status == WriteStatus::Ok; }
    explicit operator bool() const { return ok(); }
};

// Writes one beacon packet (at most 17 objects). `out` is fully overwritten (zero padding).
WriteResult write_beacon(Packet& out, double timestamp, std::string_view application,
                         bool continuation, std::span<const BeaconObject> objects) noexcept;
// Writes one data packet with `entries` in order. `out` is fully overwritten.
WriteResult write_data(Packet& out, double timestamp, std::span<const DataEntry> entries) noexcept;

// Bytes one data entry takes on the wire.
std::size_t entry_wire_size(DataType t, uint16_t count);
// True for 1..39 characters of [A-Za-z0-9_:.-].
bool valid_name(std::string_view name);
bool is_name_char(uint8_t c);
// Encodes v as data type t into dst (little-endian). Integers are rounded to nearest; false
// (dst untouched) when t cannot represent v: NaN or out of range for integers, a bool other than
// 0 or 1, a finite value beyond the float32 range.
bool encode_value(DataType t, double v, uint8_t* dst) noexcept;
// Decodes one value of type t from src (bool: any non-zero byte is 1).
double decode_value(DataType t, const uint8_t* src) noexcept;

// "192.168.167.42" <-> 0xC0A8A72A. parse_ipv4 accepts dotted quads only (no names).
std::string ipv4_to_string(uint32_t ip);
bool parse_ipv4(std::string_view s, uint32_t& out);

} // namespace beamctl::bridge::rcp
