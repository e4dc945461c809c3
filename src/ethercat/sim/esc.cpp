#include "ethercat/sim/esc.hpp"

#include "ethercat/coe.hpp"
#include "ethercat/sii.hpp"

#include <algorithm>
#include <cstring>

namespace beamctl::ethercat::sim {
namespace {

bool writable(uint32_t a) {
    if (a >= 0x1000) return true;
    if (a < 0x0010) return false;                  // type, revision, build, features
    if (a >= 0x0110 && a < 0x0120) return false;   // DL status
    if (a >= 0x0130 && a < 0x0140) return false;   // AL status and code
    if (a >= 0x0440 && a < 0x0444) return false;   // watchdog status
    if (a >= 0x0800 && a < 0x0880 && (a & 7) == 5) return false; // SM status
    if (a >= 0x0508 && a < 0x0510) return false;   // SII data (read by the master)
    return true;
}

// Copies `bits` bits from src (starting at bit sb) to dst (starting at bit db).
void copy_bits(const uint8_t* src, uint32_t sb, uint8_t* dst, uint32_t db, uint32_t bits) {
    if ((sb & 7) == 0 && (db & 7) == 0 && (bits & 7) == 0) {
        std::memcpy(dst + db / 8, src + sb / 8, bits / 8);
        return;
    }
    for (uint32_t i = 0; i < bits; ++i) {
        uint32_t s = sb + i, d = db + i;
        bool v = src[s >> 3] >> (s & 7) & 1;
        if (v) dst[d >> 3] |= uint8_t(1u << (d & 7));
        else dst[d >> 3] &= uint8_t(~(1u << (d & 7)));
    }
}

constexpr uint8_t kSmStatusMailboxFull = 0x08;

// Register block of SM n if it is an enabled mailbox SM, else nullptr.
uint8_t* mailbox_sm(std::array<uint8_t, 65536>& mem, int n) {
    uint8_t* r = &mem[reg::kSm + 8 * n];
    return (r[6] & 1) && (r[4] & 3) == 2 && le16(r + 2) ? r : nullptr;
}

} // namespace

Esc::~Esc() = default;

Esc::Esc(const DeviceDesc& desc, std::vector<uint16_t> sii) : desc_(desc), sii_(std::move(sii)) {
    mem_[reg::kType] = 0x11; // ET1100-like
    mem_[reg::kFmmuCount] = 8;
    mem_[reg::kSmCount] = 8;
    mem_[reg::kRamSize] = 60;
    put_le16(&mem_[reg::kFeatures], desc_.dc_assign_activate ? 0x000C : 0x0000);
    if (sii_.size() > 4) put_le16(&mem_[reg::kAlias], sii_[4]);
    put_le16(&mem_[reg::kDlStatus], 0x0230); // link and loop on port 0 (topology: a line)
    mem_[reg::kAlStatus] = kInit;
    put_le16(&mem_[reg::kWdDivider], 2498);
    put_le16(&mem_[reg::kWdProcessData], 1000);
    put_le16(&mem_[reg::kSiiControl], 0x0040); // 8-byte reads
    for (const auto& s : desc_.sms) {
        if (s.type == SmType::MailboxOut) mbx_out_ = s.index;
        if (s.type == SmType::MailboxIn) mbx_in_ = s.index;
    }
    if (desc_.oversampling.max > 0 && !desc_.coe)
        for (unsigned k = 1; k <= desc_.oversampling.max; ++k) {
            DeviceDesc d = desc_.with_oversampling(k);
            std::vector<uint32_t> bytes(desc_.sms.size(), 0);
            for (const auto& sm : desc_.sms) bytes[sm.index] = d.sm_bytes(sm.index);
            os_sm_bytes_.push_back(std::move(bytes));
        }
    if (desc_.coe && mbx_out_ >= 0 && mbx_in_ >= 0) {
        uint32_t serial = 0;
        if (sii_.size() > kSiiSerialWord + 1)
            serial = uint32_t(sii_[kSiiSerialWord]) | uint32_t(sii_[kSiiSerialWord + 1]) << 16;
        coe_ = std::make_unique<CoeServer>(desc_, serial);
    }
}

uint32_t Esc::expected_sm_bytes(uint8_t sm) const {
    return coe_ ? coe_->sm_bytes(sm) : desc_.sm_bytes(sm);
}

uint8_t* Esc::sm_buffer(uint8_t sm) {
    uint16_t start = le16(&mem_[reg::kSm + 8 * sm]);
    if (!start)
        for (auto& s : desc_.sms)
            if (s.index == sm) start = s.start;
    return &mem_[start];
}

uint16_t Esc::sm_length(uint8_t sm) const {
    uint16_t len = le16(&mem_[reg::kSm + 8 * sm + 2]);
    return len ? len : uint16_t(expected_sm_bytes(sm));
}

bool Esc::read_phys(uint16_t ado, uint8_t* data, uint16_t len) noexcept {
    uint32_t end = uint32_t(ado) + len;
    uint8_t emptied = 0; // slave->master mailboxes whose last byte this read takes
    for (int n = 0; n < 8; ++n) {
        uint8_t* r = mailbox_sm(mem_, n);
        if (!r) continue;
        uint32_t s = le16(r), l = le16(r + 2);
        if (end <= s || ado >= s + l || (r[4] >> 2 & 3) != 0) continue; // ECAT-read mailboxes only
        if (!(r[5] & kSmStatusMailboxFull)) return false; // nothing to read: no access
        if (ado <= s + l - 1 && end > s + l - 1) emptied |= uint8_t(1u << n);
    }
    if (ado <= reg::kDcSystemTime + 7 && end > reg::kDcSystemTime) {
        uint64_t offset = le64(&mem_[reg::kDcOffset]);
        put_le64(&mem_[reg::kDcSystemTime], local_time_ns_ + hop_delay_ns_ + offset); // as the frame passes
    }
    for (uint32_t i = 0; i < len; ++i) data[i] = mem_[(ado + i) & 0xFFFF];
    for (int n = 0; n < 8; ++n)
        if (emptied >> n & 1) mem_[reg::kSm + 8 * n + 5] &= uint8_t(~kSmStatusMailboxFull);
    return true;
}

bool Esc::write_phys(uint16_t ado, const uint8_t* data, uint16_t len) noexcept {
    uint32_t end = uint32_t(ado) + len;
    uint8_t filled = 0; // master->slave mailboxes whose last byte this write covers
    // Sync-manager buffers live in process RAM (0x1000 and up): register writes skip this check.
    for (int n = 0; end > 0x1000 && n < 8; ++n) {
        uint8_t* r = mailbox_sm(mem_, n);
        if (!r) continue;
        uint32_t s = le16(r), l = le16(r + 2);
        if (end <= s || ado >= s + l) continue;
        if ((r[4] >> 2 & 3) != 1 || (r[5] & kSmStatusMailboxFull)) { // read mailbox, or full
            ++mailbox_rejected_writes;
            return false;
        }
        if (ado <= s + l - 1 && end > s + l - 1) filled |= uint8_t(1u << n);
    }
    if (ado >= 0x1000 && end <= 0x10000) { // process RAM only: no register side effects
        std::memcpy(&mem_[ado], data, len);
        for (int n = 0; filled && n < 8; ++n)
            if (filled >> n & 1) mem_[reg::kSm + 8 * n + 5] |= kSmStatusMailboxFull;
        return true;
    }
    bool al = false, sii = false, latch = false, systime = false;
    uint8_t sm_written = 0;
    for (uint32_t i = 0; i < len; ++i) {
        uint32_t a = (ado + i) & 0xFFFF;
        if (!writable(a)) continue;
        mem_[a] = data[i];
        if (a >= reg::kSm && a < reg::kSm + 8 * 8)
            sm_written |= uint8_t(1u << ((a - reg::kSm) / 8));
        if (a == reg::kAlControl) al = true;
        if (a == reg::kSiiControl + 1) sii = true;
        if (a >= reg::kDcRecvTime && a < reg::kDcRecvTime + 4) latch = true;
        if (a == reg::kDcSystemTime) systime = true;
    }
    if (systime && len >= 4) {
        // The reference clock's time arrives (FRMW/ARMW): the difference to this slave's own
        // system time, compensated by its delay, is what its drift control would act on.
        uint64_t written = le64(&mem_[reg::kDcSystemTime]);
        int64_t own = int64_t(system_time() + hop_delay_ns_); // when the frame passes here
        int64_t diff = int64_t(written + le32(&mem_[reg::kDcDelay])) - own;
        uint32_t mag = uint32_t(std::min<int64_t>(diff < 0 ? -diff : diff, 0x7FFFFFFF));
        put_le32(&mem_[reg::kDcDiff], mag | (diff < 0 ? 0x80000000u : 0));
        system_time_diff_ns = diff;
    }
    if (latch) { // a write to 0x0900 latches the receive time of every port
        uint64_t t = local_time_ns_ + hop_delay_ns_;
        for (int p = 0; p < 4; ++p) put_le32(&mem_[reg::kDcRecvTime + 4 * p], uint32_t(t));
        put_le64(&mem_[reg::kDcRecvTimeEpu], t);
    }
    for (int n = 0; (filled | sm_written) && n < 8; ++n) {
        uint8_t* r = &mem_[reg::kSm + 8 * n];
        if (filled >> n & 1) r[5] |= kSmStatusMailboxFull;
        if ((sm_written >> n & 1) && !(r[6] & 1)) { // a disabled SM forgets its buffer state
            r[5] &= uint8_t(~kSmStatusMailboxFull);
            if (n == mbx_out_) last_counter_ = 0;
        }
    }
    if (sii) sii_command();
    if (al) al_control_written();
    return true;
}

bool Esc::logical(Datagram& d, bool read, bool write, uint16_t& wkc) noexcept {
    uint32_t da = d.logical();
    uint32_t dlen = d.len();
    bool did_read = false, did_write = false;
    for (int n = 0; n < 8; ++n) {
        const uint8_t* f = &mem_[reg::kFmmu + 16 * n];
        if (!(f[12] & 1)) continue;
        uint8_t type = f[11];
        bool fr = type & 1, fw = type & 2;
        if (!((fr && read) || (fw && write))) continue;
        uint32_t ls = le32(f), flen = le16(f + 4);
        if (!flen) continue;
        uint32_t start_bit = f[6] & 7, stop_bit = f[7] & 7;
        uint32_t log_first = ls * 8 + start_bit;             // first logical bit
        uint32_t log_last = (ls + flen - 1) * 8 + stop_bit;  // last logical bit
        uint32_t dg_first = da * 8, dg_last = (da + dlen) * 8 - 1;
        uint32_t lo = std::max(log_first, dg_first), hi = std::min(log_last, dg_last);
        if (lo > hi || dlen == 0) continue;
        uint32_t phys_bit = uint32_t(le16(f + 8)) * 8 + (f[10] & 7) + (lo - log_first);
        uint32_t bits = hi - lo + 1;
        uint32_t frame_bit = lo - dg_first;
        if (fr && read) {
            copy_bits(mem_.data(), phys_bit, d.data, frame_bit, bits);
            did_read = true;
        }
        if (fw && write) {
            copy_bits(d.data, frame_bit, mem_.data(), phys_bit, bits);
            did_write = true;
            last_output_ns_ = local_time_ns_;
        }
    }
    if (did_read) wkc += 1;
    if (did_write) {
        wkc += 2;
        output_writes++;
    }
    return did_read || did_write;
}

void Esc::process(Datagram& d) noexcept {
    uint16_t wkc = 0;
    uint16_t len = d.len();
    uint8_t tmp[kMaxDatagramData];
    switch (d.cmd()) {
    case kAprd:
    case kApwr:
    case kAprw:
    case kArmw: {
        bool me = d.adp() == 0;
        if (d.cmd() == kArmw) {
            wkc = (me ? read_phys(d.ado(), d.data, len) : write_phys(d.ado(), d.data, len)) ? 1 : 0;
        } else if (me) {
            if (d.cmd() == kAprd)
                wkc = read_phys(d.ado(), d.data, len) ? 1 : 0;
            else if (d.cmd() == kApwr)
                wkc = write_phys(d.ado(), d.data, len) ? 1 : 0;
            else
                wkc = read_write(d.ado(), d.data, len, tmp);
        }
        d.set_adp(uint16_t(d.adp() + 1));
        break;
    }
    case kFprd:
    case kFpwr:
    case kFprw:
    case kFrmw: {
        uint16_t adp = d.adp();
        bool me = adp == station_address() && adp != 0;
        if (d.cmd() == kFrmw) {
            wkc = (me ? read_phys(d.ado(), d.data, len) : write_phys(d.ado(), d.data, len)) ? 1 : 0;
        } else if (me) {
            if (d.cmd() == kFprd)
                wkc = read_phys(d.ado(), d.data, len) ? 1 : 0;
            else if (d.cmd() == kFpwr) {
                wkc = write_phys(d.ado(), d.data, len) ? 1 : 0;
                if (wkc && d.ado() == reg::kDcSystemTime && len == 8) ++system_time_writes; // a time set for it alone
            }
            else
                wkc = read_write(d.ado(), d.data, len, tmp);
        }
        break;
    }
    case kBrd:
        if (read_phys(d.ado(), tmp, len)) {
            for (uint16_t i = 0; i < len; ++i) d.data[i] |= tmp[i];
            wkc = 1;
        }
        d.set_adp(uint16_t(d.adp() + 1));
        break;
    case kBwr:
        wkc = write_phys(d.ado(), d.data, len) ? 1 : 0;
        d.set_adp(uint16_t(d.adp() + 1));
        break;
    case kBrw: {
        bool r = read_phys(d.ado(), tmp, len);
        wkc = (r ? 1 : 0) + (write_phys(d.ado(), d.data, len) ? 2 : 0);
        if (r)
            for (uint16_t i = 0; i < len; ++i) d.data[i] |= tmp[i];
        d.set_adp(uint16_t(d.adp() + 1));
        break;
    }
    case kLrd: logical(d, true, false, wkc); break;
    case kLwr: logical(d, false, true, wkc); break;
    case kLrw: logical(d, true, true, wkc); break;
    default: break; // NOP and unknown commands pass untouched
    }
    if (wkc) d.add_wkc(wkc);
}

uint16_t Esc::read_write(uint16_t ado, uint8_t* data, uint16_t len, uint8_t* tmp) noexcept {
    bool r = read_phys(ado, tmp, len);
    bool w = write_phys(ado, data, len);
    if (r) std::memcpy(data, tmp, len);
    return uint16_t((r ? 1 : 0) + (w ? 2 : 0));
}

void Esc::run_firmware() noexcept {
    check_watchdog();
    if (mbx_out_ < 0 || mbx_in_ < 0) return;
    const uint8_t* r0 = &mem_[reg::kSm + 8 * mbx_out_];
    const uint8_t* r1 = &mem_[reg::kSm + 8 * mbx_in_];
    if (!(r0[5] & kSmStatusMailboxFull)) return;                              // no request
    if (al_state() == kInit) return;                                          // mailbox not running
    if (!mailbox_sm(mem_, mbx_in_) || (r1[5] & kSmStatusMailboxFull)) return; // no room to reply
    try {
        serve_mailbox(uint8_t(mbx_out_), uint8_t(mbx_in_));
    } catch (...) { // out of memory: the request is lost, as on a slave that ran out of buffers
    }
}

void Esc::serve_mailbox(uint8_t sm_out, uint8_t sm_in) {
    uint8_t* r0 = &mem_[reg::kSm + 8 * sm_out];
    uint8_t* r1 = &mem_[reg::kSm + 8 * sm_in];
    uint32_t in_start = le16(r0), in_len = std::min<uint32_t>(le16(r0 + 2), 65536 - in_start);
    uint32_t out_start = le16(r1), out_len = std::min<uint32_t>(le16(r1 + 2), 65536 - out_start);
    std::vector<uint8_t> req(mem_.begin() + in_start, mem_.begin() + in_start + in_len);
    r0[5] &= uint8_t(~kSmStatusMailboxFull); // the PDI read the request: the master may write again
    ++mailbox_requests;
    if (req.size() < coe::kMailboxHeader || out_len < coe::kMailboxHeader + 4) return;
    uint16_t mlen = le16(req.data());
    uint8_t type = req[5] & 0x0F, counter = req[5] >> 4 & 7;
    if (counter != 0 && counter == last_counter_) return; // a repeated request: served already
    last_counter_ = counter;
    std::vector<uint8_t> reply(out_len, 0);
    std::size_t n = 0;
    uint16_t err = 0;
    if (coe::kMailboxHeader + mlen > req.size())
        err = coe::kMbxErrInvalidSize;
    else if (type == coe::kMbxCoE && coe_)
        n = coe_->handle(req.data() + coe::kMailboxHeader, mlen, reply.data() + coe::kMailboxHeader,
                         out_len - coe::kMailboxHeader, al_state(), err);
    else
        err = coe::kMbxErrUnsupportedProtocol;
    if (n == 0 && err == 0) return;
    uint8_t reply_type = coe::kMbxCoE;
    if (n == 0) { // mailbox error reply: service 1, detail
        reply_type = coe::kMbxError;
        put_le16(reply.data() + coe::kMailboxHeader, 0x0001);
        put_le16(reply.data() + coe::kMailboxHeader + 2, err);
        n = 4;
    }
    reply_counter_ = uint8_t(reply_counter_ % 7 + 1);
    put_le16(reply.data(), uint16_t(n));
    put_le16(reply.data() + 2, 0); // address: the master
    reply[4] = 0;                  // channel 0, priority 0
    reply[5] = uint8_t(reply_type | reply_counter_ << 4);
    std::memcpy(&mem_[out_start], reply.data(), out_len);
    r1[5] |= kSmStatusMailboxFull;
}

void Esc::sii_command() noexcept {
    uint16_t ctl = le16(&mem_[reg::kSiiControl]);
    uint16_t cmd = (ctl >> 8) & 7;
    ctl &= 0x00FF | 0x0040;
    ctl &= uint16_t(~0x7800); // clear error bits
    if (cmd == 1) { // read: 4 words (8-byte reads supported)
        uint32_t addr = le32(&mem_[reg::kSiiAddress]);
        bool ok = addr < sii_.size();
        for (int w = 0; w < 4; ++w) {
            uint32_t a = addr + w;
            put_le16(&mem_[reg::kSiiData + 2 * w], a < sii_.size() ? sii_[a] : 0xFFFF);
        }
        if (!ok) ctl |= 0x2000; // missing acknowledge / address error
    } else if (cmd != 0) {
        ctl |= 0x2000; // writes and reloads are not supported by the simulated EEPROM
    }
    put_le16(&mem_[reg::kSiiControl], ctl | 0x0040); // never busy: the command completed
}

void Esc::check_watchdog() noexcept {
    // SM watchdog (ethercat.md §3): in OP, an output SM with its watchdog enabled (control bit 6)
    // that receives no data for divider x time (0x0400 x 0x0420 x 40 ns; 100 ms by default)
    // takes the slave to SAFEOP with error 0x001B.
    if (al_state() != kOp) return;
    uint64_t wd_ns = uint64_t(le16(&mem_[reg::kWdDivider]) + 2) * 40 * le16(&mem_[reg::kWdProcessData]);
    if (wd_ns == 0 || local_time_ns_ < last_output_ns_ + wd_ns) return;
    for (int n = 0; n < 8; ++n) {
        const uint8_t* r = &mem_[reg::kSm + 8 * n];
        bool ecat_writes = (r[4] & 0x0C) == 0x04, watchdog = r[4] & 0x40, mailbox = (r[4] & 0x03) == 0x02;
        if ((r[6] & 1) && ecat_writes && watchdog && !mailbox) {
            ++watchdog_trips;
            set_al(kSafeop, kAlSmWatchdog);
            return;
        }
    }
}

void Esc::set_al(uint8_t state, uint16_t code) noexcept {
    if (state == kOp && al_state() != kOp) last_output_ns_ = local_time_ns_; // the watchdog starts now
    mem_[reg::kAlStatus] = uint8_t(state | (code ? 0x10 : 0));
    mem_[reg::kAlStatus + 1] = 0;
    put_le16(&mem_[reg::kAlStatusCode], code);
}

bool Esc::check_mailbox_sms() const noexcept {
    for (const auto& s : desc_.sms) {
        if (s.type != SmType::MailboxOut && s.type != SmType::MailboxIn) continue;
        const uint8_t* r = &mem_[reg::kSm + 8 * s.index];
        if (!(r[6] & 1)) return false;
        if (le16(r) != s.start || le16(r + 2) != s.default_size) return false;
    }
    return true;
}

uint16_t Esc::check_process_sms() noexcept {
    // An oversampling terminal accepts the SM lengths of any factor it supports, and samples
    // with the factor they give.
    for (std::size_t k = 0; k < os_sm_bytes_.size(); ++k)
        if (check_process_sms(&os_sm_bytes_[k]) == 0) {
            oversampling_ = unsigned(k + 1);
            return 0;
        }
    oversampling_ = 1;
    return check_process_sms(nullptr);
}

uint16_t Esc::check_process_sms(const std::vector<uint32_t>* os_bytes) const noexcept {
    for (const auto& s : desc_.sms) {
        if (s.type != SmType::Outputs && s.type != SmType::Inputs) continue;
        if (s.is_virtual) continue;
        uint32_t want = os_bytes ? (*os_bytes)[s.index] : expected_sm_bytes(s.index);
        const uint8_t* r = &mem_[reg::kSm + 8 * s.index];
        bool active = r[6] & 1;
        uint16_t code = s.type == SmType::Outputs ? kAlInvalidOutputs : kAlInvalidInputs;
        if (want == 0) {
            if (active && le16(r + 2) != 0) return code;
            continue;
        }
        if (!active || le16(r + 2) != want) return code;
        bool writes = (r[4] & 0x0C) == 0x04; // ECAT writes
        if (writes != (s.type == SmType::Outputs)) return code;
    }
    return 0;
}

void Esc::al_control_written() noexcept {
    uint8_t ctl = mem_[reg::kAlControl];
    uint8_t req = ctl & 0x0F;
    bool ack = ctl & 0x10;
    uint8_t cur = al_state();
    if (al_error()) {
        if (!ack) return; // an error must be acknowledged first
        set_al(cur, 0);
    }
    if (req != kInit && req != kPreop && req != kBoot && req != kSafeop && req != kOp) {
        set_al(cur, kAlUnknownState);
        return;
    }
    if (req == cur) return;
    if (refuse_code_ && req == refuse_state_) return set_al(cur, refuse_code_); // injected fault
    if (req < cur || req == kInit) { // going down is always allowed
        if (req == kBoot && cur != kInit) {
            set_al(cur, kAlInvalidTransition);
            return;
        }
        set_al(req, 0);
        return;
    }
    switch (cur) {
    case kInit:
        if (req == kPreop || req == kBoot) {
            if (!check_mailbox_sms()) return set_al(kInit, kAlInvalidMailbox);
            return set_al(req, 0);
        }
        break;
    case kPreop:
        if (req == kSafeop) {
            if (uint16_t code = check_process_sms()) return set_al(kPreop, code);
            return set_al(kSafeop, 0);
        }
        break;
    case kSafeop:
        if (req == kOp) return set_al(kOp, 0);
        break;
    default: break;
    }
    set_al(cur, kAlInvalidTransition);
}

} // namespace beamctl::ethercat::sim
