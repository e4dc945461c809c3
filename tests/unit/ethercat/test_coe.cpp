// Mailbox and CoE SDO (ethercat.md §3) against the simulator over the in-process link: expedited
// and normal transfers, aborts, startup SDOs in bring-up, the mailbox full/empty handshake, PDO
// assignment read over CoE, and the ESC's SAFEOP check against the current assignment.
#include "core/error.hpp"
#include "ethercat/catalog.hpp"
#include "ethercat/coe.hpp"
#include "ethercat/master.hpp"
#include "ethercat/sim/segment.hpp"

#include "sim_bus.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <functional>

using namespace beamctl;
using namespace beamctl::ethercat;
using beamctl::ethercat::simbus::Bus;
using beamctl::ethercat::simbus::demo;
using beamctl::ethercat::simbus::kDemo;

namespace {


uint16_t station(int position) {
    return uint16_t(0x1001 + position);
} // the master's scheme

// One frame with one datagram straight into the segment; returns the WKC, `data` gets the reply.
uint16_t txn(sim::Segment& seg, uint8_t cmd, uint16_t adp, uint16_t ado,
             std::vector<uint8_t>& data) {
    FrameBuilder f;
    int off = f.add(cmd, 0x33, adp, ado, uint16_t(data.size()), data.data());
    EXPECT_GE(off, 0);
    EXPECT_TRUE(seg.process(f.data(), f.size()));
    std::memcpy(data.data(), f.data() + off, data.size());
    return le16(f.data() + off + data.size());
}

// A whole 128-byte SM0 buffer holding an SDO upload request.
std::vector<uint8_t> upload_request(uint16_t index, uint8_t sub, uint8_t counter,
                                    uint8_t type = coe::kMbxCoE) {
    std::vector<uint8_t> m(128, 0);
    put_le16(m.data(), 10);
    m[5] = uint8_t(type | counter << 4);
    put_le16(m.data() + 6, 0x2000); // CoE: SDO request
    m[8] = coe::kSdoUploadRequest;
    put_le16(m.data() + 9, index);
    m[11] = sub;
    return m;
}

bool reply_waiting(sim::Segment& seg, int position) {
    std::vector<uint8_t> st(1);
    EXPECT_EQ(txn(seg, kFprd, station(position), 0x080D, st), 1);
    return st[0] & 0x08;
}

std::vector<uint8_t> bytes(std::initializer_list<int> v) {
    std::vector<uint8_t> b;
    for (int x : v) b.push_back(uint8_t(x));
    return b;
}

std::string message_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

uint32_t abort_code_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const SdoAbort& e) {
        return e.code();
    }
    return 0;
}

} // namespace

TEST(Coe, ExpeditedUploadOfIdentity) {
    Bus b({"EK1100", "EL7041", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(m.sdo_upload(2, 0x1018, 0), bytes({4}));
    EXPECT_EQ(le32(m.sdo_upload(2, 0x1018, 1).data()), 0x00000002u);
    std::vector<uint8_t> product = m.sdo_upload(2, 0x1018, 2);
    ASSERT_EQ(product.size(), 4u);
    EXPECT_EQ(le32(product.data()), 0x1c2b3052u);                    // EL7211
    EXPECT_EQ(le32(m.sdo_upload(1, 0x1018, 2).data()), 0x1b813052u); // EL7041
    EXPECT_EQ(le32(m.sdo_upload(2, 0x1018, 3).data()), 0x00180000u);
    // On the wire: an expedited response with the size in the command byte (4 bytes: 0x43).
    std::vector<uint8_t> req = upload_request(0x1018, 2, 0);
    EXPECT_EQ(txn(b.seg, kFpwr, station(2), 0x1000, req), 1);
    ASSERT_TRUE(reply_waiting(b.seg, 2));
    std::vector<uint8_t> rep(128);
    EXPECT_EQ(txn(b.seg, kFprd, station(2), 0x1080, rep), 1);
    EXPECT_EQ(le16(rep.data()), 10);          // mailbox length
    EXPECT_EQ(rep[5] & 0x0F, coe::kMbxCoE);   // type
    EXPECT_NE(rep[5] >> 4 & 7, 0);            // the slave's counter, 1..7
    EXPECT_EQ(le16(rep.data() + 6) >> 12, 3); // SDO response
    EXPECT_EQ(rep[8], 0x43);
    EXPECT_EQ(le32(rep.data() + 12), 0x1c2b3052u);
    EXPECT_FALSE(reply_waiting(b.seg, 2)); // reading the last byte emptied the mailbox
}

TEST(Coe, NormalUploadOfDeviceName) {
    Bus b({"EK1100", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    std::vector<uint8_t> name = m.sdo_upload(1, 0x1008, 0);
    EXPECT_EQ(std::string(name.begin(), name.end()), "EL7211");
    std::vector<uint8_t> req = upload_request(0x1008, 0, 0);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, req), 1);
    std::vector<uint8_t> rep(128);
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x1080, rep), 1);
    EXPECT_EQ(rep[8], 0x41);              // normal upload response, size indicated
    EXPECT_EQ(le32(rep.data() + 12), 6u); // size
    EXPECT_EQ(le16(rep.data()), 10 + 6);  // mailbox length: CoE + SDO header + data
    EXPECT_EQ(std::string(rep.begin() + 16, rep.begin() + 22), "EL7211");
}

TEST(Coe, DownloadAndReadBack) {
    Bus b({"EK1100", "EL7041"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    uint16_t v = 1000;
    m.sdo_download(1, 0x8010, 0x01, &v, 2); // expedited
    EXPECT_EQ(m.sdo_upload(1, 0x8010, 0x01), bytes({0xE8, 0x03}));
    uint8_t big[8];
    put_le64(big, 0x1122334455667788ull);
    m.sdo_download(1, 0x8020, 0x05, big, 8); // normal (more than 4 bytes)
    std::vector<uint8_t> back = m.sdo_upload(1, 0x8020, 0x05);
    ASSERT_EQ(back.size(), 8u);
    EXPECT_EQ(le64(back.data()), 0x1122334455667788ull);
    // The slave's own store holds the values.
    std::vector<uint8_t> in_esc;
    ASSERT_NE(b.seg.slave(1).coe(), nullptr);
    EXPECT_EQ(b.seg.slave(1).coe()->upload(0x8010, 0x01, in_esc), 0u);
    EXPECT_EQ(in_esc, bytes({0xE8, 0x03}));
    // A later write must have the parameter's length.
    uint32_t wide = 5;
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x8010, 0x01, &wide, 4); }), 0x06070010u);
    EXPECT_EQ(m.sdo_upload(1, 0x8010, 0x01), bytes({0xE8, 0x03})); // unchanged
}

TEST(Coe, AbortsNameBusPositionObjectAndCode) {
    Bus b(demo());
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(message_of([&] { m.sdo_upload(8, 0x8010, 0x01); }),
              "ec0 position 8: SDO upload 0x8010:01 aborted: 0x06020000 object does not exist");
    EXPECT_EQ(abort_code_of([&] { m.sdo_upload(8, 0x2000, 0); }), 0x06020000u);
    EXPECT_EQ(message_of([&] { m.sdo_upload(9, 0x1018, 7); }),
              "ec0 position 9: SDO upload 0x1018:07 aborted: 0x06090011 subindex does not exist");
    uint32_t x = 1;
    EXPECT_EQ(message_of([&] { m.sdo_download(9, 0x1018, 2, &x, 4); }),
              "ec0 position 9: SDO download 0x1018:02 aborted: 0x06010002 attempt to write a "
              "read-only object");
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(9, 0x1A00, 1, &x, 4); }), 0x06010002u); // mapping
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(9, 0x1000, 0, &x, 4); }), 0x06010002u);
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(9, 0x3000, 1, &x, 4); }), 0x06020000u);
    // Not a CoE slave, not a configured position.
    EXPECT_NE(message_of([&] {
                  m.sdo_upload(1, 0x1018, 1);
              }).find("ec0 position 1: SDO upload 0x1018:01: EL1008 has no CoE mailbox"),
              std::string::npos);
    EXPECT_NE(message_of([&] { m.sdo_upload(40, 0x1018, 1); }).find("no configured slave"),
              std::string::npos);
    // After all the aborts the mailbox still works and the bus still cycles.
    EXPECT_EQ(le32(m.sdo_upload(8, 0x1018, 2).data()), 0x1b813052u);
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
}

TEST(Coe, StartupSdosAreWrittenInPreopDuringBringUp) {
    Bus b(demo());
    b.cfg[9].sdos = {
        {0x8010, 0x01, 1000, 2}, {0x8011, 0x11, 0x12345678, 4}, {0x8010, 0x02, uint64_t(-3), 2}};
    b.cfg[8].sdos = {{0x8012, 0x05, 1, 1}};
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    sim::CoeServer* od = b.seg.slave(9).coe();
    std::vector<uint8_t> v;
    EXPECT_EQ(od->upload(0x8010, 0x01, v), 0u);
    EXPECT_EQ(v, bytes({0xE8, 0x03}));
    EXPECT_EQ(od->upload(0x8011, 0x11, v), 0u);
    EXPECT_EQ(v, bytes({0x78, 0x56, 0x34, 0x12}));
    EXPECT_EQ(od->upload(0x8010, 0x02, v), 0u);
    EXPECT_EQ(v, bytes({0xFD, 0xFF}));
    EXPECT_EQ(b.seg.slave(8).coe()->upload(0x8012, 0x05, v), 0u);
    EXPECT_EQ(v, bytes({1}));
    EXPECT_EQ(b.seg.slave(7).coe()->upload(0x8010, 0x01, v), 0x06020000u); // only where configured
    EXPECT_EQ(m.sdo_upload(9, 0x8010, 0x01), bytes({0xE8, 0x03}));
    for (std::size_t i = 0; i < b.seg.size(); ++i)
        EXPECT_EQ(b.seg.slave(i).al_state(), 8) << kDemo[i];
}

TEST(Coe, StartupSdosAreCheckedAtConfigurationAndTheirAbortsStopBringUp) {
    Bus b({"EK1100", "EL1008", "EL7211"});
    auto with = [&](int pos, StartupSdo sdo) {
        auto cfg = b.cfg;
        cfg[pos].sdos = {sdo};
        return cfg;
    };
    auto ctor_error = [&](std::vector<SlaveConfig> cfg) {
        return message_of([&] { Master(b.link, 0, cfg, Catalog::builtin()); });
    };
    EXPECT_EQ(ctor_error(with(1, {0x8000, 1, 1, 1})),
              "ec0 position 1: startup SDO 0x8000:01: EL1008 has no CoE mailbox");
    EXPECT_EQ(ctor_error(with(2, {0x8010, 1, 1, 3})),
              "ec0 position 2: startup SDO 0x8010:01: size 3 should be 1, 2, 4 or 8 bytes");
    EXPECT_EQ(ctor_error(with(2, {0x8010, 1, 70000, 2})),
              "ec0 position 2: startup SDO 0x8010:01: value 70000 does not fit in 2 byte(s)");
    EXPECT_EQ(ctor_error(with(2, {0x8010, 1, uint64_t(-40000), 2})),
              "ec0 position 2: startup SDO 0x8010:01: value -40000 does not fit in 2 byte(s)");
    Master m(b.link, 0, with(2, {0x1018, 1, 5, 4}), Catalog::builtin());
    m.set_strict(true);
    EXPECT_EQ(message_of([&] { m.bring_up(); }),
              "ec0 position 2: SDO download 0x1018:01 aborted: 0x06010002 attempt to write a "
              "read-only object");
    EXPECT_EQ(b.seg.slave(2).al_state(), 2); // stopped in PREOP
}

TEST(Coe, AnAbortedStartupSdoLeavesThatSlaveOutAndTheOthersRun) {
    Bus b({"EK1100", "EL1008", "EL7211"});
    auto cfg = b.cfg;
    cfg[2].sdos = {{0x1018, 1, 5, 4}};
    Master m(b.link, 0, cfg, Catalog::builtin());
    m.bring_up(); // not strict: starts without it
    EXPECT_EQ(m.slave_state(2), SlaveState::Error);
    EXPECT_EQ(m.slave_health(2).error_id, slave_error::kNotOperational);
    EXPECT_EQ(m.slave_last_error(2),
              "ec0 position 2: SDO download 0x1018:01 aborted: 0x06010002 attempt to write a read-only object");
    EXPECT_EQ(b.seg.slave(2).al_state(), 2);
    EXPECT_EQ(b.seg.slave(1).al_state(), 8);
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_TRUE(m.slave_valid(1));
    EXPECT_FALSE(m.slave_valid(2));
    EXPECT_NE(m.find_signal("ec0.s2.positionActual01"), nullptr); // its region is reserved
}

TEST(Coe, MailboxWrittenTwiceWithoutReadingIsRefusedAndTheMasterRecovers) {
    Bus b({"EK1100", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    sim::Esc& esc = b.seg.slave(1);
    // Reading an empty slave->master mailbox is not an access.
    std::vector<uint8_t> rep(128);
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x1080, rep), 0);
    // Two requests in one frame: the first fills SM0, the second finds it full.
    std::vector<uint8_t> r1 = upload_request(0x1018, 1, 0), r2 = upload_request(0x1018, 3, 0);
    FrameBuilder f;
    int o1 = f.add(kFpwr, 1, station(1), 0x1000, 128, r1.data());
    int o2 = f.add(kFpwr, 2, station(1), 0x1000, 128, r2.data());
    ASSERT_TRUE(b.seg.process(f.data(), f.size()));
    EXPECT_EQ(le16(f.data() + o1 + 128), 1);
    EXPECT_EQ(le16(f.data() + o2 + 128), 0);
    EXPECT_EQ(esc.mailbox_rejected_writes, 1u);
    EXPECT_TRUE(reply_waiting(b.seg, 1)); // the first was served; its reply waits unread
    // Frames apart: with the reply unread the slave cannot take the next request, which stays
    // in SM0 (status 0x0805 bit 3), so the one after is refused.
    std::vector<uint8_t> r3 = upload_request(0x1018, 4, 0), r4 = upload_request(0x1000, 0, 0);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, r3), 1);
    std::vector<uint8_t> st(1);
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x0805, st), 1);
    EXPECT_EQ(st[0] & 0x08, 0x08);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, r4), 0);
    EXPECT_EQ(esc.mailbox_rejected_writes, 2u);
    // The master drains the stale replies and gets its own answer.
    EXPECT_EQ(le32(m.sdo_upload(1, 0x1018, 2).data()), 0x1c2b3052u);
    EXPECT_FALSE(reply_waiting(b.seg, 1));
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x0805, st), 1);
    EXPECT_EQ(st[0] & 0x08, 0);
    // The master's own request refused (WKC 0): another writer filled SM0 just before it.
    int frames = 0;
    b.seg.on_frame = [&](sim::Segment&) {
        if (++frames != 1) return; // right after the master emptied the mailbox
        std::vector<uint8_t> stray = upload_request(0x1018, 3, 0);
        FrameBuilder g;
        g.add(kFpwr, 9, station(1), 0x1000, 128, stray.data());
        for_each_datagram(g.data(), g.size(), [&](Datagram& d) { esc.process(d); });
    };
    uint64_t rejected = esc.mailbox_rejected_writes;
    EXPECT_EQ(le32(m.sdo_upload(1, 0x1018, 2).data()), 0x1c2b3052u);
    EXPECT_EQ(esc.mailbox_rejected_writes, rejected + 1);
    EXPECT_FALSE(reply_waiting(b.seg, 1));
}

TEST(Coe, RepeatedCounterIsServedOnceAndUnknownProtocolsGetAMailboxError) {
    Bus b({"EK1100", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    std::vector<uint8_t> rep(128);
    std::vector<uint8_t> r1 = upload_request(0x1018, 2, 5);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, r1), 1);
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x1080, rep), 1);
    std::vector<uint8_t> again = upload_request(0x1018, 2, 5);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, again), 1);
    EXPECT_FALSE(reply_waiting(b.seg, 1)); // the same counter again: a repeat, not served twice
    std::vector<uint8_t> foe = upload_request(0x1018, 2, 6, coe::kMbxFoE);
    EXPECT_EQ(txn(b.seg, kFpwr, station(1), 0x1000, foe), 1);
    EXPECT_EQ(txn(b.seg, kFprd, station(1), 0x1080, rep), 1);
    EXPECT_EQ(rep[5] & 0x0F, coe::kMbxError);
    EXPECT_EQ(le16(rep.data() + 8), coe::kMbxErrUnsupportedProtocol);
    EXPECT_EQ(le32(m.sdo_upload(1, 0x1018, 2).data()), 0x1c2b3052u);
}

TEST(Coe, PdoAssignmentReadOverCoeMatchesSiiDefaults) {
    Bus b(demo());
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    int coe_slaves = 0;
    for (const SlaveInfo& s : m.slaves()) {
        bool coe = Catalog::builtin().find(s.type)->coe;
        EXPECT_EQ(s.pdo_from_coe, coe) << s.type;
        coe_slaves += coe;
        EXPECT_EQ(s.pdo_assign, s.sii.pdo_assign) << s.type;
        for (const auto& [sm, index] : s.pdo_assign) {
            const Pdo *got = nullptr, *want = nullptr;
            for (const auto* list : {&s.rx_pdos, &s.tx_pdos})
                for (const Pdo& p : *list)
                    if (p.index == index) got = &p;
            for (const auto* list : {&s.sii.rx_pdos, &s.sii.tx_pdos})
                for (const Pdo& p : *list)
                    if (p.index == index) want = &p;
            ASSERT_TRUE(got && want) << s.type << " PDO " << index;
            ASSERT_EQ(got->entries.size(), want->entries.size()) << s.type;
            for (std::size_t k = 0; k < got->entries.size(); ++k) {
                EXPECT_EQ(got->entries[k].index, want->entries[k].index);
                EXPECT_EQ(got->entries[k].sub, want->entries[k].sub);
                EXPECT_EQ(got->entries[k].bits, want->entries[k].bits);
                EXPECT_EQ(got->entries[k].name, want->entries[k].name);
            }
        }
    }
    EXPECT_EQ(coe_slaves, 8);
    // The objects themselves: EL7211's RxPDO assignment and one mapping.
    EXPECT_EQ(m.sdo_upload(9, 0x1C12, 0), bytes({2}));
    EXPECT_EQ(le16(m.sdo_upload(9, 0x1C12, 2).data()), 0x1601);
    EXPECT_EQ(le32(m.sdo_upload(9, 0x1601, 1).data()), 0x70100620u); // 0x7010:06, 32 bits
    EXPECT_EQ(m.sdo_upload(9, 0x1C00, 0), bytes({4}));
    EXPECT_EQ(m.sdo_upload(9, 0x1C00, 3), bytes({3})); // SM2: process data outputs
}

TEST(Coe, StartupSdosCanReassignPdosAndTheMasterFollows) {
    Bus b({"EK1100", "EL7211"});
    // ecmccfg style: 0x1C13:00 = 0, entries, 0x1C13:00 = n (drop "velocity actual", 0x1A02).
    b.cfg[1].sdos = {
        {0x1C13, 0, 0, 1}, {0x1C13, 1, 0x1A01, 2}, {0x1C13, 2, 0x1A00, 2}, {0x1C13, 0, 2, 1}};
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    EXPECT_EQ(b.seg.slave(1).al_state(), 8);
    const SlaveInfo& s = m.slaves()[1];
    EXPECT_TRUE(s.pdo_from_coe);
    EXPECT_EQ(s.in_bytes, 6u);
    EXPECT_EQ(b.seg.slave(1).expected_sm_bytes(3), 6u);
    EXPECT_EQ(m.find_signal("ec0.s1.velocityActual01"), nullptr);
    const SignalInfo* status = m.find_signal("ec0.s1.driveStatus01");
    const SignalInfo* pos = m.find_signal("ec0.s1.positionActual01");
    ASSERT_TRUE(status && pos);
    EXPECT_EQ(pos->bit_offset, status->bit_offset + 16); // in the order assigned
    put_le16(b.seg.slave(1).sm_buffer(3), 0x1237);
    m.send_process_data();
    EXPECT_EQ(m.receive_process_data(), CycleStatus::Ok);
    EXPECT_EQ(m.get(*status), 0x1237u);
}

TEST(Coe, AssignmentObjectsAreWritableOnlyInPreopAndOnlyAsEcmccfgWritesThem) {
    Bus b({"EK1100", "EL7211"});
    Master m(b.link, 0, b.cfg, Catalog::builtin());
    m.bring_up();
    uint8_t zero = 0;
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 0, &zero, 1); }), 0x08000022u); // OP
    uint16_t preop = 2;
    ASSERT_EQ(m.transact(kFpwr, station(1), 0x0120, &preop, 2), 1);
    ASSERT_EQ(b.seg.slave(1).al_state(), 2);
    uint16_t pdo = 0x1600;
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 1, &pdo, 2); }),
              0x06010003u); // sub0 != 0
    m.sdo_download(1, 0x1C12, 0, &zero, 1);
    uint16_t tx_pdo = 0x1A00;
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 1, &tx_pdo, 2); }), 0x06090030u);
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 1, &pdo, 1); }), 0x06070010u);
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 3, &pdo, 2); }), 0x06090011u);
    m.sdo_download(1, 0x1C12, 1, &pdo, 2);
    uint8_t three = 3, one = 1;
    EXPECT_EQ(abort_code_of([&] { m.sdo_download(1, 0x1C12, 0, &three, 1); }), 0x06090030u);
    m.sdo_download(1, 0x1C12, 0, &one, 1);
    EXPECT_EQ(m.sdo_upload(1, 0x1C12, 0), bytes({1}));
    EXPECT_EQ(b.seg.slave(1).expected_sm_bytes(2), 2u); // controlword only
    // SM2 is still configured for 6 bytes: SAFEOP is refused with "invalid output configuration".
    uint16_t safeop = 4;
    ASSERT_EQ(m.transact(kFpwr, station(1), 0x0120, &safeop, 2), 1);
    EXPECT_EQ(b.seg.slave(1).al_state(), 2);
    EXPECT_TRUE(b.seg.slave(1).al_error());
    EXPECT_EQ(b.seg.slave(1).al_status_code(), 0x001D);
}

TEST(Coe, AssignmentInconsistentWithTheSmSizeRefusesSafeopNamingTheSlave) {
    for (uint16_t obj : {uint16_t(0x1C12), uint16_t(0x1C13)}) {
        Bus b({"EK1100", "EL1008", "EL7211"});
        // Another writer changes the slave's assignment in PREOP after the master has read it
        // (when the master programs the process-data SMs), so the sizes no longer match.
        bool done = false;
        b.seg.on_frame = [&](sim::Segment& seg) {
            sim::Esc& esc = seg.slave(2);
            if (done || esc.al_state() != 2 || !(esc.memory()[0x0800 + 8 * 3 + 6] & 1)) return;
            uint16_t first = obj == 0x1C12 ? 0x1600 : 0x1A00;
            uint8_t zero = 0, one = 1, pdo[2] = {uint8_t(first), uint8_t(first >> 8)};
            EXPECT_EQ(esc.coe()->download(obj, 0, &zero, 1, 2), 0u);
            EXPECT_EQ(esc.coe()->download(obj, 1, pdo, 2, 2), 0u);
            EXPECT_EQ(esc.coe()->download(obj, 0, &one, 1, 2), 0u);
            done = true;
        };
        Master m(b.link, 0, b.cfg, Catalog::builtin());
        m.set_strict(true);
        std::string w = message_of([&] { m.bring_up(); });
        EXPECT_TRUE(done);
        EXPECT_NE(w.find("ec0 slave 2 (EL7211): refused SAFEOP"), std::string::npos) << w;
        EXPECT_NE(w.find(obj == 0x1C12 ? "0x001D invalid output configuration"
                                       : "0x001E invalid input configuration"),
                  std::string::npos)
            << w;
        EXPECT_EQ(b.seg.slave(2).al_state(), 2);
        EXPECT_EQ(b.seg.slave(1).al_state(), 4); // the EL1008 before it went on to SAFEOP
    }
}
