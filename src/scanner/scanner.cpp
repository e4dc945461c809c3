#include "scanner/scanner.hpp"

#include "config/yaml_reader.hpp"
#include "core/error.hpp"
#include "core/local_socket.hpp"
#include "core/log.hpp"
#include "scanner/layout.hpp"
#include "scanner/outputs.hpp"
#include "scanner/ring.hpp"
#include "scanner/shm.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <fcntl.h>
#include <random>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

namespace beamctl::scanner {

namespace {
log::Logger lg("scanner");

bool all_digits(const std::string& s) { return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos; }
} // namespace

// ---- configuration -----------------------------------------------------------------------------

ScannerConfig ScannerConfig::load(const std::string& path) {
    std::ifstream f(path);
    if (!f) throw Error(SB() << path << ": cannot open: " << std::strerror(errno));
    std::stringstream ss;
    ss << f.rdbuf();
    ErrorList errors;
    ScannerConfig c = parse(ss.str(), path, errors);
    errors.throw_if_any();
    return c;
}

ScannerConfig ScannerConfig::parse(const std::string& text, const std::string& path, ErrorList& errors) {
    std::string dir = std::filesystem::path(path).parent_path().string();
    if (dir.empty()) dir = ".";
    config::YamlReader rd(path, text, "the scanner file");
    ScannerConfig c;
    c.path = path;
    config::YamlNode root = rd.root();
    if (!root.keys({"scanner", "engine", "buses"}) || root.is_null()) {
        if (root.is_null()) rd.error(rd.top(), "empty configuration (needs scanner: and buses:)");
        rd.take_errors(errors);
        return c;
    }
    if (config::YamlNode n = root.required("scanner", " ({socket: PATH})"); n.keys({"name", "socket", "socket_group", "max_clients", "depth", "gather_window"}) && n) {
        if (auto g = n["socket_group"].string()) {
            try {
                (void)core::socket_group_named(*g, "socket_group");
                c.socket_group = *g;
            } catch (const Error&) {
                n["socket_group"].error(SB() << "'" << *g << "' is no group on this system");
            }
        }
        c.gather_window = n["gather_window"].number(config::between(0, 0.9)).value_or(0);
        c.name = n["name"].string().value_or(c.name);
        if (auto s = n.required("socket", " (the path of the socket IOCs attach through)").string()) {
            std::filesystem::path p(*s);
            c.socket = p.is_absolute() ? *s : (std::filesystem::path(dir) / p).lexically_normal().string();
        }
        c.max_clients = unsigned(n["max_clients"].unsigned_integer(kMaxClients).value_or(c.max_clients));
        if (c.max_clients == 0) n["max_clients"].error("should be at least 1");
        c.default_depth = unsigned(n["depth"].unsigned_integer(4096).value_or(c.default_depth));
        if (c.default_depth < 2 || (c.default_depth & (c.default_depth - 1)))
            n["depth"].error(SB() << c.default_depth << " should be a power of two from 2 to 4096 (cycles a client's ring holds)");
    }
    if (config::YamlNode n = root["engine"]; n.keys({"rate_hz", "cpu", "priority"})) {
        c.rate_hz = n["rate_hz"].number(config::between(1, 20000)).value_or(c.rate_hz);
        c.cpu = int(n["cpu"].integer(config::between(0, 1023)).value_or(c.cpu));
        c.priority = int(n["priority"].integer(config::between(0, 99)).value_or(c.priority));
    }
    c.buses = config::read_bus_list(root.required("buses", " (the buses this scanner runs)"), dir, true);
    rd.take_errors(errors);
    return c;
}

// ---- RT side -----------------------------------------------------------------------------------

// One attached client as the RT thread sees it. Created and released by the control thread.
struct Scanner::RtClient {
    enum State : int { Active = 1, Detaching = 2, Gone = 3 };
    std::string name;
    uint32_t pid = 0, id = 0;
    SharedMemory ring_mem, out_mem;
    std::unique_ptr<RingWriter> ring;
    std::unique_ptr<OutReader> out;
    ByteMerge claims;
    std::vector<uint8_t> scratch;
    bool zero_on_detach = true;
    std::atomic<int> state{Active};
    std::atomic<uint64_t> commits{0}, late{0}; // late: a commit answering an older cycle than the last one published before it
    std::atomic<uint64_t> missed_window{0};    // cycles whose gather window closed without its answer
    std::atomic<uint64_t> out_lat_max_ns{0};   // commit -> merged into the frame
    std::array<std::atomic<uint32_t>, kOutLatencyBins> out_lat_us{}; // its histogram, 1 µs bins (last: beyond)
};

struct Scanner::BusRt {
    config::BusConfig cfg;
    ethercat::sim::LocalBus local;
    std::vector<std::string> names; // per chain slave: its name ("" if none)
    std::array<std::atomic<RtClient*>, kMaxClients> slots{};
    std::vector<uint8_t> slot_buf;  // the slot data composed once per cycle
    uint32_t outputs_bytes = 0;
    std::unique_ptr<FanoutStage> fanout;
    std::unique_ptr<GatherStage> gather;
};

struct Scanner::FanoutStage : rt::Stage {
    BusRt& b;
    rt::Clock& clock;
    FanoutStage(BusRt& bus, rt::Clock& c) : b(bus), clock(c) {}
    const char* name() const noexcept override { return "fanout"; }
    void run(const rt::CycleInfo& c) noexcept override {
        ethercat::Bus& bus = *b.local.bus;
        ethercat::Master& m = bus.master();
        const std::size_t n = m.image_size(), k = m.slaves().size();
        uint8_t* buf = b.slot_buf.data();
        std::memcpy(buf, m.image(), n);
        CycleTail t;
        t.wkc = m.wkc();
        t.expected_wkc = m.expected_wkc();
        t.responding = m.responding();
        t.frames_lost = m.frames_lost();
        t.frames_late = m.frames_late();
        t.wkc_errors = m.wkc_errors();
        t.dc_time = m.dc_reference_time();
        std::memcpy(buf + n, &t, sizeof t);
        uint8_t* st = buf + n + sizeof t;
        for (std::size_t i = 0; i < k; ++i, st += kSlaveStatusBytes) {
            st[0] = m.slave_al_status(i);
            st[1] = m.slave_online(i);
            st[2] = m.slave_valid(i);
            st[3] = 0;
        }
        const ethercat::CycleStatus cs = bus.last_status();
        uint32_t flags = (cs != ethercat::CycleStatus::FrameLost && cs != ethercat::CycleStatus::LinkError ? kLinkUp : 0) |
                         (cs == ethercat::CycleStatus::Ok ? kWkcOk : 0);
        const uint64_t now = clock.now_ns();
        for (auto& slot : b.slots) {
            RtClient* cl = slot.load(std::memory_order_acquire);
            if (!cl || cl->state.load(std::memory_order_acquire) != RtClient::Active) continue;
            cl->ring->publish(c.cycle, c.t_ns, now, flags, buf, uint32_t(b.slot_buf.size()));
            if (cl->out->waiting()) futex_wake(cl->ring->tick_word());
        }
    }
};

struct Scanner::GatherStage : rt::Stage {
    BusRt& b;
    rt::Clock& clock;
    double window; // fraction of the period to wait for the clients' answers (0: none)
    GatherStage(BusRt& bus, rt::Clock& c, double w) : b(bus), clock(c), window(w) {}
    const char* name() const noexcept override { return "gather"; }
    void run(const rt::CycleInfo& c) noexcept override {
        uint8_t* img = b.local.bus->master().image();
        if (window > 0) { // every client's answer to this cycle, until the window closes
            const uint64_t deadline = c.t_ns + uint64_t(window * double(c.period_ns));
            for (auto& slot : b.slots) {
                RtClient* cl = slot.load(std::memory_order_acquire);
                if (cl && cl->state.load(std::memory_order_acquire) == RtClient::Active &&
                    !cl->out->wait_answer(c.cycle, deadline))
                    cl->missed_window.fetch_add(1, std::memory_order_relaxed);
            }
        }
        const uint64_t now = clock.now_ns();
        for (auto& slot : b.slots) {
            RtClient* cl = slot.load(std::memory_order_acquire);
            if (!cl) continue;
            int st = cl->state.load(std::memory_order_acquire);
            if (st == RtClient::Detaching) {
                if (cl->zero_on_detach) cl->claims.clear(img);
                slot.store(nullptr, std::memory_order_release);
                cl->state.store(RtClient::Gone, std::memory_order_release);
                continue;
            }
            if (st != RtClient::Active) continue;
            uint64_t cycle = 0, commit_ns = 0;
            if (!cl->out->take(cl->scratch.data(), cycle, commit_ns)) continue;
            cl->claims.apply(img, cl->scratch.data());
            cl->commits.fetch_add(1, std::memory_order_relaxed);
            if (cycle + 1 < c.cycle) cl->late.fetch_add(1, std::memory_order_relaxed);
            const uint64_t lat = now > commit_ns ? now - commit_ns : 0;
            if (lat > cl->out_lat_max_ns.load(std::memory_order_relaxed)) cl->out_lat_max_ns.store(lat, std::memory_order_relaxed);
            cl->out_lat_us[std::min<uint64_t>(lat / 1000, kOutLatencyBins - 1)].fetch_add(1, std::memory_order_relaxed);
        }
    }
};

// ---- control side ------------------------------------------------------------------------------

struct ClaimedEntry {
    int position;
    std::string slave, entry; // slave: its name or "s<position>"
    uint32_t bit_offset;
    uint8_t bits;
};

struct Scanner::Conn {
    int fd = -1;
    proto::Decoder dec;
    bool hello = false;
    std::string ioc, client;
    uint32_t pid = 0;
    int bus = -1; // attached to buses_[bus]
    std::unique_ptr<RtClient> rt;
    std::vector<ClaimedEntry> claims;
    uint16_t slaves = 0;
};

Scanner::Scanner(ScannerConfig cfg, const ethercat::Catalog& catalog, rt::Clock& clock)
    : cfg_(std::move(cfg)), catalog_(catalog), clock_(clock) {
    rt::EngineConfig ec;
    ec.rate_hz = cfg_.rate_hz;
    ec.cpu = cfg_.cpu;
    ec.priority = cfg_.priority;
    engine_ = std::make_unique<rt::Engine>(ec, clock_);
    std::random_device rd;
    instance_ = (uint64_t(rd()) << 32 | rd()) ^ uint64_t(::getpid());
    for (auto& bc : cfg_.buses) {
        std::sort(bc.slaves.begin(), bc.slaves.end(), [](const auto& a, const auto& b) { return a.position < b.position; });
        auto b = std::make_unique<BusRt>();
        b->cfg = bc;
        b->local = ethercat::sim::make_local_bus(bc, catalog_, cfg_.path);
        for (const auto& s : bc.slaves) b->names.push_back(s.name);
        buses_.push_back(std::move(b));
    }
}

Scanner::~Scanner() {
    for (auto& b : buses_) b->local.bus->stop_health();
    engine_->stop();
    for (auto& [id, c] : conns_)
        if (c->fd >= 0) ::close(c->fd);
    if (listen_fd_ >= 0) {
        ::close(listen_fd_);
        ::unlink(cfg_.socket.c_str());
    }
}

ethercat::Bus& Scanner::bus(std::size_t i) { return *buses_.at(i)->local.bus; }

void Scanner::start_virtual() {
    for (auto& bp : buses_) {
        BusRt& b = *bp;
        ethercat::Bus& bus = *b.local.bus;
        bus.add_stages(*engine_);
        if (b.local.sim_stage) engine_->add_stage(rt::StageOrder::BusSend, *b.local.sim_stage);
        bus.bring_up();
        ethercat::Master& m = bus.master();
        b.outputs_bytes = m.outputs_size();
        b.slot_buf.assign(slot_data_bytes(m.image_size(), m.slaves().size()), 0);
        b.fanout = std::make_unique<FanoutStage>(b, clock_);
        b.gather = std::make_unique<GatherStage>(b, clock_, cfg_.gather_window);
        engine_->add_stage(rt::StageOrder::Axes, *b.fanout);
        engine_->add_stage(rt::StageOrder::Triggers, *b.gather);
        LOG_INFO(lg, "ec" << b.cfg.id << ": " << m.slaves().size() << " slave(s), image " << m.image_size() << " bytes ("
                          << b.outputs_bytes << " of outputs)");
    }
}

void Scanner::start() {
    start_virtual();
    engine_->start();
    for (auto& b : buses_) b->local.bus->start_health();
    group_ = cfg_.socket_group.empty() ? core::socket_group() : core::socket_group_named(cfg_.socket_group, "socket_group");
    listen_fd_ = core::listen_local(cfg_.socket, "scanner socket", 32, true, &group_);
    LOG_INFO(lg, cfg_.name << ": " << buses_.size() << " bus(es) cycling at " << cfg_.rate_hz << " Hz; IOCs attach at "
                           << cfg_.socket);
}

void Scanner::serve(EventLoop& loop) {
    loop.add_fd(listen_fd_, EPOLLIN, [this, &loop](uint32_t) { accept_one(loop); });
}

void Scanner::accept_one(EventLoop& loop) {
    for (;;) {
        int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) return;
        core::Peer peer;
        if (!core::peer_allowed(fd, group_, peer)) {
            LOG_WARN(lg, "connection from pid " << peer.pid << " (uid " << peer.uid << ") refused: not this user, root or the socket group");
            ::close(fd);
            continue;
        }
        auto c = std::make_unique<Conn>();
        c->fd = fd;
        c->pid = uint32_t(peer.pid);
        int id = fd;
        conns_[id] = std::move(c);
        loop.add_fd(fd, EPOLLIN | EPOLLRDHUP, [this, &loop, fd](uint32_t) { on_readable(loop, fd); });
    }
}

void Scanner::on_readable(EventLoop& loop, int fd) {
    auto it = conns_.find(fd);
    if (it == conns_.end()) return;
    Conn& c = *it->second;
    uint8_t buf[4096];
    bool closed = false;
    for (;;) {
        ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n > 0) {
            c.dec.feed(buf, std::size_t(n));
            continue;
        }
        if (n == 0 || (errno != EAGAIN && errno != EINTR)) closed = true;
        break;
    }
    proto::Message m;
    proto::Decoder::Result r;
    while (!closed && (r = c.dec.next(m)) == proto::Decoder::Result::Message) {
        try {
            for (Reply& rep : handle(fd, m, pid_t(c.pid))) {
                std::vector<uint8_t> out;
                proto::encode(rep.msg, out);
                send_fds(fd, out.data(), out.size(), rep.fds);
                for (int f : rep.fds) ::close(f);
            }
        } catch (const Error& e) {
            LOG_WARN(lg, "client '" << c.ioc << "' (pid " << c.pid << "): " << e.what() << "; connection closed");
            closed = true;
        }
    }
    if (!closed && r == proto::Decoder::Result::Error) {
        LOG_WARN(lg, "client '" << c.ioc << "' (pid " << c.pid << "): " << c.dec.error() << "; connection closed");
        closed = true;
    }
    if (closed) {
        loop.remove_fd(fd);
        disconnect(fd);
        ::close(fd);
    }
}

void Scanner::disconnect(int conn) {
    auto it = conns_.find(conn);
    if (it == conns_.end()) return;
    if (it->second->rt) LOG_INFO(lg, "client '" << it->second->ioc << "' (pid " << it->second->pid << ") gone: detached");
    release(*it->second);
    conns_.erase(it);
}

void Scanner::release(Conn& c) {
    if (!c.rt) return;
    BusRt& b = *buses_.at(std::size_t(c.bus));
    RtClient* cl = c.rt.get();
    cl->state.store(RtClient::Detaching, std::memory_order_release);
    if (engine_->running()) {
        // The gather stage applies the detach policy and lets go of the slot within a cycle.
        for (int i = 0; i < 5000 && cl->state.load(std::memory_order_acquire) != RtClient::Gone; ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        if (cl->state.load(std::memory_order_acquire) != RtClient::Gone) {
            LOG_ERR(lg, "client '" << c.ioc << "': the cycle did not release it within 5 s; its memory is kept");
            (void)c.rt.release();
            c.claims.clear();
            c.bus = -1;
            return;
        }
    } else { // no cycle running (virtual time between cycles, shutdown): do it here
        if (cl->zero_on_detach) cl->claims.clear(b.local.bus->master().image());
        for (auto& s : b.slots)
            if (s.load() == cl) s.store(nullptr);
        cl->state.store(RtClient::Gone);
    }
    c.rt.reset();
    c.claims.clear();
    c.bus = -1;
}

std::size_t Scanner::clients() const {
    std::size_t n = 0;
    for (const auto& b : buses_)
        for (const auto& s : b->slots) n += s.load() != nullptr;
    return n;
}

std::vector<Scanner::ClientFigures> Scanner::client_figures() const {
    std::vector<ClientFigures> out;
    for (const auto& [id, c] : conns_) {
        if (!c->rt) continue;
        ClientFigures f;
        f.name = c->ioc;
        f.commits = c->rt->commits.load();
        f.late = c->rt->late.load();
        f.missed_window = c->rt->missed_window.load();
        f.out_latency_max_ns = c->rt->out_lat_max_ns.load();
        for (std::size_t i = 0; i < kOutLatencyBins; ++i) f.out_latency_us[i] = c->rt->out_lat_us[i].load();
        out.push_back(f);
    }
    return out;
}

proto::Status Scanner::status() const {
    proto::Status s;
    s.cycle = engine_->stats().cycles;
    for (const auto& b : buses_) {
        ethercat::Master& m = b->local.bus->master();
        s.frames_lost += m.frames_lost();
        s.wkc_errors += m.wkc_errors();
    }
    for (const auto& [fd, c] : conns_) {
        if (!c->rt) continue;
        proto::ClientStatus cs;
        cs.name = c->ioc;
        cs.pid = c->pid;
        cs.slaves = c->slaves;
        cs.claims = uint16_t(c->claims.size());
        cs.drops = c->rt->out->drops();
        cs.late = c->rt->late.load();
        s.clients.push_back(cs);
    }
    return s;
}

namespace {
proto::Message error_reply(uint32_t id, proto::ErrorCode code, std::string text, uint32_t abort = 0) {
    return proto::Message{id, proto::ErrorMsg{code, std::move(text), abort}};
}
} // namespace

std::vector<Scanner::Reply> Scanner::handle(int conn, const proto::Message& m, pid_t pid) {
    auto& cp = conns_[conn];
    if (!cp) {
        cp = std::make_unique<Conn>();
        cp->pid = uint32_t(pid);
    }
    Conn& c = *cp;
    std::vector<Reply> out;
    auto reply = [&](proto::Body b) { out.push_back(Reply{proto::Message{m.request_id, std::move(b)}, {}}); };
    auto refuse = [&](proto::ErrorCode code, std::string text) { out.push_back(Reply{error_reply(m.request_id, code, std::move(text)), {}}); };
    auto find_bus = [&](uint16_t id) -> BusRt* {
        for (auto& b : buses_)
            if (b->cfg.id == id) return b.get();
        return nullptr;
    };
    auto find_slave = [&](BusRt& b, int position) -> int {
        const auto& sl = b.local.bus->slaves();
        for (std::size_t i = 0; i < sl.size(); ++i)
            if (sl[i].position == position) return int(i);
        return -1;
    };

    if (const auto* h = std::get_if<proto::Hello>(&m.body)) {
        uint16_t v = std::min<uint16_t>(h->max_version, proto::kVersion);
        if (v < h->min_version || v < 1) {
            refuse(proto::ErrorCode::NoCommonVersion,
                   SB() << "this scanner speaks protocol 1.." << proto::kVersion << ", the client " << h->min_version << ".." << h->max_version);
            return out;
        }
        c.hello = true;
        c.ioc = h->ioc;
        c.client = h->client;
        proto::Welcome w;
        w.version = v;
        w.scanner = cfg_.name;
        w.instance = instance_;
        for (auto& b : buses_)
            w.buses.push_back(proto::BusInfo{uint16_t(b->cfg.id), engine_->period_ns(), uint16_t(b->local.bus->slaves().size())});
        reply(w);
        return out;
    }
    if (std::holds_alternative<proto::StatusRequest>(m.body)) {
        reply(status());
        return out;
    }
    if (!c.hello) {
        refuse(proto::ErrorCode::BadMessage, SB() << proto::to_string(m.type()) << " before Hello");
        return out;
    }
    if (const auto* d = std::get_if<proto::Describe>(&m.body)) {
        BusRt* b = find_bus(d->bus);
        if (!b) return refuse(proto::ErrorCode::UnknownBus, SB() << "no bus " << d->bus << " on scanner '" << cfg_.name << "'"), out;
        proto::Chain ch;
        ch.bus = d->bus;
        const auto& sl = b->local.bus->slaves();
        for (std::size_t i = 0; i < sl.size(); ++i) ch.slaves.push_back(chain_slave(sl[i], b->names[i]));
        reply(ch);
        return out;
    }
    if (const auto* a = std::get_if<proto::Attach>(&m.body)) {
        std::vector<int> fds;
        proto::Message r = attach(c, *a, fds);
        r.request_id = m.request_id;
        out.push_back(Reply{std::move(r), std::move(fds)});
        return out;
    }
    if (std::holds_alternative<proto::Detach>(m.body)) {
        release(c);
        reply(proto::Ok{});
        return out;
    }
    // The bus and slave an acyclic request names (nullptr: refused, the reply is in `out`).
    auto target = [&](uint16_t bus, uint16_t position, int& index) -> BusRt* {
        BusRt* b = find_bus(bus);
        if (!b) return refuse(proto::ErrorCode::UnknownBus, SB() << "no bus " << bus), nullptr;
        index = find_slave(*b, position);
        if (index < 0) return refuse(proto::ErrorCode::UnknownSlave, SB() << "ec" << bus << ": no slave at position " << position), nullptr;
        return b;
    };
    // An SDO transfer through the master: its answer, or the slave's abort code, or what failed.
    auto sdo = [&](auto&& transfer) {
        try {
            transfer();
        } catch (const ethercat::SdoAbort& e) {
            out.push_back(Reply{error_reply(m.request_id, proto::ErrorCode::SdoAbort, e.what(), e.code()), {}});
        } catch (const Error& e) {
            refuse(proto::ErrorCode::Timeout, e.what());
        }
    };
    int slave = -1;
    if (const auto* r = std::get_if<proto::SdoRead>(&m.body)) {
        if (BusRt* b = target(r->bus, r->position, slave))
            sdo([&] { reply(proto::SdoData{b->local.bus->sdo_read(r->position, r->index, r->sub)}); });
        return out;
    }
    if (const auto* w = std::get_if<proto::SdoWrite>(&m.body)) {
        BusRt* b = target(w->bus, w->position, slave);
        if (!b) return out;
        bool mine = false; // writes only to the slaves whose outputs this client claimed
        if (c.rt && c.bus >= 0 && buses_[std::size_t(c.bus)].get() == b)
            for (const auto& e : c.claims) mine = mine || e.position == w->position;
        if (!mine)
            return refuse(proto::ErrorCode::Denied, SB() << "ec" << w->bus << " s" << w->position
                                                         << ": SDO writes only to a slave whose outputs this client claimed"), out;
        sdo([&] {
            b->local.bus->sdo_write(w->position, w->index, w->sub, w->data);
            reply(proto::Ok{});
        });
        return out;
    }
    if (const auto* q = std::get_if<proto::AlInfoRequest>(&m.body)) {
        BusRt* b = target(q->bus, q->position, slave);
        if (!b) return out;
        const std::size_t i = std::size_t(slave);
        ethercat::Master& mm = b->local.bus->master();
        ethercat::SlaveHealth h = mm.slave_health(i);
        proto::AlInfo al;
        al.al_state = mm.slave_al_status(i);
        al.status_code = mm.slaves()[i].al_status_code;
        al.slave_state = uint8_t(h.state);
        al.lost = h.lost, al.reconfigured = h.reconfigured, al.refused = h.refused, al.error_id = h.error_id;
        al.last_error = mm.slave_last_error(i);
        reply(al);
        return out;
    }
    refuse(proto::ErrorCode::BadMessage, SB() << proto::to_string(m.type()) << " is not a request");
    return out;
}

proto::Message Scanner::attach(Conn& c, const proto::Attach& a, std::vector<int>& fds) {
    auto refuse = [](proto::ErrorCode code, std::string text) { return error_reply(0, code, std::move(text)); };
    BusRt* bp = nullptr;
    std::size_t bus_index = 0;
    for (std::size_t i = 0; i < buses_.size(); ++i)
        if (buses_[i]->cfg.id == a.bus) bp = buses_[i].get(), bus_index = i;
    if (!bp) return refuse(proto::ErrorCode::UnknownBus, SB() << "no bus " << a.bus << " on scanner '" << cfg_.name << "'");
    BusRt& b = *bp;
    if (c.rt) return refuse(proto::ErrorCode::Busy, "this connection is attached already (Detach first)");
    if (clients() >= std::min<std::size_t>(cfg_.max_clients, kMaxClients))
        return refuse(proto::ErrorCode::Full, SB() << "scanner '" << cfg_.name << "' has " << clients() << " clients attached, its limit (scanner.max_clients)");
    ethercat::Master& m = b.local.bus->master();
    const auto& sl = m.slaves();
    auto chain_name = [&](std::size_t i) { return b.names[i].empty() ? std::string(SB() << "s" << sl[i].position) : b.names[i]; };
    auto chain_list = [&] {
        std::string s;
        for (std::size_t i = 0; i < sl.size(); ++i) s += (i ? ", " : "") + std::to_string(sl[i].position) + (b.names[i].empty() ? "" : " " + b.names[i]);
        return s;
    };
    auto resolve = [&](const std::string& what) -> int {
        for (std::size_t i = 0; i < sl.size(); ++i)
            if ((all_digits(what) && std::to_string(sl[i].position) == what) || (!b.names[i].empty() && b.names[i] == what)) return int(i);
        return -1;
    };
    if (a.slaves.empty()) return refuse(proto::ErrorCode::UnknownSlave, "Attach names no slave");
    std::vector<int> mine;
    for (const auto& s : a.slaves) {
        int i = resolve(s);
        if (i < 0) return refuse(proto::ErrorCode::UnknownSlave, SB() << "ec" << a.bus << ": no slave '" << s << "' in the chain (" << chain_list() << ")");
        if (std::find(mine.begin(), mine.end(), i) == mine.end()) mine.push_back(i);
    }
    std::sort(mine.begin(), mine.end());
    // Claims: each a named output entry of an attached slave, or "*" for all its outputs.
    std::vector<ClaimedEntry> claims;
    for (const auto& cl : a.claims) {
        int i = resolve(cl.slave);
        if (i < 0 || std::find(mine.begin(), mine.end(), i) == mine.end())
            return refuse(proto::ErrorCode::UnknownSlave, SB() << "ec" << a.bus << ": claim on '" << cl.slave << "', which this client does not attach");
        const std::string pre = SB() << "ec" << a.bus << ".s" << sl[std::size_t(i)].position << ".";
        bool found = false;
        for (const auto& sig : m.signals()) {
            if (sig.slave != sl[std::size_t(i)].position || !sig.output || sig.name.compare(0, pre.size(), pre) != 0) continue;
            std::string entry = sig.name.substr(pre.size());
            if (cl.entry != "*" && cl.entry != entry) continue;
            found = true;
            claims.push_back(ClaimedEntry{sl[std::size_t(i)].position, chain_name(std::size_t(i)), entry, sig.bit_offset, sig.bits});
        }
        if (!found && cl.entry != "*")
            return refuse(proto::ErrorCode::UnknownSlave, SB() << "ec" << a.bus << " " << chain_name(std::size_t(i)) << ": no output entry '" << cl.entry << "'");
    }
    // Two clients never write the same bit.
    for (const auto& [fd, other] : conns_) {
        if (other.get() == &c || !other->rt || other->bus != int(bus_index)) continue;
        for (const auto& x : claims)
            for (const auto& y : other->claims)
                if (x.bit_offset < y.bit_offset + y.bits && y.bit_offset < x.bit_offset + x.bits)
                    return refuse(proto::ErrorCode::ClaimConflict,
                                  SB() << "ec" << a.bus << " " << x.slave << " " << x.entry << " is claimed by '" << other->ioc << "' (pid "
                                       << other->pid << "); '" << c.ioc << "' (pid " << c.pid << ") cannot claim it too");
    }
    unsigned depth = a.depth ? a.depth : cfg_.default_depth;
    unsigned d2 = 2;
    while (d2 < depth && d2 < 4096) d2 <<= 1;
    depth = d2;

    proto::Attached at;
    at.client_id = next_client_id_++;
    at.image_bytes = uint32_t(m.image_size());
    at.depth = uint16_t(depth);
    for (int i : mine) at.slaves.push_back(layout_slave(m, std::size_t(i), b.names[std::size_t(i)]));
    at.layout_hash = layout_hash(at);

    auto cl = std::make_unique<RtClient>();
    cl->name = c.ioc;
    cl->pid = c.pid;
    cl->id = at.client_id;
    cl->zero_on_detach = a.on_detach == 0;
    const uint32_t data = uint32_t(b.slot_buf.size());
    cl->ring_mem = SharedMemory::create(SB() << "beamctl-ring-" << c.ioc, ring_bytes(depth, data), false);
    cl->ring = std::make_unique<RingWriter>(cl->ring_mem.data(), cl->ring_mem.size(), depth, data, at.layout_hash, instance_);
    cl->out_mem = SharedMemory::create(SB() << "beamctl-out-" << c.ioc, out_block_bytes(b.outputs_bytes), true);
    init_out_block(cl->out_mem.data(), b.outputs_bytes);
    cl->out = std::make_unique<OutReader>(cl->out_mem.data(), b.outputs_bytes);
    std::vector<uint8_t> mask(b.outputs_bytes, 0);
    for (const auto& x : claims)
        for (uint32_t bit = x.bit_offset; bit < x.bit_offset + x.bits && bit / 8 < b.outputs_bytes; ++bit) mask[bit / 8] |= uint8_t(1u << (bit % 8));
    cl->claims = ByteMerge(mask);
    cl->scratch.assign(b.outputs_bytes, 0);
    // The outputs the client starts from are the frame's: its first commit changes only what it means to.
    std::memcpy(cl->scratch.data(), m.image(), b.outputs_bytes);
    std::atomic<RtClient*>* free_slot = nullptr;
    for (auto& s : b.slots)
        if (!s.load()) {
            free_slot = &s;
            break;
        }
    if (!free_slot) return refuse(proto::ErrorCode::Full, "no free client slot on this bus");
    fds.push_back(::dup(cl->ring_mem.fd()));
    fds.push_back(::dup(cl->out_mem.fd()));
    c.bus = int(bus_index);
    c.claims = std::move(claims);
    c.slaves = uint16_t(mine.size());
    free_slot->store(cl.get(), std::memory_order_release);
    c.rt = std::move(cl);
    LOG_INFO(lg, "client '" << c.ioc << "' (pid " << c.pid << ") attached to ec" << a.bus << ": " << mine.size() << " slave(s), "
                            << c.claims.size() << " output entr" << (c.claims.size() == 1 ? "y" : "ies") << " claimed, ring of " << depth
                            << " cycles");
    return proto::Message{0, std::move(at)};
}

void Scanner::stop(const std::string& reason) {
    for (auto& [id, c] : conns_) {
        if (c->fd < 0) continue;
        std::vector<uint8_t> out;
        proto::encode(proto::Message{0, proto::Goodbye{reason}}, out);
        (void)::send(c->fd, out.data(), out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    }
    for (auto& b : buses_) b->local.bus->stop_health();
    for (auto& b : buses_) {
        try {
            b->local.bus->to_safe_op();
        } catch (const Error& e) {
            LOG_WARN(lg, "ec" << b->cfg.id << ": " << e.what());
        }
    }
    engine_->stop();
    for (auto& [fd, c] : conns_) release(*c);
}

} // namespace beamctl::scanner
