#include "ethercat/master.hpp"

#include "core/error.hpp"
#include "core/log.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/coe.hpp"

#include <algorithm>
#include <chrono>
#include <functional>
#include <cstring>
#include <iomanip>
#include <map>
#include <sstream>
#include <thread>

namespace beamctl::ethercat {
namespace {
log::Logger lg("ethercat.master");

// Adds to a counter only the RT thread writes (other threads read whole values).
void bump(std::atomic<uint64_t>& a, uint64_t v) noexcept {
    a.store(a.load(std::memory_order_relaxed) + v, std::memory_order_relaxed);
}

const char* al_state_name(uint8_t al) {
    switch (al & 0x0F) {
    case 1: return "INIT";
    case 2: return "PREOP";
    case 3: return "BOOT";
    case 4: return "SAFEOP";
    case 8: return "OP";
    default: return "an unknown state";
    }
}

constexpr uint16_t kAlControl = 0x0120, kAlStatus = 0x0130, kSiiControl = 0x0502,
                   kSiiAddress = 0x0504, kSiiData = 0x0508, kFmmu = 0x0600, kSm = 0x0800;
constexpr uint16_t kStationBase = 0x1001;
constexpr uint8_t kAcyclicIdx = 0xFE; // tag of the acyclic datagram travelling with the cycle
// Cyclic datagram index: bits 3-6 = cycle sequence (mod 16), bits 0-2 = frame number.
constexpr std::size_t kMaxCyclicFrames = 8;

std::string hex(uint32_t v, int w = 8) {
    std::ostringstream os;
    os << "0x" << std::hex << std::setw(w) << std::setfill('0') << v;
    return os.str();
}

// "0x1C12:01", as object addresses are written in CoE documentation.
std::string object_name(uint16_t index, uint8_t sub) {
    std::ostringstream os;
    os << "0x" << std::hex << std::uppercase << std::setw(4) << std::setfill('0') << index << ":"
       << std::setw(2) << int(sub);
    return os.str();
}

std::string sdo_context(int bus, int position, const char* what, uint16_t index, uint8_t sub) {
    return SB() << "ec" << bus << " position " << position << ": SDO " << what << " "
                << object_name(index, sub);
}

// CoE data type name for a mapped entry the SII does not describe.
std::string datatype_for_bits(unsigned bits) {
    switch (bits) {
    case 1:
        return "BOOL";
    case 8:
        return "UINT8";
    case 16:
        return "UINT16";
    case 32:
        return "UINT32";
    case 64:
        return "UINT64";
    default:
        return bits < 8 ? std::string(SB() << "BIT" << bits) : std::string();
    }
}

const char* state_name(uint8_t s) {
    switch (s & 0x0F) {
    case 1: return "INIT";
    case 2: return "PREOP";
    case 3: return "BOOT";
    case 4: return "SAFEOP";
    case 8: return "OP";
    default: return "UNKNOWN";
    }
}

std::string al_code_text(uint16_t c) {
    switch (c) {
    case 0x0011: return "0x0011 invalid requested state change";
    case 0x0012: return "0x0012 unknown requested state";
    case 0x0016: return "0x0016 invalid mailbox configuration";
    case 0x001B: return "0x001B sync manager watchdog";
    case 0x001D: return "0x001D invalid output configuration";
    case 0x001E: return "0x001E invalid input configuration";
    case 0x0030: return "0x0030 invalid DC synchronization configuration";
    default: return hex(c, 4);
    }
}

// The device at a slave's position is not the configured one (health pass: WrongId, not Error).
class IdentityMismatch : public Error {
public:
    using Error::Error;
};

} // namespace

Master::Master(Link& link, int bus_id, std::vector<SlaveConfig> cfg, const Catalog& catalog)
    : link_(link), bus_(bus_id), cfg_(std::move(cfg)), catalog_(catalog), outage_(SB() << "ec" << bus_id) {
    std::sort(cfg_.begin(), cfg_.end(),
              [](const SlaveConfig& a, const SlaveConfig& b) { return a.position < b.position; });
    for (std::size_t i = 1; i < cfg_.size(); ++i)
        if (cfg_[i].position == cfg_[i - 1].position)
            throw Error(SB() << "ec" << bus_ << ": two slaves configured at position " << cfg_[i].position);
    for (auto& c : cfg_) {
        if (c.position < 0) throw Error(SB() << "ec" << bus_ << ": negative slave position " << c.position);
        const DeviceDesc* d = catalog_.find(c.type);
        if (!d)
            throw Error(SB() << "ec" << bus_ << " position " << c.position << ": unknown device type '"
                             << c.type << "' (not in the catalog)");
        for (const StartupSdo& sdo : c.sdos) {
            std::string what = SB() << "ec" << bus_ << " position " << c.position
                                    << ": startup SDO " << object_name(sdo.index, sdo.sub);
            if (!d->coe) throw Error(SB() << what << ": " << c.type << " has no CoE mailbox");
            if (sdo.size != 1 && sdo.size != 2 && sdo.size != 4 && sdo.size != 8)
                throw Error(SB() << what << ": size " << int(sdo.size)
                                 << " should be 1, 2, 4 or 8 bytes");
            if (sdo.size < 8) {
                int bits = 8 * sdo.size;
                bool fits_unsigned = (sdo.value >> bits) == 0;
                int64_t v = int64_t(sdo.value);
                bool fits_signed = v < 0 && v >= -(int64_t(1) << (bits - 1));
                if (!fits_unsigned && !fits_signed)
                    throw Error(SB() << what << ": value " << v << " does not fit in "
                                     << int(sdo.size) << " byte(s)");
            }
        }
    }
}

std::string Master::slave_name(const SlaveInfo& s) const {
    return SB() << "ec" << bus_ << " slave " << s.position << " (" << s.type << ")";
}

int Master::transact(uint8_t cmd, uint32_t addr, void* data, uint16_t len, int retries) {
    if (cycling_.load(std::memory_order_acquire)) return transact_via_cycle(cmd, addr, data, len, retries);
    FrameBuilder f;
    for (int attempt = 0; attempt <= retries; ++attempt) {
        uint8_t idx = next_idx_;
        next_idx_ = uint8_t(next_idx_ == 0xFF ? 0x80 : next_idx_ + 1);
        f.reset();
        int off = f.add(cmd, idx, addr, len, data);
        if (off < 0) return -1;
        if (!link_.send(f.data(), f.size())) continue;
        for (int tries = 0; tries < 4; ++tries) {
            std::size_t n = link_.receive(rx_.data(), rx_.size(), 2000);
            if (n == 0) break;
            int wkc = -1;
            for_each_datagram(rx_.data(), n, [&](Datagram& d) {
                if (d.idx() == idx && d.cmd() == cmd && d.len() == len) {
                    std::memcpy(data, d.data, len);
                    wkc = d.wkc();
                }
            });
            if (wkc >= 0) return wkc;
        }
    }
    return -1;
}

int Master::count_slaves() {
    uint16_t v = 0;
    return transact(kBrd, 0, kAlStatus, &v, 2);
}

void Master::sii_read4(const SlaveInfo& s, uint32_t addr, std::vector<uint16_t>& words) {
    uint8_t cmd[6] = {0, 1, 0, 0, 0, 0}; // control: read; address
    put_le32(cmd + 2, addr);
    if (transact(kFpwr, s.station, kSiiAddress, cmd + 2, 4) != 1 ||
        transact(kFpwr, s.station, uint16_t(kSiiControl + 1), cmd + 1, 1) != 1)
        throw Error(SB() << slave_name(s) << ": no answer while reading the SII EEPROM");
    uint8_t st[2] = {};
    for (int i = 0; i < 100; ++i) { // wait while busy
        if (transact(kFprd, s.station, kSiiControl, st, 2) != 1)
            throw Error(SB() << slave_name(s) << ": no answer while reading the SII EEPROM");
        if (!(st[1] & 0x80)) break;
    }
    if (st[1] & 0x78)
        throw Error(SB() << slave_name(s) << ": SII read error at word " << hex(addr, 4)
                         << " (status " << hex(le16(st), 4) << ")");
    uint8_t d[8] = {};
    if (transact(kFprd, s.station, kSiiData, d, 8) != 1)
        throw Error(SB() << slave_name(s) << ": no answer while reading the SII EEPROM");
    for (int w = 0; w < 4; ++w) {
        if (addr + w >= words.size()) words.resize(addr + w + 1, 0xFFFF);
        words[addr + w] = le16(d + 2 * w);
    }
}

void Master::read_identity(SlaveInfo& s) {
    std::vector<uint16_t> w;
    sii_read4(s, 0x08, w);
    sii_read4(s, 0x0C, w);
    s.sii.vendor = uint32_t(w[0x08]) | uint32_t(w[0x09]) << 16;
    s.sii.product = uint32_t(w[0x0A]) | uint32_t(w[0x0B]) << 16;
    s.sii.revision = uint32_t(w[0x0C]) | uint32_t(w[0x0D]) << 16;
}

void Master::read_sii(SlaveInfo& s) {
    // Reads 4 words at a time (8-byte reads), following the category list to its end.
    std::vector<uint16_t> words;
    for (uint32_t a = 0; a < 0x40; a += 4) sii_read4(s, a, words);
    uint32_t at = 0x40;
    for (int guard = 0; guard < 256; ++guard) { // categories: {type, length in words, data}
        if (at + 1 >= words.size()) sii_read4(s, at, words);
        uint16_t type = words[at];
        if (type == 0xFFFF) break;
        uint32_t len = words[at + 1];
        uint32_t end = at + 2 + len;
        if (end > 0x8000) throw Error(SB() << slave_name(s) << ": SII category at word " << hex(at, 4) << " runs past the EEPROM");
        for (uint32_t a = uint32_t(words.size()) & ~3u; a < end + 2; a += 4) sii_read4(s, a, words);
        at = end;
    }
    s.sii = parse_sii(words);
}

void Master::reserve_default_layout(SlaveInfo& s) const {
    const DeviceDesc* d = catalog_.find(s.type);
    s.sii = parse_sii(build_sii(*d));
    s.pdo_assign = s.sii.pdo_assign;
    s.rx_pdos = s.sii.rx_pdos;
    s.tx_pdos = s.sii.tx_pdos;
    s.pdo_from_coe = false;
    apply_oversampling(s);
}

void Master::apply_oversampling(SlaveInfo& s) const {
    // A terminal without CoE takes its factor from the SM lengths: the master assigns the sample
    // PDOs itself (as IgH does), from the catalog's description of the identity it verified.
    if (s.oversampling <= 1 || s.pdo_from_coe) return;
    DeviceDesc d = catalog_.find(s.type)->with_oversampling(s.oversampling);
    s.pdo_assign = d.pdo_assign;
    s.rx_pdos = d.rx_pdos;
    s.tx_pdos = d.tx_pdos;
}

bool Master::read_al_state(std::size_t i, uint8_t& state, uint16_t& code) {
    uint8_t st[6] = {};
    if (transact(kFprd, slaves_.at(i).station, kAlStatus, st, 6) != 1) return false;
    state = st[0];
    code = le16(st + 4);
    slaves_[i].al_state = st[0];
    slaves_[i].al_status_code = code;
    return true;
}

void Master::request_state(uint8_t state, const char* name) {
    std::vector<std::size_t> all(slaves_.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
    request_state(all, state, name);
}

void Master::to_safe_op() {
    std::vector<std::size_t> which;
    for (std::size_t i = 0; i < slaves_.size(); ++i)
        if (slave_online(i)) which.push_back(i);
    request_state(which, 4, "SAFEOP");
}

void Master::request_state(const std::vector<std::size_t>& which, uint8_t state, const char* name) {
    auto failed = request_state_each(which, state, name);
    if (!failed.empty()) throw Error(failed.front().second);
}

std::vector<std::pair<std::size_t, std::string>> Master::request_state_each(const std::vector<std::size_t>& which,
                                                                            uint8_t state, const char* name) {
    std::vector<std::pair<std::size_t, std::string>> failed;
    std::vector<std::size_t> asked;
    for (std::size_t i : which) {
        auto& s = slaves_[i];
        uint16_t v = state;
        if (transact(kFpwr, s.station, kAlControl, &v, 2) != 1)
            failed.emplace_back(i, SB() << slave_name(s) << ": no answer to the " << name << " request");
        else
            asked.push_back(i);
    }
    for (std::size_t i : asked) {
        uint8_t st = 0;
        uint16_t code = 0;
        bool reached = false, answered = true;
        for (int poll = 0; poll < 50; ++poll) {
            if (!read_al_state(i, st, code)) {
                answered = false;
                break;
            }
            if (st & 0x10) break;
            if ((st & 0x0F) == state) {
                reached = true;
                break;
            }
        }
        if (reached) continue;
        auto& s = slaves_[i];
        if (!answered) {
            failed.emplace_back(i, SB() << slave_name(s) << ": no answer while waiting for " << name);
        } else if (st & 0x10) {
            uint16_t ack = uint16_t((st & 0x0F) | 0x10); // acknowledge, stay where it is
            transact(kFpwr, s.station, kAlControl, &ack, 2);
            failed.emplace_back(i, SB() << slave_name(s) << ": refused " << name << ": AL status code "
                                        << al_code_text(code) << " (state " << state_name(st) << ")");
        } else {
            failed.emplace_back(i, SB() << slave_name(s) << ": did not reach " << name << " (state "
                                        << state_name(st) << ")");
        }
    }
    return failed;
}

void Master::bring_up() {
    slaves_.clear();
    signals_.clear();
    mbx_counter_.clear();
    dc_configured_ = false;
    // 1. Everything to INIT, FMMUs and SMs cleared (broadcast).
    uint16_t init = 0x0011;
    transact(kBwr, 0, kAlControl, &init, 2);
    std::vector<uint8_t> zeros(256, 0);
    transact(kBwr, 0, kFmmu, zeros.data(), 256);
    transact(kBwr, 0, kSm, zeros.data(), 128);
    // 2. Count.
    int found = count_slaves();
    if (found < 0) throw Error(SB() << "ec" << bus_ << ": the " << link_.kind() << " link does not answer");
    int wanted = cfg_.empty() ? 0 : cfg_.back().position + 1;
    if (found < wanted && strict_)
        throw Error(SB() << "ec" << bus_ << ": " << found << " slave(s) on the bus, but the configuration has a slave at position "
                         << cfg_.back().position << " (needs at least " << wanted << ")");
    LOG_INFO(lg, "ec" << bus_ << ": " << found << " slave(s) on the " << link_.kind() << " link");
    // 3. Station addresses for every slave present.
    for (int p = 0; p < found; ++p) {
        uint16_t addr = uint16_t(kStationBase + p);
        if (transact(kApwr, uint16_t(-p), 0x0010, &addr, 2) != 1)
            throw Error(SB() << "ec" << bus_ << ": slave " << p << " did not take its station address");
    }
    // 4. Identity of the configured slaves, then their SII. A slave missing, of another identity
    // or failing a step from here on is left out (strict: refused) with its reason.
    health_.assign(cfg_.size(), SlaveHealth{});
    last_error_.assign(cfg_.size(), std::string());
    retry_at_.assign(cfg_.size(), 0);
    backoff_.assign(cfg_.size(), 1.0);
    std::vector<char> in(cfg_.size(), 0);
    auto leave_out = [&](std::size_t i, SlaveState st, uint32_t id, const std::string& why) {
        if (strict_) throw Error(why);
        in[i] = 0;
        set_health(i, st, id, why);
        LOG_ERR(lg, why << "; starting without it");
    };
    for (std::size_t i = 0; i < cfg_.size(); ++i) {
        const SlaveConfig& c = cfg_[i];
        SlaveInfo s;
        s.position = c.position;
        s.station = uint16_t(kStationBase + c.position);
        s.type = c.type;
        s.oversampling = c.oversampling;
        slaves_.push_back(std::move(s));
        SlaveInfo& si = slaves_.back();
        const DeviceDesc* want = catalog_.find(c.type);
        if (c.position >= found) {
            reserve_default_layout(si);
            leave_out(i, SlaveState::Missing, slave_error::kNotOnline,
                      SB() << "ec" << bus_ << " position " << c.position << ": missing (expected " << c.type
                           << ", vendor " << hex(want->vendor) << ", product " << hex(want->product) << ", revision "
                           << hex(want->revision) << "; " << found << " slave(s) answer)");
            continue;
        }
        try {
            read_sii(si);
            std::string wrong = identity_error(si);
            if (!wrong.empty()) {
                uint16_t none = 0; // not ours: no station address, nothing else written
                transact(kApwr, uint16_t(-c.position), 0x0010, &none, 2);
                reserve_default_layout(si);
                leave_out(i, SlaveState::WrongId, slave_error::kVerificationFail, wrong);
                continue;
            }
            in[i] = 1;
        } catch (const Error& e) {
            reserve_default_layout(si);
            leave_out(i, SlaveState::Error, slave_error::kNotOperational, e.what());
        }
    }
    auto present = [&] {
        std::vector<std::size_t> v;
        for (std::size_t i = 0; i < in.size(); ++i)
            if (in[i]) v.push_back(i);
        return v;
    };
    auto step_each = [&](const std::function<void(std::size_t)>& step, bool before_layout) {
        for (std::size_t i : present()) {
            try {
                step(i);
            } catch (const Error& e) {
                // What it had read may be partial: reserve the default layout, as for a missing one.
                if (before_layout) reserve_default_layout(slaves_[i]);
                leave_out(i, SlaveState::Error, slave_error::kNotOperational, e.what());
            }
        }
    };
    auto transition = [&](uint8_t state, const char* name) {
        for (auto& [i, why] : request_state_each(present(), state, name))
            leave_out(i, SlaveState::Error, slave_error::kNotOperational, why);
    };
    // 5. Mailbox SMs from SII, then PREOP.
    step_each([&](std::size_t i) { configure_mailbox(slaves_[i]); }, true);
    transition(2, "PREOP");
    for (std::size_t i = 0; i < in.size(); ++i)
        if (!in[i] && slaves_[i].rx_pdos.empty() && slaves_[i].tx_pdos.empty()) reserve_default_layout(slaves_[i]);
    // 6. PREOP: startup SDOs (ecmccfg order: before the PDO layout), then the PDO layout, read
    // over CoE where the slave has it.
    step_each([&](std::size_t i) {
        apply_startup_sdos(i);
        read_pdo_layout(slaves_[i]);
    }, true);
    // 7. Process data: layout (every configured slave has its region, present or not), SMs and
    // FMMUs, SAFEOP; valid outputs, then OP.
    layout_process_image();
    step_each([&](std::size_t i) { configure_process_data(i); }, false);
    dc_pending_.clear();
    try {
        configure_dc(present());
    } catch (const Error& e) {
        if (strict_) throw;
        LOG_ERR(lg, e.what());
    }
    for (auto& p : dc_pending_)
        step_each([&](std::size_t i) {
            if (i == p.slave) configure_dc_at(i, &p.t_ref, p.master_ns);
        }, false);
    dc_pending_.clear();
    build_cyclic_frames();
    transition(4, "SAFEOP");
    for (std::size_t i : present()) set_admitted(i, true);
    for (int k = 0; k < 3; ++k) {
        send_process_data();
        receive_process_data();
    }
    transition(8, "OP");
    send_process_data();
    receive_process_data();
    int n_op = 0;
    for (std::size_t i = 0; i < slaves_.size(); ++i) {
        bool ok = in[i] != 0;
        set_admitted(i, ok);
        if (ok) ++n_op;
    }
    // The cycle just run saw them in SAFEOP; start with the states just read.
    send_process_data();
    receive_process_data();
    LOG_INFO(lg, "ec" << bus_ << ": " << n_op << " of " << slaves_.size() << " slave(s) in OP, image " << bus_bytes_
                      << " bytes (" << outputs_bytes_ << " out), expected WKC " << expected_wkc_);
}

void Master::layout_process_image() {
    // Outputs of every slave first, then inputs (SOEM's default layout), byte-aligned per slave.
    uint32_t off = 0;
    auto sm_bytes = [](const SlaveInfo& s, SmType type,
                       std::vector<std::pair<uint8_t, uint32_t>>& out) {
        for (auto& sm : s.sii.sms) {
            if (sm.type != type) continue;
            uint32_t bits = 0;
            for (auto& [smi, pdo] : s.pdo_assign) {
                if (smi != sm.index) continue;
                const auto& list = type == SmType::Outputs ? s.rx_pdos : s.tx_pdos;
                for (auto& p : list)
                    if (p.index == pdo) bits += p.bit_size();
            }
            out.emplace_back(sm.index, (bits + 7) / 8);
        }
    };
    for (auto& s : slaves_) {
        std::vector<std::pair<uint8_t, uint32_t>> v;
        sm_bytes(s, SmType::Outputs, v);
        s.out_offset = off;
        for (auto& [i, b] : v) off += b;
        s.out_bytes = off - s.out_offset;
    }
    outputs_bytes_ = off;
    for (auto& s : slaves_) {
        std::vector<std::pair<uint8_t, uint32_t>> v;
        sm_bytes(s, SmType::Inputs, v);
        s.in_offset = off;
        for (auto& [i, b] : v) off += b;
        s.in_bytes = off - s.in_offset;
    }
    // The slaves' AL status bytes, one per slave, read through an FMMU of each slave in the same
    // LRW: which slaves took part in a cycle, and in which state.
    status_bytes_ = off;
    off += uint32_t(slaves_.size());
    bus_bytes_ = off;
    // After the bus part, the master's own memory (not exchanged on the bus), as ECMC has it:
    // ec<m>.masterstatus and per slave the constant entries ONE (all bits set) and ZERO, which
    // axis configurations use for unused inputs (`ec0.s3.ONE.0`), and `valid` (1 in a cycle in
    // which the slave's data took part, in OP).
    uint32_t mem = (off + 3) / 4 * 4;
    image_.assign(mem + 4 + 12 * slaves_.size(), 0);
    masterstatus_offset_ = mem;
    valid_offset_ = mem + 4;
    signals_.push_back(SignalInfo{SB() << "ec" << bus_ << ".masterstatus", -1, mem * 8, 32, false, "UINT32"});
    for (std::size_t i = 0; i < slaves_.size(); ++i) {
        uint32_t at = mem + 4 + 12 * uint32_t(i);
        std::memset(image_.data() + at, 0xFF, 4);
        std::string pre = SB() << "ec" << bus_ << ".s" << slaves_[i].position << ".";
        signals_.push_back(SignalInfo{pre + "ONE", slaves_[i].position, at * 8, 32, false, "UINT32"});
        signals_.push_back(SignalInfo{pre + "ZERO", slaves_[i].position, (at + 4) * 8, 32, false, "UINT32"});
        signals_.push_back(SignalInfo{pre + "valid", slaves_[i].position, (at + 8) * 8, 32, false, "UINT32"});
    }
    // Signals: every named entry of the assigned PDOs, in PDO order.
    for (auto& s : slaves_) {
        for (int dir = 0; dir < 2; ++dir) {
            bool out = dir == 0;
            uint32_t bit = (out ? s.out_offset : s.in_offset) * 8;
            for (auto& sm : s.sii.sms) {
                if (sm.type != (out ? SmType::Outputs : SmType::Inputs)) continue;
                for (auto& [smi, pdo] : s.pdo_assign) {
                    if (smi != sm.index) continue;
                    for (auto& p : out ? s.rx_pdos : s.tx_pdos) {
                        if (p.index != pdo) continue;
                        for (auto& e : p.entries) {
                            if (!e.name.empty() && e.index != 0)
                                signals_.push_back(SignalInfo{SB() << "ec" << bus_ << ".s" << s.position << "." << e.name,
                                                              s.position, bit, e.bits, out, e.datatype});
                            bit += e.bits;
                        }
                    }
                }
                bit = (bit + 7) / 8 * 8; // each SM starts on a byte
            }
        }
    }
    for (auto& sig : signals_) sig.is_signed = registry::datatype_is_signed(sig.datatype);
}

std::string Master::identity_error(const SlaveInfo& s) const {
    const DeviceDesc* want = catalog_.find(s.type);
    if (s.sii.vendor == want->vendor && s.sii.product == want->product && s.sii.revision == want->revision) return {};
    const DeviceDesc* got = catalog_.find(s.sii.vendor, s.sii.product, s.sii.revision);
    return SB() << "ec" << bus_ << " position " << s.position << ": expected " << s.type << " (vendor "
                << hex(want->vendor) << ", product " << hex(want->product) << ", revision " << hex(want->revision)
                << "), found "
                << (got ? got->type : (s.sii.name.empty() ? std::string("an unknown device") : s.sii.name))
                << " (vendor " << hex(s.sii.vendor) << ", product " << hex(s.sii.product) << ", revision "
                << hex(s.sii.revision) << ")";
}

void Master::check_identity(const SlaveInfo& s) const {
    std::string e = identity_error(s);
    if (!e.empty()) throw Error(e);
}

void Master::configure_mailbox(const SlaveInfo& s) {
    for (auto& sm : s.sii.sms) {
        if (sm.type != SmType::MailboxOut && sm.type != SmType::MailboxIn) continue;
        uint8_t r[8] = {};
        bool out = sm.type == SmType::MailboxOut;
        put_le16(r, out ? s.sii.rx_mbx_offset : s.sii.tx_mbx_offset);
        put_le16(r + 2, out ? s.sii.rx_mbx_size : s.sii.tx_mbx_size);
        r[4] = sm.control;
        r[6] = 1;
        if (transact(kFpwr, s.station, uint16_t(kSm + 8 * sm.index), r, 8) != 1)
            throw Error(SB() << slave_name(s) << ": no answer while configuring mailbox SM" << int(sm.index));
    }
}

void Master::apply_startup_sdos(std::size_t i) {
    for (const StartupSdo& sdo : cfg_[i].sdos) {
        uint8_t b[8];
        put_le64(b, sdo.value);
        sdo_download(slaves_[i].position, sdo.index, sdo.sub, b, sdo.size);
    }
}

void Master::configure_process_data(std::size_t i) {
    const SlaveInfo& s = slaves_[i];
    // SMs first, then every FMMU in one datagram: the slave starts taking part in the cycle (its
    // data and its status byte) in one step, so no cycle sees half of it.
    std::vector<uint8_t> fmmus;
    uint32_t out_off = s.out_offset, in_off = s.in_offset;
    auto add_fmmu = [&](uint32_t logical, uint16_t bytes, uint16_t phys, bool out) {
        uint8_t f[16] = {};
        put_le32(f, logical);
        put_le16(f + 4, bytes);
        f[6] = 0;
        f[7] = 7;
        put_le16(f + 8, phys);
        f[10] = 0;
        f[11] = out ? 2 : 1;
        f[12] = 1;
        fmmus.insert(fmmus.end(), f, f + 16);
    };
    for (auto& sm : s.sii.sms) {
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        bool out = sm.type == SmType::Outputs;
        uint32_t bits = 0;
        for (auto& [smi, pdo] : s.pdo_assign)
            if (smi == sm.index)
                for (auto& p : out ? s.rx_pdos : s.tx_pdos)
                    if (p.index == pdo) bits += p.bit_size();
        uint32_t bytes = (bits + 7) / 8;
        if (bytes == 0) continue;
        if (sm.enable) { // a disabled ("virtual") SM only names registers for the FMMU
            uint8_t r[8] = {};
            put_le16(r, sm.start);
            put_le16(r + 2, uint16_t(bytes));
            r[4] = sm.control;
            r[6] = 1;
            if (transact(kFpwr, s.station, uint16_t(kSm + 8 * sm.index), r, 8) != 1)
                throw Error(SB() << slave_name(s) << ": no answer while configuring SM" << int(sm.index));
        }
        uint32_t& log = out ? out_off : in_off;
        add_fmmu(log, uint16_t(bytes), sm.start, out);
        log += bytes;
    }
    // The status FMMU: AL status (0x0130, low byte) read into the slave's status byte.
    add_fmmu(status_bytes_ + uint32_t(i), 1, kAlStatus, false);
    if (transact(kFpwr, s.station, kFmmu, fmmus.data(), uint16_t(fmmus.size())) != 1)
        throw Error(SB() << slave_name(s) << ": no answer while configuring its FMMUs");
}

void Master::build_cyclic_frames() {
    // One LRW per chunk of the image; chunks packed into as few frames as fit.
    cyclic_.clear();
    expected_wkc_ = 0;
    uint32_t off = 0, total = bus_bytes_;
    cyclic_.emplace_back();
    while (off < total) {
        CyclicFrame* cf = &cyclic_.back();
        std::size_t room = cf->frame.room();
        if (room < 16) {
            cyclic_.emplace_back();
            cf = &cyclic_.back();
            room = cf->frame.room();
        }
        uint32_t len = uint32_t(std::min<std::size_t>(room, total - off));
        int at = cf->frame.add(kLrw, 0, off, uint16_t(len)); // index set per cycle when sent
        cf->parts.push_back({uint32_t(at), off, len});
        off += len;
    }
    if (cyclic_.back().parts.empty()) cyclic_.pop_back();
    // What each slave adds to the working counter when it takes part: per LRW datagram, +2 if its
    // outputs overlap it, +1 if its inputs or its status byte do.
    contrib_.assign(slaves_.size(), 0);
    for (auto& cf : cyclic_)
        for (auto& p : cf.parts)
            for (std::size_t i = 0; i < slaves_.size(); ++i) {
                const SlaveInfo& s = slaves_[i];
                auto overlaps = [&](uint32_t o, uint32_t n) { return n && o < p.image_offset + p.len && o + n > p.image_offset; };
                uint16_t c = 0;
                if (overlaps(s.out_offset, s.out_bytes)) c += 2;
                if (overlaps(s.in_offset, s.in_bytes) || overlaps(status_bytes_ + uint32_t(i), 1)) c += 1;
                contrib_[i] = uint16_t(contrib_[i] + c);
                expected_wkc_ = uint16_t(expected_wkc_ + c);
            }
    // One BRD of AL status (0x0130) per cycle: its working counter is the number of slaves
    // answering, configured or not; a change tells the health pass to look.
    count_frame_ = -1;
    if (cyclic_.empty() || cyclic_.back().frame.room() < 2) cyclic_.emplace_back();
    {
        int at = cyclic_.back().frame.add(kBrd, 0, 0, kAlStatus, 2);
        count_frame_ = int(cyclic_.size() - 1);
        count_offset_ = uint32_t(at);
    }
    // The reference clock's time travels with the cycle (FRMW 0x0910): read at the reference,
    // written to every later slave, which compares it with its own system time.
    dc_frame_ = -1;
    if (dc_ref_ >= 0) {
        if (cyclic_.empty() || cyclic_.back().frame.room() < 8) cyclic_.emplace_back();
        int at = cyclic_.back().frame.add(kFrmw, 0, slaves_[std::size_t(dc_ref_)].station, 0x0910, 8);
        dc_frame_ = int(cyclic_.size() - 1);
        dc_offset_ = uint32_t(at);
    }
    if (cyclic_.size() > kMaxCyclicFrames)
        throw Error(SB() << "ec" << bus_ << ": process image of " << image_.size() << " bytes needs more than "
                         << kMaxCyclicFrames << " frames per cycle");
    std::size_t n = slaves_.size();
    slave_al_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    slave_online_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    valid_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    admit_ = std::make_unique<std::atomic<uint8_t>[]>(n);
    for (std::size_t i = 0; i < n; ++i) {
        slave_al_[i] = 0;
        slave_online_[i] = 0;
        valid_[i] = 0;
        admit_[i] = 0;
    }
    last_stat_.assign(n, 0xFF); // never a status byte: the first cycle walks
    last_consistent_ = -1;
}

void Master::set_admitted(std::size_t i, bool yes) {
    admit_[i].store(yes, std::memory_order_relaxed);
    admit_gen_.fetch_add(1, std::memory_order_release);
}

CycleStatus Master::send_process_data() noexcept {
    CycleStatus st = CycleStatus::Ok;
    seq_ = uint8_t((seq_ + 1) & 0x0F);
    for (std::size_t fi = 0; fi < cyclic_.size(); ++fi) {
        auto& cf = cyclic_[fi];
        uint8_t* f = cf.frame.data();
        uint8_t tag = uint8_t(seq_ << 3 | fi);
        for_each_datagram(f, cf.frame.size(), [&](Datagram& d) { d.hdr[1] = tag; });
        for (auto& p : cf.parts) {
            // The image as it is: outputs, and inputs as last received (a slave absent from this
            // cycle passes them back unchanged: its inputs keep their last values). Status bytes
            // are sent as 0: only a slave that takes part fills its own.
            std::memcpy(f + p.data_offset, image_.data() + p.image_offset, p.len);
            uint32_t st_lo = std::max(p.image_offset, status_bytes_), st_hi = std::min(p.image_offset + p.len, bus_bytes_);
            if (st_lo < st_hi) std::memset(f + p.data_offset + (st_lo - p.image_offset), 0, st_hi - st_lo);
            put_le16(f + p.data_offset + p.len, 0); // WKC
        }
        if (count_frame_ >= 0 && &cf == &cyclic_[std::size_t(count_frame_)]) std::memset(f + count_offset_, 0, 4);
        if (dc_frame_ >= 0 && &cf == &cyclic_[std::size_t(dc_frame_)]) std::memset(f + dc_offset_, 0, 10);
        if (!link_.send(f, cf.frame.size())) st = CycleStatus::LinkError;
    }
    send_ok_.store(st == CycleStatus::Ok, std::memory_order_relaxed);
    if (!acyc_in_flight_ && acyc_req_.pop(acyc_cur_)) {
        acyc_frame_.reset();
        int at = acyc_frame_.add(acyc_cur_.cmd, kAcyclicIdx, acyc_cur_.addr, acyc_cur_.len, acyc_cur_.data);
        if (at >= 0 && link_.send(acyc_frame_.data(), acyc_frame_.size())) {
            acyc_in_flight_ = true;
        } else {
            AcyclicReply r;
            r.wkc = -1;
            acyc_rep_.push(r);
        }
    }
    return st;
}

CycleStatus Master::receive_process_data(int timeout_us) noexcept {
    CycleStatus st = CycleStatus::Ok;
    uint32_t wkc = 0;
    std::size_t got = 0;
    std::size_t expect = cyclic_.size() + (acyc_in_flight_ ? 1 : 0);
    for (std::size_t k = 0, guard = 0; k < expect && guard < expect + 16; ++k, ++guard) {
        std::size_t n = link_.receive(rx_.data(), rx_.size(), timeout_us);
        if (n == 0) {
            if (got < cyclic_.size()) {
                bump(frames_lost_, cyclic_.size() - got);
                st = CycleStatus::FrameLost;
            }
            break;
        }
        // A frame of an earlier cycle that came back after its time-out: too old, drop it.
        if (n >= 2 + kDatagramOverhead) {
            uint8_t idx = rx_[3];
            if (idx != kAcyclicIdx && (idx >> 3 & 0x0F) != seq_) {
                frames_late_++;
                --k;
                continue;
            }
        }
        bool ok = for_each_datagram(rx_.data(), n, [&](Datagram& d) {
            if (d.cmd() == kBrd && d.ado() == kAlStatus && d.len() == 2) {
                responding_.store(d.wkc(), std::memory_order_relaxed);
                return;
            }
            if (d.cmd() == kFrmw && d.ado() == 0x0910 && d.len() == 8) {
                if (d.wkc()) dc_time_.store(le64(d.data), std::memory_order_relaxed);
                return;
            }
            if (d.idx() == kAcyclicIdx && acyc_in_flight_) {
                AcyclicReply r;
                r.wkc = d.wkc();
                std::memcpy(r.data, d.data, std::min<std::size_t>(d.len(), kMaxAcyclic));
                acyc_rep_.push(r);
                acyc_in_flight_ = false;
                return;
            }
            if (d.cmd() != kLrw || (d.idx() & 7) >= cyclic_.size()) return;
            const CyclicFrame& cf = cyclic_[d.idx() & 7];
            for (auto& p : cf.parts) {
                if (d.logical() != p.image_offset || d.len() != p.len) continue;
                wkc += d.wkc();
                // Inputs into the image (never overwrite outputs).
                uint32_t from = std::max(p.image_offset, outputs_bytes_);
                if (from < p.image_offset + p.len)
                    std::memcpy(image_.data() + from, d.data + (from - p.image_offset),
                                p.image_offset + p.len - from);
            }
        });
        if (!ok) {
            bump(frames_lost_, 1);
            st = CycleStatus::FrameLost;
        }
        ++got;
    }
    if (acyc_in_flight_) { // its frame did not come back: the requester retries
        AcyclicReply r;
        r.wkc = -1;
        acyc_rep_.push(r);
        acyc_in_flight_ = false;
    }
    wkc_.store(uint16_t(wkc), std::memory_order_relaxed);
    frames_back_.store(st == CycleStatus::Ok, std::memory_order_relaxed);
    // Which slaves took part (status byte != 0: its status FMMU answered), and the working counter
    // they give: those admitted and in OP must all count (lo); a slave present but not (yet) trusted
    // - joining, in SAFEOP after an error - may or may not count (hi).
    bool consistent = false;
    const uint8_t* stat = image_.data() + status_bytes_;
    const std::size_t n = slaves_.size();
    if (st == CycleStatus::Ok) {
        // The per-slave walk only when a status byte or an admission changed (rare): otherwise
        // the sums of the last walk hold.
        uint32_t gen = admit_gen_.load(std::memory_order_acquire);
        bool changed = gen != admit_seen_ || std::memcmp(stat, last_stat_.data(), n) != 0;
        if (changed) {
            admit_seen_ = gen;
            std::memcpy(last_stat_.data(), stat, n);
            uint32_t lo = 0, extra = 0;
            for (std::size_t i = 0; i < n; ++i) {
                uint8_t b = stat[i];
                slave_online_[i].store(b != 0, std::memory_order_relaxed);
                if (b == 0) continue;
                slave_al_[i].store(b, std::memory_order_relaxed);
                if ((b & 0x1F) == 8 && admit_[i].load(std::memory_order_relaxed)) lo += contrib_[i];
                else extra += contrib_[i];
            }
            wkc_lo_ = lo;
            wkc_hi_ = lo + extra;
        }
        consistent = wkc >= wkc_lo_ && wkc <= wkc_hi_;
        if (!consistent) {
            bump(wkc_errors_, 1);
            st = CycleStatus::WkcMismatch;
        }
        if (!changed && consistent == (last_consistent_ == 1)) {
            cycle_ok_.store(consistent, std::memory_order_relaxed);
            return st; // valid flags, masterstatus as they are
        }
    }
    last_consistent_ = consistent ? 1 : 0;
    cycle_ok_.store(consistent, std::memory_order_relaxed);
    for (std::size_t i = 0; i < n; ++i) {
        uint32_t v = consistent && (stat[i] & 0x1F) == 8 && admit_[i].load(std::memory_order_relaxed) ? 1 : 0;
        valid_[i].store(uint8_t(v), std::memory_order_relaxed);
        std::memcpy(image_.data() + valid_offset_ + 12 * i + 8, &v, 4);
    }
    uint32_t ok = consistent ? 1 : 0;
    std::memcpy(image_.data() + masterstatus_offset_, &ok, 4); // little-endian host, as the bus part
    return st;
}

// ---- CoE -------------------------------------------------------------------------------------

void Master::read_pdo_layout(SlaveInfo& s) {
    s.pdo_assign = s.sii.pdo_assign;
    s.rx_pdos = s.sii.rx_pdos;
    s.tx_pdos = s.sii.tx_pdos;
    s.pdo_from_coe = false;
    if (!(s.sii.protocols & kSiiProtocolCoE) || !s.sii.rx_mbx_size || !s.sii.tx_mbx_size) {
        apply_oversampling(s);
        return;
    }
    auto read = [&](uint16_t index, uint8_t sub, std::size_t min_bytes) {
        std::vector<uint8_t> v = sdo_upload(s.position, index, sub);
        if (v.size() < min_bytes)
            throw Error(SB() << sdo_context(bus_, s.position, "upload", index, sub) << ": "
                             << v.size() << " byte(s), expected " << min_bytes);
        return v;
    };
    std::vector<std::pair<uint8_t, uint16_t>> assign;
    std::vector<Pdo> rx, tx;
    for (const auto& sm : s.sii.sms) {
        if (sm.type != SmType::Outputs && sm.type != SmType::Inputs) continue;
        bool out = sm.type == SmType::Outputs;
        if (sm.is_virtual) { // registers, not a buffer: no CoE assignment object
            for (auto& a : s.sii.pdo_assign)
                if (a.first == sm.index) assign.push_back(a);
            continue;
        }
        uint16_t obj = uint16_t(coe::kObjSmAssignBase + sm.index);
        uint8_t n = 0;
        try {
            n = read(obj, 0, 1)[0];
        } catch (const SdoAbort& e) {
            if (e.code() != coe::kAbortNoObject) throw;
            LOG_WARN(lg, slave_name(s) << ": no PDO assignment object " << object_name(obj, 0)
                                       << ", using the SII PDO layout");
            return;
        }
        for (uint8_t k = 1; k <= n; ++k) {
            uint16_t pdo_index = le16(read(obj, k, 2).data());
            assign.emplace_back(sm.index, pdo_index);
            // The mapping, with names and types from the SII where it describes the same entry.
            const auto& sii_list = out ? s.sii.rx_pdos : s.sii.tx_pdos;
            const Pdo* sii_pdo = nullptr;
            for (auto& p : sii_list)
                if (p.index == pdo_index) sii_pdo = &p;
            Pdo p;
            p.index = pdo_index;
            if (sii_pdo) p.name = sii_pdo->name;
            uint8_t entries = read(pdo_index, 0, 1)[0];
            for (uint8_t e = 1; e <= entries; ++e) {
                uint32_t v = le32(read(pdo_index, e, 4).data());
                PdoEntry pe;
                pe.index = uint16_t(v >> 16);
                pe.sub = uint8_t(v >> 8);
                pe.bits = uint8_t(v);
                if (pe.index != 0) {
                    const PdoEntry* known = nullptr;
                    if (sii_pdo)
                        for (auto& se : sii_pdo->entries)
                            if (se.index == pe.index && se.sub == pe.sub && se.bits == pe.bits)
                                known = &se;
                    if (known) {
                        pe.name = known->name;
                        pe.datatype = known->datatype;
                    } else {
                        std::ostringstream os;
                        os << "entry" << std::hex << std::uppercase << std::setfill('0')
                           << std::setw(4) << pe.index << "_" << std::setw(2) << int(pe.sub);
                        pe.name = os.str();
                        pe.datatype = datatype_for_bits(pe.bits);
                    }
                }
                p.entries.push_back(std::move(pe));
            }
            (out ? rx : tx).push_back(std::move(p));
        }
    }
    // PDOs the slave did not assign keep their SII description.
    for (int dir = 0; dir < 2; ++dir) {
        auto& got = dir == 0 ? rx : tx;
        for (auto& p : dir == 0 ? s.sii.rx_pdos : s.sii.tx_pdos)
            if (std::none_of(got.begin(), got.end(),
                             [&](const Pdo& q) { return q.index == p.index; }))
                got.push_back(p);
    }
    s.pdo_assign = std::move(assign);
    s.rx_pdos = std::move(rx);
    s.tx_pdos = std::move(tx);
    s.pdo_from_coe = true;
}

SlaveInfo& Master::mailbox_slave(int position, const std::string& ctx) {
    for (auto& s : slaves_) {
        if (s.position != position) continue;
        if (!(s.sii.protocols & kSiiProtocolCoE) || !s.sii.rx_mbx_size || !s.sii.tx_mbx_size)
            throw Error(SB() << ctx << ": " << s.type << " has no CoE mailbox");
        return s;
    }
    throw Error(SB() << ctx
                     << ": no configured slave at this position (or bring-up did not reach it)");
}

bool Master::mailbox_in_full(const SlaveInfo& s, const std::string& ctx) {
    uint8_t sm_in = 1;
    for (auto& sm : s.sii.sms)
        if (sm.type == SmType::MailboxIn) sm_in = sm.index;
    uint8_t status = 0;
    if (transact(kFprd, s.station, uint16_t(kSm + 8 * sm_in + 5), &status, 1) != 1)
        throw Error(SB() << ctx << ": no answer while polling the mailbox");
    return status & 0x08;
}

bool Master::read_mailbox(const SlaveInfo& s, std::vector<uint8_t>& buf, const std::string& ctx) {
    buf.assign(s.sii.tx_mbx_size, 0);
    int wkc = transact(kFprd, s.station, s.sii.tx_mbx_offset, buf.data(), uint16_t(buf.size()));
    if (wkc < 0) throw Error(SB() << ctx << ": no answer while reading the mailbox");
    return wkc == 1;
}

std::vector<uint8_t> Master::sdo_exchange(SlaveInfo& s, const uint8_t* coe_data, std::size_t len,
                                          const std::string& ctx) {
    if (coe::kMailboxHeader + len > s.sii.rx_mbx_size)
        throw Error(SB() << ctx << ": a request of " << len << " bytes does not fit the "
                         << s.sii.rx_mbx_size
                         << "-byte mailbox (segmented transfers are not supported)");
    uint16_t index = le16(coe_data + 3);
    uint8_t sub = coe_data[5];
    uint8_t& counter = mbx_counter_[s.position];
    counter = uint8_t(counter % 7 + 1); // 1..7; a slave ignores a repeated counter
    std::vector<uint8_t> out(s.sii.rx_mbx_size, 0), in;
    put_le16(out.data(), uint16_t(len));
    put_le16(out.data() + 2, 0); // address: the master
    out[4] = 0;                  // channel 0, priority 0
    out[5] = uint8_t(coe::kMbxCoE | counter << 4);
    std::memcpy(out.data() + coe::kMailboxHeader, coe_data, len);

    // The reply to this request, or nothing if `in` holds something else (a stale reply).
    auto match = [&](const std::vector<uint8_t>& mb) -> bool {
        uint16_t mlen = le16(mb.data());
        if (mlen + coe::kMailboxHeader > mb.size()) return false;
        uint8_t type = mb[5] & 0x0F;
        if (type == coe::kMbxError && mlen >= 4) {
            uint16_t detail = le16(mb.data() + coe::kMailboxHeader + 2);
            throw Error(SB() << ctx << ": mailbox error 0x" << std::hex << std::setw(4)
                             << std::setfill('0') << detail << " "
                             << coe::mailbox_error_text(detail));
        }
        if (type != coe::kMbxCoE || mlen < coe::kCoeHeader + coe::kSdoHeader) return false;
        const uint8_t* c = mb.data() + coe::kMailboxHeader;
        uint8_t service = uint8_t(le16(c) >> 12);
        if (le16(c + 3) != index || c[5] != sub) return false;
        if (service == coe::kCoeSdoRequest && c[2] == coe::kSdoAbort) {
            uint32_t code = le32(c + 6);
            throw SdoAbort(SB() << ctx << " aborted: " << hex(code) << " " << coe::abort_text(code),
                           code);
        }
        return service == coe::kCoeSdoResponse;
    };
    auto reply = [&] {
        uint16_t mlen = le16(in.data());
        return std::vector<uint8_t>(in.begin() + coe::kMailboxHeader,
                                    in.begin() + coe::kMailboxHeader + mlen);
    };

    // Empty the slave->master mailbox of anything left from earlier requests.
    for (int i = 0; i < 8 && mailbox_in_full(s, ctx); ++i) read_mailbox(s, in, ctx);
    // Write the request. A full mailbox (WKC 0) means the slave has not taken an earlier request:
    // read what it answered meanwhile (perhaps this very request, if only the reply frame was
    // lost) and try again.
    bool written = false;
    for (int attempt = 0; attempt < 8 && !written; ++attempt) {
        std::vector<uint8_t> tx = out;
        int wkc = transact(kFpwr, s.station, s.sii.rx_mbx_offset, tx.data(), uint16_t(tx.size()));
        if (wkc < 0) throw Error(SB() << ctx << ": no answer while writing the mailbox");
        written = wkc == 1;
        if (!written && mailbox_in_full(s, ctx) && read_mailbox(s, in, ctx) && match(in))
            return reply();
    }
    if (!written)
        throw Error(SB() << ctx << ": the slave's mailbox stays full (it does not read requests)");
    // Poll the mailbox status until the reply is there.
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(sdo_timeout_ms_);
    for (int poll = 0;; ++poll) {
        if (mailbox_in_full(s, ctx) && read_mailbox(s, in, ctx) && match(in)) return reply();
        if (std::chrono::steady_clock::now() > deadline)
            throw Error(SB() << ctx << ": no reply within " << sdo_timeout_ms_ << " ms");
        if (poll >= 10) std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
}

std::vector<uint8_t> Master::sdo_upload(int position, uint16_t index, uint8_t sub) {
    std::string ctx = sdo_context(bus_, position, "upload", index, sub);
    SlaveInfo& s = mailbox_slave(position, ctx);
    uint8_t req[coe::kCoeHeader + coe::kSdoHeader] = {};
    put_le16(req, uint16_t(coe::kCoeSdoRequest << 12));
    req[2] = coe::kSdoUploadRequest;
    put_le16(req + 3, index);
    req[5] = sub;
    std::vector<uint8_t> r = sdo_exchange(s, req, sizeof req, ctx);
    const uint8_t* sdo = r.data() + coe::kCoeHeader;
    uint8_t cmd = sdo[0];
    if (cmd >> 5 != 2)
        throw Error(SB() << ctx << ": unexpected SDO response command " << hex(cmd, 2));
    if (cmd & 0x02) { // expedited: 1..4 bytes in the header
        std::size_t n = (cmd & 0x01) ? 4 - (cmd >> 2 & 3) : 4;
        return std::vector<uint8_t>(sdo + 4, sdo + 4 + n);
    }
    uint32_t size = le32(sdo + 4);
    std::size_t have = r.size() - coe::kCoeHeader - coe::kSdoHeader;
    if (size > have)
        throw Error(SB() << ctx << ": the object has " << size << " bytes, more than one mailbox "
                         << "carries (segmented transfers are not supported)");
    return std::vector<uint8_t>(sdo + coe::kSdoHeader, sdo + coe::kSdoHeader + size);
}

void Master::sdo_download(int position, uint16_t index, uint8_t sub, const void* data,
                          std::size_t len) {
    std::string ctx = sdo_context(bus_, position, "download", index, sub);
    if (len == 0) throw Error(SB() << ctx << ": no data to write");
    SlaveInfo& s = mailbox_slave(position, ctx);
    std::vector<uint8_t> req(coe::kCoeHeader + coe::kSdoHeader + (len > 4 ? len : 0), 0);
    put_le16(req.data(), uint16_t(coe::kCoeSdoRequest << 12));
    uint8_t* sdo = req.data() + coe::kCoeHeader;
    put_le16(sdo + 1, index);
    sdo[3] = sub;
    if (len <= 4) {
        sdo[0] = uint8_t(coe::kSdoDownloadExpedited | (4 - len) << 2);
        std::memcpy(sdo + 4, data, len);
    } else {
        sdo[0] = coe::kSdoDownloadNormal;
        put_le32(sdo + 4, uint32_t(len));
        std::memcpy(sdo + coe::kSdoHeader, data, len);
    }
    std::vector<uint8_t> r = sdo_exchange(s, req.data(), req.size(), ctx);
    uint8_t cmd = r[coe::kCoeHeader];
    if (cmd >> 5 != 3)
        throw Error(SB() << ctx << ": unexpected SDO response command " << hex(cmd, 2));
}

const SignalInfo* Master::find_signal(std::string_view name) const {
    for (auto& s : signals_)
        if (s.name == name) return &s;
    return nullptr;
}

registry::BoundSignal Master::bind(std::string_view name, int bit) {
    const SignalInfo* s = find_signal(name);
    if (!s || (bit >= 0 && bit >= s->bits)) return {};
    return registry::BoundSignal{image_.data(), s->bit_offset, s->bits, s->is_signed, bit};
}

uint64_t Master::get(const SignalInfo& s) const { return registry::image_read(image_.data(), s.bit_offset, s.bits); }

void Master::set(const SignalInfo& s, uint64_t v) { registry::image_write(image_.data(), s.bit_offset, s.bits, v); }

} // namespace beamctl::ethercat

// ---- while cycling ---------------------------------------------------------------------------

namespace beamctl::ethercat {

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
    if (s.sii.dc_assign_activate) configure_dc_slave(i);
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

namespace beamctl::ethercat {

namespace {
uint64_t master_time_ns() { // [ns] since the EtherCAT epoch 2000-01-01, from the system clock
    auto t = std::chrono::system_clock::now().time_since_epoch();
    return uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(t).count()) - 946684800ull * 1000000000ull;
}
} // namespace

void Master::configure_dc(const std::vector<std::size_t>& which) {
    // Minimal distributed clocks (ethercat.md §4): the reference is the first configured slave with
    // DC (its cyclic FRMW 0x0910 is in the frame even while it is absent); each DC slave present
    // gets its delay, offset and SYNC0 in configure_dc_slave().
    dc_ref_ = -1;
    int n = 0;
    for (std::size_t i = 0; i < slaves_.size(); ++i)
        if (slaves_[i].sii.dc_assign_activate) {
            if (dc_ref_ < 0) dc_ref_ = int(i);
            n += std::count(which.begin(), which.end(), i) ? 1 : 0;
        }
    // One latch and one master timestamp for all of them, delays from the first present.
    std::vector<std::size_t> dc;
    for (std::size_t i : which)
        if (slaves_[i].sii.dc_assign_activate) dc.push_back(i);
    if (!dc.empty()) {
        uint32_t latch = 0;
        if (transact(kBwr, 0, 0x0900, &latch, 4) < 1) throw Error(SB() << "ec" << bus_ << ": DC receive-time latch got no answer");
        uint64_t master_ns = master_time_ns();
        uint8_t rr[4] = {};
        if (transact(kFprd, slaves_[dc.front()].station, 0x0900, rr, 4) != 1)
            throw Error(SB() << slave_name(slaves_[dc.front()]) << ": no answer reading DC receive times");
        uint32_t t_ref = le32(rr);
        for (std::size_t i : dc) dc_pending_.push_back({i, t_ref, master_ns});
    }
    if (dc_ref_ >= 0)
        LOG_INFO(lg, "ec" << bus_ << ": distributed clocks on " << n << " slave(s), reference "
                          << slave_name(slaves_[std::size_t(dc_ref_)]) << ", SYNC0 every " << cycle_ns_ << " ns");
}

void Master::configure_dc_slave(std::size_t i) {
    // Receive times latched on every slave (harmless to those running); the delay from the
    // reference (from the slave itself if the reference does not answer).
    uint32_t latch = 0;
    if (transact(kBwr, 0, 0x0900, &latch, 4) < 1) throw Error(SB() << "ec" << bus_ << ": DC receive-time latch got no answer");
    uint64_t master_ns = master_time_ns();
    uint32_t t_ref = 0;
    bool have_ref = false;
    if (dc_ref_ >= 0 && std::size_t(dc_ref_) != i) {
        uint8_t rr[4] = {};
        if (transact(kFprd, slaves_[std::size_t(dc_ref_)].station, 0x0900, rr, 4) == 1) {
            t_ref = le32(rr);
            have_ref = true;
        }
    }
    configure_dc_at(i, have_ref ? &t_ref : nullptr, master_ns);
}

void Master::configure_dc_at(std::size_t i, const uint32_t* t_ref, uint64_t master_ns) {
    // Delay (line topology), offset so its system time is the master's time at the latch, SYNC0 at
    // the cycle time starting 100 ms ahead on a cycle boundary.
    SlaveInfo& s = slaves_[i];
    uint8_t rt[4] = {};
    if (transact(kFprd, s.station, 0x0900, rt, 4) != 1)
        throw Error(SB() << slave_name(s) << ": no answer reading DC receive times");
    uint32_t t0 = le32(rt);
    uint32_t d = t_ref ? t0 - *t_ref : 0;
    uint8_t delay[4];
    put_le32(delay, d);
    uint8_t local[8] = {};
    if (transact(kFprd, s.station, 0x0918, local, 8) != 1 || transact(kFpwr, s.station, 0x0928, delay, 4) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring DC delay");
    uint8_t offset[8]; // system time = master time, seen through this slave's delay
    put_le64(offset, master_ns + d - le64(local));
    if (transact(kFpwr, s.station, 0x0920, offset, 8) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring DC offset");
    uint16_t aa = s.sii.dc_assign_activate;
    uint16_t off = 0;
    // An oversampling terminal takes n samples per cycle: SYNC0 every cycle/n, SYNC1 the rest of
    // the cycle (ecmccfg's ecmcEL3702.cmd).
    uint32_t sync0 = uint32_t(cycle_ns_ / std::max(s.oversampling, 1u));
    uint8_t cyc[8];
    put_le32(cyc, sync0);
    put_le32(cyc + 4, s.oversampling > 1 ? uint32_t(cycle_ns_) - sync0 : 0);
    uint8_t st[8] = {};
    transact(kFprd, s.station, 0x0910, st, 8);
    uint64_t start = (le64(st) + 100'000'000ull) / cycle_ns_ * cycle_ns_;
    uint8_t start_b[8];
    put_le64(start_b, start);
    uint8_t act[2] = {uint8_t(aa), uint8_t(aa >> 8)};
    if (transact(kFpwr, s.station, 0x0980, &off, 2) != 1 || transact(kFpwr, s.station, 0x09A0, cyc, s.oversampling > 1 ? 8 : 4) != 1 ||
        transact(kFpwr, s.station, 0x0990, start_b, 8) != 1 || transact(kFpwr, s.station, 0x0980, act, 2) != 1)
        throw Error(SB() << slave_name(s) << ": no answer configuring SYNC0");
}

} // namespace beamctl::ethercat
