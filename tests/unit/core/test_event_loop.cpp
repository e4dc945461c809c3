// EventLoop's after-batch hooks: removed ones stop running, also when a hook removes itself or
// another while the hooks run (a CA server destroyed while its loop goes on).
#include "core/event_loop.hpp"

#include <gtest/gtest.h>

using namespace beamctl;

TEST(EventLoop, AfterBatchHooksCanBeRemovedEvenWhileTheyRun) {
    EventLoop loop;
    int a = 0, b = 0, c = 0;
    EventLoop::HookId hb = 0, hc = 0;
    loop.add_after_batch([&] { ++a; });
    hb = loop.add_after_batch([&] {
        ++b;
        loop.remove_after_batch(hb); // itself
        loop.remove_after_batch(hc); // one that has not run yet in this batch
    });
    hc = loop.add_after_batch([&] { ++c; });
    int batches = 0;
    loop.call_every(0.001, [&] {
        if (++batches == 3) loop.stop();
    });
    loop.run();
    EXPECT_GE(a, 3);
    EXPECT_EQ(b, 1);
    EXPECT_EQ(c, 0);
}
