// Numerical stress suite, GPU part: the adversarial scenes of tests/stress_scenes.hpp through
// cuda::CudaRenderer<float> in every culling mode, plain, with CaT-GS split (k = 8) and with
// the speculative cache over a 6-frame path, against the exact double CPU reference
// (CpuRenderer<double>, exact culling). Both outputs are checked: the float image must be
// finite, the 8-bit image must be the quantised float image, and the 8-bit image must be
// within the family's bound. Every test skips when no CUDA device is present.
//
// The CPU part (tests/test_stress.cpp) explains the families and the CPU bounds; the GPU
// bounds below add what differs on the device: nvcc contracts multiply-adds into FMAs and
// CUDA's exp differs from glibc's by an ulp, so a value near a threshold (alpha = 1/255,
// T = 1e-4, power = 0, a half level) can land on the other side.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>

#include "../stress_scenes.hpp"
#include "../test_util.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

using test::stress::Family;
using test::stress::StressCase;
namespace stress = test::stress;

class CudaStressTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

enum class Mode { plain, split, cache };

struct Config {
    Culling culling;
    Mode mode;
    std::string name() const {
        std::string n = std::string("cuda float ") + culling_name(culling);
        if (mode == Mode::split) n += " split8";
        if (mode == Mode::cache) n += " cache";
        return n;
    }
};

std::vector<Config> all_configs() {
    std::vector<Config> out;
    for (Culling c : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware})
        for (Mode m : {Mode::plain, Mode::split, Mode::cache}) out.push_back({c, m});
    return out;
}

constexpr std::uint32_t kSplitK = 8;
constexpr std::array<float, 3> kBackground{0.1f, 0.25f, 0.4f};

RenderOptions options_for(Culling culling, Mode mode) {
    RenderOptions o;
    o.culling = culling;
    o.background = kBackground;
    if (mode == Mode::split) o.catgs.split_k = kSplitK;
    if (mode == Mode::cache) o.catgs.cache = CacheMode::speculative;
    return o;
}

std::size_t count_nonfinite(const ImageF& image) {
    return static_cast<std::size_t>(
        std::count_if(image.rgb.begin(), image.rgb.end(), [](float v) { return !std::isfinite(v); }));
}

struct Frame {
    ImageF image;
    ImageRGB8 rgb8;
    FrameStats stats;
};

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
    CpuRenderer<double> r;
    RenderOptions o = options_for(Culling::exact, Mode::plain);
    ImageF out;
    r.render(scene, camera, o, out);
    return to_rgb8(out);
}

struct Measured {
    int max_abs = 0;
    double min_psnr = std::numeric_limits<double>::infinity();
    double max_over_one = 0;
    std::size_t nonfinite = 0, rgb8_mismatch = 0;
    int frames = 0, cached = 0;
    void merge(const Measured& o) {
        max_abs = std::max(max_abs, o.max_abs);
        min_psnr = std::min(min_psnr, o.min_psnr);
        max_over_one = std::max(max_over_one, o.max_over_one);
        nonfinite += o.nonfinite;
        rgb8_mismatch += o.rgb8_mismatch;
        frames += o.frames;
        cached += o.cached;
    }
};

std::string describe(const Measured& m) {
    std::ostringstream s;
    s << "max " << m.max_abs << " levels, psnr " << std::fixed << std::setprecision(1) << m.min_psnr << " dB, "
      << std::setprecision(4) << 100 * m.max_over_one << "% > 1 level, " << m.nonfinite << " non-finite, "
      << m.rgb8_mismatch << " rgb8 != quantised float, " << m.cached << "/" << m.frames << " cached";
    return s.str();
}

Measured measure(const std::vector<Frame>& frames, const std::vector<ImageRGB8>& refs) {
    Measured m;
    for (std::size_t k = 0; k < frames.size(); ++k) {
        const ImageError e = compare(frames[k].rgb8, refs[k]);
        m.max_abs = std::max(m.max_abs, e.max_abs);
        m.min_psnr = std::min(m.min_psnr, e.psnr);
        m.max_over_one = std::max(m.max_over_one, e.fraction_over_one);
        m.nonfinite += count_nonfinite(frames[k].image);
        const ImageRGB8 q = to_rgb8(frames[k].image);
        for (std::size_t i = 0; i < q.rgb.size() && i < frames[k].rgb8.rgb.size(); ++i)
            m.rgb8_mismatch += q.rgb[i] != frames[k].rgb8.rgb[i];
        m.rgb8_mismatch += q.rgb.size() != frames[k].rgb8.rgb.size();
        ++m.frames;
        m.cached += !frames[k].stats.key_frame;
    }
    return m;
}

// --- Bounds -----------------------------------------------------------------------------
// Measured with MeasureBounds below on an H200 (the device these runs got), on the renderer
// with the fixes of the CPU suite's StressBugs applied, over 140 seeds; quoted as (max levels /
// PSNR / % of values more than one level off); bbox3sigma maxima get 50% of margin, as on the
// CPU. Where float itself is the cause (the lines of huge_scales and field_of_view, depth ties
// in the mixtures, see test_stress.cpp) the bound is the CPU float bound, set from 350 seeds
// and 300 property-test runs: the largest difference unbounded, PSNR and fraction bounded.

struct Bound {
    int max_levels;
    double min_psnr;
    double max_over_one;
};

/// lossless: exact or opacity-aware, plain or cache; split: k = 8 (adds the exclusive-stop
/// difference explained in test_stress.cpp); bbox3sigma: any mode (cut 3-sigma tails).
struct FamilyBounds {
    Bound lossless, split, bbox;
};

/// One level where a value lands on the other side of a threshold (nvcc's FMAs, CUDA's exp).
constexpr Bound kOneLevel{1, 72.0, 0.0};
/// Split with ordinary colours (the exclusive stop) at a few pixels.
constexpr Bound kSplitFewLevels{3, 67.0, 0.0005};

FamilyBounds bounds_for(Family f) {
    // Measured worst (lossless; split; bbox3sigma) on the H200 over 140 seeds.
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
    if (cfg.culling == Culling::bbox3sigma) return b.bbox;
    return cfg.mode == Mode::split ? b.split : b.lossless;
}

std::string bound_class(const Config& cfg) {
    if (cfg.culling == Culling::bbox3sigma) return "bbox3sigma";
    return cfg.mode == Mode::split ? "split" : "lossless";
}

std::string seed_note(std::uint64_t seed) { return "(CATGS_TEST_SEED=" + std::to_string(seed) + ")"; }

/// `small_image`: a handful of pixels, where PSNR and the fraction say little: only the
/// largest difference is checked.
std::map<std::string, Measured> check_case(const StressCase& c, const std::string& note, bool small_image = false) {
    std::vector<ImageRGB8> refs;
    for (const Camera& cam : c.path) refs.push_back(reference(c.scene, cam));
    std::map<std::string, Measured> classes;
    for (const Config& cfg : all_configs()) {
        const Measured m = measure(gpu_frames(c, cfg.culling, cfg.mode), refs);
        classes[bound_class(cfg)].merge(m);
        const Bound b = bound_for(c.family, cfg);
        const std::string what = c.name + ", " + cfg.name() + ": " + describe(m) + " " + note;
        EXPECT_EQ(m.nonfinite, 0u) << what;
        EXPECT_EQ(m.rgb8_mismatch, 0u) << what;
        EXPECT_LE(m.max_abs, b.max_levels) << what;
        if (!small_image) {
            EXPECT_GE(m.min_psnr, b.min_psnr) << what;
            EXPECT_LE(m.max_over_one, b.max_over_one) << what;
        }
    }
    return classes;
}

void report(const std::string& what, const std::map<std::string, Measured>& classes) {
    for (const auto& [name, m] : classes) std::cout << "[cuda stress] " << what << ", " << name << ": " << describe(m) << std::endl;
}

void run_family(StressCase (*make)(std::uint64_t), const std::string& what) {
    const std::uint64_t seed = test::fresh_seed("cuda stress " + what);
    const StressCase c = make(seed);
    report(c.name, check_case(c, seed_note(seed)));
}

// --- Families -------------------------------------------------------------------------

TEST_F(CudaStressTest, TinyScales) { run_family(stress::tiny_scales, "tiny scales"); }
TEST_F(CudaStressTest, HugeScales) { run_family(stress::huge_scales, "huge scales"); }
TEST_F(CudaStressTest, ZeroNanAndNonNormalisedQuaternions) { run_family(stress::quaternions, "quaternions"); }
TEST_F(CudaStressTest, ExtremeOpacities) { run_family(stress::opacities, "opacities"); }
TEST_F(CudaStressTest, HugeShCoefficients) { run_family(stress::huge_sh, "huge sh"); }
TEST_F(CudaStressTest, ShNearFloatMaxAndInfinite) { run_family(stress::extreme_sh, "extreme sh"); }
TEST_F(CudaStressTest, NearPlaneCameraCentreAndBehind) { run_family(stress::near_plane, "near plane"); }
TEST_F(CudaStressTest, MeansOnTheImageBorder) { run_family(stress::image_border, "image border"); }
TEST_F(CudaStressTest, TenMillionMetresAway) { run_family(stress::far_away, "far away"); }
TEST_F(CudaStressTest, UtmOriginAndCamera) { run_family(stress::utm, "utm"); }
TEST_F(CudaStressTest, CameraInsideLargeGaussians) { run_family(stress::camera_inside, "camera inside"); }
TEST_F(CudaStressTest, DegenerateCovariances) { run_family(stress::degenerate, "degenerate"); }
TEST_F(CudaStressTest, InvalidValuesAreCulled) { run_family(stress::invalid, "invalid"); }
TEST_F(CudaStressTest, EqualDepthTies) { run_family(stress::ties, "ties"); }

TEST_F(CudaStressTest, RandomAdversarialMixtures) {
    const std::uint64_t seed = test::fresh_seed("cuda stress mixtures");
    std::map<std::string, Measured> worst, worst_hdr;
    for (int k = 0; k < 9; ++k) {
        const bool hdr = k % 3 == 2;
        const StressCase c = stress::mixture(seed + 1000003ull * static_cast<std::uint64_t>(k), 150, hdr);
        for (const auto& [name, m] : check_case(c, seed_note(seed) + " mixture " + std::to_string(k)))
            (hdr ? worst_hdr : worst)[name].merge(m);
    }
    report("mixtures", worst);
    report("hdr mixtures", worst_hdr);
}

TEST_F(CudaStressTest, FieldOfViewFiveToHundredFiftyDegrees) {
    const std::uint64_t seed = test::fresh_seed("cuda stress field of view");
    std::map<std::string, Measured> worst;
    for (double fov : {5.0, 10.0, 30.0, 60.0, 90.0, 120.0, 150.0}) {
        const StressCase c = stress::field_of_view(seed + static_cast<std::uint64_t>(fov), fov);
        for (const auto& [name, m] : check_case(c, seed_note(seed) + " fov " + std::to_string(fov))) worst[name].merge(m);
    }
    report("fov 5..150", worst);
}

TEST_F(CudaStressTest, TinyAndOddResolutions) {
    const std::uint64_t seed = test::fresh_seed("cuda stress resolutions");
    std::map<std::string, Measured> worst;
    for (auto [w, h] : {std::pair{1, 1}, std::pair{1, 2}, std::pair{2, 1}, std::pair{1, 37}, std::pair{45, 1},
                        std::pair{15, 17}, std::pair{16, 16}, std::pair{17, 17}, std::pair{255, 3}, std::pair{3, 129}}) {
        StressCase c = stress::mixture(seed + static_cast<std::uint64_t>(w * 1000 + h), 120);
        c.path = stress::short_path(test::forward_camera(w, h, 60), 0.002, 0.0);  // see stress::mixture
        // Square pixels and a 60 degree horizontal field: 3 x 129 sees 175 degrees vertically,
        // so the field-of-view bounds apply; on slivers PSNR and fractions say little.
        c.family = Family::field_of_view;
        for (const auto& [name, m] : check_case(c, seed_note(seed) + " " + std::to_string(w) + "x" + std::to_string(h),
                                                w * h < 256 || std::min(w, h) < 8))
            worst[name].merge(m);
    }
    report("resolutions 1x1..255x3", worst);
}

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
        EXPECT_EQ(count_nonfinite(f.image), 0u) << cfg.name();
        EXPECT_EQ(to_rgb8(f.image).rgb, f.rgb8.rgb) << cfg.name();
        std::vector<bool> covered(static_cast<std::size_t>(size) * size, false);
        int worst = 0;
        for (std::size_t b = 0; b < boxes.size(); ++b) {
            const auto [x0, y0, x1, y1] = boxes[b];
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    covered[static_cast<std::size_t>(y) * size + x] = true;
                    for (int ch = 0; ch < 3; ++ch) {
                        const int a = f.rgb8.rgb[3 * (static_cast<std::size_t>(y) * size + x) + ch];
                        const int r = refs[b].rgb[3 * (static_cast<std::size_t>(y - y0) * (x1 - x0) + (x - x0)) + ch];
                        worst = std::max(worst, std::abs(a - r));
                    }
                }
        }
        std::size_t stray = 0;
        const ImageRGB8 bg{1, 1, {quantize_8bit(kBackground[0]), quantize_8bit(kBackground[1]), quantize_8bit(kBackground[2])}};
        for (std::size_t i = 0; i < covered.size(); ++i)
            if (!covered[i])
                for (int ch = 0; ch < 3; ++ch) stray += f.rgb8.rgb[3 * i + ch] != bg.rgb[static_cast<std::size_t>(ch)];
        std::cout << "[cuda stress] 8192x8192 " << cfg.name() << ": " << ms << " ms, " << f.stats.pairs << " pairs, "
                  << boxes.size() << " crops, worst " << worst << " levels, " << stray << " stray values" << std::endl;
        // Float on the GPU against the double reference: one level at thresholds, and the 1e-4
        // stop flipping where opaque (1.0) Gaussians overlap; split and bbox3sigma add theirs.
        EXPECT_LE(worst, std::max(3, bound_for(Family::tiny_scales, cfg).max_levels)) << cfg.name() << " " << seed_note(seed);
        EXPECT_EQ(stray, 0u) << cfg.name() << " " << seed_note(seed);
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
            EXPECT_EQ(a[k].image.rgb, b[k].image.rgb) << cfg.name() << " frame " << k << " " << seed_note(seed);
    }
}

// --- Single Gaussians: what the GPU draws, against the CPU ------------------------------

Scene one_gaussian(std::array<float, 3> p, std::array<float, 3> s, std::array<float, 4> q, float opacity,
                   std::array<float, 3> dc, int sh_degree = 0, float sh_value = 0) {
    stress::Gaussian g;
    g.position = p;
    g.scale = s;
    g.rotation = q;
    g.opacity = opacity;
    g.dc = dc;
    Scene scene = stress::empty_scene(sh_degree);
    if (sh_degree > 0) g.sh.assign(scene.sh_floats_per_gaussian(), sh_value);
    stress::add(scene, g);
    scene.update_bounds();
    return scene;
}

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
            const Frame f = gpu_one(one_gaussian({0, 0, z}, {0.01f, 0.01f, 0.01f}, {1, 0, 0, 0}, 0.9f, {1, 1, 1}), cam, culling);
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
        const Scene far = one_gaussian({1e20f, 1e20f, 3}, {0.3f, 0.1f, 0.05f}, {0.9f, 0.3f, -0.2f, 0.25f}, 0.8f, {2, -1, -1});
        EXPECT_EQ(gpu_one(far, cam, culling).rgb8.rgb, empty.rgb) << "mean 1e21 px off-screen, " << culling_name(culling);
    }
}

TEST_F(CudaStressTest, ExtremeShColoursKeepTheFloatImageFinite) {
    const Camera cam = test::forward_camera(48, 32, 60);
    for (float v : {1e38f, 3.4e38f, stress::kInf})
        for (Culling culling : {Culling::exact, Culling::opacity_aware}) {
            const Frame f = gpu_one(one_gaussian({0, 0, 3}, {0.5f, 0.5f, 0.5f}, {1, 0, 0, 0}, 0.7f, {0, 0, 0}, 3, v), cam, culling);
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
    const Camera cam = test::forward_camera(160, 96, 60);
    Scene scene = stress::empty_scene(0);
    stress::Draw d(test::fresh_seed("cuda stress cache needles"));
    for (int i = 0; i < 30; ++i) stress::add(scene, d.ordinary(3, 12));
    for (int i = 0; i < 12; ++i) {
        stress::Gaussian g = d.ordinary();
        const float z = 2.0f + 0.1f * static_cast<float>(i);
        g.position = {(-0.6f + 0.4f * static_cast<float>(i % 4)) * z, (-0.3f + 0.3f * static_cast<float>(i / 4)) * z, z};
        const double n = std::sqrt(g.position[0] * g.position[0] + g.position[1] * g.position[1] + g.position[2] * g.position[2]);
        const std::array<double, 3> ray{g.position[0] / n, g.position[1] / n, g.position[2] / n};
        if (i % 2 == 0) {
            g.scale = {30.0f, 1e-3f, 1e-3f};
            g.rotation = stress::quaternion_x_to(ray);
        } else {
            const std::array<double, 3> normal{ray[1], -ray[0], 0};
            const double m = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1]);
            g.scale = {1e-4f, 8.0f, 8.0f};
            g.rotation = stress::quaternion_x_to({normal[0] / m, normal[1] / m, 0});
        }
        g.opacity = 0.9f;
        stress::add(scene, g);
    }
    scene.update_bounds();
    const std::vector<Camera> path = stress::short_path(cam, 0.005, 0.0, 8);
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma}) {
        cuda::CudaRenderer<float> cached, full;
        auto shared = std::make_shared<cuda::DeviceScene>(scene);
        cached.set_scene(shared);
        full.set_scene(shared);
        int worst = 0, cached_frames = 0;
        for (const Camera& c : path) {
            ImageRGB8 a, b;
            const FrameStats s = cached.render(c, options_for(culling, Mode::cache), &a, nullptr);
            full.render(c, options_for(culling, Mode::plain), &b, nullptr);
            cached_frames += !s.key_frame;
            worst = std::max(worst, compare(a, b).max_abs);
        }
        std::cout << "[cuda stress] cache with needles, " << culling_name(culling) << ": " << cached_frames
                  << " cached, worst " << worst << " levels" << std::endl;
        // bbox3sigma: a cached frame's lists hold the guard-grown squares, more of the cut tails.
        EXPECT_LE(worst, culling == Culling::bbox3sigma ? 10 : 1) << culling_name(culling);
    }
}

// A Gaussian near the camera just outside the image enters it within the envelope (the CPU
// suite's StressBugs.CacheEnvelopeHoldsForANearGaussianJustOutsideTheImage): cached frames
// must match the GPU's own per-frame render.
TEST_F(CudaStressTest, CacheEnvelopeHoldsForANearGaussianJustOutsideTheImage) {
    const Camera cam = test::forward_camera(72, 40, 60);
    Scene scene = stress::empty_scene(0);
    stress::Draw d(test::fresh_seed("cuda stress cache near gaussian"));
    for (int i = 0; i < 40; ++i) stress::add(scene, d.ordinary(8, 12));
    stress::Gaussian near;
    const double z = 0.3, u = cam.intrinsics.width + 6.0, v = d.uniform(5, 35);
    near.position = {static_cast<float>((u - cam.intrinsics.cx) / cam.intrinsics.fx * z),
                     static_cast<float>((v - cam.intrinsics.cy) / cam.intrinsics.fy * z), static_cast<float>(z)};
    near.scale = {0.002f, 0.002f, 0.002f};
    near.opacity = 0.95f;
    near.dc = {2, 2, -1};
    stress::add(scene, near);
    scene.update_bounds();
    const std::vector<Camera> path = stress::short_path(cam, 0.05, 0.0, 4);
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma, Culling::exact}) {
        cuda::CudaRenderer<float> cached, full;
        auto shared = std::make_shared<cuda::DeviceScene>(scene);
        cached.set_scene(shared);
        full.set_scene(shared);
        int worst = 0, cached_frames = 0;
        for (const Camera& c : path) {
            ImageRGB8 a, b;
            cached_frames += !cached.render(c, options_for(culling, Mode::cache), &a, nullptr).key_frame;
            full.render(c, options_for(culling, Mode::plain), &b, nullptr);
            worst = std::max(worst, compare(a, b).max_abs);
        }
        std::cout << "[cuda stress] cache with a near Gaussian outside the image, " << culling_name(culling) << ": "
                  << cached_frames << " cached, worst " << worst << " levels" << std::endl;
        EXPECT_LE(worst, culling == Culling::bbox3sigma ? 10 : 1) << culling_name(culling);
    }
}

// --- Measurement (run by hand on a GPU host to re-derive the bounds) ----------------------

TEST_F(CudaStressTest, DISABLED_MeasureBounds) {
    const char* env = std::getenv("CATGS_STRESS_SEEDS");
    const int seeds = env ? std::atoi(env) : 20;
    const std::uint64_t base = test::fresh_seed("cuda stress measure");
    std::map<std::string, Measured> worst;
    for (int s = 0; s < seeds; ++s) {
        const std::uint64_t seed = base + static_cast<std::uint64_t>(s) * 7919;
        std::vector<StressCase> cases = stress::all_families(seed);
        for (double fov : {5.0, 20.0, 90.0, 150.0}) cases.push_back(stress::field_of_view(seed + static_cast<std::uint64_t>(fov), fov));
        for (const StressCase& c : cases) {
            std::vector<ImageRGB8> refs;
            for (const Camera& cam : c.path) refs.push_back(reference(c.scene, cam));
            for (const Config& cfg : all_configs()) {
                const Measured m = measure(gpu_frames(c, cfg.culling, cfg.mode), refs);
                worst[std::string(stress::family_name(c.family)) + " " + bound_class(cfg)].merge(m);
                worst[std::string(stress::family_name(c.family)) + " / " + cfg.name()].merge(m);
            }
        }
    }
    for (const auto& [name, m] : worst) std::cout << "[measure] " << name << ": " << describe(m) << std::endl;
}

}  // namespace
}  // namespace catgs
