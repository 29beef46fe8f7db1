#include "rasterize.cuh"

#include "catgs/stages/footprint.hpp"
#include "catgs/stages/split.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

/// What the rasterizer reads of one Gaussian, staged in shared memory, with its conic and
/// min_power in AlphaMath's domain. min_power lets a pixel skip the exp where alpha cannot
/// reach 1/255 (most pixels of a tile lie outside a Gaussian's 1/255 ellipse): one log per pair
/// when staged instead of an exp per pixel. Aligned so that a warp reads it with 16-byte loads
/// (3 in float, not 10 of 4 bytes): the kernel is bound by the instructions it issues.
template <typename T>
struct alignas(16) Splat {
    Vec2<T> mean;
    Vec3<T> conic;
    T min_power;
    T opacity;
    Vec3<T> colour;
};

/// alpha's exponent and exponential. Double, the reference precision, keeps the reference's
/// own math (gaussian_power, the exact exp). Float works in base 2: the conic is staged
/// pre-multiplied by -log2(e)/2 (-log2(e) off the diagonal), so that a pixel's exponent is
/// 5 flops instead of 8 and alpha's exponential one ex2, the instruction __expf issues after its
/// own multiply by log2(e). ex2.approx.ftz is within 2^-22 relative; with the pre-scaling's
/// roundings the exponent is within a few ulp of log2(e) times the reference's, so alpha is
/// within about 1e-6 relative on the powers that can reach 1/255, far below the 8-bit output's
/// 2e-3.
template <typename T>
struct AlphaMath {
    __device__ static Vec3<T> staged_conic(Vec3<T> conic) { return conic; }
    __device__ static T staged_min_power(T opacity) { return min_visible_power(opacity); }
    __device__ static T power(const Splat<T>& s, T px, T py) { return gaussian_power(s.mean, s.conic, px, py); }
    __device__ T operator()(T power) const { return exp_of(power); }
};
template <>
struct AlphaMath<float> {
    static constexpr float kLog2E = 1.4426950408889634f;
    /// min_power is only a filter before blend's own alpha test: lowered by this many log2 units
    /// (alpha 0.007% below 1/255) so that no rounding of the staged values can drop a pixel
    /// whose alpha reaches 1/255.
    static constexpr float kMinPowerMargin = 1e-4f;
    __device__ static Vec3<float> staged_conic(Vec3<float> c) {
        return {-0.5f * kLog2E * c.x, -kLog2E * c.y, -0.5f * kLog2E * c.z};
    }
    __device__ static float staged_min_power(float opacity) {
        return kLog2E * min_visible_power(opacity) - kMinPowerMargin;
    }
    __device__ static float power(const Splat<float>& s, float px, float py) {
        const float dx = s.mean.x - px, dy = s.mean.y - py;
        return dx * fmaf(s.conic.y, dy, s.conic.x * dx) + s.conic.z * dy * dy;
    }
    __device__ float operator()(float power) const {
        float alpha_scale;
        asm("ex2.approx.ftz.f32 %0, %1;" : "=f"(alpha_scale) : "f"(power));
        return alpha_scale;
    }
};

// Each warp shades an 8x4 block of its 16x16 tile (2 across, 4 down). While a batch is staged,
// the thread staging a Gaussian also records which of the 8 blocks its 1/255 box reaches
// (visible_box; not in exact mode); each warp then walks only the Gaussians of its
// block, found 32 at a time with one ballot, instead of evaluating every Gaussian of the tile
// at each of its pixels. A skipped Gaussian has alpha < 1/255 at every pixel of the block, so
// the image is the one the full walk draws.
constexpr int kWarpBlockW = 8, kWarpBlockH = 4, kWarpBlocks = kTilePixels / 32;
static_assert(kTileSize == 16 && kWarpBlocks == 8 && kWarpBlockW * kWarpBlockH == 32,
              "the warp blocks must tile the 16x16 tile: 2 across, 4 down");

// One block per task, one thread per pixel, Gaussians staged through shared memory
// a batch at a time; the block stops when all its pixels are done. Blocks past the tiles are
// the extra sub-tasks; those beyond the atomic task count exit at once.
template <typename T>
__global__ void __launch_bounds__(kTilePixels)
    rasterize_kernel(TaskGrid grid, const std::uint64_t* range_begin, const std::uint64_t* range_end,
                     const std::uint32_t* split_slot, const TaskLabel* labels, const TaskCounters* counters,
                     const std::uint32_t* values, const Projected<T>* projected, View<T> view, Vec3<T> background,
                     T tail_transmittance, Partial<T>* partials, PixelOutputs out) {
    __shared__ Splat<T> batch[kTilePixels];
    __shared__ std::uint8_t reaches[kTilePixels];  // bit w: the Gaussian may draw in warp block w
    std::uint32_t tile, index = 0;
    if (blockIdx.x < grid.band_tiles) {
        tile = grid.first_tile + blockIdx.x;
    } else {
        const std::uint32_t extra = blockIdx.x - grid.band_tiles;
        if (!grid.split || extra >= counters->extra_tasks) return;  // uniform across the block
        tile = labels[extra].tile;
        index = labels[extra].index;
    }
    const int tile_x = static_cast<int>(tile % view.tiles_x), tile_y = static_cast<int>(tile / view.tiles_x);
    const int thread = threadIdx.y * kTileSize + threadIdx.x;
    const int warp = thread / 32, lane = thread % 32;
    const int x = tile_x * kTileSize + (warp % 2) * kWarpBlockW + lane % kWarpBlockW;
    const int y = tile_y * kTileSize + (warp / 2) * kWarpBlockH + lane / kWarpBlockW;
    const int rank = (y - tile_y * kTileSize) * kTileSize + (x - tile_x * kTileSize);  // the merge's pixel index
    const bool inside = x < view.width && y < view.height;
    std::uint64_t begin = grid.shared_list ? 0 : range_begin[tile];
    std::uint64_t end = grid.shared_list ? grid.list_size : range_end[tile];
    const std::uint32_t slot = grid.split ? split_slot[tile] : kNoSlot;
    if (slot != kNoSlot) subtask_range(begin, end, counters->split_k, index, begin, end);
    const T threshold = index > 0 ? tail_transmittance : static_cast<T>(kMinTransmittance);
    const T px = static_cast<T>(x) + T(0.5), py = static_cast<T>(y) + T(0.5);

    PixelAccumulator<T> acc;
    acc.done = !inside;
    for (std::uint64_t start = begin; start < end; start += kTilePixels) {
        if (__syncthreads_count(acc.done) == kTilePixels) break;
        const std::uint64_t idx = start + thread;
        if (idx < end) {
            const Projected<T>& p = projected[values[idx]];
            batch[thread] = Splat<T>{p.mean, AlphaMath<T>::staged_conic(p.conic),
                                     AlphaMath<T>::staged_min_power(p.opacity), p.opacity, p.colour};
            std::uint8_t bits = 0xff;
            if (grid.warp_skip) {
                const PixelBox<T> box = visible_box(p);
                bits = 0;
                for (int w = 0; w < kWarpBlocks; ++w) {
                    const T cx0 = static_cast<T>(tile_x * kTileSize + (w % 2) * kWarpBlockW) + T(0.5);
                    const T cy0 = static_cast<T>(tile_y * kTileSize + (w / 2) * kWarpBlockH) + T(0.5);
                    if (!box_misses_centres(box, cx0, cy0, cx0 + T(kWarpBlockW - 1), cy0 + T(kWarpBlockH - 1)))
                        bits |= static_cast<std::uint8_t>(1u << w);
                }
            }
            reaches[thread] = bits;
        }
        __syncthreads();
        const int count = end - start < kTilePixels ? static_cast<int>(end - start) : kTilePixels;
        // Warp-uniform from here: every lane walks the same Gaussians in list order.
        for (int base = 0; base < count; base += 32) {
            if (__all_sync(0xffffffffu, acc.done)) break;
            const int mine = base + lane;
            unsigned todo = __ballot_sync(0xffffffffu, mine < count && (reaches[mine] >> warp & 1u));
            while (todo != 0) {
                const int j = base + __ffs(todo) - 1;
                todo &= todo - 1;
                if (acc.done) continue;
                const Splat<T> s = batch[j];  // by value: three 16-byte loads in float
                const T power = AlphaMath<T>::power(s, px, py);
                // blend's tests decide (its power <= 0 holds in either domain); in float only
                // rounding at alpha = 1/255 and the hardware exp's last bits can differ.
                if (power >= s.min_power) blend_power_with(acc, power, s.opacity, s.colour, threshold, AlphaMath<T>{});
            }
        }
    }
    if (!inside) return;
    if (slot == kNoSlot) {
        write_pixel(acc, background, static_cast<std::size_t>(y) * view.width + x, out);
    } else {
        partials[(static_cast<std::size_t>(slot) + index) * kTilePixels + rank] =
            Partial<T>{acc.colour, acc.transmittance};
    }
}

}  // namespace

template <typename T>
void rasterize(const RasterizeArgs<T>& a, cudaStream_t s) {
    if (a.blocks == 0) return;
    rasterize_kernel<T><<<static_cast<unsigned>(a.blocks), dim3(kTileSize, kTileSize), 0, s>>>(
        a.grid, a.range_begin, a.range_end, a.split_slot, a.labels, a.counters, a.values, a.projected, a.view,
        a.background, a.tail_transmittance, a.partials, a.out);
    CATGS_CUDA_CHECK_LAUNCH("rasterize_kernel");
}

template void rasterize(const RasterizeArgs<float>&, cudaStream_t);
template void rasterize(const RasterizeArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
