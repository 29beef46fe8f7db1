// The scenes of stress_scenes.hpp for the targeted tests (single Gaussians, the cache
// envelope, large images), apart from the families in stress_scenes.cpp.
#include <algorithm>
#include <cmath>
#include <utility>

#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "stress_scenes.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

// --- Single Gaussians ------------------------------------------------------------------

Scene one_gaussian(std::array<float, 3> p, std::array<float, 3> s, std::array<float, 4> q, float opacity,
                   std::array<float, 3> dc, int sh_degree, float sh_value) {
    Gaussian g;
    g.position = p;
    g.scale = s;
    g.rotation = q;
    g.opacity = opacity;
    g.dc = dc;
    Scene scene = empty_scene(sh_degree);
    if (sh_degree > 0) g.sh.assign(scene.sh_floats_per_gaussian(), sh_value);
    add(scene, g);
    scene.update_bounds();
    return scene;
}

// --- Cache envelope ------------------------------------------------------------------

StressCase needles_and_discs_end_on(std::uint64_t seed) {
    const Camera cam = forward_camera(160, 96, 60);
    Scene scene = empty_scene(0);
    Draw d(seed);
    for (int i = 0; i < 30; ++i) add(scene, d.ordinary(3, 12));
    for (int i = 0; i < 12; ++i) {
        Gaussian g = d.ordinary();
        const float z = 2.0f + 0.1f * static_cast<float>(i);
        g.position = {(-0.6f + 0.4f * static_cast<float>(i % 4)) * z, (-0.3f + 0.3f * static_cast<float>(i / 4)) * z,
                      z};
        // Squared in float, unlike direction_to: a seed logged by earlier runs replays the same scene.
        const double n =
            std::sqrt(g.position[0] * g.position[0] + g.position[1] * g.position[1] + g.position[2] * g.position[2]);
        const std::array<double, 3> ray{g.position[0] / n, g.position[1] / n, g.position[2] / n};
        if (i % 2 == 0) {
            g.scale = {30.0f, 1e-3f, 1e-3f};  // needle along the line of sight
            g.rotation = quaternion_x_to(ray);
        } else {
            const std::array<double, 3> normal{ray[1], -ray[0], 0};
            const double m = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1]);
            g.scale = {1e-4f, 8.0f, 8.0f};  // disc seen edge-on
            g.rotation = quaternion_x_to({normal[0] / m, normal[1] / m, 0});
        }
        g.opacity = 0.9f;
        add(scene, g);
    }
    scene.update_bounds();
    return {"needles and discs end-on", Family::degenerate, std::move(scene), short_path(cam, 0.005, 0.0, 8)};
}

StressCase near_gaussian_outside_the_image(std::uint64_t seed) {
    const Camera cam = forward_camera(72, 40, 60);
    Scene scene = empty_scene(0);
    Draw d(seed);
    for (int i = 0; i < 40; ++i) add(scene, d.ordinary(8, 12));
    Gaussian near;
    const double z = 0.3, u = cam.intrinsics.width + 6.0, v = d.uniform(5, 35);
    near.position = {static_cast<float>((u - cam.intrinsics.cx) / cam.intrinsics.fx * z),
                     static_cast<float>((v - cam.intrinsics.cy) / cam.intrinsics.fy * z), static_cast<float>(z)};
    near.scale = {0.002f, 0.002f, 0.002f};
    near.opacity = 0.95f;
    near.dc = {2, 2, -1};
    add(scene, near);
    scene.update_bounds();
    return {"near gaussian outside the image", Family::image_border, std::move(scene), short_path(cam, 0.05, 0.0, 4)};
}

// --- Large images ---------------------------------------------------------------------

Scene local_gaussians(std::uint64_t seed, const Camera& cam, int count) {
    Draw d(seed);
    const Intrinsics& k = cam.intrinsics;
    Scene scene = empty_scene(1);
    for (int i = 0; i < count; ++i) {
        const double u =
            d.pick(std::vector<double>{0.0, 16.0, d.uniform(0, k.width), 0.5 * k.width, k.width - 16.0, 1.0 * k.width});
        const double v = d.pick(std::vector<double>{0.0, d.uniform(0, k.height), 0.5 * k.height, 1.0 * k.height});
        const double z = d.uniform(0.3, 50), sigma_px = d.log_uniform(0.3, 40);
        Gaussian g = d.ordinary();
        g.position = {static_cast<float>((u - k.cx) / k.fx * z), static_cast<float>((v - k.cy) / k.fy * z),
                      static_cast<float>(z)};
        for (float& sc : g.scale) sc = static_cast<float>(sigma_px * z / k.fx * d.uniform(0.5, 1.5));
        switch (i % 4) {
            case 0:
                g.opacity = 1.0f;
                break;
            case 1:
                g.scale[0] = 1e-12f;
                break;
            case 2:
                g.scale = {0, 0, 0};
                break;
            default:
                break;
        }
        add(scene, g);
    }
    scene.update_bounds();
    return scene;
}

std::vector<std::array<int, 4>> footprint_boxes(const Scene& scene, const Camera& cam, int margin) {
    const View<double> view = make_view<double>(cam, scene.origin);
    const int w = cam.intrinsics.width, h = cam.intrinsics.height;
    std::vector<std::array<int, 4>> boxes;
    const std::size_t stride = scene.sh_floats_per_gaussian();
    for (std::size_t i = 0; i < scene.count(); ++i) {
        const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i],  &scene.rotations[4 * i],
                            scene.opacities[i],      &scene.sh[stride * i], scene.sh_degree};
        Projected<double> p;
        if (!project_gaussian(g, view, p)) continue;
        const Vec2<double> e = footprint_extent(p, Culling::opacity_aware);
        if (!(e.x >= 0)) continue;
        auto clampi = [](double v, int hi) {
            return static_cast<int>(std::min(std::max(v, 0.0), static_cast<double>(hi)));
        };
        const std::array<int, 4> b{
            clampi(std::floor(p.mean.x - e.x) - margin, w), clampi(std::floor(p.mean.y - e.y) - margin, h),
            clampi(std::ceil(p.mean.x + e.x) + margin, w), clampi(std::ceil(p.mean.y + e.y) + margin, h)};
        if (b[2] > b[0] && b[3] > b[1]) boxes.push_back(b);
    }
    for (bool merged = true; merged;) {
        merged = false;
        for (std::size_t a = 0; a < boxes.size() && !merged; ++a)
            for (std::size_t b = a + 1; b < boxes.size() && !merged; ++b) {
                auto& p = boxes[a];
                const auto& q = boxes[b];
                if (p[0] < q[2] && q[0] < p[2] && p[1] < q[3] && q[1] < p[3]) {
                    p = {std::min(p[0], q[0]), std::min(p[1], q[1]), std::max(p[2], q[2]), std::max(p[3], q[3])};
                    boxes.erase(boxes.begin() + static_cast<std::ptrdiff_t>(b));
                    merged = true;
                }
            }
    }
    return boxes;
}

Camera crop_camera(const Camera& cam, const std::array<int, 4>& box) {
    Camera crop = cam;
    crop.intrinsics.width = box[2] - box[0];
    crop.intrinsics.height = box[3] - box[1];
    crop.intrinsics.cx = cam.intrinsics.cx - box[0];
    crop.intrinsics.cy = cam.intrinsics.cy - box[1];
    return crop;
}

}  // namespace catgs::test::stress
