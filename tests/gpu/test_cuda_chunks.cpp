// Chunk-level culling on the CUDA backend (the compacted index space of ChunkSpace): culling
// chunks changes nothing in the image, single frames and speculative cached frames alike,
// and the partitioned scene still matches the CPU reference. Skips without a device.
#include <gtest/gtest.h>

#include "../chunk_scenes.hpp"
#include "../test_util.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/stage.hpp"
#include "catgs/trajectory.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

using namespace test::chunks;

class CudaChunkTest : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

struct GpuSession {
    explicit GpuSession(const Scene& scene) {
        renderer.set_scene(std::make_shared<cuda::DeviceScene>(scene, renderer.stream()));
    }
    ImageRGB8 render(const Camera& cam, const RenderOptions& o, FrameStats* stats = nullptr) {
        ImageRGB8 out;
        const FrameStats s = renderer.render(cam, o, &out, nullptr);
        if (stats) *stats = s;
        return out;
    }
    cuda::CudaRenderer<float> renderer;
};

TEST_F(CudaChunkTest, SkippedChunksChangeNothing) {
    const std::uint64_t seed = test::fresh_seed("cuda chunk culling single frame");
    const Scene octree = surrounding_scene(seed), single = single_gaussian_chunks(surrounding_scene(seed, 8000));
    GpuSession octree_session(octree), single_session(single);
    std::mt19937_64 rng(seed);
    std::uint64_t culled = 0, total = 0;
    for (int k = 0; k < 48; ++k) {
        GpuSession& session = k % 2 ? single_session : octree_session;
        const Camera cam = k % 3 == 2 ? random_camera(rng, 21, 13) : random_camera(rng);
        for (Culling mode : {Culling::opacity_aware, Culling::bbox3sigma}) {
            RenderOptions on;
            on.culling = mode;
            RenderOptions off = on;
            off.chunk_culling = false;
            FrameStats with_stats, without_stats;
            const ImageRGB8 with = session.render(cam, on, &with_stats),
                            without = session.render(cam, off, &without_stats);
            ASSERT_EQ(with.rgb, without.rgb)
                << culling_name(mode) << " camera " << k << " (CATGS_TEST_SEED=" << seed << ")";
            ASSERT_EQ(with_stats.pairs, without_stats.pairs) << culling_name(mode) << " camera " << k;
            EXPECT_EQ(without_stats.chunks_culled, 0u);
            culled += with_stats.chunks_culled;
            total += with_stats.chunks;
        }
    }
    std::cout << "[cuda chunks] culled " << culled << " of " << total << " chunk tests" << std::endl;
    EXPECT_GT(culled, total / 4);
}

TEST_F(CudaChunkTest, SpeculativeCacheDrawsTheSameFrames) {
    const std::uint64_t seed = test::fresh_seed("cuda chunk culling cache");
    const Scene scene = hollow_scene(seed);
    GpuSession a(scene), b(scene);
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
            a.renderer.reset_cache();
            b.renderer.reset_cache();
            for (std::size_t f = 0; f < frames.size(); ++f) {
                FrameStats sa, sb;
                const ImageRGB8 with = a.render(frames[f], on, &sa), without = b.render(frames[f], off, &sb);
                ASSERT_EQ(sa.key_frame, sb.key_frame) << "path " << path << " frame " << f;
                ASSERT_EQ(with.rgb, without.rgb)
                    << culling_name(mode) << " path " << path << " frame " << f << " (CATGS_TEST_SEED=" << seed << ")";
                cached += sa.key_frame ? 0 : 1;
            }
        }
    }
    EXPECT_GT(cached, 12);
}

// chunk_cull against the CPU's chunk test, on 40000 chunks of one Gaussian each (79 blocks of
// the kernel, three steps of its last block's compaction, the last one partial): the chunks
// each key frame keeps, in float and double, for single poses (the pose passed by value) and
// windows of 2 and 16 poses (the others read from mapped host memory), while the images equal
// the ones drawn without chunk culling (a chunk lost or out of order in the compaction would
// move a Gaussian or its depth ties).
/// Chunks whose test may round the other way on the device (see the use).
constexpr double kBorderlineChunks = 2;

template <typename T>
void expect_chunk_counts_of_the_cpu(const Scene& scene, std::uint64_t seed) {
    cuda::CudaRenderer<T> gpu, whole;
    gpu.set_scene(std::make_shared<cuda::DeviceScene>(scene, gpu.stream()));
    whole.set_scene(std::make_shared<cuda::DeviceScene>(scene, whole.stream()));
    CpuRenderer<T> cpu;
    std::mt19937_64 rng(seed);
    int keys = 0;
    for (int window : {1, 2, 16}) {
        RenderOptions o;
        if (window > 1) {
            o.catgs.cache = CacheMode::speculative;
            o.catgs.window = window;
        }
        RenderOptions unculled = o;
        unculled.chunk_culling = false;
        for (int path = 0; path < 3; ++path) {
            gpu.reset_cache();
            whole.reset_cache();
            cpu.reset_cache();
            for (const Camera& cam : jittered_path(rng)) {
                ImageRGB8 with, without;
                ImageF reference;
                const FrameStats g = gpu.render(cam, o, &with, nullptr);
                whole.render(cam, unculled, &without, nullptr);
                const FrameStats c = cpu.render(scene, cam, o, reference);
                ASSERT_EQ(g.key_frame, c.key_frame) << "window " << window << " (CATGS_TEST_SEED=" << seed << ")";
                ASSERT_EQ(with.rgb, without.rgb) << "window " << window << " (CATGS_TEST_SEED=" << seed << ")";
                if (!g.key_frame) continue;
                ++keys;
                EXPECT_EQ(g.chunks, scene.chunks.size());
                // nvcc contracts the plane tests' products into FMAs, the host compiler does
                // not: a chunk whose farthest corner lies within rounding of a plane can go
                // either way (seen: 18577 culled against 18576 of 40000, images equal). Such a
                // chunk is kChunkMarginPx beyond any footprint, so either answer is sound; a
                // compaction that lost or repeated a block step would miss by thousands, and a
                // lost chunk that matters would change the image (asserted above).
                EXPECT_NEAR(g.chunks_culled, c.chunks_culled, kBorderlineChunks)
                    << "window " << window << " path " << path << " (CATGS_TEST_SEED=" << seed << ")";
            }
        }
    }
    EXPECT_GT(keys, 20);
}

TEST_F(CudaChunkTest, ChunkCullKeepsTheCpuChunksOverManyBlocks) {
    const std::uint64_t seed = test::fresh_seed("cuda chunk_cull against the cpu");
    const Scene scene = single_gaussian_chunks(surrounding_scene(seed, 40000));
    ASSERT_GT(scene.chunks.size(), 2u * 16384u);
    expect_chunk_counts_of_the_cpu<float>(scene, seed);
    expect_chunk_counts_of_the_cpu<double>(scene, seed);
}

// The built-in city as loaded (partitioned), on a survey path: the GPU with chunk culling
// against the CPU reference, and the share of chunks a survey frame skips.
TEST_F(CudaChunkTest, PartitionedCityMatchesTheCpuReference) {
    const Scene city = load_scene("builtin:city?gaussians=200000&seed=5");
    const std::vector<Camera> path = make_trajectory("builtin:survey?frames=6&altitude=70&pitch=-45", city.bounds,
                                                     intrinsics_from_fov(480, 270, 60));
    GpuSession session(city);
    CpuRenderer<float> cpu;
    for (std::size_t f = 0; f < path.size(); ++f) {
        FrameStats stats;
        const ImageRGB8 gpu = session.render(path[f], RenderOptions{}, &stats);
        ImageF reference;
        cpu.render(city, path[f], RenderOptions{}, reference);
        const ImageError e = compare(gpu, to_rgb8(reference));
        std::cout << "[cuda chunks] city frame " << f << ": culled " << stats.chunks_culled << " of " << stats.chunks
                  << " chunks, psnr " << e.psnr << " dB, max " << e.max_abs << std::endl;
        EXPECT_GT(stats.chunks_culled, 0u);
        // chunk_cull is a stage of its own on the GPU (its launch, compaction and count).
        EXPECT_GT(stats.stage_ms[Stage::chunk_cull], 0.0);
        EXPECT_GE(e.psnr, 50.0);
        EXPECT_LE(e.max_abs, 2);
    }
}

}  // namespace
}  // namespace catgs
