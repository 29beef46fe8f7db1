// The shared stage functions on the device: each runs in a tiny kernel on fresh random inputs
// and must give bit for bit what the same function gives on the host (test_stage_math.cpp and
// test_stage_tiles.cpp check the host against double references): projection geometry, tile rectangles, the
// ellipse-tile test, sort keys, the sub-task blend and the merge, the envelope bound.
//
// This file is compiled with -fmad=false (tests/CMakeLists.txt): the renderer's kernels let
// nvcc contract multiply-adds into FMAs, which rounds differently from the host, but here the
// question is whether the one source means the same on both sides, and without contraction
// every + - * / and sqrt is correctly rounded on both. log is not: CUDA's logf and glibc's may
// differ by an ulp, so the functions that take one (the opacity-aware level) are compared on
// the opacities whose level the two sides compute alike, which is most of them. Every test
// skips without a CUDA device.
#include <gtest/gtest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <iostream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "../stage_inputs.hpp"
#include "../test_util.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_renderer.hpp"

namespace catgs {
namespace {

namespace stage = test::stage;
using stage::same_bits;

void check_cuda(cudaError_t e, const char* what) {
    if (e != cudaSuccess) throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(e));
}

/// A device copy of a host vector, copied back by download().
template <typename T>
class DeviceArray {
public:
    explicit DeviceArray(const std::vector<T>& host) : size_(host.size()) {
        check_cuda(cudaMalloc(&data_, bytes()), "cudaMalloc");
        check_cuda(cudaMemcpy(data_, host.data(), bytes(), cudaMemcpyHostToDevice), "cudaMemcpy to device");
    }
    explicit DeviceArray(std::size_t size) : DeviceArray(std::vector<T>(size)) {}
    ~DeviceArray() { cudaFree(data_); }
    DeviceArray(const DeviceArray&) = delete;
    DeviceArray& operator=(const DeviceArray&) = delete;
    T* get() const { return data_; }
    std::vector<T> download() const {
        std::vector<T> host(size_);
        check_cuda(cudaMemcpy(host.data(), data_, bytes(), cudaMemcpyDeviceToHost), "cudaMemcpy to host");
        return host;
    }

private:
    std::size_t bytes() const { return size_ * sizeof(T) + 1; }  // + 1: cudaMalloc of 0 bytes
    T* data_ = nullptr;
    std::size_t size_;
};

/// One thread per item, then wait and surface launch or execution errors.
template <typename Kernel, typename... Args>
void launch(std::size_t n, const char* what, Kernel kernel, Args... args) {
    const unsigned blocks = static_cast<unsigned>((n + 127) / 128);
    const unsigned grid = blocks > 0 ? blocks : 1;
    kernel<<<grid, 128>>>(args...);
    check_cuda(cudaGetLastError(), what);
    check_cuda(cudaDeviceSynchronize(), what);
}

__device__ int thread_index() {
    return static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
}

class StageDevice : public ::testing::Test {
protected:
    void SetUp() override {
        std::string reason;
        if (!cuda::device_available(&reason)) GTEST_SKIP() << "no CUDA device: " << reason;
    }
};

std::string seed_note(std::uint64_t seed) {
    return " (CATGS_TEST_SEED=" + std::to_string(seed) + ")";
}

// --- Projection geometry ----------------------------------------------------------------

template <typename T>
__global__ void project_kernel(const float* positions, const float* scales, const float* rotations,
                               const float* opacities, int n, View<T> view, Projected<T>* out, int* visible) {
    const int i = thread_index();
    if (i >= n) return;
    const GaussianRef g{positions + 3 * i, scales + 3 * i, rotations + 4 * i, opacities[i], nullptr, 0};
    Projected<T> p{};
    visible[i] = project_geometry(g, view, p) ? 1 : 0;
    out[i] = p;
}

template <typename T>
void expect_same_projection(const Projected<T>& host, const Projected<T>& device, const std::string& what) {
    EXPECT_TRUE(same_bits(host.mean.x, device.mean.x) && same_bits(host.mean.y, device.mean.y)) << what << ": mean";
    EXPECT_TRUE(same_bits(host.conic.x, device.conic.x) && same_bits(host.conic.y, device.conic.y) &&
                same_bits(host.conic.z, device.conic.z))
        << what << ": conic";
    EXPECT_TRUE(same_bits(host.cov.x, device.cov.x) && same_bits(host.cov.y, device.cov.y) &&
                same_bits(host.cov.z, device.cov.z))
        << what << ": cov";
    EXPECT_TRUE(same_bits(host.depth, device.depth) && same_bits(host.opacity, device.opacity))
        << what << ": depth, opacity";
    EXPECT_TRUE(same_bits(host.key_depth, device.key_depth)) << what << ": key depth";
}

template <typename T>
void project_on_both(const char* precision) {
    const std::uint64_t seed = test::fresh_seed(std::string("stage device project ") + precision);
    std::mt19937_64 rng(seed);
    int visible = 0;
    for (int trial = 0; trial < 20; ++trial) {
        const Camera camera = stage::random_camera(rng);
        const View<T> view = make_view<T>(camera, {0, 0, 0});
        const stage::GaussianArrays g = stage::random_gaussians(rng, 2000, camera);
        const int n = static_cast<int>(g.count());
        DeviceArray<float> positions(g.positions), scales(g.scales), rotations(g.rotations), opacities(g.opacities);
        DeviceArray<Projected<T>> out(g.count());
        DeviceArray<int> shown(g.count());
        launch(g.count(), "project_kernel", project_kernel<T>, positions.get(), scales.get(), rotations.get(),
               opacities.get(), n, view, out.get(), shown.get());
        const std::vector<Projected<T>> device = out.download();
        const std::vector<int> device_visible = shown.download();
        for (int i = 0; i < n; ++i) {
            Projected<T> host{};
            const bool host_visible = project_geometry(g.ref(static_cast<std::size_t>(i)), view, host);
            const std::string what = std::string(precision) + " gaussian " + std::to_string(i) + seed_note(seed);
            ASSERT_EQ(device_visible[static_cast<std::size_t>(i)] != 0, host_visible) << what;
            if (!host_visible) continue;
            ++visible;
            expect_same_projection(host, device[static_cast<std::size_t>(i)], what);
        }
    }
    EXPECT_GT(visible, 10000);
}

TEST_F(StageDevice, ProjectionGeometryIsTheHostsInFloat) {
    project_on_both<float>("float");
}
TEST_F(StageDevice, ProjectionGeometryIsTheHostsInDouble) {
    project_on_both<double>("double");
}

// --- The opacity level, and the inputs of the tile and envelope tests ---------------------

__global__ void level_kernel(const Projected<float>* g, int n, float* level) {
    const int i = thread_index();
    if (i < n) level[i] = opacity_level(g[i].opacity);
}

/// `count` random projected Gaussians on a width x height image whose opacity level the
/// device computes bit for bit as the host (see the file comment); at least half of the drawn
/// ones must qualify, or the comparison would leave out most of what it is for.
std::vector<Projected<float>> agreeing_projected(std::mt19937_64& rng, std::size_t count, int width, int height) {
    std::vector<Projected<float>> drawn;
    for (std::size_t i = 0; i < 2 * count; ++i) drawn.push_back(stage::random_projected<float>(rng, width, height));
    DeviceArray<Projected<float>> in(drawn);
    DeviceArray<float> level(drawn.size());
    launch(drawn.size(), "level_kernel", level_kernel, in.get(), static_cast<int>(drawn.size()), level.get());
    const std::vector<float> device = level.download();
    std::vector<Projected<float>> out;
    for (std::size_t i = 0; i < drawn.size() && out.size() < count; ++i)
        if (same_bits(device[i], opacity_level(drawn[i].opacity))) out.push_back(drawn[i]);
    EXPECT_EQ(out.size(), count) << "the device's opacity level differs from the host's for most opacities";
    return out;
}

// --- Tile rectangles and the ellipse-tile test ------------------------------------------

__global__ void tile_rect_kernel(const Projected<float>* g, const float* guard, int n, int tiles_x, int tiles_y,
                                 TileRect* bbox, TileRect* opacity_aware) {
    const int i = thread_index();
    if (i >= n) return;
    bbox[i] = tile_rect(g[i], Culling::bbox3sigma, tiles_x, tiles_y, guard[i]);
    opacity_aware[i] = tile_rect(g[i], Culling::opacity_aware, tiles_x, tiles_y, guard[i]);
}

bool same_rect(const TileRect& a, const TileRect& b) {
    return a.x0 == b.x0 && a.y0 == b.y0 && a.x1 == b.x1 && a.y1 == b.y1;
}

TEST_F(StageDevice, TileRectsAreTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device tile rect");
    std::mt19937_64 rng(seed);
    for (int trial = 0; trial < 10; ++trial) {
        const int width = static_cast<int>(stage::uniform(rng, 1, 2000)),
                  height = static_cast<int>(stage::uniform(rng, 1, 1200));
        const std::vector<Projected<float>> g = agreeing_projected(rng, 5000, width, height);
        std::vector<float> guard;
        for (std::size_t i = 0; i < g.size(); ++i)
            guard.push_back(i % 3 == 0 ? static_cast<float>(stage::uniform(rng, 0, 8)) : 0.0f);
        DeviceArray<Projected<float>> in(g);
        DeviceArray<float> guards(guard);
        DeviceArray<TileRect> bbox(g.size()), oa(g.size());
        launch(g.size(), "tile_rect_kernel", tile_rect_kernel, in.get(), guards.get(), static_cast<int>(g.size()),
               tiles_for(width), tiles_for(height), bbox.get(), oa.get());
        const std::vector<TileRect> device_bbox = bbox.download(), device_oa = oa.download();
        for (std::size_t i = 0; i < g.size(); ++i) {
            const TileRect hb = tile_rect(g[i], Culling::bbox3sigma, tiles_for(width), tiles_for(height), guard[i]);
            const TileRect ho = tile_rect(g[i], Culling::opacity_aware, tiles_for(width), tiles_for(height), guard[i]);
            EXPECT_TRUE(same_rect(hb, device_bbox[i])) << "bbox3sigma, gaussian " << i << seed_note(seed);
            EXPECT_TRUE(same_rect(ho, device_oa[i])) << "opacity-aware, gaussian " << i << seed_note(seed);
        }
    }
}

struct TileProbe {
    int gaussian, tx, ty;
    float guard;
};

__global__ void ellipse_kernel(const Projected<float>* g, const TileProbe* probes, int n, int width, int height,
                               int* touches) {
    const int i = thread_index();
    if (i >= n) return;
    const TileProbe p = probes[i];
    const Projected<float>& gi = g[p.gaussian];
    touches[i] = ellipse_touches_tile(gi, opacity_level(gi.opacity), p.tx, p.ty, width, height, p.guard) ? 1 : 0;
}

TEST_F(StageDevice, EllipseTileTestIsTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device ellipse tile");
    std::mt19937_64 rng(seed);
    int touched = 0, missed = 0;
    for (int trial = 0; trial < 10; ++trial) {
        const int width = static_cast<int>(stage::uniform(rng, 17, 600)),
                  height = static_cast<int>(stage::uniform(rng, 17, 400));
        const std::vector<Projected<float>> g = agreeing_projected(rng, 2000, width, height);
        std::vector<TileProbe> probes;
        for (std::size_t i = 0; i < g.size(); ++i) {
            // The tiles of its rectangle grown by one, where the test decides something.
            const TileRect r = tile_rect(g[i], Culling::opacity_aware, tiles_for(width), tiles_for(height), 1.0f);
            const float guard = i % 4 == 0 ? static_cast<float>(stage::uniform(rng, 0, 6)) : 0.0f;
            for (int ty = std::max(0, r.y0 - 1); ty < std::min(tiles_for(height), r.y1 + 1); ++ty)
                for (int tx = std::max(0, r.x0 - 1); tx < std::min(tiles_for(width), r.x1 + 1); ++tx)
                    if (probes.size() < 200000) probes.push_back({static_cast<int>(i), tx, ty, guard});
        }
        DeviceArray<Projected<float>> in(g);
        DeviceArray<TileProbe> device_probes(probes);
        DeviceArray<int> out(probes.size());
        launch(probes.size(), "ellipse_kernel", ellipse_kernel, in.get(), device_probes.get(),
               static_cast<int>(probes.size()), width, height, out.get());
        const std::vector<int> device = out.download();
        for (std::size_t k = 0; k < probes.size(); ++k) {
            const TileProbe& p = probes[k];
            const Projected<float>& gi = g[static_cast<std::size_t>(p.gaussian)];
            const bool host = ellipse_touches_tile(gi, opacity_level(gi.opacity), p.tx, p.ty, width, height, p.guard);
            (host ? touched : missed) += 1;
            EXPECT_EQ(device[k] != 0, host)
                << "gaussian " << p.gaussian << ", tile " << p.tx << "," << p.ty << seed_note(seed);
        }
    }
    EXPECT_GT(touched, 1000);
    EXPECT_GT(missed, 1000);
}

/// The tiles one Gaussian reaches through the row spans (for_each_touched_tile): their count
/// and a digest of their ids, so host and device can be compared per Gaussian.
struct TileSetDigest {
    std::uint32_t count;
    std::uint64_t digest;
};

template <typename T>
__host__ __device__ TileSetDigest touched_digest(const Projected<T>& g, const View<T>& view, T guard) {
    TileSetDigest d{0, 0};
    d.count = for_each_window_tile<1>(&g, 1u, 1, Culling::opacity_aware, guard, view,
                                      [&](std::uint32_t t) { d.digest = d.digest * 1000003u + t + 1u; });
    return d;
}

__global__ void row_span_kernel(const Projected<float>* g, const float* guard, int n, View<float> view,
                                TileSetDigest* out) {
    const int i = thread_index();
    if (i < n) out[i] = touched_digest(g[i], view, guard[i]);
}

TEST_F(StageDevice, RowSpanTilesAreTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device row spans");
    std::mt19937_64 rng(seed);
    std::uint64_t touched = 0;
    for (int trial = 0; trial < 10; ++trial) {
        const int width = static_cast<int>(stage::uniform(rng, 17, 900)),
                  height = static_cast<int>(stage::uniform(rng, 17, 600));
        const View<float> view = stage::image_view<float>(width, height);
        const std::vector<Projected<float>> g = agreeing_projected(rng, 5000, view.width, view.height);
        std::vector<float> guard;
        for (std::size_t i = 0; i < g.size(); ++i)
            guard.push_back(i % 3 == 0 ? static_cast<float>(stage::uniform(rng, 0, 8)) : 0.0f);
        DeviceArray<Projected<float>> in(g);
        DeviceArray<float> guards(guard);
        DeviceArray<TileSetDigest> out(g.size());
        launch(g.size(), "row_span_kernel", row_span_kernel, in.get(), guards.get(), static_cast<int>(g.size()), view,
               out.get());
        const std::vector<TileSetDigest> device = out.download();
        for (std::size_t i = 0; i < g.size(); ++i) {
            const TileSetDigest host = touched_digest(g[i], view, guard[i]);
            touched += host.count;
            EXPECT_EQ(device[i].count, host.count) << "gaussian " << i << seed_note(seed);
            EXPECT_EQ(device[i].digest, host.digest) << "gaussian " << i << seed_note(seed);
        }
    }
    EXPECT_GT(touched, 10000u);
}

// --- Sort keys ---------------------------------------------------------------------------

__global__ void keys_kernel(const std::uint32_t* tiles, const float* depths, int n, std::uint64_t* keys,
                            std::uint32_t* tiles_back, int* tile_bits) {
    const int i = thread_index();
    if (i >= n) return;
    keys[i] = make_sort_key(tiles[i], depths[i]);
    tiles_back[i] = key_tile(keys[i]);
    tile_bits[i] = sort_key_tile_bits(tiles[i]);
}

TEST_F(StageDevice, SortKeysAreTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device keys");
    std::mt19937_64 rng(seed);
    const std::vector<float> depths = stage::random_depths(rng, 100000);
    std::vector<std::uint32_t> tiles;
    for (std::size_t i = 0; i < depths.size(); ++i) {
        const unsigned bits = static_cast<unsigned>(stage::uniform(rng, 0, 32));  // every magnitude of tile id
        tiles.push_back(static_cast<std::uint32_t>(stage::uniform(rng, 0, 4294967295.0)) >> bits);
    }
    DeviceArray<std::uint32_t> in_tiles(tiles), back(tiles.size());
    DeviceArray<float> in_depths(depths);
    DeviceArray<std::uint64_t> keys(tiles.size());
    DeviceArray<int> bits(tiles.size());
    launch(tiles.size(), "keys_kernel", keys_kernel, in_tiles.get(), in_depths.get(), static_cast<int>(tiles.size()),
           keys.get(), back.get(), bits.get());
    const std::vector<std::uint64_t> device_keys = keys.download();
    const std::vector<std::uint32_t> device_tiles = back.download();
    const std::vector<int> device_bits = bits.download();
    for (std::size_t i = 0; i < tiles.size(); ++i) {
        ASSERT_EQ(device_keys[i], make_sort_key(tiles[i], depths[i])) << "pair " << i << seed_note(seed);
        ASSERT_EQ(device_tiles[i], tiles[i]) << "pair " << i << seed_note(seed);
        ASSERT_EQ(device_bits[i], sort_key_tile_bits(tiles[i])) << "tile " << tiles[i];
    }
}

// --- The sub-task blend and the merge ---------------------------------------------------

/// Per pixel list l, entries [list_begin[l], list_begin[l + 1]) split with threshold k[l]:
/// each sub-task blends its slice from T = 1 (as stage_inputs.hpp's blend_slice does on the
/// host), and the merge composites the partials.
__global__ void merge_kernel(const float* alphas, const float* colours, const int* list_begin, const std::uint32_t* k,
                             int lists, MergeState<float>* out) {
    const int l = thread_index();
    if (l >= lists) return;
    const std::uint64_t begin = static_cast<std::uint64_t>(list_begin[l]),
                        end = static_cast<std::uint64_t>(list_begin[l + 1]);
    MergeState<float> m;
    const std::uint32_t parts = split_count(end - begin, k[l]) + 1;
    for (std::uint32_t s = 0; s < parts; ++s) {
        std::uint64_t first, last;
        subtask_range(begin, end, k[l], s, first, last);
        PixelAccumulator<float> acc;
        for (std::uint64_t i = first; i < last; ++i)
            blend_power(acc, 0.0f, alphas[i], Vec3<float>{colours[3 * i], colours[3 * i + 1], colours[3 * i + 2]},
                        0.0f);
        merge_partial(m, Partial<float>{acc.colour, acc.transmittance});
    }
    out[l] = m;
}

TEST_F(StageDevice, MergeOfPartialsIsTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device merge");
    std::mt19937_64 rng(seed);
    std::vector<float> alphas, colours;
    std::vector<int> begin{0};
    std::vector<std::uint32_t> k;
    for (int l = 0; l < 5000; ++l) {
        // Some lists end with an opaque run, so that the merge's stop is reached too.
        const int n = static_cast<int>(stage::uniform(rng, 1, 200));
        const double max_alpha = l % 3 == 0 ? kMaxAlpha : 0.1;
        for (int i = 0; i < n; ++i) {
            alphas.push_back(static_cast<float>(stage::uniform(rng, kMinAlpha, max_alpha)));
            for (int c = 0; c < 3; ++c) colours.push_back(static_cast<float>(stage::uniform(rng, 0, 2)));
        }
        begin.push_back(static_cast<int>(alphas.size()));
        k.push_back(static_cast<std::uint32_t>(stage::uniform(rng, 1, 64)));
    }
    DeviceArray<float> a(alphas), c(colours);
    DeviceArray<int> b(begin);
    DeviceArray<std::uint32_t> kk(k);
    DeviceArray<MergeState<float>> out(k.size());
    launch(k.size(), "merge_kernel", merge_kernel, a.get(), c.get(), b.get(), kk.get(), static_cast<int>(k.size()),
           out.get());
    const std::vector<MergeState<float>> device = out.download();
    int stopped = 0;
    for (std::size_t l = 0; l < k.size(); ++l) {
        const std::vector<float> la(alphas.begin() + begin[l], alphas.begin() + begin[l + 1]);
        const std::vector<float> lc(colours.begin() + 3 * begin[l], colours.begin() + 3 * begin[l + 1]);
        MergeState<float> host;
        const std::uint32_t parts = split_count(la.size(), k[l]) + 1;
        for (std::uint32_t s = 0; s < parts; ++s) {
            std::uint64_t first, last;
            subtask_range(0, la.size(), k[l], s, first, last);
            merge_partial(host, stage::blend_slice(la, lc, first, last));
        }
        stopped += host.done;
        const MergeState<float>& d = device[l];
        EXPECT_TRUE(same_bits(host.colour.x, d.colour.x) && same_bits(host.colour.y, d.colour.y) &&
                    same_bits(host.colour.z, d.colour.z) && same_bits(host.transmittance, d.transmittance) &&
                    host.done == d.done)
            << "list " << l << seed_note(seed);
    }
    EXPECT_GT(stopped, 100);
}

// --- The envelope bound ------------------------------------------------------------------

struct EnvelopeOut {
    float bound[2];
    int can_enter[2];
    float enter_bound[2];
};

__global__ void envelope_kernel(const Projected<float>* g, const float* max_scale, int n, View<float> key, float guard,
                                float move, EnvelopeOut* out) {
    const int i = thread_index();
    if (i >= n) return;
    const float focal = key.fx > key.fy ? key.fx : key.fy;
    const Culling modes[2] = {Culling::bbox3sigma, Culling::opacity_aware};
    EnvelopeOut o{};
    for (int m = 0; m < 2; ++m) {
        o.bound[m] = footprint_bound_px(g[i], modes[m], max_scale[i], focal);
        o.enter_bound[m] = -1.0f;
        o.can_enter[m] = uncached_can_enter(g[i], modes[m], key, guard, move, max_scale[i], o.enter_bound[m]) ? 1 : 0;
    }
    out[i] = o;
}

TEST_F(StageDevice, EnvelopeBoundsAreTheHosts) {
    const std::uint64_t seed = test::fresh_seed("stage device envelope");
    std::mt19937_64 rng(seed);
    int entering = 0;
    for (int trial = 0; trial < 10; ++trial) {
        const Camera camera = stage::random_camera(rng);
        const View<float> key = make_view<float>(camera, {0, 0, 0});
        const std::vector<Projected<float>> g = agreeing_projected(rng, 5000, key.width, key.height);
        std::vector<float> max_scale;
        for (std::size_t i = 0; i < g.size(); ++i)
            max_scale.push_back(static_cast<float>(stage::log_uniform(rng, 1e-4, 10)));
        const float guard = static_cast<float>(stage::uniform(rng, 0, 4)),
                    move = static_cast<float>(stage::uniform(rng, 0, 0.5));
        DeviceArray<Projected<float>> in(g);
        DeviceArray<float> scales(max_scale);
        DeviceArray<EnvelopeOut> out(g.size());
        launch(g.size(), "envelope_kernel", envelope_kernel, in.get(), scales.get(), static_cast<int>(g.size()), key,
               guard, move, out.get());
        const std::vector<EnvelopeOut> device = out.download();
        const Culling modes[2] = {Culling::bbox3sigma, Culling::opacity_aware};
        for (std::size_t i = 0; i < g.size(); ++i)
            for (int m = 0; m < 2; ++m) {
                const std::string what =
                    std::string(culling_name(modes[m])) + ", gaussian " + std::to_string(i) + seed_note(seed);
                EXPECT_TRUE(same_bits(device[i].bound[m],
                                      footprint_bound_px(g[i], modes[m], max_scale[i], std::max(key.fx, key.fy))))
                    << what;
                float bound = -1.0f;
                const bool host = uncached_can_enter(g[i], modes[m], key, guard, move, max_scale[i], bound);
                EXPECT_EQ(device[i].can_enter[m] != 0, host) << what;
                EXPECT_TRUE(same_bits(device[i].enter_bound[m], bound)) << what;
                entering += host;
            }
    }
    EXPECT_GT(entering, 1000);
}

}  // namespace
}  // namespace catgs
