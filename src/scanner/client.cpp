#include "scanner/client.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "registry/image.hpp"
#include "scanner/layout.hpp"
#include "scanner/outputs.hpp"
#include "scanner/ring.hpp"
#include "scanner/shm.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <thread>
#include <time.h>
#include <unistd.h>

namespace beamctl::scanner {

namespace {
log::Logger lg("scanner-client");

double now_s() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}
uint64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}

// The scanner answered a request with Error: not worth retrying (a conflict, an unknown slave).
class Refused : public Error {
public:
    using Error::Error;
};

template <class T> const T& expect(const proto::Message& m, const char* what) {
    if (const auto* e = std::get_if<proto::ErrorMsg>(&m.body))
        throw Refused(SB() << what << " refused (" << proto::to_string(e->code) << "): " << e->text);
    if (const auto* t = std::get_if<T>(&m.body)) return *t;
    throw Error(SB() << what << ": the scanner answered " << proto::to_string(m.type()));
}
} // namespace

// ---- Channel -----------------------------------------------------------------------------------

Channel::~Channel() { close(); }

void Channel::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    dec_ = proto::Decoder();
}

void Channel::connect(const std::string& socket) {
    close();
    socket_ = socket;
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    if (socket.size() >= sizeof a.sun_path) throw Error(SB() << "scanner socket " << socket << ": path too long");
    std::memcpy(a.sun_path, socket.c_str(), socket.size() + 1);
    int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) throw Error(SB() << "socket: " << std::strerror(errno));
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        int e = errno;
        ::close(fd);
        throw Error(SB() << "scanner socket " << socket << ": " << std::strerror(e)
                         << (e == ENOENT || e == ECONNREFUSED ? " (is `beamctl scanner` running?)" : ""));
    }
    fd_ = fd;
}

bool Channel::read_message(proto::Message& m, double timeout_s, std::vector<int>* fds) {
    const double end = now_s() + timeout_s;
    for (;;) {
        switch (dec_.next(m)) {
        case proto::Decoder::Result::Message: return true;
        case proto::Decoder::Result::Error: throw Error(SB() << "scanner " << socket_ << ": " << dec_.error());
        case proto::Decoder::Result::NeedMore: break;
        }
        double left = end - now_s();
        if (left <= 0) return false;
        pollfd p{fd_, POLLIN, 0};
        int r = ::poll(&p, 1, int(left * 1000) + 1);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) continue;
        uint8_t buf[8192];
        std::vector<int> got;
        long n = recv_fds(fd_, buf, sizeof buf, got);
        if (fds) fds->insert(fds->end(), got.begin(), got.end());
        else
            for (int f : got) ::close(f);
        if (n == 0) throw Error(SB() << "scanner " << socket_ << ": connection closed");
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN) continue;
            throw Error(SB() << "scanner " << socket_ << ": " << std::strerror(errno));
        }
        dec_.feed(buf, std::size_t(n));
    }
}

proto::Message Channel::call(proto::Body req, double timeout_s, std::vector<int>* fds) {
    if (fd_ < 0) throw Error("scanner: not connected");
    proto::Message m{next_id_++, std::move(req)};
    std::vector<uint8_t> out;
    proto::encode(m, out);
    send_fds(fd_, out.data(), out.size(), {});
    const double end = now_s() + timeout_s;
    for (;;) {
        proto::Message r;
        if (!read_message(r, end - now_s(), fds))
            throw Error(SB() << "scanner " << socket_ << ": no answer to " << proto::to_string(m.type()) << " within " << timeout_s << " s");
        if (const auto* g = std::get_if<proto::Goodbye>(&r.body)) throw Error(SB() << "scanner " << socket_ << " said goodbye: " << g->reason);
        if (r.request_id == m.request_id) return r;
    }
}

bool Channel::closed_by_peer(std::string& reason) {
    if (fd_ < 0) return true;
    for (;;) {
        uint8_t buf[4096];
        ssize_t n = ::recv(fd_, buf, sizeof buf, MSG_DONTWAIT);
        if (n == 0) {
            reason = "the scanner closed the connection";
            return true;
        }
        if (n < 0) {
            if (errno == EAGAIN || errno == EINTR) break;
            reason = std::strerror(errno);
            return true;
        }
        dec_.feed(buf, std::size_t(n));
    }
    proto::Message m;
    for (;;) {
        auto r = dec_.next(m);
        if (r == proto::Decoder::Result::Error) {
            reason = dec_.error();
            return true;
        }
        if (r == proto::Decoder::Result::NeedMore) return false;
        if (const auto* g = std::get_if<proto::Goodbye>(&m.body)) {
            reason = "the scanner said goodbye: " + g->reason;
            return true;
        }
    }
}

// ---- ClientBackend -----------------------------------------------------------------------------

struct KeepMerge {
    ByteMerge merge;
};

struct ClientBackend::Session {
    SharedMemory ring_mem, out_mem;
    std::unique_ptr<RingReader> ring;
    std::unique_ptr<OutWriter> out;
    uint64_t instance = 0;
};

ClientBackend::ClientBackend(ClientConfig cfg) : cfg_(std::move(cfg)), bus_(cfg_.bus) {}

ClientBackend::~ClientBackend() {
    std::lock_guard<std::mutex> lk(ctl_mu_);
    session_.store(nullptr);
    owned_.reset();
}

std::vector<proto::ChainSlave> ClientBackend::resolve(const std::string& socket, int bus, const std::vector<std::string>& slaves,
                                                      double timeout_s) {
    const double end = now_s() + timeout_s;
    bool told = false;
    for (;;) {
        try {
            Channel ch;
            ch.connect(socket);
            proto::Hello h;
            h.client = "beamctl";
            h.ioc = "describe";
            h.pid = uint32_t(::getpid());
            (void)expect<proto::Welcome>(ch.call(h, 5), "Hello");
            const proto::Chain chain = expect<proto::Chain>(ch.call(proto::Describe{uint16_t(bus)}, 5), "Describe");
            std::vector<proto::ChainSlave> out;
            for (const auto& want : slaves) {
                const proto::ChainSlave* hit = nullptr;
                for (const auto& c : chain.slaves)
                    if (c.name == want || std::to_string(c.position) == want) hit = &c;
                if (!hit) {
                    std::string have;
                    for (const auto& c : chain.slaves) have += (have.empty() ? "" : ", ") + std::to_string(c.position) + (c.name.empty() ? "" : " " + c.name);
                    throw Refused(SB() << "ec" << bus << ": the scanner has no slave '" << want << "' (its chain: " << have << ")");
                }
                out.push_back(*hit);
            }
            return out;
        } catch (const Refused&) {
            throw;
        } catch (const Error& e) {
            if (now_s() >= end) throw;
            if (!told) LOG_INFO(lg, "waiting for the scanner at " << socket << " (" << e.what() << ")");
            told = true;
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
        }
    }
}

const ethercat::SignalInfo* ClientBackend::find_signal(std::string_view name) const {
    for (const auto& s : signals_)
        if (s.name == name) return &s;
    return nullptr;
}

void ClientBackend::bring_up() {
    const double end = now_s() + cfg_.connect_timeout_s;
    bool told = false;
    for (;;) {
        try {
            attach_once();
            return;
        } catch (const Refused& e) {
            throw Error(SB() << "ec" << bus_ << ": scanner at " << cfg_.socket << ": " << e.what());
        } catch (const Error& e) {
            if (now_s() >= end)
                throw Error(SB() << "ec" << bus_ << ": no scanner to attach to within " << cfg_.connect_timeout_s << " s: " << e.what());
            if (!told) LOG_INFO(lg, "ec" << bus_ << ": waiting for the scanner at " << cfg_.socket << " (" << e.what() << ")");
            told = true;
            std::this_thread::sleep_for(std::chrono::milliseconds(200));
        }
    }
}

void ClientBackend::attach_once() {
    std::lock_guard<std::mutex> lk(ctl_mu_);
    ch_.connect(cfg_.socket);
    proto::Hello h;
    h.client = "beamctl";
    h.ioc = cfg_.ioc;
    h.pid = uint32_t(::getpid());
    const proto::Welcome w = expect<proto::Welcome>(ch_.call(h, 5), "Hello");
    // The IOC's cycle is the scanner's: axes and PLCs compute with this IOC's period, so the two must agree.
    for (const auto& b : w.buses)
        if (b.id == bus_ && b.cycle_ns != period_ns_) {
            ch_.close();
            throw Refused(SB() << "the scanner cycles bus " << bus_ << " at " << 1e9 / double(b.cycle_ns) << " Hz, this IOC's engine at "
                               << 1e9 / double(period_ns_) << " Hz: set engine.rate_hz to " << 1e9 / double(b.cycle_ns));
        }
    const proto::Chain chain = expect<proto::Chain>(ch_.call(proto::Describe{uint16_t(bus_)}, 5), "Describe");
    proto::Attach a;
    a.bus = uint16_t(bus_);
    a.slaves = cfg_.slaves;
    a.claims = cfg_.claims;
    a.depth = cfg_.depth;
    std::vector<int> fds;
    proto::Message reply = ch_.call(a, 5, &fds);
    auto close_fds = [&] {
        for (int f : fds) ::close(f);
        fds.clear();
    };
    const proto::Attached* at = nullptr;
    try {
        at = &expect<proto::Attached>(reply, "Attach");
        if (fds.size() != 2) throw Error(SB() << "Attached came with " << fds.size() << " file descriptors, 2 expected");
    } catch (...) {
        close_fds();
        ch_.close();
        throw;
    }
    const bool first = layout_hash_ == 0;
    if (!first && at->layout_hash != layout_hash_) {
        close_fds();
        (void)ch_.call(proto::Detach{}, 2);
        ch_.close();
        throw Refused(SB() << "the scanner's layout for this IOC's slaves changed since this IOC started (chain or PDO "
                              "assignment): restart the IOC to take the new layout");
    }
    if (first) { // the layout this IOC binds to, for its life
        chain_size_ = chain.slaves.size();
        scanner_image_ = at->image_bytes;
        masterstatus_offset_ = (scanner_image_ + 3) / 4 * 4;
        image_.assign(masterstatus_offset_ + 4, 0);
        recv_.assign(slot_data_bytes(scanner_image_, chain_size_), 0);
        std::size_t bus_end = 0;
        for (const auto& ls : at->slaves) {
            ethercat::SlaveInfo si;
            si.position = ls.slave.position;
            si.type = ls.slave.type;
            si.oversampling = ls.slave.oversampling;
            si.sii.vendor = ls.slave.vendor, si.sii.product = ls.slave.product, si.sii.revision = ls.slave.revision;
            si.out_offset = ls.out_offset, si.out_bytes = ls.out_bytes, si.in_offset = ls.in_offset, si.in_bytes = ls.in_bytes;
            bus_end = std::max<std::size_t>({bus_end, ls.out_offset + ls.out_bytes, ls.in_offset + ls.in_bytes});
            int ci = -1;
            for (std::size_t k = 0; k < chain.slaves.size(); ++k)
                if (chain.slaves[k].position == ls.slave.position) ci = int(k);
            chain_index_.push_back(ci);
            slaves_.push_back(si);
            for (const auto& e : ls.entries) {
                ethercat::SignalInfo s;
                s.name = SB() << "ec" << bus_ << ".s" << ls.slave.position << "." << e.name;
                s.slave = ls.slave.position;
                s.bit_offset = e.bit_offset;
                s.bits = e.bits;
                s.output = e.output;
                s.datatype = e.datatype;
                s.is_signed = registry::datatype_is_signed(e.datatype);
                signals_.push_back(s);
            }
        }
        ethercat::SignalInfo ms;
        ms.name = SB() << "ec" << bus_ << ".masterstatus";
        ms.slave = -1;
        ms.bit_offset = uint32_t(masterstatus_offset_ * 8);
        ms.bits = 32;
        ms.datatype = "UINT32";
        signals_.push_back(ms);
        bus_bytes_ = bus_end;
        slave_status_.assign(slaves_.size() * 3, 0);
        health_.assign(slaves_.size(), ethercat::SlaveHealth{});
        last_error_.assign(slaves_.size(), "");
        layout_hash_ = at->layout_hash;
    }
    auto s = std::make_unique<Session>();
    try {
        s->ring_mem = SharedMemory::map(fds[0], "cycle ring", sizeof(RingHeader), false);
        fds[0] = -1;
        s->out_mem = SharedMemory::map(fds[1], "output block", sizeof(OutHeader), true);
        fds[1] = -1;
        s->ring = std::make_unique<RingReader>(s->ring_mem.data(), s->ring_mem.size());
        s->out = std::make_unique<OutWriter>(s->out_mem.data(), s->out_mem.size());
        if (s->ring->data_bytes() != recv_.size() || s->ring->layout_hash() != layout_hash_)
            throw Error(SB() << "cycle ring of " << s->ring->data_bytes() << " bytes per cycle, " << recv_.size() << " expected");
    } catch (...) {
        for (int f : fds)
            if (f >= 0) ::close(f);
        ch_.close();
        throw;
    }
    s->instance = w.instance;
    if (first) {
        // What of a slot goes into the image: everything but the outputs this IOC claimed.
        outputs_bytes_ = s->out->data_bytes();
        std::vector<uint8_t> keep(scanner_image_, 0xFF);
        for (const auto& sig : signals_)
            if (sig.output)
                for (uint32_t bit = sig.bit_offset; bit < sig.bit_offset + sig.bits && bit / 8 < outputs_bytes_; ++bit) {
                    bool claimed = false;
                    for (const auto& c : cfg_.claims) {
                        int pos = -1;
                        for (const auto& cs : chain.slaves)
                            if (cs.name == c.slave || std::to_string(cs.position) == c.slave) pos = cs.position;
                        std::string pre = SB() << "ec" << bus_ << ".s" << pos << ".";
                        claimed = claimed || (sig.slave == pos && (c.entry == "*" || sig.name == pre + c.entry));
                    }
                    if (claimed) keep[bit / 8] &= uint8_t(~(1u << (bit % 8)));
                }
        keep_ = std::make_unique<KeepMerge>(KeepMerge{ByteMerge(keep)});
    }
    owned_ = std::move(s);
    session_.store(owned_.get(), std::memory_order_release);
    attaches_.fetch_add(1);
    LOG_INFO(lg, "ec" << bus_ << ": attached to scanner '" << w.scanner << "' at " << cfg_.socket << " (" << slaves_.size()
                      << " slave(s), ring of " << at->depth << " cycles)");
}

void ClientBackend::detach_session(const std::string& why) {
    // Called with ctl_mu_ held. The RT side stops using the session, then it is released.
    Session* s = session_.exchange(nullptr, std::memory_order_acq_rel);
    if (!s) return;
    const uint64_t e = rt_epoch_.load(std::memory_order_acquire);
    for (int i = 0; i < 500 && rt_epoch_.load(std::memory_order_acquire) < e + 2; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    owned_.reset();
    ch_.close();
    LOG_WARN(lg, "ec" << bus_ << ": scanner lost (" << why << "): bus data invalid, reattaching when it is back");
    {
        std::lock_guard<std::mutex> hl(health_mu_);
        for (std::size_t i = 0; i < health_.size(); ++i) {
            health_[i].state = ethercat::SlaveState::Lost;
            health_[i].lost++;
            health_[i].error_id = ethercat::slave_error::kNotOnline;
            last_error_[i] = "scanner lost: " + why;
        }
    }
    health_version_.fetch_add(1);
}

void ClientBackend::health_pass() {
    const double now = now_s();
    if (session_.load()) {
        std::string why;
        bool gone;
        {
            std::lock_guard<std::mutex> lk(ctl_mu_);
            gone = ch_.closed_by_peer(why);
            if (gone) detach_session(why);
        }
        if (gone) {
            next_try_s_ = now + 0.5;
            return;
        }
        if (now < next_health_s_) return;
        next_health_s_ = now + 1.0;
        // Each slave's AL state and health, as the scanner's master sees it.
        bool changed = false;
        for (std::size_t i = 0; i < slaves_.size(); ++i) {
            proto::AlInfo al;
            try {
                std::lock_guard<std::mutex> lk(ctl_mu_);
                if (!session_.load()) return;
                al = expect<proto::AlInfo>(ch_.call(proto::AlInfoRequest{uint16_t(bus_), uint16_t(slaves_[i].position)}, 2), "AlInfo");
            } catch (const Error& e) {
                LOG_WARN(lg, "ec" << bus_ << " s" << slaves_[i].position << ": " << e.what());
                return;
            }
            std::lock_guard<std::mutex> hl(health_mu_);
            ethercat::SlaveHealth h;
            h.state = ethercat::SlaveState(al.slave_state);
            h.lost = al.lost, h.reconfigured = al.reconfigured, h.refused = al.refused, h.error_id = al.error_id;
            if (h.state != health_[i].state || h.lost != health_[i].lost || h.reconfigured != health_[i].reconfigured ||
                h.refused != health_[i].refused || h.error_id != health_[i].error_id || al.last_error != last_error_[i]) {
                health_[i] = h;
                last_error_[i] = al.last_error;
                slaves_[i].al_state = al.al_state;
                slaves_[i].al_status_code = al.status_code;
                changed = true;
            }
        }
        if (changed) health_version_.fetch_add(1);
        return;
    }
    if (now < next_try_s_) return;
    next_try_s_ = now + 1.0;
    try {
        attach_once();
        last_refusal_.clear();
        next_health_s_ = 0;
    } catch (const Error& e) {
        std::string msg = e.what();
        if (msg != last_refusal_) LOG_WARN(lg, "ec" << bus_ << ": not attached: " << msg);
        last_refusal_ = msg;
    }
}

ethercat::SlaveHealth ClientBackend::slave_health(std::size_t i) const {
    std::lock_guard<std::mutex> hl(health_mu_);
    return i < health_.size() ? health_[i] : ethercat::SlaveHealth{};
}

std::string ClientBackend::slave_last_error(std::size_t i) const {
    std::lock_guard<std::mutex> hl(health_mu_);
    return i < last_error_.size() ? last_error_[i] : std::string();
}

std::vector<uint8_t> ClientBackend::sdo_read(int position, uint16_t index, uint8_t sub) {
    std::lock_guard<std::mutex> lk(ctl_mu_);
    if (!session_.load()) throw Error(SB() << "ec" << bus_ << ": not attached to the scanner");
    proto::Message r = ch_.call(proto::SdoRead{uint16_t(bus_), uint16_t(position), index, sub, false}, 10);
    if (const auto* e = std::get_if<proto::ErrorMsg>(&r.body)) {
        if (e->code == proto::ErrorCode::SdoAbort) throw ethercat::SdoAbort(e->text, e->abort_code);
        throw Error(e->text);
    }
    return expect<proto::SdoData>(r, "SdoRead").data;
}

void ClientBackend::sdo_write(int position, uint16_t index, uint8_t sub, const std::vector<uint8_t>& data) {
    std::lock_guard<std::mutex> lk(ctl_mu_);
    if (!session_.load()) throw Error(SB() << "ec" << bus_ << ": not attached to the scanner");
    proto::Message r = ch_.call(proto::SdoWrite{uint16_t(bus_), uint16_t(position), index, sub, false, data}, 10);
    if (const auto* e = std::get_if<proto::ErrorMsg>(&r.body)) {
        if (e->code == proto::ErrorCode::SdoAbort) throw ethercat::SdoAbort(e->text, e->abort_code);
        throw Error(e->text);
    }
    (void)expect<proto::Ok>(r, "SdoWrite");
}

// ---- RT ----------------------------------------------------------------------------------------

bool ClientBackend::wait(uint64_t deadline_ns, uint64_t& tick_ns) noexcept {
    for (;;) {
        Session* s = session_.load(std::memory_order_acquire);
        if (!s) { // not attached: the engine runs on its own until the deadline
            rt_epoch_.fetch_add(1, std::memory_order_release);
            timespec ts{time_t(deadline_ns / 1'000'000'000), long(deadline_ns % 1'000'000'000)};
            while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
            }
            return false;
        }
        // The tick's time is when the scanner published the cycle: the engine's wake-up latency
        // figures then measure bus cycle -> this IOC's cycle.
        auto tick_time = [&] {
            uint64_t p = s->ring->peek_publish_ns();
            return p ? p : now_ns();
        };
        const uint32_t t = s->ring->tick();
        if (s->ring->pending()) {
            tick_ns = tick_time();
            return true;
        }
        s->out->set_waiting(true);
        const bool more = s->ring->pending();
        if (!more && !futex_wait_until(s->ring->tick_word(), t, deadline_ns)) {
            s->out->set_waiting(false);
            if (!s->ring->pending()) return false;
        }
        s->out->set_waiting(false);
        if (s->ring->pending()) {
            tick_ns = tick_time();
            return true;
        }
        if (now_ns() >= deadline_ns) return false;
    }
}

ethercat::CycleStatus ClientBackend::receive(const rt::CycleInfo&) noexcept {
    Session* s = session_.load(std::memory_order_acquire);
    uint32_t ok = 0;
    ethercat::CycleStatus st = ethercat::CycleStatus::LinkError;
    if (s != rt_session_) { // a new attachment: its ring counts from 0
        drops_total_ += drops_.exchange(0, std::memory_order_relaxed);
        rt_session_ = s;
        have_cycle_ = have_cycle_ && s != nullptr;
    }
    if (s) {
        CycleSlot slot;
        if (s->ring->read(slot, recv_.data()) == RingReader::Result::Cycle && slot.data_bytes == recv_.size()) {
            keep_->merge.apply(image_.data(), recv_.data());
            const uint8_t* st_bytes = recv_.data() + scanner_image_ + sizeof(CycleTail);
            for (std::size_t i = 0; i < slaves_.size(); ++i) {
                int ci = chain_index_[i];
                const uint8_t* b = ci >= 0 ? st_bytes + std::size_t(ci) * kSlaveStatusBytes : nullptr;
                slave_status_[3 * i] = b ? b[0] : 0;
                slave_status_[3 * i + 1] = b ? b[1] : 0;
                slave_status_[3 * i + 2] = b ? b[2] : 0;
            }
            if (have_cycle_ && slot.cycle > prev_cycle_ + 1) gaps_.fetch_add(slot.cycle - prev_cycle_ - 1, std::memory_order_relaxed);
            prev_cycle_ = slot.cycle;
            have_cycle_ = true;
            last_cycle_.store(slot.cycle, std::memory_order_relaxed);
            flags_ = slot.flags;
            drops_.store(s->ring->lost(), std::memory_order_relaxed);
            s->out->report_drops(s->ring->lost());
            st = !(slot.flags & kLinkUp) ? ethercat::CycleStatus::FrameLost
                 : (slot.flags & kWkcOk) ? ethercat::CycleStatus::Ok
                                         : ethercat::CycleStatus::WkcMismatch;
            ok = st == ethercat::CycleStatus::Ok;
        } else {
            st = ethercat::CycleStatus::FrameLost; // no cycle from the scanner in time
        }
    }
    if (st != ethercat::CycleStatus::Ok) {
        // No fresh data: every slave invalid (as a lost frame on a bus of our own).
        for (std::size_t i = 0; i < slaves_.size(); ++i) slave_status_[3 * i + 2] = 0;
        if (!s)
            for (std::size_t i = 0; i < slaves_.size(); ++i) slave_status_[3 * i + 1] = 0;
        for (const auto& sig : signals_)
            if (sig.name.size() > 6 && sig.name.compare(sig.name.size() - 6, 6, ".valid") == 0)
                registry::image_write(image_.data(), sig.bit_offset, sig.bits, 0);
    }
    std::memcpy(image_.data() + masterstatus_offset_, &ok, 4);
    return st;
}

void ClientBackend::send(const rt::CycleInfo&) noexcept {
    if (Session* s = session_.load(std::memory_order_acquire)) s->out->commit(prev_cycle_, now_ns(), image_.data());
    rt_epoch_.fetch_add(1, std::memory_order_release);
}

void ClientBackend::fill(ethercat::BusSnapshot& s, ethercat::CycleStatus last) noexcept {
    CycleTail t;
    std::memcpy(&t, recv_.data() + scanner_image_, sizeof t);
    s.wkc = t.wkc;
    s.expected_wkc = t.expected_wkc;
    s.frames_lost = t.frames_lost;
    s.frames_late = t.frames_late;
    s.wkc_errors = t.wkc_errors;
    s.responding = session_.load(std::memory_order_relaxed) ? t.responding : -1;
    s.link_up = last != ethercat::CycleStatus::FrameLost && last != ethercat::CycleStatus::LinkError;
    s.wkc_ok = last == ethercat::CycleStatus::Ok;
    s.scanner_bus = true;
    s.scanner_attached = session_.load(std::memory_order_relaxed) != nullptr;
    s.scanner_cycle = last_cycle_.load(std::memory_order_relaxed);
    s.scanner_missed = gaps_.load(std::memory_order_relaxed);
    s.scanner_drops = drops_total_ + drops_.load(std::memory_order_relaxed);
    s.scanner_attaches = attaches_.load(std::memory_order_relaxed);
    for (std::size_t i = 0; i < s.slave_al.size() && i < slaves_.size(); ++i) {
        s.slave_al[i] = slave_status_[3 * i];
        s.slave_online[i] = slave_status_[3 * i + 1] && s.link_up;
        s.slave_valid[i] = slave_status_[3 * i + 2];
    }
}

} // namespace beamctl::scanner
