#include "ca/circuit.hpp"

#include "ca/dbr.hpp"
#include "core/log.hpp"

#include <algorithm>
#include <arpa/inet.h>
#include <cstring>

namespace beamctl::ca {
namespace {
log::Logger lg("ca.circuit");

uint32_t eca_of(pv::PutStatus st) {
    switch (st) {
    case pv::PutStatus::Ok: return kEcaNormal;
    case pv::PutStatus::ReadOnly:
    case pv::PutStatus::NoAccess: return kEcaNoWtAccess;
    case pv::PutStatus::BadValue:
    case pv::PutStatus::Failed:
    case pv::PutStatus::Disconnected: return kEcaPutFail;
    }
    return kEcaPutFail;
}
} // namespace

struct Circuit::Channel : pv::RecordObserver {
    Circuit* circ;
    uint32_t cid, sid;
    pv::Address addr;
    unsigned rights = 0;
    std::string name;
    void on_record_removed(pv::Record&) override { circ->remove_channel(this, true); }
};

struct Circuit::Monitor : pv::Subscription {
    Circuit* circ;
    Channel* chan;
    uint32_t subid;
    uint16_t dtype;
    uint32_t count; // 0: dynamic (current element count)
    QueuedEvent* pending = nullptr;
    void on_event(unsigned) override { circ->queue_event(*this, false); }
};

Circuit::Circuit(ServerContext& ctx, uint32_t peer_ip, uint16_t peer_port)
    : ctx_(ctx), peer_port_(peer_port), life_(std::make_shared<Life>(Life{this})) {
    in_addr a{};
    a.s_addr = htonl(peer_ip);
    char buf[INET_ADDRSTRLEN];
    inet_ntop(AF_INET, &a, buf, sizeof buf);
    peer_ip_str_ = buf;
    host_ = buf;
    ctx_.stats.circuits_opened++;
    // The server announces itself as soon as the circuit is accepted.
    append_message(out_, kVersion, 0, kMinorVersion, 0, 0);
}

Circuit::~Circuit() {
    life_->c = nullptr; // put completions arriving later are dropped
    for (auto& [id, m] : monitors_) ctx_.db.unsubscribe(*m);
    for (auto& [sid, ch] : channels_) ctx_.db.unobserve(*ch->addr.rec, *ch);
    ctx_.stats.circuits_closed++;
}

std::string Circuit::peer() const { return peer_ip_str_ + ":" + std::to_string(peer_port_); }

void Circuit::changed() {
    if (wake_) wake_();
}

void Circuit::consume_output(std::size_t n) {
    out_off_ += n;
    if (out_off_ >= out_.size()) {
        out_.clear();
        out_off_ = 0;
    } else if (out_off_ > (1u << 20) && out_off_ > out_.size() / 2) {
        out_.erase(0, out_off_);
        out_off_ = 0;
    }
}

void Circuit::receive(const uint8_t* data, std::size_t n) {
    if (close_) return;
    if (drain_) {
        std::size_t skip = std::min(drain_, n);
        drain_ -= skip;
        data += skip;
        n -= skip;
    }
    // Parse straight from the caller's buffer when nothing is pending; keep only a partial tail.
    const uint8_t* p;
    std::size_t avail;
    if (in_.empty()) {
        p = data;
        avail = n;
    } else {
        in_.append(reinterpret_cast<const char*>(data), n);
        p = reinterpret_cast<const uint8_t*>(in_.data());
        avail = in_.size();
    }
    std::size_t used = 0;
    while (!close_ && avail - used >= 16) {
        Header h;
        std::size_t hs = decode_header(p + used, avail - used, minor_ == 0 || minor_ >= 9, h);
        if (hs == 0) break;
        current_raw_ = p + used;
        ctx_.stats.messages++;
        if (h.payload_size % 8 != 0) {
            protocol_error(h, p + used, kEcaInternal, "Missaligned protocol rejected");
            break;
        }
        if (h.payload_size > ctx_.max_payload) {
            ctx_.stats.oversized++;
            send_error(h, p + used, 0xFFFFFFFF, kEcaTooLarge,
                       "CA request message too large (EPICS_CA_MAX_ARRAY_BYTES)");
            std::size_t have = avail - used - hs;
            if (have >= h.payload_size) {
                used += hs + h.payload_size;
                continue;
            }
            drain_ = h.payload_size - have;
            used = avail;
            break;
        }
        if (avail - used < hs + h.payload_size) break;
        dispatch(h, p + used + hs);
        used += hs + h.payload_size;
    }
    current_raw_ = nullptr;
    if (close_) {
        in_.clear();
        return;
    }
    if (in_.empty()) {
        if (used < avail) in_.assign(reinterpret_cast<const char*>(p + used), avail - used);
    } else {
        in_.erase(0, used);
    }
}

void Circuit::dispatch(const Header& h, const uint8_t* payload) {
    LOG_TRACE(lg, peer() << " " << cmd_name(h.cmd) << " dtype=" << h.dtype << " count=" << h.count
                         << " p1=" << h.p1 << " p2=" << h.p2 << " size=" << h.payload_size);
    switch (h.cmd) {
    case kVersion:
        if (h.count) minor_ = uint16_t(h.count);
        priority_ = h.dtype;
        break;
    case kEventAdd: on_event_add(h, payload); break;
    case kEventCancel: on_event_cancel(h); break;
    case kRead: on_read_notify(h, true); break;
    case kWrite: on_write(h, payload, false); break;
    case kSearch: on_search(h, payload); break;
    case kEventsOff: events_off_ = true; break;
    case kEventsOn:
        events_off_ = false;
        changed();
        break;
    case kReadSync: append_message(out_, kReadSync, h.dtype, h.count, h.p1, h.p2); break;
    case kClearChannel: {
        Channel* ch = channel(h.p1, h, current_raw_);
        if (!ch) break;
        uint32_t sid = ch->sid, cid = ch->cid;
        remove_channel(ch, false);
        append_message(out_, kClearChannel, h.dtype, h.count, sid, cid);
        break;
    }
    case kReadNotify: on_read_notify(h, false); break;
    case kCreateChan: on_create_chan(h, payload); break;
    case kWriteNotify: on_write(h, payload, true); break;
    case kClientName: on_name(h, payload, false); break;
    case kHostName: on_name(h, payload, true); break;
    case kEcho: append_message(out_, kEcho, h.dtype, h.count, h.p1, h.p2, payload, h.payload_size); break;
    default:
        protocol_error(h, current_raw_, kEcaInternal, "Invalid Request Code");
        LOG_WARN(lg, peer() << ": unknown command " << h.cmd << ", circuit closed");
        break;
    }
}

void Circuit::send_error(const Header& h, const uint8_t* raw, uint32_t cid, uint32_t eca,
                         std::string_view text) {
    std::string payload;
    if (raw) payload.assign(reinterpret_cast<const char*>(raw), h.header_size);
    else payload.assign(16, '\0');
    payload.append(text);
    payload.push_back('\0');
    append_message(out_, kError, 0, 0, cid, eca, payload.data(), payload.size());
}

void Circuit::protocol_error(const Header& h, const uint8_t* raw, uint32_t eca, std::string_view text) {
    ctx_.stats.protocol_errors++;
    send_error(h, raw, 0xFFFFFFFF, eca, text);
    close_ = true;
    changed();
}

Circuit::Channel* Circuit::channel(uint32_t sid, const Header& h, const uint8_t* raw) {
    auto it = channels_.find(sid);
    if (it != channels_.end()) return it->second.get();
    ctx_.stats.bad_ids++;
    send_error(h, raw, 0xFFFFFFFF, kEcaInternal, "Bad Resource ID");
    return nullptr;
}

unsigned Circuit::compute_rights(const Channel& ch) const {
    const pv::Record& r = *ch.addr.rec;
    std::string_view asg(r.asg, strnlen(r.asg, sizeof r.asg));
    unsigned rights = ctx_.acf.rights(asg, ch.addr.asl(), user_, host_, peer_ip_str_);
    if (!ch.addr.writable()) rights &= ~unsigned(kAccessWrite);
    return rights;
}

void Circuit::refresh_rights() {
    for (auto& [sid, ch] : channels_) {
        unsigned r = compute_rights(*ch);
        if (r == ch->rights) continue;
        ch->rights = r;
        append_message(out_, kAccessRights, 0, 0, ch->cid, r);
        changed();
    }
}

void Circuit::on_name(const Header& h, const uint8_t* payload, bool host) {
    std::size_t len = strnlen(reinterpret_cast<const char*>(payload), h.payload_size);
    if (len > 512) {
        send_error(h, current_raw_, 0xFFFFFFFF, kEcaInternal, "client/host name too long");
        return;
    }
    std::string name(reinterpret_cast<const char*>(payload), len);
    if (!channels_.empty()) {
        // As RSRV: a name change after channels exist is refused (rights were computed already).
        send_error(h, current_raw_, 0xFFFFFFFF, kEcaInternal,
                   "client/host name change after channels were created is ignored");
        return;
    }
    (host ? host_ : user_) = std::move(name);
}

void Circuit::on_create_chan(const Header& h, const uint8_t* payload) {
    uint32_t cid = h.p1;
    std::size_t len = strnlen(reinterpret_cast<const char*>(payload), h.payload_size);
    std::string name(reinterpret_cast<const char*>(payload), len);
    pv::Address a;
    std::string why;
    if (name.empty() || !ctx_.db.resolve(name, a, &why)) {
        LOG_DEBUG(lg, peer() << ": CREATE_CHAN " << name << " failed: " << why);
        append_message(out_, kCreateChFail, 0, 0, cid, 0);
        return;
    }
    while (channels_.count(next_sid_) || next_sid_ == 0xFFFFFFFF) ++next_sid_;
    uint32_t sid = next_sid_++;
    auto ch = std::make_unique<Channel>();
    ch->circ = this;
    ch->cid = cid;
    ch->sid = sid;
    ch->addr = a;
    ch->name = std::move(name);
    ch->rights = compute_rights(*ch);
    ctx_.db.observe(*a.rec, *ch);
    append_message(out_, kAccessRights, 0, 0, cid, ch->rights);
    append_message(out_, kCreateChan, uint16_t(a.native), a.count, cid, sid);
    channels_.emplace(sid, std::move(ch));
}

void Circuit::remove_channel(Channel* ch, bool server_disconnect) {
    for (auto it = monitors_.begin(); it != monitors_.end();) {
        Monitor* m = it->second.get();
        if (m->chan != ch) {
            ++it;
            continue;
        }
        ctx_.db.unsubscribe(*m);
        for (auto& e : queue_)
            if (e.mon == m) e.mon = nullptr;
        it = monitors_.erase(it);
    }
    ctx_.db.unobserve(*ch->addr.rec, *ch);
    if (server_disconnect) {
        append_message(out_, kServerDisconn, 0, 0, ch->cid, 0);
        changed();
    }
    channels_.erase(ch->sid);
}

uint32_t Circuit::client_limit_count(uint16_t dtype) const {
    const DbrInfo& d = dbr_info(dtype);
    std::size_t esz = pv::prim_size(d.prim);
    if (ctx_.max_payload <= d.size) return 1;
    return uint32_t((ctx_.max_payload - d.size) / esz + 1);
}

void Circuit::on_read_notify(const Header& h, bool old_read) {
    Channel* ch = channel(h.p1, h, current_raw_);
    if (!ch) return;
    uint16_t t = h.dtype;
    if (!dbr_valid(t) || t == kDbrPutAckt || t == kDbrPutAcks) {
        protocol_error(h, current_raw_, kEcaBadType, "bad DBR type in read request");
        return;
    }
    uint32_t n = h.count;
    bool dynamic = n == 0 && minor_ >= 13;
    if (n == 0) n = dynamic ? ctx_.db.current_count(ch->addr) : ch->addr.count;
    if (n > client_limit_count(t)) {
        send_error(h, current_raw_, ch->cid, kEcaTooLarge, "read request too large");
        return;
    }
    std::size_t size = dbr_payload_size(t, n);
    bool readable = ch->rights & kAccessRead;
    if (old_read && t == 0 && n == 1 && readable) {
        char s[40];
        ctx_.db.get(ch->addr, pv::Prim::String, s, 1);
        size = strnlen(s, 40) + 1;
        append_message(out_, kRead, t, 1, ch->cid, h.p2, s, size);
        return;
    }
    std::size_t padded = pad8(size);
    std::size_t at = out_.size();
    uint8_t hdr[24];
    // a string that holds no number read as a number: the read fails (as EPICS's dbGet)
    bool converts = ctx_.db.readable_as(ch->addr, dbr_info(t).prim);
    uint32_t status = !readable ? kEcaNoRdAccess : converts ? kEcaNormal : kEcaGetFail;
    std::size_t hs = encode_header(hdr, old_read ? kRead : kReadNotify, uint32_t(padded), t, n,
                                   old_read ? ch->cid : status, h.p2);
    out_.append(reinterpret_cast<char*>(hdr), hs);
    out_.append(padded, '\0');
    if (readable && converts) encode_dbr(ctx_.db, ch->addr, t, n, reinterpret_cast<uint8_t*>(&out_[at + hs]));
}

void Circuit::on_write(const Header& h, const uint8_t* payload, bool notify) {
    Channel* ch = channel(h.p1, h, current_raw_);
    if (!ch) {
        if (notify) append_message(out_, kWriteNotify, h.dtype, h.count, kEcaPutFail, h.p2);
        return;
    }
    auto reply = [&](uint32_t eca, const char* text) {
        if (eca != kEcaNormal) ctx_.stats.put_denied++;
        if (notify)
            append_message(out_, kWriteNotify, h.dtype, h.count, eca, h.p2);
        else if (eca != kEcaNormal)
            send_error(h, current_raw_, ch->cid, eca, text);
    };
    uint16_t t = h.dtype;
    if (!(ch->rights & kAccessWrite)) return reply(kEcaNoWtAccess, "no write access");
    if (t == kDbrPutAckt || t == kDbrPutAcks) {
        if (h.payload_size < 2 || h.count < 1) return reply(kEcaBadCount, "bad count");
        uint16_t v = get16(payload);
        pv::Record& r = *ch->addr.rec;
        if (t == kDbrPutAckt) {
            r.ackt = v ? 1 : 0;
            r.post("ACKT", pv::kDbeValue | pv::kDbeAlarm);
            if (!r.ackt && r.acks > r.sevr) {
                r.acks = r.sevr;
                r.post("ACKS", pv::kDbeValue | pv::kDbeAlarm);
            }
        } else if (v >= r.acks) {
            r.acks = 0;
            r.post("ACKS", pv::kDbeValue | pv::kDbeAlarm);
        }
        return reply(kEcaNormal, "");
    }
    if (t > 6) return reply(kEcaBadType, "bad DBR type for a put");
    std::size_t esz = pv::prim_size(pv::Prim(t));
    bool short_string = t == 0 && h.count == 1 && h.payload_size > 0; // strlen+1, padded
    if (h.count == 0 || (!short_string && std::size_t(h.count) * esz > h.payload_size))
        return reply(kEcaBadCount, "put count does not match the payload");
    std::vector<char> host;
    if (!decode_put(t, payload, h.payload_size, h.count, host))
        return reply(kEcaBadCount, "short put payload");
    pv::PutCallback cb;
    if (notify) {
        std::shared_ptr<Life> life = life_;
        uint16_t dtype = h.dtype;
        uint32_t count = h.count, ioid = h.p2;
        cb = [life, dtype, count, ioid](pv::PutStatus st) {
            Circuit* c = life->c;
            if (!c) return;
            if (st != pv::PutStatus::Ok) c->ctx_.stats.put_denied++;
            append_message(c->out_, kWriteNotify, dtype, count, eca_of(st), ioid);
            c->changed();
        };
    }
    bool asg_write = ch->addr.field && std::strcmp(ch->addr.field->name, "ASG") == 0;
    origin_.assign(user_).append("@").append(host_); // who, for audit logs (a latch's acknowledgement)
    ctx_.db.set_put_origin(origin_);
    pv::PutStatus st = ctx_.db.put(ch->addr, pv::Prim(t), host.data(), h.count, std::move(cb));
    ctx_.db.set_put_origin({});
    if (!notify && st != pv::PutStatus::Ok) reply(eca_of(st), "put failed");
    if (asg_write && on_asg_changed) on_asg_changed();
}

void Circuit::on_search(const Header& h, const uint8_t* payload) {
    std::size_t len = strnlen(reinterpret_cast<const char*>(payload), h.payload_size);
    std::string_view name(reinterpret_cast<const char*>(payload), len);
    if (!name.empty() && ctx_.db.has_record_for(name)) {
        append_message(out_, kSearch, ctx_.tcp_port, 0, 0xFFFFFFFF, h.p2);
    } else if (h.dtype == kSearchDoReply) {
        append_message(out_, kNotFound, h.dtype, h.count, h.p1, h.p2);
    }
}

void Circuit::on_event_add(const Header& h, const uint8_t* payload) {
    Channel* ch = channel(h.p1, h, current_raw_);
    if (!ch) return;
    uint16_t t = h.dtype;
    if (!dbr_valid(t) || t == kDbrPutAckt || t == kDbrPutAcks) {
        protocol_error(h, current_raw_, kEcaBadType, "bad DBR type in subscription request");
        return;
    }
    if (h.payload_size < 16) {
        protocol_error(h, current_raw_, kEcaInternal, "subscription request without mask");
        return;
    }
    unsigned mask = get16(payload + 12) & (pv::kDbeValue | pv::kDbeLog | pv::kDbeAlarm | pv::kDbeProperty);
    if (!mask) {
        send_error(h, current_raw_, ch->cid, kEcaBadMask, "empty event mask");
        return;
    }
    uint32_t count = h.count;
    if (count == 0 && minor_ < 13) count = ch->addr.count;
    if ((count ? count : ch->addr.count) > client_limit_count(t)) {
        send_error(h, current_raw_, ch->cid, kEcaTooLarge, "subscription too large");
        return;
    }
    auto it = monitors_.find(h.p2);
    if (it != monitors_.end()) { // same id again: the new request replaces the old one
        ctx_.db.unsubscribe(*it->second);
        for (auto& e : queue_)
            if (e.mon == it->second.get()) e.mon = nullptr;
        monitors_.erase(it);
    }
    auto m = std::make_unique<Monitor>();
    m->addr = ch->addr;
    m->mask = mask;
    m->circ = this;
    m->chan = ch;
    m->subid = h.p2;
    m->dtype = t;
    m->count = count;
    Monitor& ref = *m;
    monitors_.emplace(h.p2, std::move(m));
    ctx_.db.subscribe(ref);
    queue_event(ref, true);
}

void Circuit::on_event_cancel(const Header& h) {
    Channel* ch = channel(h.p1, h, current_raw_);
    if (!ch) return;
    auto it = monitors_.find(h.p2);
    if (it == monitors_.end() || it->second->chan != ch) {
        ctx_.stats.bad_ids++;
        send_error(h, current_raw_, ch->cid, kEcaBadMonId, "Bad Monitor ID");
        return;
    }
    Monitor* m = it->second.get();
    ctx_.db.unsubscribe(*m);
    for (auto& e : queue_)
        if (e.mon == m) e.mon = nullptr;
    append_message(out_, kEventAdd, h.dtype, h.count, h.p1, h.p2);
    monitors_.erase(it);
}

void Circuit::encode_event(Monitor& m, std::string& out) {
    Channel& ch = *m.chan;
    uint32_t n = m.count ? m.count : ctx_.db.current_count(ch.addr);
    std::size_t padded = pad8(dbr_payload_size(m.dtype, n));
    bool readable = ch.rights & kAccessRead;
    bool converts = ctx_.db.readable_as(ch.addr, dbr_info(m.dtype).prim);
    std::size_t at = out.size();
    uint8_t hdr[24];
    std::size_t hs = encode_header(hdr, kEventAdd, uint32_t(padded), m.dtype, n,
                                   !readable ? kEcaNoRdAccess : converts ? kEcaNormal : kEcaGetFail, m.subid);
    out.append(reinterpret_cast<char*>(hdr), hs);
    out.append(padded, '\0');
    if (readable && converts) encode_dbr(ctx_.db, ch.addr, m.dtype, n, reinterpret_cast<uint8_t*>(&out[at + hs]));
    ctx_.stats.events_sent++;
}

void Circuit::queue_event(Monitor& m, bool first) {
    (void)first;
    if (queue_.empty() && !events_off_ && output_size() < kDefaultHighWater) {
        encode_event(m, out_);
        changed();
        return;
    }
    bool crowded = events_off_ || queue_.size() >= ctx_.event_queue_limit ||
                   queued_bytes_ >= ctx_.event_queue_bytes;
    if (m.pending && crowded) {
        // Keep only the latest value of this subscription (its existing slot keeps its place).
        queued_bytes_ -= m.pending->msg.size();
        m.pending->msg.clear();
        encode_event(m, m.pending->msg);
        queued_bytes_ += m.pending->msg.size();
        ctx_.stats.events_coalesced++;
        return;
    }
    queue_.push_back(QueuedEvent{&m, {}});
    encode_event(m, queue_.back().msg);
    queued_bytes_ += queue_.back().msg.size();
    m.pending = &queue_.back();
    changed();
}

void Circuit::fill_events(std::size_t high_water) {
    if (events_off_) return;
    while (!queue_.empty() && output_size() < high_water) {
        QueuedEvent& e = queue_.front();
        if (e.mon) {
            out_ += e.msg;
            if (e.mon->pending == &e) e.mon->pending = nullptr;
        }
        queued_bytes_ -= e.msg.size();
        queue_.pop_front();
    }
}

std::vector<std::string> Circuit::channel_names() const {
    std::vector<std::pair<uint32_t, std::string>> by_sid;
    for (const auto& [sid, ch] : channels_) by_sid.emplace_back(sid, ch->name);
    std::sort(by_sid.begin(), by_sid.end());
    std::vector<std::string> out;
    for (auto& [sid, name] : by_sid) out.push_back(std::move(name));
    return out;
}

} // namespace beamctl::ca
