// What the stage kernels of the CUDA backend share: launch sizes, the device view of the
// scene, the chunk-compacted index space, the device counters and the projection of one
// Gaussian against the window's poses. Included by the stage files (*.cu) only.
#pragma once

#include <cstdint>
#include <type_traits>

#include "catgs/constants.hpp"
#include "catgs/scene.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"

namespace catgs::cuda {

inline constexpr int kThreads = 256;                       // one Gaussian / pair / tile per thread
inline constexpr int kTilePixels = kTileSize * kTileSize;  // one thread per pixel of a tile

/// A tile that is not split has no partial slots.
inline constexpr std::uint32_t kNoSlot = 0xffffffffu;

/// Bands of tile rows copy_out copies the image in, each as soon as its tiles are drawn: with
/// 16 the copy left after the last pixel is drawn is a sixteenth of the image (about 30 us at
/// 4K), and the 16 waits cost the copy stream nothing measurable.
inline constexpr int kMaxCopyBands = 16;

/// The kernel instance of preprocess and keys for windows of 2..kUnrolledWindow poses, unrolled
/// over its poses (tiles.hpp); in double, which serves the tests only, it would spill, so double
/// takes the general instance.
template <typename T>
inline constexpr int kSmallWindow = std::is_same_v<T, float> ? kUnrolledWindow : kMaxWindow;

inline unsigned blocks_for(std::uint64_t n, int threads) {
    return static_cast<unsigned>((n + threads - 1) / threads);
}

struct DeviceSceneView {
    const float* positions;
    const float* scales;
    const float* rotations;
    const float* opacities;
    const float* sh;  // 16-byte aligned (preprocess reads degree-3 rows as float4)
    int sh_degree;
    std::uint64_t count;
};

/// A key frame's list totals, side by side so that one read-back brings them all to the host
/// before the depth sort: the host needs the selected count to size the sort, the pair total
/// to size keys and sort and to plan bands, and the chunks kept for the later stages' index
/// space. A read-back after chunk culling and another after the scan each stalled the GPU for
/// a round trip through the host every key frame.
struct ListTotals {
    unsigned long long pairs;        // preprocess: every slot's tiles summed (the scan's total)
    unsigned long long with_pairs;   // depth_order's select: the slots with pairs
    unsigned long long live_chunks;  // chunk_cull: the chunks some pose may see (when it ran)
};

/// ranges' blocks meet here: the last to finish writes the task counters and clears both
/// again for the next band.
struct RangesTally {
    unsigned int blocks_done;
    unsigned int nonempty_tiles;  // of the blocks done so far
};

/// Device-side counters, one allocation, read back once per frame. The frame part is reset
/// every frame; the task part belongs to the task list, which cached frames reuse from their
/// key frame, so only a key frame's (or a re-sorting cached frame's) ranges pass resets it.
struct FrameCounters {
    ListTotals lists;
    unsigned long long visible;         // Gaussians with tiles at the actual pose
    unsigned int min_depth_bits;        // float bits of the nearest depth (positive floats order as ints)
    unsigned int max_extent_bits;       // float bits of the largest non-full-grid half-extent
    double inverse_depth_sum;           // over visible Gaussians at the actual pose
    unsigned long long occluded;        // Gaussians the occlusion cut left out of the lists
    unsigned long long occluded_pairs;  // the pairs they would have had
    unsigned int chunk_cull_blocks;     // chunk_cull: its blocks done (the last one compacts)
    RangesTally ranges;
};
struct TaskCounters {
    unsigned long long rendered_pairs;  // ranges: pairs inside the grid (cached frames park others)
    unsigned int nonempty_tiles;        // ranges
    unsigned int split_k;               // the k used (auto or fixed)
    unsigned int extra_tasks;           // split: atomic task counter beyond the tiles
    unsigned int split_slots;           // split: partial slots handed out
    unsigned int split_tiles;           // split: tiles that were split
    unsigned int heavy_tiles;           // split: unsplit lists listed to run first (runs_first)
    unsigned long long longest_list;    // rasterize: the most pairs one tile list holds (frame-wide, last)
    unsigned int occlusion_misses;      // rasterize: tiles that did not stop in front of the occlusion cut
};
struct Counters {
    FrameCounters frame;
    TaskCounters tasks;
};

/// A new task list's counters, which split then fills: ranges sets them per band (on the
/// device, or by an upload under exact culling) beside its own two counts; longest_list and
/// occlusion_misses span the frame's bands and are cleared when a frame begins.
__host__ __device__ inline void start_task_list(TaskCounters& c, unsigned int split_k) {
    c.split_k = split_k;
    c.extra_tasks = 0;
    c.split_slots = 0;
    c.split_tiles = 0;
    c.heavy_tiles = 0;
}

/// Whether this block is the last of `arrivals` blocks to get here (CUDA's threadFenceReduction
/// idiom), the same answer in all its threads; every thread of every arriving block must call
/// it. `ticket` counts the blocks that got here: zero before the first, and the last one's to
/// clear for the next use. Each thread's earlier stores are fenced before its block takes a
/// ticket, so the last block sees every block's stores (chunk_cull reads all their flags,
/// merge all the sub-tasks' partials), and it fences again before reading them.
__device__ inline bool last_to_arrive(unsigned int* ticket, unsigned int arrivals) {
    __shared__ bool last;
    __threadfence();
    __syncthreads();
    if (threadIdx.x == 0) last = atomicAdd(ticket, 1u) == arrivals - 1;
    __syncthreads();
    const bool mine = last;
    if (mine) __threadfence();
    return mine;
}

/// last_to_arrive over the whole grid (one-dimensional).
__device__ inline bool last_block_done(unsigned int* ticket) {
    return last_to_arrive(ticket, gridDim.x);
}

/// A CaT-GS label: the tile and split index of an extra task.
struct TaskLabel {
    std::uint32_t tile, index;
};

/// A key frame's compacted index space: slot p belongs to chunk selected[p / kChunkGaussians],
/// so only the chunks that survived chunk culling are preprocessed, scanned and emitted.
/// Per-slot buffers (tile counts, sort depths, offsets) are indexed by slot; the projected
/// Gaussians and the pairs' values by Gaussian index. Slots past a short chunk's end are
/// empty (a count of 0).
struct ChunkSpace {
    const Chunk* chunks;
    const std::uint32_t* selected;
    std::uint64_t slots;
    /// Before the host reads back how many chunks chunk_cull kept (a key frame's preprocess and
    /// select): their count on the device, with `slots` covering every chunk. Null after.
    const unsigned long long* live_chunks = nullptr;

    __device__ std::uint64_t live_slots() const {
        return live_chunks ? static_cast<std::uint64_t>(*live_chunks) * kChunkGaussians : slots;
    }

    /// The Gaussian of slot p, or false for an empty slot.
    __device__ bool gaussian(std::uint64_t p, std::uint64_t& i) const {
        const Chunk& c = chunks[selected[p / kChunkGaussians]];
        i = c.begin + p % kChunkGaussians;
        return i < c.end;
    }
};

__device__ inline GaussianRef gaussian_ref(const DeviceSceneView& scene, std::uint64_t i) {
    const std::size_t sh_stride = 3u * static_cast<std::size_t>(sh_coefficient_count(scene.sh_degree));
    return GaussianRef{scene.positions + 3 * i, scene.scales + 3 * i,     scene.rotations + 4 * i,
                       scene.opacities[i],      scene.sh + sh_stride * i, scene.sh_degree};
}

/// Projects Gaussian i against the window's poses; returns the mask of valid poses. Shared by
/// the count (preprocess) and the keys pass so they cannot disagree.
template <typename T, int MaxWindow>
__device__ std::uint32_t project_window(const DeviceSceneView& scene, std::uint64_t i, const View<T>* views, int window,
                                        Projected<T>* poses) {
    const GaussianRef g = gaussian_ref(scene, i);
    std::uint32_t valid = 0;
#pragma unroll
    for (int k = 0; k < MaxWindow; ++k)
        if (k < window && project_geometry(g, views[k], poses[k])) valid |= 1u << k;
    return valid;
}

/// Where rasterize and merge write a finished pixel; any pointer may be null. A partial frame
/// (CudaRenderer::render_partial, what a shard of a sharded frame contributes) renders with a
/// zero background, so `rgb` holds the colour R exactly, and adds the transmittance A and
/// whether the blend stopped (partial_image.hpp).
struct PixelOutputs {
    std::uint8_t* rgb8;
    float* rgb;
    float* transmittance;
    std::uint8_t* stopped;
    /// Where the tiles drawn are counted for copy_out, per band of `rows_per_copy_band` tile
    /// rows (CopyStream::tiles_drawn); null when no copy waits on them.
    unsigned int* tiles_drawn;
    int rows_per_copy_band;
    /// Where the heavy lists (TaskGrid::max_heavy) put their 8-bit pixels instead, or null (they
    /// draw into rgb8 like the other tiles): host memory mapped into the device, a tile's 16x16
    /// pixels row-major at its place in the heavy list, and the tile at the same place in
    /// heavy_tiles. Such a tile counts as drawn when it starts, so no copy band waits for the
    /// frame's longest lists, which rasterize starts first and which finish last; copy_out puts
    /// their pixels into the image on the host. Only with rgb8 alone (rgb, transmittance and
    /// stopped null).
    std::uint8_t* heavy_rgb8;
    std::uint32_t* heavy_tiles;
};

/// Counts a tile of row `tile_y` drawn without a fence: for a tile whose pixels go elsewhere
/// (PixelOutputs::heavy_rgb8). One thread a block.
__device__ inline void count_tile_drawn(const PixelOutputs& out, int tile_y) {
    if (out.tiles_drawn) atomicAdd(&out.tiles_drawn[tile_y / out.rows_per_copy_band], 1u);
}

/// Called by every thread of a block that wrote the final pixels of a tile in row `tile_y`,
/// once its writes are issued: the tile counts as drawn only after every thread's writes are
/// visible to the device, which is what copy_out's copy engine reads (its wait is on the count).
__device__ inline void tile_drawn(const PixelOutputs& out, int tile_y) {
    if (!out.tiles_drawn) return;  // uniform: a frame's outputs are the same for every block
    __threadfence();
    __syncthreads();
    if (threadIdx.x == 0 && threadIdx.y == 0) count_tile_drawn(out, tile_y);
}

/// Writes a final pixel: C + T * background, to 8-bit and/or float outputs, and T and the stop
/// for a partial frame (rasterize, merge).
template <typename T>
__device__ void write_pixel(const PixelAccumulator<T>& acc, Vec3<T> background, std::size_t pixel,
                            const PixelOutputs& out) {
    const Vec3<T> c = finish_pixel(acc, background);
    const std::size_t o = 3 * pixel;
    if (out.rgb8) {
        out.rgb8[o] = quantize_8bit(c.x);
        out.rgb8[o + 1] = quantize_8bit(c.y);
        out.rgb8[o + 2] = quantize_8bit(c.z);
    }
    if (out.rgb) {
        out.rgb[o] = static_cast<float>(c.x);
        out.rgb[o + 1] = static_cast<float>(c.y);
        out.rgb[o + 2] = static_cast<float>(c.z);
    }
    if (out.transmittance) out.transmittance[pixel] = static_cast<float>(acc.transmittance);
    if (out.stopped) out.stopped[pixel] = acc.done ? 1 : 0;
}

}  // namespace catgs::cuda
