// EtherCAT master, mailbox and CoE: the PDO layout read over CoE, SDO upload and download.
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


} // namespace beamctl::ethercat
