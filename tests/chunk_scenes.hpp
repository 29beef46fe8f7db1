// Scenes, cameras and paths for the chunk-culling tests, shared by the CPU (test_chunks.cpp)
// and the CUDA (gpu/test_cuda_chunks.cpp) suites.
#pragma once

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/scene.hpp"
#include "catgs/scene_ops.hpp"
#include "test_util.hpp"

namespace catgs::test::chunks {

/// Gaussians all around a camera near the middle, a few of them huge (metres across, some
/// containing the camera), several chunks' worth.
inline Scene surrounding_scene(std::uint64_t seed, std::size_t count = 30000) {
    RandomSceneParams p;
    p.count = count;
    p.sh_degree = 1;
    p.extent = 60.0;
    p.depth_min = -60.0;
    p.depth_max = 60.0;
    p.log_scale_min = -3.0;
    p.log_scale_max = 0.0;
    Scene s = random_scene(seed, p);
    std::mt19937_64 rng(seed ^ 0x9e3779b97f4a7c15ull);
    std::uniform_int_distribution<std::size_t> pick(0, count - 1);
    for (int k = 0; k < 4; ++k) {
        const std::size_t i = pick(rng);
        for (int a = 0; a < 3; ++a) s.scales[3 * i + a] = static_cast<float>(2.0 + 2.0 * k);
    }
    s.update_bounds();
    partition_into_chunks(s);
    return s;
}

/// One chunk per Gaussian: the chunk test then decides for each Gaussian alone, so a test
/// that is too tight anywhere (the radius growth, the margin, the guards) drops a Gaussian
/// that a tile needs, where the kChunkGaussians-sized boxes of a real partition would hide it.
inline Scene single_gaussian_chunks(Scene s) {
    s.chunks.clear();
    for (std::uint32_t i = 0; i < s.count(); ++i) s.chunks.push_back(Chunk{.begin = i, .end = i + 1});
    s.update_chunk_bounds();
    return s;
}

/// A random camera inside the scene: random direction, field of view 20..150 degrees, an
/// off-centre principal point.
inline Camera random_camera(std::mt19937_64& rng, int width = 90, int height = 61, double eye_range = 10.0) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const std::array<double, 3> eye{(2 * u(rng) - 1) * eye_range, (2 * u(rng) - 1) * eye_range,
                                    (2 * u(rng) - 1) * eye_range};
    std::normal_distribution<double> n(0.0, 1.0);
    const std::array<double, 3> target{eye[0] + n(rng), eye[1] + n(rng), eye[2] + n(rng)};
    Camera c;
    c.intrinsics = intrinsics_from_fov(width, height, 20.0 + 130.0 * u(rng));
    c.intrinsics.cx += (u(rng) - 0.5) * 0.4 * width;
    c.intrinsics.cy += (u(rng) - 0.5) * 0.4 * height;
    c.pose = look_at(eye, target, {0, 1, 0});
    return c;
}

/// A hollow version of surrounding_scene, nothing within 12 m of the origin, in single-Gaussian
/// chunks: for cameras near the origin a jitter of centimetres moves footprints by a fraction
/// of a pixel, so that frames stay cached.
inline Scene hollow_scene(std::uint64_t seed, std::size_t count = 5000) {
    Scene scene = surrounding_scene(seed, count);
    for (std::size_t i = 0; i < scene.count(); ++i) {
        float* p = &scene.positions[3 * i];
        const float r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        if (r > 0)
            for (int a = 0; a < 3; ++a) p[a] *= (r + 12.0f) / r;
    }
    scene.update_bounds();
    return single_gaussian_chunks(scene);
}

/// 12 frames from a random camera near the origin: constant velocity and yaw rate, with a
/// jitter off the constant-velocity prediction inside the envelope's 0.25 m guard, so that
/// cached frames rely on the guard.
inline std::vector<Camera> jittered_path(std::mt19937_64& rng) {
    const Camera cam = random_camera(rng, 90, 61, 1.0);
    std::vector<Camera> frames;
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const std::array<double, 3> step{0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng)};
    const double turn = 0.01 * u(rng);
    for (int f = 0; f < 12; ++f) {
        Camera c = cam;
        std::array<double, 3> eye = camera_centre(cam.pose);
        for (int a = 0; a < 3; ++a) eye[a] += f * step[a] + 0.02 * u(rng);
        // Yaw about the camera's own y axis: world-to-camera R' = Ry(turn f) R.
        const double cs = std::cos(turn * f), sn = std::sin(turn * f);
        const std::array<double, 9>& r = cam.pose.rotation;
        const double ry[9] = {cs, 0, sn, 0, 1, 0, -sn, 0, cs};
        std::array<double, 9> camera_to_world{};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 3; ++k) camera_to_world[3 * j + i] += ry[3 * i + k] * r[3 * k + j];
        c.pose = pose_from_centre(eye, camera_to_world);
        frames.push_back(c);
    }
    return frames;
}

}  // namespace catgs::test::chunks
