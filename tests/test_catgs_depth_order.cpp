// The depth order a cached frame reuses (--resort off, the default): every Gaussian a window
// lists is keyed by its depth at the key pose, so that a translation, which shifts all those
// depths alike, keeps their order. An independent float64 reference found the order wrong when
// the keys were taken at each Gaussian's first visible pose instead: a camera backing away
// brings two Gaussians from behind it into view at different poses of the window, and their
// depths, taken at different poses, sorted the nearer one behind the farther one (the centre
// pixel green where it is red, up to 230 levels).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "catgs/cpu_renderer.hpp"
#include "catgs/render_options.hpp"
#include "catgs/stages/keys.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 80, kHeight = 60;
constexpr double kFovDegrees = 67.38;

void add_gaussian(Scene& s, std::array<double, 3> position, double scale, double opacity, std::array<float, 3> dc) {
    const std::size_t n = s.count();
    s.resize(n + 1);
    for (int a = 0; a < 3; ++a) {
        s.positions[3 * n + a] = static_cast<float>(position[a]);
        s.scales[3 * n + a] = static_cast<float>(scale);
        s.sh[s.sh_floats_per_gaussian() * n + a] = dc[a];
    }
    s.rotations[4 * n] = 1.0f;
    s.opacities[n] = static_cast<float>(opacity);
}

/// A red Gaussian 2.9 m nearer the path's end than a green one, both on the optical axis and
/// behind the camera at the start, over a background ahead of it.
Scene red_before_green() {
    Scene s;
    s.sh_degree = 0;
    add_gaussian(s, {0, 0, -4.85}, 0.30, 0.95, {1.77f, -1.77f, -1.77f});  // red
    add_gaussian(s, {0, 0, -1.95}, 0.37, 0.95, {-1.77f, 1.77f, -1.77f});  // green
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int i = 0; i < 40; ++i)
        add_gaussian(s, {6 * u(rng) - 3, 4 * u(rng) - 2, 3 + 3 * u(rng)}, 0.1 + 0.2 * u(rng), 0.5,
                     {static_cast<float>(u(rng) - 0.5), static_cast<float>(u(rng) - 0.5), 0.0f});
    s.update_bounds();
    return s;
}

TEST(CatgsDepthOrder, GaussiansEnteringFromBehindKeepTheirOrderInCachedFrames) {
    const Scene scene = red_before_green();
    // The camera looks down +z and backs away along -z, 1 m a frame: the green Gaussian comes
    // into view first (frame 2, 5 cm ahead), the red one later (frame 5), in front of it.
    std::vector<Camera> path;
    for (int k = 0; k < 9; ++k) {
        path.push_back(test::forward_camera(kWidth, kHeight, kFovDegrees, {0, 0, -static_cast<double>(k)}));
        path.back().timestamp = k / 30.0;
    }
    RenderOptions cached_options = default_pipeline_options();
    cached_options.catgs.adaptive_window = false;
    cached_options.catgs.window = 8;
    cached_options.catgs.split_k = 0;
    ASSERT_FALSE(cached_options.catgs.resort_cached) << "the default reuses the key frame's order";
    CpuRenderer<float> cached, full;
    int cached_with_both = 0;
    for (std::size_t k = 0; k < path.size(); ++k) {
        ImageF a, b;
        const FrameStats s = cached.render(scene, path[k], cached_options, a);
        full.render(scene, path[k], RenderOptions{}, b);
        float worst = 0;
        for (std::size_t v = 0; v < a.rgb.size(); ++v) worst = std::max(worst, std::fabs(a.rgb[v] - b.rgb[v]));
        EXPECT_LE(worst, 1.0f / 255) << "frame " << k << (s.key_frame ? " (key)" : " (cached)");
        if (!s.key_frame && k >= 6) ++cached_with_both;
    }
    // The trap is set only if some cached frame sees both in front of the camera.
    EXPECT_GT(cached_with_both, 0);
}

/// Keys order as depths do across zero: a cached window's keys may be negative.
TEST(CatgsDepthOrder, SortKeysOrderNegativeDepthsFirst) {
    const std::vector<float> depths{-1e30f, -5.0f, -1.0f, -1e-30f, -0.0f, 0.0f, 1e-30f, 1e-3f, 0.2f, 1.0f, 3e38f};
    for (std::size_t i = 0; i + 1 < depths.size(); ++i) {
        EXPECT_LE(make_sort_key(7, depths[i]), make_sort_key(7, depths[i + 1])) << depths[i] << " " << depths[i + 1];
        EXPECT_LT(make_sort_key(6, depths[i + 1]), make_sort_key(7, depths[i])) << "the tile comes first";
    }
    for (float d : depths) EXPECT_EQ(depth_of_key(make_sort_key(7, d)), d) << d;
}

}  // namespace
}  // namespace catgs
