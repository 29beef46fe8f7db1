// The split stage's heavy lists (stages/split.hpp: runs_first, kHeavyListFactor): rasterize
// starts the unsplit lists of at least the factor times the mean non-empty list right after the
// extra sub-tasks. The device must list exactly the tiles the rule names, and the order must not
// change a single pixel, in any task layout, split or not, in bands, on cached frames and in
// partial frames, nor may their pixels' way through host memory. Skips without a CUDA device.
#include <gtest/gtest.h>

#include <iostream>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "../test_util.hpp"
#include "same_renders.hpp"
#include "catgs/render_options.hpp"
#include "catgs/stages/split.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

class CudaHeavyListsTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

/// Random Gaussians with a quarter drawn into a narrow cone around the view axis, so that the
/// tiles at the image centre hold lists many times the mean (the heavy ones), as a tower or a
/// horizon does in the kit's garden.
Scene clustered_scene(const std::string& what) {
    test::RandomSceneParams p;
    p.count = 24000;
    p.extent = 2.5;
    Scene s = test::random_scene(test::fresh_seed("heavy lists " + what), p);
    for (std::size_t i = 0; i < s.count() / 4; ++i) {
        s.positions[3 * i] *= 0.04f;
        s.positions[3 * i + 1] *= 0.04f;
    }
    return s;
}

/// The tiles runs_first names among the unsplit lists of the frame read back.
std::vector<std::uint32_t> expected_heavy(const cuda::StageReadback<float>& stages, double factor) {
    std::uint64_t pairs = 0;
    std::uint32_t nonempty = 0;
    for (const TileRange& r : stages.tile_ranges) {
        pairs += r.end - r.begin;
        nonempty += r.end > r.begin;
    }
    std::vector<std::uint32_t> heavy;
    for (std::uint32_t t = 0; t < stages.tile_ranges.size(); ++t) {
        const std::uint64_t size = stages.tile_ranges[t].end - stages.tile_ranges[t].begin;
        if (split_count(size, stages.split_k) == 0 && runs_first(size, pairs, nonempty, factor)) heavy.push_back(t);
    }
    return heavy;
}

TEST_F(CudaHeavyListsTest, TheDeviceListsTheTilesTheRuleNames) {
    const Scene scene = clustered_scene("rule");
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    const Camera camera = test::forward_camera(320, 240, 70.0);
    RenderOptions split_auto, split_64;
    split_auto.catgs.split_auto = true;
    split_64.catgs.split_k = 64;
    const struct {
        std::string name;
        RenderOptions options;
    } configs[] = {{"unsplit", RenderOptions{}}, {"split auto", split_auto}, {"split 64", split_64}};
    for (const auto& c : configs)
        for (const double factor : {kHeavyListFactor, 1.5, 0.0}) {
            const std::string what = c.name + ", factor " + std::to_string(factor);
            cuda::CudaLimits limits;
            limits.heavy_list_factor = factor;
            cuda::CudaRenderer<float> gpu(nullptr, limits);
            gpu.set_scene(device_scene);
            ImageRGB8 image;
            gpu.render(camera, c.options, &image, nullptr);
            const cuda::StageReadback<float> stages = gpu.read_back_stages();
            const std::vector<std::uint32_t> expected = expected_heavy(stages, factor);
            // 300 tiles: fewer than any GPU of the last decade holds at once, so all are listed.
            EXPECT_EQ(stages.heavy_tiles, expected) << what;
            std::cout << "[heavy lists] " << what << ": " << expected.size() << " of " << stages.tile_ranges.size()
                      << " tiles" << std::endl;
            if (factor == 0) {
                EXPECT_TRUE(expected.empty()) << what;
            } else if (c.name == "unsplit") {
                EXPECT_FALSE(expected.empty()) << what << ": the cluster must give the rule tiles to name";
            }
        }
}

/// Alternating views, or a steady glide where the cache is on (its cached frames).
Camera pixels_view(bool glide, int frame) {
    const double x = glide ? 0.01 * frame : 0.3 * (frame % 2);
    return test::forward_camera(333, 250, 70.0, {x, 0.5 * x, 0.0});
}

RenderOptions split_at_64() {
    RenderOptions split;
    split.catgs.split_k = 64;
    return split;
}

/// The cache on, planning from work counts: two renderers plan alike.
RenderOptions cached_by_work() {
    RenderOptions cached = default_pipeline_options();
    cached.catgs.window_cost = WindowCost::work;
    return cached;
}

TEST_F(CudaHeavyListsTest, TheOrderChangesNoPixel) {
    const Scene scene = clustered_scene("pixels");
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    auto view = pixels_view;
    const RenderOptions split = split_at_64(), cached = cached_by_work();
    FrameStats one_pass;
    {
        cuda::CudaRenderer<float> probe;
        probe.set_scene(device_scene);
        ImageRGB8 image;
        one_pass = probe.render(view(false, 0), RenderOptions{}, &image, nullptr);
    }
    const struct {
        std::string name;
        RenderOptions options;
        cuda::RasterLayout layout;
        std::uint64_t max_pairs;
    } configs[] = {
        {"one pixel a thread", RenderOptions{}, cuda::RasterLayout::pixel_per_thread, 0},
        {"two pixels a thread", RenderOptions{}, cuda::RasterLayout::two_pixels_per_thread, 0},
        {"split", split, cuda::RasterLayout::automatic, 0},
        // The cluster piles its pairs into a few tile rows: a budget of a third of the frame's
        // pairs can hold no band around them, three quarters bands most of the views.
        {"bands", RenderOptions{}, cuda::RasterLayout::automatic, one_pass.pairs * 3 / 4},
        {"cached frames", cached, cuda::RasterLayout::automatic, 0},
    };
    for (const auto& c : configs) {
        cuda::CudaLimits row_order{c.max_pairs, c.layout}, heavy_first{c.max_pairs, c.layout};
        row_order.heavy_list_factor = 0;
        heavy_first.heavy_list_factor = 1.5;  // more lists reordered than the default's few
        cuda::CudaRenderer<float> a(nullptr, row_order), b(nullptr, heavy_first);
        a.set_scene(device_scene);
        b.set_scene(device_scene);
        const bool glide = c.options.catgs.cache != CacheMode::off;
        int cached_frames = 0, banded = 0;
        for (const auto& [sa, sb] : test::expect_same_renders(
                 a, b, c.options, [&](int frame) { return view(glide, frame); }, 5, view(false, 1), c.name)) {
            EXPECT_EQ(sa.split_tasks, sb.split_tasks) << c.name;
            banded += sb.bands > 1;
            cached_frames += !sb.key_frame;
        }
        if (glide) {
            EXPECT_GT(cached_frames, 0) << c.name;
        }
        if (c.max_pairs) {
            EXPECT_GT(banded, 0) << c.name;
        }
    }
}

/// An 8-bit image alone: the heavy lists write their pixels to host memory and copy_out puts
/// them in place (CudaLimits::heavy_pixels_to_host); the image must be the one they draw on the
/// device, frame after frame (a tile left out would show the last frame's pixels there).
TEST_F(CudaHeavyListsTest, HeavyPixelsThroughHostMemoryChangeNoPixel) {
    const Scene scene = clustered_scene("to host");
    auto device_scene = std::make_shared<cuda::DeviceScene>(scene);
    auto view = pixels_view;
    const RenderOptions split = split_at_64(), cached = cached_by_work();
    const struct {
        std::string name;
        RenderOptions options;
        cuda::RasterLayout layout;
        bool lists_heavy;  // split at 64, the cluster's long lists are all split: none runs first
    } configs[] = {
        {"one pixel a thread", RenderOptions{}, cuda::RasterLayout::pixel_per_thread, true},
        {"two pixels a thread", RenderOptions{}, cuda::RasterLayout::two_pixels_per_thread, true},
        {"split", split, cuda::RasterLayout::automatic, false},
        {"cached frames", cached, cuda::RasterLayout::automatic, true},
    };
    for (const auto& c : configs) {
        cuda::CudaLimits on_device{0, c.layout}, to_host{0, c.layout};
        on_device.heavy_list_factor = to_host.heavy_list_factor = 1.5;
        on_device.heavy_pixels_to_host = false;
        cuda::CudaRenderer<float> a(nullptr, on_device), b(nullptr, to_host);
        a.set_scene(device_scene);
        b.set_scene(device_scene);
        if (!b.copies_while_drawing()) {
            std::cout << "[heavy lists] no stream memory waits: the heavy lists draw on the device" << std::endl;
        }
        const bool glide = c.options.catgs.cache != CacheMode::off;
        std::size_t listed = 0;
        for (int frame = 0; frame < 6; ++frame) {
            const Camera camera = view(glide, frame);
            ImageRGB8 image_a, image_b;
            a.render(camera, c.options, &image_a, nullptr);
            const FrameStats stats = b.render(camera, c.options, &image_b, nullptr);
            const std::string what = c.name + ", frame " + std::to_string(frame);
            ASSERT_EQ(image_a.rgb, image_b.rgb) << what;
            if (stats.bands == 1) listed += b.read_back_stages().heavy_tiles.size();
        }
        if (c.lists_heavy) {
            EXPECT_GT(listed, 0u) << c.name << ": no heavy list was drawn";
        }
    }
}

}  // namespace
}  // namespace catgs
