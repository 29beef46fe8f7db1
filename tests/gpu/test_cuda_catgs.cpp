// CaT-GS on the GPU: tile task splitting and the speculative cache through the CUDA backend,
// against the CPU reference. Skips without a CUDA device.
#include <gtest/gtest.h>

#include "../catgs_paths.hpp"
#include "../test_util.hpp"
#include "catgs/builtin_city.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/trajectory.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

class CudaCatgsTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

ImageRGB8 cpu_full(const Scene& scene, const Camera& camera, Culling culling = Culling::opacity_aware) {
    CpuRenderer<float> r;
    RenderOptions o;
    o.culling = culling;
    ImageF out;
    r.render(scene, camera, o, out);
    return to_rgb8(out);
}

TEST_F(CudaCatgsTest, SplittingMatchesTheUnsplitReference) {
    test::RandomSceneParams p;
    p.count = 40000;
    p.extent = 2.0;  // dense: long lists
    const Scene scene = test::random_scene(test::fresh_seed("cuda split"), p);
    const Camera cam = test::forward_camera(257, 143, 60.0);
    const ImageRGB8 reference = cpu_full(scene, cam);
    cuda::CudaRenderer<float> gpu;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    for (const char* mode : {"7", "64", "300", "auto"}) {
        RenderOptions o;
        if (std::string(mode) == "auto")
            o.catgs.split_auto = true;
        else
            o.catgs.split_k = static_cast<std::uint32_t>(std::stoul(mode));
        ImageRGB8 image;
        const FrameStats s = gpu.render(cam, o, &image, nullptr);
        const ImageError e = compare(image, reference);
        std::cout << "[cuda split " << mode << "] k " << s.split_k << ", extra tasks " << s.split_tasks << ", psnr "
                  << e.psnr << ", max " << e.max_abs << std::endl;
        if (std::string(mode) != "auto") {
            EXPECT_GT(s.split_tasks, 0u) << mode;
        }
        EXPECT_GE(e.psnr, 50.0) << mode;
        EXPECT_LE(e.max_abs, 2) << mode;
    }
    // The CPU split with the same k agrees with the GPU split.
    RenderOptions o;
    o.catgs.split_k = 64;
    CpuRenderer<float> cpu;
    ImageF c;
    const FrameStats cs = cpu.render(scene, cam, o, c);
    ImageRGB8 g;
    const FrameStats gs = gpu.render(cam, o, &g, nullptr);
    EXPECT_EQ(cs.split_tasks, gs.split_tasks);
    EXPECT_LE(compare(g, to_rgb8(c)).max_abs, 2);
}

// A cached frame draws its key frame's task list whatever k its own plan names: the key frame
// may have split at another k (SplitChooser moves k along its ladder per path), and rasterize
// must launch every extra sub-task of that list, or a split tile is never merged and its copy
// band never completes (session 40: the kit's garden hung at the first cached frame after a
// key frame split at k / 2). Here the options' k changes between the two frames.
TEST_F(CudaCatgsTest, CachedFramesDrawTheKeyFramesSplitWhateverTheirOwnK) {
    test::RandomSceneParams p;
    p.count = 40000;
    p.extent = 2.0;  // dense: long lists
    const Scene scene = test::random_scene(test::fresh_seed("cached split k"), p);
    Camera cam = test::forward_camera(257, 143, 60.0);
    const ImageRGB8 reference = cpu_full(scene, cam);
    cuda::CudaRenderer<float> gpu;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    RenderOptions o = test::cached_list_options(7);
    ImageRGB8 image;
    const FrameStats key = gpu.render(cam, o, &image, nullptr);
    ASSERT_TRUE(key.key_frame);
    ASSERT_GT(key.split_tasks, 0u);
    o.catgs.split_k = 4096;  // fewer extra tasks than the key frame's list holds
    for (int i = 1; i < 3; ++i) {
        cam.timestamp = i / 30.0;
        const FrameStats cached = gpu.render(cam, o, &image, nullptr);
        EXPECT_FALSE(cached.key_frame) << "frame " << i;
        EXPECT_EQ(cached.split_k, 7u) << "frame " << i;
        const ImageError e = compare(image, reference);
        EXPECT_LE(e.max_abs, 2) << "frame " << i;
        EXPECT_GE(e.psnr, 50.0) << "frame " << i;
    }
}

/// The built-in city at 200000 Gaussians: tile lists long enough to split.
Scene gpu_city(const std::string& what) {
    CityParams params;
    params.gaussians = 200000;
    params.seed = test::fresh_seed(what);
    return make_city(params);
}

struct PathResult {
    double mean_psnr = 0, worst_psnr = 1e9;
    int cached = 0;
    std::uint64_t cached_split_tasks = 0;
};

PathResult run_gpu_path(const Scene& scene, const std::vector<Camera>& cameras, const RenderOptions& options) {
    cuda::CudaRenderer<float> gpu;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    PathResult r;
    double sum = 0;
    for (const Camera& cam : cameras) {
        ImageRGB8 image;
        const FrameStats s = gpu.render(cam, options, &image, nullptr);
        const double psnr = std::min(compare(image, cpu_full(scene, cam)).psnr, 100.0);
        sum += psnr;
        r.worst_psnr = std::min(r.worst_psnr, psnr);
        r.cached += !s.key_frame;
        if (!s.key_frame) r.cached_split_tasks += s.split_tasks;
    }
    r.mean_psnr = sum / static_cast<double>(cameras.size());
    return r;
}

// The accuracy bar on the GPU: cached and split frames against the per-frame CPU render.
TEST_F(CudaCatgsTest, CacheMeetsTheAccuracyBarOnUavPaths) {
    const Scene city = gpu_city("cuda cache city");
    const Intrinsics k = intrinsics_from_fov(480, 270, 70.0);
    std::vector<test::CameraPath> paths;
    for (const char* spec : {"builtin:survey?frames=30&altitude=70", "builtin:orbit?frames=30&altitude=60&speed=12",
                             "builtin:flythrough?frames=30&altitude=40&speed=14", "builtin:hover?frames=30"})
        paths.push_back({spec, make_trajectory(spec, city.bounds, k)});
    int cached = 0;
    test::for_each_accuracy_bar_run(paths, [&](const test::CameraPath& p, const test::CacheRun& run) {
        const PathResult r = run_gpu_path(city, p.cameras, run.options);
        std::cout << "[cuda cache " << p.name << run.label << "] psnr mean " << r.mean_psnr << " worst " << r.worst_psnr
                  << ", cached " << r.cached << std::endl;
        EXPECT_GE(r.mean_psnr, test::kMeanPsnrBar) << p.name;
        EXPECT_GE(r.worst_psnr, test::kWorstPsnrBar) << p.name;
        if (r.cached > 0) {
            EXPECT_GT(r.cached_split_tasks, 0u) << p.name;
        }
        cached += r.cached;
    });
    EXPECT_GT(cached, 100);
}

TEST_F(CudaCatgsTest, UnspeculatedCacheShowsStripesThatSpeculationRemoves) {
    const Scene city = gpu_city("cuda stripes");
    const auto [bad, good] = test::run_stripes_path(city, intrinsics_from_fov(480, 270, 70.0), run_gpu_path);
    std::cout << "[cuda unspeculated] worst " << bad.worst_psnr << "; [speculative] worst " << good.worst_psnr
              << ", cached " << good.cached << std::endl;
    EXPECT_LT(bad.worst_psnr, test::kStripedWorstPsnr);
    EXPECT_GE(good.worst_psnr, test::kWorstPsnrBar);
    EXPECT_GT(good.cached, 8);
}

// A frame rendered in bands cannot seed a cached window: the next frame is a key frame, and
// every frame still matches the reference.
TEST_F(CudaCatgsTest, BandedFramesAreNeverCached) {
    test::RandomSceneParams p;
    p.count = 30000;
    const Scene scene = test::random_scene(test::fresh_seed("bands and cache"), p);
    const Camera cam = test::forward_camera(320, 240, 70.0);
    cuda::CudaRenderer<float> gpu;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    RenderOptions o;
    o.catgs.cache = CacheMode::speculative;
    ImageRGB8 image;
    const FrameStats whole = gpu.render(cam, o, &image, nullptr);
    gpu.reset_cache();
    gpu.set_limits(cuda::CudaLimits{whole.pairs / 3});
    Camera c = cam;
    for (int i = 0; i < 4; ++i) {
        c.timestamp = i / 30.0;
        const FrameStats s = gpu.render(c, o, &image, nullptr);
        EXPECT_GT(s.bands, 1);
        EXPECT_TRUE(s.key_frame) << "frame " << i;
        EXPECT_LE(compare(image, cpu_full(scene, c)).max_abs, 2);
    }
}

}  // namespace
}  // namespace catgs
