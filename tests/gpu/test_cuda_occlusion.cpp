// The occlusion cut (stages/occlusion.hpp) through the CUDA backend: every frame's image is the
// one the full lists draw, bit for bit, whether the cut held, missed and drew the frame again,
// or stood aside (windows, splits, partials, double); and it does leave Gaussians out of dense
// scenes. Skips without a CUDA device.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "../occlusion_paths.hpp"
#include "../test_util.hpp"
#include "catgs/occlusion_tracker.hpp"
#include "cuda_renderer.hpp"
#include "occlusion.cuh"

namespace catgs {
namespace {

class CudaOcclusionTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

std::vector<Camera> occlusion_path(int width, int height) {
    return test::occlusion::path(width, height);
}

using test::occlusion::PathCounts;

/// Renders the path with the cut on and off, one renderer each, and asserts every frame equal.
PathCounts compare_path(const Scene& scene, const std::vector<Camera>& path, RenderOptions options,
                        cuda::CudaLimits limits, const std::string& what) {
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    cuda::CudaRenderer<float> with(nullptr, limits), without(nullptr, limits);
    with.set_scene(device_scene);
    without.set_scene(device_scene);
    RenderOptions off = options;
    options.catgs.occlusion_cut = true;
    off.catgs.occlusion_cut = false;
    PathCounts counts;
    for (std::size_t f = 0; f < path.size(); ++f) {
        ImageRGB8 a8, b8;
        ImageF af, bf;
        const FrameStats a = with.render(path[f], options, &a8, &af);
        const FrameStats b = without.render(path[f], off, &b8, &bf);
        const std::string frame = what + ", frame " + std::to_string(f);
        EXPECT_EQ(a8.rgb, b8.rgb) << frame;
        EXPECT_EQ(af.rgb, bf.rgb) << frame;
        test::occlusion::check_frame(a, b, frame, counts);
    }
    test::occlusion::report(counts, what);
    return counts;
}

test::RandomSceneParams dense_scene() {
    return test::occlusion::dense_scene(150000);
}

TEST_F(CudaOcclusionTest, EveryFrameIsTheFullListsImageWhetherTheCutHeldOrMissed) {
    const Scene scene = test::random_scene(test::fresh_seed("occlusion cut"), dense_scene());
    const std::vector<Camera> path = occlusion_path(320, 240);
    for (const auto& [name, layout] : {std::pair{"two pixels a thread", cuda::RasterLayout::two_pixels_per_thread},
                                       std::pair{"one pixel a thread", cuda::RasterLayout::pixel_per_thread}}) {
        const PathCounts c = compare_path(scene, path, RenderOptions{}, cuda::CudaLimits{0, layout, true}, name);
        EXPECT_GE(c.frames_cut, 4u) << name << ": the glide's frames leave Gaussians out";
        EXPECT_GE(c.redrawn, 1u) << name << ": the jump past the edge misses";
    }
}

// In pair-budget bands each band's tiles check and record their own cut.
TEST_F(CudaOcclusionTest, BandedFramesCutAndCheckEveryBand) {
    const Scene scene = test::random_scene(test::fresh_seed("occlusion bands"), dense_scene());
    const std::vector<Camera> path = occlusion_path(256, 200);
    cuda::CudaRenderer<float> probe;
    probe.set_scene(std::make_shared<cuda::DeviceScene>(scene, probe.stream()));
    ImageRGB8 image;
    const FrameStats full = probe.render(path[0], RenderOptions{}, &image, nullptr);
    const PathCounts c = compare_path(scene, path, RenderOptions{},
                                      cuda::CudaLimits{full.pairs / 3, cuda::RasterLayout::automatic, true}, "bands");
    EXPECT_GE(c.frames_cut, 4u);
}

// Where the cut cannot be checked tile by tile it stands aside: split tiles (a sub-task's stop
// says nothing of its tile's), windows of the cache (their lists serve other poses) and exact
// culling (one list for every tile). The images stay the full lists' all the same.
TEST_F(CudaOcclusionTest, StandsAsideForSplitsWindowsAndExactCulling) {
    test::RandomSceneParams p = dense_scene();
    p.count = 60000;
    const Scene scene = test::random_scene(test::fresh_seed("occlusion aside"), p);
    const std::vector<Camera> path = occlusion_path(200, 150);
    RenderOptions split;
    split.catgs.split_k = 64;
    RenderOptions window;
    window.catgs.cache = CacheMode::speculative;
    window.catgs.adaptive_window = false;
    window.catgs.window = 4;
    RenderOptions exact;
    exact.culling = Culling::exact;
    for (const auto& [name, options] : {std::pair{"split", split}, std::pair{"window", window}}) {
        const PathCounts c = compare_path(scene, path, options, cuda::CudaLimits{}, name);
        EXPECT_EQ(c.occluded, 0u) << name;
    }
    const std::vector<Camera> short_path(path.begin(), path.begin() + 3);
    const PathCounts c = compare_path(scene, short_path, exact, cuda::CudaLimits{}, "exact");
    EXPECT_EQ(c.occluded, 0u);
}

// A partial frame (a shard's colour and transmittance) goes on past its own Gaussians' opacity,
// so it neither takes the cut nor records one; nor does double, the reference precision.
TEST_F(CudaOcclusionTest, PartialAndDoubleFramesTakeNoCut) {
    const Scene scene = test::random_scene(test::fresh_seed("occlusion partial"), dense_scene());
    const std::vector<Camera> path = occlusion_path(160, 120);
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    RenderOptions on;
    on.catgs.occlusion_cut = true;
    cuda::CudaRenderer<float> gpu;
    gpu.set_scene(device_scene);
    for (int f = 0; f < 4; ++f) {
        PartialImage partial;
        EXPECT_EQ(gpu.render_partial(path[static_cast<std::size_t>(f)], on, partial).occluded, 0u) << f;
    }
    cuda::CudaRenderer<double> reference;
    reference.set_scene(device_scene);
    for (int f = 0; f < 4; ++f) {
        ImageRGB8 image;
        EXPECT_EQ(reference.render(path[static_cast<std::size_t>(f)], on, &image, nullptr).occluded, 0u) << f;
    }
}

// The device's prediction and pyramid (occlusion.cu) against the shared functions on the host.
TEST_F(CudaOcclusionTest, PredictionKernelMatchesTheHostFunctions) {
    std::mt19937_64 rng(test::fresh_seed("occlusion prediction"));
    std::uniform_real_distribution<float> depth(0.5f, 80.0f);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (const auto& [w, h] : {std::pair{37, 23}, std::pair{240, 135}, std::pair{1, 1}}) {
        const OcclusionPyramid p = occlusion_pyramid(w, h);
        std::vector<float> recorded(static_cast<std::size_t>(w * h));
        for (float& c : recorded) c = u(rng) < 0.05 ? INFINITY : depth(rng);
        const OcclusionMotion m = occlusion_motion(0.004, 0.3, 1000.0);
        ASSERT_TRUE(m.usable);
        void *d_recorded = nullptr, *d_cells = nullptr;
        ASSERT_EQ(cudaMalloc(&d_recorded, recorded.size() * sizeof(float)), cudaSuccess);
        ASSERT_EQ(cudaMalloc(&d_cells, static_cast<std::size_t>(p.cells) * sizeof(float)), cudaSuccess);
        cudaMemcpy(d_recorded, recorded.data(), recorded.size() * sizeof(float), cudaMemcpyHostToDevice);
        cuda::predict_occlusion(static_cast<const float*>(d_recorded), p, m, static_cast<float*>(d_cells), nullptr);
        std::vector<float> cells(static_cast<std::size_t>(p.cells));
        ASSERT_EQ(cudaMemcpy(cells.data(), d_cells, cells.size() * sizeof(float), cudaMemcpyDeviceToHost), cudaSuccess);
        cudaFree(d_recorded);
        cudaFree(d_cells);
        // Within a rounding: nvcc may fuse the prediction's multiply-add.
        const std::vector<float> host = occlusion_cells(recorded, p, m);
        for (std::size_t c = 0; c < host.size(); ++c) {
            if (std::isinf(host[c])) {
                ASSERT_EQ(cells[c], host[c]) << w << "x" << h << " cell " << c;
            } else {
                ASSERT_NEAR(cells[c], host[c], 1e-6f * host[c]) << w << "x" << h << " cell " << c;
            }
        }
    }
}

}  // namespace
}  // namespace catgs
