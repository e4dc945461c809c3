// Beacon timing in virtual time: +0, 20, 60, 140, 300 ms ... ids 0,0,1,2,... (ca-protocol.md §8).
#include "ca/server.hpp"

#include <gtest/gtest.h>

using beamctl::ca::BeaconSchedule;

TEST(BeaconSchedule, FastStartDoublesUpToThePeriod) {
    BeaconSchedule s(1.0);
    double t = 0;
    std::vector<double> times;
    std::vector<uint32_t> ids;
    for (int i = 0; i < 10; ++i) {
        auto n = s.next();
        times.push_back(t);
        ids.push_back(n.id);
        t += n.delay_s;
    }
    const double expect[] = {0, 0.02, 0.06, 0.14, 0.30, 0.62, 1.26, 2.26, 3.26, 4.26};
    for (int i = 0; i < 10; ++i) EXPECT_NEAR(times[i], expect[i], 1e-9) << "beacon " << i;
    EXPECT_EQ(ids, (std::vector<uint32_t>{0, 0, 1, 2, 3, 4, 5, 6, 7, 8}));
}

TEST(BeaconSchedule, ShortPeriodCapsTheFirstInterval) {
    BeaconSchedule s(0.01);
    EXPECT_DOUBLE_EQ(s.next().delay_s, 0.01);
    EXPECT_DOUBLE_EQ(s.next().delay_s, 0.01);
}
