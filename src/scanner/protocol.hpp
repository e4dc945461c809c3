// The bus scanner's control protocol, version 1 (docs/scanner.md, "Protocol"): what an IOC and the
// scanner say to each other on the scanner's UNIX stream socket. Process data does not travel
// here (shared memory, per cycle); this carries the handshake, the chain and layout, claims,
// acyclic access (SDO, AL state), status and goodbye.
//
// Frame: a 16-byte header, little-endian, then the body:
//   magic u32 "BCSP" | version u16 | type u16 | length u32 (body bytes, <= 1 MiB) | request_id u32
// Body fields are little-endian; a string is u16 length + UTF-8 bytes; a list is u16 count +
// elements; bytes are u16 length + bytes. A body must be consumed exactly (trailing bytes are an
// error). An unknown type, a bad magic or version, a length over the limit or a body that does not
// parse is an error naming the frame's offset in the stream and what is wrong; the connection that
// sent it is closed (nothing else is affected). Versions are negotiated in Hello/Welcome.
// Threading: none; Decoder is one connection's, used by one thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <variant>
#include <vector>

namespace beamctl::scanner::proto {

constexpr uint32_t kMagic = 0x50534342;  // "BCSP" in stream order
constexpr uint16_t kVersion = 1;          // this implementation speaks 1..kVersion
constexpr std::size_t kHeaderSize = 16;
constexpr uint32_t kMaxBody = 1u << 20;   // [bytes]
constexpr std::size_t kMaxSdoBytes = 512; // SDO data in one message

enum class Type : uint16_t {
    Hello = 1,     // client -> scanner: versions, who it is
    Welcome,       // scanner -> client: the version chosen, the buses
    Describe,      // client -> scanner: a bus's chain (no attach)
    Chain,         //   its answer
    Attach,        // client -> scanner: slaves, output claims, queue depth, detach policy
    Attached,      //   its answer: the layout (shared memory comes with it, SCM_RIGHTS)
    Error,         // scanner -> client: a request refused (code, text)
    Detach,        // client -> scanner: release the claims
    SdoRead,       // client -> scanner
    SdoWrite,      // client -> scanner
    SdoData,       //   the answer to SdoRead
    Ok,            //   the answer to SdoWrite, Detach
    AlInfoRequest, // client -> scanner: one slave's AL state and health
    AlInfo,        //   its answer
    StatusRequest, // any client (`beamctl scanner status`)
    Status,        //   its answer: bus counters and clients
    Goodbye,       // scanner -> client: the scanner is stopping
};
constexpr uint16_t kLastType = uint16_t(Type::Goodbye);
const char* to_string(Type t);

enum class ErrorCode : uint16_t {
    BadMessage = 1, NoCommonVersion, UnknownBus, UnknownSlave, ClaimConflict, RateMismatch,
    Full, Denied, SdoAbort, Timeout, Busy,
};
const char* to_string(ErrorCode c);

struct Hello {
    uint16_t min_version = 1, max_version = kVersion;
    std::string client;  // "beamctl 0.9"
    std::string ioc;     // the IOC's name
    uint32_t pid = 0;
    bool operator==(const Hello&) const = default;
};
struct BusInfo {
    uint16_t id = 0;
    uint64_t cycle_ns = 0;
    uint16_t slaves = 0;
    bool operator==(const BusInfo&) const = default;
};
struct Welcome {
    uint16_t version = kVersion;
    std::string scanner;   // "beamctl 0.9"
    uint64_t instance = 0; // changes at every scanner start
    std::vector<BusInfo> buses;
    bool operator==(const Welcome&) const = default;
};
struct Describe {
    uint16_t bus = 0;
    bool operator==(const Describe&) const = default;
};
struct ChainSlave {
    uint16_t position = 0;
    std::string name, type;  // "M1", "EL7041"
    uint32_t vendor = 0, product = 0, revision = 0;
    uint16_t oversampling = 1;
    bool operator==(const ChainSlave&) const = default;
};
struct Chain {
    uint16_t bus = 0;
    std::vector<ChainSlave> slaves;
    bool operator==(const Chain&) const = default;
};
struct Claim {
    std::string slave; // name or position
    std::string entry; // an output entry, or "*" for all of the slave's outputs
    bool operator==(const Claim&) const = default;
};
struct Attach {
    uint16_t bus = 0;
    std::vector<std::string> slaves; // names or positions
    std::vector<Claim> claims;
    uint16_t depth = 16;     // cycles the client's queue holds
    uint8_t on_detach = 0;   // 0: claimed outputs to zero, 1: hold
    bool operator==(const Attach&) const = default;
};
struct LayoutEntry {
    std::string name;        // "driveControl01"
    uint16_t index = 0;
    uint8_t sub = 0;
    uint16_t pdo = 0;
    uint32_t bit_offset = 0; // in the client's image
    uint8_t bits = 0;
    std::string datatype;
    bool output = false;
    bool operator==(const LayoutEntry&) const = default;
};
struct LayoutSlave {
    ChainSlave slave;
    uint32_t out_offset = 0, out_bytes = 0, in_offset = 0, in_bytes = 0; // [bytes] in the image
    std::vector<LayoutEntry> entries;
    bool operator==(const LayoutSlave&) const = default;
};
struct Attached {
    uint32_t client_id = 0;
    uint32_t image_bytes = 0;
    uint64_t layout_hash = 0;
    uint16_t depth = 0;
    std::vector<LayoutSlave> slaves;
    bool operator==(const Attached&) const = default;
};
struct ErrorMsg {
    ErrorCode code = ErrorCode::BadMessage;
    std::string text;
    uint32_t abort_code = 0; // SdoAbort: the CoE abort code
    bool operator==(const ErrorMsg&) const = default;
};
struct Detach {
    bool operator==(const Detach&) const = default;
};
struct SdoRead {
    uint16_t bus = 0, position = 0, index = 0;
    uint8_t sub = 0;
    bool complete_access = false;
    bool operator==(const SdoRead&) const = default;
};
struct SdoWrite {
    uint16_t bus = 0, position = 0, index = 0;
    uint8_t sub = 0;
    bool complete_access = false;
    std::vector<uint8_t> data; // <= kMaxSdoBytes
    bool operator==(const SdoWrite&) const = default;
};
struct SdoData {
    std::vector<uint8_t> data;
    bool operator==(const SdoData&) const = default;
};
struct Ok {
    bool operator==(const Ok&) const = default;
};
struct AlInfoRequest {
    uint16_t bus = 0, position = 0;
    bool operator==(const AlInfoRequest&) const = default;
};
struct AlInfo {
    uint8_t al_state = 0;      // AL status register (state | 0x10 error)
    uint16_t status_code = 0;  // AL status code
    uint8_t slave_state = 0;   // ethercat::SlaveState
    uint32_t lost = 0, reconfigured = 0, refused = 0, error_id = 0;
    std::string last_error;
    bool operator==(const AlInfo&) const = default;
};
struct StatusRequest {
    bool operator==(const StatusRequest&) const = default;
};
struct ClientStatus {
    std::string name;
    uint32_t pid = 0;
    uint16_t slaves = 0, claims = 0;
    uint64_t drops = 0, late = 0;
    bool operator==(const ClientStatus&) const = default;
};
struct Status {
    uint64_t cycle = 0, frames_lost = 0, wkc_errors = 0;
    std::vector<ClientStatus> clients;
    bool operator==(const Status&) const = default;
};
struct Goodbye {
    std::string reason;
    bool operator==(const Goodbye&) const = default;
};

// In Type order: the variant's index is the type minus 1.
using Body = std::variant<Hello, Welcome, Describe, Chain, Attach, Attached, ErrorMsg, Detach, SdoRead, SdoWrite,
                          SdoData, Ok, AlInfoRequest, AlInfo, StatusRequest, Status, Goodbye>;

struct Message {
    uint32_t request_id = 0; // a reply carries its request's id
    Body body;
    Type type() const { return Type(body.index() + 1); }
    bool operator==(const Message&) const = default;
};

// Appends the frame of `m` to `out`. Throws Error naming the field when a string or list is longer
// than its u16 length, SDO data is over kMaxSdoBytes or the body over kMaxBody.
void encode(const Message& m, std::vector<uint8_t>& out);

// One connection's incoming stream: bytes in as they arrive, whole messages out.
class Decoder {
public:
    enum class Result { Message, NeedMore, Error };
    void feed(const uint8_t* data, std::size_t n);
    // The next complete message, NeedMore, or Error (error() says what and at which stream offset;
    // the decoder stays in error: close the connection).
    Result next(Message& out);
    const std::string& error() const { return error_; }
    std::size_t buffered() const { return buf_.size() - at_; }

private:
    std::vector<uint8_t> buf_;
    std::size_t at_ = 0;       // next unread byte of buf_
    uint64_t consumed_ = 0;    // stream bytes before buf_[0]
    std::string error_;
};

} // namespace beamctl::scanner::proto
