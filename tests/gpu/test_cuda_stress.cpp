// Numerical stress suite, GPU part. The backend "cuda" of the shared suite (stress_suite.cpp
// runs the adversarial scenes of stress_scenes.hpp through it): cuda::CudaRenderer<float> in
// every culling mode, plain, with CaT-GS split (k = 8) and with the speculative cache over a
// 6-frame path, against the exact double CPU reference (CpuRenderer<double>, exact culling).
// Both outputs are checked: the float image must be finite, the 8-bit image must be the
// quantised float image, and the 8-bit image must be within the family's bound. Here too the
// GPU's own tests (8192 x 8192, determinism, single Gaussians, the cache envelope). Every test
// skips when no CUDA device is present.
//
// The CPU part (tests/test_stress.cpp) explains the families and the CPU bounds; the GPU
// bounds below add what differs on the device: nvcc contracts multiply-adds into FMAs and
// CUDA's exp differs from glibc's by an ulp, so a value near a threshold (alpha = 1/255,
// T = 1e-4, power = 0, a half level) can land on the other side.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>

#include "../stress_harness.hpp"
#include "../stress_scenes.hpp"
#include "../test_util.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

using test::stress::Bound;
using test::stress::cache_vs_full_levels;
using test::stress::Config;
using test::stress::count_nonfinite;
using test::stress::Family;
using test::stress::Frame;
using test::stress::kBackground;
using test::stress::Mode;
using test::stress::one_gaussian;
using test::stress::options_for;
using test::stress::seed_note;
using test::stress::StressCase;
namespace stress = test::stress;

class CudaStressTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

/// cuda::CudaRenderer<float> is float only.
std::vector<Config> all_configs() {
    return stress::all_configs(/*with_double=*/false);
}

std::string cuda_name(const Config& cfg) {
    return "cuda " + cfg.name();
}

/// Frame 0 (plain, split) or the whole path through one renderer (cache).
std::vector<Frame> gpu_frames(const StressCase& c, Culling culling, Mode mode) {
    cuda::CudaRenderer<float> renderer;
    renderer.set_scene(std::make_shared<cuda::DeviceScene>(c.scene, renderer.stream()));
    const RenderOptions options = options_for(culling, mode);
    const std::size_t frames = mode == Mode::cache ? c.path.size() : 1;
    std::vector<Frame> out;
    for (std::size_t k = 0; k < frames; ++k) {
        Frame f;
        f.stats = renderer.render(c.path[k], options, &f.rgb8, &f.image);
        out.push_back(std::move(f));
    }
    return out;
}

ImageRGB8 reference(const Scene& scene, const Camera& camera) {
    return stress::reference_frame(scene, camera).rgb8;
}

// --- Bounds -----------------------------------------------------------------------------
// Measured with StressProperty.DISABLED_MeasureBounds/cuda on an H200 (the device these runs
// got), on the renderer with the fixes of the CPU suite's StressBugs applied, over 140 seeds;
// quoted as (max levels / PSNR / % of values more than one level off); bbox3sigma maxima get
// 50% of margin, as on the CPU. Where float itself is the cause (the lines of huge_scales and field_of_view, depth ties
// in the mixtures, see test_stress.cpp) the bound is the CPU float bound, set from 350 seeds
// and 300 property-test runs: the largest difference unbounded, PSNR and fraction bounded.

/// One bound per stress::BoundClass (test_stress.cpp explains the split's exclusive-stop
/// difference and bbox3sigma's cut 3-sigma tails).
struct FamilyBounds {
    Bound lossless, split, bbox;
};

/// One level where a value lands on the other side of a threshold (nvcc's FMAs, CUDA's exp).
constexpr Bound kOneLevel{1, 72.0, 0.0};
/// Split with ordinary colours (the exclusive stop) at a few pixels.
constexpr Bound kSplitFewLevels{3, 67.0, 0.0005};

FamilyBounds bounds_for(Family f) {
    // Measured worst (lossless; split; bbox3sigma) on the H200 over 140 seeds, before the
    // harness held the split's exclusive-stop difference to its range (stress::Reference,
    // session 27): the split's and split bbox3sigma's differences can only be smaller now.
    // Not re-measured on a GPU since; the CPU's split now measures 1 level in every family.
    switch (f) {
        case Family::tiny_scales:  // 1/82.7/0; 1/82.7/0; 6/67.8/0.093%
            return {kOneLevel, kSplitFewLevels, {24, 58.0, 0.01}};
        case Family::huge_scales:  // 57/51.2/0.069%; 57/52.3/0.035%; 57/51.2/0.069% (CPU float: 76/48.4)
            return {{255, 42.0, 0.005}, {255, 42.0, 0.005}, {255, 42.0, 0.01}};
        case Family::quaternions:  // 1/82.7/0; 1/62.4/0; 4/62.4/0.069%
            return {kOneLevel, {2, 47.0, 0.0005}, {9, 47.0, 0.01}};
        case Family::opacities:  // 1/82.7/0; 1/84.5/0; 12/61.2/0.14%
            return {kOneLevel, kSplitFewLevels, {27, 58.0, 0.01}};
        case Family::huge_sh:  // 1/84.5/0; 1/87.5/0; 229/24.4/0.83%
            return {kOneLevel, kSplitFewLevels, {255, 21.0, 0.015}};
        case Family::extreme_sh:  // 1/84.5/0; 1/84.5/0; 229/27.9/0.35%
            return {kOneLevel, kSplitFewLevels, {255, 18.0, 0.02}};
        case Family::near_plane:  // 1/82.7/0; 1/84.5/0; 12/65.2/0.15%
            return {kOneLevel, kSplitFewLevels, {23, 60.0, 0.01}};
        case Family::image_border:  // 1/84.5/0; 1/81.5/0; 2/64.8/0.046%
            return {kOneLevel, kSplitFewLevels, {6, 61.0, 0.01}};
        case Family::far_away:  // 1/84.5/0; 1/87.5/0; 5/68.4/0.093%
            return {kOneLevel, kSplitFewLevels, {20, 61.0, 0.01}};
        case Family::utm:  // 1/84.5/0; 1/84.5/0; 10/59.4/1.0%
            return {kOneLevel, kSplitFewLevels, {27, 55.0, 0.015}};
        case Family::camera_inside:  // 1/82.7/0; 1/87.5/0; 4/73.0/0.035%
            return {kOneLevel, kSplitFewLevels, {11, 65.0, 0.01}};
        case Family::degenerate:  // 1/75.7/0; 1/80.5/0; 4/70.5/0.081%
            return {kOneLevel, kSplitFewLevels, {11, 64.0, 0.01}};
        case Family::invalid:  // 1/84.5/0; 1/87.5/0; 4/69.4/0.093%
            return {kOneLevel, kSplitFewLevels, {26, 60.0, 0.01}};
        case Family::ties:  // 1/84.5/0; 1/70.8/0; 6/65.0/0.14%
            return {kOneLevel, kSplitFewLevels, {12, 60.0, 0.01}};
        case Family::field_of_view:  // 78/45.7/0.79%; 76/45.7/0.24%; 78/45.7/0.79% (CPU float: 101/40.7)
            return {{255, 33.0, 0.02}, {255, 33.0, 0.02}, {255, 33.0, 0.02}};
        case Family::mixture:  // 28/50.3/0.47%; 1/55.5/0; 28/50.3/0.47% (line gaps, depth ties: test_stress.cpp)
            return {{255, 38.0, 0.03}, {255, 38.0, 0.045}, {255, 38.0, 0.045}};
        case Family::hdr_mixture:  // 1/81.5/0; 213/27.4/0.42%; 213/28.8/0.79%
            return {{255, 40.0, 0.01}, {255, 24.0, 0.01}, {255, 26.0, 0.015}};
    }
    return {};
}

Bound bound_for(Family f, const Config& cfg) {
    const FamilyBounds b = bounds_for(f);
    switch (stress::bound_class(cfg)) {
        case stress::BoundClass::bbox3sigma:
            return b.bbox;
        case stress::BoundClass::split:
            return b.split;
        case stress::BoundClass::lossless:
            return b.lossless;
    }
    return {};
}

std::string class_label(const Config& cfg) {
    return stress::bound_class_name(stress::bound_class(cfg));
}

/// The CUDA backend of the shared suite: float only, the 8-bit image written on the device.
class CudaStressBackend final : public stress::Backend {
public:
    std::string name() const override { return "cuda"; }
    /// Log lines "[cuda stress] ...", seeds "cuda stress ...".
    std::string suite() const override { return "cuda stress"; }
    std::string unavailable() const override {
        std::string reason;
        return cuda::device_available(&reason) ? std::string() : "no CUDA device: " + reason;
    }
    std::vector<Config> configs() const override { return all_configs(); }
    std::string config_name(const Config& cfg) const override { return cuda_name(cfg); }
    std::string class_label(const Config& cfg) const override { return catgs::class_label(cfg); }
    Bound bound_for(Family f, const Config& cfg) const override { return catgs::bound_for(f, cfg); }
    std::vector<Frame> render(const StressCase& c, const Config& cfg) const override {
        return gpu_frames(c, cfg.culling, cfg.mode);
    }
    bool writes_rgb8() const override { return true; }
};

}  // namespace

namespace test::stress {
const std::vector<const Backend*>& stress_backends() {
    static const CudaStressBackend cuda;
    static const std::vector<const Backend*> backends{&cuda};
    return backends;
}
}  // namespace test::stress

namespace {

// --- The GPU's own tests ----------------------------------------------------------------

// 8192 x 8192 in every culling mode and configuration, with 300 adversarial Gaussians of
// bounded footprint: the exact double reference on crops around them (the same camera with
// the principal point shifted), the background exactly elsewhere, the whole float image
// finite and quantised like the 8-bit one.
TEST_F(CudaStressTest, Huge8192x8192) {
    const std::uint64_t seed = test::fresh_seed("cuda stress 8192");
    stress::Draw d(seed);
    const int size = 8192;
    const Camera cam = test::forward_camera(size, size, d.uniform(20, 120));
    StressCase c{"8192", Family::mixture, stress::local_gaussians(seed, cam, 300), stress::short_path(cam)};
    std::vector<std::array<int, 4>> boxes = stress::footprint_boxes(c.scene, cam);
    std::vector<ImageRGB8> refs;
    for (const auto& box : boxes) refs.push_back(reference(c.scene, stress::crop_camera(cam, box)));
    for (const Config& cfg : all_configs()) {
        if (cfg.mode == Mode::cache) continue;  // one frame is enough at this size
        const auto start = std::chrono::steady_clock::now();
        const Frame f = std::move(gpu_frames(c, cfg.culling, cfg.mode).front());
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        ASSERT_EQ(f.image.rgb.size(), 3u * size * size);
        EXPECT_EQ(count_nonfinite(f.image), 0u) << cuda_name(cfg);
        EXPECT_EQ(to_rgb8(f.image).rgb, f.rgb8.rgb) << cuda_name(cfg);
        std::vector<bool> covered(static_cast<std::size_t>(size) * size, false);
        int worst = 0;
        const auto level = [&](std::size_t i) { return static_cast<int>(f.rgb8.rgb[i]); };
        for (std::size_t b = 0; b < boxes.size(); ++b)
            worst = std::max(worst, stress::worst_in_crop(size, level, boxes[b], refs[b], covered));
        std::size_t stray = 0;
        const ImageRGB8 bg{
            1, 1, {quantize_8bit(kBackground[0]), quantize_8bit(kBackground[1]), quantize_8bit(kBackground[2])}};
        for (std::size_t i = 0; i < covered.size(); ++i)
            if (!covered[i])
                for (int ch = 0; ch < 3; ++ch) stray += f.rgb8.rgb[3 * i + ch] != bg.rgb[static_cast<std::size_t>(ch)];
        std::cout << "[cuda stress] 8192x8192 " << cuda_name(cfg) << ": " << ms << " ms, " << f.stats.pairs
                  << " pairs, " << boxes.size() << " crops, worst " << worst << " levels, " << stray << " stray values"
                  << std::endl;
        // Float on the GPU against the double reference: one level at thresholds, and the 1e-4
        // stop flipping where opaque (1.0) Gaussians overlap; split and bbox3sigma add theirs.
        EXPECT_LE(worst, std::max(3, bound_for(Family::tiny_scales, cfg).max_levels))
            << cuda_name(cfg) << " " << seed_note(seed);
        EXPECT_EQ(stray, 0u) << cuda_name(cfg) << " " << seed_note(seed);
    }
}

// Equal depths: GPU renders are deterministic (CUB's radix sort is stable, keys are emitted
// in Gaussian order), run after run and renderer after renderer.
TEST_F(CudaStressTest, EqualDepthsAreDeterministic) {
    const std::uint64_t seed = test::fresh_seed("cuda stress ties");
    const StressCase c = stress::ties(seed);
    for (const Config& cfg : all_configs()) {
        const std::vector<Frame> a = gpu_frames(c, cfg.culling, cfg.mode), b = gpu_frames(c, cfg.culling, cfg.mode);
        for (std::size_t k = 0; k < a.size(); ++k)
            EXPECT_EQ(a[k].image.rgb, b[k].image.rgb) << cuda_name(cfg) << " frame " << k << " " << seed_note(seed);
    }
}

// --- Single Gaussians: what the GPU draws, against the CPU ------------------------------

Frame gpu_one(const Scene& scene, const Camera& cam, Culling culling) {
    StressCase c{"one", Family::invalid, scene, {cam}};
    return std::move(gpu_frames(c, culling, Mode::plain).front());
}

ImageRGB8 background_image(const Camera& cam) {
    ImageRGB8 out;
    out.width = cam.intrinsics.width;
    out.height = cam.intrinsics.height;
    for (int i = 0; i < out.width * out.height; ++i)
        for (float b : kBackground) out.rgb.push_back(quantize_8bit(b));
    return out;
}

// The near plane on the GPU: float, so z = 0.2f (not beyond 0.2f) is culled like on the CPU
// in float; the camera centre, behind and one ulp behind are culled; a few ulps in front drawn.
TEST_F(CudaStressTest, NearPlaneCentreBehindAndOnThePlane) {
    const Camera cam = test::forward_camera(40, 30, 60);
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        auto visible = [&](float z) {
            const Frame f =
                gpu_one(one_gaussian({0, 0, z}, {0.01f, 0.01f, 0.01f}, {1, 0, 0, 0}, 0.9f, {1, 1, 1}), cam, culling);
            EXPECT_EQ(count_nonfinite(f.image), 0u);
            return f.stats.visible;
        };
        EXPECT_EQ(visible(0.0f), 0u) << culling_name(culling);
        EXPECT_EQ(visible(-1.0f), 0u) << culling_name(culling);
        EXPECT_EQ(visible(std::nextafter(0.2f, 0.0f)), 0u) << culling_name(culling);
        EXPECT_EQ(visible(0.2f), 0u) << culling_name(culling);
        EXPECT_EQ(visible(0.2f * (1 + 1e-6f)), 1u) << culling_name(culling);
    }
}

// The inputs of the CPU suite's StressBugs, on the GPU (the fixes there are in the shared
// stage headers, so they fix both backends).
TEST_F(CudaStressTest, NanOpacityAndFarOffScreenMeansDrawNothing) {
    const Camera cam = test::forward_camera(48, 32, 60);
    const ImageRGB8 empty = background_image(cam);
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        const Scene nan = one_gaussian({0, 0, 3}, {0.1f, 0.1f, 0.1f}, {1, 0, 0, 0}, stress::kNaN, {2, -1, -1});
        EXPECT_EQ(gpu_one(nan, cam, culling).rgb8.rgb, empty.rgb) << "NaN opacity, " << culling_name(culling);
        const Scene far =
            one_gaussian({1e20f, 1e20f, 3}, {0.3f, 0.1f, 0.05f}, {0.9f, 0.3f, -0.2f, 0.25f}, 0.8f, {2, -1, -1});
        EXPECT_EQ(gpu_one(far, cam, culling).rgb8.rgb, empty.rgb)
            << "mean 1e21 px off-screen, " << culling_name(culling);
    }
}

// Two opaque Gaussians on one pixel centre, both at the alpha cap: T = (1 - 0.99)^2 ties the
// 1e-4 stop in real arithmetic. With the cap at float's 0.99 (kMaxAlpha) the GPU, the CPU in
// float and the double reference all stop before the far layer (test_cpu_renderer.cpp's
// TwoCappedLayersStopBeforeTheSecond); drawing it would put 2 levels of its green there.
TEST_F(CudaStressTest, TwoCappedLayersStopBeforeTheSecond) {
    Camera cam = test::forward_camera(32, 32, 40);
    cam.intrinsics.cx = 15.5;  // both centres project onto pixel (15, 15)'s centre
    cam.intrinsics.cy = 15.5;
    Scene scene = stress::empty_scene(0);
    stress::Gaussian far, near;
    far.position = {0, 0, 9};
    far.scale = {0.5f, 0.5f, 0.5f};
    far.opacity = 1.0f;
    far.dc = {-2.0f, 1.5f, -2.0f};  // green
    near.position = {0, 0, 4};
    near.scale = {0.2f, 0.2f, 0.2f};
    near.opacity = 1.0f;
    near.dc = {1.5f, -2.0f, -2.0f};  // red
    stress::add(scene, far);
    stress::add(scene, near);
    scene.update_bounds();
    const ImageRGB8 ref = reference(scene, cam);
    const std::size_t pixel = 3 * (15 * 32 + 15);
    // Green: the background through the near layer's 1 - 0.99 (1 level); the far layer would make it 2.
    EXPECT_EQ(ref.rgb[pixel + 1], quantize_8bit((1 - 0.99f) * kBackground[1])) << "the reference drew the far layer";
    for (Culling culling : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware}) {
        const Frame f = gpu_one(scene, cam, culling);
        for (int c = 0; c < 3; ++c)
            EXPECT_EQ(f.rgb8.rgb[pixel + c], ref.rgb[pixel + c]) << culling_name(culling) << ", channel " << c;
    }
}

TEST_F(CudaStressTest, ExtremeShColoursKeepTheFloatImageFinite) {
    const Camera cam = test::forward_camera(48, 32, 60);
    for (float v : {1e38f, 3.4e38f, stress::kInf})
        for (Culling culling : {Culling::exact, Culling::opacity_aware}) {
            const Frame f =
                gpu_one(one_gaussian({0, 0, 3}, {0.5f, 0.5f, 0.5f}, {1, 0, 0, 0}, 0.7f, {0, 0, 0}, 3, v), cam, culling);
            EXPECT_EQ(count_nonfinite(f.image), 0u) << "SH " << v << ", " << culling_name(culling);
            EXPECT_EQ(to_rgb8(f.image).rgb, f.rgb8.rgb) << "SH " << v << ", " << culling_name(culling);
        }
}

TEST_F(CudaStressTest, ScreenFillingGaussianWhoseDeterminantOverflowsFloat) {
    const Camera cam = test::forward_camera(8192, 4, 5.0);
    const Scene scene = one_gaussian({0, 0, 0.21f}, {1e6f, 1e6f, 1e6f}, {1, 0, 0, 0}, 0.6f, {1, 0, -1});
    const Frame f = gpu_one(scene, cam, Culling::opacity_aware);
    EXPECT_EQ(f.stats.visible, 1u) << "the GPU culls the Gaussian the camera is inside";
    EXPECT_LE(compare(f.rgb8, reference(scene, cam)).max_abs, 1);
}

// Needles and discs seen end-on under a slowly moving camera: every cached frame must match
// the GPU's own full per-frame render (the envelope bug of the CPU suite's StressBugs).
TEST_F(CudaStressTest, CacheEnvelopeHoldsForNeedlesAndDiscsSeenEndOn) {
    const StressCase c = stress::needles_and_discs_end_on(test::fresh_seed("cuda stress cache needles"));
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma}) {
        cuda::CudaRenderer<float> cached, full;
        auto shared = std::make_shared<cuda::DeviceScene>(c.scene);
        cached.set_scene(shared);
        full.set_scene(shared);
        int worst = 0, cached_frames = 0;
        for (const Camera& cam : c.path) {
            ImageRGB8 a, b;
            const FrameStats s = cached.render(cam, options_for(culling, Mode::cache), &a, nullptr);
            full.render(cam, options_for(culling, Mode::plain), &b, nullptr);
            cached_frames += !s.key_frame;
            worst = std::max(worst, compare(a, b).max_abs);
        }
        std::cout << "[cuda stress] cache with needles, " << culling_name(culling) << ": " << cached_frames
                  << " cached, worst " << worst << " levels" << std::endl;
        EXPECT_LE(worst, cache_vs_full_levels(culling)) << culling_name(culling);
    }
}

// A Gaussian near the camera just outside the image enters it within the envelope (the CPU
// suite's StressBugs.CacheEnvelopeHoldsForANearGaussianJustOutsideTheImage): cached frames
// must match the GPU's own per-frame render.
TEST_F(CudaStressTest, CacheEnvelopeHoldsForANearGaussianJustOutsideTheImage) {
    const StressCase c = stress::near_gaussian_outside_the_image(test::fresh_seed("cuda stress cache near gaussian"));
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma, Culling::exact}) {
        cuda::CudaRenderer<float> cached, full;
        auto shared = std::make_shared<cuda::DeviceScene>(c.scene);
        cached.set_scene(shared);
        full.set_scene(shared);
        int worst = 0, cached_frames = 0;
        for (const Camera& cam : c.path) {
            ImageRGB8 a, b;
            cached_frames += !cached.render(cam, options_for(culling, Mode::cache), &a, nullptr).key_frame;
            full.render(cam, options_for(culling, Mode::plain), &b, nullptr);
            worst = std::max(worst, compare(a, b).max_abs);
        }
        std::cout << "[cuda stress] cache with a near Gaussian outside the image, " << culling_name(culling) << ": "
                  << cached_frames << " cached, worst " << worst << " levels" << std::endl;
        EXPECT_LE(worst, cache_vs_full_levels(culling)) << culling_name(culling);
    }
}

}  // namespace
}  // namespace catgs
