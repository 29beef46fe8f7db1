// The rules around the stage math that both backends share: how many key bits a sort needs,
// the clamp region that bounds the envelope, the per-Gaussian key-frame summary bound, the
// frame planner's near plane and its cached-to-key rule, the straight-line blend, and the CPU's
// partials of split tiles.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"
#include "stage_inputs.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

TEST(SortKeyTileBits, HoldEveryTileAndTheParkedOneAtPowerOfTwoBoundaries) {
    EXPECT_EQ(sort_key_tile_bits(0), 0);
    EXPECT_EQ(sort_key_tile_bits(1), 1);
    for (int k = 1; k < 40; ++k) {
        const std::uint64_t p = std::uint64_t{1} << k;
        // A grid of 2^k - 1 tiles parks at id 2^k - 1: k bits. One more tile needs k + 1.
        EXPECT_EQ(sort_key_tile_bits(p - 1), k) << k;
        EXPECT_EQ(sort_key_tile_bits(p), k + 1) << k;
        EXPECT_EQ(sort_key_tile_bits(p + 1), k + 1) << k;
        EXPECT_EQ(sort_key_tile_bits(p), static_cast<int>(std::bit_width(p)));
    }
    static_assert(sort_key_tile_bits(1920 / 16 * 68) == 13);  // 1080p: 8160 tiles
}

TEST(SortKeyTileBits, NarrowTileKeysHoldEveryIdOfTheGridAndTheParkedOne) {
    // The GPU's 16-bit tile ids (tile_key.cuh) must hold every real id and the parked one.
    for (std::uint64_t tiles : {1ull, 8160ull, 32400ull, 65534ull, 65535ull}) {
        EXPECT_TRUE(narrow_tile_keys(tiles)) << tiles;
        EXPECT_LE(parked_tile(static_cast<std::uint32_t>(tiles)), 0xffffu) << tiles;
    }
    for (std::uint64_t tiles : {65536ull, 65537ull, 1048576ull}) EXPECT_FALSE(narrow_tile_keys(tiles)) << tiles;
    static_assert(narrow_tile_keys(3840 / 16 * (2160 / 16)));  // 4K: 32400 tiles
}

TEST(SortKeyTileBits, ParkedKeysSortLastWithinTheSortedBits) {
    for (std::uint32_t tiles : {1u, 2u, 3u, 255u, 256u, 257u, 8160u, 65535u, 65536u}) {
        const int bits = kSortKeyDepthBits + sort_key_tile_bits(tiles);
        const std::uint64_t limit = bits >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << bits);
        const std::uint64_t parked = make_sort_key(parked_tile(tiles), 1e30f);
        const std::uint64_t last_real = make_sort_key(tiles - 1, 1e30f);
        EXPECT_LT(parked, limit) << tiles;
        EXPECT_LT(last_real, make_sort_key(parked_tile(tiles), 1e-30f)) << tiles;
        EXPECT_EQ(key_tile(parked), tiles);
    }
}

View<double> test_view(int width, int height) {
    return make_view<double>(test::forward_camera(width, height, 60.0), {0, 0, 0});
}

TEST(ClampRegion, IsTheImagePlusFifteenPercentPerSide) {
    const View<double> v = test_view(200, 100);
    EXPECT_TRUE(in_clamp_region(v, Vec2<double>{-29.999, -14.999}));
    EXPECT_TRUE(in_clamp_region(v, Vec2<double>{229.999, 114.999}));
    EXPECT_FALSE(in_clamp_region(v, Vec2<double>{-30.001, 50.0}));
    EXPECT_FALSE(in_clamp_region(v, Vec2<double>{230.001, 50.0}));
    EXPECT_FALSE(in_clamp_region(v, Vec2<double>{100.0, -15.001}));
    EXPECT_FALSE(in_clamp_region(v, Vec2<double>{100.0, 115.001}));
    EXPECT_FALSE(in_clamp_region(v, Vec2<double>{std::nan(""), 50.0}));
    // The projection's clamp edge lands on the region's edge (centred principal point).
    EXPECT_NEAR(v.cx + v.fx * v.clamp_right, 1.15 * v.width, 1e-9);
    EXPECT_NEAR(v.cy - v.fy * v.clamp_top, -0.15 * v.height, 1e-9);
    EXPECT_EQ(max_clamp_tangent(v),
              std::max(std::max(v.clamp_left, v.clamp_right), std::max(v.clamp_top, v.clamp_bottom)));
}

Projected<double> round_gaussian(double x, double y, double variance, double opacity, double depth) {
    Projected<double> g{};
    g.mean = {x, y};
    g.cov = {variance, 0.0, variance};
    g.conic = {1.0 / variance, 0.0, 1.0 / variance};
    g.opacity = opacity;
    g.depth = depth;
    return g;
}

TEST(KeyFrameSummaryBound, OnlyGaussiansInEveryListAreLeftOut) {
    const View<double> v = test_view(64, 32);  // 4 x 2 tiles
    EXPECT_TRUE(cached_can_gain_tiles(Culling::opacity_aware, 7, v));
    EXPECT_FALSE(cached_can_gain_tiles(Culling::opacity_aware, 8, v));
    EXPECT_TRUE(cached_can_gain_tiles(Culling::bbox3sigma, 1, v));
    EXPECT_FALSE(cached_can_gain_tiles(Culling::exact, 1, v));
}

TEST(KeyFrameSummaryBound, IsTheLargerOfTheExtentAndTheProjectedSize) {
    for (Culling mode : {Culling::bbox3sigma, Culling::opacity_aware}) {
        // A wide footprint: its 2D extent is the larger; a needle seen end-on: the 3D size.
        const Projected<double> wide = round_gaussian(10, 10, 400.0, 0.9, 5.0);
        const Projected<double> needle = round_gaussian(10, 10, 0.5, 0.9, 5.0);
        for (const Projected<double>& g : {wide, needle}) {
            const Vec2<double> e = footprint_extent(g, mode);
            const double b = footprint_bound_px(g, mode, 0.2, 500.0);
            EXPECT_EQ(cached_extent_bound_px(g, mode, 0.2, 500.0), std::max({e.x, e.y, b}));
        }
        EXPECT_GT(cached_extent_bound_px(needle, mode, 0.2, 500.0), footprint_extent(needle, mode).x);
    }
}

TEST(FramePlanner, WindowNearPlaneIsLoweredOnlyBySpeculation) {
    CatgsOptions o;
    o.guard_translation = 0.25;
    FramePlanner::Plan plan;
    o.cache = CacheMode::speculative;
    EXPECT_DOUBLE_EQ(plan.window_near_plane(o, 0.2), 0.2 - 0.25 > 1e-3 ? 0.2 - 0.25 : 1e-3);
    EXPECT_DOUBLE_EQ(plan.window_near_plane(o, 1.0), 0.75);
    plan.plain = true;
    EXPECT_EQ(plan.window_near_plane(o, 1.0), 1.0);
    plan.plain = false;
    o.cache = CacheMode::unspeculated;
    EXPECT_EQ(plan.window_near_plane(o, 1.0), 1.0);
    o.cache = CacheMode::off;
    EXPECT_EQ(plan.window_near_plane(o, 1.0), 1.0);
}

TEST(FramePlanner, ACachedFrameThatWouldResortWithoutTheEmissionOrderIsAKeyFrame) {
    CatgsOptions reuse;
    reuse.cache = CacheMode::speculative;
    reuse.adaptive_window = false;
    reuse.window = 4;
    reuse.resort_cached = false;
    reuse.reuse_order_max_angle = std::numeric_limits<double>::infinity();  // never re-sorts
    ASSERT_FALSE(reuse.cached_frames_may_resort());
    auto at = [](double dx, double t) {
        Camera c = test::forward_camera(64, 32, 60.0, {dx, 0, 0});
        c.timestamp = t;
        return c;
    };
    KeyFrameSummary summary;
    summary.min_depth = 50;
    summary.mean_inverse_depth = 1.0 / 80;

    FramePlanner planner;
    const FramePlanner::Plan key = planner.next(at(0, 0), reuse);
    ASSERT_TRUE(key.key);
    EXPECT_FALSE(key.keep_emission_order);
    planner.key_rendered(key, summary);
    const FramePlanner::Plan reused = planner.next(at(0.001, 1 / 30.0), reuse);
    ASSERT_FALSE(reused.key);
    EXPECT_FALSE(reused.resort);

    // Re-sorting is asked for mid-window: the key frame kept no emission order, so the frame is
    // a key frame of its own pose, which keeps it for the cached frames after it.
    CatgsOptions resort = reuse;
    resort.resort_cached = true;
    const FramePlanner::Plan fallback = planner.next(at(0.002, 2 / 30.0), resort);
    ASSERT_TRUE(fallback.key);
    EXPECT_EQ(fallback.poses.size(), 1u);
    EXPECT_EQ(fallback.window, 4);
    EXPECT_FALSE(fallback.plain);
    EXPECT_TRUE(fallback.keep_emission_order);
    planner.key_rendered(fallback, summary);
    const FramePlanner::Plan resorted = planner.next(at(0.003, 3 / 30.0), resort);
    ASSERT_FALSE(resorted.key);
    EXPECT_TRUE(resorted.resort);

    // A plain key frame keeps nothing; invalidate forgets what was kept.
    CatgsOptions off = resort;
    off.cache = CacheMode::off;
    EXPECT_FALSE(planner.next(at(0.004, 4 / 30.0), off).keep_emission_order);
    planner.invalidate();
    EXPECT_TRUE(planner.next(at(0.005, 5 / 30.0), resort).key);
}

// graphdeco's per-pixel rule as plain branches, the way its renderer reads: skip a power
// above 0 or an alpha below 1/255, clamp alpha at 0.99, stop (drawing nothing) where T would
// fall below the threshold. blend_power_unless_done is the same rule as straight-line code.
// One rounding is catgs', not graphdeco's: the next T is T - alpha T (sharing the colour's
// weight), not T (1 - alpha), an ulp of T apart.
template <typename T>
void branchy_blend(PixelAccumulator<T>& acc, T power, T opacity, Vec3<T> c, T min_t) {
    if (acc.done) return;
    if (!(power <= T(0))) return;
    T alpha = opacity * std::exp(power);
    if (!(alpha >= static_cast<T>(kMinAlpha))) return;
    if (alpha > static_cast<T>(kMaxAlpha)) alpha = static_cast<T>(kMaxAlpha);
    const T w = alpha * acc.transmittance;
    const T next = acc.transmittance - w;
    if (next < min_t) {
        acc.done = true;
        return;
    }
    acc.colour = {acc.colour.x + c.x * w, acc.colour.y + c.y * w, acc.colour.z + c.z * w};
    acc.transmittance = next;
}

template <typename T>
void check_straight_line_blend(const char* name) {
    std::mt19937_64 rng(test::fresh_seed(name));
    std::uniform_real_distribution<T> unit(T(0), T(1));
    const T inf = std::numeric_limits<T>::infinity(), nan = std::numeric_limits<T>::quiet_NaN();
    // Powers around the tests' edges: 0 and just above it, where opacity * e^power crosses 1/255
    // and 0.99, and the non-finite values an off-screen mean produces.
    auto power_of = [&](T opacity) -> T {
        switch (rng() % 8) {
            case 0:
                return T(0);
            case 1:
                return std::nextafter(T(0), T(1));
            case 2:
                return std::log(static_cast<T>(kMinAlpha) / opacity) * (T(1) + (unit(rng) - T(0.5)) * T(1e-6));
            case 3:
                return std::log(static_cast<T>(kMaxAlpha) / opacity);
            case 4:
                return std::array<T, 3>{nan, inf, -inf}[rng() % 3];
            default:
                return -T(8) * unit(rng);
        }
    };
    int drawn = 0, stopped = 0, refused = 0;
    for (int pixel = 0; pixel < 2000; ++pixel) {
        PixelAccumulator<T> straight, branchy;
        SignedPixel<T> signed_pixel;
        // Thresholds down to 0 (a split tile's tail may be anything >= 0 in the library's options).
        const T min_t = rng() % 2 ? static_cast<T>(kMinTransmittance) : rng() % 8 == 0 ? T(0) : T(0.3) * unit(rng);
        for (int g = 0; g < 40; ++g) {
            const T opacity = rng() % 10 == 0 ? T(0) : unit(rng);
            const T power = power_of(opacity);
            const Vec3<T> c{unit(rng), T(4) * unit(rng), unit(rng)};
            const PixelAccumulator<T> before = branchy;
            blend_power_unless_done(straight, power, opacity, c, min_t, [](T v) { return std::exp(v); });
            branchy_blend(branchy, power, opacity, c, min_t);
            blend_power_signed(signed_pixel, power, opacity, c, min_t, [](T v) { return std::exp(v); });
            ASSERT_EQ(straight.done, branchy.done) << name << " pixel " << pixel << " gaussian " << g;
            const PixelAccumulator<T> from_signed = signed_pixel.accumulator();
            ASSERT_EQ(from_signed.done, branchy.done) << name << " signed, pixel " << pixel << " gaussian " << g;
            ASSERT_TRUE(test::stage::same_bits(from_signed.transmittance, branchy.transmittance))
                << name << " signed, pixel " << pixel;
            ASSERT_TRUE(test::stage::same_bits(from_signed.colour.x, branchy.colour.x)) << name << " signed " << pixel;
            ASSERT_TRUE(test::stage::same_bits(from_signed.colour.y, branchy.colour.y)) << name << " signed " << pixel;
            ASSERT_TRUE(test::stage::same_bits(from_signed.colour.z, branchy.colour.z)) << name << " signed " << pixel;
            ASSERT_TRUE(test::stage::same_bits(straight.transmittance, branchy.transmittance))
                << name << " pixel " << pixel;
            ASSERT_TRUE(test::stage::same_bits(straight.colour.x, branchy.colour.x)) << name << " pixel " << pixel;
            ASSERT_TRUE(test::stage::same_bits(straight.colour.y, branchy.colour.y)) << name << " pixel " << pixel;
            ASSERT_TRUE(test::stage::same_bits(straight.colour.z, branchy.colour.z)) << name << " pixel " << pixel;
            drawn += branchy.transmittance != before.transmittance;
            stopped += branchy.done && !before.done;
            refused += !before.done && branchy.transmittance == before.transmittance && !branchy.done;
        }
    }
    // Every branch of the rule was taken, or the comparison proves little.
    EXPECT_GT(drawn, 1000) << name;
    EXPECT_GT(stopped, 100) << name;
    EXPECT_GT(refused, 1000) << name;
}

TEST(Blend, SignedPixelOutsideTheImageStaysDone) {
    SignedPixel<float> outside = SignedPixel<float>::starting(false);
    ASSERT_TRUE(outside.done());
    for (const float min_t : {0.0f, static_cast<float>(kMinTransmittance), 0.5f})
        blend_power_signed(outside, 0.0f, 0.9f, Vec3<float>{1, 1, 1}, min_t, [](float v) { return std::exp(v); });
    EXPECT_TRUE(outside.done());
    EXPECT_EQ(outside.accumulator().transmittance, 1.0f);
    EXPECT_EQ(outside.colour.x, 0.0f) << "a done pixel draws nothing";
}

TEST(Blend, StraightLineCodeIsGraphdecosBranchyRule) {
    check_straight_line_blend<float>("blend-float");
    check_straight_line_blend<double>("blend-double");
}

// The CUDA float rasterizer's alpha (blend_alpha_folded, the opacity's log2 added to the
// exponent in base 2) against blend_alpha in double: the same visibility away from its two
// edges, and alpha within the float exponent's rounding.
TEST(Blend, FoldedOpacityAlphaIsBlendAlpha) {
    std::mt19937_64 rng(test::fresh_seed("blend-folded"));
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const double log2e = 1.0 / std::log(2.0);
    const auto exp2f_ = [](float v) { return std::exp2(v); };
    int visible = 0, hidden = 0;
    for (int i = 0; i < 200000; ++i) {
        const double opacity = i % 50 == 0 ? 0.0 : unit(rng);
        // Powers from the peak (and a little past it, where a rounded quadratic form can land)
        // to well below the 1/255 edge.
        const double power = 0.05 - 8.0 * unit(rng);
        const BlendAlpha<double> want = blend_alpha(power, opacity, [](double v) { return std::exp(v); });
        const float log2_opacity = std::log2(static_cast<float>(opacity));
        const float folded = static_cast<float>(power * log2e) + log2_opacity;
        const BlendAlpha<float> got = blend_alpha_folded(folded, log2_opacity, exp2f_);
        const double raw = opacity * std::exp(power);
        const bool near_edge = std::abs(power) < 1e-5 || std::abs(raw / kMinAlpha - 1.0) < 1e-5;
        if (!near_edge) {
            ASSERT_EQ(got.visible, want.visible) << "opacity " << opacity << " power " << power;
        }
        if (got.visible && want.visible) {
            ASSERT_NEAR(got.alpha, want.alpha, 4e-6 * want.alpha) << "opacity " << opacity << " power " << power;
            ++visible;
        } else {
            ++hidden;
        }
        if (opacity == 0.0) {
            ASSERT_FALSE(got.visible) << "opacity 0 draws";
        }
    }
    EXPECT_GT(visible, 50000);
    EXPECT_GT(hidden, 50000);
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    for (const float folded : {nan, inf, -inf, 1.0f})
        EXPECT_FALSE(blend_alpha_folded(folded, std::log2(0.5f), exp2f_).visible) << folded;
    EXPECT_FALSE(blend_alpha_folded(-inf, -inf, exp2f_).visible) << "opacity 0 at the peak";
    EXPECT_EQ(blend_alpha_folded(0.0f, 0.0f, exp2f_).alpha, static_cast<float>(kMaxAlpha)) << "clamped at the peak";
}

TEST(CpuRendererPartials, MergeToTheSplitTilesPixels) {
    const Scene scene = test::random_scene(test::fresh_seed("partials"));
    const Camera camera = test::forward_camera(64, 48, 60.0);
    RenderOptions o;
    o.catgs.split_k = 16;
    o.background = {0.25f, 0.5f, 0.75f};
    CpuRenderer<double> r(2);
    ImageF out;
    const FrameStats stats = r.render(scene, camera, o, out);
    const View<double> view = make_view<double>(camera, scene.origin);
    const Vec3<double> background{0.25, 0.5, 0.75};
    int split_tiles = 0;
    for (std::uint32_t tile = 0; tile < r.tile_ranges().size(); ++tile) {
        const TileRange range = r.tile_ranges()[tile];
        const std::uint32_t splits = split_count(range.end - range.begin, o.catgs.split_k);
        if (splits == 0) {
            EXPECT_EQ(r.partial(tile, 0), nullptr);
            continue;
        }
        ++split_tiles;
        EXPECT_EQ(r.partial(tile, splits + 1), nullptr);
        const int x0 = static_cast<int>(tile % view.tiles_x) * kTileSize;
        const int y0 = static_cast<int>(tile / view.tiles_x) * kTileSize;
        for (int y = y0; y < std::min(y0 + kTileSize, view.height); ++y)
            for (int x = x0; x < std::min(x0 + kTileSize, view.width); ++x) {
                MergeState<double> m;
                for (std::uint32_t i = 0; i <= splits; ++i) {
                    const Partial<double>* p = r.partial(tile, i);
                    ASSERT_NE(p, nullptr);
                    merge_partial(m, p[(y - y0) * kTileSize + (x - x0)]);
                }
                PixelAccumulator<double> acc;
                acc.colour = m.colour;
                acc.transmittance = m.transmittance;
                const Vec3<double> c = finish_pixel(acc, background);
                const float* px = &out.rgb[3 * (static_cast<std::size_t>(y) * view.width + x)];
                EXPECT_EQ(px[0], static_cast<float>(c.x));
                EXPECT_EQ(px[1], static_cast<float>(c.y));
                EXPECT_EQ(px[2], static_cast<float>(c.z));
            }
    }
    EXPECT_GT(split_tiles, 0);
    // The longest list, split or not: what the GPU's layout choice reads.
    std::uint64_t longest_list = 0;
    for (const TileRange& range : r.tile_ranges()) longest_list = std::max(longest_list, range.end - range.begin);
    EXPECT_GT(longest_list, o.catgs.split_k);
    EXPECT_EQ(stats.longest_list, longest_list);
    o.catgs.split_k = 0;
    EXPECT_EQ(r.render(scene, camera, o, out).longest_list, longest_list);
}

}  // namespace
}  // namespace catgs
