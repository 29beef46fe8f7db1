// scene_origin (catgs/scene.hpp): positions are float offsets from a double origin, the
// centre of the bounds unless a few stray Gaussians set the bounds; then the bulk's centre, so
// that one floater 10^7 m out does not round every other Gaussian's position to half a metre.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

#include "catgs/cpu_renderer.hpp"
#include "catgs/image.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_io.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

Bounds bounds_of(const std::vector<std::array<double, 3>>& world) {
    Bounds b;
    for (int a = 0; a < 3; ++a) {
        b.min[a] = b.max[a] = world.front()[a];
        for (const auto& w : world) {
            b.min[a] = std::min(b.min[a], w[a]);
            b.max[a] = std::max(b.max[a], w[a]);
        }
    }
    return b;
}

std::array<double, 3> origin_of(const std::vector<std::array<double, 3>>& world) {
    return scene_origin(bounds_of(world), world.size(), [&](std::size_t i, int a) { return world[i][a]; });
}

/// `n` points uniform in the box [lo, hi] of every axis.
std::vector<std::array<double, 3>> bulk(std::mt19937_64& rng, std::size_t n, double lo, double hi) {
    std::uniform_real_distribution<double> u(lo, hi);
    std::vector<std::array<double, 3>> world(n);
    for (auto& w : world) w = {u(rng), u(rng), u(rng)};
    return world;
}

TEST(SceneOrigin, ANormalSceneKeepsTheCentreOfItsBounds) {
    std::mt19937_64 rng(test::fresh_seed("origin normal"));
    auto world = bulk(rng, 5000, -50.0, 50.0);
    // A town's towers: 2% of the points reach 6 times the bulk's height.
    for (std::size_t i = 0; i < world.size(); i += 50) world[i][2] = 300.0 * (static_cast<double>(i) / 5000.0);
    const Bounds b = bounds_of(world);
    const std::array<double, 3> origin = origin_of(world);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(origin[a], 0.5 * (b.min[a] + b.max[a])) << "axis " << a;
}

TEST(SceneOrigin, AStrayGaussianLeavesTheOriginInTheBulkOnItsAxisOnly) {
    std::mt19937_64 rng(test::fresh_seed("origin stray"));
    auto world = bulk(rng, 3000, 4.0e6, 4.0e6 + 80.0);
    world[1234][0] = 4.0e6 + 1.0e7;  // one floater far out along x
    const Bounds b = bounds_of(world);
    const std::array<double, 3> origin = origin_of(world);
    EXPECT_GE(origin[0], 4.0e6);
    EXPECT_LE(origin[0], 4.0e6 + 80.0);
    for (int a = 1; a < 3; ++a) EXPECT_EQ(origin[a], 0.5 * (b.min[a] + b.max[a])) << "axis " << a;
}

TEST(SceneOrigin, AFlatBulkWithAStrayTakesTheBulksPlane) {
    std::mt19937_64 rng(test::fresh_seed("origin flat"));
    auto world = bulk(rng, 400, -10.0, 10.0);
    for (auto& w : world) w[2] = 120.5;
    world[7][2] = -3.0e6;
    EXPECT_EQ(origin_of(world)[2], 120.5);
}

TEST(SceneOrigin, RecentreChoosesAsTheLoadersDo) {
    Scene s = test::random_scene(test::fresh_seed("origin recentre"));
    s.positions[0] = 2.0e7f;
    s.recentre();
    EXPECT_LT(std::abs(s.origin[0]), 10.0) << "the bulk lies within 4 m of the world origin";
    EXPECT_FLOAT_EQ(s.positions[0], static_cast<float>(2.0e7 - s.origin[0]));
}

template <typename T>
ImageRGB8 render_rgb8(const Scene& scene, const Camera& camera) {
    CpuRenderer<T> renderer(0);
    ImageF out;
    renderer.render(scene, camera, RenderOptions{}, out);
    return to_rgb8(out);
}

/// The image of `loaded` with its origin moved back to the centre of its bounds, as loaders
/// chose it before scene_origin: the control that shows the loaded check can fail.
Scene at_bounds_centre(Scene s) {
    std::array<double, 3> centre;
    for (int a = 0; a < 3; ++a) centre[a] = 0.5 * (s.bounds.min[a] + s.bounds.max[a]);
    for (std::size_t i = 0; i < s.count(); ++i)
        for (int a = 0; a < 3; ++a)
            s.positions[3 * i + a] =
                static_cast<float>(s.origin[a] + static_cast<double>(s.positions[3 * i + a]) - centre[a]);
    s.origin = centre;
    s.update_bounds();
    s.update_chunk_bounds();
    return s;
}

// A capture of 600 Gaussians and one floater 10^7 m to the side, out of view, through a PLY:
// loaded, it renders as the capture alone does, in float and double; with the origin at the
// centre of its bounds, both miss by tens of levels.
TEST(SceneOrigin, ALoadedSceneWithAFarStrayRendersLikeTheSceneWithout) {
    test::RandomSceneParams p;
    p.count = 600;
    p.log_scale_min = -3.5;
    const Scene capture = test::random_scene(test::fresh_seed("origin loaded"), p);
    const Camera camera = test::forward_camera(96, 64, 70.0, {0.3, -0.2, 0.1});
    Scene with_stray = capture;
    with_stray.resize(capture.count() + 1);  // resize keeps the leading values
    const std::size_t last = capture.count();
    for (int a = 0; a < 3; ++a) with_stray.scales[3 * last + a] = 0.05f;
    with_stray.positions[3 * last] = 1.0e7f;
    with_stray.positions[3 * last + 1] = 0.0f;
    with_stray.positions[3 * last + 2] = 5.0f;
    with_stray.rotations[4 * last] = 1.0f;
    with_stray.opacities[last] = 0.5f;
    with_stray.update_bounds();
    const std::string path =
        (std::filesystem::temp_directory_path() / ("catgs-origin-" + std::to_string(::getpid()) + ".ply")).string();
    write_ply(with_stray, path);
    const Scene loaded = load_scene(path);
    std::filesystem::remove(path);
    ASSERT_EQ(loaded.count(), capture.count() + 1);
    EXPECT_LT(std::abs(loaded.origin[0]), 10.0) << "the capture lies within 4 m of the world origin";

    const ImageRGB8 reference = render_rgb8<double>(capture, camera);
    const ImageError single = compare(render_rgb8<float>(loaded, camera), reference);
    const ImageError twice = compare(render_rgb8<double>(loaded, camera), reference);
    EXPECT_LE(single.max_abs, 1) << "float, psnr " << single.psnr;
    EXPECT_LE(twice.max_abs, 1) << "double, psnr " << twice.psnr;

    const Scene centred = at_bounds_centre(loaded);
    const ImageError control = compare(render_rgb8<double>(centred, camera), reference);
    EXPECT_GT(control.max_abs, 20) << "at the centre of the bounds the positions round to 0.5 m";
}

}  // namespace
}  // namespace catgs
