// The adversarial scenes of stress_scenes.hpp, which documents each generator.
#include "stress_scenes.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "catgs/math.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

const char* family_name(Family f) {
    switch (f) {
        case Family::tiny_scales:
            return "tiny_scales";
        case Family::huge_scales:
            return "huge_scales";
        case Family::quaternions:
            return "quaternions";
        case Family::opacities:
            return "opacities";
        case Family::huge_sh:
            return "huge_sh";
        case Family::extreme_sh:
            return "extreme_sh";
        case Family::near_plane:
            return "near_plane";
        case Family::image_border:
            return "image_border";
        case Family::far_away:
            return "far_away";
        case Family::utm:
            return "utm";
        case Family::camera_inside:
            return "camera_inside";
        case Family::degenerate:
            return "degenerate";
        case Family::invalid:
            return "invalid";
        case Family::ties:
            return "ties";
        case Family::field_of_view:
            return "field_of_view";
        case Family::mixture:
            return "mixture";
        case Family::hdr_mixture:
            return "hdr_mixture";
    }
    return "?";
}

float activated_opacity(double logit) {
    return static_cast<float>(1.0 / (1.0 + std::exp(-logit)));
}

void add(Scene& s, const Gaussian& g) {
    s.positions.insert(s.positions.end(), g.position.begin(), g.position.end());
    s.scales.insert(s.scales.end(), g.scale.begin(), g.scale.end());
    s.rotations.insert(s.rotations.end(), g.rotation.begin(), g.rotation.end());
    s.opacities.push_back(g.opacity);
    const std::size_t stride = s.sh_floats_per_gaussian();
    if (!g.sh.empty()) {
        for (std::size_t k = 0; k < stride; ++k) s.sh.push_back(k < g.sh.size() ? g.sh[k] : 0.0f);
    } else {
        for (std::size_t k = 0; k < stride; ++k) s.sh.push_back(k < 3 ? g.dc[k] : ((k / 3) % 2 ? g.rest : -g.rest));
    }
}

double Draw::log_uniform(double lo, double hi) {
    return std::exp(uniform(std::log(lo), std::log(hi)));
}

std::array<float, 4> Draw::unit_quaternion() {
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

std::array<float, 3> Draw::colour() {
    return {static_cast<float>(uniform(-1.5, 1.5)), static_cast<float>(uniform(-1.5, 1.5)),
            static_cast<float>(uniform(-1.5, 1.5))};
}

Gaussian Draw::ordinary(double depth_min, double depth_max) {
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

std::array<float, 4> quaternion_x_to(std::array<double, 3> dir) {
    // Half-way quaternion between e_x and dir: q = (1 + dir.x, 0, -dir.z, dir.y) normalised
    // (cross(e_x, dir) = (0, -dir.z, dir.y)); dir = -e_x is the degenerate case.
    double w = 1 + dir[0], x = 0, y = -dir[2], z = dir[1];
    double n = std::sqrt(w * w + x * x + y * y + z * z);
    if (n < 1e-9) return {0, 0, 0, 1};  // 180 degrees about z
    return {static_cast<float>(w / n), static_cast<float>(x / n), static_cast<float>(y / n), static_cast<float>(z / n)};
}

Scene empty_scene(int sh_degree) {
    Scene s;
    s.sh_degree = sh_degree;
    return s;
}

std::vector<Camera> short_path(const Camera& start, double step, double turn, int frames) {
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

Camera case_camera(double fov) {
    return forward_camera(kCaseWidth, kCaseHeight, fov);
}

std::vector<Camera> sideways_path(const Camera& start) {
    return short_path(start, 0.002, 0.0);
}

StressCase make_case(std::string name, Family family, Scene scene, const Camera& camera) {
    scene.update_bounds();
    StressCase c{std::move(name), family, std::move(scene), short_path(camera)};
    return c;
}

std::array<double, 3> direction_to(const std::array<float, 3>& position) {
    const std::array<double, 3> p{position[0], position[1], position[2]};
    const double n = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    return {p[0] / n, p[1] / n, p[2] / n};
}

namespace {

void add_ordinary(Scene& s, Draw& d, int count) {
    for (int i = 0; i < count; ++i) add(s, d.ordinary());
}

struct FamilyShape {
    int sh_degree;
    int background;
    int adversarial;
};

template <typename DrawOne>
StressCase family_case(std::uint64_t seed, std::string name, Family family, FamilyShape shape, DrawOne draw_one) {
    Draw d(seed);
    Scene s = empty_scene(shape.sh_degree);
    add_ordinary(s, d, shape.background);
    for (int i = 0; i < shape.adversarial; ++i) add(s, draw_one(d, s, i));
    return make_case(std::move(name), family, std::move(s), case_camera());
}

}  // namespace

// --- Families -------------------------------------------------------------------------

StressCase tiny_scales(std::uint64_t seed) {
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

StressCase huge_scales(std::uint64_t seed) {
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

StressCase quaternions(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 2, .background = 40, .adversarial = 60};
    return family_case(seed, "quaternions", Family::quaternions, shape, [](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 8.0);
        g.scale = {static_cast<float>(d.log_uniform(0.02, 0.3)), static_cast<float>(d.log_uniform(0.02, 0.3)),
                   static_cast<float>(d.log_uniform(0.02, 0.3))};
        const auto q = d.unit_quaternion();
        switch (d.integer(0, 6)) {
            case 0:
                g.rotation = {0, 0, 0, 0};
                break;
            case 1:
                g.rotation = {kNaN, q[1], q[2], q[3]};
                break;
            case 2:
                g.rotation = {q[0], kInf, q[2], q[3]};
                break;
            case 3:
                g.rotation = {1e-40f, 0, 0, 0};
                break;  // denormal, near zero
            default: {
                const float k = static_cast<float>(d.pick(std::vector<double>{1e-3, 0.5, 0.9, 1.1, 2.0, 30.0}));
                g.rotation = {k * q[0], k * q[1], k * q[2], k * q[3]};
            }
        }
        return g;
    });
}

StressCase opacities(std::uint64_t seed) {
    const float a255 = static_cast<float>(1.0 / 255.0);
    const std::vector<float> values{activated_opacity(100),
                                    activated_opacity(-100),
                                    1.0f,
                                    std::nextafter(1.0f, 0.0f),
                                    a255,
                                    std::nextafter(a255, 0.0f),
                                    std::nextafter(a255, 1.0f),
                                    0.0f,
                                    0.99f,
                                    activated_opacity(30)};
    const FamilyShape shape{.sh_degree = 0, .background = 30, .adversarial = 90};
    return family_case(seed, "opacities", Family::opacities, shape, [&](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        g.opacity = d.pick(values);
        return g;
    });
}

StressCase huge_sh(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 3, .background = 60, .adversarial = 12};
    return family_case(seed, "huge sh", Family::huge_sh, shape, [](Draw& d, const Scene& s, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        g.sh.assign(s.sh_floats_per_gaussian(), 0.0f);
        for (int j = 0; j < 3; ++j) g.sh[static_cast<std::size_t>(j)] = g.dc[static_cast<std::size_t>(j)];
        const int hits = d.integer(1, 4);
        for (int h = 0; h < hits; ++h)
            g.sh[static_cast<std::size_t>(d.integer(0, static_cast<int>(g.sh.size()) - 1))] =
                d.chance(0.5) ? 1e30f : -1e30f;
        return g;
    });
}

StressCase extreme_sh(std::uint64_t seed) {
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

StressCase near_plane(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 40, .adversarial = 60};
    StressCase c = family_case(seed, "near plane", Family::near_plane, shape, [](Draw& d, const Scene&, int i) {
        Gaussian g;
        double z = 0.2;
        switch (d.integer(0, 3)) {
            case 0:
                z = 0.0;
                break;  // camera centre
            case 1:
                z = -d.log_uniform(1e-3, 10);
                break;  // behind
            default:
                z = 0.2 * (1 + (d.chance(0.5) ? 1 : -1) * d.log_uniform(1e-5, 1e-2));
        }
        const double lateral = z > 0 ? z : 0.2;
        g.position = {static_cast<float>(d.uniform(-0.6, 0.6) * lateral),
                      static_cast<float>(d.uniform(-0.4, 0.4) * lateral), static_cast<float>(z)};
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

StressCase image_border(std::uint64_t seed) {
    const Intrinsics k = case_camera().intrinsics;
    const FamilyShape shape{.sh_degree = 0, .background = 30, .adversarial = 60};
    return family_case(seed, "image border", Family::image_border, shape, [&](Draw& d, const Scene&, int) {
        Gaussian g = d.ordinary(1.0, 10.0);
        const double z = g.position[2];
        double u = d.uniform(0, k.width), v = d.uniform(0, k.height);
        switch (d.integer(0, 4)) {
            case 0:
                u = d.chance(0.5) ? 0.0 : k.width;
                break;
            case 1:
                v = d.chance(0.5) ? 0.0 : k.height;
                break;
            case 2:
                u = 16.0 * d.integer(0, k.width / 16);
                break;
            case 3:
                v = 16.0 * d.integer(0, k.height / 16);
                break;
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

StressCase far_away(std::uint64_t seed) {
    Draw d(seed);
    Scene s = empty_scene(2);
    add_ordinary(s, d, 40);
    for (int i = 0; i < 30; ++i) {
        Gaussian g = d.ordinary();
        const double z = d.uniform(0.5e7, 1e7);
        const double spread = d.chance(0.7) ? 0.5 : 40.0;  // on screen, or far outside the frustum
        g.position = {static_cast<float>(d.uniform(-spread, spread) * z),
                      static_cast<float>(d.uniform(-spread, spread) * z), static_cast<float>(d.chance(0.9) ? z : -z)};
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

StressCase utm(std::uint64_t seed) {
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

StressCase camera_inside(std::uint64_t seed) {
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

StressCase degenerate(std::uint64_t seed) {
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
                normal =
                    m > 1e-9 ? std::array<double, 3>{normal[0] / m, normal[1] / m, 0} : std::array<double, 3>{1, 0, 0};
                const float wide = static_cast<float>(d.log_uniform(0.05, 2.0));
                g.scale = {static_cast<float>(d.log_uniform(1e-12, 1e-4)), wide, wide};
                g.rotation = quaternion_x_to(normal);
            }
        }
        g.opacity = static_cast<float>(d.uniform(0.3, 1.0));
        return g;
    });
}

StressCase invalid(std::uint64_t seed) {
    const FamilyShape shape{.sh_degree = 1, .background = 40, .adversarial = 30};
    return family_case(seed, "invalid values", Family::invalid, shape, [](Draw& d, const Scene& s, int) {
        Gaussian g = d.ordinary(1.0, 8.0);
        const float bad = d.pick(std::vector<float>{kNaN, kInf, -kInf});
        switch (d.integer(0, 3)) {
            case 0:
                g.position[static_cast<std::size_t>(d.integer(0, 2))] = bad;
                break;
            case 1:
                g.scale[static_cast<std::size_t>(d.integer(0, 2))] = bad;
                break;
            case 2:
                g.opacity = kNaN;
                break;
            default:
                g.sh.assign(s.sh_floats_per_gaussian(), kNaN);  // colour NaN: clamped to 0 (black)
        }
        return g;
    });
}

Scene equal_depth(std::uint64_t seed, int count, float z) {
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

StressCase ties(std::uint64_t seed) {
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

const std::vector<FamilyGenerator>& family_generators() {
    static const std::vector<FamilyGenerator> families{
        {"TinyScales", "tiny scales", tiny_scales},
        {"HugeScales", "huge scales", huge_scales},
        {"ZeroNanAndNonNormalisedQuaternions", "quaternions", quaternions},
        {"ExtremeOpacities", "opacities", opacities},
        {"HugeShCoefficients", "huge sh", huge_sh},
        {"ShNearFloatMaxAndInfinite", "extreme sh", extreme_sh},
        {"NearPlaneCameraCentreAndBehind", "near plane", near_plane},
        {"MeansOnTheImageBorder", "image border", image_border},
        {"TenMillionMetresAway", "far away", far_away},
        {"UtmOriginAndCamera", "utm", utm},
        {"CameraInsideLargeGaussians", "camera inside", camera_inside},
        {"DegenerateCovariances", "degenerate", degenerate},
        {"InvalidValuesAreCulled", "invalid", invalid},
        {"EqualDepthTies", "ties", ties},
    };
    return families;
}

std::vector<StressCase> all_families(std::uint64_t seed) {
    std::vector<StressCase> cases;
    std::uint64_t k = 0;
    // The seed of each case follows from its position: a logged seed replays the same cases.
    auto next = [&] { return seed + 0x9E3779B97F4A7C15ull * ++k; };
    for (const FamilyGenerator& f : family_generators()) cases.push_back(f.make(next()));
    cases.push_back(mixture(next()));
    cases.push_back(mixture(next(), 150, true));
    return cases;
}

}  // namespace catgs::test::stress
