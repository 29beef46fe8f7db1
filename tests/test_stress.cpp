// Numerical stress suite, CPU part: the adversarial scenes of tests/stress_scenes.hpp through
// every pipeline configuration (float and double; exact, bbox3sigma and opacity-aware
// culling; plain, CaT-GS split with k = 8, and the speculative cache over a 6-frame path),
// each frame against the exact double-precision reference (CpuRenderer<double>, exact
// culling, no split, no cache). Every render must be free of NaN/inf in its float image and
// within the stated bounds of its case family; seeds are fresh every run (test::fresh_seed
// prints them; CATGS_TEST_SEED replays one). What the CUDA part (tests/gpu/test_cuda_stress.cpp)
// runs the same way is in tests/stress_harness.hpp; the bounds are each backend's own.
//
// StressBugs holds one test per renderer bug this suite found, each described where it is.
// Bugs 1, 2, 3b and 4 are fixed in b131577; bugs 3 and 5 are open as of 0aaf544, so those two
// tests fail, and so do the family and property tests whose inputs reach them (huge_scales,
// degenerate, the mixtures, field of view). The bounds are the ones measured with the fixes
// for 3 and 5 (the suite's report) applied.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs_paths.hpp"
#include "stress_harness.hpp"
#include "stress_scenes.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

using test::stress::Bound;
using test::stress::Config;
using test::stress::Family;
using test::stress::Frame;
using test::stress::Measured;
using test::stress::Mode;
using test::stress::StressCase;
using test::stress::cache_vs_full_levels;
using test::stress::count_nonfinite;
using test::stress::describe;
using test::stress::kBackground;
using test::stress::one_gaussian;
using test::stress::options_for;
using test::stress::seed_note;
namespace stress = test::stress;

/// Log lines "[stress] ...", seeds "stress ...".
const std::string kSuite = "stress";

/// Every backend configuration except the reference itself (double, exact, plain).
std::vector<Config> all_configs() { return stress::all_configs(/*with_double=*/true); }

/// Renders frame 0 of the case's path (plain, split), or the whole path through one
/// renderer (cache: the frames after a key frame may come from the cache).
template <typename T>
std::vector<Frame> render_frames(const StressCase& c, Culling culling, Mode mode, int threads = 0) {
    CpuRenderer<T> renderer(threads);
    const RenderOptions options = options_for(culling, mode);
    const std::size_t frames = mode == Mode::cache ? c.path.size() : 1;
    std::vector<Frame> out;
    for (std::size_t k = 0; k < frames; ++k) {
        Frame f;
        f.stats = renderer.render(c.scene, c.path[k], options, f.image);
        f.rgb8 = to_rgb8(f.image);
        out.push_back(std::move(f));
    }
    return out;
}

std::vector<Frame> render_frames(const StressCase& c, const Config& cfg, int threads = 0) {
    return cfg.use_double ? render_frames<double>(c, cfg.culling, cfg.mode, threads)
                          : render_frames<float>(c, cfg.culling, cfg.mode, threads);
}

/// The exact double reference of every frame of the path.
std::vector<Frame> reference_frames(const StressCase& c) {
    std::vector<Frame> out;
    for (const Camera& cam : c.path) {
        StressCase one = c;
        one.path = {cam};
        out.push_back(std::move(render_frames<double>(one, Culling::exact, Mode::plain).front()));
    }
    return out;
}

Measured measure(const std::vector<Frame>& frames, const std::vector<Frame>& reference) {
    Measured m;
    for (std::size_t k = 0; k < frames.size(); ++k) m.add(frames[k], reference[k].rgb8);
    return m;
}

// --- Bounds ---------------------------------------------------------------------------
//
// Each bound is the largest error measured over 350 seeds x every configuration of its class
// (StressMeasure.DISABLED_MeasureBounds, on the renderer with the fixes of StressBugs
// applied), plus a margin; the measured worst values are in the comments. The fixes matter:
// without them float renders of the huge_scales, degenerate, far_away and invalid families
// were off by up to 238 levels and the cache missed Gaussians (see StressBugs). SH colours
// clamp at kMaxShColour (1e4 as of b131577; the measurements were taken with 1e30, which
// amplifies the split and bbox3sigma differences of the SH families more, not less).
//
// Why float differs from double at all: every stage runs in the render precision, so a
// quantity that lands within rounding of a threshold flips: the 1/255 alpha skip, the 1e-4
// transmittance stop, the "power > 0" skip, the near plane, the 0.5 rounding to 8 bits. For
// ordinary Gaussians that moves a pixel by one level. The families below say where it can
// move it by more.

/// Per family, the bound of each class of configuration (stress::BoundClass, lossless and
/// bbox3sigma per precision):
///  - lossless: exact or opacity-aware culling, plain or with the cache. In double these only
///    drop pairs whose alpha is below 1/255 anyway (opacity-aware) or reuse lists that
///    provably hold every needed pair, re-sorted by the current depth (cache).
///  - split (CaT-GS, k = 8, exact or opacity-aware culling, both precisions): not lossless.
///    The unsplit blend stops BEFORE the Gaussian that would take T below 1e-4 (graphdeco's
///    exclusive stop), and that Gaussian can carry alpha 0.99 at T up to 1e-4 / 0.01: up to
///    1% of the light, dropped. A later sub-task blends it from its own T = 1, so the merge
///    keeps it: 0.0101 x 255 x |colour - background| = up to 2.6 levels for colours <= 1
///    (more for brighter SH colours) wherever an opaque (opacity >= 0.99) Gaussian ends a
///    pixel's blend.
///  - bbox3sigma (any mode): graphdeco's square of tiles around the 3-sigma circle cuts the
///    tails of opaque Gaussians, whose alpha at 3 sigma is 0.011 sigma (> 1/255 for sigma >
///    0.35): lossy by design, a few levels per cut tail.
struct FamilyBounds {
    Bound double_lossless, float_lossless, split, double_bbox, float_bbox;
};

/// Double, lossless configurations: measured identical to the reference in every family
/// (0 levels over 350 seeds); one level of margin for a sum that the cache's re-sort or
/// opacity-aware culling regroups onto the other side of a half level.
constexpr Bound kDoubleLossless{1, 80.0, 0.0};
/// Float where nothing amplifies rounding: one level where a value lands on the other side
/// of a threshold (1/255, 1e-4, a half level). Measured 1 level, PSNR >= 74.5 dB.
constexpr Bound kFloatOneLevel{1, 72.0, 0.0};
/// Split with ordinary colours: the exclusive-stop difference (above) at a few pixels.
/// Measured at most 2 levels, PSNR >= 70.6 dB (ties: dense lists, many 1-level moves).
constexpr Bound kSplitFewLevels{3, 67.0, 0.0005};

// Measured worst values over 350 seeds (three runs of 150, 100 and 100; every configuration
// of the class; 72 x 40 images) are quoted as (max levels / PSNR / % of values more than one
// level off). The bbox3sigma bounds differ per family with how many opaque tails get cut;
// their largest differences carry 50% of margin (3 levels at least) and their fractions a
// floor of 1%, because cut tails add up and 30 further runs of the suite found 8 where 5
// had been measured.
FamilyBounds bounds_for(Family f) {
    switch (f) {
        case Family::tiny_scales:
            // A 1e-12..0 scale leaves the 0.3 blur: a one-pixel dot, as stable as any other.
            // float 1/84.5/0, split 1/84.5/0, bbox 12/63.5/0.093%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {24, 58.0, 0.01}, {24, 58.0, 0.01}};
        case Family::huge_scales:
            // Float: a Gaussian with one 1e3..1e6 axis projects to a line (a rank-one covariance
            // plus the blur). Along it q ~ 0, but the conic form a dx^2 + 2b dx dy + c dy^2
            // sums terms of size |conic| d^2 that cancel: at d ~ 10^3 px float leaves an error of
            // ~1e-7 |conic| d^2 ~ 0.05 in q, so alpha is off by a few % along the line and the
            // "power > 0" skip drops it where q rounds below 0. Double: 1e-16, invisible.
            // float 76/48.4/0.104%, split 73/49.1/0.035%, bbox double 7/68.1/0.069%. The float
            // largest difference is left unbounded (255): a pixel on such a line can lose the
            // whole Gaussian to the skip; PSNR and the fraction of values bound the damage.
            return {kDoubleLossless, {255, 42.0, 0.005}, {255, 42.0, 0.005}, {18, 60.0, 0.01}, {255, 42.0, 0.01}};
        case Family::quaternions:
            // Non-normalised quaternions scale the covariance by up to 30^4: screen-filling,
            // smooth footprints where many values sit near a half level (1-level moves, low
            // PSNR for one level); NaN/inf ones are culled. float 1/76.4/0, split 2/50.9/0.15%,
            // bbox 2/50.9/0.15%.
            return {kDoubleLossless, kFloatOneLevel, {3, 47.0, 0.003}, {6, 47.0, 0.01}, {6, 47.0, 0.01}};
        case Family::opacities:
            // 1.0 and 1 - 1 ulp hit the 0.99 cap; two such layers leave T = 1e-4 within
            // rounding of the stop. float 1/84.5/0, split 2/79.0/0.012%, bbox 14/62.7/0.16%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {27, 58.0, 0.01}, {27, 58.0, 0.01}};
        case Family::huge_sh:
            // Colours of 1e30 (clamped to kMaxShColour) turn any alpha difference into a
            // full-scale one: bbox3sigma's cut
            // tails saturate pixels the reference leaves alone. float 1/84.5/0, split 1/84.5/0,
            // bbox 231/28.9/0.29%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {255, 26.0, 0.01}, {255, 26.0, 0.01}};
        case Family::extreme_sh:
            // SH 1e38 / inf / NaN, colours clamped to [0, kMaxShColour] (NaN -> 0). A float sum
            // whose terms overflow to +inf and -inf gives NaN (black) where double gives +-1e38
            // and would differ full-scale; not seen in 350 seeds. float 1/84.5/0, split 1/87.5/0,
            // bbox 233/21.0/1.03%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {255, 18.0, 0.02}, {255, 18.0, 0.02}};
        case Family::near_plane:
            // 1e-5 relative from the plane is ~170 float ulps, and the family's path translates
            // sideways (depths unchanged): no side flips. float 1/84.5/0, split 1/87.5/0,
            // bbox 9/65.0/0.069%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {18, 60.0, 0.01}, {18, 60.0, 0.01}};
        case Family::image_border:
            // float 1/84.5/0, split 1/84.5/0, bbox 2/68.2/0.035%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {6, 64.0, 0.01}, {6, 64.0, 0.01}};
        case Family::far_away:
            // 10^7 m: the view transform is formed in double (make_view), depth 1e7 keeps 7
            // float digits; 1e21 px off-screen means are culled or skipped. float 1/82.7/0,
            // split 1/87.5/0, bbox 10/65.0/0.093%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {20, 61.0, 0.01}, {20, 61.0, 0.01}};
        case Family::utm:
            // Camera-relative in double: renders like a scene at the origin. float 1/84.5/0,
            // split 1/84.5/0, bbox 14/62.0/0.127% (0.80% once in 30 extra runs).
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {27, 55.0, 0.015}, {27, 55.0, 0.015}};
        case Family::camera_inside:
            // float 1/82.7/0, split 1/87.5/0, bbox 5/68.7/0.046%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {11, 65.0, 0.01}, {11, 65.0, 0.01}};
        case Family::degenerate:
            // Rank-one covariances plus the blur at ordinary sizes (lines a few px long).
            // float 1/74.5/0, split 1/78.5/0, bbox 5/68.1/0.081%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {11, 64.0, 0.01}, {11, 64.0, 0.01}};
        case Family::invalid:
            // Culled in every mode: the image is that of the valid Gaussians (NaN SH: black).
            // float 1/84.5/0, split 1/84.5/0, bbox 13/64.6/0.093%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {26, 60.0, 0.01}, {26, 60.0, 0.01}};
        case Family::ties:
            // Dense: 3000 overlapping Gaussians. float 1/82.7/0, split 1/70.6/0,
            // bbox 6/64.4/0.21%.
            return {kDoubleLossless, kFloatOneLevel, kSplitFewLevels, {12, 60.0, 0.01}, {12, 60.0, 0.01}};
        case Family::field_of_view:
            // The mixture at 5..150 degrees: at 5 degrees (f = 820 px) the lines of huge_scales
            // run 10^3 px from their means and dominate the float error (see huge_scales).
            // float 101/40.7/0.42%, split 101/45.5/0.38% (double split 2/53.1/0.012%),
            // bbox double 4/51.2/0.023%, float 101/40.7/0.42%; the float largest difference is
            // unbounded for the reason given under huge_scales.
            return {kDoubleLossless, {255, 33.0, 0.02}, {255, 33.0, 0.02}, {18, 48.0, 0.01}, {255, 33.0, 0.02}};
        case Family::mixture:
            // Every family at once, SH 1e30 excluded. Opacity-1.0 Gaussians make the split's
            // exclusive-stop difference (2 levels) common. Float adds the line gaps of
            // huge_scales, and depth ties: two overlapping Gaussians whose view depths differ by
            // less than float's rounding of the view transform (near-plane ones at 0.202 m on a
            // turning path) sort by index in float and by depth in double (10 levels once in
            // 90 extra seeds); and near-plane ones swept across the plane by a turning camera
            // (13 levels on 3.8% of a frame), which is why the mixture paths now translate
            // only. float 5/70.3/0.046% over 350 seeds; in 300 more runs of the property test
            // up to 56/40.7/1.1% and 44/42.7/1.5%, so the float largest difference is unbounded
            // and PSNR / fraction carry the bound. split 2/53.7/2.88% (double), bbox
            // 5/53.7/2.84%.
            return {kDoubleLossless, {255, 38.0, 0.03}, {255, 38.0, 0.045}, {15, 50.0, 0.045}, {255, 38.0, 0.045}};
        case Family::hdr_mixture:
            // The mixture with SH 1e30 (translating path, see stress_scenes.hpp). Besides
            // bbox3sigma's cut tails, the split's exclusive-stop difference is full-scale here:
            // the Gaussian the unsplit blend drops carries a colour of 1e30. A float flip at
            // a 1/255 contour would be full-scale too (not seen: float 1/82.7/0 over 100 seeds
            // on this path; 151 levels on 16% of one frame when the camera also turned and a
            // near-plane Gaussian crossed the plane). split 227/26.6/0.56%, bbox 227/28.9/0.43%.
            return {kDoubleLossless, {255, 40.0, 0.01}, {255, 24.0, 0.01}, {255, 26.0, 0.01}, {255, 26.0, 0.01}};
    }
    return {};
}

/// The class of bound a configuration is held to (FamilyBounds): split is one class for both
/// precisions, the others are two.
std::string class_label(const Config& cfg) {
    const stress::BoundClass k = stress::bound_class(cfg);
    if (k == stress::BoundClass::split) return stress::bound_class_name(k);
    return std::string(cfg.use_double ? "double " : "float ") + stress::bound_class_name(k);
}

Bound bound_for(Family f, const Config& cfg) {
    const FamilyBounds b = bounds_for(f);
    switch (stress::bound_class(cfg)) {
        case stress::BoundClass::bbox3sigma: return cfg.use_double ? b.double_bbox : b.float_bbox;
        case stress::BoundClass::split: return b.split;
        case stress::BoundClass::lossless: return cfg.use_double ? b.double_lossless : b.float_lossless;
    }
    return {};
}

/// Runs every configuration of one case against its family's bounds. Returns the worst
/// measurement per configuration class.
stress::Classes check_case(const StressCase& c, const std::string& note, bool small_image) {
    const std::vector<Frame> reference = reference_frames(c);
    std::size_t reference_nonfinite = 0;
    for (const Frame& f : reference) reference_nonfinite += count_nonfinite(f.image);
    EXPECT_EQ(reference_nonfinite, 0u) << c.name << ": the double reference wrote non-finite values " << note;
    stress::Classes classes;
    for (const Config& cfg : all_configs()) {
        const std::vector<Frame> frames = render_frames(c, cfg);
        const Measured m = measure(frames, reference);
        classes[class_label(cfg)].merge(m);
        const std::string what = c.name + ", " + cfg.name() + ": " + describe(m) + " " + note;
        stress::expect_within(m, bound_for(c.family, cfg), small_image, what);
        for (const Frame& f : frames) {
            EXPECT_EQ(f.image.width, c.path[0].intrinsics.width) << what;
            EXPECT_EQ(f.image.rgb.size(), 3u * static_cast<std::size_t>(c.path[0].intrinsics.width) *
                                              static_cast<std::size_t>(c.path[0].intrinsics.height))
                << what;
        }
    }
    return classes;
}

void run_family(StressCase (*make)(std::uint64_t), const std::string& what) {
    stress::run_family(kSuite, check_case, make, what);
}

// --- Families -------------------------------------------------------------------------

TEST(StressFamilies, TinyScales) { run_family(stress::tiny_scales, "tiny scales"); }
TEST(StressFamilies, HugeScales) { run_family(stress::huge_scales, "huge scales"); }
TEST(StressFamilies, ZeroNanAndNonNormalisedQuaternions) { run_family(stress::quaternions, "quaternions"); }
TEST(StressFamilies, ExtremeOpacities) { run_family(stress::opacities, "opacities"); }
TEST(StressFamilies, HugeShCoefficients) { run_family(stress::huge_sh, "huge sh"); }
TEST(StressFamilies, ShNearFloatMaxAndInfinite) { run_family(stress::extreme_sh, "extreme sh"); }
TEST(StressFamilies, NearPlaneCameraCentreAndBehind) { run_family(stress::near_plane, "near plane"); }
TEST(StressFamilies, MeansOnTheImageBorder) { run_family(stress::image_border, "image border"); }
TEST(StressFamilies, TenMillionMetresAway) { run_family(stress::far_away, "far away"); }
TEST(StressFamilies, UtmOriginAndCamera) { run_family(stress::utm, "utm"); }
TEST(StressFamilies, CameraInsideLargeGaussians) { run_family(stress::camera_inside, "camera inside"); }
TEST(StressFamilies, DegenerateCovariances) { run_family(stress::degenerate, "degenerate"); }
TEST(StressFamilies, InvalidValuesAreCulled) { run_family(stress::invalid, "invalid"); }
TEST(StressFamilies, EqualDepthTies) { run_family(stress::ties, "ties"); }

// --- Property tests over fresh seeds ----------------------------------------------------

TEST(StressProperty, RandomAdversarialMixtures) {
    stress::run_cases(kSuite, "mixtures", stress::mixture_cases, check_case);
}

TEST(StressProperty, FieldOfViewFiveToHundredFiftyDegrees) {
    stress::run_cases(kSuite, "field of view", stress::field_of_view_cases, check_case);
}

TEST(StressProperty, TinyAndOddResolutions) {
    stress::run_cases(kSuite, "resolutions", stress::resolution_cases, check_case);
}

// --- 8192 x 8192 ----------------------------------------------------------------------

/// The largest image of the issue, on the CPU: float, opacity-aware culling, a dozen
/// adversarial Gaussians that touch a few tiles each (the rasterizer still visits all 262144
/// tiles). The exact double reference is rendered on crops around each Gaussian (a crop is
/// the same camera with the principal point shifted: identical projection for Gaussians
/// whose mean is inside it); everything outside the crops must be exactly the background.
TEST(StressResolution, Huge8192x8192WithAFewGaussians) {
    const std::uint64_t seed = test::fresh_seed("stress 8192");
    stress::Draw d(seed);
    const int size = 8192;
    const Camera cam = test::forward_camera(size, size, d.uniform(20, 120));
    const Scene scene = stress::local_gaussians(seed, cam, 12);

    CpuRenderer<float> renderer;
    RenderOptions options = options_for(Culling::opacity_aware, Mode::plain);
    ImageF image;
    const auto start = std::chrono::steady_clock::now();
    const FrameStats stats = renderer.render(scene, cam, options, image);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    std::cout << "[stress] 8192x8192 float opacity-aware: " << ms << " ms, " << stats.visible << " visible, " << stats.pairs
              << " pairs" << std::endl;
    ASSERT_EQ(image.width, size);
    ASSERT_EQ(image.rgb.size(), 3u * size * size);
    EXPECT_EQ(count_nonfinite(image), 0u);
    EXPECT_LE(stats.pairs, 5000u) << "the scene is meant to touch few tiles";

    const std::vector<std::array<int, 4>> boxes = stress::footprint_boxes(scene, cam);
    ASSERT_GT(boxes.size(), 2u);
    std::vector<bool> covered(static_cast<std::size_t>(size) * size, false);
    int worst = 0;
    for (const auto& box : boxes) {
        const auto [x0, y0, x1, y1] = box;
        ASSERT_LE(static_cast<double>(x1 - x0) * (y1 - y0), 4e6) << "crop too large for the exact reference";
        CpuRenderer<double> reference;
        ImageF ref;
        reference.render(scene, stress::crop_camera(cam, box), options_for(Culling::exact, Mode::plain), ref);
        const auto level = [&](std::size_t i) { return static_cast<int>(quantize_8bit(image.rgb[i])); };
        worst = std::max(worst, stress::worst_in_crop(size, level, box, to_rgb8(ref), covered));
    }
    std::cout << "[stress] 8192x8192: " << boxes.size() << " crops, worst " << worst
              << " levels against the exact double reference" << std::endl;
    // Float against the double reference; opaque (1.0) Gaussians overlap here and there, so
    // the 1e-4 stop can flip between the precisions: kSplitFewLevels' 3 levels.
    EXPECT_LE(worst, kSplitFewLevels.max_levels);
    std::size_t stray = 0;
    for (std::size_t i = 0; i < covered.size(); ++i) {
        if (covered[i]) continue;
        for (int ch = 0; ch < 3; ++ch) stray += image.rgb[3 * i + ch] != kBackground[static_cast<std::size_t>(ch)];
    }
    EXPECT_EQ(stray, 0u) << "pixels outside every footprint must be exactly the background";
}

// --- Ties -----------------------------------------------------------------------------

// Thousands of Gaussians at exactly the same depth: the order is Gaussian index (stable sort
// on tile | depth keys emitted in index order), identical across runs, thread counts,
// precisions and configurations.
TEST(StressTies, EqualDepthsAreInIndexOrderAndDeterministic) {
    const std::uint64_t seed = test::fresh_seed("stress ties");
    const StressCase c = stress::ties(seed);
    for (const Config& cfg : all_configs()) {
        const std::vector<Frame> a = render_frames(c, cfg, 1), b = render_frames(c, cfg, 1), two = render_frames(c, cfg, 2);
        ASSERT_EQ(a.size(), two.size());
        for (std::size_t k = 0; k < a.size(); ++k) {
            EXPECT_EQ(a[k].image.rgb, b[k].image.rgb) << cfg.name() << " frame " << k << ": two runs differ " << seed_note(seed);
            EXPECT_EQ(a[k].image.rgb, two[k].image.rgb) << cfg.name() << " frame " << k << ": 1 vs 2 threads differ "
                                                        << seed_note(seed);
        }
    }
    // Within every tile, equal keys hold increasing Gaussian indices; float and double agree.
    auto check_order = [&](const auto& renderer, const char* what) {
        const auto& keys = renderer.sorted_keys();
        const auto& values = renderer.sorted_values();
        std::size_t ties = 0;
        for (std::size_t j = 1; j < keys.size(); ++j)
            if (keys[j] == keys[j - 1]) {
                ++ties;
                ASSERT_LT(values[j - 1], values[j]) << what << " slot " << j << " " << seed_note(seed);
            }
        EXPECT_GT(ties, 1000u) << what;
    };
    CpuRenderer<float> f(2);
    CpuRenderer<double> d(2);
    ImageF out;
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        f.render(c.scene, c.path[0], options_for(culling, Mode::plain), out);
        d.render(c.scene, c.path[0], options_for(culling, Mode::plain), out);
        check_order(f, culling_name(culling));
        check_order(d, culling_name(culling));
        // Exact culling lists every visible Gaussian once: the whole order must agree.
        if (culling == Culling::exact) {
            EXPECT_EQ(f.sorted_values(), d.sorted_values());
        }
    }
}

// --- What the renderer draws for degenerate input ----------------------------------------

template <typename T>
ImageF render_one(const Scene& scene, const Camera& camera, Culling culling = Culling::exact, FrameStats* stats = nullptr) {
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
        const Scene scene = one_gaussian({0, 0, static_cast<float>(z)}, scales, {1, 0, 0, 0}, static_cast<float>(sigma), dc);
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
        const Scene scene = one_gaussian({0, 0, static_cast<float>(z)}, {static_cast<float>(s), static_cast<float>(s), static_cast<float>(s)},
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
        const ImageF image = use_double ? render_one<double>(scene, cam, culling, &s) : render_one<float>(scene, cam, culling, &s);
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
        EXPECT_EQ(render_one<float>(scene, cam, culling).rgb, render_one<float>(empty, cam, culling).rgb) << culling_name(culling);
        EXPECT_EQ(render_one<double>(scene, cam, culling).rgb, render_one<double>(empty, cam, culling).rgb) << culling_name(culling);
    }
}

TEST(StressBugs, FarOffScreenMeanDrawsNothingInFloat) {
    // A finite position 1e20 m to the side at a depth of 3 m: the mean is 1e21 px off-screen,
    // dx^2 overflows float to inf, and the conic's cross term (b < 0 for this rotation, dx and
    // dy of one sign) makes power = -inf - (-inf) = NaN: exact culling then paints alpha 0.99
    // over the whole image.
    const Camera cam = test::forward_camera(48, 32, 60);
    const Scene scene = one_gaussian({1e20f, 1e20f, 3}, {0.3f, 0.1f, 0.05f}, {0.9f, 0.3f, -0.2f, 0.25f}, 0.8f, {2, -1, -1});
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
        ASSERT_TRUE(project_gaussian(ref, vf, pf)) << "float culls gaussian " << i << " that double projects " << seed_note(seed);
        // The conic (the inverse covariance) decides alpha; compare it through q at a few
        // offsets of a pixel or more, relative to the offset's length squared over the blur.
        for (auto [dx, dy] : {std::pair{1.0, 0.0}, std::pair{0.0, 1.0}, std::pair{3.0, -2.0}, std::pair{-5.0, 7.0}}) {
            const double qd = conic_form(pd.conic, dx, dy);
            const double qf = conic_form(cast<double>(pf.conic), dx, dy);
            EXPECT_NEAR(qf, qd, 1e-3 * (dx * dx + dy * dy) / kCovarianceBlur) << "gaussian " << i << " " << seed_note(seed);
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

// --- Measurement (run by hand to re-derive the bounds) ----------------------------------

// CATGS_STRESS_SEEDS=N build/tests/catgs_tests --gtest_also_run_disabled_tests
//   --gtest_filter='*MeasureBounds*' prints the worst error over N seeds (default 20) per
// family and configuration class, and per family and configuration: the numbers the
// bounds above were set from.
TEST(StressMeasure, DISABLED_MeasureBounds) {
    stress::measure_bounds(kSuite, [](const StressCase& c, stress::Classes& worst) {
        const std::vector<Frame> reference = reference_frames(c);
        for (const Config& cfg : all_configs()) {
            const std::string family = stress::family_name(c.family);
            Measured m = measure(render_frames(c, cfg), reference);
            for (const Frame& f : reference) m.nonfinite += count_nonfinite(f.image);
            worst[family + " " + class_label(cfg)].merge(m);
            worst[family + " / " + cfg.name()].merge(m);
        }
    });
}

}  // namespace
}  // namespace catgs
