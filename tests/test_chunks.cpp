// Chunk-level culling: the partition at load and the conservative chunk test. Culling chunks
// must change nothing: the same sorted tile lists and the same image as preprocessing every
// Gaussian, on fresh random scenes that surround the camera (so that most chunks are off
// screen), for every culling mode that culls, with and without the speculative cache.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/stages/chunks.hpp"
#include "catgs/stages/view.hpp"
#include "chunk_scenes.hpp"
#include "test_util.hpp"

namespace catgs {
namespace {

using namespace test::chunks;

struct Rendered {
    ImageF image;
    std::vector<std::uint64_t> keys;
    std::vector<std::uint32_t> values;
    FrameStats stats;
};

Rendered render(CpuRenderer<float>& renderer, const Scene& scene, const Camera& cam, RenderOptions o) {
    Rendered r;
    r.stats = renderer.render(scene, cam, o, r.image);
    r.keys = renderer.sorted_keys();
    r.values = renderer.sorted_values();
    return r;
}

TEST(ChunkPartition, ReordersWithoutLosingAGaussianAndBoundsEveryMember) {
    const std::uint64_t seed = test::fresh_seed("chunk partition");
    test::RandomSceneParams p;
    p.count = 20000;
    p.sh_degree = 2;
    const Scene original = test::random_scene(seed, p);
    Scene s = original;
    partition_into_chunks(s);
    ASSERT_NO_THROW(s.check_consistent("partitioned"));
    ASSERT_EQ(s.count(), original.count());
    ASSERT_GE(s.chunks.size(), (original.count() + kChunkGaussians - 1) / kChunkGaussians);
    // The same Gaussians, each record intact: compare as sorted tuples of all fields.
    auto records = [](const Scene& sc) {
        std::vector<std::vector<float>> out;
        const std::size_t stride = sc.sh_floats_per_gaussian();
        for (std::size_t i = 0; i < sc.count(); ++i) {
            std::vector<float> r(&sc.positions[3 * i], &sc.positions[3 * i] + 3);
            r.insert(r.end(), &sc.scales[3 * i], &sc.scales[3 * i] + 3);
            r.insert(r.end(), &sc.rotations[4 * i], &sc.rotations[4 * i] + 4);
            r.push_back(sc.opacities[i]);
            r.insert(r.end(), &sc.sh[stride * i], &sc.sh[stride * i] + stride);
            out.push_back(std::move(r));
        }
        std::sort(out.begin(), out.end());
        return out;
    };
    EXPECT_EQ(records(s), records(original));
    double chunk_volume = 0;
    for (const Chunk& c : s.chunks) {
        for (std::uint32_t i = c.begin; i < c.end; ++i)
            for (int a = 0; a < 3; ++a) {
                ASSERT_GE(s.positions[3 * i + a], c.lo[a]);
                ASSERT_LE(s.positions[3 * i + a], c.hi[a]);
                ASSERT_LE(kChunkSigmas * s.scales[3 * i + a], c.radius * (1 + 1e-6));
            }
        chunk_volume += static_cast<double>(c.hi[0] - c.lo[0]) * (c.hi[1] - c.lo[1]) * (c.hi[2] - c.lo[2]);
    }
    // Chunks along the octree are compact: a chunk's box stays inside one octree cell, so the
    // boxes cover the scene's box a few times at most (measured: 1.7 for 24 chunks), where
    // the file order gives every chunk nearly the whole box (C times it).
    const double box =
        (s.bounds.max[0] - s.bounds.min[0]) * (s.bounds.max[1] - s.bounds.min[1]) * (s.bounds.max[2] - s.bounds.min[2]);
    std::cout << "[chunks] " << s.chunks.size() << " chunks, " << s.count() / static_cast<double>(s.chunks.size())
              << " Gaussians each on average; their boxes sum to " << chunk_volume / box << " of the scene box"
              << std::endl;
    EXPECT_LT(chunk_volume, 3.0 * box);
}

/// The volume of a chunk's box of means.
double chunk_box_volume(const Chunk& c) {
    return static_cast<double>(c.hi[0] - c.lo[0]) * (c.hi[1] - c.lo[1]) * (c.hi[2] - c.lo[2]);
}

/// A few far strays stretch the scene's box: 10^5..10^7 m out, the bulk (a 8 x 8 x 9 m box)
/// fits one cell of the 1024^3 grid over that box. Its chunks must still follow the bulk's own
/// octree: their boxes cover the bulk's box a few times at most, as without strays (the first
/// partition cut the cell in file order, every chunk nearly the whole bulk: ~20x).
TEST(ChunkPartition, FarStraysLeaveTheBulkChunksCompact) {
    const std::uint64_t seed = test::fresh_seed("chunk partition strays");
    test::RandomSceneParams p;
    p.count = 20000;
    p.sh_degree = 0;
    Scene s = test::random_scene(seed, p);
    const float strays[][3] = {{1e6f, 0, 5}, {-2e5f, 3e7f, 5}, {0, 0, -1e5f}};
    for (std::size_t k = 0; k < std::size(strays); ++k)
        for (int a = 0; a < 3; ++a) s.positions[3 * (100 * k + 7) + a] = strays[k][a];
    auto is_stray = [&](std::uint32_t i) {
        return std::abs(s.positions[3 * i]) > 100 || std::abs(s.positions[3 * i + 1]) > 100 ||
               std::abs(s.positions[3 * i + 2]) > 100;
    };
    partition_into_chunks(s);
    ASSERT_NO_THROW(s.check_consistent("partitioned"));
    const double bulk_box = 2 * p.extent * 2 * p.extent * (p.depth_max - p.depth_min);
    double bulk_chunk_volume = 0;
    int stray_chunks = 0, strays_found = 0;
    for (const Chunk& c : s.chunks) {
        int in_chunk = 0;
        for (std::uint32_t i = c.begin; i < c.end; ++i) in_chunk += is_stray(i) ? 1 : 0;
        strays_found += in_chunk;
        if (in_chunk > 0)
            ++stray_chunks;
        else
            bulk_chunk_volume += chunk_box_volume(c);
    }
    EXPECT_EQ(strays_found, 3);
    EXPECT_LE(stray_chunks, 3);
    std::cout << "[chunks] " << s.chunks.size() << " chunks; the bulk's boxes sum to " << bulk_chunk_volume / bulk_box
              << " of its box (CATGS_TEST_SEED=" << seed << ")" << std::endl;
    EXPECT_LT(bulk_chunk_volume, 3.0 * bulk_box) << "CATGS_TEST_SEED=" << seed;
}

TEST(ChunkPartition, NonFinitePositionsGoLastInAChunkThatIsNeverCulled) {
    Scene s = test::random_scene(7, {.count = 3000});
    s.positions[3 * 10] = std::numeric_limits<float>::quiet_NaN();
    s.scales[3 * 20 + 1] = std::numeric_limits<float>::infinity();
    partition_into_chunks(s);
    EXPECT_TRUE(std::isnan(s.positions[3 * (s.count() - 1)]));
    int unbounded = 0;
    for (const Chunk& c : s.chunks) unbounded += std::isinf(c.radius) ? 1 : 0;
    EXPECT_EQ(unbounded, 2);
    const View<double> v = make_view<double>(test::forward_camera(64, 64, 60), s.origin);
    for (const Chunk& c : s.chunks)
        if (std::isinf(c.radius)) {
            EXPECT_TRUE(chunk_may_be_visible(c, v, 0.0, 0.0));
        }
}

TEST(ChunkPartition, InconsistentChunksAreRefusedWithTheReason) {
    Scene s = test::random_scene(3, {.count = 2500});
    s.chunks = {Chunk{.begin = 0, .end = 1024}, Chunk{.begin = 1024, .end = 2048}, Chunk{.begin = 2048, .end = 2500}};
    s.update_chunk_bounds();
    ASSERT_NO_THROW(s.check_consistent("scene"));
    Scene gap = s;
    gap.chunks[1].begin += 1;
    try {
        gap.check_consistent("scene");
        FAIL() << "a gap between chunks was accepted";
    } catch (const Error& e) {
        EXPECT_STREQ(
            e.what(),
            "scene: chunk 1 covers [1025, 2048), expected to start at 1024 with 1..1024 of the 2500 Gaussians");
    }
    Scene short_cover = s;
    short_cover.chunks.pop_back();
    try {
        short_cover.check_consistent("scene");
        FAIL() << "chunks that miss Gaussians were accepted";
    } catch (const Error& e) {
        EXPECT_STREQ(e.what(), "scene: chunks cover 2048 of the 2500 Gaussians");
    }
    CpuRenderer<float> renderer(1);
    ImageF out;
    EXPECT_THROW(renderer.render(short_cover, test::forward_camera(16, 16, 60), RenderOptions{}, out), Error);
}

TEST(ChunkPartition, LoadScenePartitionsUnlessAskedNotTo) {
    const Scene chunked = load_scene("builtin:city?gaussians=20000&seed=3");
    EXPECT_GE(chunked.chunks.size(), (chunked.count() + kChunkGaussians - 1) / kChunkGaussians);
    EXPECT_NO_THROW(chunked.check_consistent("city"));
    LoadOptions keep;
    keep.chunks = false;
    const Scene plain = load_scene("builtin:city?gaussians=20000&seed=3", keep);
    EXPECT_TRUE(plain.chunks.empty());
    EXPECT_EQ(plain.count(), chunked.count());
    EXPECT_NE(plain.positions, chunked.positions);  // reordered
}

// The property: over random cameras, culling chunks leaves the sorted lists and the image
// exactly as they are, while skipping a good share of the chunks.
TEST(ChunkCulling, SkippedChunksHoldNoPairOfAnyTile) {
    const std::uint64_t seed = test::fresh_seed("chunk culling single frame");
    const Scene octree = surrounding_scene(seed), single = single_gaussian_chunks(surrounding_scene(seed, 8000));
    std::mt19937_64 rng(seed);
    std::uint64_t culled = 0, total = 0;
    for (int k = 0; k < 48; ++k) {
        const Scene& scene = k % 2 ? single : octree;
        // Every third camera is tiny: its partial edge tiles reach past the clamp region.
        const Camera cam = k % 3 == 2 ? random_camera(rng, 21, 13) : random_camera(rng);
        for (Culling mode : {Culling::opacity_aware, Culling::bbox3sigma}) {
            RenderOptions on;
            on.culling = mode;
            RenderOptions off = on;
            off.chunk_culling = false;
            CpuRenderer<float> a(2), b(2);
            const Rendered with = render(a, scene, cam, on), without = render(b, scene, cam, off);
            ASSERT_EQ(with.keys, without.keys)
                << culling_name(mode) << " camera " << k << " (CATGS_TEST_SEED=" << seed << ")";
            ASSERT_EQ(with.values, without.values) << culling_name(mode) << " camera " << k;
            ASSERT_EQ(with.image.rgb, without.image.rgb) << culling_name(mode) << " camera " << k;
            EXPECT_EQ(without.stats.chunks_culled, 0u);
            EXPECT_EQ(with.stats.chunks, scene.chunks.size());
            culled += with.stats.chunks_culled;
            total += with.stats.chunks;
        }
    }
    std::cout << "[chunks] culled " << culled << " of " << total << " chunk tests" << std::endl;
    EXPECT_GT(culled, total / 4) << "the test should exercise culling";
    // Exact culling is the reference: it never skips a chunk.
    CpuRenderer<float> r(2);
    RenderOptions exact;
    exact.culling = Culling::exact;
    ImageF out;
    EXPECT_EQ(r.render(octree, random_camera(rng, 24, 16), exact, out).chunks_culled, 0u);
}

// With the speculative cache, key frames cull against every pose of the window plus the
// envelope's guards: cached frames draw the same images, and the planner sees the same
// key-frame summaries (the same frames become key frames).
TEST(ChunkCulling, SpeculativeCacheDrawsTheSameFrames) {
    const std::uint64_t seed = test::fresh_seed("chunk culling cache");
    const Scene scene = hollow_scene(seed);
    std::mt19937_64 rng(seed);
    int cached = 0;
    for (int path = 0; path < 6; ++path) {
        const std::vector<Camera> frames = jittered_path(rng);
        for (Culling mode : {Culling::opacity_aware, Culling::bbox3sigma}) {
            RenderOptions on;
            on.culling = mode;
            on.catgs.cache = CacheMode::speculative;
            on.catgs.window = 4;
            RenderOptions off = on;
            off.chunk_culling = false;
            CpuRenderer<float> a(2), b(2);
            for (std::size_t f = 0; f < frames.size(); ++f) {
                const Rendered with = render(a, scene, frames[f], on), without = render(b, scene, frames[f], off);
                ASSERT_EQ(with.stats.key_frame, without.stats.key_frame) << "path " << path << " frame " << f;
                ASSERT_EQ(with.image.rgb, without.image.rgb)
                    << culling_name(mode) << " path " << path << " frame " << f << " (CATGS_TEST_SEED=" << seed << ")";
                cached += with.stats.key_frame ? 0 : 1;
            }
        }
    }
    // Some paths pass a huge Gaussian near the camera, where every frame is a key frame.
    EXPECT_GT(cached, 12) << "the test should exercise cached frames";
}

}  // namespace
}  // namespace catgs
