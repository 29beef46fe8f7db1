#include "preprocess.cuh"

#include <cub/block/block_reduce.cuh>
#include <cuda/functional>

#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/occlusion.hpp"
#include "catgs/stages/tiles.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// Preprocess waits on its loads (scene, SH) more than it computes, so it runs faster with more
// warps resident, and registers bound how many (94 a thread in float: 16 warps an SM).
// - The single-frame kernel is held to 80 registers, 6 blocks of 128 an SM, without spilling:
//   preprocess 15-19% faster on the bench kit's paths than at ptxas' own choice (H200,
//   session 9, then in blocks of 256). Blocks of 128 hold as many warps as 3 of 256 did, but a
//   block waits at its closing count for fewer footprints' tile counts, and a finished block
//   frees its slot sooner: preprocess 8-13% faster on all six of the kit's paths than in blocks
//   of 256 (city_ring 1080p 0.557 -> 0.511 ms, garden survey 4K 0.706 -> 0.623; blocks of 64
//   were within 3% of 128 either way; H200, session 21, plain, 120 frames, twice each).
// - The kernel that also summarises for the planner would spill at 80, so it runs in blocks
//   of 128 threads instead: 5 of them fit where 2 of 256 did (20 warps instead of 16).
// The double kernels only serve tests and keep the defaults.
template <typename T>
constexpr int kSingleThreads = sizeof(T) == 4 ? 128 : kThreads;
template <typename T>
constexpr int kSingleMinBlocks = sizeof(T) == 4 ? 6 : 1;
constexpr int kSummarizeThreads = 128;

// The SH colour of a Gaussian that touches a tile. At degree 3 its 48 coefficients (192 bytes,
// 16-byte aligned in DeviceScene's own allocation) are fetched as 12 float4 loads instead of 48
// scalar ones: a warp's scalar loads at a 192-byte stride each touched 32 sectors for 128 useful
// bytes. Preprocess on the kit's city_ring (SH 3) fell from 0.80 to 0.61 ms at 1080p and 0.84 to
// 0.66 at 4K, DRAM throughput 27% -> 37% (H200, 2026-12-03). Other degrees keep the scalar
// loads: rows of degree 0 and 2 are not 16-byte multiples, and degree 1 has only 12 floats.
template <typename T>
__device__ void shade_visible(const GaussianRef& g, const View<T>& view, Projected<T>& p) {
    if (g.sh_degree == 3 && reinterpret_cast<std::uintptr_t>(g.sh) % alignof(float4) == 0) {
        const float4* rows = reinterpret_cast<const float4*>(g.sh);
        const auto lane = [](const float4& q, int j) { return j == 0 ? q.x : j == 1 ? q.y : j == 2 ? q.z : q.w; };
        // Coefficient k is floats 3k..3k+2: within one float4 or across two. k is a constant
        // once sh_colour_of is unrolled, so the selects fold away and repeated loads merge.
        const auto coefficient = [rows, lane](int k) {
            const float4 a = __ldg(rows + (3 * k) / 4), b = __ldg(rows + (3 * k + 2) / 4);
            const int j = (3 * k) % 4;
            return Vec3<T>{static_cast<T>(lane(a, j)), static_cast<T>(j + 1 < 4 ? lane(a, j + 1) : lane(b, 0)),
                           static_cast<T>(j + 2 < 4 ? lane(a, j + 2) : lane(b, j - 2))};
        };
        shade_gaussian_with(g, coefficient, view, p);
    } else {
        shade_gaussian(g, view, p);
    }
}

// Counts the tiles of the union of each Gaussian's footprints over the window
// (MaxWindow = 1: the plain single-frame pipeline) and projects it at the actual pose for
// rasterizing (opacity 0 when culled there). Key frames of the cache also reduce what the
// planner needs: nearest depth, mean inverse depth, largest footprint.
template <typename T, int MaxWindow, bool Summarize, int Threads, int MinBlocks>
__global__ void __launch_bounds__(Threads, MinBlocks)
    preprocess_kernel(DeviceSceneView scene, ChunkSpace space, const View<T>* views, int window, View<T> actual,
                      bool reproject_actual, Culling culling, T guard, T guard_translation, Projected<T>* projected,
                      std::uint64_t* touched, float* sort_depth, FrameCounters* counters, OcclusionCut occlusion) {
    const std::uint64_t slot = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    // The grid covers every chunk; chunk_cull kept the first live_slots (ChunkSpace). The end
    // mark of the scan's counts goes after them (the host writes it at space.slots).
    const std::uint64_t live = space.live_slots();
    if (slot == live && live < space.slots) touched[slot] = 0;
    if (static_cast<std::uint64_t>(blockIdx.x) * blockDim.x >= live) return;  // the whole block: no barrier left
    bool visible = false;
    std::uint32_t occluded_pairs = 0;
    unsigned long long pairs = 0;  // this slot's, into the frame's total
    float nearest = INFINITY, extent = 0.0f;
    double inverse_depth = 0.0;
    std::uint64_t i = 0;
    const bool present = slot < live && space.gaussian(slot, i);
    if (slot < live && !present) touched[slot] = 0;
    if (present) {
        Projected<T> poses[MaxWindow];
        const std::uint32_t valid = project_window<T, MaxWindow>(scene, i, views, window, poses);
        std::uint32_t tiles =
            for_each_window_tile<MaxWindow>(poses, valid, window, culling, guard, views[0], [](std::uint32_t) {});
        // Single pose only (the host never sets a cut for windows); the planner's summary below
        // still sees the Gaussian, as it would without the cut.
        if (MaxWindow == 1 && occlusion.active() && tiles > 0 &&
            occluded(occlusion.pyramid, occlusion.cuts, tile_rect(poses[0], culling, actual.tiles_x, actual.tiles_y),
                     poses[0].key_depth)) {
            occluded_pairs = tiles;
            tiles = 0;
        }
        touched[slot] = tiles;
        pairs = tiles;
        if (Summarize && tiles == 0 && guard > T(0) && culling != Culling::exact) {
            // In no list, but able to enter the image within the envelope (envelope.hpp), near
            // any pose of the window: a cached frame may lie near any of them.
            const float* sc = gaussian_ref(scene, i).scale;
            const T max_scale = static_cast<T>(fmaxf(fabsf(sc[0]), fmaxf(fabsf(sc[1]), fabsf(sc[2]))));
            T reach_depth = INFINITY, reach_bound = T(0);
            summarize_uncached<MaxWindow>(poses, valid, window, views, scene.positions + 3 * i, culling, guard,
                                          guard_translation, max_scale, reach_depth, reach_bound);
            nearest = fminf(nearest, static_cast<float>(reach_depth));
            extent = fmaxf(extent, static_cast<float>(reach_bound));
        }
        if (tiles > 0) {
            // At the key pose for every listed Gaussian (cpu_renderer.cpp says why).
            sort_depth[slot] = (valid & 1u) ? poses[0].key_depth : key_depth_at(views[0], scene.positions + 3 * i);
            // At the actual pose: pose 0's geometry unless the window lowered the near plane;
            // the SH colour only now that the Gaussian is known to touch a tile.
            const GaussianRef g = gaussian_ref(scene, i);
            Projected<T> p = poses[0];
            bool at_actual = (valid & 1u) != 0;
            if (reproject_actual) at_actual = project_geometry(g, actual, p);
            if (at_actual)
                shade_visible(g, actual, p);
            else
                p.opacity = T(0);
            projected[i] = p;
            visible = at_actual;
            if (Summarize) {
#pragma unroll
                for (int k = 0; k < MaxWindow; ++k)
                    if (k < window && (valid >> k & 1u)) nearest = fminf(nearest, static_cast<float>(poses[k].depth));
                if (at_actual) {
                    inverse_depth = 1.0 / static_cast<double>(p.depth);
                    if (cached_can_gain_tiles(culling, tiles, actual)) {
                        const float* sc = g.scale;
                        extent = fmaxf(0.0f, static_cast<float>(cached_extent_bound_px(
                                                 p, culling, static_cast<T>(fmaxf(sc[0], fmaxf(sc[1], sc[2]))),
                                                 actual.fx > actual.fy ? actual.fx : actual.fy)));
                    }
                }
            }
        }
    }
    const int block_visible = __syncthreads_count(visible);
    if (threadIdx.x == 0 && block_visible > 0)
        atomicAdd(&counters->visible, static_cast<unsigned long long>(block_visible));
    {
        // 64-bit: a window's footprint union on a large grid can pass 2^32 pairs over a block.
        using PairReduce = cub::BlockReduce<unsigned long long, Threads>;
        __shared__ typename PairReduce::TempStorage pair_temp;
        const unsigned long long block_total = PairReduce(pair_temp).Sum(pairs);
        if (threadIdx.x == 0 && block_total > 0) atomicAdd(&counters->lists.pairs, block_total);
    }
    if (MaxWindow == 1 && occlusion.active()) {  // uniform across the launch
        using CountReduce = cub::BlockReduce<std::uint32_t, Threads>;
        __shared__ typename CountReduce::TempStorage count_temp;
        const std::uint32_t block_pairs = CountReduce(count_temp).Sum(occluded_pairs);  // < 2^32: 128 x 2^20 tiles
        const int block_occluded = __syncthreads_count(occluded_pairs > 0);
        if (threadIdx.x == 0 && block_occluded > 0) {
            atomicAdd(&counters->occluded, static_cast<unsigned long long>(block_occluded));
            atomicAdd(&counters->occluded_pairs, static_cast<unsigned long long>(block_pairs));
        }
    }
    if (Summarize) {
        using FloatReduce = cub::BlockReduce<float, Threads>;
        using DoubleReduce = cub::BlockReduce<double, Threads>;
        __shared__ union {
            typename FloatReduce::TempStorage f;
            typename DoubleReduce::TempStorage d;
        } temp;
        const float block_nearest = FloatReduce(temp.f).Reduce(nearest, ::cuda::minimum<float>{});
        __syncthreads();
        const float block_extent = FloatReduce(temp.f).Reduce(extent, ::cuda::maximum<float>{});
        __syncthreads();
        const double block_inverse = DoubleReduce(temp.d).Sum(inverse_depth);
        if (threadIdx.x == 0) {
            if (block_nearest < INFINITY) atomicMin(&counters->min_depth_bits, __float_as_uint(block_nearest));
            atomicMax(&counters->max_extent_bits, __float_as_uint(block_extent));
            if (block_inverse > 0) atomicAdd(&counters->inverse_depth_sum, block_inverse);
        }
    }
}

// Cached frame: re-project the cached Gaussians at the actual pose (opacity 0 if culled).
template <typename T>
__global__ void reproject_kernel(DeviceSceneView scene, ChunkSpace space, View<T> actual, const std::uint64_t* touched,
                                 Projected<T>* projected, FrameCounters* counters) {
    const std::uint64_t p = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    bool visible = false;
    std::uint64_t i = 0;
    if (p < space.slots && touched[p] > 0 && space.gaussian(p, i)) {
        Projected<T> p;
        const GaussianRef g = gaussian_ref(scene, i);
        visible = project_geometry(g, actual, p);
        if (visible)
            shade_visible(g, actual, p);
        else
            p.opacity = T(0);
        projected[i] = p;
    }
    const int block_visible = __syncthreads_count(visible);
    if (threadIdx.x == 0 && block_visible > 0)
        atomicAdd(&counters->visible, static_cast<unsigned long long>(block_visible));
}

}  // namespace

template <typename T>
void preprocess(const PreprocessArgs<T>& a, cudaStream_t s) {
    if (a.space.slots == 0) return;
    const auto launch = [&](auto kernel, int threads, int window) {
        kernel<<<blocks_for(a.space.slots, threads), threads, 0, s>>>(
            a.scene, a.space, a.views, window, a.actual, a.reproject_actual, a.culling, a.guard, a.guard_translation,
            a.projected, a.touched, a.sort_depth, a.counters, a.occlusion);
    };
    if (a.window == 1 && !a.summarize)
        launch(preprocess_kernel<T, 1, false, kSingleThreads<T>, kSingleMinBlocks<T>>, kSingleThreads<T>, 1);
    else if (a.window == 1)
        launch(preprocess_kernel<T, 1, true, kSummarizeThreads, 1>, kSummarizeThreads, 1);
    else if (a.window <= kUnrolledWindow)
        launch(preprocess_kernel<T, kSmallWindow<T>, true, kThreads, 1>, kThreads, a.window);
    else
        launch(preprocess_kernel<T, kMaxWindow, true, kThreads, 1>, kThreads, a.window);
    CATGS_CUDA_CHECK_LAUNCH("preprocess_kernel");
}

template <typename T>
void reproject(const ReprojectArgs<T>& a, cudaStream_t s) {
    if (a.space.slots == 0) return;
    reproject_kernel<T><<<blocks_for(a.space.slots, kThreads), kThreads, 0, s>>>(a.scene, a.space, a.actual, a.touched,
                                                                                 a.projected, a.counters);
    CATGS_CUDA_CHECK_LAUNCH("reproject_kernel");
}

template void preprocess(const PreprocessArgs<float>&, cudaStream_t);
template void preprocess(const PreprocessArgs<double>&, cudaStream_t);
template void reproject(const ReprojectArgs<float>&, cudaStream_t);
template void reproject(const ReprojectArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
