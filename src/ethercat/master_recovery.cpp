// EtherCAT master while cycling (health thread): acyclic datagrams through the cycle, slave
// health, lost slaves, hot connect and re-configuration.
#include "ethercat/master.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/coe.hpp"
#include "ethercat/master_internal.hpp"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cstring>
#include <iomanip>
#include <map>
#include <sstream>
#include <thread>

namespace beamctl::ethercat {
using namespace master_detail;
namespace {
log::Logger lg("ethercat.master");
} // namespace


int Master::transact_via_cycle(uint8_t cmd, uint32_t addr, void* data, uint16_t len, int retries) {
    if (len > kMaxAcyclic) return -1;
    AcyclicRequest req;
    req.cmd = cmd;
    req.addr = addr;
    req.len = len;
    std::memcpy(req.data, data, len);
    for (int attempt = 0; attempt <= retries; ++attempt) {
        while (!acyc_req_.push(req)) std::this_thread::sleep_for(std::chrono::microseconds(100));
        AcyclicReply rep;
        auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(500);
        bool got = false;
        while (std::chrono::steady_clock::now() < deadline) {
            if (acyc_rep_.pop(rep)) {
                got = true;
                break;
            }
            std::this_thread::sleep_for(std::chrono::microseconds(100));
        }
        if (!got) return -1; // the cycle is not running
        if (rep.wkc >= 0) {
            std::memcpy(data, rep.data, len);
            return rep.wkc;
        }
    }
    return -1;
}

const char* slave_state_name(SlaveState s) {
    switch (s) {
    case SlaveState::Op: return "OP";
    case SlaveState::Missing: return "MISSING";
    case SlaveState::WrongId: return "WRONG_ID";
    case SlaveState::Error: return "ERROR";
    case SlaveState::Lost: return "LOST";
    case SlaveState::Configuring: return "CONFIGURING";
    }
    return "?";
}

void Master::set_health(std::size_t i, SlaveState st, uint32_t error_id, const std::string& error) {
    std::lock_guard<std::mutex> l(health_mu_);
    SlaveHealth& h = health_[i];
    h.state = st;
    h.error_id = error_id;
    if (!error.empty()) last_error_[i] = error;
    health_version_.fetch_add(1, std::memory_order_release);
}

std::string Master::slave_last_error(std::size_t i) const {
    std::lock_guard<std::mutex> l(health_mu_);
    return i < last_error_.size() ? last_error_[i] : std::string();
}

SlaveHealth Master::slave_health(std::size_t i) const {
    std::lock_guard<std::mutex> l(health_mu_);
    return i < health_.size() ? health_[i] : SlaveHealth{};
}

int Master::slaves_op() const {
    int n = 0;
    for (std::size_t i = 0; i < slaves_.size(); ++i) n += slave_valid(i);
    return n;
}

bool Master::health_due() const {
    if (responding() != last_responding_) return true;
    for (std::size_t i = 0; i < slaves_.size(); ++i)
        if (admit_[i].load(std::memory_order_relaxed) && !(slave_online(i) && (slave_al_status(i) & 0x1F) == 8)) return true;
    return false;
}

bool Master::claim_position(std::size_t i) {
    SlaveInfo& s = slaves_[i];
    uint16_t addr = 0xFFFF;
    if (transact(kAprd, uint16_t(-s.position), 0x0010, &addr, 2, 0) != 1) return false;
    if (addr == s.station) return true;
    // Only a slave without an address is ours to take: with a slave missing, positions shift and
    // the one answering may be a neighbour that still has its own address.
    if (addr != 0) return false;
    uint16_t st = s.station;
    return transact(kApwr, uint16_t(-s.position), 0x0010, &st, 2) == 1;
}

void Master::configure_slave(std::size_t i, bool full_sii) {
    SlaveInfo& s = slaves_[i];
    // Identity first, before anything is written to it.
    SlaveInfo fresh = s;
    if (full_sii) read_sii(fresh);
    else read_identity(fresh);
    std::string wrong = identity_error(fresh);
    if (!wrong.empty()) {
        uint16_t none = 0; // not ours: take the station address back, leave it alone
        transact(kFpwr, s.station, 0x0010, &none, 2);
        throw IdentityMismatch(wrong);
    }
    if (full_sii) s.sii = fresh.sii;
    uint16_t ack = 0x0011; // INIT, acknowledge any error
    transact(kFpwr, s.station, kAlControl, &ack, 2);
    uint8_t zeros[256] = {};
    transact(kFpwr, s.station, kFmmu, zeros, 256);
    transact(kFpwr, s.station, kSm, zeros, 128);
    request_state({i}, 1, "INIT");
    configure_mailbox(s);
    request_state({i}, 2, "PREOP");
    mbx_counter_.erase(s.position);
    apply_startup_sdos(i);
    // The PDO layout must be the one its image region was laid out for, entry by entry.
    SlaveInfo layout = s;
    read_pdo_layout(layout);
    auto entries = [](const SlaveInfo& x, bool out) {
        std::vector<std::tuple<uint16_t, uint8_t, uint8_t>> v;
        for (auto& [smi, pdo] : x.pdo_assign)
            for (auto& p : out ? x.rx_pdos : x.tx_pdos)
                if (p.index == pdo)
                    for (auto& e : p.entries) v.emplace_back(e.index, e.sub, e.bits);
        return v;
    };
    for (bool out : {true, false})
        if (entries(layout, out) != entries(s, out))
            throw Error(SB() << slave_name(s) << ": its PDO " << (out ? "outputs" : "inputs")
                             << " differ from the layout reserved at start (restart the IOC to use them)");
    configure_process_data(i);
    if (uses_dc_time(s.sii)) configure_dc_slave(i);
    request_state({i}, 4, "SAFEOP");
    request_state({i}, 8, "OP");
}

std::string Master::check_outage(double now_s) {
    BusSample smp;
    smp.send_ok = send_ok_.load(std::memory_order_relaxed);
    smp.frames_back = frames_back_.load(std::memory_order_relaxed);
    smp.wkc = wkc();
    // A slave left out (missing, lost) is the health pass's to report, not an outage: the cycle
    // counts as good while the working counter is the one the slaves taking part give.
    smp.expected_wkc = cycle_ok() ? smp.wkc : expected_wkc_;
    smp.frames_lost = frames_lost();
    smp.wkc_errors = wkc_errors();
    if (smp.frames_back) {
        SB sb;
        const char* sep = "";
        for (std::size_t i = 0; i < slaves_.size(); ++i) {
            uint8_t al = slave_al_status(i);
            if (!slave_online(i)) sb << sep << "slave " << slaves_[i].position << " (" << slaves_[i].type << ") not answering";
            else if (al != 8)
                sb << sep << "slave " << slaves_[i].position << " (" << slaves_[i].type << ") in " << al_state_name(al)
                   << (al & 0x10 ? " with an error" : "") << " (AL status " << hex(al, 2) << ")";
            else continue;
            sep = ", ";
        }
        smp.slaves = sb;
    }
    std::optional<OutageMonitor::Report> r = outage_.update(smp, now_s);
    if (!r) return {};
    BEAMCTL_LOG_AT(lg, r->level, r->text);
    return r->text;
}

int Master::check_and_recover() {
    double now = std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
    check_outage(now);
    int responding_now = responding();
    bool topology_changed = responding_now != last_responding_;
    last_responding_ = responding_now;
    int brought = 0;
    for (std::size_t i = 0; i < slaves_.size(); ++i) {
        SlaveInfo& s = slaves_[i];
        bool online = slave_online(i);
        uint8_t al = slave_al_status(i);
        SlaveHealth h = slave_health(i);
        bool admitted = admit_[i].load(std::memory_order_relaxed);
        if (admitted) {
            if (online && (al & 0x1F) == 8) continue;
            // It was in the cycle and is no longer there, or left OP: out of the cycle's trust
            // until configured again.
            set_admitted(i, false);
            {
                std::lock_guard<std::mutex> l(health_mu_);
                health_[i].lost++;
            }
            health_version_.fetch_add(1, std::memory_order_release);
            std::string why = online ? std::string(SB() << slave_name(s) << ": left OP (AL status " << hex(al, 2) << ")")
                                     : std::string(SB() << slave_name(s) << ": lost (no answer at station " << hex(s.station, 4) << ")");
            set_health(i, SlaveState::Lost, online ? slave_error::kNotOperational : slave_error::kNotOnline, why);
            LOG_WARN(lg, why);
            retry_at_[i] = 0;
            backoff_[i] = 1.0;
        }
        // Not in the cycle: Missing, WrongId, Error, Lost. A slave that failed or was of another
        // identity is tried again with a back-off (1 s doubling to 30 s) unless the bus changed.
        if (!topology_changed && now < retry_at_[i]) continue;
        if (!online && !claim_position(i)) continue; // nothing (ours) at its position yet
        // A slave that was in OP before has its SII cached: its identity is enough.
        bool full_sii = h.state != SlaveState::Lost;
        set_health(i, SlaveState::Configuring, h.error_id, "");
        try {
            configure_slave(i, full_sii);
            set_admitted(i, true);
            {
                std::lock_guard<std::mutex> l(health_mu_);
                health_[i].reconfigured++;
            }
            set_health(i, SlaveState::Op, 0, "");
            ++brought;
            recoveries_++;
            backoff_[i] = 1.0;
            LOG_INFO(lg, slave_name(s) << (h.state == SlaveState::Missing ? ": appeared, configured and in OP"
                                                                          : ": configured again and back in OP")
                                       << (cfg_[i].sdos.empty() ? "" : std::string(SB() << " (" << cfg_[i].sdos.size() << " start-up SDO(s) written)")));
        } catch (const Error& e) {
            bool wrong = dynamic_cast<const IdentityMismatch*>(&e) != nullptr;
            SlaveState st = wrong ? SlaveState::WrongId : SlaveState::Error;
            {
                std::lock_guard<std::mutex> l(health_mu_);
                health_[i].refused++;
            }
            bool same = slave_last_error(i) == e.what();
            set_health(i, st, wrong ? slave_error::kVerificationFail : slave_error::kNotOperational, e.what());
            if (!same) LOG_ERR(lg, e.what() << (wrong ? "; left out" : "; will try again"));
            retry_at_[i] = now + backoff_[i];
            backoff_[i] = std::min(backoff_[i] * 2, 30.0);
        }
    }
    return brought;
}


} // namespace beamctl::ethercat
