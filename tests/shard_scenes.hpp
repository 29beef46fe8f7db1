// Scenes and cameras of the sharded-frame tests of both backends (tests/test_shards.cpp,
// tests/gpu/test_cuda_shards.cpp).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_ops.hpp"
#include "test_util.hpp"

namespace catgs::test {

/// Separated clusters on a 2x2x2 grid, 4 m apart with extents under 0.3 m, in front of
/// forward_camera: no Gaussian straddles a shard plane, so k shards composite to the unsharded
/// frame up to float rounding. Opacities stay low enough that no pixel nears the stop at
/// T = 1e-4, where a back shard, which starts its blend at T = 1, would go on blending.
inline Scene separated_clusters(std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    RandomSceneParams p;
    p.count = 8 * 1100;
    p.sh_degree = 1;
    Scene scene = random_scene(rng(), p);
    for (std::size_t i = 0; i < scene.count(); ++i) {
        const std::size_t cluster = i % 8;
        const float centre[3] = {cluster & 1 ? 2.0f : -2.0f, cluster & 2 ? 2.0f : -2.0f, cluster & 4 ? 11.0f : 7.0f};
        for (int a = 0; a < 3; ++a) {
            scene.positions[3 * i + a] = centre[a] + static_cast<float>((2 * u(rng) - 1) * 0.5);
            scene.scales[3 * i + a] = static_cast<float>(std::exp(-5.0 + 2.0 * u(rng)));  // <= 0.05 m
        }
        scene.opacities[i] = static_cast<float>(0.02 + 0.2 * u(rng));
    }
    scene.update_bounds();
    partition_into_chunks(scene);
    return scene;
}

/// Random scenes' cameras (random_scene puts them in front of forward_camera): head-on, and
/// from the side at an angle, so that every axis of the plan's planes is seen from both sides
/// across the tests.
inline std::vector<Camera> random_scene_cameras(int width, int height, double fov) {
    std::vector<Camera> cameras{forward_camera(width, height, fov)};
    Camera side;
    side.intrinsics = intrinsics_from_fov(width, height, fov);
    side.pose = look_at({9, -4, 1}, {0, 0, 7}, {0, -1, 0});
    cameras.push_back(side);
    return cameras;
}

/// The separated clusters seen from below, behind and to the side: every plane from its other
/// side than forward_camera sees it.
inline Camera oblique_cluster_camera(int width, int height, double fov) {
    Camera oblique;
    oblique.intrinsics = intrinsics_from_fov(width, height, fov);
    oblique.pose = look_at({-6, -5, -4}, {0, 0, 9}, {0, -1, 0});
    return oblique;
}

}  // namespace catgs::test
