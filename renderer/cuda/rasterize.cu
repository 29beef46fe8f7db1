#include "rasterize.cuh"

#include "catgs/stages/footprint.hpp"
#include "catgs/stages/occlusion.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/error.hpp"
#include "cuda_check.hpp"
#include "merge.cuh"

#include <type_traits>

namespace catgs::cuda {
namespace {

/// What the rasterizer reads of one Gaussian, staged in shared memory, with its conic and
/// opacity in AlphaMath's domain. Aligned so that a warp reads it with 16-byte loads (3 in
/// float, not 9 of 4 bytes): the kernel is bound by the instructions it issues.
template <typename T>
struct alignas(16) Splat {
    Vec2<T> mean;
    Vec3<T> conic;
    T opacity;
    Vec3<T> colour;
};

/// alpha's exponent and exponential. Double, the reference precision, keeps the reference's
/// own math (gaussian_power, the exact exp). Float works in base 2 with the opacity folded in
/// (blend_alpha_folded): the conic is staged pre-multiplied by -log2(e)/2 (-log2(e) off the
/// diagonal) and the opacity as its log2, which joins the exponent's terms in dy, taken once a
/// row of pixels (Row). That leaves 3 flops and one ex2 a pixel, no multiply by the opacity.
/// ex2.approx.ftz is within 2^-22 relative and lg2.approx within 2^-22 absolute; with the
/// pre-scaling's roundings the exponent is within a few ulp of the reference's, so alpha is
/// within about 1e-6 relative on the powers that can reach 1/255, far below the 8-bit output's
/// 2e-3.
template <typename T>
struct AlphaMath {
    struct Row {
        T py;
    };
    __device__ static Vec3<T> staged_conic(Vec3<T> conic) { return conic; }
    __device__ static T staged_opacity(T opacity) { return opacity; }
    __device__ static Row row(const Splat<T>&, T py) { return {py}; }
    __device__ static BlendAlpha<T> alpha(const Splat<T>& s, T px, Row r) {
        return blend_alpha(gaussian_power(s.mean, s.conic, px, r.py), s.opacity, [](T v) { return exp_of(v); });
    }
};
template <>
struct AlphaMath<float> {
    static constexpr float kLog2E = 1.4426950408889634f;
    struct Row {
        float cy_dy, cz_dy2_log2_opacity;
    };
    __device__ static Vec3<float> staged_conic(Vec3<float> c) {
        return {-0.5f * kLog2E * c.x, -kLog2E * c.y, -0.5f * kLog2E * c.z};
    }
    __device__ static float staged_opacity(float opacity) { return __log2f(opacity); }  // 0 -> -inf
    __device__ static Row row(const Splat<float>& s, float py) {
        const float dy = s.mean.y - py;
        return {s.conic.y * dy, fmaf(s.conic.z * dy, dy, s.opacity)};
    }
    __device__ static BlendAlpha<float> alpha(const Splat<float>& s, float px, Row r) {
        const float dx = s.mean.x - px;
        const float folded = fmaf(dx, fmaf(s.conic.x, dx, r.cy_dy), r.cz_dy2_log2_opacity);
        return blend_alpha_folded(folded, s.opacity, [](float v) {
            float e;
            asm("ex2.approx.ftz.f32 %0, %1;" : "=f"(e) : "f"(v));
            return e;
        });
    }
};

// The 16x16 tile as eight 8x4 warp blocks, 2 across and 4 down. While a batch is staged, the
// thread staging a Gaussian also records which blocks its 1/255 box reaches (not in exact
// mode); a warp then walks only the Gaussians that reach one of its blocks, found 32 at a time
// with one ballot. A skipped Gaussian has alpha < 1/255 at every pixel of the block, so the
// image is the one the full walk draws. A walked Gaussian is shaded on all of the warp's blocks,
// reached or not (an unreached block's blend draws nothing): a branch per block kept the two
// pixels' blends apart, and interleaved they hide each other's latency; with the branch the
// frames took 3-8% longer on every kit path (H100, 2026-12-06).
constexpr int kWarpBlockW = 8, kWarpBlockH = 4, kWarpBlocks = kTilePixels / 32;
static_assert(kTileSize == 16 && kWarpBlocks == 8 && kWarpBlockW * kWarpBlockH == 32,
              "the warp blocks must tile the 16x16 tile: 2 across, 4 down");

template <typename T>
__device__ std::uint32_t blocks_reached(const Projected<T>& p, int tile_x, int tile_y) {
    const PixelBox<T> box = visible_box(p);
    std::uint32_t bits = 0;
    for (int w = 0; w < kWarpBlocks; ++w) {
        const T cx0 = static_cast<T>(tile_x * kTileSize + (w % 2) * kWarpBlockW) + T(0.5);
        const T cy0 = static_cast<T>(tile_y * kTileSize + (w / 2) * kWarpBlockH) + T(0.5);
        if (!box_misses_centres(box, cx0, cy0, cx0 + T(kWarpBlockW - 1), cy0 + T(kWarpBlockH - 1))) bits |= 1u << w;
    }
    return bits;
}

/// Whether every pixel a thread owns is done.
template <typename T, int Pixels>
__device__ bool all_done(const SignedPixel<T> (&acc)[Pixels]) {
    bool done = true;
#pragma unroll
    for (int b = 0; b < Pixels; ++b) done &= acc[b].done();
    return done;
}

/// Gaussians staged a batch at a time, whatever the layout: one per pixel of the tile, so that
/// a thread stages as many as it owns pixels.
constexpr int kBatch = kTilePixels;

/// How a task's pixels reach threads: each thread owns pixel (lane % 8, lane / 8) of Pixels
/// warp blocks, so that a Gaussian's fetch from shared memory and its walk are paid once for
/// Pixels pixels. Warp w owns blocks w * Pixels .. w * Pixels + Pixels - 1: with 2 a 16x4
/// strip, one row of blocks, whose two pixels a thread share their dy terms.
template <int Pixels>
struct PixelLayout {
    static_assert(Pixels == 1 || Pixels == 2, "one pixel a thread, or two side by side");
    static constexpr int kThreads = kTilePixels / Pixels;
    static constexpr int kCols = Pixels == 1 ? 1 : 2;
    static constexpr int kRows = Pixels / kCols;
    int first_col, first_row;  // the warp's first warp block, in block columns and rows
    __device__ explicit PixelLayout(int warp)
        : first_col(Pixels == 1 ? warp % 2 : 0), first_row(Pixels == 1 ? warp / 2 : warp * Pixels / 2) {}
};

/// The tile and sub-task index of block `block`; false for a block past the tasks that exist.
/// With split tiles, the extra sub-tasks come first: each is a full k-long slice, the longest
/// tasks of the frame, and started last they would run alone on an idle GPU at the end. Then
/// the heavy lists (kHeavyListFactor), for the same reason, then the other tiles in row order.
__device__ inline bool task_of_block(const TaskGrid& grid, const TaskLabel* labels, TaskCounters* counters,
                                     std::uint32_t block, std::uint32_t& tile, std::uint32_t& index) {
    index = 0;
    if (grid.split) {
        if (block < grid.max_extra) {
            if (block >= counters->extra_tasks) return false;
            tile = labels[block].tile;
            index = labels[block].index;
            return true;
        }
        block -= static_cast<std::uint32_t>(grid.max_extra);
    }
    if (grid.max_heavy > 0) {
        if (block < grid.max_heavy) {
            if (block >= counters->heavy_tiles) return false;
            tile = grid.heavy_tiles[block];
            return true;
        }
        block -= static_cast<std::uint32_t>(grid.max_heavy);
    }
    if (block >= grid.band_tiles) return false;
    tile = grid.first_tile + block;
    return grid.max_heavy == 0 || grid.runs_first[tile] == 0;
}

/// The place in the heavy list of the tile block `block` draws, when its pixels go to host
/// memory (PixelOutputs::heavy_rgb8), else kNoSlot; from the launch's constants alone, so that
/// it is asked again after the blend loop instead of held in a register through it.
__device__ inline std::uint32_t heavy_to_host(const TaskGrid& grid, std::uint32_t block, std::uint32_t slot,
                                              const PixelOutputs& out) {
    if (!out.heavy_rgb8 || slot != kNoSlot) return kNoSlot;
    if (grid.split) {
        if (block < grid.max_extra) return kNoSlot;
        block -= static_cast<std::uint32_t>(grid.max_extra);
    }
    return block < grid.max_heavy ? block : kNoSlot;
}

/// warp_done's value for a warp whose pixels are not all done.
constexpr std::uint32_t kNotDone = 0xffffffffu;

/// The sort depth by which every pixel of a tile had stopped, from how far into its list
/// (`list`) each warp's pixels were all done: a warp notices at the first walk after its last
/// pixel stops, so its stop is no later than the Gaussian before that point. +infinity when a
/// warp is not done (the list ran out first).
template <int Warps, typename T>
__device__ float stop_depth(const std::uint32_t* warp_done, const std::uint32_t* list, const Projected<T>* projected) {
    std::uint32_t last = 0;
    for (int w = 0; w < Warps; ++w) {
        if (warp_done[w] == kNotDone) return INFINITY;
        last = warp_done[w] > last ? warp_done[w] : last;
    }
    return last == 0 ? -INFINITY : projected[list[last - 1]].key_depth;  // 0: no pixel to draw
}

/// Blocks an SM is asked to hold: in float what ptxas chose unasked when measured (40 and 56
/// registers); double, the reference precision, needs room for its 64-bit values instead (at
/// ptxas' own choice it spilled). The occlusion cut's check (CheckCut) spilled at 6 blocks of
/// one pixel a thread (42 registers): 5.
template <typename T, int Pixels, bool CheckCut>
constexpr int resident_blocks() {
    return std::is_same_v<T, double> ? 1 : Pixels == 1 ? (CheckCut ? 5 : 6) : 9;
}

// One block per task (task_of_block); Gaussians staged through shared memory a batch at a
// time; the block stops when all its pixels are done. StopAtMin: every task stops at
// kMinTransmittance (the tail threshold is the default), so the threshold is an immediate
// operand; a threshold chosen per block was reloaded from the constant bank and re-selected on
// every blend, 3 of its ~24 instructions a pixel (ncu, city_ring 4K, H200).
template <typename T, int Pixels, bool StopAtMin, bool CheckCut>
__global__ void __launch_bounds__(PixelLayout<Pixels>::kThreads, resident_blocks<T, Pixels, CheckCut>())
    rasterize_kernel(TaskGrid grid, const std::uint64_t* range_begin, const std::uint64_t* range_end,
                     const std::uint32_t* split_slot, const TaskLabel* labels, TaskCounters* counters,
                     const std::uint32_t* values, const Projected<T>* projected, View<T> view, Vec3<T> background,
                     T tail_transmittance, Partial<T>* partials, unsigned int* merge_tickets, PixelOutputs out,
                     const float* predicted_cut, float* recorded_cut) {
    using Layout = PixelLayout<Pixels>;
    constexpr int kThreads = Layout::kThreads, kStaged = kBatch / kThreads;
    constexpr unsigned kAll = 0xffffffffu;
    __shared__ Splat<T> batch[kBatch];
    __shared__ std::uint8_t reaches[kBatch];  // bit w: the Gaussian's 1/255 box reaches a pixel centre of warp block w
    // Per warp: how far into the list its pixels were all done (kNotDone: not yet), for the
    // occlusion cut's check and record (stop_depth).
    __shared__ std::uint32_t warp_done[kThreads / 32];
    // CheckCut: the tile's predicted cut and the batch's sort depths, where a ballot finds the
    // first Gaussian deeper than the cut.
    __shared__ float tile_cut;
    __shared__ float depths[CheckCut ? kBatch : 1];
    // A heavy list's 8-bit pixels, on their way to host memory (PixelOutputs::heavy_rgb8).
    __shared__ std::uint32_t heavy_words[kTilePixels * 3 / 4];
    std::uint32_t tile, index;
    if (!task_of_block(grid, labels, counters, blockIdx.x, tile, index)) return;  // uniform across the block
    const int tile_x = static_cast<int>(tile % view.tiles_x), tile_y = static_cast<int>(tile / view.tiles_x);
    const int thread = static_cast<int>(threadIdx.x);
    const int warp = thread / 32, lane = thread % 32;
    const Layout layout(warp);
    if (lane == 0) warp_done[warp] = kNotDone;
    const std::uint32_t warp_blocks = ((1u << Pixels) - 1u) << (warp * Pixels);
    T px[Layout::kCols], py[Layout::kRows];
#pragma unroll
    for (int c = 0; c < Layout::kCols; ++c)
        px[c] = static_cast<T>(tile_x * kTileSize + (layout.first_col + c) * kWarpBlockW + lane % kWarpBlockW) + T(0.5);
#pragma unroll
    for (int r = 0; r < Layout::kRows; ++r)
        py[r] = static_cast<T>(tile_y * kTileSize + (layout.first_row + r) * kWarpBlockH + lane / kWarpBlockW) + T(0.5);
    std::uint64_t begin = grid.shared_list ? 0 : range_begin[tile];
    std::uint64_t end = grid.shared_list ? grid.list_size : range_end[tile];
    // The whole list's length, once a tile; no one waits on the result: a reduction, not a round trip.
    if (thread == 0 && index == 0 && end > begin)
        atomicMax(&counters->longest_list, static_cast<unsigned long long>(end - begin));
    const std::uint32_t slot = grid.split ? split_slot[tile] : kNoSlot;
    if (slot != kNoSlot) subtask_range(begin, end, counters->split_k, index, begin, end);
    // Its pixels are not in the image the copy bands read: drawn as far as they care.
    if (thread == 0 && heavy_to_host(grid, blockIdx.x, slot, out) != kNoSlot) count_tile_drawn(out, tile_y);
    const T threshold = StopAtMin || index == 0 ? static_cast<T>(kMinTransmittance) : tail_transmittance;

    if (CheckCut) {
        // Its own barrier: an empty list skips the batch loop's, and its check below still reads the cut.
        if (thread == 0) tile_cut = slot == kNoSlot ? predicted_cut[tile] : INFINITY;
        __syncthreads();
    }
    SignedPixel<T> acc[Pixels];
#pragma unroll
    for (int b = 0; b < Pixels; ++b)
        acc[b] = SignedPixel<T>::starting(px[b % Layout::kCols] < static_cast<T>(view.width) &&
                                          py[b / Layout::kCols] < static_cast<T>(view.height));
    std::uint64_t start = begin;
    for (; start < end; start += kBatch) {
        if (__syncthreads_count(all_done(acc)) == kThreads) break;
#pragma unroll
        for (int k = 0; k < kStaged; ++k) {
            const int at = k * kThreads + thread;
            const std::uint64_t idx = start + at;
            if (idx >= end) break;
            const Projected<T>& p = projected[values[idx]];
            const std::uint32_t bits = grid.warp_skip ? blocks_reached(p, tile_x, tile_y) : 0xffu;
            batch[at] = Splat<T>{p.mean, AlphaMath<T>::staged_conic(p.conic), AlphaMath<T>::staged_opacity(p.opacity),
                                 p.colour};
            reaches[at] = static_cast<std::uint8_t>(bits);
            if (CheckCut) depths[at] = p.key_depth;
        }
        __syncthreads();
        const int count = end - start < kBatch ? static_cast<int>(end - start) : kBatch;
        // Warp-uniform from here: every lane walks the same Gaussians in list order.
        for (int base = 0; base < count; base += 32) {
            if (__all_sync(kAll, all_done(acc))) {
                if (lane == 0 && warp_done[warp] == kNotDone)
                    warp_done[warp] = static_cast<std::uint32_t>(start - begin) + static_cast<std::uint32_t>(base);
                break;
            }
            const int mine = base + lane;
            // The chunk's Gaussians whose lanes are set in `lanes`, in list order.
            const auto blend_lanes = [&](unsigned lanes) {
                while (lanes != 0) {
                    const Splat<T> s = batch[base + __ffs(lanes) - 1];  // by value: three 16-byte loads in float
                    lanes &= lanes - 1;
                    typename AlphaMath<T>::Row rows[Layout::kRows];
#pragma unroll
                    for (int r = 0; r < Layout::kRows; ++r) rows[r] = AlphaMath<T>::row(s, py[r]);
#pragma unroll
                    for (int b = 0; b < Pixels; ++b) {
                        // blend's tests decide; in float only rounding at alpha = 1/255 and the
                        // hardware exp's last bits can differ.
                        blend_signed(acc[b], AlphaMath<T>::alpha(s, px[b % Layout::kCols], rows[b / Layout::kCols]),
                                     s.colour, threshold);
                    }
                }
            };
            unsigned todo = __ballot_sync(kAll, mine < count && (reaches[mine] & warp_blocks) != 0);
            if (CheckCut) {
                // The occlusion cut's check, exact: every pixel done before the first Gaussian
                // deeper than the cut (the list is in sort-depth order), behind which the
                // Gaussians left out would have come. Later chunks repeat it harmlessly.
                const unsigned deeper = __ballot_sync(kAll, mine < count && depths[mine] > tile_cut);
                if (deeper != 0) {
                    const unsigned in_front = (1u << (__ffs(deeper) - 1)) - 1u;
                    blend_lanes(todo & in_front);
                    todo &= ~in_front;
                    if (!__all_sync(kAll, all_done(acc)) && lane == 0) atomicAdd(&counters->occlusion_misses, 1u);
                }
            }
            blend_lanes(todo);
        }
    }
    const bool finished = __all_sync(kAll, all_done(acc));
    // The list ran out with pixels to draw: what the cut left out lay in front of them.
    if (CheckCut && !finished && tile_cut < INFINITY && lane == 0) atomicAdd(&counters->occlusion_misses, 1u);
    if (recorded_cut) {  // uniform across the launch
        if (lane == 0 && finished && warp_done[warp] == kNotDone)
            warp_done[warp] = static_cast<std::uint32_t>((start < end ? start : end) - begin);
        __syncthreads();
        if (thread == 0 && index == 0)
            recorded_cut[tile] = slot == kNoSlot ? stop_depth<kThreads / 32>(warp_done, values + begin, projected)
                                                 : INFINITY;  // a split tile's stop is not known here
    }
    const std::uint32_t heavy = heavy_to_host(grid, blockIdx.x, slot, out);  // uniform across the block
#pragma unroll
    for (int b = 0; b < Pixels; ++b) {
        const int x = tile_x * kTileSize + (layout.first_col + b % Layout::kCols) * kWarpBlockW + lane % kWarpBlockW;
        const int y = tile_y * kTileSize + (layout.first_row + b / Layout::kCols) * kWarpBlockH + lane / kWarpBlockW;
        if (x >= view.width || y >= view.height) continue;
        const PixelAccumulator<T> pixel = acc[b].accumulator();
        const int rank = (y - tile_y * kTileSize) * kTileSize + (x - tile_x * kTileSize);  // row-major in the tile
        if (heavy != kNoSlot) {
            PixelOutputs staged{};
            staged.rgb8 = reinterpret_cast<std::uint8_t*>(heavy_words);
            write_pixel(pixel, background, static_cast<std::size_t>(rank), staged);
        } else if (slot == kNoSlot) {
            write_pixel(pixel, background, static_cast<std::size_t>(y) * view.width + x, out);
        } else {
            partials[(static_cast<std::size_t>(slot) + index) * kTilePixels + rank] =
                Partial<T>{pixel.colour, pixel.transmittance};
        }
    }
    if (heavy != kNoSlot) {
        // In words: the rasterizer's byte stores reach host memory at a sixth of the link's rate.
        __syncthreads();
        std::uint32_t* words = reinterpret_cast<std::uint32_t*>(out.heavy_rgb8) + heavy * (kTilePixels * 3 / 4);
        for (int w = thread; w < kTilePixels * 3 / 4; w += kThreads) words[w] = heavy_words[w];
        if (thread == 0) out.heavy_tiles[heavy] = tile;
    } else if (slot == kNoSlot) {
        tile_drawn(out, tile_y);
    } else {
        // The tile's last sub-task to finish merges it (merge.cuh). Its sub-task count is read
        // again here rather than kept from subtask_range, so no register holds it through the
        // blend loop (as heavy_to_host).
        const std::uint32_t parts = split_count(range_end[tile] - range_begin[tile], counters->split_k) + 1;
        if (last_to_arrive(&merge_tickets[tile], parts)) {  // uniform across the block
            merge_split_tile<T, kThreads>(tile, slot, parts, partials, view, background, out);
            if (thread == 0) merge_tickets[tile] = 0;
            tile_drawn(out, tile_y);
        }
    }
}

template <typename T, int Pixels>
void launch_rasterize(const RasterizeArgs<T>& a, cudaStream_t s) {
    const auto launch = [&](auto kernel) {
        kernel<<<static_cast<unsigned>(a.blocks), PixelLayout<Pixels>::kThreads, 0, s>>>(
            a.grid, a.range_begin, a.range_end, a.split_slot, a.labels, a.counters, a.values, a.projected, a.view,
            a.background, a.tail_transmittance, a.partials, a.merge_tickets, a.out, a.predicted_cut, a.recorded_cut);
    };
    const bool stop_at_min = a.tail_transmittance == static_cast<T>(kMinTransmittance);
    if constexpr (std::is_same_v<T, float>) {
        // A frame under the cut does not split (frame_occlusion.cu): its tasks all stop at the minimum.
        if (a.predicted_cut) {
            if (!stop_at_min) throw Error("rasterize: the occlusion cut's check needs every task to stop at 1e-4");
            launch(rasterize_kernel<T, Pixels, true, true>);
            return;
        }
    }
    if (a.predicted_cut) throw Error("rasterize: the occlusion cut is for float renders");
    if (stop_at_min)
        launch(rasterize_kernel<T, Pixels, true, false>);
    else
        launch(rasterize_kernel<T, Pixels, false, false>);
}

}  // namespace

template <typename T>
void rasterize(const RasterizeArgs<T>& a, cudaStream_t s) {
    if (a.blocks == 0) return;
    if (a.layout == RasterLayout::pixel_per_thread)
        launch_rasterize<T, 1>(a, s);
    else
        launch_rasterize<T, 2>(a, s);
    CATGS_CUDA_CHECK_LAUNCH("rasterize_kernel");
}

template <typename T>
std::uint64_t resident_tasks(RasterLayout layout) {
    int device = 0, sms = 0, blocks = 0;
    CATGS_CUDA_CHECK(cudaGetDevice(&device));
    CATGS_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
    if (layout == RasterLayout::pixel_per_thread)
        CATGS_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, rasterize_kernel<T, 1, true, false>,
                                                                       PixelLayout<1>::kThreads, 0));
    else
        CATGS_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, rasterize_kernel<T, 2, true, false>,
                                                                       PixelLayout<2>::kThreads, 0));
    return static_cast<std::uint64_t>(sms) * static_cast<std::uint64_t>(blocks);
}

template void rasterize(const RasterizeArgs<float>&, cudaStream_t);
template void rasterize(const RasterizeArgs<double>&, cudaStream_t);
template std::uint64_t resident_tasks<float>(RasterLayout);
template std::uint64_t resident_tasks<double>(RasterLayout);

}  // namespace catgs::cuda
