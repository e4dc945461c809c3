// EtherCAT master, bring-up: from INIT to OP (identity, mailbox, start-up SDOs, PDO layout,
// process image, SMs and FMMUs), and the layout a slave absent at start gets reserved.
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
    for (auto& sig : signals_) {
        sig.is_signed = registry::datatype_is_signed(sig.datatype);
        sig.real = registry::datatype_float_bits(sig.datatype);
    }
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


} // namespace beamctl::ethercat
