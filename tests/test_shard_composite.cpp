// A sharded frame composited away from the host (ShardedRenderer::set_compositor): the partials
// stay where each shard's renderer drew them and a PartialCompositor gathers them. Here on the
// CPU, with renderers that hand out their partials' host memory as if it were a device's and
// a compositor that composites those with composite_partials: what ShardedRenderer hands the
// compositor (the visibility order, the devices), what it reports, and the flags and errors
// around it. The CUDA compositor itself is tested in tests/gpu/test_cuda_shards.cpp.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "catgs/device_list.hpp"
#include "catgs/error.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/sharded_renderer.hpp"
#include "shard_flags.hpp"
#include "shard_scenes.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

constexpr int kWidth = 160, kHeight = 120;
constexpr double kFov = 60.0;

/// A CPU renderer whose render_partial_on_device leaves the partial in its own memory and
/// hands out pointers to it, "on device" `device`.
class HostMemoryShard final : public Renderer {
public:
    explicit HostMemoryShard(int device) : device_(device), cpu_(make_renderer("cpu", Precision::single, 1)) {}
    void set_scene(std::shared_ptr<const Scene> scene) override { cpu_->set_scene(std::move(scene)); }
    FrameStats render(const Camera& camera, const RenderOptions& options, ImageF& out,
                      const FrameHints* hints) override {
        return cpu_->render(camera, options, out, hints);
    }
    FrameStats render_partial_on_device(const Camera& camera, const RenderOptions& options, DevicePartialImage& out,
                                        const FrameHints* hints) override {
        const FrameStats stats = cpu_->render_partial(camera, options, partial_, hints);
        out = DevicePartialImage{device_,
                                 partial_.width,
                                 partial_.height,
                                 partial_.colour.data(),
                                 partial_.transmittance.data(),
                                 partial_.stopped.data()};
        return stats;
    }
    void reset_cache() override { cpu_->reset_cache(); }
    std::string name() const override { return "test/host-memory"; }

private:
    int device_;
    std::unique_ptr<Renderer> cpu_;
    PartialImage partial_;
};

/// Composites what it is handed with the host composite, and remembers the devices it was
/// handed, in order; reports fixed times so that their way into the stats can be seen.
class RecordingCompositor final : public PartialCompositor {
public:
    CompositeTimes composite(const std::vector<DevicePartialImage>& front_to_back,
                             const std::array<float, 3>& background, ImageF* rgb, ImageRGB8* rgb8) override {
        devices.clear();
        std::vector<PartialImage> copies;
        for (const DevicePartialImage& d : front_to_back) {
            devices.push_back(d.device);
            PartialImage p;
            p.width = d.width;
            p.height = d.height;
            const std::size_t pixels = static_cast<std::size_t>(d.width) * static_cast<std::size_t>(d.height);
            p.colour.assign(d.colour, d.colour + 3 * pixels);
            p.transmittance.assign(d.transmittance, d.transmittance + pixels);
            p.stopped.assign(d.stopped, d.stopped + pixels);
            copies.push_back(std::move(p));
        }
        std::vector<const PartialImage*> ordered;
        for (const PartialImage& p : copies) ordered.push_back(&p);
        ImageF image;
        composite_partials(ordered, background, rgb ? *rgb : image, 1);
        if (rgb8) *rgb8 = to_rgb8(rgb ? *rgb : image);
        CompositeTimes t;
        t.transfer_ms = 0.25;
        t.merge_ms = 0.5;
        t.copy_out_ms = 0.125;
        t.peer_direct = 3;
        t.peer_staged = 1;
        return t;
    }
    int device() const override { return 7; }

    std::vector<int> devices;
};

Scene chunked_scene(const char* label) {
    test::RandomSceneParams p;
    p.count = 6000;
    Scene scene = test::random_scene(test::fresh_seed(label), p);
    partition_into_chunks(scene);
    return scene;
}

using test::error_of;

// The compositor gets every shard's partial once, in the frame's visibility order, and its
// image is the host composite's bit for bit; its times and device reach the frame's stats.
TEST(ShardComposite, CompositorGetsThePartialsInVisibilityOrder) {
    const Scene scene = chunked_scene("shard compositor order");
    const std::vector<Camera> cameras = test::random_scene_cameras(kWidth, kHeight, kFov);
    ShardedRenderer host(
        scene, 4, [](int) { return make_renderer("cpu", Precision::single, 1); }, 1);
    ShardedRenderer device(
        scene, host.plan(), [](int s) { return std::make_unique<HostMemoryShard>(s); }, 1);
    auto compositor = std::make_unique<RecordingCompositor>();
    const RecordingCompositor& recorded = *compositor;
    device.set_compositor(std::move(compositor));
    EXPECT_EQ(device.compositor_device(), 7);
    EXPECT_EQ(host.compositor_device(), -1);
    RenderOptions options;
    options.background = {0.2f, 0.1f, 0.4f};
    for (const Camera& camera : cameras) {
        ImageF expected, image;
        host.render(camera, options, expected);
        const ShardedFrameStats stats = device.render(camera, options, image);
        EXPECT_EQ(recorded.devices, stats.order) << "shard s renders on device s here";
        EXPECT_EQ(image.rgb, expected.rgb);
        EXPECT_EQ(stats.composited_on, 7);
        EXPECT_EQ(stats.transfer_ms, 0.25);
        EXPECT_EQ(stats.merge_ms, 0.5);
        EXPECT_EQ(stats.copy_out_ms, 0.125);
        EXPECT_EQ(stats.peer_direct, 3);
        EXPECT_EQ(stats.peer_staged, 1);
        EXPECT_EQ(stats.devices, (std::vector<int>{0, 1, 2, 3}));
        ImageRGB8 eight;
        device.render_rgb8(camera, options, eight);
        EXPECT_EQ(eight.rgb, to_rgb8(expected).rgb);
    }
}

// The host composite's 8-bit frame is its float frame quantised.
TEST(ShardComposite, HostCompositeInEightBitsIsTheFloatFrameQuantised) {
    const Scene scene = chunked_scene("shard rgb8");
    ShardedRenderer sharded(
        scene, 3, [](int) { return make_renderer("cpu", Precision::single, 1); }, 1);
    const Camera camera = test::random_scene_cameras(kWidth, kHeight, kFov)[0];
    ImageF image;
    ImageRGB8 eight;
    sharded.render(camera, RenderOptions{}, image);
    const ShardedFrameStats stats = sharded.render_rgb8(camera, RenderOptions{}, eight);
    EXPECT_EQ(eight.width, kWidth);
    EXPECT_EQ(eight.rgb, to_rgb8(image).rgb);
    EXPECT_EQ(stats.composited_on, -1);
    EXPECT_EQ(stats.transfer_ms, 0.0);
}

FrameStats shard_stats(double preprocess, double rasterize, std::uint64_t pairs, bool key) {
    FrameStats s;
    s.stage_ms[Stage::preprocess] = preprocess;
    s.stage_ms[Stage::rasterize] = rasterize;
    s.stage_ms[Stage::merge] = 0.0625;
    s.pairs = pairs;
    s.visible = pairs / 4;
    s.key_frame = key;
    s.window = key ? 1 : 4;
    s.longest_list = pairs / 10;
    s.total_ms = preprocess + rasterize + 0.0625;
    return s;
}

// Stages and totals add up when the shards take turns and the slowest shard's counts when
// they render at once; the composite's merge and the transfers go to their stages; counts add
// up.
TEST(ShardComposite, CombinedStatsSumInTurnAndTakeTheSlowestAtOnce) {
    ShardedFrameStats sharded;
    sharded.shards = {shard_stats(1.0, 3.0, 1000, false), shard_stats(2.0, 0.5, 3000, true)};
    sharded.merge_ms = 0.25;
    sharded.transfer_ms = 0.5;
    sharded.copy_out_ms = 0.125;
    sharded.total_ms = 9.0;  // the wall time: not what the combined frame reports
    const FrameStats in_turn = combine_shard_stats(sharded, false);
    EXPECT_DOUBLE_EQ(in_turn.stage_ms[Stage::preprocess], 3.0);
    EXPECT_DOUBLE_EQ(in_turn.stage_ms[Stage::rasterize], 3.5);
    EXPECT_DOUBLE_EQ(in_turn.stage_ms[Stage::merge], 0.0625 * 2 + 0.25);
    EXPECT_DOUBLE_EQ(in_turn.stage_ms[Stage::copy_out], 0.625);
    const FrameStats at_once = combine_shard_stats(sharded, true);
    EXPECT_DOUBLE_EQ(at_once.stage_ms[Stage::preprocess], 2.0);
    EXPECT_DOUBLE_EQ(at_once.stage_ms[Stage::rasterize], 3.0);
    EXPECT_DOUBLE_EQ(at_once.stage_ms[Stage::merge], 0.0625 + 0.25);
    for (const FrameStats& s : {in_turn, at_once}) {
        EXPECT_EQ(s.pairs, 4000u);
        EXPECT_EQ(s.visible, 1000u);
        EXPECT_EQ(s.longest_list, 300u);
        EXPECT_TRUE(s.key_frame);
        EXPECT_EQ(s.window, 4);
    }
    // GPU time as an unsharded frame counts it: the shards' (4.0625 and 2.5625 ms), summed or
    // the slowest, and the composite's 0.875.
    EXPECT_DOUBLE_EQ(in_turn.total_ms, 4.0625 + 2.5625 + 0.875);
    EXPECT_DOUBLE_EQ(at_once.total_ms, 4.0625 + 0.875);
    // Shards at once on separate GPUs: their spans are the devices'. Two sharing a GPU overlap
    // there, so the frame counts its wall time.
    sharded.devices = {0, 1};
    EXPECT_DOUBLE_EQ(combine_shard_stats(sharded, true).total_ms, 4.0625 + 0.875);
    sharded.devices = {1, 1};
    EXPECT_DOUBLE_EQ(combine_shard_stats(sharded, true).total_ms, 9.0);
    EXPECT_DOUBLE_EQ(combine_shard_stats(sharded, false).total_ms, 4.0625 + 2.5625 + 0.875);
}

TEST(ShardComposite, BadRequestsAreNamed) {
    const Scene scene = chunked_scene("shard compositor errors");
    auto cpu = make_renderer("cpu", Precision::single, 1);
    DevicePartialImage partial;
    EXPECT_EQ(
        error_of([&] { cpu->render_partial_on_device(test::forward_camera(8, 8, 60), RenderOptions{}, partial); }),
        "render_partial_on_device: not supported by backend cpu/float");
    EXPECT_EQ(error_of([] { make_partial_compositor("cpu", 0); }),
              "backend 'cpu' has no device compositor: its shards composite on the host (composite_partials)");
    EXPECT_EQ(error_of([] { make_partial_compositor("vulkan", 0); }).rfind("unknown backend 'vulkan'", 0), 0u);

    ShardedRenderer sharded(
        scene, 2, [](int) { return make_renderer("cpu", Precision::single, 1); }, 1);
    sharded.set_compositor(std::make_unique<RecordingCompositor>());
    ImageF image;
    EXPECT_EQ(error_of([&] { sharded.render(test::forward_camera(8, 8, 60), RenderOptions{}, image); }),
              "render_partial_on_device: not supported by backend cpu/float");

    EXPECT_EQ(error_of([] { parse_device_list("--shard-devices", "0,x", 2, 1); }),
              "--shard-devices: '0,x': 'x' is not a device index; expected all, a device count N or a "
              "comma-separated list of device indices (0,2)");
    EXPECT_EQ(error_of([] { parse_device_list("--shard-devices", "3", 2, 1); }),
              "--shard-devices: '3': 3 devices asked for, but 2 CUDA devices are present (0..1)");
    EXPECT_EQ(parse_device_list("--shard-devices", "1,0", 2, 1), (std::vector<int>{0, 1}));

    cli::ShardFlags flags;
    flags.shards = 2;
    flags.composite = "device";
    EXPECT_EQ(error_of([&] { cli::make_sharded_renderer(flags, scene, "cpu", Precision::single, 1); }),
              "--composite device: backend 'cpu' has no device memory; use host or auto");
    flags.composite = "auto";
    flags.shards = 1;
    EXPECT_EQ(cli::make_sharded_renderer(flags, scene, "cpu", Precision::single, 1), nullptr);
    flags.shards = 3;
    const auto made = cli::make_sharded_renderer(flags, scene, "cpu", Precision::single, 1);
    ASSERT_NE(made, nullptr);
    EXPECT_EQ(made->compositor_device(), -1);
    EXPECT_FALSE(made->concurrent());
    EXPECT_EQ(cli::describe_sharding(flags, *made, "cpu"), "3 shards of cpu/float, composited on the host");
}

}  // namespace
}  // namespace catgs
