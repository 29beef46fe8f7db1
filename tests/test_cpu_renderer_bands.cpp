// The CPU renderer over its pair budget (cpu_renderer_bands.cpp): the frame is drawn in bands
// of tile rows, and the image is the one a single pass draws, bit for bit, in both precisions,
// with and without split, as an image or as a partial; a tile row over the budget, and exact
// culling over it, are errors that name the numbers.

#include <gtest/gtest.h>

#include <string>

#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 160, kHeight = 120;  // 10 x 8 tiles

/// Large Gaussians in front of the camera: every tile row holds many pairs.
Scene dense_scene(std::uint64_t seed) {
    test::RandomSceneParams params;
    params.count = 600;
    params.sh_degree = 1;
    params.log_scale_min = -2.5;
    params.log_scale_max = -0.5;
    return test::random_scene(seed, params);
}

RenderOptions options_with(std::uint32_t split_k) {
    RenderOptions o;
    o.catgs.cache = CacheMode::off;
    o.catgs.split_k = split_k;
    return o;
}

template <typename T>
void expect_bands_match_one_pass(const Scene& scene, const RenderOptions& options, const std::string& what) {
    const Camera camera = test::forward_camera(kWidth, kHeight, 70.0);
    CpuRenderer<T> whole(2);
    ImageF expected;
    const FrameStats one = whole.render(scene, camera, options, expected);
    ASSERT_EQ(one.bands, 1) << what;
    ASSERT_GT(one.pairs, 200u) << what;
    // A budget of a quarter of the frame's pairs, but at least the fullest row's.
    CpuRenderer<T> banded(2, CpuLimits{one.pairs / 4});
    ImageF image;
    FrameStats stats;
    try {
        stats = banded.render(scene, camera, options, image);
    } catch (const Error& e) {
        GTEST_SKIP() << what << ": one tile row holds more than a quarter of the pairs (" << e.what() << ")";
    }
    EXPECT_GE(stats.bands, 4) << what;
    EXPECT_EQ(stats.pairs, one.pairs) << what;
    EXPECT_EQ(stats.split_tasks, one.split_tasks) << what;
    EXPECT_EQ(stats.tasks, one.tasks) << what;
    EXPECT_EQ(image.rgb, expected.rgb) << what;

    PartialImage expected_partial, partial;
    whole.render_partial(scene, camera, options, expected_partial);
    banded.render_partial(scene, camera, options, partial);
    EXPECT_EQ(partial.colour, expected_partial.colour) << what;
    EXPECT_EQ(partial.transmittance, expected_partial.transmittance) << what;
    EXPECT_EQ(partial.stopped, expected_partial.stopped) << what;
}

TEST(CpuRendererBands, BandsDrawTheImageOfOnePass) {
    const Scene scene = dense_scene(test::fresh_seed("cpu bands"));
    for (std::uint32_t split_k : {0u, 16u}) {
        const std::string what = "split k " + std::to_string(split_k);
        expect_bands_match_one_pass<float>(scene, options_with(split_k), what + ", float");
        expect_bands_match_one_pass<double>(scene, options_with(split_k), what + ", double");
    }
}

// With the cache on, a banded key frame starts no window: the next frame is a key frame again,
// and every frame is the image of one pass.
TEST(CpuRendererBands, ABandedFrameStartsNoCachedWindow) {
    const Scene scene = dense_scene(test::fresh_seed("cpu bands cache"));
    RenderOptions options;
    options.catgs.cache = CacheMode::speculative;
    options.catgs.window_cost = WindowCost::off;
    const Camera camera = test::forward_camera(kWidth, kHeight, 70.0);
    CpuRenderer<float> whole(2);
    ImageF expected;
    const FrameStats one = whole.render(scene, camera, options_with(0), expected);
    CpuRenderer<float> banded(2, CpuLimits{one.pairs / 2});
    for (int frame = 0; frame < 3; ++frame) {
        ImageF image;
        FrameStats stats;
        try {
            stats = banded.render(scene, camera, options, image);
        } catch (const Error& e) {
            GTEST_SKIP() << "one tile row holds more than half of the pairs (" << e.what() << ")";
        }
        EXPECT_TRUE(stats.key_frame) << "frame " << frame;
        EXPECT_GE(stats.bands, 2) << "frame " << frame;
        EXPECT_EQ(image.rgb, expected.rgb) << "frame " << frame;
    }
}

TEST(CpuRendererBands, ARowOverTheBudgetAndExactCullingOverItAreNamed) {
    const Scene scene = dense_scene(test::fresh_seed("cpu bands errors"));
    const Camera camera = test::forward_camera(kWidth, kHeight, 70.0);
    CpuRenderer<float> tiny(2, CpuLimits{1});
    ImageF image;
    try {
        tiny.render(scene, camera, options_with(0), image);
        FAIL() << "rendered over a budget of one pair";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_EQ(message.rfind("cpu renderer: tile row ", 0), 0u) << message;
        EXPECT_NE(message.find("tile-Gaussian pairs, more than the pair budget of 1; lower the resolution"),
                  std::string::npos)
            << message;
    }
    RenderOptions exact = options_with(0);
    exact.culling = Culling::exact;
    try {
        tiny.render(scene, camera, exact, image);
        FAIL() << "exact culling over a budget of one pair";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_EQ(message.rfind("cpu renderer: exact culling needs ", 0), 0u) << message;
        EXPECT_NE(message.find(" pairs, more than the pair budget of 1"), std::string::npos) << message;
    }
}

TEST(CpuRendererBands, TheAutomaticBudgetIsAShareOfTheHostsMemory) {
    const CpuRenderer<float> automatic(1);
    EXPECT_GT(automatic.pair_budget(), std::uint64_t{1} << 20);  // any host with 300 MB
    const CpuRenderer<float> set(1, CpuLimits{12345});
    EXPECT_EQ(set.pair_budget(), 12345u);
}

}  // namespace
}  // namespace catgs
