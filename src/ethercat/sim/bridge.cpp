#include "ethercat/sim/bridge.hpp"

#include "core/error.hpp"
#include "ethercat/sim/segment.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace beamctl::ethercat::sim {
namespace {

// The pairs of this process by name; a pair lives while a side holds it.
std::mutex hub_mu;
std::map<std::string, std::weak_ptr<BridgePair>>& hub() {
    static std::map<std::string, std::weak_ptr<BridgePair>> h;
    return h;
}

const char* side_name(int me) { return me ? "secondary" : "primary"; }

} // namespace

BridgeSide::BridgeSide(Segment& seg, int position, const std::string& pair, int me) : position_(position), me_(me) {
    bind(seg);
    if (pair.empty()) { // a bridge whose other side is nowhere: never connected
        pair_ = std::make_shared<BridgePair>();
    } else {
        std::lock_guard<std::mutex> l(hub_mu);
        std::weak_ptr<BridgePair>& w = hub()[pair];
        pair_ = w.lock();
        if (!pair_) w = pair_ = std::make_shared<BridgePair>();
    }
    std::lock_guard<std::mutex> l(pair_->mu);
    BridgePair::Side& s = pair_->side[me_];
    if (s.joined)
        throw Error(SB() << "EL6692 bridge '" << pair << "': its " << side_name(me_) << " side is already on another segment (slave " << position
                         << " here is a " << side_name(me_) << " side too: the two sides of a pair are one primary and one secondary)");
    s.joined = true;
    s.op = false;
    s.out.assign(out_.size(), 0);
}

void BridgeSide::bind(Segment& seg) {
    const DeviceDesc& d = seg.slave(std::size_t(position_)).desc();
    auto bind_user = [&](const std::vector<Pdo>& pdos, uint16_t index, std::vector<IoPoint>& to) {
        for (const Pdo& p : pdos)
            for (const PdoEntry& e : p.entries) {
                if (e.index != index || e.sub == 0 || e.name.empty()) continue;
                if (to.size() < e.sub) to.resize(e.sub);
                to[e.sub - 1] = bind_assigned(seg, position_, e.name); // unassigned PDOs: unbound
            }
    };
    bind_user(d.rx_pdos, 0x7000, out_);
    bind_user(d.tx_pdos, 0x6000, in_);
    toggle_ = bind_assigned(seg, position_, "txPdoToggle01");
    state_ = bind_assigned(seg, position_, "txPdoState01");
    not_connected_ = bind_assigned(seg, position_, "externalDeviceNotConnected01");
    ts_toggle_ = bind_assigned(seg, position_, "timestampToggle01");
    int_ts_ = bind_assigned(seg, position_, "internalTimestamp01");
    ext_ts_ = bind_assigned(seg, position_, "externalTimestamp01");
    scratch_.assign(out_.size(), 0);
}

BridgeSide::~BridgeSide() {
    std::lock_guard<std::mutex> l(pair_->mu);
    BridgePair::Side& s = pair_->side[me_];
    s.joined = false;
    s.op = false;
}

void BridgeSide::step(Segment& seg) noexcept {
    const bool plugged = seg.plugged(std::size_t(position_));
    const uint8_t al = plugged ? seg.slave(std::size_t(position_)).al_state() : 0;
    if (al != al_seen_) { // SAFEOP: the assignment the master configured holds from now on
        al_seen_ = al;
        if (al == kSafeop) bind(seg); // allocates, once per state change (not in the cycle's steady state)
    }
    const bool op = plugged && seg.slave(std::size_t(position_)).outputs_valid();
    for (std::size_t k = 0; k < out_.size(); ++k) scratch_[k] = out_[k].bound() ? out_[k].get(seg) : 0;
    const uint64_t now = seg.time(), dc = seg.dc_system_time();
    bool connected = false, news = false;
    uint64_t ext = 0;
    {
        std::lock_guard<std::mutex> l(pair_->mu);
        const BridgePair::Side& other = pair_->side[1 - me_];
        connected = other.joined && other.op;
        if (connected && other.seq != seen_seq_) {
            const std::size_t n = std::min(in_.size(), other.out.size());
            for (std::size_t k = 0; k < n; ++k)
                if (in_[k].bound()) in_[k].set(seg, other.out[k]);
            seen_seq_ = other.seq;
            news = true;
        }
        if (connected) // the other segment's DC time now: from its last frame, at its clock's rate
            ext = other.dc_ns + uint64_t(std::llround(double(int64_t(now - other.t_ns)) * other.rate));
        BridgePair::Side& mine = pair_->side[me_];
        mine.op = op;
        mine.t_ns = now;
        mine.dc_ns = dc;
        mine.rate = seg.clock_rate();
        if (op) {
            std::copy(scratch_.begin(), scratch_.end(), mine.out.begin());
            ++mine.seq;
        }
    }
    if (news) toggled_ = !toggled_;
    toggle_.set(seg, toggled_ ? 1 : 0);
    state_.set(seg, connected ? 0 : 1);
    not_connected_.set(seg, connected ? 0 : 1);
    if (connected && int_ts_.bound()) { // both time stamps, latched together
        int_ts_.set(seg, dc);
        ext_ts_.set(seg, ext);
        ts_toggled_ = !ts_toggled_;
        ts_toggle_.set(seg, ts_toggled_ ? 1 : 0);
    }
}

} // namespace beamctl::ethercat::sim
