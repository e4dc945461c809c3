// The EtherCAT master: construction, datagram transactions, SII, AL states, signals.
// Bring-up, the cyclic path, mailbox/CoE, recovery and DC are in master_*.cpp.
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
            throw Error(SB() << "ec" << bus_ << " position " << c.position << ": "
                             << catalog_.unknown_type_error(c.type));
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
