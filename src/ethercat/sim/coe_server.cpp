#include "ethercat/sim/coe_server.hpp"

#include "ethercat/coe.hpp"
#include "ethercat/frame.hpp"
#include "ethercat/sim/esc.hpp"

#include <algorithm>
#include <cstring>

namespace beamctl::ethercat::sim {
namespace {

std::vector<uint8_t> u8v(uint8_t v) {
    return {v};
}
std::vector<uint8_t> u16v(uint16_t v) {
    return {uint8_t(v), uint8_t(v >> 8)};
}
std::vector<uint8_t> u32v(uint32_t v) {
    std::vector<uint8_t> b(4);
    put_le32(b.data(), v);
    return b;
}

constexpr uint32_t kDeviceTypeMdp = 0x00001389; // modular device profile (ETG.5001)

} // namespace

CoeServer::CoeServer(const DeviceDesc& desc, uint32_t serial)
    : desc_(desc) {
    add(coe::kObjDeviceType, 0, u32v(kDeviceTypeMdp));
    add(coe::kObjDeviceName, 0, std::vector<uint8_t>(desc_.type.begin(), desc_.type.end()));
    add(coe::kObjIdentity, 0, u8v(4));
    add(coe::kObjIdentity, 1, u32v(desc_.vendor));
    add(coe::kObjIdentity, 2, u32v(desc_.product));
    add(coe::kObjIdentity, 3, u32v(desc_.revision));
    add(coe::kObjIdentity, 4, u32v(serial));
    uint8_t n_sms = 0;
    for (const auto& sm : desc_.sms) n_sms = std::max<uint8_t>(n_sms, uint8_t(sm.index + 1));
    add(coe::kObjSmTypes, 0, u8v(n_sms));
    for (uint8_t i = 0; i < n_sms; ++i) add(coe::kObjSmTypes, uint8_t(i + 1), u8v(0));
    for (const auto& sm : desc_.sms) {
        objects_[coe::kObjSmTypes].subs[uint8_t(sm.index + 1)] = u8v(uint8_t(sm.type));
        if ((sm.type != SmType::Outputs && sm.type != SmType::Inputs) || sm.is_virtual) continue;
        // Assignment of a process-data SM: one sub per PDO of its direction, default from Pdo@Sm.
        uint16_t obj = uint16_t(coe::kObjSmAssignBase + sm.index);
        const auto& pdos = sm.type == SmType::Outputs ? desc_.rx_pdos : desc_.tx_pdos;
        uint8_t n = 0;
        for (const auto& [smi, pdo] : desc_.pdo_assign)
            if (smi == sm.index) add(obj, ++n, u16v(pdo), Access::PdoAssign);
        for (std::size_t k = n; k < pdos.size(); ++k)
            add(obj, uint8_t(k + 1), u16v(0), Access::PdoAssign);
        add(obj, 0, u8v(n), Access::PdoAssign);
    }
    for (const auto* list : {&desc_.rx_pdos, &desc_.tx_pdos}) {
        for (const Pdo& p : *list) {
            add(p.index, 0, u8v(uint8_t(p.entries.size())));
            uint8_t k = 0;
            for (const PdoEntry& e : p.entries)
                add(p.index, ++k, u32v(uint32_t(e.index) << 16 | uint32_t(e.sub) << 8 | e.bits));
        }
    }
}

void CoeServer::add(uint16_t index, uint8_t sub, std::vector<uint8_t> value, Access a) {
    Object& o = objects_[index];
    o.access = a;
    o.subs[sub] = std::move(value);
}

uint32_t CoeServer::upload(uint16_t index, uint8_t sub, std::vector<uint8_t>& out) const {
    auto it = objects_.find(index);
    if (it == objects_.end()) return coe::kAbortNoObject;
    auto s = it->second.subs.find(sub);
    if (s == it->second.subs.end()) return coe::kAbortNoSubindex;
    out = s->second;
    return 0;
}

void CoeServer::refuse_download(uint16_t index, uint8_t sub, uint32_t code) {
    if (index == 0 && code == 0) refused_.clear();
    else if (code == 0) refused_.erase(uint32_t(index) << 8 | sub);
    else refused_[uint32_t(index) << 8 | sub] = code;
}

uint32_t CoeServer::download(uint16_t index, uint8_t sub, const uint8_t* data, std::size_t len,
                             uint8_t al_state) {
    if (auto r = refused_.find(uint32_t(index) << 8 | sub); r != refused_.end()) return r->second;
    auto it = objects_.find(index);
    if (it == objects_.end()) {
        if (index < 0x8000 || index > 0x8FFF) return coe::kAbortNoObject;
        it = objects_.emplace(index, Object{Access::ReadWrite, {}}).first;
    }
    Object& o = it->second;
    auto s = o.subs.find(sub);
    switch (o.access) {
    case Access::ReadOnly:
        return s == o.subs.end() ? coe::kAbortNoSubindex : coe::kAbortReadOnly;
    case Access::PdoAssign:
        if (s == o.subs.end()) return coe::kAbortNoSubindex;
        return assign_write(index, o, sub, data, len, al_state);
    case Access::ReadWrite:
        if (s == o.subs.end()) { // the parameter store: the first write defines the parameter
            o.subs[sub].assign(data, data + len);
            return 0;
        }
        if (s->second.size() != len) return coe::kAbortLength;
        s->second.assign(data, data + len);
        return 0;
    }
    return coe::kAbortGeneral;
}

uint32_t CoeServer::assign_write(uint16_t index, Object& o, uint8_t sub, const uint8_t* data,
                                 std::size_t len, uint8_t al_state) {
    if (al_state != kPreop) return coe::kAbortDeviceState;
    uint8_t sm = uint8_t(index - coe::kObjSmAssignBase);
    bool outputs = false;
    for (const auto& d : desc_.sms)
        if (d.index == sm) outputs = d.type == SmType::Outputs;
    uint8_t max = uint8_t(o.subs.size() - 1);
    if (sub == 0) {
        if (len != 1) return coe::kAbortLength;
        uint8_t n = data[0];
        if (n > max) return coe::kAbortValueRange;
        for (uint8_t k = 1; k <= n; ++k)
            if (le16(o.subs[k].data()) == 0) return coe::kAbortValueRange;
        o.subs[0] = u8v(n);
        return 0;
    }
    if (len != 2) return coe::kAbortLength;
    if (o.subs[0][0] != 0) return coe::kAbortSubindex0NotZero;
    uint16_t pdo = le16(data);
    bool known = false;
    for (const Pdo& p : outputs ? desc_.rx_pdos : desc_.tx_pdos) known |= p.index == pdo;
    if (!known) return coe::kAbortValueRange;
    o.subs[sub] = u16v(pdo);
    return 0;
}

uint32_t CoeServer::sm_bytes(uint8_t sm) const {
    auto it = objects_.find(uint16_t(coe::kObjSmAssignBase + sm));
    if (sm >= 0x20 || it == objects_.end()) return desc_.sm_bytes(sm);
    const auto& subs = it->second.subs;
    uint32_t bits = 0;
    uint8_t n = subs.at(0)[0];
    for (uint8_t k = 1; k <= n; ++k)
        if (const Pdo* p = desc_.find_pdo(le16(subs.at(k).data()))) bits += p->bit_size();
    return (bits + 7) / 8;
}

bool CoeServer::assigned(uint8_t sm, std::vector<uint16_t>& pdos) const {
    auto it = objects_.find(uint16_t(coe::kObjSmAssignBase + sm));
    if (sm >= 0x20 || it == objects_.end()) return false;
    pdos.clear();
    const auto& subs = it->second.subs;
    for (uint8_t k = 1, n = subs.at(0)[0]; k <= n; ++k) pdos.push_back(le16(subs.at(k).data()));
    return true;
}

std::size_t CoeServer::handle(const uint8_t* req, std::size_t len, uint8_t* reply, std::size_t cap,
                              uint8_t al_state, uint16_t& mbx_error) {
    mbx_error = 0;
    if (len < coe::kCoeHeader) {
        mbx_error = coe::kMbxErrSizeTooShort;
        return 0;
    }
    if ((le16(req) >> 12) != coe::kCoeSdoRequest) {
        mbx_error = coe::kMbxErrServiceNotSupported; // emergency, SDO info, PDO services
        return 0;
    }
    if (len < coe::kCoeHeader + coe::kSdoHeader || cap < coe::kCoeHeader + coe::kSdoHeader) {
        mbx_error = coe::kMbxErrSizeTooShort;
        return 0;
    }
    const uint8_t* sdo = req + coe::kCoeHeader;
    uint8_t cmd = sdo[0];
    uint16_t index = le16(sdo + 1);
    uint8_t sub = sdo[3];
    std::memset(reply, 0, coe::kCoeHeader + coe::kSdoHeader);
    uint8_t* out = reply + coe::kCoeHeader;
    put_le16(out + 1, index);
    out[3] = sub;
    auto abort = [&](uint32_t code) {
        put_le16(reply, uint16_t(coe::kCoeSdoRequest << 12)); // an abort is an SDO request
        out[0] = coe::kSdoAbort;
        put_le32(out + 4, code);
        return coe::kCoeHeader + coe::kSdoHeader;
    };
    put_le16(reply, uint16_t(coe::kCoeSdoResponse << 12));
    uint8_t ccs = cmd >> 5;
    if (ccs == 4) return 0; // the master aborted: nothing to answer
    if ((ccs == 1 || ccs == 2) && (cmd & coe::kSdoCompleteAccess))
        return abort(coe::kAbortUnsupportedAccess);
    if (ccs == 2) { // initiate upload
        std::vector<uint8_t> v;
        if (uint32_t code = upload(index, sub, v)) return abort(code);
        if (v.size() <= 4) {
            out[0] = uint8_t(coe::kSdoUploadExpedited | (4 - v.size()) << 2);
            std::memcpy(out + 4, v.data(), v.size());
            return coe::kCoeHeader + coe::kSdoHeader;
        }
        std::size_t n = coe::kCoeHeader + coe::kSdoHeader + v.size();
        if (n > cap) return abort(coe::kAbortTooLongForMailbox); // would need segments
        out[0] = coe::kSdoUploadNormal;
        put_le32(out + 4, uint32_t(v.size()));
        std::memcpy(out + coe::kSdoHeader, v.data(), v.size());
        return n;
    }
    if (ccs == 1) { // initiate download
        const uint8_t* data = sdo + 4;
        std::size_t n = 4;
        if (cmd & 0x02) { // expedited: size in bits 2-3 if indicated, else the object's size
            if (cmd & 0x01) {
                n = 4 - (cmd >> 2 & 3);
            } else {
                std::vector<uint8_t> cur;
                if (upload(index, sub, cur) == 0 && cur.size() < 4) n = cur.size();
            }
        } else {
            if (!(cmd & 0x01)) return abort(coe::kAbortCommand);
            n = le32(sdo + 4);
            data = sdo + coe::kSdoHeader;
            if (n > len - coe::kCoeHeader - coe::kSdoHeader)
                return abort(coe::kAbortTooLongForMailbox); // a segmented download
        }
        if (uint32_t code = download(index, sub, data, n, al_state)) return abort(code);
        out[0] = coe::kSdoDownloadResponse;
        return coe::kCoeHeader + coe::kSdoHeader;
    }
    return abort(coe::kAbortCommand); // segments, block transfers, unknown commands
}

} // namespace beamctl::ethercat::sim
