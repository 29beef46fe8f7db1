// A sharded frame composited on a GPU (device_compositor.hpp, composite.cuh): the partial a
// renderer leaves on its device (render_partial_on_device) is the one it copies to the host,
// the GPU composite is the host composite (composite_partials) of the same partials, and
// shards spread over several GPUs give the frame they give on one. Skips without a CUDA
// device; the several-GPU test skips with fewer than two.
#include <cuda_runtime_api.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "../shard_scenes.hpp"
#include "../test_util.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/sharded_renderer.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 301, kHeight = 187;  // not multiples of the tile: edge tiles are partial
constexpr double kFov = 60.0;
/// The GPU composite and the host composite evaluate the same float operations on the same
/// partials; nvcc may contract a multiply-add the host rounds twice.
constexpr double kCompositeMaxAbs = 1e-6;

class CudaCompositeTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

using test::error_of;

Scene chunked_random_scene(const char* label, std::size_t count) {
    test::RandomSceneParams p;
    p.count = count;
    Scene scene = test::random_scene(test::fresh_seed(label), p);
    partition_into_chunks(scene);
    return scene;
}

/// Shard s on devices[s % n].
ShardedRenderer::RendererFactory shards_on(std::vector<int> devices) {
    return [devices](int s) {
        return make_renderer("cuda", Precision::single, 0, devices[static_cast<std::size_t>(s) % devices.size()]);
    };
}

double max_abs(const std::vector<float>& a, const std::vector<float>& b) {
    EXPECT_EQ(a.size(), b.size());
    double worst = 0;
    for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
        worst = std::max(worst, static_cast<double>(std::fabs(a[i] - b[i])));
    return worst;
}

template <typename V>
std::vector<V> to_host(const V* device, std::size_t count) {
    std::vector<V> host(count);
    EXPECT_EQ(cudaMemcpy(host.data(), device, count * sizeof(V), cudaMemcpyDeviceToHost), cudaSuccess);
    return host;
}

// What render_partial_on_device leaves on the device is, bit for bit, what render_partial
// copies to the host, on a plain and a split frame.
TEST_F(CudaCompositeTest, PartialLeftOnTheDeviceIsTheCopiedPartial) {
    const Scene scene = chunked_random_scene("cuda device partial", 12000);
    auto renderer = make_renderer("cuda", Precision::single);
    renderer->set_scene(std::make_shared<Scene>(scene));
    RenderOptions split;
    split.catgs.split_k = 64;
    for (const RenderOptions& options : {RenderOptions{}, split})
        for (const Camera& camera : test::random_scene_cameras(kWidth, kHeight, kFov)) {
            PartialImage host;
            renderer->render_partial(camera, options, host);
            DevicePartialImage device;
            renderer->render_partial_on_device(camera, options, device);
            ASSERT_EQ(device.width, kWidth);
            ASSERT_EQ(device.height, kHeight);
            EXPECT_EQ(device.device, 0);
            const std::size_t pixels = host.transmittance.size();
            EXPECT_EQ(to_host(device.colour, 3 * pixels), host.colour);
            EXPECT_EQ(to_host(device.transmittance, pixels), host.transmittance);
            EXPECT_EQ(to_host(device.stopped, pixels), host.stopped);
        }
}

// Shards on one GPU composited there: the host composite of the same partials, in float and
// (quantised on the device) in 8 bits, for k = 1..8 and a background.
TEST_F(CudaCompositeTest, GpuCompositeIsTheHostComposite) {
    const Scene scene = chunked_random_scene("cuda composite", 20000);
    RenderOptions options;
    options.background = {0.3f, 0.1f, 0.6f};
    for (int k : {1, 2, 4, 8}) {
        ShardedRenderer host(scene, k, shards_on({0}), 1);
        ShardedRenderer gpu(scene, host.plan(), shards_on({0}), 1);
        gpu.set_compositor(make_partial_compositor("cuda", 0));
        for (const Camera& camera : test::random_scene_cameras(kWidth, kHeight, kFov)) {
            ImageF expected, image;
            host.render(camera, options, expected);
            const ShardedFrameStats stats = gpu.render(camera, options, image);
            const double d = max_abs(image.rgb, expected.rgb);
            std::cout << "[gpu composite] k " << k << ": max abs " << d << ", merge " << stats.merge_ms << " ms, copy "
                      << stats.copy_out_ms << " ms\n";
            EXPECT_LE(d, kCompositeMaxAbs) << "k " << k;
            EXPECT_EQ(stats.composited_on, 0);
            EXPECT_EQ(stats.peer_direct + stats.peer_staged, 0) << "every partial lies on the compositing device";
            EXPECT_GT(stats.merge_ms, 0.0);
            ImageRGB8 eight;
            gpu.render_rgb8(camera, options, eight);
            const ImageError e = compare(eight, to_rgb8(expected));
            EXPECT_LE(e.max_abs, 1) << "k " << k;  // a value on a rounding boundary may round apart
            EXPECT_LE(e.fraction_over_one, 0.0);
        }
    }
}

// Shards spread over two GPUs, rendering at once, composited on either: the frame of the same
// shards on one GPU, each partial of the other device copied over (peer or staged).
TEST_F(CudaCompositeTest, ShardsOnTwoGpusGiveTheFrameOfOne) {
    if (device_count("cuda") < 2) GTEST_SKIP() << "fewer than two CUDA devices";
    const Scene scene = chunked_random_scene("cuda two gpus", 20000);
    RenderOptions options;
    options.background = {0.1f, 0.2f, 0.3f};
    for (int k : {2, 3, 4}) {
        ShardedRenderer one(scene, k, shards_on({0}), 1);
        one.set_compositor(make_partial_compositor("cuda", 0));
        for (int compositing : {0, 1}) {
            ShardedRenderer two(scene, one.plan(), shards_on({0, 1}), 1);
            two.set_concurrent(true);
            two.set_compositor(make_partial_compositor("cuda", compositing));
            for (const Camera& camera : test::random_scene_cameras(kWidth, kHeight, kFov)) {
                ImageF expected, image;
                one.render(camera, options, expected);
                const ShardedFrameStats stats = two.render(camera, options, image);
                EXPECT_LE(max_abs(image.rgb, expected.rgb), kCompositeMaxAbs) << "k " << k;
                // Shards 0, 2, ... on device 0 and 1, 3, ... on device 1.
                const int elsewhere = compositing == 0 ? k / 2 : (k + 1) / 2;
                EXPECT_EQ(stats.peer_direct + stats.peer_staged, elsewhere) << "k " << k;
                std::cout << "[two gpus] k " << k << " on device " << compositing << ": transfer " << stats.transfer_ms
                          << " ms (" << stats.peer_direct << " peer, " << stats.peer_staged << " staged), merge "
                          << stats.merge_ms << " ms\n";
            }
        }
    }
}

TEST_F(CudaCompositeTest, BadPartialsAreNamed) {
    auto compositor = make_partial_compositor("cuda", 0);
    ImageF out;
    EXPECT_EQ(error_of([&] {
                  compositor->composite({}, {0, 0, 0}, &out, nullptr);
              }),
              "composite: no partial images to composite");
    const float colour[3 * 12] = {};
    const float transmittance[12] = {};
    const std::uint8_t stopped[12] = {};
    const DevicePartialImage a{0, 4, 3, colour, transmittance, stopped};
    DevicePartialImage b = a;
    b.width = 3;
    b.height = 4;
    EXPECT_EQ(error_of([&] {
                  compositor->composite({a, b}, {0, 0, 0}, &out, nullptr);
              }),
              "composite: partial 1 is 3x4, expected the first partial's 4x3");
    DevicePartialImage unset;
    unset.width = 4;
    unset.height = 3;
    EXPECT_EQ(error_of([&] {
                  compositor->composite({a, unset}, {0, 0, 0}, &out, nullptr);
              }),
              "composite: partial 1 has no device buffers (not rendered by render_partial_on_device)");
    const std::vector<DevicePartialImage> too_many(static_cast<std::size_t>(kMaxShards) + 1, a);
    EXPECT_EQ(error_of([&] {
                  compositor->composite(too_many, {0, 0, 0}, &out, nullptr);
              }),
              "composite: 65 partials, more than the 64 shards a frame may have");
    const int present = device_count("cuda");
    EXPECT_EQ(error_of([&] { make_partial_compositor("cuda", present); }),
              "composite: no CUDA device " + std::to_string(present) + " (" + std::to_string(present) + " present)");
}

}  // namespace
}  // namespace catgs
