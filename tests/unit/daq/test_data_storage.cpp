// ECMC's data storage buffers (daq::DataStorage): normal, ring and FIFO filling, blocks, the
// index, resizing within the capacity, statistics over the valid values, publication to the IOC
// loop (sample period, push, requests), and no allocation in the cycle.
#include "../alloc_counter.hpp"
#include "daq/data_storage.hpp"

#include <gtest/gtest.h>

#include <vector>

using namespace beamctl::daq;

namespace {
std::vector<double> values(const DataStorage& d) { return {d.data(), d.data() + d.size()}; }
} // namespace

TEST(DataStorage, NormalFillsThenDiscards) {
    DataStorage d(0, 3, BufferType::Normal);
    for (double v : {1.0, 2.0}) EXPECT_EQ(d.append(v), 0u);
    EXPECT_FALSE(d.full());
    EXPECT_EQ(d.index(), 2u);
    EXPECT_EQ(d.append(3), 0u);
    EXPECT_TRUE(d.full());
    EXPECT_EQ(d.append(4), 0u); // discarded, no error (ECMC)
    EXPECT_EQ(values(d), (std::vector<double>{1, 2, 3}));
    EXPECT_EQ(d.index(), 3u);
    EXPECT_EQ(d.count(), 3u);
    EXPECT_EQ(d.appended(), 4u);
}

TEST(DataStorage, RingWrapsAndOverwrites) {
    DataStorage d(0, 3, BufferType::Ring);
    for (double v : {1.0, 2.0, 3.0, 4.0, 5.0}) EXPECT_EQ(d.append(v), 0u);
    EXPECT_EQ(values(d), (std::vector<double>{4, 5, 3}));
    EXPECT_EQ(d.index(), 2u);
    EXPECT_TRUE(d.full());
    const double block[] = {6, 7};
    EXPECT_EQ(d.append(block, 2), 0u); // one at the end, one from the start
    EXPECT_EQ(values(d), (std::vector<double>{7, 5, 6}));
    EXPECT_EQ(d.index(), 1u);
}

TEST(DataStorage, FifoKeepsTheNewestAtTheEnd) {
    DataStorage d(0, 3, BufferType::Fifo);
    d.append(1);
    EXPECT_EQ(values(d), (std::vector<double>{0, 0, 1}));
    EXPECT_EQ(d.average(), 1); // over the valid (last) values only
    for (double v : {2.0, 3.0, 4.0}) d.append(v);
    EXPECT_EQ(values(d), (std::vector<double>{2, 3, 4}));
    EXPECT_EQ(d.index(), 0u); // not used by a FIFO
    EXPECT_EQ(d.minimum(), 2);
    EXPECT_EQ(d.maximum(), 4);
    EXPECT_DOUBLE_EQ(d.average(), 3);
}

TEST(DataStorage, ABlockLargerThanTheBufferIsRefusedWhole) {
    for (BufferType t : {BufferType::Normal, BufferType::Ring, BufferType::Fifo}) {
        DataStorage d(0, 2, t);
        const double block[] = {1, 2, 3};
        EXPECT_EQ(d.append(block, 3), ds_error::kBlockTooLarge) << to_string(t);
        EXPECT_EQ(d.count(), 0u);
        EXPECT_EQ(values(d), (std::vector<double>{0, 0}));
        EXPECT_EQ(d.error(), ds_error::kBlockTooLarge);
    }
}

TEST(DataStorage, IndexElementsAndClear) {
    DataStorage d(0, 4, BufferType::Normal);
    EXPECT_EQ(d.set_index(4), 0u); // 0..size inclusive
    EXPECT_EQ(d.set_index(5), ds_error::kPositionOutOfRange);
    EXPECT_EQ(d.set_index(-1), ds_error::kPositionOutOfRange);
    EXPECT_EQ(d.set_index(1), 0u);
    d.append(7);
    double v = -1;
    EXPECT_EQ(d.get(1, v), 0u);
    EXPECT_EQ(v, 7);
    EXPECT_EQ(d.get(4, v), ds_error::kPositionOutOfRange);
    EXPECT_EQ(v, 7); // untouched
    EXPECT_EQ(d.set(3, 9), 0u);
    EXPECT_EQ(d.set(4, 9), ds_error::kPositionOutOfRange);
    d.clear();
    EXPECT_EQ(values(d), (std::vector<double>{0, 0, 0, 0}));
    EXPECT_EQ(d.index(), 0u);
    EXPECT_EQ(d.count(), 0u);
    EXPECT_EQ(d.average(), 0);
}

TEST(DataStorage, ResizeWithinTheCapacityOnly) {
    DataStorage d(0, 2, BufferType::Normal, 5);
    EXPECT_EQ(d.capacity(), 5u);
    d.append(1);
    d.append(2);
    EXPECT_TRUE(d.full());
    EXPECT_EQ(d.resize(4), 0u);
    EXPECT_EQ(d.size(), 4u);
    EXPECT_FALSE(d.full()); // count reset, as ECMC
    EXPECT_EQ(d.resize(6), ds_error::kSizeOverCapacity);
    EXPECT_EQ(d.resize(0), ds_error::kSizeOverCapacity);
    EXPECT_EQ(d.size(), 4u);
}

TEST(DataStorage, PublishesWhenChangedEverySamplePeriodOrAtOnceWhenPushed) {
    DataStorage d(3, 4, BufferType::Ring, 0, 10);
    d.publish(0); // the first look: the empty buffer
    ASSERT_TRUE(d.update());
    EXPECT_EQ(d.snapshot().count, 0u);
    d.append(5);
    for (uint64_t c = 1; c < 10; ++c) d.publish(c);
    EXPECT_FALSE(d.update()); // within the period
    d.publish(10);
    ASSERT_TRUE(d.update());
    EXPECT_EQ(d.snapshot().data[0], 5);
    EXPECT_EQ(d.snapshot().count, 1u);
    d.publish(30);
    EXPECT_FALSE(d.update()); // unchanged: nothing new
    d.append(6);
    d.request_push(); // ds_push_asyn
    d.publish(31);
    ASSERT_TRUE(d.update());
    EXPECT_EQ(d.snapshot().data[1], 6);
    EXPECT_EQ(DataStorage::status_word(d.snapshot()), 1u << 16); // ring, not full
}

TEST(DataStorage, RequestsFromTheIocLoopApplyInTheCycle) {
    DataStorage d(0, 3, BufferType::Normal);
    const double w[] = {1, 2, 3, 4};
    ASSERT_TRUE(d.request_data(w, 4)); // more than size: the first 3
    EXPECT_FALSE(d.request_data(w, 1)); // the cycle has not taken the first yet
    EXPECT_EQ(d.count(), 0u);
    d.publish(0);
    EXPECT_EQ(values(d), (std::vector<double>{1, 2, 3}));
    ASSERT_TRUE(d.update());
    EXPECT_TRUE(d.snapshot().full);
    ASSERT_TRUE(d.request_index(1));
    ASSERT_TRUE(d.request_clear());
    d.publish(1);
    EXPECT_EQ(d.index(), 0u); // the clear came last
    EXPECT_EQ(d.count(), 0u);
}

TEST(DataStorage, TheCycleAllocatesNothing) {
    DataStorage d(0, 100, BufferType::Fifo, 200, 1);
    beamctl::test::count_allocations(true);
    for (int i = 0; i < 1000; ++i) {
        d.append(double(i));
        d.publish(uint64_t(i));
    }
    (void)d.average();
    beamctl::test::count_allocations(false);
    EXPECT_EQ(beamctl::test::allocations(), 0);
}
