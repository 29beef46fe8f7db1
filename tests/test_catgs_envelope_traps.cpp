// The cache's envelope (envelope.hpp, cache.hpp) on two scripted traps an adversarial review
// found, where a cached frame lacked a Gaussian the per-frame pipeline draws: a tiny Gaussian
// half a metre from the camera, beyond the Jacobian clamp region at every pose of the window,
// that a 0.2 m jerk brings into view (the envelope once took whatever lay beyond the clamp
// region as unable to enter); and one outside the image at the window's later poses and far
// outside at the key pose, that a small swerve near a later pose brings in (the envelope once
// asked only the key pose what could enter). Both fly over a ground 50 m away, whose depth
// alone would let the planner accept those frames.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/render_options.hpp"
#include "catgs_paths.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 160, kHeight = 90;
constexpr double kFovDegrees = 70.0;
constexpr double kGroundDepth = 50.0;

/// A Gaussian of the traps: isotropic, axis-aligned, red on a grey ground.
void add_gaussian(Scene& s, std::array<double, 3> position, double scale, double opacity, bool red) {
    const std::size_t n = s.count();
    s.resize(n + 1);
    for (int a = 0; a < 3; ++a) {
        s.positions[3 * n + a] = static_cast<float>(position[a]);
        s.scales[3 * n + a] = static_cast<float>(scale);
    }
    s.rotations[4 * n] = 1.0f;
    s.opacities[n] = static_cast<float>(opacity);
    const std::size_t stride = s.sh_floats_per_gaussian();
    for (int c = 0; c < 3; ++c) s.sh[stride * n + c] = red ? (c == 0 ? 1.5f : -1.5f) : 0.2f * static_cast<float>(c);
}

/// A ground of large Gaussians kGroundDepth ahead of cameras looking down +z, over x, y in
/// [-span, span], and the trap.
Scene ground_with(std::array<double, 3> trap, double trap_scale, double span, double ground_depth = kGroundDepth) {
    Scene s;
    s.sh_degree = 0;
    for (double x = -span; x <= span; x += 3.0)
        for (double y = -20.0; y <= 20.0; y += 3.0) add_gaussian(s, {x, y, ground_depth}, 1.5, 0.9, false);
    add_gaussian(s, trap, trap_scale, 0.99, true);
    s.update_bounds();
    return s;
}

Camera camera_at(std::array<double, 3> centre, int frame) {
    Camera c;
    c.intrinsics = intrinsics_from_fov(kWidth, kHeight, kFovDegrees);
    c.pose = pose_from_centre(centre, {1, 0, 0, 0, 1, 0, 0, 0, 1});
    c.timestamp = frame / 30.0;
    return c;
}

/// The cache at a fixed window of `window` frames (so the traps' windows fall where they are
/// built), split off: every cached frame against the per-frame pipeline, pair by pair.
std::uint64_t missing_over(const Scene& scene, const std::vector<Camera>& path, int window,
                           std::vector<int>* key_frames = nullptr) {
    RenderOptions options = default_pipeline_options();
    options.catgs.adaptive_window = false;
    options.catgs.window = window;
    options.catgs.split_k = 0;
    RenderOptions full_options;
    CpuRenderer<float> cached, full;
    ImageF a, b;
    std::uint64_t missing = 0;
    for (std::size_t i = 0; i < path.size(); ++i) {
        const FrameStats s = cached.render(scene, path[i], options, a);
        full.render(scene, path[i], full_options, b);
        if (s.key_frame) {
            if (key_frames) key_frames->push_back(static_cast<int>(i));
            continue;
        }
        const std::uint64_t m = test::missing_pairs(cached, full);
        EXPECT_EQ(m, 0u) << "frame " << i << " (W " << s.window << ")";
        missing += m;
    }
    return missing;
}

TEST(CatgsEnvelopeTraps, AJerkBringsInAGaussianFromBeyondTheClampRegion) {
    const Intrinsics k = intrinsics_from_fov(kWidth, kHeight, kFovDegrees);
    // 0.5 m ahead at pixel column 190 of 160 at rest: beyond the clamp region (15% past the
    // image); 0.2 m of sideways jerk puts it at column 144.
    const double depth = 0.5, x = (190.0 - k.cx) / k.fx * depth;
    const Scene scene = ground_with({x, 0.0, depth}, 0.005, 24.0);
    std::vector<Camera> path;
    for (int i = 0; i < 12; ++i) path.push_back(camera_at({0, 0, 0}, i));  // hover
    for (int i = 12; i < 16; ++i) path.push_back(camera_at({0.2, 0, 0}, i));
    std::vector<int> keys;
    EXPECT_EQ(missing_over(scene, path, 16, &keys), 0u);
    EXPECT_EQ(keys.front(), 0);
    EXPECT_TRUE(keys.size() < 2 || keys[1] >= 12) << "the hover itself should be drawn from the cache";
}

TEST(CatgsEnvelopeTraps, AStepBackBringsInAGaussianBehindTheNearPlane) {
    // 2 cm behind the camera while it hovers; a 0.24 m step back puts it 0.22 m ahead, past
    // the 0.2 m near plane, on the optical axis.
    const Scene scene = ground_with({0.0, 0.0, -0.02}, 0.01, 120.0, 300.0);
    std::vector<Camera> path;
    for (int i = 0; i < 12; ++i) path.push_back(camera_at({0, 0, 0}, i));
    for (int i = 12; i < 16; ++i) path.push_back(camera_at({0, 0, -0.24}, i));
    std::vector<int> keys;
    EXPECT_EQ(missing_over(scene, path, 16, &keys), 0u);
    EXPECT_EQ(keys.front(), 0);
}

TEST(CatgsEnvelopeTraps, ASwerveNearALaterPoseBringsInAGaussianTheKeyPoseCannotReach) {
    const Intrinsics k = intrinsics_from_fov(kWidth, kHeight, kFovDegrees);
    // The camera flies along +x at 0.6 m a frame. Frame 0 knows no velocity and frame 1 leaves
    // its envelope, so windows of 4 start at frames 1 and 5. The trap, 1 m ahead, is at the
    // image's centre column at frame 7 but 8 px below its bottom edge, and 1.2 m to the side
    // (column 217, beyond the clamp region) at the key frame 5. Frame 7 swerves 0.1 m towards
    // it, which puts it inside the image.
    const double step = 0.6, depth = 1.0;
    const double below = (kHeight + 8.0 - k.cy) / k.fy * depth;
    const Scene scene = ground_with({7 * step, below, depth}, 0.01, 30.0);
    std::vector<Camera> path;
    for (int i = 0; i < 10; ++i) path.push_back(camera_at({i * step, i == 7 ? 0.1 : 0.0, 0}, i));
    std::vector<int> keys;
    EXPECT_EQ(missing_over(scene, path, 4, &keys), 0u);
    EXPECT_EQ(std::vector<int>(keys.begin(), keys.begin() + std::min<std::size_t>(keys.size(), 3)),
              (std::vector<int>{0, 1, 5}))
        << "the trap is set for a window starting at frame 5";
}

}  // namespace
}  // namespace catgs
