// The motion-adaptive speculation window of CaT-GS: its range, its ramp and its hysteresis.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "catgs/cache.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

TEST(CatgsWindow, StartsAtFourStaysInRangeAndFollowsMotion) {
    WindowController c(4, 16.0);
    EXPECT_EQ(c.window(), 4);
    // Fast motion: 10 px per frame allows one frame.
    EXPECT_EQ(c.update(10.0), 1);
    // A step down to hover: W grows, at most doubling per two key frames, up to 16.
    std::vector<int> seen;
    for (int i = 0; i < 12; ++i) seen.push_back(c.update(0.0));
    EXPECT_EQ(seen.back(), 16);
    for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_LE(seen[i], 2 * seen[i - 1]);
    // A step up to fast motion shrinks it at once.
    EXPECT_EQ(c.update(5.0), 3);
    EXPECT_EQ(c.update(1000.0), 1);
}

TEST(CatgsWindow, RampsMonotonically) {
    WindowController c(4, 16.0);
    int previous = 16;
    for (int i = 0; i < 40; ++i) c.update(0.1);  // hover first: W = 16
    for (double m = 0.5; m < 20; m *= 1.2) {
        const int w = c.update(m);
        EXPECT_LE(w, previous) << "speeding up must never grow W";
        if (w > 1) {
            EXPECT_LE(w * m, 16.0 + 1e-9) << "a window must span at most the budget";
        }
        previous = w;
    }
    EXPECT_EQ(previous, 1);
}

TEST(CatgsWindow, JitterAroundABoundaryDoesNotOscillate) {
    WindowController c(4, 16.0);
    // Motion alternating around 16/4 = 4 px: W must settle, not flip every key frame.
    int changes = 0, last = c.window();
    const auto seed = test::fresh_seed("window jitter");
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> jitter(-0.3, 0.3);
    for (int i = 0; i < 200; ++i) {
        const int w = c.update(4.0 + jitter(rng));
        changes += w != last;
        last = w;
    }
    EXPECT_LE(changes, 4);
    EXPECT_GE(last, 3);
    EXPECT_LE(last, 4);
}

}  // namespace
}  // namespace catgs
