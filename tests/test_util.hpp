// Shared helpers for the tests: fresh random seeds (logged, overridable with CATGS_TEST_SEED
// to reproduce a failure) and random scenes in front of a camera.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iostream>
#include <random>
#include <string>

#include "catgs/camera.hpp"
#include "catgs/error.hpp"
#include "catgs/render_options.hpp"
#include "catgs/scene.hpp"

namespace catgs::test {

/// Runs f and returns the catgs::Error message; fails the test on no exception or another type
/// (bad-input tests assert the message).
inline std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected catgs::Error, got another exception: " << e.what();
        return "";
    }
    ADD_FAILURE() << "expected catgs::Error, nothing was thrown";
    return "";
}

/// Folder of the shared test data: $CATGS_SHARED_DIR when set (GPU hosts get a carried
/// copy), else ../shared beside the checkout (compile-time CATGS_SHARED_DIR).
inline std::string shared_dir() {
    if (const char* env = std::getenv("CATGS_SHARED_DIR")) return env;
#ifdef CATGS_SHARED_DIR
    return CATGS_SHARED_DIR;
#else
    return "../shared";
#endif
}

/// A fresh seed for each call unless CATGS_TEST_SEED is set; printed so a failure can be
/// replayed.
inline std::uint64_t fresh_seed(const std::string& what) {
    std::uint64_t seed;
    if (const char* env = std::getenv("CATGS_TEST_SEED")) {
        seed = std::strtoull(env, nullptr, 10);
    } else {
        std::random_device rd;
        seed = (static_cast<std::uint64_t>(rd()) << 32) ^ rd();
    }
    std::cout << "[seed] " << what << ": CATGS_TEST_SEED=" << seed << std::endl;
    return seed;
}

struct RandomSceneParams {
    std::size_t count = 2000;
    int sh_degree = 3;
    double extent = 4.0;  ///< Gaussians in [-extent, extent]^2 x [depth_min, depth_max]
    double depth_min = 3.0, depth_max = 12.0;
    double log_scale_min = -4.0, log_scale_max = -1.0;
    double sh_rest_magnitude = 0.2;
};

/// Random Gaussians in front of a camera at the origin looking down +z. Positions are
/// relative to scene.origin = {0, 0, 0}; call shift_scene to move them.
inline Scene random_scene(std::uint64_t seed, const RandomSceneParams& p = {}) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    Scene s;
    s.sh_degree = p.sh_degree;
    s.resize(p.count);
    const std::size_t stride = s.sh_floats_per_gaussian();
    for (std::size_t i = 0; i < p.count; ++i) {
        s.positions[3 * i] = static_cast<float>((2 * u(rng) - 1) * p.extent);
        s.positions[3 * i + 1] = static_cast<float>((2 * u(rng) - 1) * p.extent);
        s.positions[3 * i + 2] = static_cast<float>(p.depth_min + u(rng) * (p.depth_max - p.depth_min));
        for (int a = 0; a < 3; ++a)
            s.scales[3 * i + a] =
                static_cast<float>(std::exp(p.log_scale_min + u(rng) * (p.log_scale_max - p.log_scale_min)));
        double q[4], n = 0;
        for (double& c : q) {
            c = normal(rng);
            n += c * c;
        }
        n = std::sqrt(n);
        for (int a = 0; a < 4; ++a) s.rotations[4 * i + a] = static_cast<float>(q[a] / n);
        s.opacities[i] = static_cast<float>(0.02 + 0.97 * u(rng));
        for (std::size_t k = 0; k < stride; ++k)
            s.sh[stride * i + k] =
                static_cast<float>(k < 3 ? (u(rng) - 0.5) * 3.0 : (2 * u(rng) - 1) * p.sh_rest_magnitude);
    }
    s.update_bounds();
    return s;
}

/// A camera at `centre` looking down world +z (identity rotation).
inline Camera forward_camera(int width, int height, double fov_x_degrees, std::array<double, 3> centre = {0, 0, 0}) {
    Camera c;
    c.intrinsics = intrinsics_from_fov(width, height, fov_x_degrees);
    c.pose = pose_from_centre(centre, {1, 0, 0, 0, 1, 0, 0, 0, 1});
    return c;
}

/// The speculative cache with a fixed W = 4 whose cached frames of an unmoved camera keep the
/// key frame's depth order and task list as they are, split at `split_k`: the scene of the
/// backends' twin tests of what a cached frame draws (CachedFrames...K in test_catgs_split.cpp
/// and gpu/test_cuda_catgs.cpp).
inline RenderOptions cached_list_options(std::uint32_t split_k) {
    RenderOptions o;
    o.catgs.cache = CacheMode::speculative;
    o.catgs.adaptive_window = false;
    o.catgs.window = 4;
    o.catgs.resort_cached = false;
    o.catgs.split_k = split_k;
    return o;
}

}  // namespace catgs::test
