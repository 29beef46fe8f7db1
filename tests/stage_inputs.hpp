// Random inputs for the stage-function tests: the host tests (test_stage_math.cpp,
// test_stage_tiles.cpp) check each stage function against a double reference, the device
// tests (gpu/test_stage_math_device.cu) run the same functions in tiny kernels on the same
// kind of inputs and compare bit for bit.
// C++17 and host-only, so that nvcc compiles it for the device test.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/math.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"

namespace catgs::test::stage {

/// Gaussians as the scene stores them: activated, in flat arrays (GaussianRef points into them).
struct GaussianArrays {
    std::vector<float> positions, scales, rotations, opacities;
    std::size_t count() const { return opacities.size(); }
    GaussianRef ref(std::size_t i) const {
        return {&positions[3 * i], &scales[3 * i], &rotations[4 * i], opacities[i], nullptr, 0};
    }
};

inline double uniform(std::mt19937_64& rng, double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng);
}
inline double log_uniform(std::mt19937_64& rng, double lo, double hi) {
    return std::exp(uniform(rng, std::log(lo), std::log(hi)));
}

/// A camera of 33..1500 x 17..900 pixels (partial tiles), a 20..120 degree field of view, the
/// principal point off centre, at a random position looking in a random direction.
inline Camera random_camera(std::mt19937_64& rng) {
    const int width = static_cast<int>(uniform(rng, 33, 1500)), height = static_cast<int>(uniform(rng, 17, 900));
    Camera c;
    c.intrinsics = intrinsics_from_fov(width, height, uniform(rng, 20, 120));
    c.intrinsics.cx += uniform(rng, -0.2, 0.2) * width;
    c.intrinsics.cy += uniform(rng, -0.2, 0.2) * height;
    const std::array<double, 3> eye{uniform(rng, -50, 50), uniform(rng, -50, 50), uniform(rng, -5, 30)};
    std::normal_distribution<double> n(0, 1);
    const std::array<double, 3> target{eye[0] + n(rng), eye[1] + n(rng), eye[2] + n(rng)};
    c.pose = look_at(eye, target, {0, 0, 1});
    return c;
}

/// `count` Gaussians around the camera's line of sight, at 0.05 .. 200 m (some behind it),
/// up to twice the field of view off axis, scales 1e-4 .. 30 m with a few needles and discs,
/// unit quaternions, opacities 1e-3 .. 1.
inline GaussianArrays random_gaussians(std::mt19937_64& rng, std::size_t count, const Camera& camera) {
    GaussianArrays g;
    const Intrinsics& k = camera.intrinsics;
    const std::array<double, 3> centre = camera_centre(camera.pose);
    const auto& r = camera.pose.rotation;  // world to camera: rows are the camera axes
    std::normal_distribution<double> n(0, 1);
    for (std::size_t i = 0; i < count; ++i) {
        const double z = uniform(rng, 0, 1) < 0.05 ? -uniform(rng, 0, 5) : log_uniform(rng, 0.05, 200);
        const double u = uniform(rng, -0.5, 1.5) * k.width, v = uniform(rng, -0.5, 1.5) * k.height;
        const double xc = (u - k.cx) / k.fx * std::fabs(z), yc = (v - k.cy) / k.fy * std::fabs(z);
        for (int a = 0; a < 3; ++a)
            g.positions.push_back(static_cast<float>(centre[a] + r[a] * xc + r[3 + a] * yc + r[6 + a] * z));
        std::array<double, 3> s{log_uniform(rng, 1e-4, 30), log_uniform(rng, 1e-4, 30), log_uniform(rng, 1e-4, 30)};
        if (uniform(rng, 0, 1) < 0.1) s[1] = s[2] = 1e-6 * s[0];  // needle
        if (uniform(rng, 0, 1) < 0.1) s[0] = 1e-7 * s[1];         // disc
        for (double v3 : s) g.scales.push_back(static_cast<float>(v3));
        double q[4], norm = 0;
        for (double& c : q) {
            c = n(rng);
            norm += c * c;
        }
        for (double c : q) g.rotations.push_back(static_cast<float>(c / std::sqrt(norm)));
        g.opacities.push_back(static_cast<float>(log_uniform(rng, 1e-3, 1.0)));
    }
    return g;
}

/// A projected Gaussian as the tile stage sees it, built from a 2D covariance (pixels^2)
/// whose conic is formed in double and rounded to T: mean anywhere from 30% of the image
/// before to 30% past it, axes 0.05 .. 200 px at any angle plus the blur, opacity 1e-3 .. 1.
template <typename T>
Projected<T> random_projected(std::mt19937_64& rng, int width, int height) {
    const double sa = log_uniform(rng, 0.05, 200), sb = log_uniform(rng, 0.05, 200), angle = uniform(rng, 0, 3.14159);
    const double c = std::cos(angle), s = std::sin(angle);
    const double xx = c * c * sa * sa + s * s * sb * sb + kCovarianceBlur;
    const double xy = c * s * (sa * sa - sb * sb);
    const double yy = s * s * sa * sa + c * c * sb * sb + kCovarianceBlur;
    const double det = xx * yy - xy * xy;
    Projected<T> p{};
    p.mean = {static_cast<T>(uniform(rng, -0.3, 1.3) * width), static_cast<T>(uniform(rng, -0.3, 1.3) * height)};
    p.cov = {static_cast<T>(xx), static_cast<T>(xy), static_cast<T>(yy)};
    p.conic = {static_cast<T>(yy / det), static_cast<T>(-xy / det), static_cast<T>(xx / det)};
    p.opacity = static_cast<T>(log_uniform(rng, 1e-3, 1.0));
    p.depth = static_cast<T>(log_uniform(rng, 0.2, 500));
    p.key_depth = static_cast<float>(p.depth);
    p.colour = {T(0), T(0), T(0)};
    return p;
}

/// The image and tile grid of a view, all the tile stage reads of it (the pose is left zero).
template <typename T>
View<T> image_view(int width, int height) {
    View<T> view{};
    view.width = width;
    view.height = height;
    view.tiles_x = tiles_for(width);
    view.tiles_y = tiles_for(height);
    return view;
}

/// The same projected Gaussian in double: what the double pipeline would get from the float one.
inline Projected<double> widened(const Projected<float>& p) {
    Projected<double> d{};
    d.mean = {p.mean.x, p.mean.y};
    d.conic = {p.conic.x, p.conic.y, p.conic.z};
    d.cov = {p.cov.x, p.cov.y, p.cov.z};
    d.colour = {p.colour.x, p.colour.y, p.colour.z};
    d.opacity = p.opacity;
    d.depth = p.depth;
    d.key_depth = p.key_depth;
    return d;
}

/// Positive float depths across the whole range: denormals, the near plane, ordinary depths,
/// huge ones up to the largest finite float, and exact repeats (ties).
inline std::vector<float> random_depths(std::mt19937_64& rng, std::size_t count) {
    std::vector<float> out;
    for (std::size_t i = 0; i < count; ++i) {
        const double pick = uniform(rng, 0, 1);
        float d;
        if (pick < 0.05f) {
            d = std::numeric_limits<float>::denorm_min() * static_cast<float>(uniform(rng, 1, 1000));
        } else if (pick < 0.1) {
            d = std::numeric_limits<float>::max() / static_cast<float>(uniform(rng, 1, 1000));
        } else if (pick < 0.2 && !out.empty()) {
            d = out[static_cast<std::size_t>(uniform(rng, 0, static_cast<double>(out.size())))];
        } else {
            d = static_cast<float>(log_uniform(rng, 1e-30, 1e30));
        }
        out.push_back(d);
    }
    return out;
}

/// A sub-task's slice [begin, end) of a pixel's list blended from T = 1 by the rasterizer's
/// blend (power 0, so alpha is the opacity), without the early stop: the partial (R, A) a
/// sub-task of a split tile writes. `colours` holds one RGB triple per entry.
template <typename T>
Partial<T> blend_slice(const std::vector<T>& alphas, const std::vector<T>& colours, std::size_t begin,
                       std::size_t end) {
    PixelAccumulator<T> acc;
    for (std::size_t i = begin; i < end; ++i)
        blend_power(acc, T(0), alphas[i], Vec3<T>{colours[3 * i], colours[3 * i + 1], colours[3 * i + 2]}, T(0));
    return {acc.colour, acc.transmittance};
}

/// Whether two values have the same bits (NaN equal to itself, -0 unlike +0).
template <typename T>
bool same_bits(T a, T b) {
    return std::memcmp(&a, &b, sizeof(T)) == 0;
}

}  // namespace catgs::test::stage
