// The CPU reference renderer: analytic cases against closed forms, then the pipeline's
// modes and precisions against each other on fresh random scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/sh.hpp"
#include "catgs/stages/tiles.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

/// One Gaussian with DC colour `rgb` (before the +0.5 offset) at scene position p.
Scene single_gaussian(std::array<float, 3> p, float scale, float opacity, std::array<float, 3> dc) {
    Scene s;
    s.sh_degree = 0;
    s.resize(1);
    for (int a = 0; a < 3; ++a) {
        s.positions[a] = p[a];
        s.scales[a] = scale;
        s.sh[a] = dc[a];
    }
    s.rotations = {1, 0, 0, 0};
    s.opacities[0] = opacity;
    s.update_bounds();
    return s;
}

void append(Scene& dst, const Scene& src) {
    ASSERT_EQ(dst.sh_degree, src.sh_degree);
    dst.positions.insert(dst.positions.end(), src.positions.begin(), src.positions.end());
    dst.scales.insert(dst.scales.end(), src.scales.begin(), src.scales.end());
    dst.rotations.insert(dst.rotations.end(), src.rotations.begin(), src.rotations.end());
    dst.opacities.insert(dst.opacities.end(), src.opacities.begin(), src.opacities.end());
    dst.sh.insert(dst.sh.end(), src.sh.begin(), src.sh.end());
    dst.update_bounds();
}

template <typename T>
ImageF render(const Scene& scene, const Camera& camera, Culling culling, std::array<float, 3> bg = {0, 0, 0},
              int threads = 0) {
    CpuRenderer<T> renderer(threads);
    RenderOptions options;
    options.culling = culling;
    options.background = bg;
    ImageF out;
    renderer.render(scene, camera, options, out);
    return out;
}

// An isotropic Gaussian on the optical axis projects to a circular 2D Gaussian of variance
// (f s / z)^2 + 0.3 centred on the principal point; every pixel is alpha * c + (1 - alpha) * bg.
TEST(CpuRendererAnalytic, IsotropicGaussianMatchesClosedForm) {
    const int w = 64, h = 48;
    Camera cam = test::forward_camera(w, h, 60.0);
    cam.intrinsics.cx = 30.25;  // off-centre principal point: it must be honoured
    cam.intrinsics.cy = 20.75;
    const float z = 5.0f, s = 0.08f, opacity = 0.8f;
    const std::array<float, 3> dc{0.3f, -0.4f, 1.1f};
    const std::array<float, 3> bg{0.1f, 0.2f, 0.3f};
    const Scene scene = single_gaussian({0, 0, z}, s, opacity, dc);
    const ImageF image = render<double>(scene, cam, Culling::exact, bg);

    const double f = cam.intrinsics.fx;
    const double variance = std::pow(f * s / z, 2) + 0.3;
    int lit = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const double dx = x + 0.5 - cam.intrinsics.cx, dy = y + 0.5 - cam.intrinsics.cy;
            double alpha = std::min(0.99, opacity * std::exp(-0.5 * (dx * dx + dy * dy) / variance));
            if (alpha < 1.0 / 255.0) alpha = 0;
            lit += alpha > 0;
            for (int c = 0; c < 3; ++c) {
                const double colour = std::max(0.0, kShC0 * dc[c] + 0.5);
                const double expected = alpha * colour + (1 - alpha) * bg[c];
                ASSERT_NEAR(image.rgb[3 * (y * w + x) + c], expected, 1e-6) << "pixel " << x << "," << y;
            }
        }
    EXPECT_GT(lit, 20);  // the Gaussian covers a visible disc, not a pixel
}

// Two Gaussians on the same ray: C = a1 c1 + (1 - a1) a2 c2 + (1 - a1)(1 - a2) bg, with the
// near one in front whatever their order in the scene.
TEST(CpuRendererAnalytic, TwoGaussiansCompositeInDepthOrder) {
    const Camera cam = test::forward_camera(32, 32, 40.0);
    Scene scene = single_gaussian({0, 0, 9}, 0.5f, 0.7f, {-1.0f, 1.5f, -1.0f});   // far, green
    append(scene, single_gaussian({0, 0, 4}, 0.2f, 0.6f, {1.5f, -1.0f, -1.0f}));  // near, red
    const std::array<float, 3> bg{0.0f, 0.0f, 1.0f};
    const ImageF image = render<double>(scene, cam, Culling::exact, bg);
    const double f = cam.intrinsics.fx;
    auto alpha_at = [&](double z, double s, double o, double r2) {
        const double a = std::min(0.99, o * std::exp(-0.5 * r2 / (std::pow(f * s / z, 2) + 0.3)));
        return a < 1.0 / 255.0 ? 0.0 : a;
    };
    auto colour = [](double dc) { return std::max(0.0, kShC0 * dc + 0.5); };
    for (int y = 10; y < 22; ++y)
        for (int x = 10; x < 22; ++x) {
            const double dx = x + 0.5 - 16, dy = y + 0.5 - 16, r2 = dx * dx + dy * dy;
            const double a1 = alpha_at(4, 0.2, 0.6, r2), a2 = alpha_at(9, 0.5, 0.7, r2);
            const double c1[3] = {colour(1.5), colour(-1.0), colour(-1.0)};
            const double c2[3] = {colour(-1.0), colour(1.5), colour(-1.0)};
            for (int c = 0; c < 3; ++c) {
                const double expected = a1 * c1[c] + (1 - a1) * a2 * c2[c] + (1 - a1) * (1 - a2) * bg[c];
                ASSERT_NEAR(image.rgb[3 * (y * 32 + x) + c], expected, 1e-6) << x << "," << y << " ch " << c;
            }
        }
}

// Two opaque Gaussians on one pixel's ray, both at the alpha cap: T = (1 - 0.99)^2 is exactly
// the 1e-4 stop in real arithmetic. The cap is float's 0.99 in every precision (kMaxAlpha), so
// float and double both land 2e-6 under the stop and leave the far layer out, as graphdeco's
// float kernel does; with the exact 0.99 the double reference drew it (a random-scene sweep
// found float and double 2 levels apart at such a pixel).
TEST(CpuRendererAnalytic, TwoCappedLayersStopBeforeTheSecond) {
    Camera cam = test::forward_camera(32, 32, 40.0);
    cam.intrinsics.cx = 15.5;  // both centres project onto pixel (15, 15)'s centre: alpha = cap
    cam.intrinsics.cy = 15.5;
    Scene scene = single_gaussian({0, 0, 9}, 0.5f, 1.0f, {-2.0f, 1.5f, -2.0f});   // far, green
    append(scene, single_gaussian({0, 0, 4}, 0.2f, 1.0f, {1.5f, -2.0f, -2.0f}));  // near, red
    const std::array<float, 3> bg{0.0f, 0.0f, 1.0f};
    const double cap = static_cast<double>(0.99f), red = kShC0 * 1.5 + 0.5;
    // Near layer at the cap, far layer not drawn, the rest of the light from the background.
    const double expected[3] = {cap * red, 0.0, (1 - cap) * bg[2]};
    // Images hold floats: 1e-6 is their rounding; the far layer would add 0.009 green.
    const ImageF as_float = render<float>(scene, cam, Culling::exact, bg);
    const ImageF as_double = render<double>(scene, cam, Culling::exact, bg);
    const std::size_t pixel = 3 * (15 * 32 + 15);
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(as_float.rgb[pixel + c], expected[c], 1e-6) << "float, channel " << c;
        EXPECT_NEAR(as_double.rgb[pixel + c], expected[c], 1e-6) << "double, channel " << c;
    }
}

// Degree 1..3 real SH basis written out independently (graphdeco's sign convention) and
// compared with sh_colour one coefficient at a time.
TEST(CpuRendererAnalytic, ShDegreesOneToThreeMatchHandComputedBasis) {
    const double x0 = 1, y0 = -2, z0 = 3, n = std::sqrt(x0 * x0 + y0 * y0 + z0 * z0);
    const double x = x0 / n, y = y0 / n, z = z0 / n;
    const double basis[16] = {0.28209479177387814,
                              -0.4886025119029199 * y,
                              0.4886025119029199 * z,
                              -0.4886025119029199 * x,
                              1.0925484305920792 * x * y,
                              -1.0925484305920792 * y * z,
                              0.31539156525252005 * (2 * z * z - x * x - y * y),
                              -1.0925484305920792 * x * z,
                              0.5462742152960396 * (x * x - y * y),
                              -0.5900435899266435 * y * (3 * x * x - y * y),
                              2.890611442640554 * x * y * z,
                              -0.4570457994644658 * y * (4 * z * z - x * x - y * y),
                              0.3731763325901154 * z * (2 * z * z - 3 * x * x - 3 * y * y),
                              -0.4570457994644658 * x * (4 * z * z - x * x - y * y),
                              1.445305721320277 * z * (x * x - y * y),
                              -0.5900435899266435 * x * (x * x - 3 * y * y)};
    for (int degree = 1; degree <= 3; ++degree) {
        const int count = sh_coefficient_count(degree);
        for (int k = 0; k < count; ++k) {
            std::vector<float> coefficients(3 * count, 0.0f);
            coefficients[3 * k] = 0.75f;      // red
            coefficients[3 * k + 1] = -0.5f;  // green
            const Vec3<double> c = sh_colour<double>(coefficients.data(), degree, {x, y, z});
            EXPECT_NEAR(c.x, std::max(0.0, 0.75 * basis[k] + 0.5), 1e-12) << "degree " << degree << " k " << k;
            EXPECT_NEAR(c.y, std::max(0.0, -0.5 * basis[k] + 0.5), 1e-12) << "degree " << degree << " k " << k;
            EXPECT_NEAR(c.z, 0.5, 1e-12);
        }
    }
    // Degree truncation: coefficients beyond the scene's degree are never read.
    std::vector<float> coefficients(48, 0.0f);
    coefficients[3 * 9] = 10.0f;
    EXPECT_NEAR(sh_colour<double>(coefficients.data(), 2, {x, y, z}).x, 0.5, 1e-12);
}

// The rendered colour of a degree-1 Gaussian follows the viewing direction.
// Truncating SH to a lower degree renders exactly the scene whose higher coefficients are
// zero (adding zero terms is exact), in float and double; the degree and size follow.
TEST(CpuRendererAnalytic, TruncatedShRendersAsZeroedHigherCoefficients) {
    const Scene full = test::random_scene(test::fresh_seed("truncate SH"));
    const Camera camera = test::forward_camera(64, 48, 70.0);
    for (int degree = 0; degree <= 2; ++degree) {
        Scene truncated = full, zeroed = full;
        truncate_sh(truncated, degree);
        EXPECT_EQ(truncated.sh_degree, degree);
        ASSERT_EQ(truncated.sh.size(), truncated.count() * 3u * static_cast<std::size_t>((degree + 1) * (degree + 1)));
        truncated.check_consistent("truncated");
        const std::size_t stride = full.sh_floats_per_gaussian();
        for (std::size_t i = 0; i < full.count(); ++i)
            for (std::size_t k = 3u * static_cast<std::size_t>((degree + 1) * (degree + 1)); k < stride; ++k)
                zeroed.sh[i * stride + k] = 0.0f;
        EXPECT_EQ(render<float>(truncated, camera, Culling::opacity_aware).rgb,
                  render<float>(zeroed, camera, Culling::opacity_aware).rgb)
            << "degree " << degree;
        EXPECT_EQ(render<double>(truncated, camera, Culling::opacity_aware).rgb,
                  render<double>(zeroed, camera, Culling::opacity_aware).rgb)
            << "degree " << degree;
        // ... and it is not the full scene's image (the random scene has view-dependent colour).
        EXPECT_NE(render<float>(truncated, camera, Culling::opacity_aware).rgb,
                  render<float>(full, camera, Culling::opacity_aware).rgb)
            << "degree " << degree;
    }
    Scene same = full;
    truncate_sh(same, 3);
    EXPECT_EQ(same.sh, full.sh);
    try {
        truncate_sh(same, -1);
        FAIL() << "a negative degree must throw";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "SH degree -1: expected 0..3");
    }
}

TEST(CpuRendererAnalytic, ViewDependentColourFollowsDirection) {
    Scene scene = single_gaussian({0, 0, 0}, 0.3f, 0.9f, {0, 0, 0});
    scene.sh_degree = 1;
    scene.sh.assign(12, 0.0f);
    scene.sh[3 * 3] = 0.8f;  // red varies with -x of the direction (basis -C1 x)
    Camera left = test::forward_camera(16, 16, 30.0, {-1, 0, -5});
    Camera right = test::forward_camera(16, 16, 30.0, {1, 0, -5});
    // Both look down +z; the Gaussian is seen from direction (+1,0,5) and (-1,0,5).
    const ImageF a = render<double>(scene, left, Culling::exact);
    const ImageF b = render<double>(scene, right, Culling::exact);
    auto max_red = [](const ImageF& im) {
        float m = 0;
        for (std::size_t i = 0; i < im.rgb.size(); i += 3) m = std::max(m, im.rgb[i]);
        return m;
    };
    const double dx = 1 / std::sqrt(26.0);
    const double red_left = 0.5 - kShC1 * dx * 0.8, red_right = 0.5 + kShC1 * dx * 0.8;
    EXPECT_LT(max_red(a), max_red(b));
    EXPECT_NEAR(max_red(a) / max_red(b), red_left / red_right, 1e-3);
}

TEST(CpuRendererAnalytic, NearPlaneCullsAndBackgroundFills) {
    const Camera cam = test::forward_camera(20, 10, 60.0);
    const Scene scene = single_gaussian({0, 0, 0.19f}, 1.0f, 0.99f, {1, 1, 1});
    const ImageF image = render<float>(scene, cam, Culling::opacity_aware, {0.25f, 0.5f, 0.75f});
    for (std::size_t i = 0; i < image.rgb.size(); i += 3) {
        ASSERT_FLOAT_EQ(image.rgb[i], 0.25f);
        ASSERT_FLOAT_EQ(image.rgb[i + 2], 0.75f);
    }
    // Just beyond the near plane it is drawn.
    const Scene visible = single_gaussian({0, 0, 0.21f}, 0.01f, 0.99f, {1, 1, 1});
    const ImageF lit = render<float>(visible, cam, Culling::opacity_aware, {0, 0, 0});
    EXPECT_GT(lit.rgb[3 * (5 * 20 + 10)], 0.5f);
}

TEST(CpuRendererAnalytic, SmallAndOddImageSizes) {
    const Scene scene = single_gaussian({0, 0, 3}, 0.5f, 0.9f, {1, 0, 0});
    for (auto [w, h] : {std::pair{1, 1}, std::pair{17, 1}, std::pair{1, 33}, std::pair{31, 17}}) {
        const Camera cam = test::forward_camera(w, h, 60.0);
        const ImageF exact = render<float>(scene, cam, Culling::exact);
        const ImageF fast = render<float>(scene, cam, Culling::opacity_aware);
        ASSERT_EQ(exact.rgb.size(), 3u * w * h);
        EXPECT_GT(exact.rgb[3 * ((h / 2) * w + w / 2)], 0.3f) << w << "x" << h;
        EXPECT_LE(compare(to_rgb8(fast), to_rgb8(exact)).max_abs, 1) << w << "x" << h;
    }
}

// A side of 0, or past kMaxImageSide, is refused by name before anything is drawn.
TEST(CpuRendererAnalytic, InvalidIntrinsicsAreRejectedWithTheirName) {
    const Scene scene = single_gaussian({0, 0, 3}, 0.5f, 0.9f, {1, 0, 0});
    for (const auto& [width, message] :
         {std::pair{0, "camera 'frame7': image size 0x16 must be positive"},
          std::pair{kMaxImageSide + 1,
                    "camera 'frame7': image size 16385x16 exceeds the largest supported side, 16384"}}) {
        Camera cam = test::forward_camera(16, 16, 60.0);
        cam.name = "frame7";
        cam.intrinsics.width = width;
        CpuRenderer<float> renderer;
        ImageF out;
        try {
            renderer.render(scene, cam, RenderOptions{}, out);
            FAIL() << "no error for width " << width;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
        }
        EXPECT_TRUE(out.rgb.empty()) << width;
    }
}

// --- Comparisons on fresh random scenes -------------------------------------------------

struct RandomCase {
    Scene scene;
    Camera camera;
};

RandomCase random_case(const std::string& what, std::size_t count = 1500) {
    const auto seed = test::fresh_seed(what);
    test::RandomSceneParams p;
    p.count = count;
    RandomCase c{test::random_scene(seed, p), test::forward_camera(96, 64, 70.0)};
    return c;
}

TEST(CpuRendererCompare, FloatMatchesDouble) {
    const RandomCase c = random_case("float vs double");
    for (Culling mode : {Culling::exact, Culling::opacity_aware}) {
        const ImageError e =
            compare(to_rgb8(render<float>(c.scene, c.camera, mode)), to_rgb8(render<double>(c.scene, c.camera, mode)));
        EXPECT_GE(e.psnr, 50.0) << culling_name(mode);
        EXPECT_LE(e.max_abs, 2) << culling_name(mode);
    }
}

// Pairs of Gaussians a few float ulps apart, so that their depths differ by less than one
// float ulp: float arithmetic used to tie or swap them against the double reference (on the
// built-in city a road marking and the asphalt under it changed a pixel by 35 levels). Sort
// keys come from a double depth in every precision, so the two renderers sort identically.
TEST(CpuRendererCompare, FloatAndDoubleSortNearTiesIdentically) {
    const std::uint64_t seed = test::fresh_seed("near-tie pairs");
    test::RandomSceneParams params;
    params.count = 1000;
    Scene base = test::random_scene(seed, params);
    Scene scene;
    scene.sh_degree = base.sh_degree;
    scene.resize(2 * base.count());
    const std::size_t stride = base.sh_floats_per_gaussian();
    std::mt19937_64 rng(seed);
    for (std::size_t i = 0; i < base.count(); ++i)
        for (std::size_t copy = 0; copy < 2; ++copy) {
            const std::size_t o = 2 * i + copy;
            for (int a = 0; a < 3; ++a) {
                scene.positions[3 * o + a] = base.positions[3 * i + a];
                scene.scales[3 * o + a] = base.scales[3 * i + a];
            }
            for (int a = 0; a < 4; ++a) scene.rotations[4 * o + a] = base.rotations[4 * i + a];
            scene.opacities[o] = base.opacities[i];
            for (std::size_t k = 0; k < stride; ++k) scene.sh[stride * o + k] = base.sh[stride * i + k];
            if (copy == 1) {
                // A different colour, moved 1..4 float ulps along x and z.
                for (int c = 0; c < 3; ++c) scene.sh[stride * o + c] = -scene.sh[stride * o + c];
                for (int a : {0, 2}) {
                    float& v = scene.positions[3 * o + a];
                    for (int step = 0, n = 1 + static_cast<int>(rng() % 4); step < n; ++step)
                        v = std::nextafter(v, rng() % 2 ? 1e30f : -1e30f);
                }
            }
        }
    scene.update_bounds();
    // Turned 30 degrees about y and moved, so that depth mixes x and z and rounds in float.
    const double c = std::cos(kPi / 6), s = std::sin(kPi / 6);
    Camera camera = test::forward_camera(96, 64, 70.0);
    camera.pose = pose_from_centre({-1.37, 0.21, -0.53}, {c, 0, s, 0, 1, 0, -s, 0, c});

    CpuRenderer<float> single(1);
    CpuRenderer<double> reference(1);
    RenderOptions options;
    ImageF a, b;
    single.render(scene, camera, options, a);
    reference.render(scene, camera, options, b);
    ASSERT_GT(single.sorted_values().size(), 1000u);
    ASSERT_EQ(single.sorted_values().size(), reference.sorted_values().size());
    std::size_t differ = 0;
    for (std::size_t j = 0; j < single.sorted_values().size(); ++j)
        differ += single.sorted_values()[j] != reference.sorted_values()[j];
    EXPECT_EQ(differ, 0u) << "of " << single.sorted_values().size() << " tile-Gaussian pairs";
    const ImageError e = compare(to_rgb8(a), to_rgb8(b));
    EXPECT_LE(e.max_abs, 1) << "psnr " << e.psnr;
}

TEST(CpuRendererCompare, OpacityAwareLosesNothingAgainstExact) {
    for (int trial = 0; trial < 3; ++trial) {
        const RandomCase c = random_case("opacity-aware vs exact, trial " + std::to_string(trial));
        const ImageRGB8 exact = to_rgb8(render<double>(c.scene, c.camera, Culling::exact));
        const ImageRGB8 fast = to_rgb8(render<double>(c.scene, c.camera, Culling::opacity_aware));
        const ImageError e = compare(fast, exact);
        EXPECT_LE(e.max_abs, 1) << "psnr " << e.psnr;
    }
}

TEST(CpuRendererCompare, BBox3SigmaIsCloseToExact) {
    const RandomCase c = random_case("bbox3sigma vs exact");
    const ImageError e = compare(to_rgb8(render<float>(c.scene, c.camera, Culling::bbox3sigma)),
                                 to_rgb8(render<double>(c.scene, c.camera, Culling::exact)));
    EXPECT_GE(e.psnr, 45.0);
}

// The opacity-aware tile set is a subset of the 3-sigma square for ordinary Gaussians, and
// every pixel whose alpha reaches 1/255 lies in a tile of the set.
TEST(CpuRendererCompare, OpacityAwareTilesCoverEveryContributingPixel) {
    const RandomCase c = random_case("opacity-aware tile cover", 300);
    CpuRenderer<double> renderer(1);
    RenderOptions options;
    ImageF out;
    renderer.render(c.scene, c.camera, options, out);
    const View<double> view = make_view<double>(c.camera, c.scene.origin);
    std::size_t checked = 0;
    for (std::size_t i = 0; i < c.scene.count(); ++i) {
        if (renderer.tiles_touched()[i] == 0) continue;
        const Projected<double>& g = renderer.projected()[i];
        std::vector<bool> touched(static_cast<std::size_t>(view.tiles_x * view.tiles_y), false);
        for_each_touched_tile(g, Culling::opacity_aware, view, [&](std::uint32_t t) { touched[t] = true; });
        for (int y = 0; y < view.height; ++y)
            for (int x = 0; x < view.width; ++x) {
                PixelAccumulator<double> acc;
                blend_gaussian(acc, g.mean, g.conic, g.opacity, g.colour, x + 0.5, y + 0.5);
                if (acc.transmittance < 1.0) {
                    ++checked;
                    ASSERT_TRUE(touched[(y / kTileSize) * view.tiles_x + x / kTileSize])
                        << "gaussian " << i << " pixel " << x << "," << y;
                }
            }
    }
    EXPECT_GT(checked, 1000u);
}

// visible_box (the GPU rasterizer's per-warp skip): every pixel a Gaussian draws on, in float
// and in double, has its centre inside the box; and the box does skip most of the pixels of
// the tiles a Gaussian touches, or it would save nothing.
template <typename T>
void check_visible_box(const char* name) {
    const RandomCase c = random_case(name, 300);
    CpuRenderer<T> renderer(1);
    RenderOptions options;
    ImageF out;
    renderer.render(c.scene, c.camera, options, out);
    const View<T> view = make_view<T>(c.camera, c.scene.origin);
    std::size_t drawn = 0, in_tiles = 0, skipped = 0;
    for (std::size_t i = 0; i < c.scene.count(); ++i) {
        if (renderer.tiles_touched()[i] == 0) continue;
        const Projected<T>& g = renderer.projected()[i];
        const PixelBox<T> box = visible_box(g);
        std::vector<bool> touched(static_cast<std::size_t>(view.tiles_x * view.tiles_y), false);
        for_each_touched_tile(g, Culling::opacity_aware, view, [&](std::uint32_t t) { touched[t] = true; });
        for (int y = 0; y < view.height; ++y)
            for (int x = 0; x < view.width; ++x) {
                const T cx = static_cast<T>(x) + T(0.5), cy = static_cast<T>(y) + T(0.5);
                const bool missed = box_misses_centres(box, cx, cy, cx, cy);
                if (touched[(y / kTileSize) * view.tiles_x + x / kTileSize]) {
                    ++in_tiles;
                    skipped += missed;
                }
                // The rasterizer's own test, as the GPU runs it.
                const T power = gaussian_power(g.mean, g.conic, cx, cy);
                if (!(power >= min_visible_power(g.opacity))) continue;
                PixelAccumulator<T> acc;
                blend_power(acc, power, g.opacity, g.colour);
                if (acc.transmittance < T(1)) {
                    ++drawn;
                    ASSERT_FALSE(missed) << name << ": gaussian " << i << " draws pixel " << x << "," << y
                                         << " outside its visible box";
                }
            }
    }
    EXPECT_GT(drawn, 1000u);
    EXPECT_GT(static_cast<double>(skipped), 0.3 * static_cast<double>(in_tiles)) << name;
    std::printf("%s: %zu drawn pixels inside their boxes; the boxes skip %.1f%% of the pixels of touched tiles\n", name,
                drawn, 100.0 * static_cast<double>(skipped) / static_cast<double>(in_tiles));
}

TEST(CpuRendererCompare, VisibleBoxHoldsEveryDrawnPixel) {
    check_visible_box<float>("visible box, float");
    check_visible_box<double>("visible box, double");
    // A Gaussian whose extent is not finite is never skipped; one that cannot reach 1/255 always is.
    Projected<float> g{};
    g.opacity = 0.5f;
    g.cov = {std::nanf(""), 0.f, 1.f};
    EXPECT_FALSE(box_misses_centres(visible_box(g), 0.5f, 0.5f, 0.5f, 0.5f));
    g.cov = {1.f, 0.f, 1.f};
    g.opacity = 1.0f / 512;
    EXPECT_TRUE(box_misses_centres(visible_box(g), 0.5f, 0.5f, 100.5f, 100.5f));
}

TEST(CpuRendererCompare, DeterministicAcrossRunsAndThreadCounts) {
    test::RandomSceneParams p;
    p.count = 3000;
    // Ties: a block of Gaussians at exactly the same depth must keep index order.
    Scene scene = test::random_scene(test::fresh_seed("determinism"), p);
    for (std::size_t i = 0; i < 200; ++i) scene.positions[3 * i + 2] = 6.0f;
    const Camera cam = test::forward_camera(80, 48, 70.0);
    const ImageF a = render<float>(scene, cam, Culling::opacity_aware, {0, 0, 0}, 1);
    const ImageF b = render<float>(scene, cam, Culling::opacity_aware, {0, 0, 0}, 1);
    const ImageF c = render<float>(scene, cam, Culling::opacity_aware, {0, 0, 0}, 3);
    EXPECT_EQ(a.rgb, b.rgb);
    EXPECT_EQ(a.rgb, c.rgb);
}

// Ties in depth are resolved by Gaussian index: the lower index is in front.
TEST(CpuRendererCompare, EqualDepthsOrderByIndex) {
    Scene scene = single_gaussian({0, 0, 5}, 0.5f, 0.9f, {1.5f, -1, -1});   // red, index 0
    append(scene, single_gaussian({0, 0, 5}, 0.5f, 0.9f, {-1, 1.5f, -1}));  // green, index 1
    const Camera cam = test::forward_camera(16, 16, 40.0);
    const ImageF image = render<float>(scene, cam, Culling::opacity_aware);
    const float* centre = &image.rgb[3 * (8 * 16 + 8)];
    EXPECT_GT(centre[0], centre[1]);
}

// UTM-sized coordinates: the same scene 10^6..10^7 m from the world origin, seen by the
// same camera moved by the same offset, renders like the scene near the origin. A naive
// float layout (absolute positions in float, no recentring) visibly fails the same check.
TEST(CpuRendererCompare, LargeCoordinatesRenderLikeTheOrigin) {
    const std::array<double, 3> offset{4.52e6, 5.41e6, 312.0};
    test::RandomSceneParams p;
    p.count = 1500;
    p.log_scale_min = -3.5;
    const Scene local = test::random_scene(test::fresh_seed("large coordinates"), p);
    const Camera cam = test::forward_camera(96, 64, 70.0, {0.3, -0.2, 0.1});
    const ImageRGB8 reference = to_rgb8(render<float>(local, cam, Culling::opacity_aware));

    auto shifted = [&](bool recentre) {
        Scene s = local;
        for (std::size_t i = 0; i < s.count(); ++i)
            for (int a = 0; a < 3; ++a)  // as a loader would see them: world coordinates
                s.positions[3 * i + a] = static_cast<float>(offset[a] + local.positions[3 * i + a]);
        if (recentre) {
            // What the loaders do: origin at the bounds centre, computed from double world
            // coordinates, positions relative to it.
            for (std::size_t i = 0; i < s.count(); ++i)
                for (int a = 0; a < 3; ++a) s.positions[3 * i + a] = local.positions[3 * i + a];
            s.origin = offset;
            s.recentre();
        }
        s.update_bounds();
        return s;
    };
    Camera moved = cam;
    moved.pose = pose_from_centre({0.3 + offset[0], -0.2 + offset[1], 0.1 + offset[2]}, {1, 0, 0, 0, 1, 0, 0, 0, 1});

    const ImageError good = compare(to_rgb8(render<float>(shifted(true), moved, Culling::opacity_aware)), reference);
    EXPECT_LE(good.max_abs, 1) << "psnr " << good.psnr;
    const ImageError naive = compare(to_rgb8(render<float>(shifted(false), moved, Culling::opacity_aware)), reference);
    EXPECT_LT(naive.psnr, 30.0) << "the naive float layout should fail visibly";
    EXPECT_GT(naive.max_abs, 50);
}

}  // namespace
}  // namespace catgs
