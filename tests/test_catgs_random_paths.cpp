// The cache's guarantee (cache.hpp: no cached frame lacks a Gaussian the per-frame pipeline
// draws) on camera paths no other test contains: random scenes with large, needle-like, near
// and just-off-screen Gaussians, flown along random paths that speed up, stop, turn about any
// axis and jerk, at irregular frame intervals, with no hints, with the true flight plan, or
// with a flight plan or velocity that lies. The other cache tests fly scripted UAV paths over
// the city; this one looks for the paths they do not contain.
//
// CATGS_RANDOM_PATHS=N runs N paths per configuration instead of the CI's few, to search
// (each path logs its seed; CATGS_TEST_SEED replays one).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/render_options.hpp"
#include "catgs_paths.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

using Mat3 = std::array<double, 9>;  // row-major

Mat3 multiply(const Mat3& a, const Mat3& b) {
    Mat3 c{};
    for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k)
            for (int j = 0; j < 3; ++j) c[3 * r + j] += a[3 * r + k] * b[3 * k + j];
    return c;
}

/// The rotation by |w| radians about w (Rodrigues).
Mat3 rotation(const std::array<double, 3>& w) {
    const double angle = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (angle == 0) return {1, 0, 0, 0, 1, 0, 0, 0, 1};
    const double x = w[0] / angle, y = w[1] / angle, z = w[2] / angle;
    const double c = std::cos(angle), s = std::sin(angle), t = 1 - c;
    return {t * x * x + c,     t * x * y - s * z, t * x * z + s * y, t * x * y + s * z, t * y * y + c,
            t * y * z - s * x, t * x * z - s * y, t * y * z + s * x, t * z * z + c};
}

/// Appends `count` Gaussians drawn by `make(rng, i)` into `s` (positions, log scales).
struct Extra {
    std::array<double, 3> position;
    std::array<double, 3> scale;
    double opacity;
};

template <typename Make>
void append(Scene& s, std::mt19937_64& rng, int count, Make make) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    const std::size_t stride = s.sh_floats_per_gaussian();
    for (int i = 0; i < count; ++i) {
        const Extra e = make(rng);
        const std::size_t n = s.count();
        s.resize(n + 1);
        double q[4], norm = 0;
        for (double& c : q) {
            c = normal(rng);
            norm += c * c;
        }
        norm = std::sqrt(norm);
        for (int a = 0; a < 3; ++a) {
            s.positions[3 * n + a] = static_cast<float>(e.position[a]);
            s.scales[3 * n + a] = static_cast<float>(e.scale[a]);
        }
        for (int a = 0; a < 4; ++a) s.rotations[4 * n + a] = static_cast<float>(q[a] / norm);
        s.opacities[n] = static_cast<float>(e.opacity);
        for (std::size_t k = 0; k < stride; ++k)
            s.sh[stride * n + k] = static_cast<float>(k < 3 ? (u(rng) - 0.5) * 3.0 : (2 * u(rng) - 1) * 0.2);
    }
}

/// Around a camera that starts at the origin looking down +z: a field of ordinary Gaussians
/// ahead, and the kinds that stress the envelope: large ones, needles and discs (seen end-on
/// they are far smaller on screen than in space), ones within a few metres of the start (they
/// cross the near plane as the camera moves) and ones just outside the start's field of view.
Scene adversarial_scene(std::uint64_t seed) {
    test::RandomSceneParams p;
    p.count = 1200;
    p.extent = 25.0;
    p.depth_min = -10.0;
    p.depth_max = 60.0;
    p.log_scale_min = -3.5;
    p.log_scale_max = -0.5;
    Scene s = test::random_scene(seed, p);
    std::mt19937_64 rng(seed ^ 0x9e3779b97f4a7c15ull);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    auto anywhere = [&](std::mt19937_64& r) {
        return std::array<double, 3>{(2 * u(r) - 1) * 25, (2 * u(r) - 1) * 25, -10 + 70 * u(r)};
    };
    append(s, rng, 60, [&](std::mt19937_64& r) {  // large
        const double a = std::exp(-0.5 + 2.0 * u(r)), b = std::exp(-0.5 + 2.0 * u(r)), c = std::exp(-0.5 + 2 * u(r));
        return Extra{anywhere(r), {a, b, c}, 0.05 + 0.9 * u(r)};
    });
    append(s, rng, 80, [&](std::mt19937_64& r) {  // needles (one long axis) and discs (one thin axis)
        const double long_axis = 1.0 + 5.0 * u(r), thin = 0.005 + 0.02 * u(r);
        const bool needle = u(r) < 0.5;
        return Extra{
            anywhere(r),
            needle ? std::array<double, 3>{long_axis, thin, thin} : std::array<double, 3>{long_axis, long_axis, thin},
            0.2 + 0.79 * u(r)};
    });
    append(s, rng, 40, [&](std::mt19937_64& r) {  // near the start
        const double d = 0.2 + 2.5 * u(r), theta = 6.283185307179586 * u(r), h = 2 * u(r) - 1;
        const double rad = std::sqrt(1 - h * h);
        return Extra{{d * rad * std::cos(theta), d * rad * std::sin(theta), d * h},
                     {0.02 + 0.3 * u(r), 0.02 + 0.3 * u(r), 0.02 + 0.3 * u(r)},
                     0.3 + 0.69 * u(r)};
    });
    append(s, rng, 80, [&](std::mt19937_64& r) {  // just off screen at the start: 40..80 degrees off-axis
        const double depth = 2 + 30 * u(r), off = (40 + 40 * u(r)) * 3.141592653589793 / 180;
        const double side = 6.283185307179586 * u(r), lateral = depth * std::tan(off);
        return Extra{{lateral * std::cos(side), lateral * std::sin(side), depth},
                     {0.05 + 0.5 * u(r), 0.05 + 0.5 * u(r), 0.05 + 0.5 * u(r)},
                     0.3 + 0.69 * u(r)};
    });
    s.update_bounds();
    return s;
}

/// What a path's client tells the server beside its poses.
enum class Hints { none, true_plan, lying_plan, lying_velocity };

const char* hints_name(Hints h) {
    switch (h) {
        case Hints::none:
            return "no hints";
        case Hints::true_plan:
            return "true flight plan";
        case Hints::lying_plan:
            return "lying flight plan";
        case Hints::lying_velocity:
            return "lying velocity";
    }
    return "?";
}

/// A random flight from the origin looking down +z: it holds its linear and angular velocity
/// for a while, then changes them (a new direction and speed up to 20 m/s, a turn up to 2.5
/// rad/s about any camera axis, a stop, or a hover with a slow drift), at 30 or 60 frames per
/// second with jittered intervals; now and then the viewer zooms or resizes its window.
std::vector<Camera> random_path(std::mt19937_64& rng, Intrinsics k, int frames) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    const double fps = u(rng) < 0.5 ? 30.0 : 60.0;
    std::array<double, 3> centre{0, 0, 0}, velocity{0, 0, 0}, spin{0, 0, 0};
    Mat3 camera_to_world{1, 0, 0, 0, 1, 0, 0, 0, 1};
    double t = 0;
    std::vector<Camera> out;
    for (int i = 0; i < frames; ++i) {
        Camera c;
        c.intrinsics = k;
        c.pose = pose_from_centre(centre, camera_to_world);
        c.timestamp = t;
        out.push_back(c);
        const double change = u(rng);
        if (change < 0.08) {  // a new velocity
            const double speed = 20.0 * u(rng) * u(rng);
            for (double& v : velocity) v = normal(rng);
            const double n =
                std::sqrt(velocity[0] * velocity[0] + velocity[1] * velocity[1] + velocity[2] * velocity[2]);
            for (double& v : velocity) v *= speed / n;
        } else if (change < 0.16) {  // a new turn, about the camera's axes
            const double rate = 2.5 * u(rng) * u(rng);
            for (double& w : spin) w = normal(rng);
            const double n = std::sqrt(spin[0] * spin[0] + spin[1] * spin[1] + spin[2] * spin[2]);
            for (double& w : spin) w *= rate / n;
        } else if (change < 0.20) {  // stop
            velocity = {0, 0, 0};
            spin = {0, 0, 0};
        } else if (change < 0.24) {  // hover: a slow drift
            for (double& v : velocity) v = 0.05 * normal(rng);
            for (double& w : spin) w = 0.002 * normal(rng);
        } else if (change < 0.26) {  // a zoom, or a resized window
            const bool resize = u(rng) < 0.5;
            k = intrinsics_from_fov(resize ? 64 + static_cast<int>(rng() % 96) : k.width,
                                    resize ? 48 + static_cast<int>(rng() % 72) : k.height, 30.0 + 100.0 * u(rng));
        }
        const double dt = (1.0 / fps) * (0.7 + 0.6 * u(rng));
        t += dt;
        for (int a = 0; a < 3; ++a) centre[a] += velocity[a] * dt;
        camera_to_world = multiply(camera_to_world, rotation({spin[0] * dt, spin[1] * dt, spin[2] * dt}));
    }
    return out;
}

/// The hints frame i of `path` carries.
FrameHints hints_for(Hints kind, const std::vector<Camera>& path, std::size_t i, std::mt19937_64& rng) {
    FrameHints h;
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    switch (kind) {
        case Hints::none:
            break;
        case Hints::true_plan:
            for (std::size_t j = i + 1; j < path.size() && j <= i + 16; ++j) h.plan.push_back(path[j]);
            break;
        case Hints::lying_plan: {
            // The same timestamps, the camera somewhere else and turned: what a buggy or hostile
            // client sends.
            const std::array<double, 3> c0 = camera_centre(path[i].pose);
            const std::array<double, 3> drift{u(rng) * 3, u(rng) * 3, u(rng) * 3};
            for (std::size_t j = i + 1; j < path.size() && j <= i + 16; ++j) {
                Camera c = path[j];
                const double s = static_cast<double>(j - i);
                c.pose = pose_from_centre({c0[0] + drift[0] * s, c0[1] + drift[1] * s, c0[2] + drift[2] * s},
                                          rotation({u(rng) * 0.05 * s, u(rng) * 0.05 * s, 0}));
                h.plan.push_back(c);
            }
            break;
        }
        case Hints::lying_velocity:
            h.linear_velocity = std::array<double, 3>{0, 0, 0};
            h.angular_speed = 0.0;
            break;
    }
    return h;
}

struct Tally {
    std::uint64_t missing = 0;
    int cached_frames = 0, key_frames = 0;
};

/// One random path under `options`: every cached frame against the per-frame pipeline.
Tally fly(const Scene& scene, const std::vector<Camera>& path, Hints hints, const RenderOptions& options,
          std::mt19937_64& rng, const std::string& name) {
    CpuRenderer<float> cached, full;
    RenderOptions full_options;
    full_options.culling = options.culling;
    Tally tally;
    ImageF a, b;
    for (std::size_t i = 0; i < path.size(); ++i) {
        const FrameHints h = hints_for(hints, path, i, rng);
        const FrameStats s = cached.render(scene, path[i], options, a, &h);
        full.render(scene, path[i], full_options, b);
        if (s.key_frame) {
            ++tally.key_frames;
            continue;
        }
        ++tally.cached_frames;
        const std::uint64_t missing = test::missing_pairs(cached, full);
        EXPECT_EQ(missing, 0u) << name << ", frame " << i << " (t = " << path[i].timestamp << " s, W " << s.window
                               << ")";
        tally.missing += missing;
    }
    return tally;
}

/// Paths per configuration: CATGS_RANDOM_PATHS, else `ci`.
int path_count(int ci) {
    const char* env = std::getenv("CATGS_RANDOM_PATHS");
    return env ? std::max(1, std::atoi(env)) : ci;
}

/// The configurations whose cached frames must lack nothing: the defaults (window planned by
/// counted work, so a replayed seed plans alike), and the cache at fixed W = 4 and W = 16 with
/// a wider culling mode, so that long windows over fast motion are tried too.
std::vector<test::CacheRun> configurations() {
    RenderOptions defaults = default_pipeline_options();
    defaults.catgs.window_cost = WindowCost::work;
    defaults.catgs.split_k = 64;
    RenderOptions w4 = defaults;
    w4.catgs.adaptive_window = false;
    w4.catgs.window = 4;
    RenderOptions w16 = w4;
    w16.catgs.window = 16;
    RenderOptions bbox = w4;
    bbox.culling = Culling::bbox3sigma;
    return {{"defaults", defaults}, {"W=4", w4}, {"W=16", w16}, {"W=4 bbox3sigma", bbox}};
}

TEST(CatgsRandomPaths, CachedFramesLackNoGaussianOnRandomFlights) {
    const int paths = path_count(2);
    Tally total;
    for (int p = 0; p < paths; ++p) {
        const std::uint64_t seed = test::fresh_seed("random flight " + std::to_string(p));
        std::mt19937_64 rng(seed);
        const Scene scene = adversarial_scene(seed);
        const double fov = 40.0 + 80.0 * std::uniform_real_distribution<double>(0, 1)(rng);
        const Intrinsics k = intrinsics_from_fov(128, 96, fov);
        const std::vector<Camera> path = random_path(rng, k, 48);
        const Hints hints = static_cast<Hints>(rng() % 4);
        for (const test::CacheRun& run : configurations()) {
            const std::string name = "seed " + std::to_string(seed) + ", " + run.label + ", fov " +
                                     std::to_string(fov) + ", " + hints_name(hints);
            const Tally t = fly(scene, path, hints, run.options, rng, name);
            std::cout << "[" << name << "] key " << t.key_frames << " cached " << t.cached_frames << " missing "
                      << t.missing << std::endl;
            total.missing += t.missing;
            total.cached_frames += t.cached_frames;
            total.key_frames += t.key_frames;
        }
    }
    EXPECT_EQ(total.missing, 0u);
    // Random flights hover and drift often enough that caching, not key frames alone, meets this.
    EXPECT_GT(total.cached_frames, 0);
}

}  // namespace
}  // namespace catgs
