// Adversarial scenes for the numerical stress suite (tests/test_stress.cpp on the CPU,
// tests/gpu/test_cuda_stress.cpp on the GPU). Header-only: each generator builds a
// catgs::Scene directly, with ACTIVATED values (linear scales, (w, x, y, z) quaternions,
// opacity in (0, 1]), because the values a loader would reject (NaN, zero quaternions) must
// still be survivable when a Scene holds them.
//
// Every generator takes a seed, so a failure replays with CATGS_TEST_SEED (test_util.hpp),
// and returns a StressCase: the scene, a short camera path (frame 0 is the single-frame
// camera; all six frames are rendered for the speculative cache) and its family, which
// selects the error bounds in the tests.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/math.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

/// The case families of the issue. Each has its own error bounds (test_stress.cpp).
enum class Family {
    tiny_scales,      ///< scales 1e-12 .. 1e-45 and 0 on some or all axes
    huge_scales,      ///< scales 1e3 .. 1e6, camera inside some of them
    quaternions,      ///< zero, NaN, inf, denormal and non-normalised quaternions
    opacities,        ///< logits +-100 (1.0f and 3.7e-44), exactly 1.0f, 1/255 +- 1 ulp, 0
    huge_sh,          ///< SH coefficients of magnitude 1e30 (both signs, every degree)
    extreme_sh,       ///< SH coefficients 1e38 (near float max), +inf, -inf, NaN
    near_plane,       ///< at the camera centre, 0.2 +- (1e-5 .. 1e-2), behind the camera
    image_border,     ///< means exactly on the image border and on tile boundaries
    far_away,         ///< 10^7 m from the camera, scales up to 1e5
    utm,              ///< scene origin and camera at 10^6 .. 10^7 m
    camera_inside,    ///< the camera inside large Gaussians whose mean is in front of it
    degenerate,       ///< 2D covariances that are rank one before the blur: 1e-20 x 1e-20 x 1,
                      ///< needles seen end-on, discs seen edge-on
    invalid,          ///< NaN / inf positions, scales, opacities
    ties,             ///< thousands of Gaussians at exactly the same depth
    field_of_view,    ///< a mixture seen at 5 .. 150 degrees
    mixture,          ///< random draws from every family above in one scene, SH 1e30 excluded
    hdr_mixture,      ///< the mixture with SH 1e30 colours included
};

inline const char* family_name(Family f) {
    switch (f) {
        case Family::tiny_scales: return "tiny_scales";
        case Family::huge_scales: return "huge_scales";
        case Family::quaternions: return "quaternions";
        case Family::opacities: return "opacities";
        case Family::huge_sh: return "huge_sh";
        case Family::extreme_sh: return "extreme_sh";
        case Family::near_plane: return "near_plane";
        case Family::image_border: return "image_border";
        case Family::far_away: return "far_away";
        case Family::utm: return "utm";
        case Family::camera_inside: return "camera_inside";
        case Family::degenerate: return "degenerate";
        case Family::invalid: return "invalid";
        case Family::ties: return "ties";
        case Family::field_of_view: return "field_of_view";
        case Family::mixture: return "mixture";
        case Family::hdr_mixture: return "hdr_mixture";
    }
    return "?";
}

inline constexpr float kInf = std::numeric_limits<float>::infinity();
inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// The activated opacity a loader computes from a logit, in float as it stores it:
/// sigmoid(100) rounds to exactly 1.0f, sigmoid(-100) to the denormal 3.7e-44f.
inline float activated_opacity(double logit) { return static_cast<float>(1.0 / (1.0 + std::exp(-logit))); }

/// One Gaussian, activated. `sh` (if not empty) holds every coefficient of the scene's
/// degree; otherwise DC = dc and every higher coefficient is `rest` with alternating sign.
struct Gaussian {
    std::array<float, 3> position{0, 0, 5};
    std::array<float, 3> scale{0.1f, 0.1f, 0.1f};
    std::array<float, 4> rotation{1, 0, 0, 0};
    float opacity = 0.8f;
    std::array<float, 3> dc{0, 0, 0};
    float rest = 0;
    std::vector<float> sh;
};

/// Appends a Gaussian to `s` (whose sh_degree is already set).
inline void add(Scene& s, const Gaussian& g) {
    s.positions.insert(s.positions.end(), g.position.begin(), g.position.end());
    s.scales.insert(s.scales.end(), g.scale.begin(), g.scale.end());
    s.rotations.insert(s.rotations.end(), g.rotation.begin(), g.rotation.end());
    s.opacities.push_back(g.opacity);
    const std::size_t stride = s.sh_floats_per_gaussian();
    if (!g.sh.empty()) {
        for (std::size_t k = 0; k < stride; ++k) s.sh.push_back(k < g.sh.size() ? g.sh[k] : 0.0f);
    } else {
        for (std::size_t k = 0; k < stride; ++k)
            s.sh.push_back(k < 3 ? g.dc[k] : ((k / 3) % 2 ? g.rest : -g.rest));
    }
}

/// Random draws for the generators.
class Draw {
public:
    explicit Draw(std::uint64_t seed) : rng_(seed) {}
    std::mt19937_64& rng() { return rng_; }
    double uniform(double lo = 0, double hi = 1) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
    double log_uniform(double lo, double hi) { return std::exp(uniform(std::log(lo), std::log(hi))); }
    int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }  // [lo, hi]
    bool chance(double p) { return uniform() < p; }
    template <typename V>
    const typename V::value_type& pick(const V& values) {
        return values[static_cast<std::size_t>(integer(0, static_cast<int>(values.size()) - 1))];
    }
    std::array<float, 4> unit_quaternion() {
        std::normal_distribution<double> n(0, 1);
        double q[4], norm = 0;
        for (double& c : q) {
            c = n(rng_);
            norm += c * c;
        }
        norm = std::sqrt(norm);
        return {static_cast<float>(q[0] / norm), static_cast<float>(q[1] / norm), static_cast<float>(q[2] / norm),
                static_cast<float>(q[3] / norm)};
    }
    std::array<float, 3> colour() {
        return {static_cast<float>(uniform(-1.5, 1.5)), static_cast<float>(uniform(-1.5, 1.5)),
                static_cast<float>(uniform(-1.5, 1.5))};
    }
    /// An ordinary Gaussian in the view frustum of a camera at the origin looking down +z
    /// (fov up to ~150 degrees): the background the adversarial ones interact with.
    Gaussian ordinary(double depth_min = 1.0, double depth_max = 12.0) {
        Gaussian g;
        const double z = uniform(depth_min, depth_max);
        g.position = {static_cast<float>(uniform(-0.8, 0.8) * z), static_cast<float>(uniform(-0.6, 0.6) * z),
                      static_cast<float>(z)};
        for (float& s : g.scale) s = static_cast<float>(log_uniform(0.01, 0.4));
        g.rotation = unit_quaternion();
        g.opacity = static_cast<float>(uniform(0.05, 0.99));
        g.dc = colour();
        g.rest = static_cast<float>(uniform(-0.2, 0.2));
        return g;
    }

private:
    std::mt19937_64 rng_;
};

/// A quaternion (w, x, y, z) whose rotation maps the local x axis onto `dir` (unit): the long
/// axis of a needle with scale (long, thin, thin) then points along `dir`.
inline std::array<float, 4> quaternion_x_to(std::array<double, 3> dir) {
    // Half-way quaternion between e_x and dir: q = (1 + dir.x, 0, -dir.z, dir.y) normalised
    // (cross(e_x, dir) = (0, -dir.z, dir.y)); dir = -e_x is the degenerate case.
    double w = 1 + dir[0], x = 0, y = -dir[2], z = dir[1];
    double n = std::sqrt(w * w + x * x + y * y + z * z);
    if (n < 1e-9) return {0, 0, 0, 1};  // 180 degrees about z
    return {static_cast<float>(w / n), static_cast<float>(x / n), static_cast<float>(y / n), static_cast<float>(z / n)};
}

/// A scene of the given SH degree (origin 0) with nothing in it yet.
inline Scene empty_scene(int sh_degree) {
    Scene s;
    s.sh_degree = sh_degree;
    return s;
}

/// A camera path of `frames` frames at 30 fps, starting at `start`, translating by `step`
/// metres per frame along the camera's x axis and turning by `turn` radians per frame about
/// its y axis: slow enough that the speculative cache serves some frames from its lists.
inline std::vector<Camera> short_path(const Camera& start, double step = 0.002, double turn = 1e-4, int frames = 6) {
    std::vector<Camera> path;
    const auto c0 = camera_centre(start.pose);
    const auto& r0 = start.pose.rotation;
    for (int k = 0; k < frames; ++k) {
        // Camera-to-world rotation: columns are the camera axes; rotate them about camera y.
        const double a = turn * k, ca = std::cos(a), sa = std::sin(a);
        std::array<double, 9> c2w{};
        for (int i = 0; i < 3; ++i) {
            const double ax = r0[0 * 3 + i], ay = r0[1 * 3 + i], az = r0[2 * 3 + i];  // axes in world
            c2w[3 * i + 0] = ca * ax - sa * az;
            c2w[3 * i + 1] = ay;
            c2w[3 * i + 2] = sa * ax + ca * az;
        }
        std::array<double, 3> centre{c0[0] + step * k * r0[0], c0[1] + step * k * r0[1], c0[2] + step * k * r0[2]};
        Camera c = start;
        c.pose = pose_from_centre(centre, c2w);
        c.timestamp = start.timestamp + k / 30.0;
        path.push_back(c);
    }
    return path;
}

struct StressCase {
    std::string name;
    Family family;
    Scene scene;
    std::vector<Camera> path;  ///< frame 0 is the single-frame camera
};

/// Default image of the family cases: small (CI), with a partial tile on each axis.
inline constexpr int kCaseWidth = 72, kCaseHeight = 40;

/// The camera of the family cases: the default image at `fov` degrees horizontally.
inline Camera case_camera(double fov = 60) { return forward_camera(kCaseWidth, kCaseHeight, fov); }

/// The default path without the turn. Scenes with near-plane Gaussians need it: a turning
/// camera sweeps some of them across the plane, and one that lands within float rounding of
/// it is drawn by one precision and culled by the other (StressNearPlane covers that boundary
/// on its own). Scenes of equal depths need it to keep the depths equal on cached frames.
inline std::vector<Camera> sideways_path(const Camera& start) { return short_path(start, 0.002, 0.0); }

inline StressCase make_case(std::string name, Family family, Scene scene, const Camera& camera) {
    scene.update_bounds();
    StressCase c{std::move(name), family, std::move(scene), short_path(camera)};
    return c;
}

inline void add_ordinary(Scene& s, Draw& d, int count) {
    for (int i = 0; i < count; ++i) add(s, d.ordinary());
}

/// The unit direction from the origin (the case camera's centre) to `position`.
inline std::array<double, 3> direction_to(const std::array<float, 3>& position) {
    const std::array<double, 3> p{position[0], position[1], position[2]};
    const double n = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    return {p[0] / n, p[1] / n, p[2] / n};
}

/// What most family scenes are made of: `background` ordinary Gaussians, which the
/// adversarial ones blend with, then `adversarial` Gaussians of the family.
struct FamilyShape {
    int sh_degree;
    int background;
    int adversarial;
};

/// A family case of that shape, seen by case_camera() on the default path. `draw_one(d,
/// scene, i)` returns the i-th adversarial Gaussian (the scene is there for its SH layout).
/// The draws come in a fixed order, background first, so that a seed names one scene.
template <typename DrawOne>
StressCase family_case(std::uint64_t seed, std::string name, Family family, FamilyShape shape, DrawOne draw_one) {
    Draw d(seed);
    Scene s = empty_scene(shape.sh_degree);
    add_ordinary(s, d, shape.background);
    for (int i = 0; i < shape.adversarial; ++i) add(s, draw_one(d, s, i));
    return make_case(std::move(name), family, std::move(s), case_camera());
}

// --- Families -------------------------------------------------------------------------

/// Scales 1e-12, 1e-20, 1e-30, 1e-45 (denormal) and 0 on one, two or three axes: the 3D
/// covariance underflows, the 2D covariance is the 0.3 blur (a one-pixel dot) or a line.
inline StressCase tiny_scales(std::uint64_t seed) {
    const std::vector<float> tiny{1e-12f, 1e-20f, 1e-30f, 1e-45f, 0.0f};
    const FamilyShape shape{.sh_degree = 3, .background = 40, .adversarial = 60};
    return family_case(seed, "tiny scales", Family::tiny_scales, shape, [&](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(0.5, 8.0);
        const int axes = d.integer(1, 3);
        for (int a = 0; a < axes; ++a) g.scale[static_cast<std::size_t>(d.integer(0, 2))] = d.pick(tiny);
        g.opacity = static_cast<float>(d.uniform(0.3, 1.0));
        return g;
    });
}

/// Scales 1e3 .. 1e6 (isotropic and mixed with ordinary axes), in front of the camera,
/// some containing the camera: the 2D covariance reaches 1e19 px^2 (1e38 for the
/// determinant, float's limit).
inline StressCase huge_scales(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 60, .adversarial = 4};
    return family_case(seed, "huge scales", Family::huge_scales, shape, [](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(0.3, 50.0);
        const double big = d.log_uniform(1e3, 1e6);
        if (d.chance(0.5)) {
            g.scale = {static_cast<float>(big), static_cast<float>(big), static_cast<float>(big)};
        } else {
            g.scale[static_cast<std::size_t>(d.integer(0, 2))] = static_cast<float>(big);
        }
        g.opacity = static_cast<float>(d.uniform(0.05, 0.5));  // see-through: the rest stays visible
        return g;
    });
}

/// Zero, NaN, inf, denormal and non-normalised quaternions. Rendering uses quat_to_matrix
/// as it is (no normalisation): a zero quaternion is the identity, a quaternion k q gives
/// I + k^2 (R(q) - I), not a rotation, and NaN/inf ones make the covariance NaN (culled).
inline StressCase quaternions(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 2, .background = 40, .adversarial = 60};
    return family_case(seed, "quaternions", Family::quaternions, shape, [](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 8.0);
        g.scale = {static_cast<float>(d.log_uniform(0.02, 0.3)), static_cast<float>(d.log_uniform(0.02, 0.3)),
                   static_cast<float>(d.log_uniform(0.02, 0.3))};
        const auto q = d.unit_quaternion();
        switch (d.integer(0, 6)) {
            case 0: g.rotation = {0, 0, 0, 0}; break;
            case 1: g.rotation = {kNaN, q[1], q[2], q[3]}; break;
            case 2: g.rotation = {q[0], kInf, q[2], q[3]}; break;
            case 3: g.rotation = {1e-40f, 0, 0, 0}; break;  // denormal, near zero
            default: {
                const float k = static_cast<float>(d.pick(std::vector<double>{1e-3, 0.5, 0.9, 1.1, 2.0, 30.0}));
                g.rotation = {k * q[0], k * q[1], k * q[2], k * q[3]};
            }
        }
        return g;
    });
}

/// Opacities from logits +-100 (1.0f and the denormal 3.7e-44f), exactly 1.0f, the largest
/// float below 1, 1/255 and its float neighbours, and 0: alpha hits the 0.99 cap, the 1/255
/// skip and the 1e-4 transmittance stop exactly.
inline StressCase opacities(std::uint64_t seed) {
    const float a255 = static_cast<float>(1.0 / 255.0);
    const std::vector<float> values{activated_opacity(100),        activated_opacity(-100),
                                    1.0f,                          std::nextafter(1.0f, 0.0f),
                                    a255,                          std::nextafter(a255, 0.0f),
                                    std::nextafter(a255, 1.0f),    0.0f,
                                    0.99f,                         activated_opacity(30)};
    const FamilyShape shape{.sh_degree = 0, .background = 30, .adversarial = 90};
    return family_case(seed, "opacities", Family::opacities, shape, [&](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        g.opacity = d.pick(values);
        return g;
    });
}

/// SH coefficients of magnitude 1e30 in every degree and both signs, mixed with ordinary
/// Gaussians: colours 1e30 saturate every pixel they reach with alpha >= 1/255.
inline StressCase huge_sh(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 3, .background = 60, .adversarial = 12};
    return family_case(seed, "huge sh", Family::huge_sh, shape, [](Draw& d, const Scene& s, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        g.sh.assign(s.sh_floats_per_gaussian(), 0.0f);
        for (int j = 0; j < 3; ++j) g.sh[static_cast<std::size_t>(j)] = g.dc[static_cast<std::size_t>(j)];
        const int hits = d.integer(1, 4);
        for (int h = 0; h < hits; ++h)
            g.sh[static_cast<std::size_t>(d.integer(0, static_cast<int>(g.sh.size()) - 1))] = d.chance(0.5) ? 1e30f : -1e30f;
        return g;
    });
}

/// SH coefficients 1e38 (near float max: a degree-3 sum can overflow float), +inf, -inf
/// and NaN.
inline StressCase extreme_sh(std::uint64_t seed) {
    const std::vector<float> values{1e38f, -1e38f, 3.4e38f, kInf, -kInf, kNaN};
    const FamilyShape shape{.sh_degree = 3, .background = 40, .adversarial = 12};
    return family_case(seed, "extreme sh", Family::extreme_sh, shape, [&](Draw& d, const Scene& s, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        g.sh.assign(s.sh_floats_per_gaussian(), 0.0f);
        const int hits = d.integer(1, 6);
        for (int h = 0; h < hits; ++h)
            g.sh[static_cast<std::size_t>(d.integer(0, static_cast<int>(g.sh.size()) - 1))] = d.pick(values);
        return g;
    });
}

/// Gaussians at the camera centre, just in front of and just behind the near plane 0.2
/// (relative offsets 1e-5 .. 1e-2, so that float and double agree on which side they are;
/// test_stress.cpp covers the ones within an ulp separately) and behind the camera.
inline StressCase near_plane(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 40, .adversarial = 60};
    StressCase c = family_case(seed, "near plane", Family::near_plane, shape, [](Draw& d, const Scene&, int i) {
        Gaussian g;
        double z = 0.2;
        switch (d.integer(0, 3)) {
            case 0: z = 0.0; break;                                           // camera centre
            case 1: z = -d.log_uniform(1e-3, 10); break;                      // behind
            default: z = 0.2 * (1 + (d.chance(0.5) ? 1 : -1) * d.log_uniform(1e-5, 1e-2));
        }
        const double lateral = z > 0 ? z : 0.2;
        g.position = {static_cast<float>(d.uniform(-0.6, 0.6) * lateral), static_cast<float>(d.uniform(-0.4, 0.4) * lateral),
                      static_cast<float>(z)};
        if (i % 10 == 0) g.position[0] = g.position[1] = 0;  // on the optical axis
        for (float& sc : g.scale) sc = static_cast<float>(d.log_uniform(1e-4, 0.05));
        g.rotation = d.unit_quaternion();
        g.opacity = static_cast<float>(d.uniform(0.1, 0.99));
        g.dc = d.colour();
        return g;
    });
    c.path = sideways_path(c.path.front());
    return c;
}

/// Means exactly on the image border (x = 0, x = width, y = 0, y = height: pixel centres
/// are at +0.5) and on tile boundaries, small and large.
inline StressCase image_border(std::uint64_t seed) {
    const Intrinsics k = case_camera().intrinsics;
    const FamilyShape shape{.sh_degree = 0, .background = 30, .adversarial = 60};
    return family_case(seed, "image border", Family::image_border, shape, [&](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        const double z = g.position[2];
        double u = d.uniform(0, k.width), v = d.uniform(0, k.height);
        switch (d.integer(0, 4)) {
            case 0: u = d.chance(0.5) ? 0.0 : k.width; break;
            case 1: v = d.chance(0.5) ? 0.0 : k.height; break;
            case 2: u = 16.0 * d.integer(0, k.width / 16); break;
            case 3: v = 16.0 * d.integer(0, k.height / 16); break;
            default:
                u = d.chance(0.5) ? 0.0 : k.width;
                v = d.chance(0.5) ? 0.0 : k.height;
        }
        g.position[0] = static_cast<float>((u - k.cx) / k.fx * z);
        g.position[1] = static_cast<float>((v - k.cy) / k.fy * z);
        const double px = d.log_uniform(0.05, 30.0);  // footprint sigma in pixels
        for (float& sc : g.scale) sc = static_cast<float>(px * z / k.fx);
        return g;
    });
}

/// Gaussians 10^7 m away (on screen with scales 1e4 .. 1e5, far outside the frustum, and
/// behind), in front of an ordinary scene; and some at finite but absurd lateral offsets
/// (1e20 m at a depth of metres), whose means lie 1e21 px off-screen so that dx^2 overflows
/// float in the blend.
inline StressCase far_away(std::uint64_t seed) {
    Draw d(seed);
    Scene s = empty_scene(2);
    add_ordinary(s, d, 40);
    for (int i = 0; i < 30; ++i) {
        Gaussian g = d.ordinary();
        const double z = d.uniform(0.5e7, 1e7);
        const double spread = d.chance(0.7) ? 0.5 : 40.0;  // on screen, or far outside the frustum
        g.position = {static_cast<float>(d.uniform(-spread, spread) * z), static_cast<float>(d.uniform(-spread, spread) * z),
                      static_cast<float>(d.chance(0.9) ? z : -z)};
        for (float& sc : g.scale) sc = static_cast<float>(d.log_uniform(1e4, 1e5));
        add(s, g);
    }
    for (int i = 0; i < 4; ++i) {
        Gaussian g = d.ordinary();
        g.position[0] = d.chance(0.5) ? 1e20f : -1e20f;
        g.position[1] = d.chance(0.5) ? 1e20f : -1e20f;
        add(s, g);
    }
    return make_case("far away", Family::far_away, std::move(s), case_camera());
}

/// A scene whose origin is at UTM-sized coordinates (10^6 .. 10^7 m), the camera there too
/// and rotated (look_at): positions are float offsets from the double origin.
inline StressCase utm(std::uint64_t seed) {
    Draw d(seed);
    Scene s = empty_scene(3);
    add_ordinary(s, d, 150);
    s.origin = {d.uniform(1e6, 9e6), d.uniform(1e6, 9e6), d.uniform(0, 500)};
    Camera cam = case_camera();
    const std::array<double, 3> eye{s.origin[0] + d.uniform(-0.5, 0.5), s.origin[1] + d.uniform(-0.5, 0.5),
                                    s.origin[2] + d.uniform(-0.5, 0.5)};
    const std::array<double, 3> target{s.origin[0] + d.uniform(-1, 1), s.origin[1] + d.uniform(-1, 1), s.origin[2] + 6};
    cam.pose = look_at(eye, target, {0, 1, 0});
    return make_case("utm", Family::utm, std::move(s), cam);
}

/// The camera inside large Gaussians (scales 1 .. 1e3, mean in front of the near plane,
/// the camera within one sigma), with ordinary ones behind: alpha is nearly uniform over
/// the screen.
inline StressCase camera_inside(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 60, .adversarial = 3};
    return family_case(seed, "camera inside", Family::camera_inside, shape, [](Draw& d, const Scene&, int) {
        Gaussian g;
        const double sigma = d.log_uniform(1.0, 1e3);
        g.position = {static_cast<float>(d.uniform(-0.3, 0.3)), static_cast<float>(d.uniform(-0.3, 0.3)),
                      static_cast<float>(d.uniform(0.21, 0.9))};
        g.scale = {static_cast<float>(sigma * d.uniform(0.5, 2)), static_cast<float>(sigma * d.uniform(0.5, 2)),
                   static_cast<float>(sigma * d.uniform(0.5, 2))};
        g.rotation = d.unit_quaternion();
        g.opacity = static_cast<float>(d.uniform(0.05, 0.4));
        g.dc = d.colour();
        return g;
    });
}

/// Rank-one-before-the-blur 2D covariances: scales 1e-20 x 1e-20 x 1 (the 3D determinant
/// underflows in float), needles (thin 1e-6 .. 1e-3, long 0.1 .. 1e3) seen end-on along the
/// ray through their mean, flat discs seen edge-on.
inline StressCase degenerate(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 0, .background = 30, .adversarial = 40};
    return family_case(seed, "degenerate", Family::degenerate, shape, [](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        const std::array<double, 3> ray = direction_to(g.position);
        switch (d.integer(0, 2)) {
            case 0:  // 1e-20 x 1e-20 x 1, any orientation
                g.scale = {1e-20f, 1e-20f, 1.0f};
                break;
            case 1: {  // needle along the viewing ray
                const float thin = static_cast<float>(d.log_uniform(1e-6, 1e-3));
                g.scale = {static_cast<float>(d.log_uniform(0.1, 1e3)), thin, thin};
                g.rotation = quaternion_x_to(ray);
                break;
            }
            default: {  // disc whose normal (local x) is perpendicular to the ray: edge-on
                std::array<double, 3> normal{ray[1], -ray[0], 0};
                const double m = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1]);
                normal = m > 1e-9 ? std::array<double, 3>{normal[0] / m, normal[1] / m, 0} : std::array<double, 3>{1, 0, 0};
                const float wide = static_cast<float>(d.log_uniform(0.05, 2.0));
                g.scale = {static_cast<float>(d.log_uniform(1e-12, 1e-4)), wide, wide};
                g.rotation = quaternion_x_to(normal);
            }
        }
        g.opacity = static_cast<float>(d.uniform(0.3, 1.0));
        return g;
    });
}

/// Values a loader rejects: NaN / inf positions, NaN / inf scales, NaN opacity, NaN SH.
/// A non-finite position, scale or opacity must cull the Gaussian (draw nothing of it) in
/// every mode; a NaN SH colour is clamped to 0: the Gaussian is drawn black.
inline StressCase invalid(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 40, .adversarial = 30};
    return family_case(seed, "invalid values", Family::invalid, shape, [](Draw& d, const Scene& s, int) {
        Gaussian g = d.ordinary(1.0, 8.0);
        const float bad = d.pick(std::vector<float>{kNaN, kInf, -kInf});
        switch (d.integer(0, 3)) {
            case 0: g.position[static_cast<std::size_t>(d.integer(0, 2))] = bad; break;
            case 1: g.scale[static_cast<std::size_t>(d.integer(0, 2))] = bad; break;
            case 2: g.opacity = kNaN; break;
            default: g.sh.assign(s.sh_floats_per_gaussian(), kNaN);  // colour NaN: clamped to 0 (black)
        }
        return g;
    });
}

/// One random adversarial Gaussian from any family (the generators above, one draw each).
/// `huge_colours` allows SH coefficients of 1e30.
inline Gaussian adversarial(Draw& d, const Intrinsics& k, int sh_degree, bool huge_colours) {
    Gaussian g = d.ordinary(0.3, 15.0);
    const std::size_t sh_floats = 3u * static_cast<std::size_t>(sh_coefficient_count(sh_degree));
    int kind = d.integer(0, 11);
    if (kind == 4 && !huge_colours) kind = 11;
    switch (kind) {
        case 0: g.scale[static_cast<std::size_t>(d.integer(0, 2))] = d.pick(std::vector<float>{1e-12f, 1e-20f, 0.0f}); break;
        case 1: {
            const float big = static_cast<float>(d.log_uniform(1e2, 1e6));
            g.scale = {big, big, d.chance(0.5) ? big : 0.1f};
            g.opacity = static_cast<float>(d.uniform(0.02, 0.3));
            break;
        }
        case 2: {
            const auto q = d.unit_quaternion();
            const float f = d.pick(std::vector<float>{0.0f, 1e-3f, 2.0f, 30.0f});
            g.rotation = {f * q[0], f * q[1], f * q[2], f * q[3]};
            if (d.chance(0.3)) g.rotation[0] = kNaN;
            break;
        }
        case 3:
            g.opacity = d.pick(std::vector<float>{activated_opacity(100), activated_opacity(-100), 1.0f,
                                                  static_cast<float>(1.0 / 255.0)});
            break;
        case 4:
            g.sh.assign(sh_floats, 0.0f);
            g.sh[static_cast<std::size_t>(d.integer(0, static_cast<int>(sh_floats) - 1))] = d.chance(0.5) ? 1e30f : -1e30f;
            break;
        case 5: {
            const double z = d.pick(std::vector<double>{0.0, 0.2 * (1 + 1e-4), 0.2 * (1 - 1e-4), 0.2 * (1 + 1e-2), -1.0});
            g.position = {static_cast<float>(d.uniform(-0.1, 0.1)), static_cast<float>(d.uniform(-0.1, 0.1)),
                          static_cast<float>(z)};
            for (float& s : g.scale) s = static_cast<float>(d.log_uniform(1e-4, 0.02));
            break;
        }
        case 6: {
            const double z = g.position[2];
            const double u = d.chance(0.5) ? 0.0 : k.width, v = d.uniform(0, k.height);
            g.position[0] = static_cast<float>((u - k.cx) / k.fx * z);
            g.position[1] = static_cast<float>((v - k.cy) / k.fy * z);
            break;
        }
        case 7: {
            const double z = d.uniform(1e6, 1e7);
            g.position = {static_cast<float>(d.uniform(-0.5, 0.5) * z), static_cast<float>(d.uniform(-0.3, 0.3) * z),
                          static_cast<float>(z)};
            for (float& s : g.scale) s = static_cast<float>(d.log_uniform(1e3, 1e5));
            break;
        }
        case 8: {
            const float s = static_cast<float>(d.log_uniform(1.0, 100.0));
            g.position = {0, 0, static_cast<float>(d.uniform(0.25, 0.8))};
            g.scale = {s, s, s};
            g.opacity = static_cast<float>(d.uniform(0.05, 0.3));
            break;
        }
        case 9: {
            const float thin = static_cast<float>(d.log_uniform(1e-6, 1e-3));
            g.scale = {static_cast<float>(d.log_uniform(0.1, 1e3)), thin, thin};
            g.rotation = quaternion_x_to(direction_to(g.position));
            break;
        }
        case 10: g.scale = {1e-20f, 1e-20f, 1.0f}; break;
        default: break;  // an ordinary one
    }
    return g;
}

/// `count` adversarial Gaussians in one scene; with `huge_colours`, SH 1e30 among them.
inline StressCase mixture(std::uint64_t seed, int count = 150, bool huge_colours = false) {
    Draw d(seed);
    Scene s = empty_scene(d.integer(0, 3));
    const Camera cam = case_camera();
    for (int i = 0; i < count; ++i) add(s, adversarial(d, cam.intrinsics, s.sh_degree, huge_colours));
    StressCase c = make_case(huge_colours ? "hdr mixture" : "mixture", huge_colours ? Family::hdr_mixture : Family::mixture,
                             std::move(s), cam);
    // The mixture holds near-plane Gaussians (0.2 m +- 1e-4); with colours of 1e30 a flip at
    // the plane would be full-scale over the whole footprint.
    c.path = sideways_path(c.path.front());
    return c;
}

/// The mixture seen with a horizontal field of view of `fov` degrees (5 .. 150).
inline StressCase field_of_view(std::uint64_t seed, double fov) {
    StressCase c = mixture(seed, 120);
    c.name = "fov " + std::to_string(static_cast<int>(fov));
    c.family = Family::field_of_view;
    c.path = sideways_path(case_camera(fov));  // see mixture()
    return c;
}

/// `count` Gaussians at exactly the same view depth `z` (ties), overlapping on screen.
inline Scene equal_depth(std::uint64_t seed, int count, float z = 5.0f) {
    Draw d(seed);
    Scene s = empty_scene(0);
    for (int i = 0; i < count; ++i) {
        Gaussian g = d.ordinary();
        g.position = {static_cast<float>(d.uniform(-0.4, 0.4) * z), static_cast<float>(d.uniform(-0.25, 0.25) * z), z};
        g.opacity = static_cast<float>(d.uniform(0.3, 0.99));
        add(s, g);
    }
    s.update_bounds();
    return s;
}

/// Ties: 2000 Gaussians at depth 5 and 1000 at depth 8 (exactly, for the camera at the
/// origin: the view depth of each is the same float), in index order of nothing in
/// particular: equal depths must be ordered by index, deterministically.
inline StressCase ties(std::uint64_t seed) {
    Scene s = equal_depth(seed, 2000, 5.0f);
    const Scene back = equal_depth(seed + 1, 1000, 8.0f);
    s.positions.insert(s.positions.end(), back.positions.begin(), back.positions.end());
    s.scales.insert(s.scales.end(), back.scales.begin(), back.scales.end());
    s.rotations.insert(s.rotations.end(), back.rotations.begin(), back.rotations.end());
    s.opacities.insert(s.opacities.end(), back.opacities.begin(), back.opacities.end());
    s.sh.insert(s.sh.end(), back.sh.begin(), back.sh.end());
    StressCase c = make_case("ties", Family::ties, std::move(s), case_camera());
    c.path = sideways_path(c.path.front());
    return c;
}

// --- Single Gaussians ------------------------------------------------------------------

/// A scene of one Gaussian at `p`; with `sh_degree` > 0 every SH coefficient is `sh_value`.
inline Scene one_gaussian(std::array<float, 3> p, std::array<float, 3> s, std::array<float, 4> q, float opacity,
                          std::array<float, 3> dc, int sh_degree = 0, float sh_value = 0) {
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
// Cases for the speculative cache's envelope: each backend renders the path with the cache
// and without, and the cached frames must match (the StressBugs of test_stress.cpp). No family
// bound applies; `family` names the closest family.

/// 30 ordinary Gaussians 3 .. 12 m away and, in a 4 x 3 grid 2 .. 3 m away, alternately
/// needles pointing at the camera and discs seen edge-on (one-pixel footprints that open up
/// as the line of sight turns), on a 160 x 96 camera moving 5 mm a frame sideways.
inline StressCase needles_and_discs_end_on(std::uint64_t seed) {
    const Camera cam = forward_camera(160, 96, 60);
    Scene scene = empty_scene(0);
    Draw d(seed);
    for (int i = 0; i < 30; ++i) add(scene, d.ordinary(3, 12));
    for (int i = 0; i < 12; ++i) {
        Gaussian g = d.ordinary();
        const float z = 2.0f + 0.1f * static_cast<float>(i);
        g.position = {(-0.6f + 0.4f * static_cast<float>(i % 4)) * z, (-0.3f + 0.3f * static_cast<float>(i / 4)) * z, z};
        // Squared in float, unlike direction_to: a seed logged by earlier runs replays the same scene.
        const double n = std::sqrt(g.position[0] * g.position[0] + g.position[1] * g.position[1] + g.position[2] * g.position[2]);
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

/// 40 ordinary Gaussians 8 .. 12 m away and a small bright one at 0.3 m depth whose mean is
/// 6 px right of a 72 x 40 image; the camera moves 5 cm a frame to the right, which brings the
/// near one into the image by 10 px a frame while the far ones move less than a pixel.
inline StressCase near_gaussian_outside_the_image(std::uint64_t seed) {
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

/// `count` Gaussians with bounded footprints (sigma 0.3 .. 40 px, so a few tiles each) for a
/// large image: at the corners, on the border, on tile boundaries, at the centre and at
/// random, some opaque (1.0), some with a 1e-12 axis, some with zero scales (the blur).
inline Scene local_gaussians(std::uint64_t seed, const Camera& cam, int count) {
    Draw d(seed);
    const Intrinsics& k = cam.intrinsics;
    Scene scene = empty_scene(1);
    for (int i = 0; i < count; ++i) {
        const double u = d.pick(std::vector<double>{0.0, 16.0, d.uniform(0, k.width), 0.5 * k.width, k.width - 16.0, 1.0 * k.width});
        const double v = d.pick(std::vector<double>{0.0, d.uniform(0, k.height), 0.5 * k.height, 1.0 * k.height});
        const double z = d.uniform(0.3, 50), sigma_px = d.log_uniform(0.3, 40);
        Gaussian g = d.ordinary();
        g.position = {static_cast<float>((u - k.cx) / k.fx * z), static_cast<float>((v - k.cy) / k.fy * z), static_cast<float>(z)};
        for (float& sc : g.scale) sc = static_cast<float>(sigma_px * z / k.fx * d.uniform(0.5, 1.5));
        switch (i % 4) {
            case 0: g.opacity = 1.0f; break;
            case 1: g.scale[0] = 1e-12f; break;
            case 2: g.scale = {0, 0, 0}; break;
            default: break;
        }
        add(scene, g);
    }
    scene.update_bounds();
    return scene;
}

/// Pixel boxes {x0, y0, x1, y1} (half-open) around the footprint of every Gaussian visible to
/// `cam` (the box of q <= its opacity level, grown by `margin`), merged where they overlap,
/// so that every Gaussian reaching a box has its mean inside it.
inline std::vector<std::array<int, 4>> footprint_boxes(const Scene& scene, const Camera& cam, int margin = 4) {
    const View<double> view = make_view<double>(cam, scene.origin);
    const int w = cam.intrinsics.width, h = cam.intrinsics.height;
    std::vector<std::array<int, 4>> boxes;
    const std::size_t stride = scene.sh_floats_per_gaussian();
    for (std::size_t i = 0; i < scene.count(); ++i) {
        const GaussianRef g{&scene.positions[3 * i], &scene.scales[3 * i], &scene.rotations[4 * i], scene.opacities[i],
                            &scene.sh[stride * i], scene.sh_degree};
        Projected<double> p;
        if (!project_gaussian(g, view, p)) continue;
        const Vec2<double> e = footprint_extent(p, Culling::opacity_aware);
        if (!(e.x >= 0)) continue;
        auto clampi = [](double v, int hi) { return static_cast<int>(std::min(std::max(v, 0.0), static_cast<double>(hi))); };
        const std::array<int, 4> b{clampi(std::floor(p.mean.x - e.x) - margin, w), clampi(std::floor(p.mean.y - e.y) - margin, h),
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

/// The camera that renders exactly the pixels `box` of `cam`: same focal lengths, principal
/// point shifted. Projection is identical for every Gaussian whose mean is inside the box (the
/// Jacobian clamp, principal-point aware, only differs beyond it).
inline Camera crop_camera(const Camera& cam, const std::array<int, 4>& box) {
    Camera crop = cam;
    crop.intrinsics.width = box[2] - box[0];
    crop.intrinsics.height = box[3] - box[1];
    crop.intrinsics.cx = cam.intrinsics.cx - box[0];
    crop.intrinsics.cy = cam.intrinsics.cy - box[1];
    return crop;
}

/// Every family once (field of view at 60 degrees is the mixture).
inline std::vector<StressCase> all_families(std::uint64_t seed) {
    std::vector<StressCase> cases;
    std::uint64_t k = 0;
    auto next = [&] { return seed + 0x9E3779B97F4A7C15ull * ++k; };
    cases.push_back(tiny_scales(next()));
    cases.push_back(huge_scales(next()));
    cases.push_back(quaternions(next()));
    cases.push_back(opacities(next()));
    cases.push_back(huge_sh(next()));
    cases.push_back(extreme_sh(next()));
    cases.push_back(near_plane(next()));
    cases.push_back(image_border(next()));
    cases.push_back(far_away(next()));
    cases.push_back(utm(next()));
    cases.push_back(camera_inside(next()));
    cases.push_back(degenerate(next()));
    cases.push_back(invalid(next()));
    cases.push_back(ties(next()));
    cases.push_back(mixture(next()));
    cases.push_back(mixture(next(), 150, true));
    return cases;
}

}  // namespace catgs::test::stress
