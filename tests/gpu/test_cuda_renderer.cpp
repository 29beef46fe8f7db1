// The CUDA backend against the CPU reference. Every test skips when no CUDA device is
// present (CI has none); on an H100/H200 they run with the `gpu` ctest label.
#include <gtest/gtest.h>

#include <filesystem>
#include <thread>

#include "../test_util.hpp"
#include "same_renders.hpp"
#include "catgs/builtin_city.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/stage.hpp"
#include "catgs/trajectory.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

// Acceptance bar of the CUDA backend against the CPU reference (issue: PSNR >= 50 dB and at
// most 2 levels): both evaluate the same float formulas, but nvcc contracts multiply-adds
// into FMAs and the CUDA exp differs from glibc's by an ulp, so a pixel near a threshold
// (alpha = 1/255, T = 1e-4) can flip.
constexpr double kMinPsnr = 50.0;
constexpr int kMaxLevels = 2;

class CudaRendererTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

// The layout rule needs no device: the kit's paths as measured (longest list, pairs, the
// H200's resident two-pixel tasks) land on the side that rasterized them faster, and the
// boundary sits at kCriticalListShare.
TEST(RasterLayoutChoice, FollowsTheLongestListsShareOfAResidentTask) {
    constexpr std::uint64_t kH200Tasks = 132 * 9;
    EXPECT_EQ(cuda::choose_raster_layout(14436, 25'900'000, kH200Tasks), cuda::RasterLayout::two_pixels_per_thread)
        << "city 4K";
    EXPECT_EQ(cuda::choose_raster_layout(9304, 8'000'000, kH200Tasks), cuda::RasterLayout::two_pixels_per_thread)
        << "garden low 4K";
    EXPECT_EQ(cuda::choose_raster_layout(43232, 8'700'000, kH200Tasks), cuda::RasterLayout::pixel_per_thread)
        << "garden survey 1080p";
    EXPECT_EQ(cuda::choose_raster_layout(23097, 5'000'000, kH200Tasks), cuda::RasterLayout::pixel_per_thread)
        << "garden low 1080p";
    // 1000 pairs over 100 tasks: 10 a task, so the boundary is a list of 17.
    EXPECT_EQ(cuda::choose_raster_layout(17, 1000, 100), cuda::RasterLayout::two_pixels_per_thread);
    EXPECT_EQ(cuda::choose_raster_layout(18, 1000, 100), cuda::RasterLayout::pixel_per_thread);
    EXPECT_EQ(cuda::choose_raster_layout(0, 0, 100), cuda::RasterLayout::two_pixels_per_thread) << "an empty frame";
}

ImageRGB8 cpu_render(const Scene& scene, const Camera& camera, const RenderOptions& options) {
    CpuRenderer<float> renderer;
    ImageF out;
    renderer.render(scene, camera, options, out);
    return to_rgb8(out);
}

ImageRGB8 gpu_render(const Scene& scene, const Camera& camera, const RenderOptions& options,
                     FrameStats* stats = nullptr, cuda::CudaLimits limits = {}) {
    cuda::CudaRenderer<float> renderer(nullptr, limits);
    renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
    ImageRGB8 out;
    FrameStats s = renderer.render(camera, options, &out, nullptr);
    if (stats) *stats = s;
    return out;
}

void expect_matches_cpu(const Scene& scene, const Camera& camera, const RenderOptions& options,
                        const std::string& what) {
    FrameStats stats;
    const ImageRGB8 gpu = gpu_render(scene, camera, options, &stats);
    const ImageRGB8 cpu = cpu_render(scene, camera, options);
    const ImageError e = compare(gpu, cpu);
    std::cout << "[cuda vs cpu] " << what << ": psnr " << e.psnr << " dB, max " << e.max_abs << " levels, pairs "
              << stats.pairs << ", visible " << stats.visible << std::endl;
    EXPECT_GE(e.psnr, kMinPsnr) << what;
    EXPECT_LE(e.max_abs, kMaxLevels) << what;
}

TEST_F(CudaRendererTest, RandomScenesMatchCpuInEveryCullingMode) {
    for (int trial = 0; trial < 3; ++trial) {
        test::RandomSceneParams p;
        p.count = 20000;
        const Scene scene = test::random_scene(test::fresh_seed("cuda random " + std::to_string(trial)), p);
        const Camera cam = test::forward_camera(333 + trial * 100, 197 + trial * 50, 75.0);
        for (Culling mode : {Culling::opacity_aware, Culling::bbox3sigma}) {
            RenderOptions o;
            o.culling = mode;
            o.background = {0.1f, 0.3f, 0.2f};
            expect_matches_cpu(scene, cam, o, std::string(culling_name(mode)) + " trial " + std::to_string(trial));
        }
    }
    test::RandomSceneParams small;
    small.count = 400;
    const Scene scene = test::random_scene(test::fresh_seed("cuda exact"), small);
    RenderOptions exact;
    exact.culling = Culling::exact;
    expect_matches_cpu(scene, test::forward_camera(120, 80, 70.0), exact, "exact");
}

// A 4K image (24.9 MB of RGB8) leaves the pinned staging through the renderer's helper
// threads (copy_out spreads images of 16 MiB and more, renderer_state.cuh): each frame of a
// moving camera, through one renderer, matches the CPU's.
TEST_F(CudaRendererTest, FourKImagesTakenBySeveralThreadsMatchCpu) {
    static_assert(3 * 3840 * 2160 >= (16 << 20), "the frame must be above copy_out's spread size");
    test::RandomSceneParams p;
    p.count = 20000;
    const Scene scene = test::random_scene(test::fresh_seed("cuda 4k copy"), p);
    cuda::CudaRenderer<float> renderer;
    renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
    ImageRGB8 gpu;
    for (int frame = 0; frame < 3; ++frame) {
        const Camera cam = test::forward_camera(3840, 2160, 75.0, {0.2 * frame, -0.1 * frame, 0.0});
        const FrameStats stats = renderer.render(cam, RenderOptions{}, &gpu, nullptr);
        const ImageError e = compare(gpu, cpu_render(scene, cam, RenderOptions{}));
        std::cout << "[cuda vs cpu] 4K frame " << frame << ": psnr " << e.psnr << " dB, max " << e.max_abs
                  << " levels, pairs " << stats.pairs << std::endl;
        EXPECT_GT(stats.pairs, 0u) << frame;
        EXPECT_GE(e.psnr, kMinPsnr) << "4K frame " << frame;
        EXPECT_LE(e.max_abs, kMaxLevels) << "4K frame " << frame;
    }
}

TEST_F(CudaRendererTest, BuiltinCityMatchesCpu) {
    CityParams params;
    params.gaussians = 300000;
    params.seed = test::fresh_seed("cuda city");
    const Scene city = make_city(params);
    const auto cameras = make_trajectory("builtin:survey?frames=40&altitude=70&pitch=-45", city.bounds,
                                         intrinsics_from_fov(640, 360, 70.0));
    for (std::size_t i : {std::size_t{0}, std::size_t{39}})
        expect_matches_cpu(city, cameras[i], RenderOptions{}, "city frame " + std::to_string(i));
}

TEST_F(CudaRendererTest, TruckSplatMatchesCpu) {
    const std::string path = test::shared_dir() + "/data/scenes/tandt-truck-uav4geo/truck.splat";
    if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not present";
    const Scene truck = read_splat(path);
    const auto cameras =
        make_trajectory("builtin:orbit?frames=8&up=-y&altitude=1.5", truck.bounds, intrinsics_from_fov(800, 600, 60.0));
    expect_matches_cpu(truck, cameras[3], RenderOptions{}, "truck orbit");
}

TEST_F(CudaRendererTest, EdgeCases) {
    // One Gaussian covering the whole screen.
    Scene big;
    big.resize(1);
    big.positions = {0, 0, 2};
    big.scales = {5, 5, 5};
    big.rotations = {1, 0, 0, 0};
    big.opacities = {0.7f};
    big.sh = {1.0f, -0.5f, 0.2f};
    big.update_bounds();
    expect_matches_cpu(big, test::forward_camera(257, 129, 90.0), RenderOptions{}, "screen-covering Gaussian");

    // Gaussians straddling the near plane: those at z <= 0.2 culled, those just beyond drawn.
    test::RandomSceneParams p;
    p.count = 3000;
    p.depth_min = 0.15;
    p.depth_max = 0.3;
    p.extent = 0.2;
    p.log_scale_min = -6;
    p.log_scale_max = -4;
    expect_matches_cpu(test::random_scene(test::fresh_seed("near plane"), p), test::forward_camera(200, 100, 70.0),
                       RenderOptions{}, "near plane");

    // Nothing visible (everything behind the camera), a 1x1 image, odd sizes.
    Scene behind = test::random_scene(test::fresh_seed("behind"), {});
    for (std::size_t i = 0; i < behind.count(); ++i) behind.positions[3 * i + 2] *= -1.0f;
    RenderOptions bg;
    bg.background = {0.25f, 0.5f, 1.0f};
    FrameStats stats;
    const ImageRGB8 empty = gpu_render(behind, test::forward_camera(31, 17, 60.0), bg, &stats);
    EXPECT_EQ(stats.pairs, 0u);
    for (std::size_t i = 0; i < empty.rgb.size(); i += 3) {
        ASSERT_EQ(empty.rgb[i], 64);
        ASSERT_EQ(empty.rgb[i + 2], 255);
    }
    const Scene front = test::random_scene(test::fresh_seed("tiny images"), {});
    for (auto [w, h] : {std::pair{1, 1}, std::pair{1, 37}, std::pair{45, 1}, std::pair{17, 33}})
        expect_matches_cpu(front, test::forward_camera(w, h, 60.0), RenderOptions{},
                           std::to_string(w) + "x" + std::to_string(h));
}

// A pair budget below the frame's pairs: the frame is rendered in bands and equals the
// one-pass render; a budget below one tile row's pairs is a clear error.
TEST_F(CudaRendererTest, CapacityOverflowRendersInBandsOrFailsCleanly) {
    test::RandomSceneParams p;
    p.count = 30000;
    const Scene scene = test::random_scene(test::fresh_seed("overflow"), p);
    const Camera cam = test::forward_camera(400, 300, 70.0);
    FrameStats whole, banded;
    const ImageRGB8 a = gpu_render(scene, cam, RenderOptions{}, &whole);
    const ImageRGB8 b = gpu_render(scene, cam, RenderOptions{}, &banded, cuda::CudaLimits{whole.pairs / 3});
    EXPECT_EQ(whole.bands, 1);
    EXPECT_GT(banded.bands, 1);
    EXPECT_EQ(a.rgb, b.rgb);
    try {
        gpu_render(scene, cam, RenderOptions{}, nullptr, cuda::CudaLimits{10});
        FAIL() << "no error for a budget of 10 pairs";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("more than the budget of 10"), std::string::npos) << e.what();
    }
}

TEST_F(CudaRendererTest, DeterministicAndSafeWithSeveralInstances) {
    test::RandomSceneParams p;
    p.count = 20000;
    const Scene scene = test::random_scene(test::fresh_seed("instances"), p);
    const Camera cam = test::forward_camera(300, 200, 70.0);
    const ImageRGB8 reference = gpu_render(scene, cam, RenderOptions{});
    EXPECT_EQ(gpu_render(scene, cam, RenderOptions{}).rgb, reference.rgb);
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    std::vector<ImageRGB8> results(4);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            cuda::CudaRenderer<float> renderer;
            renderer.set_scene(device_scene);
            for (int k = 0; k < 5; ++k) renderer.render(cam, RenderOptions{}, &results[t], nullptr);
        });
    for (auto& t : threads) t.join();
    for (const auto& r : results) EXPECT_EQ(r.rgb, reference.rgb);
}

// Every stage that launches work on a plain frame is timed by its own pair of events; the
// frame's time is their sum, and encode is the server's.
TEST_F(CudaRendererTest, StageTimesCoverTheFrame) {
    test::RandomSceneParams p;
    p.count = 20000;
    const Scene scene = test::random_scene(test::fresh_seed("stage times"), p);
    FrameStats stats;
    gpu_render(scene, test::forward_camera(320, 240, 70.0), RenderOptions{}, &stats);
    for (Stage stage :
         {Stage::preprocess, Stage::scan, Stage::keys, Stage::sort, Stage::ranges, Stage::rasterize, Stage::copy_out})
        EXPECT_GT(stats.stage_ms[stage], 0.0) << stage_name(stage);
    EXPECT_EQ(stats.stage_ms[Stage::encode], 0.0);
    EXPECT_DOUBLE_EQ(stats.total_ms, stats.stage_ms.sum());
}

// copy_out copies each band of rows once its tiles are drawn, on a stream of its own, while
// later tiles are drawn. Against the copy after the whole pass: the same bytes in every output,
// frame after frame of alternating views (a band copied before its tiles were drawn would hold
// the other view's pixels), in both layouts, split or not, in pair-budget bands, for cached
// frames and for partial frames.
TEST_F(CudaRendererTest, CopyOutOverlapsTheDrawingWithoutChangingTheImage) {
    test::RandomSceneParams p;
    p.count = 30000;
    const Scene scene = test::random_scene(test::fresh_seed("overlapped copy"), p);
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    std::cout << "[copy out] stream memory waits " << (cuda::stream_memory_waits_available() ? "taken" : "refused")
              << std::endl;
    // Alternating views, or a steady glide where the cache is on (its cached frames).
    auto view = [](bool glide, int frame) {
        const double x = glide ? 0.01 * frame : 0.4 * (frame % 2);
        return test::forward_camera(333, 250, 70.0, {x, 0.5 * x, 0.0});
    };
    const FrameStats one_pass = [&] {
        FrameStats stats;
        gpu_render(scene, view(false, 0), RenderOptions{}, &stats);
        return stats;
    }();
    RenderOptions split;
    split.catgs.split_k = 64;
    RenderOptions cached = default_pipeline_options();
    cached.catgs.window_cost = WindowCost::work;  // plans from work counts: both renderers plan alike
    struct Config {
        std::string name;
        RenderOptions options;
        cuda::RasterLayout layout;
        std::uint64_t max_pairs;
    };
    const Config configs[] = {
        {"one pixel a thread", RenderOptions{}, cuda::RasterLayout::pixel_per_thread, 0},
        {"two pixels a thread", RenderOptions{}, cuda::RasterLayout::two_pixels_per_thread, 0},
        {"split", split, cuda::RasterLayout::two_pixels_per_thread, 0},
        {"split, one pixel", split, cuda::RasterLayout::pixel_per_thread, 0},
        {"bands", RenderOptions{}, cuda::RasterLayout::automatic, one_pass.pairs / 3},
        {"split bands", split, cuda::RasterLayout::automatic, one_pass.pairs / 3},
        {"cached frames", cached, cuda::RasterLayout::automatic, 0},
    };
    for (const Config& c : configs) {
        cuda::CudaLimits overlapped{c.max_pairs, c.layout, true}, after_pass{c.max_pairs, c.layout, false};
        cuda::CudaRenderer<float> a(nullptr, overlapped), b(nullptr, after_pass);
        a.set_scene(device_scene);
        b.set_scene(device_scene);
        EXPECT_FALSE(b.copies_while_drawing());
        const bool glide = c.options.catgs.cache != CacheMode::off;
        int banded = 0, split_frames = 0, cached_frames = 0;
        for (const auto& [sa, sb] : test::expect_same_renders(
                 a, b, c.options, [&](int frame) { return view(glide, frame); }, 6, view(false, 1), c.name)) {
            banded += sa.bands > 1;
            split_frames += sa.split_tasks > 0;
            cached_frames += !sa.key_frame;
            EXPECT_GT(sa.stage_ms[Stage::copy_out], 0.0) << c.name;
        }
        if (c.max_pairs) {
            EXPECT_EQ(banded, 6) << c.name;
        }
        if (c.options.catgs.split_k == 64) {
            EXPECT_GT(split_frames, 0) << c.name;
        }
        if (glide) {
            EXPECT_GT(cached_frames, 0) << c.name;
        }
        // Where the driver takes stream memory waits, every frame copied while drawing (a wait
        // it refused mid-frame would have turned the renderer to the fallback for good).
        EXPECT_EQ(a.copies_while_drawing(), cuda::stream_memory_waits_available()) << c.name;
    }
}

TEST_F(CudaRendererTest, DoublePrecisionMatchesCpuDouble) {
    test::RandomSceneParams p;
    p.count = 5000;
    const Scene scene = test::random_scene(test::fresh_seed("cuda double"), p);
    const Camera cam = test::forward_camera(200, 120, 70.0);
    cuda::CudaRenderer<double> gpu;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    ImageRGB8 g;
    gpu.render(cam, RenderOptions{}, &g, nullptr);
    CpuRenderer<double> cpu;
    ImageF c;
    cpu.render(scene, cam, RenderOptions{}, c);
    const ImageError e = compare(g, to_rgb8(c));
    EXPECT_LE(e.max_abs, 1);
}

}  // namespace
}  // namespace catgs
