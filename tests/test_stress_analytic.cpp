// Numerical stress suite, CPU part: what the renderer draws for single adversarial Gaussians
// (against closed forms and the near plane), and StressBugs, one test per renderer bug the
// suite found, each described where it is. The CPU backend and its bounds are in
// test_stress.cpp, the scenes in stress_scenes.hpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>
#include <tuple>
#include <utility>

#include "catgs/constants.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "catgs_paths.hpp"
#include "stress_harness.hpp"
#include "stress_scenes.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

using test::stress::cache_vs_full_levels;
using test::stress::count_nonfinite;
using test::stress::kBackground;
using test::stress::Mode;
using test::stress::one_gaussian;
using test::stress::options_for;
using test::stress::seed_note;
using test::stress::StressCase;
namespace stress = test::stress;

// --- What the renderer draws for degenerate input ----------------------------------------

template <typename T>
ImageF render_one(const Scene& scene, const Camera& camera, Culling culling = Culling::exact,
                  FrameStats* stats = nullptr) {
    CpuRenderer<T> r(1);
    ImageF out;
    const FrameStats s = r.render(scene, camera, options_for(culling, Mode::plain), out);
    if (stats) *stats = s;
    return out;
}

double max_abs_difference(const ImageF& a, const ImageF& b) {
    double m = 0;
    for (std::size_t i = 0; i < a.rgb.size(); ++i) m = std::max(m, std::fabs(static_cast<double>(a.rgb[i]) - b.rgb[i]));
    return m;
}

// Quaternions are used as given (quat_to_matrix, no normalisation): a zero quaternion is the
// identity; k q is I + k^2 (R(q) - I), e.g. (0, 2, 0, 0) is diag(1, -7, -7), which renders
// as the identity with the y and z scales multiplied by 7; a NaN one is culled.
TEST(StressAnalytic, QuaternionsAreUsedAsGiven) {
    const Camera cam = test::forward_camera(64, 48, 60);
    const Scene identity = one_gaussian({0.1f, -0.05f, 4}, {0.3f, 0.05f, 0.1f}, {1, 0, 0, 0}, 0.8f, {1, 0, -1});
    const Scene zero = one_gaussian({0.1f, -0.05f, 4}, {0.3f, 0.05f, 0.1f}, {0, 0, 0, 0}, 0.8f, {1, 0, -1});
    const Scene doubled = one_gaussian({0.1f, -0.05f, 4}, {0.3f, 0.05f, 0.1f}, {0, 2, 0, 0}, 0.8f, {1, 0, -1});
    const Scene stretched = one_gaussian({0.1f, -0.05f, 4}, {0.3f, 0.35f, 0.7f}, {1, 0, 0, 0}, 0.8f, {1, 0, -1});
    const Scene nan = one_gaussian({0.1f, -0.05f, 4}, {0.3f, 0.05f, 0.1f}, {stress::kNaN, 0, 0, 0}, 0.8f, {1, 0, -1});
    const Scene empty = stress::empty_scene(0);
    EXPECT_EQ(render_one<float>(zero, cam).rgb, render_one<float>(identity, cam).rgb);
    EXPECT_LT(max_abs_difference(render_one<double>(doubled, cam), render_one<double>(stretched, cam)), 1e-6);
    EXPECT_LT(max_abs_difference(render_one<float>(doubled, cam), render_one<double>(stretched, cam)), 1e-5);
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        FrameStats s;
        EXPECT_EQ(render_one<float>(nan, cam, culling, &s).rgb, render_one<float>(empty, cam, culling).rgb);
        EXPECT_EQ(s.visible, 0u) << culling_name(culling);
    }
}

// Scales 1e-20 x 1e-20 x 1 along x: the 3D covariance is singular in float (its determinant
// 1e-80 underflows), the 2D covariance is diag((f s/z)^2, 0) + 0.3: a horizontal line one
// blur wide, alpha = sigma exp(-0.5 (dx^2 / ((f/z)^2 + 0.3) + dy^2 / 0.3)), in both precisions.
// All-zero scales leave the blur alone: a dot of variance 0.3.
TEST(StressAnalytic, UnderflowingCovariancesRenderAsTheBlur) {
    const Camera cam = test::forward_camera(64, 48, 60);
    const double f = cam.intrinsics.fx, z = 5, sigma = 0.9;
    const std::array<float, 3> dc{1.2f, -0.3f, 0.4f};
    for (const auto& scales : {std::array<float, 3>{1, 1e-20f, 1e-20f}, std::array<float, 3>{0, 0, 0}}) {
        const Scene scene =
            one_gaussian({0, 0, static_cast<float>(z)}, scales, {1, 0, 0, 0}, static_cast<float>(sigma), dc);
        const double vx = std::pow(f * scales[0] / z, 2) + kCovarianceBlur, vy = kCovarianceBlur;
        const ImageF fl = render_one<float>(scene, cam), db = render_one<double>(scene, cam);
        for (int y = 0; y < 48; ++y)
            for (int x = 0; x < 64; ++x) {
                const double dx = x + 0.5 - cam.intrinsics.cx, dy = y + 0.5 - cam.intrinsics.cy;
                double alpha = std::min(kMaxAlpha, sigma * std::exp(-0.5 * (dx * dx / vx + dy * dy / vy)));
                if (alpha < kMinAlpha) alpha = 0;
                for (int ch = 0; ch < 3; ++ch) {
                    const double c = std::max(0.0, kShC0 * dc[static_cast<std::size_t>(ch)] + kShColourOffset);
                    const double expected = alpha * c + (1 - alpha) * kBackground[static_cast<std::size_t>(ch)];
                    const std::size_t i = 3 * (static_cast<std::size_t>(y) * 64 + x) + static_cast<std::size_t>(ch);
                    ASSERT_NEAR(db.rgb[i], expected, 1e-6) << "double " << x << "," << y << " scale x " << scales[0];
                    ASSERT_NEAR(fl.rgb[i], expected, 1e-5) << "float " << x << "," << y << " scale x " << scales[0];
                }
            }
    }
}

// The camera inside a Gaussian of scale S whose mean is in front of the near plane on the
// optical axis: the 2D covariance is (f S / z)^2 + 0.3 isotropic, so every pixel is
// alpha c + (1 - alpha) bg with alpha ~ sigma: a uniform veil, in float too. S = 1e6 at 5
// degrees on 8192 columns puts sigma at 4e11 px, det at 3e46: past float's range.
TEST(StressAnalytic, CameraInsideAHugeGaussianSeesAUniformVeil) {
    const double sigma = 0.6, z = 0.21;
    const std::array<float, 3> dc{1, 0, -1};
    for (const auto& [width, fov, s] : {std::tuple{72, 60.0, 10.0}, std::tuple{72, 60.0, 1e3}, std::tuple{72, 5.0, 1e6},
                                        std::tuple{8192, 5.0, 1e6}}) {
        const Camera cam = test::forward_camera(width, 8, fov);
        const Scene scene = one_gaussian({0, 0, static_cast<float>(z)},
                                         {static_cast<float>(s), static_cast<float>(s), static_cast<float>(s)},
                                         {1, 0, 0, 0}, static_cast<float>(sigma), dc);
        const double variance = std::pow(cam.intrinsics.fx * s / z, 2) + kCovarianceBlur;
        const ImageF fl = render_one<float>(scene, cam, Culling::opacity_aware), db = render_one<double>(scene, cam);
        double worst_f = 0, worst_d = 0;
        for (int y = 0; y < 8; ++y)
            for (int x = 0; x < width; ++x) {
                const double dx = x + 0.5 - cam.intrinsics.cx, dy = y + 0.5 - cam.intrinsics.cy;
                const double alpha = sigma * std::exp(-0.5 * (dx * dx + dy * dy) / variance);
                for (int ch = 0; ch < 3; ++ch) {
                    const double c = std::max(0.0, kShC0 * dc[static_cast<std::size_t>(ch)] + kShColourOffset);
                    const double expected = alpha * c + (1 - alpha) * kBackground[static_cast<std::size_t>(ch)];
                    const std::size_t i = 3 * (static_cast<std::size_t>(y) * width + x) + static_cast<std::size_t>(ch);
                    worst_d = std::max(worst_d, std::fabs(db.rgb[i] - expected));
                    worst_f = std::max(worst_f, std::fabs(fl.rgb[i] - expected));
                }
            }
        EXPECT_LT(worst_d, 1e-6) << width << " px, " << fov << " deg, scale " << s;
        EXPECT_LT(worst_f, 1e-5) << width << " px, " << fov << " deg, scale " << s
                                 << ": float drops the veil when its determinant overflows (see StressBugs)";
    }
}

// The near plane 0.2: at the camera centre and behind, nothing is drawn in any
// configuration; a few ulps in front, both precisions draw. Exactly at z = 0.2f (the float
// nearest 0.2, 3e-9 beyond it) the two precisions disagree by design: double compares
// 0.2000000030 > 0.2 and draws, float compares 0.2f > 0.2f and culls. Any precision has such
// a boundary; what matters is that it is the near plane within one float ulp.
TEST(StressNearPlane, CentreBehindAndOnThePlane) {
    const Camera cam = test::forward_camera(40, 30, 60);
    auto visible = [&](float z, bool use_double, Culling culling) {
        const Scene scene = one_gaussian({0, 0, z}, {0.01f, 0.01f, 0.01f}, {1, 0, 0, 0}, 0.9f, {1, 1, 1});
        FrameStats s;
        const ImageF image =
            use_double ? render_one<double>(scene, cam, culling, &s) : render_one<float>(scene, cam, culling, &s);
        EXPECT_EQ(count_nonfinite(image), 0u);
        return s.visible;
    };
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware})
        for (bool use_double : {false, true}) {
            const std::string what = std::string(use_double ? "double " : "float ") + culling_name(culling);
            EXPECT_EQ(visible(0.0f, use_double, culling), 0u) << what << ": at the camera centre";
            EXPECT_EQ(visible(-0.0f, use_double, culling), 0u) << what;
            EXPECT_EQ(visible(-1.0f, use_double, culling), 0u) << what << ": behind";
            EXPECT_EQ(visible(std::nextafter(0.2f, 0.0f), use_double, culling), 0u) << what << ": one ulp behind";
            EXPECT_EQ(visible(0.2f * (1 + 1e-6f), use_double, culling), 1u) << what << ": a few ulps in front";
            EXPECT_EQ(visible(0.2f, use_double, culling), use_double ? 1u : 0u) << what << ": exactly 0.2f";
        }
}

// --- Bugs -----------------------------------------------------------------------------
// Each test below failed on the renderer as of 230c838. Bugs 1, 2, 3b and 4 are fixed in
// b131577 (the tests stay as regression tests); 3 and 5 are open as of 0aaf544, and the
// report that came with this suite gives the proposed patch for them.

// Bug 1. A NaN opacity is not culled: blend_gaussian computes alpha = NaN * exp(power) = NaN,
// `alpha < 0.99 ? alpha : 0.99` turns it into 0.99, and `alpha < 1/255` lets it through, so
// exact culling paints the Gaussian's colour at alpha 0.99 over the WHOLE image, bbox3sigma
// over its square, while opacity-aware culls it (its level log(NaN) is NaN). The same path
// makes a NaN power draw: inf - inf in float when a far off-screen mean makes dx^2 overflow
// (bug 1b). Expected: such a Gaussian draws nothing, in every mode. (Fixed in b131577.)
TEST(StressBugs, NanOpacityDrawsNothingInEveryMode) {
    const Camera cam = test::forward_camera(48, 32, 60);
    const Scene scene = one_gaussian({0, 0, 3}, {0.1f, 0.1f, 0.1f}, {1, 0, 0, 0}, stress::kNaN, {2, -1, -1});
    const Scene empty = stress::empty_scene(0);
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        EXPECT_EQ(render_one<float>(scene, cam, culling).rgb, render_one<float>(empty, cam, culling).rgb)
            << culling_name(culling);
        EXPECT_EQ(render_one<double>(scene, cam, culling).rgb, render_one<double>(empty, cam, culling).rgb)
            << culling_name(culling);
    }
}

TEST(StressBugs, FarOffScreenMeanDrawsNothingInFloat) {
    // A finite position 1e20 m to the side at a depth of 3 m: the mean is 1e21 px off-screen,
    // dx^2 overflows float to inf, and the conic's cross term (b < 0 for this rotation, dx and
    // dy of one sign) makes power = -inf - (-inf) = NaN: exact culling then paints alpha 0.99
    // over the whole image.
    const Camera cam = test::forward_camera(48, 32, 60);
    const Scene scene =
        one_gaussian({1e20f, 1e20f, 3}, {0.3f, 0.1f, 0.05f}, {0.9f, 0.3f, -0.2f, 0.25f}, 0.8f, {2, -1, -1});
    const Scene empty = stress::empty_scene(0);
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        const ImageF image = render_one<float>(scene, cam, culling);
        EXPECT_EQ(image.rgb, render_one<float>(empty, cam, culling).rgb) << culling_name(culling);
    }
}

// Bug 2. SH coefficients near float max or infinite write inf into the float image:
// sh_colour clamps the colour at 0 but not above, the blend sums colour x weight, and
// C + T bg overflows float (in the double renderer too, when it is converted to the float
// image). Expected: a finite image; the 8-bit output is saturated either way. (Fixed in
// b131577: colours clamp at kMaxShColour.)
TEST(StressBugs, ExtremeShColoursKeepTheFloatImageFinite) {
    const Camera cam = test::forward_camera(48, 32, 60);
    for (float v : {1e38f, 3.4e38f, stress::kInf}) {
        Scene scene = stress::empty_scene(3);
        for (int i = 0; i < 4; ++i) {
            stress::Gaussian g;
            g.position = {0.05f * static_cast<float>(i), 0, 3.0f + static_cast<float>(i)};
            g.scale = {0.5f, 0.5f, 0.5f};
            g.opacity = 0.7f;
            g.sh.assign(scene.sh_floats_per_gaussian(), v);  // every coefficient, every channel
            stress::add(scene, g);
        }
        scene.update_bounds();
        for (Culling culling : {Culling::exact, Culling::opacity_aware}) {
            EXPECT_EQ(count_nonfinite(render_one<float>(scene, cam, culling)), 0u) << "float, SH " << v;
            EXPECT_EQ(count_nonfinite(render_one<double>(scene, cam, culling)), 0u) << "double, SH " << v;
        }
    }
}

// Bug 3. Float loses Gaussians whose 2D covariance is nearly rank one: the determinant
// cxx cyy - cxy^2 of a Gaussian with one axis of 1e4 m projects to ~1e20 - 1e20 in float,
// which cancels to anything (<= 0: culled; else a conic wrong by orders of magnitude), and
// R S S^T R^T has already lost the thin axes. The true determinant is >= 0.3 (cxx + cyy)
// thanks to the blur. Its float projection must match the double one. (Open as of 0aaf544:
// b131577 scales the covariance before cxx cyy - cxy^2, which removes the overflow of 3b but
// not this cancellation. Fix: form Sigma' from M = J W R S, det by Binet-Cauchy.)
TEST(StressBugs, FloatProjectsNearlyRankOneCovariances) {
    const Camera cam = test::forward_camera(72, 40, 60);
    const View<float> vf = make_view<float>(cam, {0, 0, 0});
    const View<double> vd = make_view<double>(cam, {0, 0, 0});
    const std::uint64_t seed = test::fresh_seed("stress rank one");
    stress::Draw d(seed);
    int checked = 0;
    for (int i = 0; i < 200; ++i) {
        stress::Gaussian g = d.ordinary(1.0, 30.0);
        g.scale[static_cast<std::size_t>(d.integer(0, 2))] = static_cast<float>(d.log_uniform(1e3, 1e6));
        const float sh[3] = {0, 0, 0};
        const GaussianRef ref{g.position.data(), g.scale.data(), g.rotation.data(), g.opacity, sh, 0};
        Projected<double> pd;
        Projected<float> pf;
        if (!project_gaussian(ref, vd, pd)) continue;
        ++checked;
        ASSERT_TRUE(project_gaussian(ref, vf, pf))
            << "float culls gaussian " << i << " that double projects " << seed_note(seed);
        // The conic (the inverse covariance) decides alpha; compare it through q at a few
        // offsets of a pixel or more, relative to the offset's length squared over the blur.
        for (auto [dx, dy] : {std::pair{1.0, 0.0}, std::pair{0.0, 1.0}, std::pair{3.0, -2.0}, std::pair{-5.0, 7.0}}) {
            const double qd = conic_form(pd.conic, dx, dy);
            const double qf = conic_form(cast<double>(pf.conic), dx, dy);
            EXPECT_NEAR(qf, qd, 1e-3 * (dx * dx + dy * dy) / kCovarianceBlur)
                << "gaussian " << i << " " << seed_note(seed);
        }
    }
    EXPECT_GT(checked, 150);
}

// Bug 3b. The same determinant overflows float for a screen-filling Gaussian: scale 1e6 at
// 0.21 m seen with f = 94000 px (8192 columns at 5 degrees) has sigma 4e11 px and det 3e46 >
// float max, so float culls it (the veil of CameraInsideAHugeGaussianSeesAUniformVeil
// vanishes) while double draws it. (Fixed in b131577.)
TEST(StressBugs, FloatKeepsAScreenFillingGaussianWhoseDeterminantOverflows) {
    const Camera cam = test::forward_camera(8192, 4, 5.0);
    const Scene scene = one_gaussian({0, 0, 0.21f}, {1e6f, 1e6f, 1e6f}, {1, 0, 0, 0}, 0.6f, {1, 0, -1});
    FrameStats sf, sd;
    render_one<float>(scene, cam, Culling::opacity_aware, &sf);
    render_one<double>(scene, cam, Culling::opacity_aware, &sd);
    EXPECT_EQ(sd.visible, 1u);
    EXPECT_EQ(sf.visible, 1u) << "float culls the Gaussian the camera is inside";
}

// Bug 4. The speculative cache's envelope misses Gaussians whose footprint grows faster than
// the bound assumes. The planner bounds footprint growth by (largest cached footprint) x
// (translation / depth + rotation); but a needle seen end-on or a disc seen edge-on has a
// one-pixel footprint that opens up to its full 3D size as the line of sight turns: a 20 m
// needle at 2 m depth seen from 5 mm aside spans f L dt / z^2 ~ 3 px. Cached frames then
// lack pairs the per-frame pipeline has (measured up to 130 levels in the degenerate family).
// (Fixed in b131577: footprint_bound_px.)
TEST(StressBugs, CacheEnvelopeHoldsForNeedlesAndDiscsSeenEndOn) {
    const StressCase c = stress::needles_and_discs_end_on(test::fresh_seed("stress cache needles"));
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma}) {
        CpuRenderer<double> cached(2), full(2);
        RenderOptions o = options_for(culling, Mode::cache);
        int cached_frames = 0;
        std::uint64_t missing = 0;
        int worst = 0;
        for (const Camera& cam : c.path) {
            ImageF a, b;
            const FrameStats s = cached.render(c.scene, cam, o, a);
            full.render(c.scene, cam, options_for(culling, Mode::plain), b);
            worst = std::max(worst, compare(to_rgb8(a), to_rgb8(b)).max_abs);
            if (s.key_frame) continue;
            ++cached_frames;
            missing += test::missing_pairs(cached, full);
        }
        std::cout << "[stress] cache with needles, " << culling_name(culling) << ": " << cached_frames << " cached, "
                  << missing << " missing pairs, worst " << worst << " levels" << std::endl;
        EXPECT_EQ(missing, 0u) << culling_name(culling);
        EXPECT_LE(worst, cache_vs_full_levels(culling)) << culling_name(culling);
    }
}

// Bug 5. The same envelope ignores Gaussians that are in no list at the key frame: the planner
// bounds the motion of the cached Gaussians only (nearest cached depth), but a Gaussian near
// the camera just outside the image moves f dt / z per frame, far more. Here one at 0.3 m
// depth sits 6 px right of the image (beyond the 2 px guard) in front of a scene 8..12 m
// away; the camera moves 5 cm a frame to the right, which the envelope accepts (0.6 px at
// 8 m), and the near Gaussian enters the image by 10 px a frame: the cached frames lack it
// (measured: 196 levels in opacity-aware). (A needle just outside the image that opens up
// into it is the same hole; the degenerate family finds those: 76 levels in bbox3sigma.)
// Open as of 0aaf544.
TEST(StressBugs, CacheEnvelopeHoldsForANearGaussianJustOutsideTheImage) {
    const StressCase c = stress::near_gaussian_outside_the_image(test::fresh_seed("stress cache near gaussian"));
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma, Culling::exact}) {
        CpuRenderer<double> cached(2), full(2);
        int worst = 0, cached_frames = 0;
        for (const Camera& cam : c.path) {
            ImageF a, b;
            cached_frames += !cached.render(c.scene, cam, options_for(culling, Mode::cache), a).key_frame;
            full.render(c.scene, cam, options_for(culling, Mode::plain), b);
            worst = std::max(worst, compare(to_rgb8(a), to_rgb8(b)).max_abs);
        }
        std::cout << "[stress] cache with a near Gaussian outside the image, " << culling_name(culling) << ": "
                  << cached_frames << " cached, worst " << worst << " levels" << std::endl;
        EXPECT_LE(worst, cache_vs_full_levels(culling)) << culling_name(culling);
    }
}

}  // namespace
}  // namespace catgs
