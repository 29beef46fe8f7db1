// The mixture families of stress_scenes.hpp: one scene of random draws from every adversarial
// family (stress_scenes.cpp), with or without SH colours of 1e30, and the same mixture seen at
// fields of view from 5 to 150 degrees.
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "stress_scenes.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

namespace {

/// One random adversarial Gaussian from any family (stress_scenes.cpp's generators, one draw each).
/// `huge_colours` allows SH coefficients of 1e30.
Gaussian adversarial(Draw& d, const Intrinsics& k, int sh_degree, bool huge_colours) {
    Gaussian g = d.ordinary(0.3, 15.0);
    const std::size_t sh_floats = 3u * static_cast<std::size_t>(sh_coefficient_count(sh_degree));
    int kind = d.integer(0, 11);
    if (kind == 4 && !huge_colours) kind = 11;
    switch (kind) {
        case 0:
            g.scale[static_cast<std::size_t>(d.integer(0, 2))] = d.pick(std::vector<float>{1e-12f, 1e-20f, 0.0f});
            break;
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
            g.sh[static_cast<std::size_t>(d.integer(0, static_cast<int>(sh_floats) - 1))] =
                d.chance(0.5) ? 1e30f : -1e30f;
            break;
        case 5: {
            const double z =
                d.pick(std::vector<double>{0.0, 0.2 * (1 + 1e-4), 0.2 * (1 - 1e-4), 0.2 * (1 + 1e-2), -1.0});
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
        case 10:
            g.scale = {1e-20f, 1e-20f, 1.0f};
            break;
        default:
            break;  // an ordinary one
    }
    return g;
}

}  // namespace

StressCase mixture(std::uint64_t seed, int count, bool huge_colours) {
    Draw d(seed);
    Scene s = empty_scene(d.integer(0, 3));
    const Camera cam = case_camera();
    for (int i = 0; i < count; ++i) add(s, adversarial(d, cam.intrinsics, s.sh_degree, huge_colours));
    StressCase c = make_case(huge_colours ? "hdr mixture" : "mixture",
                             huge_colours ? Family::hdr_mixture : Family::mixture, std::move(s), cam);
    // The mixture holds near-plane Gaussians (0.2 m +- 1e-4); with colours of 1e30 a flip at
    // the plane would be full-scale over the whole footprint.
    c.path = sideways_path(c.path.front());
    return c;
}

StressCase field_of_view(std::uint64_t seed, double fov) {
    StressCase c = mixture(seed, 120);
    c.name = "fov " + std::to_string(static_cast<int>(fov));
    c.family = Family::field_of_view;
    c.path = sideways_path(case_camera(fov));  // see mixture()
    return c;
}

}  // namespace catgs::test::stress
