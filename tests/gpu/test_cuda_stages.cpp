// The CUDA backend against the CPU reference stage by stage, not only per image: the sorted
// keys and values, the tile ranges, the split task list and the sub-tasks' partial (R, A)
// (CudaRenderer::read_back_stages against CpuRenderer's accessors), on fresh random scenes.
// In double both backends must agree exactly; in float they may differ only inside a boundary
// band measured here. Skips without a CUDA device.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "../test_util.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

constexpr std::size_t kTilePixels = static_cast<std::size_t>(kTileSize) * kTileSize;

// Double: the same double formulas on both sides, apart from nvcc's fused multiply-adds and
// CUDA's exp (within an ulp of glibc's): each blend step differs by a few ulps (1e-16
// relative) and a sub-task blends at most a few thousand Gaussians, so (R, A) agree to about
// 1e-12. 1e-9 leaves a thousandfold margin and still catches any real difference (one blend
// step more or less moves a value by at least alpha >= 1/255).
constexpr double kDoublePartialTolerance = 1e-9;

// Float: the boundary band. The float projections of the two backends differ from the double
// one by rounding: the mean by about 1e-3 px at most for the random scenes below (values up to
// a few thousand pixels, a few ulps each), the 2D covariance by about 1e-4 relative, more for
// near-circular footprints, where the eigenvalue behind bbox3sigma's radius cancels
// (sqrt(mid^2 - det)). A tile-Gaussian pair may be on one side only if moving the double
// footprint by kBandShiftPx or scaling it by 1 +- kBandScale flips the pair: that footprint
// lies within the band of the tile's edge. 10x and more beyond the rounding, far inside a
// pixel.
constexpr double kBandShiftPx = 1e-2;
constexpr double kBandScale = 1e-3;
// Float partials of identical lists: the per-image bar of the backends (test_cuda_renderer:
// 50 dB, 2 levels): a Gaussian whose alpha is within rounding of 1/255 at a pixel is blended
// on one side only.
constexpr double kFloatPartialMaxAbs = 2.0 / 255.0;
constexpr double kFloatPartialMinPsnr = 50.0;

class CudaStagesTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

struct Case {
    std::string name;
    RenderOptions options;
};

/// Every culling mode with lists per tile, plain and split (a fixed k that splits nearly every
/// tile, and the automatic k; opacity-aware k = 8 also with a tail threshold of its own); exact
/// culling (one shared list) unsplit.
std::vector<Case> cases() {
    std::vector<Case> out;
    for (Culling culling : {Culling::opacity_aware, Culling::bbox3sigma}) {
        for (int split = 0; split < 3; ++split) {
            Case c;
            c.options.culling = culling;
            c.options.background = {0.1f, 0.25f, 0.4f};
            c.name = culling_name(culling);
            if (split == 1) {
                c.options.catgs.split_k = 8;
                c.name += " split8";
            } else if (split == 2) {
                c.options.catgs.split_auto = true;
                c.name += " split-auto";
            }
            out.push_back(c);
            if (culling == Culling::opacity_aware && split == 1) {
                // Later sub-tasks stopping at their own threshold: the rasterizer's other instance.
                c.options.catgs.split_tail_transmittance = 1e-2;
                c.name += " tail1e-2";
                out.push_back(c);
            }
        }
    }
    Case exact;
    exact.options.culling = Culling::exact;
    exact.name = "exact";
    out.push_back(exact);
    return out;
}

/// A random scene on the host and on the device.
struct TestScene {
    Scene host;
    std::shared_ptr<cuda::DeviceScene> device;
};

/// Dense enough for lists of a few hundred Gaussians (k = 8 splits nearly every tile; the
/// automatic k, four times the mean length, rarely splits a uniform scene but is compared).
/// Exact culling evaluates every Gaussian at every pixel on the CPU: it gets a tenth of them.
TestScene stage_scene(const std::string& what, Culling culling) {
    test::RandomSceneParams p;
    p.count = culling == Culling::exact ? 2000 : 20000;
    p.extent = 2.5;
    TestScene s;
    s.host = test::random_scene(test::fresh_seed("cuda stages " + what), p);
    s.device = std::make_shared<cuda::DeviceScene>(s.host);
    return s;
}

template <typename T>
struct Both {
    CpuRenderer<T> cpu;
    cuda::CudaRenderer<T> gpu;
    cuda::StageReadback<T> stages;
    FrameStats cpu_stats, gpu_stats;

    void render(const Scene& scene, const Camera& camera, const RenderOptions& options) {
        ImageF image;
        cpu_stats = cpu.render(scene, camera, options, image);
        ImageRGB8 gpu_image;
        gpu_stats = gpu.render(camera, options, &gpu_image, nullptr);
        stages = gpu.read_back_stages();
    }
};

template <typename V>
std::size_t first_difference(const std::vector<V>& a, const std::vector<V>& b) {
    const std::size_t n = std::min(a.size(), b.size());
    for (std::size_t i = 0; i < n; ++i)
        if (!(a[i] == b[i])) return i;
    return a.size() == b.size() ? std::string::npos : n;
}

bool same_range(const TileRange& a, const TileRange& b) {
    return a.begin == b.begin && a.end == b.end;
}
bool same_task(const TileTask& a, const TileTask& b) {
    return a.tile == b.tile && a.index == b.index;
}

/// The pixels of tile `tile` inside the image, as indices into a tile's partial slot.
std::vector<std::size_t> pixels_in_image(const View<double>& view, std::uint32_t tile) {
    std::vector<std::size_t> out;
    const int x0 = static_cast<int>(tile % view.tiles_x) * kTileSize,
              y0 = static_cast<int>(tile / view.tiles_x) * kTileSize;
    for (int y = y0; y < std::min(y0 + kTileSize, view.height); ++y)
        for (int x = x0; x < std::min(x0 + kTileSize, view.width); ++x)
            out.push_back(static_cast<std::size_t>((y - y0) * kTileSize + (x - x0)));
    return out;
}

// --- Double: exact ------------------------------------------------------------------------

void expect_identical_stages(const CpuRenderer<double>& cpu, const cuda::StageReadback<double>& gpu,
                             const View<double>& view, const std::string& what) {
    std::size_t d = first_difference(gpu.sorted_keys, cpu.sorted_keys());
    EXPECT_EQ(d, std::string::npos) << what << ": sorted keys differ first at " << d << " of "
                                    << cpu.sorted_keys().size() << " (gpu " << gpu.sorted_keys.size() << ")";
    d = first_difference(gpu.sorted_values, cpu.sorted_values());
    EXPECT_EQ(d, std::string::npos) << what << ": sorted values differ first at " << d;
    ASSERT_EQ(gpu.tile_ranges.size(), cpu.tile_ranges().size()) << what;
    for (std::size_t t = 0; t < gpu.tile_ranges.size(); ++t)
        ASSERT_TRUE(same_range(gpu.tile_ranges[t], cpu.tile_ranges()[t]))
            << what << ": tile " << t << " range gpu [" << gpu.tile_ranges[t].begin << ", " << gpu.tile_ranges[t].end
            << ") cpu [" << cpu.tile_ranges()[t].begin << ", " << cpu.tile_ranges()[t].end << ")";
    ASSERT_EQ(gpu.tasks.size(), cpu.tasks().size()) << what;
    for (std::size_t i = 0; i < gpu.tasks.size(); ++i)
        ASSERT_TRUE(same_task(gpu.tasks[i], cpu.tasks()[i])) << what << ": task " << i;
    double worst = 0;
    if (gpu.tasks.size() > gpu.tile_ranges.size()) {  // split: every sub-task of every split tile
        for (std::uint32_t tile = 0; tile < gpu.tile_ranges.size(); ++tile) {
            const TileRange& r = gpu.tile_ranges[tile];
            const std::uint32_t splits = split_count(r.end - r.begin, gpu.split_k);
            for (std::uint32_t index = 0; splits > 0 && index <= splits; ++index) {
                const Partial<double>* g = gpu.partial(tile, index);
                const Partial<double>* c = cpu.partial(tile, index);
                ASSERT_TRUE(g && c) << what << ": tile " << tile << " sub-task " << index;
                for (std::size_t px : pixels_in_image(view, tile))
                    worst =
                        std::max({worst, std::abs(g[px].colour.x - c[px].colour.x),
                                  std::abs(g[px].colour.y - c[px].colour.y), std::abs(g[px].colour.z - c[px].colour.z),
                                  std::abs(g[px].transmittance - c[px].transmittance)});
            }
        }
    }
    std::cout << "[cuda stages] " << what << ": " << cpu.sorted_keys().size() << " pairs, " << gpu.tasks.size()
              << " tasks, partials within " << worst << std::endl;
    EXPECT_LE(worst, kDoublePartialTolerance) << what;
}

TEST_F(CudaStagesTest, DoubleStagesEqualTheCpuStages) {
    const Camera camera = test::forward_camera(333, 197, 75.0);
    const TestScene lists = stage_scene("double", Culling::opacity_aware);
    const TestScene exact = stage_scene("double exact", Culling::exact);
    for (const Case& c : cases())
        for (const cuda::RasterLayout layout :
             {cuda::RasterLayout::pixel_per_thread, cuda::RasterLayout::two_pixels_per_thread}) {
            const TestScene& scene = c.options.culling == Culling::exact ? exact : lists;
            const View<double> view = make_view<double>(camera, scene.host.origin);
            const std::string what = "double " + c.name + " layout " + std::to_string(static_cast<int>(layout));
            Both<double> both;
            cuda::CudaLimits limits{0, layout};
            // The one-pixel runs emit every Gaussian's pairs by its warp; the two-pixel runs as shipped.
            if (layout == cuda::RasterLayout::pixel_per_thread) limits.keys_thread_pairs = 0;
            both.gpu.set_limits(limits);
            both.gpu.set_scene(scene.device);
            both.render(scene.host, camera, c.options);
            expect_identical_stages(both.cpu, both.stages, view, what);
            EXPECT_EQ(both.gpu_stats.pairs, both.cpu_stats.pairs) << what;
            EXPECT_EQ(both.gpu_stats.split_k, both.cpu_stats.split_k) << what;
            EXPECT_EQ(both.gpu_stats.split_tasks, both.cpu_stats.split_tasks) << what;
            EXPECT_EQ(both.gpu_stats.longest_list, both.cpu_stats.longest_list) << what;
            EXPECT_GT(both.gpu_stats.longest_list, 0u) << what;
        }
}

// Footprints of hundreds of tiles and more tile rows than a warp has lanes (the regime where keys
// hands a Gaussian's emission to its warp, a tile row a lane: kKeysThreadPairs): the same pairs in
// the same order as the CPU's, as shipped and with every Gaussian emitted by its warp.
TEST_F(CudaStagesTest, DoubleStagesEqualTheCpuStagesOnLargeFootprints) {
    const Camera camera = test::forward_camera(360, 1100, 75.0);
    test::RandomSceneParams p;
    p.count = 3000;
    p.extent = 2.5;
    p.log_scale_min = -2.5;
    p.log_scale_max = 0.7;  // about 1,800 footprints of more than 32 tiles, 50-70 of more than 32 rows
    const Scene host = test::random_scene(test::fresh_seed("cuda stages large footprints"), p);
    const auto device = std::make_shared<cuda::DeviceScene>(host);
    const View<double> view = make_view<double>(camera, host.origin);
    for (const Case& c : cases()) {
        if (c.options.culling == Culling::exact) continue;  // one shared list: nothing per footprint
        for (const std::uint64_t thread_pairs : {cuda::kKeysThreadPairs, std::uint64_t{0}}) {
            Both<double> both;
            cuda::CudaLimits limits;
            limits.keys_thread_pairs = thread_pairs;  // 0: every Gaussian's pairs by its warp
            both.gpu.set_limits(limits);
            both.gpu.set_scene(device);
            both.render(host, camera, c.options);
            const std::string what =
                "double large footprints " + c.name + " keys_thread_pairs " + std::to_string(thread_pairs);
            expect_identical_stages(both.cpu, both.stages, view, what);
            std::map<std::uint32_t, std::set<std::uint32_t>> rows_of;  // Gaussian -> its tile rows
            std::map<std::uint32_t, std::size_t> tiles_of;
            for (std::size_t i = 0; i < both.cpu.sorted_keys().size(); ++i) {
                const std::uint32_t g = both.cpu.sorted_values()[i];
                rows_of[g].insert(key_tile(both.cpu.sorted_keys()[i]) / static_cast<std::uint32_t>(view.tiles_x));
                ++tiles_of[g];
            }
            std::size_t large = 0, tall = 0;
            for (const auto& [g, n] : tiles_of) large += n > 32;
            for (const auto& [g, rows] : rows_of) tall += rows.size() > 32;
            EXPECT_GT(large, 500u) << what << ": footprints of more than 32 tiles";
            EXPECT_GT(tall, 10u) << what << ": footprints of more than 32 tile rows";
        }
    }
}

// The pairs' tile ids are 16 bits wide up to 65535 tiles (whose parked id is 0xffff) and 32
// bits from 65536 on (tile_key.cuh): at both sides of that edge, a plain frame, a split one and
// a cached run that re-keys and parks pairs must give the CPU's stages. 4080x4112 is 255 x 257 =
// 65535 tiles; 4096x4096 is 65536. The scene is sparse, so that the CPU's double reference of
// 17M pixels stays quick.
TEST_F(CudaStagesTest, DoubleStagesEqualTheCpuStagesAtTheTileKeyWidthEdge) {
    test::RandomSceneParams p;
    p.count = 3000;
    p.extent = 2.5;
    const Scene host = test::random_scene(test::fresh_seed("cuda stages tile key width"), p);
    const auto device = std::make_shared<cuda::DeviceScene>(host);
    struct Grid {
        int width, height, key_bytes;
    };
    for (const Grid grid : {Grid{4080, 4112, 2}, Grid{4096, 4096, 4}}) {
        const std::string size = std::to_string(grid.width) + "x" + std::to_string(grid.height);
        for (int split_k : {0, 8}) {
            RenderOptions options;
            options.catgs.split_k = static_cast<std::uint32_t>(split_k);
            const Camera camera = test::forward_camera(grid.width, grid.height, 75.0);
            Both<double> both;
            both.gpu.set_scene(device);
            both.render(host, camera, options);
            const std::string what = "tile key width " + size + " split " + std::to_string(split_k);
            EXPECT_EQ(both.stages.tile_key_bytes, grid.key_bytes) << what;
            expect_identical_stages(both.cpu, both.stages, make_view<double>(camera, host.origin), what);
        }
        RenderOptions cached;
        cached.catgs.cache = CacheMode::speculative;
        cached.catgs.resort_cached = true;  // re-key every cached frame: the parked ids
        Both<double> both;
        both.gpu.set_scene(device);
        int resorted = 0;
        for (int frame = 0; frame < 4; ++frame) {
            const Camera camera =
                test::forward_camera(grid.width, grid.height, 75.0, {0.002 * frame, 0.0, 0.004 * frame});
            both.render(host, camera, cached);
            if (both.gpu_stats.key_frame != both.cpu_stats.key_frame || both.gpu_stats.window != both.cpu_stats.window)
                break;
            const std::string what = "tile key width " + size + " cached frame " + std::to_string(frame);
            EXPECT_EQ(both.stages.tile_key_bytes, grid.key_bytes) << what;
            expect_identical_stages(both.cpu, both.stages, make_view<double>(camera, host.origin), what);
            resorted += !both.gpu_stats.key_frame && !both.gpu_stats.order_reused;
        }
        EXPECT_GE(resorted, 1) << size << ": no cached frame re-keyed its pairs";
    }
}

// The speculative cache: key frames with a window of poses (union footprints), and cached
// frames that re-key, park and re-sort the key frame's pairs. The run stops at the first frame
// the two planners plan differently (their key-frame summaries are reduced in different
// precisions).
TEST_F(CudaStagesTest, DoubleCachedFramesEqualTheCpuStages) {
    const TestScene scene = stage_scene("cached", Culling::opacity_aware);
    RenderOptions options;
    options.catgs.cache = CacheMode::speculative;
    options.catgs.split_k = 16;
    Both<double> both;
    both.gpu.set_scene(scene.device);
    int compared = 0, cached = 0;
    for (int frame = 0; frame < 8; ++frame) {
        const Camera camera = test::forward_camera(320, 180, 70.0, {0.01 * frame, 0.0, 0.02 * frame});
        both.render(scene.host, camera, options);
        // From a different plan on, the two may hold lists of different key frames.
        if (both.gpu_stats.key_frame != both.cpu_stats.key_frame || both.gpu_stats.window != both.cpu_stats.window ||
            both.gpu_stats.order_reused != both.cpu_stats.order_reused)
            break;
        expect_identical_stages(
            both.cpu, both.stages, make_view<double>(camera, scene.host.origin),
            "cached run frame " + std::to_string(frame) + (both.gpu_stats.key_frame ? " (key)" : ""));
        ++compared;
        cached += !both.gpu_stats.key_frame;
    }
    EXPECT_GE(compared, 1);
    std::cout << "[cuda stages] cached run: " << compared << " frames compared, " << cached << " of them cached"
              << std::endl;
}

// --- Float: within the boundary band ------------------------------------------------------

/// Is tile `tile` in the footprint of g under every perturbation of the band, or in none?
/// False: the pair is within the band of the tile's edge.
bool outside_band(const Projected<double>& g, Culling culling, const View<double>& view, std::uint32_t tile) {
    const bool base = touches_tile(g, culling, view, tile);
    const double d = kBandShiftPx;
    for (const auto& [dx, dy] :
         std::vector<std::pair<double, double>>{{d, 0}, {-d, 0}, {0, d}, {0, -d}, {d, d}, {d, -d}, {-d, d}, {-d, -d}}) {
        Projected<double> p = g;
        p.mean.x += dx;
        p.mean.y += dy;
        if (touches_tile(p, culling, view, tile) != base) return false;
    }
    for (double s : {1.0 + kBandScale, 1.0 - kBandScale}) {
        Projected<double> p = g;
        p.cov = {g.cov.x * s, g.cov.y * s, g.cov.z * s};
        p.conic = {g.conic.x / s, g.conic.y / s, g.conic.z / s};
        if (touches_tile(p, culling, view, tile) != base) return false;
    }
    return true;
}

std::uint32_t depth_bits(std::uint64_t key) {
    return static_cast<std::uint32_t>(key);
}

/// (tile, Gaussian) -> key of every pair.
std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint64_t> pair_map(const std::vector<std::uint64_t>& keys,
                                                                          const std::vector<std::uint32_t>& values) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint64_t> out;
    for (std::size_t i = 0; i < keys.size(); ++i) out[{key_tile(keys[i]), values[i]}] = keys[i];
    return out;
}

struct BandReport {
    std::size_t pairs = 0, gpu_only = 0, cpu_only = 0, outside = 0, depth_ulps = 0;
};

/// Keys: the same pairs but for the band, with the same depth bits (both backends compute the
/// key depth in double and round it once; one ulp apart only when the double lands on a float
/// rounding boundary, about 1e-9 of the time); the pairs both hold in the same order.
BandReport check_keys(const CpuRenderer<float>& cpu, const cuda::StageReadback<float>& gpu,
                      const CpuRenderer<double>& reference, Culling culling, const View<double>& view,
                      const std::string& what) {
    BandReport r;
    const auto g = pair_map(gpu.sorted_keys, gpu.sorted_values);
    const auto c = pair_map(cpu.sorted_keys(), cpu.sorted_values());
    r.pairs = c.size();
    auto in_band = [&](std::pair<std::uint32_t, std::uint32_t> pair) {
        return !outside_band(reference.projected()[pair.second], culling, view, pair.first);
    };
    std::set<std::pair<std::uint32_t, std::uint32_t>> common;
    for (const auto& [pair, key] : g) {
        const auto it = c.find(pair);
        if (it == c.end()) {
            ++r.gpu_only;
            if (!in_band(pair)) {
                ++r.outside;
                ADD_FAILURE() << what << ": pair (tile " << pair.first << ", Gaussian " << pair.second
                              << ") only on the GPU, outside the band";
            }
            continue;
        }
        common.insert(pair);
        const std::uint32_t a = depth_bits(key), b = depth_bits(it->second);
        if (a != b) {
            ++r.depth_ulps;
            EXPECT_LE(a > b ? a - b : b - a, 1u)
                << what << ": depth of (tile " << pair.first << ", Gaussian " << pair.second << ")";
        }
    }
    for (const auto& [pair, key] : c) {
        if (g.count(pair)) continue;
        ++r.cpu_only;
        if (!in_band(pair)) {
            ++r.outside;
            ADD_FAILURE() << what << ": pair (tile " << pair.first << ", Gaussian " << pair.second
                          << ") only on the CPU, outside the band";
        }
    }
    // The order of the common pairs: the sorted lists restricted to them are the same.
    auto restricted = [&](const std::vector<std::uint64_t>& keys, const std::vector<std::uint32_t>& values) {
        std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
        for (std::size_t i = 0; i < keys.size(); ++i)
            if (common.count({key_tile(keys[i]), values[i]})) out.push_back({key_tile(keys[i]), values[i]});
        return out;
    };
    const std::size_t d = first_difference(restricted(gpu.sorted_keys, gpu.sorted_values),
                                           restricted(cpu.sorted_keys(), cpu.sorted_values()));
    EXPECT_EQ(d, std::string::npos) << what << ": the common pairs are ordered differently from position " << d;
    return r;
}

/// Ranges: each the span of its tile in the GPU's own sorted keys, as long as the CPU's but for
/// the band pairs of the tile. Returns the tiles whose lists are the same on both backends.
std::vector<bool> check_ranges(const CpuRenderer<float>& cpu, const cuda::StageReadback<float>& gpu, Culling culling,
                               const std::string& what) {
    const std::size_t tiles = cpu.tile_ranges().size();
    std::vector<bool> same(tiles, false);
    EXPECT_EQ(gpu.tile_ranges.size(), tiles) << what;
    if (gpu.tile_ranges.size() != tiles) return same;
    std::vector<TileRange> own(tiles);
    for (std::size_t i = 0; i < gpu.sorted_keys.size(); ++i) {
        const std::uint32_t t = key_tile(gpu.sorted_keys[i]);
        if (t >= tiles) continue;
        if (own[t].end == 0) own[t].begin = i;
        own[t].end = i + 1;
    }
    if (culling == Culling::exact) std::fill(own.begin(), own.end(), TileRange{0, gpu.sorted_keys.size()});
    for (std::size_t t = 0; t < tiles; ++t) {
        EXPECT_TRUE(same_range(gpu.tile_ranges[t], own[t])) << what << ": tile " << t << " range";
        const TileRange& g = gpu.tile_ranges[t];
        const TileRange& c = cpu.tile_ranges()[t];
        same[t] = g.end - g.begin == c.end - c.begin &&
                  std::equal(gpu.sorted_values.begin() + static_cast<std::ptrdiff_t>(g.begin),
                             gpu.sorted_values.begin() + static_cast<std::ptrdiff_t>(g.end),
                             cpu.sorted_values().begin() + static_cast<std::ptrdiff_t>(c.begin));
    }
    return same;
}

/// Tasks and partials of the tiles whose lists are the same: the same sub-tasks, and partial
/// (R, A) within the per-image bar.
void check_tasks_and_partials(const CpuRenderer<float>& cpu, std::uint32_t cpu_k, const cuda::StageReadback<float>& gpu,
                              const std::vector<bool>& same_list, const View<double>& view, const std::string& what) {
    std::map<std::uint32_t, std::vector<std::uint32_t>> g, c;
    for (const TileTask& t : gpu.tasks) g[t.tile].push_back(t.index);
    for (const TileTask& t : cpu.tasks()) c[t.tile].push_back(t.index);
    // The automatic k follows the mean list length, which the band pairs may move by one.
    const bool same_k = cpu_k == gpu.split_k;
    if (!same_k) {
        EXPECT_LE(cpu_k > gpu.split_k ? cpu_k - gpu.split_k : gpu.split_k - cpu_k, 1u) << what << ": split k";
    }
    double worst = 0, square_sum = 0;
    std::size_t values = 0, split_tiles = 0;
    for (std::uint32_t tile = 0; tile < same_list.size(); ++tile) {
        if (!same_list[tile] || !same_k) continue;
        EXPECT_EQ(g[tile], c[tile]) << what << ": tasks of tile " << tile;
        if (g[tile].size() < 2 || g[tile] != c[tile]) continue;
        ++split_tiles;
        for (std::uint32_t index : g[tile]) {
            const Partial<float>* a = gpu.partial(tile, index);
            const Partial<float>* b = cpu.partial(tile, index);
            ASSERT_TRUE(a && b) << what << ": tile " << tile << " sub-task " << index;
            for (std::size_t px : pixels_in_image(view, tile)) {
                for (double d : {static_cast<double>(a[px].colour.x) - b[px].colour.x,
                                 static_cast<double>(a[px].colour.y) - b[px].colour.y,
                                 static_cast<double>(a[px].colour.z) - b[px].colour.z,
                                 static_cast<double>(a[px].transmittance) - b[px].transmittance}) {
                    worst = std::max(worst, std::abs(d));
                    square_sum += d * d;
                    ++values;
                }
            }
        }
    }
    if (values == 0) return;
    const double rms = std::sqrt(square_sum / static_cast<double>(values));
    const double psnr = rms > 0 ? -20.0 * std::log10(rms) : 999.0;
    std::cout << "[cuda stages] " << what << ": partials of " << split_tiles << " split tiles, max " << worst
              << ", psnr " << psnr << " dB" << std::endl;
    EXPECT_LE(worst, kFloatPartialMaxAbs) << what;
    EXPECT_GE(psnr, kFloatPartialMinPsnr) << what;
}

TEST_F(CudaStagesTest, FloatStagesDifferOnlyInTheBoundaryBand) {
    // 273 and 375 tiles, and 512: ranges' last thread block ends exactly at the grid's end.
    const int sizes[][2] = {{333, 197}, {397, 229}, {512, 256}};
    for (int trial = 0; trial < 3; ++trial) {
        const Camera camera = test::forward_camera(sizes[trial][0], sizes[trial][1], 75.0);
        const TestScene lists = stage_scene("float " + std::to_string(trial), Culling::opacity_aware);
        const TestScene exact = stage_scene("float exact " + std::to_string(trial), Culling::exact);
        for (const Case& c : cases()) {
            const TestScene& scene = c.options.culling == Culling::exact ? exact : lists;
            const View<double> view = make_view<double>(camera, scene.host.origin);
            const std::string what = "float " + c.name + " trial " + std::to_string(trial);
            Both<float> both;
            both.gpu.set_scene(scene.device);
            both.render(scene.host, camera, c.options);
            CpuRenderer<double> reference;
            ImageF ignored;
            reference.render(scene.host, camera, c.options, ignored);
            const BandReport r = check_keys(both.cpu, both.stages, reference, c.options.culling, view, what);
            std::cout << "[cuda stages] " << what << ": " << r.pairs << " pairs, " << r.gpu_only << " only on the GPU, "
                      << r.cpu_only << " only on the CPU (band " << kBandShiftPx << " px, " << kBandScale
                      << " relative), " << r.outside << " outside the band, " << r.depth_ulps
                      << " depth keys an ulp apart" << std::endl;
            EXPECT_EQ(r.outside, 0u) << what;
            // The band is a boundary effect: a small share of the pairs at most.
            EXPECT_LE(r.gpu_only + r.cpu_only, r.pairs / 100 + 10) << what;
            const std::vector<bool> same_list = check_ranges(both.cpu, both.stages, c.options.culling, what);
            check_tasks_and_partials(both.cpu, both.cpu_stats.split_k, both.stages, same_list, view, what);
        }
    }
}

TEST_F(CudaStagesTest, ReadBackNeedsOneWholeFrame) {
    cuda::CudaRenderer<float> gpu;
    EXPECT_THROW(gpu.read_back_stages(), Error);
    test::RandomSceneParams p;
    p.count = 5000;
    const Scene scene = test::random_scene(test::fresh_seed("cuda stages bands"), p);
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    const Camera camera = test::forward_camera(256, 160, 70.0);
    const FrameStats whole = gpu.render(camera, RenderOptions{}, nullptr, nullptr);
    EXPECT_EQ(gpu.read_back_stages().sorted_keys.size(), whole.pairs);
    gpu.set_limits(cuda::CudaLimits{whole.pairs / 3});
    const FrameStats banded = gpu.render(camera, RenderOptions{}, nullptr, nullptr);
    ASSERT_GT(banded.bands, 1);
    EXPECT_THROW(gpu.read_back_stages(), Error);
}

}  // namespace
}  // namespace catgs
