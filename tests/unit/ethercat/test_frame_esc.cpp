// Frame codec and the simulated ESC: addressing, working-counter rules (ethercat.md §1), FMMU
// mapping and the AL state machine checks (§2, §3).
#include "ethercat/catalog.hpp"
#include "ethercat/frame.hpp"
#include "ethercat/sim/segment.hpp"

#include <gtest/gtest.h>

using namespace beamctl::ethercat;

namespace {

// One datagram through the segment; returns its WKC and the data that came back.
struct Txn {
    sim::Segment& seg;
    uint16_t run(uint8_t cmd, uint32_t addr, std::vector<uint8_t>& data) {
        FrameBuilder f;
        int off = f.add(cmd, 7, addr, uint16_t(data.size()), data.data());
        EXPECT_GE(off, 0);
        EXPECT_TRUE(seg.process(f.data(), f.size()));
        std::memcpy(data.data(), f.data() + off, data.size());
        return le16(f.data() + off + data.size());
    }
    uint16_t run(uint8_t cmd, uint16_t adp, uint16_t ado, std::vector<uint8_t>& data) {
        return run(cmd, uint32_t(adp) | uint32_t(ado) << 16, data);
    }
};

const DeviceDesc& dev(const char* type) {
    const DeviceDesc* d = Catalog::builtin().find(type);
    EXPECT_NE(d, nullptr) << type;
    return *d;
}

} // namespace

TEST(Frame, BuilderSetsLengthAndMoreBits) {
    FrameBuilder f;
    uint8_t a[4] = {1, 2, 3, 4};
    int o1 = f.add(kFprd, 1, 0x1001, 0x0130, 2);
    int o2 = f.add(kLrw, 2, 0x10000, 4, a);
    EXPECT_EQ(o1, 12);
    EXPECT_EQ(o2, 12 + 2 + 2 + 10);
    EXPECT_EQ(f.size(), 2u + 14 + 16);
    EXPECT_EQ(le16(f.data()), 0x1000 | (14 + 16));
    std::vector<uint8_t> cmds;
    std::vector<bool> more;
    EXPECT_TRUE(for_each_datagram(f.data(), f.size(), [&](Datagram& d) {
        cmds.push_back(d.cmd());
        more.push_back(d.more());
    }));
    EXPECT_EQ(cmds, (std::vector<uint8_t>{kFprd, kLrw}));
    EXPECT_EQ(more, (std::vector<bool>{true, false}));
}

TEST(Frame, TruncatedOrForeignFramesAreRejected) {
    FrameBuilder f;
    f.add(kBrd, 0, 0, 0x130, 2);
    int n = 0;
    EXPECT_FALSE(for_each_datagram(f.data(), f.size() - 1, [&](Datagram&) { ++n; }));
    std::vector<uint8_t> bad(f.data(), f.data() + f.size());
    bad[1] = 0x20; // type 2 (ADS): not processed
    EXPECT_FALSE(for_each_datagram(bad.data(), bad.size(), [&](Datagram&) { ++n; }));
    EXPECT_EQ(n, 0);
    EXPECT_EQ(f.add(kLrw, 0, 0, 1487), -1); // more than a datagram can carry
}

TEST(Esc, BroadcastReadCountsSlavesAndAutoIncrementAddresses) {
    sim::Segment seg;
    for (int i = 0; i < 5; ++i) seg.add(dev("EL1008"));
    Txn t{seg};
    std::vector<uint8_t> two(2);
    EXPECT_EQ(t.run(kBrd, 0, 0x0130, two), 5);
    for (int p = 0; p < 5; ++p) {
        std::vector<uint8_t> a = {uint8_t(0x01 + p), 0x10};
        EXPECT_EQ(t.run(kApwr, uint16_t(-p), 0x0010, a), 1);
    }
    EXPECT_EQ(seg.slave(3).station_address(), 0x1004);
    std::vector<uint8_t> r(2);
    EXPECT_EQ(t.run(kFprd, 0x1004, 0x0010, r), 1);
    EXPECT_EQ(le16(r.data()), 0x1004);
    EXPECT_EQ(t.run(kFprd, 0x2000, 0x0010, r), 0); // nobody has that address
    std::vector<uint8_t> rw = {0x34, 0x12};
    EXPECT_EQ(t.run(kFprw, 0x1002, 0x0012, rw), 3); // read (alias 0) + write
    EXPECT_EQ(le16(rw.data()), 0);
    EXPECT_EQ(t.run(kBwr, 0, 0x0900, two), 5);
}

TEST(Esc, ArmwAndFrmwReadAtTheReferenceAndWriteEverywhereElse) {
    sim::Segment seg;
    for (int i = 0; i < 4; ++i) seg.add(dev("EL1008"));
    Txn t{seg};
    for (int p = 0; p < 4; ++p) {
        std::vector<uint8_t> a = {uint8_t(0x01 + p), 0x10};
        t.run(kApwr, uint16_t(-p), 0x0010, a);
    }
    seg.set_time(123456789);
    std::vector<uint8_t> v(8);
    EXPECT_EQ(t.run(kFrmw, 0x1001, 0x0910, v), 4);
    EXPECT_EQ(le64(v.data()), 123456789u);
    EXPECT_EQ(t.run(kArmw, 0, 0x0910, v), 4);
}

TEST(Esc, LogicalAccessThroughFmmusWithWorkingCounter) {
    sim::Segment seg;
    seg.add(dev("EL2008"));
    seg.add(dev("EL1008"));
    Txn t{seg};
    for (int p = 0; p < 2; ++p) {
        std::vector<uint8_t> a = {uint8_t(0x01 + p), 0x10};
        t.run(kApwr, uint16_t(-p), 0x0010, a);
    }
    // EL2008: logical byte 0 -> its output SM buffer (write FMMU); EL1008: logical 1 <- inputs.
    auto fmmu = [&](uint16_t station, uint32_t log, uint16_t phys, uint8_t type) {
        std::vector<uint8_t> f(16, 0);
        put_le32(f.data(), log);
        put_le16(f.data() + 4, 1);
        f[7] = 7;
        put_le16(f.data() + 8, phys);
        f[11] = type;
        f[12] = 1;
        EXPECT_EQ(t.run(kFpwr, station, 0x0600, f), 1);
    };
    const auto& out_sm = dev("EL2008").sms.at(0);
    const auto& in_sm = dev("EL1008").sms.at(0);
    fmmu(0x1001, 0, out_sm.start, 2);
    fmmu(0x1002, 1, in_sm.start, 1);
    seg.slave(1).memory()[in_sm.start] = 0xA5;
    std::vector<uint8_t> img = {0x3C, 0x00};
    EXPECT_EQ(t.run(kLrw, 0, img), 3); // write (2) at EL2008 + read (1) at EL1008
    EXPECT_EQ(img[1], 0xA5);
    EXPECT_EQ(seg.slave(0).memory()[out_sm.start], 0x3C);
    std::vector<uint8_t> only_in = {0};
    EXPECT_EQ(t.run(kLrd, 1, only_in), 1);
    EXPECT_EQ(t.run(kLwr, 1, only_in), 0); // no write FMMU there
}

TEST(Esc, BitGranularFmmu) {
    sim::Segment seg;
    seg.add(dev("EL1008"));
    Txn t{seg};
    std::vector<uint8_t> a = {0x01, 0x10};
    t.run(kApwr, 0, 0x0010, a);
    // Map physical bits 0..3 of the input byte to logical bits 4..7 of byte 2.
    std::vector<uint8_t> f(16, 0);
    put_le32(f.data(), 2);
    put_le16(f.data() + 4, 1);
    f[6] = 4;
    f[7] = 7;
    put_le16(f.data() + 8, dev("EL1008").sms.at(0).start);
    f[11] = 1;
    f[12] = 1;
    t.run(kFpwr, 0x1001, 0x0600, f);
    seg.slave(0).memory()[dev("EL1008").sms.at(0).start] = 0x0B;
    std::vector<uint8_t> img = {0, 0, 0x05};
    EXPECT_EQ(t.run(kLrd, 0, img), 1);
    EXPECT_EQ(img[2], 0xB5); // low nibble kept, high nibble = physical 0xB
}

TEST(Esc, AlStateMachineChecksTransitionsAndSyncManagers) {
    sim::Segment seg;
    seg.add(dev("EL1008"));
    Txn t{seg};
    std::vector<uint8_t> a = {0x01, 0x10};
    t.run(kApwr, 0, 0x0010, a);
    auto request = [&](uint16_t v) {
        std::vector<uint8_t> c = {uint8_t(v), uint8_t(v >> 8)};
        t.run(kFpwr, 0x1001, 0x0120, c);
    };
    request(8); // INIT -> OP skips states
    EXPECT_EQ(seg.slave(0).al_state(), 1);
    EXPECT_TRUE(seg.slave(0).al_error());
    EXPECT_EQ(seg.slave(0).al_status_code(), 0x0011);
    request(2); // not acknowledged: ignored
    EXPECT_EQ(seg.slave(0).al_state(), 1);
    request(0x12); // acknowledge + PREOP
    EXPECT_EQ(seg.slave(0).al_state(), 2);
    EXPECT_FALSE(seg.slave(0).al_error());
    request(4); // SAFEOP without the input SM configured
    EXPECT_EQ(seg.slave(0).al_state(), 2);
    EXPECT_EQ(seg.slave(0).al_status_code(), 0x001E);
}
