#include "scanner/protocol.hpp"

#include "core/error.hpp"

#include <cstring>
#include <type_traits>

namespace beamctl::scanner::proto {

const char* to_string(Type t) {
    static const char* names[] = {"Hello",   "Welcome",   "Describe", "Chain", "Attach", "Attached",
                                  "Error",   "Detach",    "SdoRead",  "SdoWrite", "SdoData", "Ok",
                                  "AlInfoRequest", "AlInfo", "StatusRequest", "Status", "Goodbye"};
    uint16_t i = uint16_t(t);
    return i >= 1 && i <= kLastType ? names[i - 1] : "unknown";
}

const char* to_string(ErrorCode c) {
    static const char* names[] = {"BadMessage", "NoCommonVersion", "UnknownBus", "UnknownSlave", "ClaimConflict",
                                  "RateMismatch", "Full", "Denied", "SdoAbort", "Timeout", "Busy"};
    uint16_t i = uint16_t(c);
    return i >= 1 && i <= uint16_t(ErrorCode::Busy) ? names[i - 1] : "unknown";
}

namespace {

// ---- the two directions of one description of each body ---------------------------------------

class Writer {
public:
    explicit Writer(std::vector<uint8_t>& out) : out_(out) {}
    template <class T> void put_le(T v) {
        for (std::size_t i = 0; i < sizeof(T); ++i) out_.push_back(uint8_t(uint64_t(v) >> (8 * i)));
    }
    void operator()(const uint8_t& v, const char*) { put_le(v); }
    void operator()(const uint16_t& v, const char*) { put_le(v); }
    void operator()(const uint32_t& v, const char*) { put_le(v); }
    void operator()(const uint64_t& v, const char*) { put_le(v); }
    void operator()(const bool& v, const char*) { put_le(uint8_t(v ? 1 : 0)); }
    void operator()(const ErrorCode& v, const char*) { put_le(uint16_t(v)); }
    void operator()(const std::string& s, const char* what) {
        if (s.size() > 0xFFFF) throw Error(SB() << "scanner protocol: " << what << ": " << s.size() << " bytes, at most 65535");
        put_le(uint16_t(s.size()));
        out_.insert(out_.end(), s.begin(), s.end());
    }
    void operator()(const std::vector<uint8_t>& b, const char* what) {
        if (b.size() > kMaxSdoBytes) throw Error(SB() << "scanner protocol: " << what << ": " << b.size() << " bytes, at most " << kMaxSdoBytes);
        put_le(uint16_t(b.size()));
        out_.insert(out_.end(), b.begin(), b.end());
    }
    template <class T> void operator()(const std::vector<T>& v, const char* what) {
        if (v.size() > 0xFFFF) throw Error(SB() << "scanner protocol: " << what << ": " << v.size() << " elements, at most 65535");
        put_le(uint16_t(v.size()));
        for (const T& x : v) (*this)(x, what);
    }
    template <class T> std::enable_if_t<std::is_class_v<T>> operator()(const T& x, const char*) { io(*this, const_cast<T&>(x)); }

private:
    std::vector<uint8_t>& out_;
};

class Reader {
public:
    Reader(const uint8_t* p, std::size_t n) : p_(p), n_(n) {}
    bool ok() const { return error_.empty(); }
    const std::string& error() const { return error_; }
    std::size_t at() const { return at_; }
    std::size_t left() const { return n_ - at_; }
    void fail(std::string why) {
        if (error_.empty()) error_ = std::move(why);
    }
    template <class T> bool get_le(T& v, const char* what) {
        if (!ok()) return false;
        if (left() < sizeof(T)) {
            fail(SB() << what << ": the body ends at byte " << n_ << ", " << sizeof(T) << " more needed at byte " << at_);
            return false;
        }
        uint64_t x = 0;
        for (std::size_t i = 0; i < sizeof(T); ++i) x |= uint64_t(p_[at_ + i]) << (8 * i);
        at_ += sizeof(T);
        v = T(x);
        return true;
    }
    void operator()(uint8_t& v, const char* what) { get_le(v, what); }
    void operator()(uint16_t& v, const char* what) { get_le(v, what); }
    void operator()(uint32_t& v, const char* what) { get_le(v, what); }
    void operator()(uint64_t& v, const char* what) { get_le(v, what); }
    void operator()(bool& v, const char* what) {
        uint8_t b = 0;
        if (!get_le(b, what)) return;
        if (b > 1) fail(SB() << what << ": " << int(b) << " is not a boolean (0 or 1)");
        v = b != 0;
    }
    void operator()(ErrorCode& v, const char* what) {
        uint16_t c = 0;
        if (!get_le(c, what)) return;
        if (c < 1 || c > uint16_t(ErrorCode::Busy)) fail(SB() << what << ": unknown error code " << c);
        v = ErrorCode(c);
    }
    void operator()(std::string& s, const char* what) {
        uint16_t len = 0;
        if (!get_le(len, what)) return;
        if (left() < len) return fail(SB() << what << ": a string of " << len << " bytes, " << left() << " left in the body");
        s.assign(reinterpret_cast<const char*>(p_ + at_), len);
        at_ += len;
    }
    void operator()(std::vector<uint8_t>& b, const char* what) {
        uint16_t len = 0;
        if (!get_le(len, what)) return;
        if (len > kMaxSdoBytes) return fail(SB() << what << ": " << len << " bytes, at most " << kMaxSdoBytes);
        if (left() < len) return fail(SB() << what << ": " << len << " bytes, " << left() << " left in the body");
        b.assign(p_ + at_, p_ + at_ + len);
        at_ += len;
    }
    template <class T> void operator()(std::vector<T>& v, const char* what) {
        uint16_t count = 0;
        if (!get_le(count, what)) return;
        // every element takes at least a byte: a count the body cannot hold is refused before
        // anything is allocated for it
        if (count > left()) return fail(SB() << what << ": " << count << " elements, " << left() << " bytes left in the body");
        v.clear();
        v.reserve(count);
        for (uint16_t i = 0; i < count && ok(); ++i) {
            v.emplace_back();
            (*this)(v.back(), what);
        }
    }
    template <class T> std::enable_if_t<std::is_class_v<T>> operator()(T& x, const char*) { io(*this, x); }

private:
    const uint8_t* p_;
    std::size_t n_, at_ = 0;
    std::string error_;
};

// ---- the bodies (one description, both directions) ---------------------------------------------
template <class A> void io(A& a, Hello& m) {
    a(m.min_version, "min_version"), a(m.max_version, "max_version"), a(m.client, "client"), a(m.ioc, "ioc"), a(m.pid, "pid");
}
template <class A> void io(A& a, BusInfo& m) { a(m.id, "bus.id"), a(m.cycle_ns, "bus.cycle_ns"), a(m.slaves, "bus.slaves"); }
template <class A> void io(A& a, Welcome& m) {
    a(m.version, "version"), a(m.scanner, "scanner"), a(m.instance, "instance"), a(m.buses, "buses");
}
template <class A> void io(A& a, Describe& m) { a(m.bus, "bus"); }
template <class A> void io(A& a, ChainSlave& m) {
    a(m.position, "slave.position"), a(m.name, "slave.name"), a(m.type, "slave.type"), a(m.vendor, "slave.vendor"),
        a(m.product, "slave.product"), a(m.revision, "slave.revision"), a(m.oversampling, "slave.oversampling");
}
template <class A> void io(A& a, Chain& m) { a(m.bus, "bus"), a(m.slaves, "slaves"); }
template <class A> void io(A& a, Claim& m) { a(m.slave, "claim.slave"), a(m.entry, "claim.entry"); }
template <class A> void io(A& a, Attach& m) {
    a(m.bus, "bus"), a(m.slaves, "slaves"), a(m.claims, "claims"), a(m.depth, "depth"), a(m.on_detach, "on_detach");
}
template <class A> void io(A& a, LayoutEntry& m) {
    a(m.name, "entry.name"), a(m.index, "entry.index"), a(m.sub, "entry.sub"), a(m.pdo, "entry.pdo"),
        a(m.bit_offset, "entry.bit_offset"), a(m.bits, "entry.bits"), a(m.datatype, "entry.datatype"), a(m.output, "entry.output");
}
template <class A> void io(A& a, LayoutSlave& m) {
    a(m.slave, "slave"), a(m.out_offset, "slave.out_offset"), a(m.out_bytes, "slave.out_bytes"),
        a(m.in_offset, "slave.in_offset"), a(m.in_bytes, "slave.in_bytes"), a(m.entries, "slave.entries");
}
template <class A> void io(A& a, Attached& m) {
    a(m.client_id, "client_id"), a(m.image_bytes, "image_bytes"), a(m.layout_hash, "layout_hash"), a(m.depth, "depth"),
        a(m.slaves, "slaves");
}
template <class A> void io(A& a, ErrorMsg& m) { a(m.code, "code"), a(m.text, "text"), a(m.abort_code, "abort_code"); }
template <class A> void io(A&, Detach&) {}
template <class A> void io(A& a, SdoRead& m) {
    a(m.bus, "bus"), a(m.position, "position"), a(m.index, "index"), a(m.sub, "sub"), a(m.complete_access, "complete_access");
}
template <class A> void io(A& a, SdoWrite& m) {
    a(m.bus, "bus"), a(m.position, "position"), a(m.index, "index"), a(m.sub, "sub"), a(m.complete_access, "complete_access"),
        a(m.data, "data");
}
template <class A> void io(A& a, SdoData& m) { a(m.data, "data"); }
template <class A> void io(A&, Ok&) {}
template <class A> void io(A& a, AlInfoRequest& m) { a(m.bus, "bus"), a(m.position, "position"); }
template <class A> void io(A& a, AlInfo& m) {
    a(m.al_state, "al_state"), a(m.status_code, "status_code"), a(m.slave_state, "slave_state"), a(m.lost, "lost"),
        a(m.reconfigured, "reconfigured"), a(m.refused, "refused"), a(m.error_id, "error_id"), a(m.last_error, "last_error");
}
template <class A> void io(A&, StatusRequest&) {}
template <class A> void io(A& a, ClientStatus& m) {
    a(m.name, "client.name"), a(m.pid, "client.pid"), a(m.slaves, "client.slaves"), a(m.claims, "client.claims"),
        a(m.drops, "client.drops"), a(m.late, "client.late");
}
template <class A> void io(A& a, Status& m) {
    a(m.cycle, "cycle"), a(m.frames_lost, "frames_lost"), a(m.wkc_errors, "wkc_errors"), a(m.clients, "clients");
}
template <class A> void io(A& a, Goodbye& m) { a(m.reason, "reason"); }

// The body of type t (1-based) decoded into `out`.
template <std::size_t I = 0> void decode_body(std::size_t index, Reader& r, Body& out) {
    if constexpr (I < std::variant_size_v<Body>) {
        if (index == I) {
            out.emplace<I>();
            io(r, std::get<I>(out));
            return;
        }
        decode_body<I + 1>(index, r, out);
    }
}

uint32_t le32(const uint8_t* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }
uint16_t le16(const uint8_t* p) { return uint16_t(p[0] | p[1] << 8); }

} // namespace

void encode(const Message& m, std::vector<uint8_t>& out) {
    std::vector<uint8_t> body;
    Writer w(body);
    std::visit([&](const auto& b) { io(w, const_cast<std::remove_cvref_t<decltype(b)>&>(b)); }, m.body);
    if (body.size() > kMaxBody)
        throw Error(SB() << "scanner protocol: a " << to_string(m.type()) << " body of " << body.size() << " bytes, at most " << kMaxBody);
    Writer h(out);
    h.put_le(kMagic);
    h.put_le(kVersion);
    h.put_le(uint16_t(m.type()));
    h.put_le(uint32_t(body.size()));
    h.put_le(m.request_id);
    out.insert(out.end(), body.begin(), body.end());
}

void Decoder::feed(const uint8_t* data, std::size_t n) {
    if (!error_.empty()) return;
    if (at_ > 0 && at_ == buf_.size()) { // all consumed: start over (no growth)
        consumed_ += at_;
        buf_.clear();
        at_ = 0;
    } else if (at_ > 65536) {
        consumed_ += at_;
        buf_.erase(buf_.begin(), buf_.begin() + std::ptrdiff_t(at_));
        at_ = 0;
    }
    buf_.insert(buf_.end(), data, data + n);
}

Decoder::Result Decoder::next(Message& out) {
    if (!error_.empty()) return Result::Error;
    if (buffered() < kHeaderSize) return Result::NeedMore;
    const uint8_t* h = buf_.data() + at_;
    const uint64_t offset = consumed_ + at_;
    auto fail = [&](const std::string& why) {
        error_ = SB() << "scanner protocol: frame at stream byte " << offset << ": " << why;
        return Result::Error;
    };
    if (le32(h) != kMagic) return fail("not a frame (no BCSP magic)");
    uint16_t version = le16(h + 4), type = le16(h + 6);
    uint32_t length = le32(h + 8), id = le32(h + 12);
    if (version < 1 || version > kVersion) return fail(SB() << "protocol version " << version << " (this side speaks 1.." << kVersion << ")");
    if (type < 1 || type > kLastType) return fail(SB() << "unknown message type " << type);
    if (length > kMaxBody) return fail(SB() << to_string(Type(type)) << ": body of " << length << " bytes, at most " << kMaxBody);
    if (buffered() < kHeaderSize + length) return Result::NeedMore;
    Reader r(h + kHeaderSize, length);
    Message m;
    m.request_id = id;
    decode_body(std::size_t(type - 1), r, m.body);
    if (r.ok() && r.left() != 0) r.fail(SB() << r.left() << " byte(s) after the end of the body's fields");
    if (!r.ok()) return fail(SB() << to_string(Type(type)) << ": " << r.error());
    at_ += kHeaderSize + length;
    out = std::move(m);
    return Result::Message;
}

} // namespace beamctl::scanner::proto
