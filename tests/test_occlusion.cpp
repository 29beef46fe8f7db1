// The occlusion cut's shared math (stages/occlusion.hpp), which preprocess and rasterize call on
// the device: the pyramid's layout and its rectangle query against a brute-force max, the
// prediction from the last frame's cuts, the motion rule and the per-tile check.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "catgs/occlusion_tracker.hpp"
#include "catgs/stages/occlusion.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

TEST(OcclusionPyramid, HalvesEachSideUpToOneCell) {
    const OcclusionPyramid p = occlusion_pyramid(240, 135);  // 4K in tiles
    ASSERT_EQ(p.levels, 9);
    const int widths[] = {240, 120, 60, 30, 15, 8, 4, 2, 1}, heights[] = {135, 68, 34, 17, 9, 5, 3, 2, 1};
    int cells = 0;
    for (int l = 0; l < p.levels; ++l) {
        EXPECT_EQ(p.width[l], widths[l]) << l;
        EXPECT_EQ(p.height[l], heights[l]) << l;
        EXPECT_EQ(p.offset[l], cells) << l;
        cells += widths[l] * heights[l];
    }
    EXPECT_EQ(p.cells, cells);
    const OcclusionPyramid one = occlusion_pyramid(1, 1);
    EXPECT_EQ(one.levels, 1);
    EXPECT_EQ(one.cells, 1);
}

// Never below the deepest tile of the rectangle (a Gaussian is left out only behind all of
// them), exact for one tile, and for rectangles of up to 2x2 tiles that sit on even tiles.
TEST(OcclusionPyramid, RectangleQueryBoundsTheDeepestTileFromAbove) {
    std::mt19937_64 rng(test::fresh_seed("occlusion pyramid"));
    std::uniform_real_distribution<float> depth(1.0f, 100.0f);
    for (const auto& [w, h] : {std::pair{37, 23}, std::pair{1, 9}, std::pair{64, 1}, std::pair{120, 68}}) {
        const OcclusionPyramid p = occlusion_pyramid(w, h);
        std::vector<float> level0(static_cast<std::size_t>(w * h));
        for (float& c : level0) c = depth(rng);
        OcclusionMotion exact;  // radius 0, no margins: level 0 is the recorded cuts
        exact.usable = true;
        const std::vector<float> cells = occlusion_cells(level0, p, exact);
        ASSERT_TRUE(std::equal(level0.begin(), level0.end(), cells.begin()));
        std::uniform_int_distribution<int> xs(0, w - 1), ys(0, h - 1);
        for (int trial = 0; trial < 2000; ++trial) {
            int x0 = xs(rng), x1 = xs(rng), y0 = ys(rng), y1 = ys(rng);
            if (x0 > x1) std::swap(x0, x1);
            if (y0 > y1) std::swap(y0, y1);
            const TileRect rect{x0, y0, x1 + 1, y1 + 1};
            float deepest = -INFINITY;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) deepest = std::max(deepest, level0[static_cast<std::size_t>(y * w + x)]);
            const float query = cut_over_rect(p, cells.data(), rect);
            ASSERT_GE(query, deepest) << w << "x" << h << " rect " << x0 << ".." << x1 << ", " << y0 << ".." << y1;
            if (x0 == x1 && y0 == y1) {
                ASSERT_EQ(query, deepest);
            }
            EXPECT_EQ(occluded(p, cells.data(), rect, std::nextafter(query, INFINITY)), true);
            EXPECT_EQ(occluded(p, cells.data(), rect, query), false);  // at the cut: kept
        }
        EXPECT_FALSE(occluded(p, cells.data(), TileRect{3 % w, 0, 3 % w, 1}, 1e30f)) << "empty rectangle";
        EXPECT_FALSE(occluded(p, cells.data(), TileRect{0, 0, 1, 1}, NAN)) << "NaN depth";
    }
}

TEST(OcclusionPrediction, TakesTheDeepestNeighbourGrownAndInfinityWhereAnyTileDidNotStop) {
    const int w = 5, h = 4;
    std::vector<float> recorded(w * h);
    for (int i = 0; i < w * h; ++i) recorded[static_cast<std::size_t>(i)] = 10.0f + static_cast<float>(i);
    OcclusionMotion m;
    m.usable = true;
    m.radius = 1;
    m.grow = 1.5f;
    m.add = 2.0f;
    // Tile (1, 1): neighbours (0..2, 0..2), deepest index 2 * 5 + 2 = 12.
    EXPECT_FLOAT_EQ(predicted_cut(recorded.data(), w, h, 1, 1, m), 22.0f * 1.5f + 2.0f);
    // A corner sees only the tiles inside the grid.
    EXPECT_FLOAT_EQ(predicted_cut(recorded.data(), w, h, 0, 0, m), 16.0f * 1.5f + 2.0f);
    recorded[static_cast<std::size_t>(3 * w + 4)] = INFINITY;  // tile (4, 3) did not stop
    EXPECT_EQ(predicted_cut(recorded.data(), w, h, 3, 2, m), INFINITY);
    EXPECT_LT(predicted_cut(recorded.data(), w, h, 2, 1, m), INFINITY);  // (4, 3) is two tiles away
    recorded[0] = NAN;
    EXPECT_EQ(predicted_cut(recorded.data(), w, h, 1, 1, m), INFINITY);
    m.radius = 3;
    EXPECT_EQ(predicted_cut(recorded.data(), w, h, 2, 1, m), INFINITY);
}

TEST(OcclusionMotion, WidensWithTheTurnAndGivesUpPastTheLargestRadius) {
    const double f = 2300.0;  // 4K, 80 degrees across
    const OcclusionMotion still = occlusion_motion(0.0, 0.0, f);
    EXPECT_TRUE(still.usable);
    EXPECT_EQ(still.radius, 1);
    EXPECT_FLOAT_EQ(still.grow, static_cast<float>(1.0 + kOcclusionDepthMargin));
    EXPECT_EQ(still.add, 0.0f);
    const OcclusionMotion step = occlusion_motion(0.0, 0.27, f);  // 8 m/s at 30 frames/s
    EXPECT_FLOAT_EQ(step.add, 0.27f);
    const OcclusionMotion turn = occlusion_motion(10.0 / f, 0.0, f);  // 10 pixels: one tile more
    EXPECT_TRUE(turn.usable);
    EXPECT_EQ(turn.radius, 2);
    EXPECT_GT(turn.grow, still.grow);
    const double widest = 0.999 * (kOcclusionMaxRadius - 1) * kTileSize / f;
    EXPECT_TRUE(occlusion_motion(widest, 0.0, f).usable);
    EXPECT_EQ(occlusion_motion(widest, 0.0, f).radius, kOcclusionMaxRadius);
    EXPECT_FALSE(occlusion_motion(widest * 1.01, 0.0, f).usable);
    EXPECT_FALSE(occlusion_motion(NAN, 0.0, f).usable);
    EXPECT_FALSE(occlusion_motion(0.0, NAN, f).usable);
    EXPECT_FALSE(occlusion_motion(0.0, 0.0, 0.0).usable);
}

TEST(OcclusionCheck, HoldsOnlyWhereTheTileStoppedNoDeeperThanItsCut) {
    EXPECT_TRUE(occlusion_holds(10.0f, 10.0f));
    EXPECT_TRUE(occlusion_holds(10.0f, 3.0f));
    EXPECT_TRUE(occlusion_holds(10.0f, -INFINITY));
    EXPECT_FALSE(occlusion_holds(10.0f, std::nextafter(10.0f, 11.0f)));
    EXPECT_FALSE(occlusion_holds(10.0f, INFINITY));    // the list ran out first
    EXPECT_TRUE(occlusion_holds(INFINITY, INFINITY));  // nothing was left out there
}

}  // namespace
}  // namespace catgs
