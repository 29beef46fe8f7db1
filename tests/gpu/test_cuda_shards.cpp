// The CUDA backend's partial output (CudaRenderer::render_partial: colour R, transmittance A
// and the stop per pixel, before the background) against the CPU's, and sharded frames whose
// shards render in sequence on one GPU against the unsharded frame (sharded_renderer.hpp).
// Every test skips when no CUDA device is present (CI has none).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

#include "../shard_scenes.hpp"
#include "../test_util.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/sharded_renderer.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 333, kHeight = 197;  // not multiples of the tile: edge tiles are partial
constexpr double kFov = 60.0;

/// Float partials of the two backends evaluate the same formulas, but nvcc contracts
/// multiply-adds and the CUDA exp differs by an ulp, so a pixel near a threshold (alpha =
/// 1/255, T = 1e-4) can flip: the bar of the float image test (CudaRendererTest: 2 levels),
/// in colour and transmittance, and a few stops.
constexpr double kFloatMaxAbs = 2.0 / 255.0;
constexpr double kFloatMaxStopShare = 1e-3;
/// Double partials are rounded to float on both sides: they agree to float rounding.
constexpr double kDoubleMaxAbs = 1e-6;

class CudaShardsTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

struct PartialDifference {
    double colour = 0, transmittance = 0;
    std::size_t stops_differing = 0;
};

PartialDifference difference(const PartialImage& a, const PartialImage& b) {
    PartialDifference d;
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_EQ(a.colour.size(), b.colour.size());
    EXPECT_EQ(a.transmittance.size(), b.transmittance.size());
    for (std::size_t i = 0; i < std::min(a.colour.size(), b.colour.size()); ++i)
        d.colour = std::max(d.colour, static_cast<double>(std::fabs(a.colour[i] - b.colour[i])));
    for (std::size_t p = 0; p < std::min(a.transmittance.size(), b.transmittance.size()); ++p) {
        d.transmittance =
            std::max(d.transmittance, static_cast<double>(std::fabs(a.transmittance[p] - b.transmittance[p])));
        d.stops_differing += a.stopped[p] != b.stopped[p];
    }
    return d;
}

template <typename T>
PartialImage gpu_partial(const Scene& scene, const Camera& camera, const RenderOptions& options,
                         cuda::RasterLayout layout) {
    cuda::CudaRenderer<T> renderer(nullptr, cuda::CudaLimits{0, layout});
    renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
    PartialImage out;
    renderer.render_partial(camera, options, out);
    return out;
}

template <typename T>
PartialImage cpu_partial(const Scene& scene, const Camera& camera, const RenderOptions& options) {
    CpuRenderer<T> renderer;
    PartialImage out;
    renderer.render_partial(scene, camera, options, out);
    return out;
}

/// Both of the rasterizer's layouts: the automatic choice would draw these small frames with
/// one only.
constexpr cuda::RasterLayout kLayouts[] = {cuda::RasterLayout::pixel_per_thread,
                                           cuda::RasterLayout::two_pixels_per_thread};

std::vector<Camera> cameras() {
    return test::random_scene_cameras(kWidth, kHeight, kFov);
}

/// The plain pipeline, and split k = 64 so that most tiles' pixels come from merge.
std::vector<RenderOptions> partial_options() {
    RenderOptions plain;
    plain.background = {0.2f, 0.5f, 0.9f};  // ignored by a partial
    RenderOptions split = plain;
    split.catgs.split_k = 64;
    return {plain, split};
}

TEST_F(CudaShardsTest, FloatPartialsMatchTheCpuPartials) {
    test::RandomSceneParams p;
    p.count = 20000;
    Scene scene = test::random_scene(test::fresh_seed("cuda partial float"), p);
    partition_into_chunks(scene);
    for (const RenderOptions& options : partial_options())
        for (const Camera& camera : cameras())
            for (const cuda::RasterLayout layout : kLayouts) {
                const PartialDifference d = difference(gpu_partial<float>(scene, camera, options, layout),
                                                       cpu_partial<float>(scene, camera, options));
                std::cout << "[cuda partial float] layout " << static_cast<int>(layout) << " split "
                          << options.catgs.split_k << ": colour " << d.colour << ", transmittance " << d.transmittance
                          << ", stops differing " << d.stops_differing << "\n";
                EXPECT_LE(d.colour, kFloatMaxAbs);
                EXPECT_LE(d.transmittance, kFloatMaxAbs);
                EXPECT_LE(static_cast<double>(d.stops_differing), kFloatMaxStopShare * kWidth * kHeight);
            }
}

TEST_F(CudaShardsTest, DoublePartialsEqualTheCpuPartials) {
    test::RandomSceneParams p;
    p.count = 5000;
    Scene scene = test::random_scene(test::fresh_seed("cuda partial double"), p);
    partition_into_chunks(scene);
    for (const RenderOptions& options : partial_options())
        for (const Camera& camera : cameras())
            for (const cuda::RasterLayout layout : kLayouts) {
                const PartialDifference d = difference(gpu_partial<double>(scene, camera, options, layout),
                                                       cpu_partial<double>(scene, camera, options));
                EXPECT_LE(d.colour, kDoubleMaxAbs) << "layout " << static_cast<int>(layout);
                EXPECT_LE(d.transmittance, kDoubleMaxAbs) << "layout " << static_cast<int>(layout);
                EXPECT_EQ(d.stops_differing, 0u) << "layout " << static_cast<int>(layout);
            }
}

// R + A * background from the partial is the frame render() draws with that background, up to
// the float rounding of that one multiply-add.
TEST_F(CudaShardsTest, PartialIsTheFrameBeforeItsBackground) {
    test::RandomSceneParams p;
    p.count = 8000;
    Scene scene = test::random_scene(test::fresh_seed("cuda partial frame"), p);
    partition_into_chunks(scene);
    for (RenderOptions options : partial_options()) {
        options.background = {0.3f, 0.6f, 0.1f};
        const Camera camera = cameras()[1];
        cuda::CudaRenderer<float> renderer;
        renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
        PartialImage partial;
        ImageF image;
        renderer.render_partial(camera, options, partial);
        renderer.render(camera, options, nullptr, &image);
        ASSERT_EQ(image.rgb.size(), 3 * partial.transmittance.size());
        std::size_t covered = 0;
        double worst = 0;
        for (std::size_t px = 0; px < partial.transmittance.size(); ++px) {
            covered += partial.transmittance[px] < 0.5f;
            for (int c = 0; c < 3; ++c)
                worst = std::max(worst, static_cast<double>(std::fabs(
                                            image.rgb[3 * px + c] -
                                            (partial.colour[3 * px + c] +
                                             partial.transmittance[px] * options.background[static_cast<size_t>(c)]))));
        }
        EXPECT_LT(worst, 1e-6);
        EXPECT_GT(covered, partial.transmittance.size() / 10) << "the scene must cover part of the frame";
    }
}

ShardedRenderer::RendererFactory gpu_shards() {
    return [](int) { return make_renderer("cuda", Precision::single); };
}

ImageF gpu_frame(const Scene& scene, const Camera& camera, const RenderOptions& options) {
    cuda::CudaRenderer<float> renderer;
    renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
    ImageF image;
    renderer.render(camera, options, nullptr, &image);
    return image;
}

double max_abs(const ImageF& a, const ImageF& b) {
    EXPECT_EQ(a.rgb.size(), b.rgb.size());
    double worst = 0;
    for (std::size_t i = 0; i < std::min(a.rgb.size(), b.rgb.size()); ++i)
        worst = std::max(worst, static_cast<double>(std::fabs(a.rgb[i] - b.rgb[i])));
    return worst;
}

// Shards rendered one after another on one GPU, composited on the host: where no Gaussian
// straddles a plane, the unsharded frame up to float rounding (the CPU test's bound).
TEST_F(CudaShardsTest, ShardsInSequenceOnOneGpuMatchTheUnshardedFrame) {
    const Scene scene = test::separated_clusters(test::fresh_seed("cuda separated clusters"));
    RenderOptions options;
    options.background = {0.1f, 0.2f, 0.3f};
    for (int k : {1, 2, 4, 8})
        for (const Camera& camera :
             {test::forward_camera(kWidth, kHeight, kFov), test::oblique_cluster_camera(kWidth, kHeight, kFov)}) {
            ShardedRenderer sharded(scene, k, gpu_shards(), 1);
            ImageF image;
            const ShardedFrameStats stats = sharded.render(camera, options, image);
            EXPECT_EQ(stats.shards.size(), static_cast<std::size_t>(k));
            const double d = max_abs(image, gpu_frame(scene, camera, options));
            std::cout << "[cuda separated] k " << k << ": max abs " << d << "\n";
            EXPECT_LT(d, 1e-5) << "k " << k;
        }
}

// With straddlers the sharded frame is not the unsharded one, but the two backends shard alike
// (one plan, one order): the CUDA composite is the CPU composite to the float image bar.
TEST_F(CudaShardsTest, ShardedFramesMatchTheCpuShardedFrames) {
    test::RandomSceneParams p;
    p.count = 20000;
    Scene scene = test::random_scene(test::fresh_seed("cuda sharded random"), p);
    partition_into_chunks(scene);
    for (int k : {2, 4})
        for (const Camera& camera : cameras()) {
            ShardedRenderer gpu(scene, k, gpu_shards(), 1);
            ShardedRenderer cpu(
                scene, gpu.plan(), [](int) { return make_renderer("cpu", Precision::single); }, 1);
            ImageF g, c;
            gpu.render(camera, RenderOptions{}, g);
            cpu.render(camera, RenderOptions{}, c);
            const ImageError e = compare(to_rgb8(g), to_rgb8(c));
            std::cout << "[cuda vs cpu sharded] k " << k << ": psnr " << e.psnr << " dB, max " << e.max_abs
                      << " levels\n";
            EXPECT_GE(e.psnr, 50.0);
            EXPECT_LE(e.max_abs, 2);
        }
}

}  // namespace
}  // namespace catgs
