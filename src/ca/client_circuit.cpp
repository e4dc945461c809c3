#include "ca/client_circuit.hpp"

#include "ca/dbr.hpp"
#include "core/error.hpp"

#include <cstring>

namespace beamctl::ca {

ClientCircuit::ClientCircuit(ClientCircuitHandler& h, ClientStats& stats, std::size_t max_payload)
    : h_(h), stats_(stats), max_payload_(max_payload) {}

void ClientCircuit::fail(std::string why) {
    if (close_) return;
    close_ = true;
    error_ = std::move(why);
    stats_.protocol_errors++;
    in_.clear();
}

void ClientCircuit::receive(const uint8_t* data, std::size_t n) {
    if (close_) return;
    in_.append(reinterpret_cast<const char*>(data), n);
    std::size_t off = 0;
    while (!close_) {
        const uint8_t* p = reinterpret_cast<const uint8_t*>(in_.data()) + off;
        std::size_t avail = in_.size() - off;
        Header h;
        std::size_t hs = decode_header(p, avail, true, h);
        if (hs == 0) break;
        if (h.payload_size > max_payload_) {
            fail(SB() << cmd_name(h.cmd) << " with a payload of " << h.payload_size << " bytes (limit " << max_payload_
                      << ")");
            break;
        }
        if (avail < hs + h.payload_size) break;
        stats_.messages++;
        dispatch(h, p + hs);
        off += hs + h.payload_size;
    }
    if (close_) return;
    in_.erase(0, off);
}

void ClientCircuit::dispatch(const Header& h, const uint8_t* payload) {
    std::size_t len = h.payload_size;
    // A value reply: a known value type, and as many bytes as its type and count need.
    auto value_ok = [&](const char* what) {
        if (h.dtype > 34) {
            fail(SB() << what << " with DBR type " << h.dtype);
            return false;
        }
        if (h.count > (1u << 28) || len < dbr_payload_size(h.dtype, h.count)) {
            fail(SB() << what << " of " << h.count << " element(s) of DBR type " << h.dtype << " in " << len
                      << " bytes");
            return false;
        }
        return true;
    };
    switch (h.cmd) {
    case kVersion:
        server_minor_ = uint16_t(h.count);
        h_.on_server_version(server_minor_);
        return;
    case kAccessRights: h_.on_access_rights(h.p1, h.p2); return;
    case kCreateChan:
        if (h.dtype > 6) return fail(SB() << "CREATE_CHAN reply with native DBR type " << h.dtype);
        h_.on_create_chan(h.p1, h.p2, h.dtype, h.count);
        return;
    case kCreateChFail: h_.on_create_fail(h.p1); return;
    case kServerDisconn: h_.on_server_disconn(h.p1); return;
    case kReadNotify:
        if (h.p1 == kEcaNormal && !value_ok("READ_NOTIFY reply")) return;
        h_.on_read(h.p2, h.p1, h.dtype, h.count, payload, len);
        return;
    case kEventAdd:
        if (len == 0) { // EVENT_CANCEL confirmation
            h_.on_event_cancelled(h.p2);
            return;
        }
        if (h.p1 == kEcaNormal && !value_ok("monitor update")) return;
        h_.on_event(h.p2, h.p1, h.dtype, h.count, payload, len);
        return;
    case kWriteNotify: h_.on_write_notify(h.p2, h.p1); return;
    case kError: {
        Header req;
        req.cmd = 0xFFFF;
        std::size_t rs = len >= 16 ? decode_header(payload, len, true, req) : 0;
        if (rs == 0) req.cmd = 0xFFFF;
        std::size_t at = rs ? rs : 0;
        const char* text = reinterpret_cast<const char*>(payload + at);
        std::size_t tl = at < len ? strnlen(text, len - at) : 0;
        h_.on_error(h.p1, h.p2, req, std::string_view(text, tl));
        return;
    }
    case kEcho:
    case kReadSync: h_.on_echo(); return;
    case kClearChannel: return; // confirmation: the channel is already forgotten
    case kRsrvIsUp:
    case kNotFound:
    case kSearch: return;       // TCP search replies: this client searches over UDP only
    default: fail(SB() << "unknown command " << h.cmd << " from the server"); return;
    }
}

void ClientCircuit::send_hello(uint16_t priority, std::string_view user, std::string_view host) {
    append_message(out_, kVersion, priority, kMinorVersion, 0, 0);
    std::string u(user), hn(host);
    append_message(out_, kClientName, 0, 0, 0, 0, u.c_str(), u.size() + 1);
    append_message(out_, kHostName, 0, 0, 0, 0, hn.c_str(), hn.size() + 1);
}

void ClientCircuit::create_chan(uint32_t cid, std::string_view name) {
    std::string n(name);
    append_message(out_, kCreateChan, 0, 0, cid, kMinorVersion, n.c_str(), n.size() + 1);
}

void ClientCircuit::clear_chan(uint32_t sid, uint32_t cid) { append_message(out_, kClearChannel, 0, 0, sid, cid); }

void ClientCircuit::read_notify(uint32_t sid, uint32_t ioid, uint16_t dtype, uint32_t count) {
    append_message(out_, kReadNotify, dtype, count, sid, ioid);
}

void ClientCircuit::write(uint32_t sid, uint32_t cid, uint16_t dtype, uint32_t count, const void* payload,
                          std::size_t len) {
    append_message(out_, kWrite, dtype, count, sid, cid, payload, len);
}

void ClientCircuit::write_notify(uint32_t sid, uint32_t ioid, uint16_t dtype, uint32_t count, const void* payload,
                                 std::size_t len) {
    append_message(out_, kWriteNotify, dtype, count, sid, ioid, payload, len);
}

void ClientCircuit::event_add(uint32_t sid, uint32_t subid, uint16_t dtype, uint32_t count, uint16_t mask) {
    uint8_t body[16] = {};
    put16(body + 12, mask);
    append_message(out_, kEventAdd, dtype, count, sid, subid, body, sizeof body);
}

void ClientCircuit::event_cancel(uint32_t sid, uint32_t subid, uint16_t dtype, uint32_t count) {
    append_message(out_, kEventCancel, dtype, count, sid, subid);
}

void ClientCircuit::echo() { append_message(out_, kEcho, 0, 0, 0, 0); }

void ClientCircuit::consume_output(std::size_t n) {
    out_off_ += n;
    if (out_off_ >= out_.size()) {
        out_.clear();
        out_off_ = 0;
    } else if (out_off_ > 65536) {
        out_.erase(0, out_off_);
        out_off_ = 0;
    }
}

bool parse_client_datagram(const uint8_t* p, std::size_t n, uint32_t sender_ip, std::vector<SearchReply>& replies,
                           std::vector<Beacon>& beacons, ClientStats& stats) {
    std::size_t off = 0;
    while (off < n) {
        Header h;
        std::size_t hs = decode_header(p + off, n - off, true, h);
        if (hs == 0 || h.payload_size > n - off - hs) {
            stats.udp_malformed++;
            return false;
        }
        const uint8_t* payload = p + off + hs;
        switch (h.cmd) {
        case kSearch: {
            SearchReply r;
            r.search_id = h.p2;
            r.server_ip = h.p1 == 0xFFFFFFFFu ? sender_ip : h.p1;
            r.server_port = h.dtype;
            r.server_minor = h.payload_size >= 2 ? get16(payload) : 0;
            if (r.server_port == 0) {
                stats.udp_malformed++;
                return false;
            }
            stats.search_replies++;
            replies.push_back(r);
            break;
        }
        case kRsrvIsUp: {
            Beacon b;
            b.server_ip = h.p2 ? h.p2 : sender_ip;
            b.server_port = uint16_t(h.count);
            b.id = h.p1;
            stats.beacons++;
            beacons.push_back(b);
            break;
        }
        default: break; // VERSION, NOT_FOUND, REPEATER_CONFIRM, ...
        }
        off += hs + h.payload_size;
    }
    return true;
}

} // namespace beamctl::ca
