#include "cuda_renderer.hpp"

#include <cub/block/block_reduce.cuh>
#include <cuda/functional>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "catgs/stages/blend.hpp"
#include "catgs/stages/chunks.hpp"
#include "catgs/stages/envelope.hpp"
#include "catgs/stages/footprint.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/tiles.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_check.hpp"
#include "device_buffer.hpp"

namespace catgs::cuda {
namespace {

constexpr int kThreads = 256;                        // one Gaussian / pair / tile per thread
constexpr int kTilePixels = kTileSize * kTileSize;  // one thread per pixel of a tile

/// Bytes of device memory one tile-Gaussian pair needs: key + value, twice (sort buffers).
constexpr std::uint64_t kBytesPerPair = 2 * (sizeof(std::uint64_t) + sizeof(std::uint32_t));
/// Share of free device memory the automatic pair budget may take (the rest stays for the
/// scene, other renderers and CUB's temporary storage).
constexpr double kAutoPairMemoryShare = 0.25;
/// A tile that is not split has no partial slots.
constexpr std::uint32_t kNoSlot = 0xffffffffu;
/// The speculative near plane never goes below this, so 1/z stays finite.
constexpr double kMinSpeculativeNear = 1e-3;

struct DeviceSceneView {
    const float* positions;
    const float* scales;
    const float* rotations;
    const float* opacities;
    const float* sh;
    int sh_degree;
    std::uint64_t count;
};

/// What the rasterizer reads of one Gaussian, staged in shared memory. min_power lets a
/// pixel skip the exp where alpha cannot reach 1/255 (most pixels of a tile lie outside a
/// Gaussian's 1/255 ellipse): one log per pair when staged instead of an exp per pixel.
template <typename T>
struct Splat {
    Vec2<T> mean;
    Vec3<T> conic;
    T opacity;
    T min_power;
    Vec3<T> colour;
};

/// Device-side counters, one allocation, read back once per frame. The frame part is reset
/// every frame; the task part belongs to the task list, which cached frames reuse from their
/// key frame, so only a key frame's split pass resets it.
struct FrameCounters {
    unsigned long long visible;       // Gaussians with tiles at the actual pose
    unsigned int min_depth_bits;      // float bits of the nearest depth (positive floats order as ints)
    unsigned int max_extent_bits;     // float bits of the largest non-full-grid half-extent
    double inverse_depth_sum;         // over visible Gaussians at the actual pose
};
struct TaskCounters {
    unsigned long long rendered_pairs;  // ranges: pairs inside the grid (cached frames park others)
    unsigned int nonempty_tiles;      // ranges
    unsigned int split_k;             // the k used (auto or fixed)
    unsigned int extra_tasks;         // split: atomic task counter beyond the tiles
    unsigned int split_slots;         // split: partial slots handed out
    unsigned int split_tiles;         // split: tiles that were split
};
struct Counters {
    FrameCounters frame;
    TaskCounters tasks;
};

/// A CaT-GS label: the tile and split index of an extra task.
struct TaskLabel {
    std::uint32_t tile, index;
};

int bit_width(std::uint64_t v) {
    int bits = 0;
    while (v) {
        ++bits;
        v >>= 1;
    }
    return bits;
}

unsigned blocks_for(std::uint64_t n, int threads) { return static_cast<unsigned>((n + threads - 1) / threads); }

/// A key frame's compacted index space: slot p belongs to chunk selected[p / kChunkGaussians],
/// so only the chunks that survived chunk culling are preprocessed, scanned and emitted.
/// Per-slot buffers (tile counts, sort depths, offsets) are indexed by slot; the projected
/// Gaussians and the pairs' values by Gaussian index. Slots past a short chunk's end are
/// empty (a count of 0).
struct ChunkSpace {
    const Chunk* chunks;
    const std::uint32_t* selected;
    std::uint64_t slots;

    /// The Gaussian of slot p, or false for an empty slot.
    __device__ bool gaussian(std::uint64_t p, std::uint64_t& i) const {
        const Chunk& c = chunks[selected[p / kChunkGaussians]];
        i = c.begin + p % kChunkGaussians;
        return i < c.end;
    }
};

// Stage 0: flag the chunks that some pose of the window may see (stages/chunks.hpp).
template <typename T>
__global__ void chunk_cull_kernel(const Chunk* chunks, std::uint32_t count, const View<T>* views, int window, T guard,
                                  T guard_translation, std::uint8_t* flags) {
    const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c < count) flags[c] = chunk_in_window(chunks[c], views, window, guard, guard_translation) ? 1 : 0;
}

__device__ GaussianRef gaussian_ref(const DeviceSceneView& scene, std::uint64_t i) {
    const std::size_t sh_stride = 3u * static_cast<std::size_t>(sh_coefficient_count(scene.sh_degree));
    return GaussianRef{scene.positions + 3 * i, scene.scales + 3 * i, scene.rotations + 4 * i, scene.opacities[i],
                       scene.sh + sh_stride * i, scene.sh_degree};
}

/// Projects Gaussian i against the window's poses; returns the mask of valid poses. Shared by
/// the count (preprocess) and the emit pass so they cannot disagree.
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

// Stage 1: count the tiles of the union of each Gaussian's footprints over the window
// (MaxWindow = 1: the plain single-frame pipeline) and project it at the actual pose for
// rasterizing (opacity 0 when culled there). Key frames of the cache also reduce what the
// planner needs: nearest depth, mean inverse depth, largest footprint.
template <typename T, int MaxWindow, bool Summarize>
__global__ void preprocess_kernel(DeviceSceneView scene, ChunkSpace space, const View<T>* views, int window, View<T> actual,
                                  bool reproject_actual, Culling culling, T guard, T guard_translation,
                                  Projected<T>* projected, std::uint64_t* touched, float* sort_depth,
                                  FrameCounters* counters) {
    const std::uint64_t slot = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    bool visible = false;
    float nearest = INFINITY, extent = 0.0f;
    double inverse_depth = 0.0;
    std::uint64_t i = 0;
    const bool present = slot < space.slots && space.gaussian(slot, i);
    if (slot < space.slots && !present) touched[slot] = 0;
    if (present) {
        Projected<T> poses[MaxWindow];
        const std::uint32_t valid = project_window<T, MaxWindow>(scene, i, views, window, poses);
        const std::uint32_t tiles =
            for_each_window_tile<MaxWindow>(poses, valid, window, culling, guard, views[0], [](std::uint32_t) {});
        touched[slot] = tiles;
        if (Summarize && tiles == 0 && guard > T(0) && culling != Culling::exact && (valid & 1u)) {
            // As CpuRenderer::preprocess: in no list, but able to enter the image within the envelope.
            const float* sc = gaussian_ref(scene, i).scale;
            T bound = T(0);
            if (uncached_can_enter(poses[0], culling, views[0], guard, guard_translation,
                                   static_cast<T>(fmaxf(fabsf(sc[0]), fmaxf(fabsf(sc[1]), fabsf(sc[2])))), bound)) {
                nearest = fminf(nearest, static_cast<float>(poses[0].depth));
                extent = fmaxf(extent, static_cast<float>(bound));
            }
        }
        if (tiles > 0) {
            sort_depth[slot] = poses[first_valid_pose(valid)].key_depth;
            // At the actual pose: pose 0's geometry unless the window lowered the near plane;
            // the SH colour only now that the Gaussian is known to touch a tile.
            const GaussianRef g = gaussian_ref(scene, i);
            Projected<T> p = poses[0];
            bool at_actual = (valid & 1u) != 0;
            if (reproject_actual) at_actual = project_geometry(g, actual, p);
            if (at_actual)
                shade_gaussian(g, actual, p);
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
                    // As CpuRenderer::summarize: only a Gaussian in every list cannot gain tiles.
                    if (culling != Culling::exact &&
                        tiles < static_cast<std::uint32_t>(actual.tiles_x) * static_cast<std::uint32_t>(actual.tiles_y)) {
                        // Current 2D extent, or the projected 3D size (needles seen end-on).
                        const Vec2<T> e = footprint_extent(p, culling);
                        const float* sc = g.scale;
                        const T bound = footprint_bound_px(p, culling, static_cast<T>(fmaxf(sc[0], fmaxf(sc[1], sc[2]))),
                                                           actual.fx > actual.fy ? actual.fx : actual.fy);
                        extent = fmaxf(0.0f, fmaxf(fmaxf(static_cast<float>(e.x), static_cast<float>(e.y)),
                                                   static_cast<float>(bound)));
                    }
                }
            }
        }
    }
    const int block_visible = __syncthreads_count(visible);
    if (threadIdx.x == 0 && block_visible > 0)
        atomicAdd(&counters->visible, static_cast<unsigned long long>(block_visible));
    if (Summarize) {
        using FloatReduce = cub::BlockReduce<float, kThreads>;
        using DoubleReduce = cub::BlockReduce<double, kThreads>;
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

// Count within a band of tile rows (overflow path only), through the same predicate.
template <typename T>
__global__ void count_band_kernel(ChunkSpace space, const Projected<T>* projected, const std::uint64_t* visible,
                                  View<T> view, Culling culling, TileRows rows, std::uint64_t* touched) {
    const std::uint64_t slot = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (slot >= space.slots) return;
    std::uint64_t i = 0;
    touched[slot] = visible[slot] == 0 || !space.gaussian(slot, i)
                        ? 0
                        : for_each_touched_tile(projected[i], culling, view, [](std::uint32_t) {}, rows);
}

// Stage 3: keys at each Gaussian's offset, in Gaussian order, so that the stable sort keeps
// index order for equal depths. `capacity` bounds every write.
template <typename T, int MaxWindow>
__global__ void __launch_bounds__(kThreads)
    emit_kernel(DeviceSceneView scene, ChunkSpace space, const View<T>* views, int window, Culling culling, T guard,
                const Projected<T>* projected, const std::uint64_t* touched, const std::uint64_t* offsets,
                const float* sort_depth, TileRows rows, bool band, bool reprojected, std::uint64_t capacity,
                std::uint64_t* keys, std::uint32_t* values) {
    const std::uint64_t p = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    std::uint64_t i = 0;
    if (p >= space.slots || touched[p] == 0 || !space.gaussian(p, i)) return;
    std::uint64_t slot = offsets[p];
    const std::uint64_t end = min(slot + touched[p], capacity);
    const float depth = sort_depth[p];
    auto emit = [&](std::uint32_t tile) {
        if (slot < end) {
            keys[slot] = make_sort_key(tile, depth);
            values[slot] = static_cast<std::uint32_t>(i);
        }
        ++slot;
    };
    if (band || (MaxWindow == 1 && !reprojected)) {
        // One pose whose geometry preprocess stored (bands: caching is off for them).
        for_each_touched_tile(projected[i], culling, views[0], emit, rows);
        return;
    }
    Projected<T> poses[MaxWindow];
    const std::uint32_t valid = project_window<T, MaxWindow>(scene, i, views, window, poses);
    for_each_window_tile<MaxWindow>(poses, valid, window, culling, guard, views[0], emit, rows);
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
        visible = project_gaussian(gaussian_ref(scene, i), actual, p);
        if (!visible) p.opacity = T(0);
        projected[i] = p;
    }
    const int block_visible = __syncthreads_count(visible);
    if (threadIdx.x == 0 && block_visible > 0)
        atomicAdd(&counters->visible, static_cast<unsigned long long>(block_visible));
}

// Cached frame, re-sort: every pair the key frame emitted keeps its tile if the footprint at
// the current pose still touches it (the single-frame predicate) and takes the current depth;
// otherwise it is parked past the grid (sorts last, no range covers it). Reading the pairs in
// emission (Gaussian) order makes the stable sort order equal depths by index, as a full
// render does.
template <typename T>
__global__ void rekey_kernel(std::uint64_t n, const std::uint64_t* emitted_keys, const std::uint32_t* emitted_values,
                             const Projected<T>* projected, View<T> view, Culling culling, std::uint64_t* keys,
                             std::uint32_t* values) {
    const std::uint64_t j = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (j >= n) return;
    const std::uint32_t tiles = static_cast<std::uint32_t>(view.tiles_x) * view.tiles_y;
    const std::uint32_t index = emitted_values[j];
    const Projected<T>& p = projected[index];
    const std::uint32_t tile = key_tile(emitted_keys[j]);
    // Exact culling shares one list among all tiles: nothing to filter.
    const bool keep = culling == Culling::exact || (p.opacity > T(0) && touches_tile(p, culling, view, tile));
    keys[j] = make_sort_key(keep ? tile : parked_tile(tiles), p.key_depth);
    values[j] = index;
}

// Stage 5: tile ranges; ids beyond the grid are ignored rather than written (defence against
// a corrupted key, the failure mode of gaussian-splatting#781).
__global__ void ranges_kernel(std::uint64_t n, const std::uint64_t* keys, std::uint32_t tiles,
                              std::uint64_t* range_begin, std::uint64_t* range_end, TaskCounters* counters) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    bool first = false, inside = false;
    if (i < n) {
        const std::uint32_t tile = key_tile(keys[i]);
        inside = tile < tiles;
        if (inside) {
            first = i == 0 || key_tile(keys[i - 1]) != tile;
            if (first) range_begin[tile] = i;
            if (i + 1 == n || key_tile(keys[i + 1]) != tile) range_end[tile] = i + 1;
        }
    }
    const int block_first = __syncthreads_count(first);
    const int block_inside = __syncthreads_count(inside);
    if (threadIdx.x == 0 && block_first > 0) atomicAdd(&counters->nonempty_tiles, static_cast<unsigned>(block_first));
    if (threadIdx.x == 0 && block_inside > 0)
        atomicAdd(&counters->rendered_pairs, static_cast<unsigned long long>(block_inside));
}

// Automatic k from this frame's lists: max(floor, factor x mean non-empty length).
__global__ void auto_split_kernel(TaskCounters* counters) {
    const unsigned nonempty = counters->nonempty_tiles;
    const double mean = nonempty ? static_cast<double>(counters->rendered_pairs) / nonempty : 0.0;
    counters->split_k = max(kAutoSplitFloor, static_cast<unsigned>(ceil(kAutoSplitFactor * mean)));
}

// Stage 6 (CaT-GS Algorithm 1): a tile longer than k keeps its remainder-sized first
// sub-task as task `tile`; its split_num extra sub-tasks are appended through the atomic
// task counter with (tile, split index) labels. Split tiles get split_num + 1 partial slots
// and a place in the merge list.
__global__ void split_kernel(std::uint32_t tiles, const std::uint64_t* range_begin, const std::uint64_t* range_end,
                             std::uint64_t max_extra, TaskCounters* counters, std::uint32_t* split_slot,
                             TaskLabel* labels, std::uint32_t* split_tiles) {
    const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
    if (t >= tiles) return;
    const std::uint32_t splits = split_count(range_end[t] - range_begin[t], counters->split_k);
    if (splits == 0) {
        split_slot[t] = kNoSlot;
        return;
    }
    const std::uint32_t first_extra = atomicAdd(&counters->extra_tasks, splits);
    split_slot[t] = atomicAdd(&counters->split_slots, splits + 1);
    split_tiles[atomicAdd(&counters->split_tiles, 1u)] = t;
    for (std::uint32_t i = 1; i <= splits; ++i)
        if (first_extra + i - 1 < max_extra) labels[first_extra + i - 1] = TaskLabel{t, i};
}

/// Writes a final pixel: C + T * background, to 8-bit and/or float outputs.
template <typename T>
__device__ void write_pixel(const PixelAccumulator<T>& acc, Vec3<T> background, std::size_t o, std::uint8_t* out_rgb8,
                            float* out_float) {
    const Vec3<T> c = finish_pixel(acc, background);
    if (out_rgb8) {
        out_rgb8[o] = quantize_8bit(c.x);
        out_rgb8[o + 1] = quantize_8bit(c.y);
        out_rgb8[o + 2] = quantize_8bit(c.z);
    }
    if (out_float) {
        out_float[o] = static_cast<float>(c.x);
        out_float[o + 1] = static_cast<float>(c.y);
        out_float[o + 2] = static_cast<float>(c.z);
    }
}

struct TaskGrid {
    std::uint32_t first_tile;  // tiles of this band: [first_tile, first_tile + band_tiles)
    std::uint32_t band_tiles;
    bool split;                // split_slot / labels / partials are valid
    bool shared_list;          // exact culling: one list for every tile
    std::uint64_t list_size;
    bool warp_skip;            // warps skip Gaussians whose visible_box misses their block
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

// Stage 7: one block per task, one thread per pixel, Gaussians staged through shared memory
// a batch at a time; the block stops when all its pixels are done. Blocks past the tiles are
// the extra sub-tasks; those beyond the atomic task count exit at once.
template <typename T>
__global__ void __launch_bounds__(kTilePixels)
    rasterize_kernel(TaskGrid grid, const std::uint64_t* range_begin, const std::uint64_t* range_end,
                     const std::uint32_t* split_slot, const TaskLabel* labels, const TaskCounters* counters,
                     const std::uint32_t* values, const Projected<T>* projected, View<T> view, Vec3<T> background,
                     T tail_transmittance, Partial<T>* partials, std::uint8_t* out_rgb8, float* out_float) {
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
            batch[thread] = Splat<T>{p.mean, p.conic, p.opacity, min_visible_power(p.opacity), p.colour};
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
                const Splat<T>& s = batch[j];
                const T power = gaussian_power(s.mean, s.conic, px, py);
                // Only rounding at alpha = 1/255 can differ from blend_gaussian's own test.
                if (power >= s.min_power) blend_power(acc, power, s.opacity, s.colour, threshold);
            }
        }
    }
    if (!inside) return;
    if (slot == kNoSlot) {
        write_pixel(acc, background, 3 * (static_cast<std::size_t>(y) * view.width + x), out_rgb8, out_float);
    } else {
        partials[(static_cast<std::size_t>(slot) + index) * kTilePixels + rank] = Partial<T>{acc.colour, acc.transmittance};
    }
}

// Stage 8: composite each split tile's sub-tasks front to back.
template <typename T>
__global__ void __launch_bounds__(kTilePixels)
    merge_kernel(const std::uint32_t* split_tiles, const std::uint32_t* split_slot, const std::uint64_t* range_begin,
                 const std::uint64_t* range_end, const TaskCounters* counters, const Partial<T>* partials, View<T> view,
                 Vec3<T> background, std::uint8_t* out_rgb8, float* out_float) {
    if (blockIdx.x >= counters->split_tiles) return;
    const std::uint32_t tile = split_tiles[blockIdx.x];
    const int x = static_cast<int>(tile % view.tiles_x) * kTileSize + threadIdx.x;
    const int y = static_cast<int>(tile / view.tiles_x) * kTileSize + threadIdx.y;
    if (x >= view.width || y >= view.height) return;
    const std::uint32_t parts = split_count(range_end[tile] - range_begin[tile], counters->split_k) + 1;
    const std::size_t base = static_cast<std::size_t>(split_slot[tile]) * kTilePixels + threadIdx.y * kTileSize + threadIdx.x;
    MergeState<T> m;
    for (std::uint32_t i = 0; i < parts && !m.done; ++i) merge_partial(m, partials[base + static_cast<std::size_t>(i) * kTilePixels]);
    PixelAccumulator<T> acc;
    acc.colour = m.colour;
    acc.transmittance = m.transmittance;
    write_pixel(acc, background, 3 * (static_cast<std::size_t>(y) * view.width + x), out_rgb8, out_float);
}

/// Device events around the stages of one frame.
enum Stage {
    kStart, kPreprocess, kScan, kBandCount, kBandScan, kEmit, kSort, kRanges, kSplit, kRasterize, kMerge, kCopyStart,
    kCopy, kStageCount
};

template <typename V>
V* alloc_copy(const std::vector<V>& host, cudaStream_t stream, std::size_t& bytes) {
    V* d = nullptr;
    const std::size_t n = std::max<std::size_t>(host.size(), 1) * sizeof(V);
    CATGS_CUDA_CHECK(cudaMalloc(&d, n));
    if (!host.empty())
        CATGS_CUDA_CHECK(cudaMemcpyAsync(d, host.data(), host.size() * sizeof(V), cudaMemcpyHostToDevice, stream));
    bytes += n;
    return d;
}

}  // namespace

bool device_available(std::string* reason) {
    int count = 0;
    const cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess || count == 0) {
        if (reason) *reason = status != cudaSuccess ? cudaGetErrorString(status) : "no CUDA device";
        cudaGetLastError();  // clear the error state for later calls
        return false;
    }
    return true;
}

DeviceScene::DeviceScene(const Scene& scene, cudaStream_t stream)
    : count_(scene.count()), sh_degree_(scene.sh_degree), origin_(scene.origin) {
    scene.check_consistent("scene upload");
    try {
        positions_ = alloc_copy(scene.positions, stream, bytes_);
        scales_ = alloc_copy(scene.scales, stream, bytes_);
        rotations_ = alloc_copy(scene.rotations, stream, bytes_);
        opacities_ = alloc_copy(scene.opacities, stream, bytes_);
        sh_ = alloc_copy(scene.sh, stream, bytes_);
        // An unpartitioned scene: runs of kChunkGaussians with infinite boxes, so that every
        // frame walks one compacted index space and culls nothing.
        partitioned_ = !scene.chunks.empty();
        std::vector<Chunk> chunks = scene.chunks;
        if (!partitioned_) {
            constexpr float kInf = std::numeric_limits<float>::infinity();
            for (std::size_t b = 0; b < count_; b += kChunkGaussians) {
                Chunk c;
                for (int a = 0; a < 3; ++a) {
                    c.lo[a] = -kInf;
                    c.hi[a] = kInf;
                }
                c.radius = kInf;
                c.begin = static_cast<std::uint32_t>(b);
                c.end = static_cast<std::uint32_t>(std::min<std::size_t>(count_, b + kChunkGaussians));
                chunks.push_back(c);
            }
        }
        chunk_count_ = static_cast<std::uint32_t>(chunks.size());
        std::vector<std::uint32_t> ids(chunks.size());
        for (std::size_t c = 0; c < ids.size(); ++c) ids[c] = static_cast<std::uint32_t>(c);
        chunks_ = alloc_copy(chunks, stream, bytes_);
        all_chunks_ = alloc_copy(ids, stream, bytes_);
        CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
    } catch (...) {
        free_all();
        throw;
    }
}

void DeviceScene::free_all() {
    for (float* p : {positions_, scales_, rotations_, opacities_, sh_}) cudaFree(p);
    cudaFree(chunks_);
    cudaFree(all_chunks_);
}

DeviceScene::~DeviceScene() { free_all(); }

template <typename T>
struct CudaRenderer<T>::Impl {
    cudaStream_t stream = nullptr;
    bool own_stream = false;
    CudaLimits limits;
    std::shared_ptr<const DeviceScene> scene;
    cudaEvent_t events[kStageCount] = {};
    FramePlanner planner;
    bool cache_valid = false;           // the lists on the device belong to the current window
    std::uint64_t cached_pairs = 0;     // pairs of the cached lists
    bool cached_split = false;          // the cached task list has split tiles
    bool cached_emitted = false;        // emitted_keys/values hold the key frame's pairs (re-sort)
    ChunkSpace key_space{};             // the key frame's compacted index space (cached frames reuse it)
    std::uint64_t key_chunks_culled = 0;

    // Arenas, one per stage buffer.
    DeviceArray<View<T>> views;            // the window's poses
    DeviceArray<std::uint8_t> chunk_flags;  // chunk culling: 1 = some pose may see the chunk
    DeviceArray<std::uint32_t> selected;    // chunk culling: the visible chunks, in scene order
    DeviceArray<std::uint32_t> selected_count;
    DeviceArray<std::uint8_t> select_temp;
    DeviceArray<Projected<T>> projected;   // preprocess: at the actual pose
    DeviceArray<std::uint64_t> visible;    // band path: full-frame tile counts
    DeviceArray<std::uint64_t> touched;    // count for the current pass, with a trailing 0
    DeviceArray<float> sort_depth;         // preprocess: the depth keys sort by
    DeviceArray<Counters> counters;
    DeviceArray<std::uint64_t> offsets;    // scan: exclusive sum; offsets[n] = pass total
    DeviceArray<std::uint8_t> scan_temp;
    DeviceArray<std::uint64_t> keys[2];    // emit + sort (double buffer)
    DeviceArray<std::uint32_t> values[2];
    DeviceArray<std::uint64_t> emitted_keys;  // a key frame's pairs in emission order (cache)
    DeviceArray<std::uint32_t> emitted_values;
    int current = 0;                       // which of keys/values holds the sorted pairs
    DeviceArray<std::uint8_t> sort_temp;
    DeviceArray<std::uint64_t> range_begin, range_end;  // ranges
    DeviceArray<std::uint32_t> split_slot, split_tiles;  // split
    DeviceArray<TaskLabel> labels;
    DeviceArray<Partial<T>> partials;      // rasterize: sub-task (R, A)
    DeviceArray<std::uint8_t> image_rgb8;  // rasterize / merge
    DeviceArray<float> image_float;
    View<T>* host_views = nullptr;         // pinned staging of the window's poses
    std::uint64_t* host_total = nullptr;   // pinned, one read-back per pass
    std::uint32_t* host_selected = nullptr;  // pinned, the visible chunk count of a key frame
    Counters* host_counters = nullptr;
    std::uint8_t* host_rgb8 = nullptr;     // pinned staging for copy-out
    float* host_float = nullptr;
    std::size_t host_rgb8_bytes = 0, host_float_bytes = 0;

    std::size_t arena_bytes() const {
        return views.bytes() + chunk_flags.bytes() + selected.bytes() + selected_count.bytes() + select_temp.bytes() +
               projected.bytes() + visible.bytes() + touched.bytes() + sort_depth.bytes() +
               counters.bytes() + offsets.bytes() + scan_temp.bytes() + keys[0].bytes() + keys[1].bytes() +
               values[0].bytes() + values[1].bytes() + emitted_keys.bytes() + emitted_values.bytes() +
               sort_temp.bytes() + range_begin.bytes() + range_end.bytes() +
               split_slot.bytes() + split_tiles.bytes() + labels.bytes() + partials.bytes() + image_rgb8.bytes() +
               image_float.bytes();
    }

    std::uint64_t pair_budget() {
        if (limits.max_pairs == 0) {
            std::size_t free_bytes = 0, total_bytes = 0;
            CATGS_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
            limits.max_pairs = std::max<std::uint64_t>(
                1, static_cast<std::uint64_t>(kAutoPairMemoryShare * static_cast<double>(free_bytes) / kBytesPerPair));
        }
        return limits.max_pairs;
    }

    /// Exclusive scan of touched[0..n] into offsets; returns the pass total (one read-back).
    std::uint64_t scan(std::uint64_t n) {
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, touched.data(), offsets.data(),
                                                       static_cast<std::int64_t>(n + 1), stream));
        scan_temp.reserve(temp_bytes, stream);
        CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_temp.data(), temp_bytes, touched.data(), offsets.data(),
                                                       static_cast<std::int64_t>(n + 1), stream));
        CATGS_CUDA_CHECK(cudaMemcpyAsync(host_total, offsets.data() + n, sizeof(std::uint64_t),
                                         cudaMemcpyDeviceToHost, stream));
        CATGS_CUDA_CHECK(cudaStreamSynchronize(stream));
        return *host_total;
    }

    /// Radix sort of the first `pairs` pairs in keys/values[current] over the used bits.
    void sort(std::uint64_t pairs, int tile_bits) {
        if (pairs <= 1) return;
        cub::DoubleBuffer<std::uint64_t> kb(keys[current].data(), keys[1 - current].data());
        cub::DoubleBuffer<std::uint32_t> vb(values[current].data(), values[1 - current].data());
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb, static_cast<std::int64_t>(pairs), 0,
                                                         32 + tile_bits, stream));
        sort_temp.reserve(temp_bytes, stream);
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(sort_temp.data(), temp_bytes, kb, vb,
                                                         static_cast<std::int64_t>(pairs), 0, 32 + tile_bits, stream));
        current = kb.selector == 0 ? current : 1 - current;
    }
};

template <typename T>
CudaRenderer<T>::CudaRenderer(cudaStream_t stream, CudaLimits limits) : impl_(std::make_unique<Impl>()) {
    impl_->limits = limits;
    if (stream) {
        impl_->stream = stream;
    } else {
        CATGS_CUDA_CHECK(cudaStreamCreateWithFlags(&impl_->stream, cudaStreamNonBlocking));
        impl_->own_stream = true;
    }
    for (auto& e : impl_->events) CATGS_CUDA_CHECK(cudaEventCreate(&e));
    CATGS_CUDA_CHECK(cudaMallocHost(&impl_->host_total, sizeof(std::uint64_t)));
    CATGS_CUDA_CHECK(cudaMallocHost(&impl_->host_selected, sizeof(std::uint32_t)));
    CATGS_CUDA_CHECK(cudaMallocHost(&impl_->host_counters, sizeof(Counters)));
    CATGS_CUDA_CHECK(cudaMallocHost(&impl_->host_views, kMaxWindow * sizeof(View<T>)));
    impl_->counters.reserve(1, impl_->stream);
    impl_->views.reserve(kMaxWindow, impl_->stream);
}

template <typename T>
CudaRenderer<T>::~CudaRenderer() {
    if (!impl_) return;
    cudaStreamSynchronize(impl_->stream);
    for (auto& e : impl_->events) cudaEventDestroy(e);
    cudaFreeHost(impl_->host_total);
    cudaFreeHost(impl_->host_selected);
    cudaFreeHost(impl_->host_counters);
    cudaFreeHost(impl_->host_views);
    cudaFreeHost(impl_->host_rgb8);
    cudaFreeHost(impl_->host_float);
    if (impl_->own_stream) cudaStreamDestroy(impl_->stream);
}

template <typename T>
void CudaRenderer<T>::set_scene(std::shared_ptr<const DeviceScene> scene) {
    impl_->scene = std::move(scene);
    reset_cache();
}

template <typename T>
void CudaRenderer<T>::reset_cache() {
    impl_->planner.reset();
    impl_->cache_valid = false;
}

template <typename T>
void CudaRenderer<T>::set_limits(CudaLimits limits) {
    impl_->limits = limits;
}

template <typename T>
cudaStream_t CudaRenderer<T>::stream() const {
    return impl_->stream;
}

template <typename T>
FrameStats CudaRenderer<T>::render(const Camera& camera, const RenderOptions& options, ImageRGB8* rgb8,
                                   ImageF* rgb_float, const FrameHints* hints) {
    Impl& m = *impl_;
    if (!m.scene) throw Error("cuda renderer: no scene set");
    validate(camera.intrinsics, "camera '" + camera.name + "'");
    const DeviceScene& scene = *m.scene;
    const View<T> view = make_view<T>(camera, scene.origin(), options.near_plane);
    const std::uint64_t n = scene.count();
    const std::uint64_t tiles = static_cast<std::uint64_t>(view.tiles_x) * view.tiles_y;
    const std::size_t pixels = static_cast<std::size_t>(view.width) * view.height;
    const int tile_bits = bit_width(tiles);
    const CatgsOptions& catgs = options.catgs;
    const bool shared_list = options.culling == Culling::exact;
    const bool splitting = catgs.split_auto || catgs.split_k > 0;
    cudaStream_t s = m.stream;
    cudaEvent_t* e = m.events;

    FramePlanner::Plan plan = m.planner.next(camera, catgs, hints);
    // A cached frame that re-sorts needs the pairs in emission order, which a key frame that
    // reused the depth order did not keep.
    if (!plan.key && (!m.cache_valid || (plan.resort && !m.cached_emitted)))
        plan = FramePlanner::Plan{true, {camera}, plan.window};
    const CacheMode frame_cache = plan.cache(catgs);
    FrameStats stats;
    stats.key_frame = plan.key;
    stats.window = plan.window;
    stats.order_reused = !plan.key && !plan.resort;

    // Arenas for this frame's per-Gaussian, per-slot (chunk-compacted), per-tile and per-pixel
    // buffers.
    const std::uint32_t chunk_count = scene.chunk_count();
    const std::uint64_t max_slots = static_cast<std::uint64_t>(chunk_count) * kChunkGaussians;
    m.projected.reserve(n, s);
    m.visible.reserve(max_slots + 1, s);
    m.touched.reserve(max_slots + 1, s);
    m.sort_depth.reserve(max_slots, s);
    m.offsets.reserve(max_slots + 1, s);
    m.range_begin.reserve(tiles, s);
    m.range_end.reserve(tiles, s);
    m.split_slot.reserve(tiles, s);
    m.split_tiles.reserve(tiles, s);
    if (rgb8) m.image_rgb8.reserve(3 * pixels, s);
    if (rgb_float) m.image_float.reserve(3 * pixels, s);

    const DeviceSceneView sv{scene.positions(), scene.scales(), scene.rotations(), scene.opacities(),
                             scene.sh(),        scene.sh_degree(), n};
    FrameCounters* frame_counters = &m.counters.data()->frame;
    TaskCounters* task_counters = &m.counters.data()->tasks;
    CATGS_CUDA_CHECK(cudaMemsetAsync(frame_counters, 0, sizeof(FrameCounters), s));
    const unsigned int far_bits = 0x7f800000u;  // +inf: the atomicMin start of the nearest depth
    CATGS_CUDA_CHECK(cudaMemcpyAsync(&frame_counters->min_depth_bits, &far_bits, sizeof(far_bits),
                                     cudaMemcpyHostToDevice, s));
    CATGS_CUDA_CHECK(cudaEventRecord(e[kStart], s));

    std::uint64_t total = 0;
    std::vector<TileRows> bands{{0, view.tiles_y}};
    float pre_ms = 0, scan_ms = 0, emit_ms = 0, sort_ms = 0, ranges_ms = 0, split_ms = 0, raster_ms = 0, merge_ms = 0;
    // The extra-task and slot bounds of the task list (k is at least the floor when automatic).
    const std::uint64_t k_min = catgs.split_auto ? kAutoSplitFloor : std::max<std::uint32_t>(catgs.split_k, 1);

    // A speculative window lowers the near plane by the translation guard, so that a pose
    // inside the envelope finds Gaussians that cross the near plane; the actual pose is then
    // projected again with the real near plane.
    const bool speculative = frame_cache == CacheMode::speculative;
    const double near = speculative ? std::max(kMinSpeculativeNear, options.near_plane - catgs.guard_translation)
                                    : options.near_plane;
    const bool reproject_actual = near != options.near_plane;

    // Ranges and the task list (split) over the sorted pairs; key frames and cached frames
    // that re-sort both run it. Returns whether tiles were split.
    auto ranges_and_tasks = [&](std::uint64_t pass_total) {
        // Ranges: empty tiles keep [0, 0).
        CATGS_CUDA_CHECK(cudaMemsetAsync(m.range_begin.data(), 0, tiles * sizeof(std::uint64_t), s));
        CATGS_CUDA_CHECK(cudaMemsetAsync(m.range_end.data(), 0, tiles * sizeof(std::uint64_t), s));
        TaskCounters fresh{};
        fresh.split_k = catgs.split_auto ? 0 : catgs.split_k;
        CATGS_CUDA_CHECK(cudaMemcpyAsync(task_counters, &fresh, sizeof(fresh), cudaMemcpyHostToDevice, s));
        if (pass_total > 0 && !shared_list) {
            ranges_kernel<<<blocks_for(pass_total, kThreads), kThreads, 0, s>>>(
                pass_total, m.keys[m.current].data(), static_cast<std::uint32_t>(tiles), m.range_begin.data(),
                m.range_end.data(), task_counters);
            CATGS_CUDA_CHECK_LAUNCH("ranges");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kRanges], s));
        // Split (exact culling shares one list, which this task layout does not split).
        const bool split = splitting && !shared_list && pass_total > 0;
        if (split) {
            const std::uint64_t max_extra = pass_total / k_min + 1;
            m.labels.reserve(max_extra, s);
            m.partials.reserve((max_extra + std::min<std::uint64_t>(tiles, max_extra)) * kTilePixels, s);
            if (catgs.split_auto) {
                auto_split_kernel<<<1, 1, 0, s>>>(task_counters);
                CATGS_CUDA_CHECK_LAUNCH("auto_split");
            }
            split_kernel<<<blocks_for(tiles, kThreads), kThreads, 0, s>>>(
                static_cast<std::uint32_t>(tiles), m.range_begin.data(), m.range_end.data(), max_extra, task_counters,
                m.split_slot.data(), m.labels.data(), m.split_tiles.data());
            CATGS_CUDA_CHECK_LAUNCH("split");
        }
        return split;
    };

    if (plan.key) {
        // The window: poses projected with the near plane lowered by the translation guard
        // and footprints dilated by the pixel guard (cache.hpp).
        const int w = static_cast<int>(plan.poses.size());
        for (int k = 0; k < w; ++k) m.host_views[k] = make_view<T>(plan.poses[k], scene.origin(), near);
        CATGS_CUDA_CHECK(
            cudaMemcpyAsync(m.views.data(), m.host_views, w * sizeof(View<T>), cudaMemcpyHostToDevice, s));
        const T guard = speculative ? static_cast<T>(catgs.guard_px) : T(0);
        const T guard_translation = speculative ? static_cast<T>(catgs.guard_translation) : T(0);
        // Stage 0: the chunks some pose of the window may see, compacted in scene order (so
        // that pairs are still emitted in Gaussian order); exact culling keeps them all.
        std::uint32_t live_chunks = chunk_count;
        const std::uint32_t* selected = scene.all_chunks();
        if (options.chunk_culling && options.culling != Culling::exact && scene.partitioned() && chunk_count > 0) {
            m.chunk_flags.reserve(chunk_count, s);
            m.selected.reserve(chunk_count, s);
            m.selected_count.reserve(1, s);
            chunk_cull_kernel<T><<<blocks_for(chunk_count, kThreads), kThreads, 0, s>>>(
                scene.chunks(), chunk_count, m.views.data(), w, guard, guard_translation, m.chunk_flags.data());
            CATGS_CUDA_CHECK_LAUNCH("chunk_cull");
            std::size_t temp_bytes = 0;
            CATGS_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, temp_bytes, scene.all_chunks(), m.chunk_flags.data(),
                                                        m.selected.data(), m.selected_count.data(),
                                                        static_cast<std::int64_t>(chunk_count), s));
            m.select_temp.reserve(temp_bytes, s);
            CATGS_CUDA_CHECK(cub::DeviceSelect::Flagged(m.select_temp.data(), temp_bytes, scene.all_chunks(),
                                                        m.chunk_flags.data(), m.selected.data(), m.selected_count.data(),
                                                        static_cast<std::int64_t>(chunk_count), s));
            CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_selected, m.selected_count.data(), sizeof(std::uint32_t),
                                             cudaMemcpyDeviceToHost, s));
            CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
            live_chunks = *m.host_selected;
            selected = m.selected.data();
        }
        m.key_space = ChunkSpace{scene.chunks(), selected, static_cast<std::uint64_t>(live_chunks) * kChunkGaussians};
        m.key_chunks_culled = scene.partitioned() ? chunk_count - live_chunks : 0;
        const std::uint64_t slots = m.key_space.slots;
        CATGS_CUDA_CHECK(cudaMemsetAsync(m.touched.data() + slots, 0, sizeof(std::uint64_t), s));
        if (slots > 0) {
            const unsigned blocks = blocks_for(slots, kThreads);
            if (w == 1 && frame_cache == CacheMode::off)
                preprocess_kernel<T, 1, false><<<blocks, kThreads, 0, s>>>(
                    sv, m.key_space, m.views.data(), 1, view, reproject_actual, options.culling, guard,
                    guard_translation, m.projected.data(), m.touched.data(), m.sort_depth.data(), frame_counters);
            else if (w == 1)
                preprocess_kernel<T, 1, true><<<blocks, kThreads, 0, s>>>(
                    sv, m.key_space, m.views.data(), 1, view, reproject_actual, options.culling, guard,
                    guard_translation, m.projected.data(), m.touched.data(), m.sort_depth.data(), frame_counters);
            else
                preprocess_kernel<T, kMaxWindow, true><<<blocks, kThreads, 0, s>>>(
                    sv, m.key_space, m.views.data(), w, view, reproject_actual, options.culling, guard,
                    guard_translation, m.projected.data(), m.touched.data(), m.sort_depth.data(), frame_counters);
            CATGS_CUDA_CHECK_LAUNCH("preprocess");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kPreprocess], s));
        total = m.scan(slots);
        CATGS_CUDA_CHECK(cudaEventRecord(e[kScan], s));

        // Bands: split the tile rows so each band's pairs fit the budget. The full-frame
        // counts are kept in `visible` so each band recounts only its own rows. A banded
        // frame holds no whole-frame lists, so it cannot start a cached window.
        const std::uint64_t budget = m.pair_budget();
        if (total > budget) {
            if (shared_list)
                throw Error("cuda renderer: exact culling needs " + std::to_string(total) +
                            " pairs, more than the pair budget of " + std::to_string(budget));
            bands.clear();
            const int band_count =
                static_cast<int>(std::min<std::uint64_t>(view.tiles_y, (total + budget - 1) / budget * 2));
            const int rows_per_band = (view.tiles_y + band_count - 1) / band_count;
            for (int r = 0; r < view.tiles_y; r += rows_per_band)
                bands.push_back({r, std::min(view.tiles_y, r + rows_per_band)});
            CATGS_CUDA_CHECK(cudaMemcpyAsync(m.visible.data(), m.touched.data(), (slots + 1) * sizeof(std::uint64_t),
                                             cudaMemcpyDeviceToDevice, s));
        }
        CATGS_CUDA_CHECK(cudaEventSynchronize(e[kScan]));
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&pre_ms, e[kStart], e[kPreprocess]));
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&scan_ms, e[kPreprocess], e[kScan]));
    } else {
        // Cached frame: re-project what the lists hold, then (by default) re-sort them by the
        // current depth; tiles, ranges and tasks stay as the key frame left them.
        if (m.key_space.slots > 0) {
            reproject_kernel<T><<<blocks_for(m.key_space.slots, kThreads), kThreads, 0, s>>>(
                sv, m.key_space, view, m.touched.data(), m.projected.data(), frame_counters);
            CATGS_CUDA_CHECK_LAUNCH("reproject");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kPreprocess], s));
        total = m.cached_pairs;
        if (plan.resort && total > 0) {
            m.current = 0;
            rekey_kernel<T><<<blocks_for(total, kThreads), kThreads, 0, s>>>(
                total, m.emitted_keys.data(), m.emitted_values.data(), m.projected.data(), view, options.culling,
                m.keys[0].data(), m.values[0].data());
            CATGS_CUDA_CHECK_LAUNCH("rekey");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kEmit], s));
        if (plan.resort) m.sort(total, tile_bits);
        CATGS_CUDA_CHECK(cudaEventRecord(e[kSort], s));
        if (plan.resort) {
            m.cached_split = ranges_and_tasks(total);
        } else {
            CATGS_CUDA_CHECK(cudaEventRecord(e[kRanges], s));
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kSplit], s));
    }

    const Vec3<T> bg{static_cast<T>(options.background[0]), static_cast<T>(options.background[1]),
                     static_cast<T>(options.background[2])};
    const T tail = static_cast<T>(catgs.split_tail_transmittance);
    float scan_extra_ms = 0;
    bool split_used = plan.key ? false : m.cached_split;
    for (std::size_t b = 0; b < bands.size(); ++b) {
        const TileRows rows = bands[b];
        std::uint64_t pass_total = total;
        if (plan.key) {
            cudaEvent_t pass_start = e[kScan];
            if (bands.size() > 1) {
                CATGS_CUDA_CHECK(cudaEventRecord(e[kBandCount], s));
                const std::uint64_t slots = m.key_space.slots;
                if (slots > 0) {
                    count_band_kernel<T><<<blocks_for(slots, kThreads), kThreads, 0, s>>>(
                        m.key_space, m.projected.data(), m.visible.data(), view, options.culling, rows,
                        m.touched.data());
                    CATGS_CUDA_CHECK_LAUNCH("count_band");
                }
                pass_total = m.scan(slots);
                CATGS_CUDA_CHECK(cudaEventRecord(e[kBandScan], s));
                CATGS_CUDA_CHECK(cudaEventSynchronize(e[kBandScan]));
                float ms = 0;
                CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kBandCount], e[kBandScan]));
                scan_extra_ms += ms;
                pass_start = e[kBandScan];
                if (pass_total > m.pair_budget())
                    throw Error("cuda renderer: tile rows " + std::to_string(rows.begin) + ".." +
                                std::to_string(rows.end) + " need " + std::to_string(pass_total) +
                                " tile-Gaussian pairs, more than the budget of " + std::to_string(m.pair_budget()) +
                                "; raise the pair budget or lower the resolution");
            }
            // Emit.
            m.current = 0;
            if (pass_total > 0) {
                for (int k = 0; k < 2; ++k) {
                    m.keys[k].reserve(pass_total, s);
                    m.values[k].reserve(pass_total, s);
                }
                const bool band = bands.size() > 1;
                const int w = static_cast<int>(plan.poses.size());
                const T guard = speculative ? static_cast<T>(catgs.guard_px) : T(0);
                const unsigned emit_blocks = blocks_for(m.key_space.slots, kThreads);
                if (w == 1)
                    emit_kernel<T, 1><<<emit_blocks, kThreads, 0, s>>>(
                        sv, m.key_space, m.views.data(), 1, options.culling, guard, m.projected.data(), m.touched.data(),
                        m.offsets.data(), m.sort_depth.data(), rows, band, reproject_actual, pass_total,
                        m.keys[0].data(), m.values[0].data());
                else
                    emit_kernel<T, kMaxWindow><<<emit_blocks, kThreads, 0, s>>>(
                        sv, m.key_space, m.views.data(), w, options.culling, guard, m.projected.data(), m.touched.data(),
                        m.offsets.data(), m.sort_depth.data(), rows, band, reproject_actual, pass_total,
                        m.keys[0].data(), m.values[0].data());
                CATGS_CUDA_CHECK_LAUNCH("emit");
            }
            // Cached frames that re-sort re-key from the pairs in emission order (rekey_kernel).
            // With the depth order reused they never read them, and the copy (12 bytes a pair,
            // 6M pairs on the city) would only lengthen key frames.
            m.cached_emitted = frame_cache != CacheMode::off && catgs.cached_frames_may_resort() && bands.size() == 1;
            if (m.cached_emitted && pass_total > 0) {
                m.emitted_keys.reserve(pass_total, s);
                m.emitted_values.reserve(pass_total, s);
                CATGS_CUDA_CHECK(cudaMemcpyAsync(m.emitted_keys.data(), m.keys[0].data(), pass_total * sizeof(std::uint64_t),
                                                 cudaMemcpyDeviceToDevice, s));
                CATGS_CUDA_CHECK(cudaMemcpyAsync(m.emitted_values.data(), m.values[0].data(),
                                                 pass_total * sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, s));
            }
            CATGS_CUDA_CHECK(cudaEventRecord(e[kEmit], s));
            m.sort(pass_total, tile_bits);
            CATGS_CUDA_CHECK(cudaEventRecord(e[kSort], s));
            split_used = ranges_and_tasks(pass_total);
            CATGS_CUDA_CHECK(cudaEventRecord(e[kSplit], s));
            CATGS_CUDA_CHECK(cudaEventSynchronize(e[kSplit]));
            float ms = 0;
            CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, pass_start, e[kEmit]));
            emit_ms += ms;
            CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kEmit], e[kSort]));
            sort_ms += ms;
            CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kSort], e[kRanges]));
            ranges_ms += ms;
            CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kRanges], e[kSplit]));
            split_ms += ms;
        }
        // Rasterize the band's tasks: its tiles, then (bounded) extra sub-tasks.
        CATGS_CUDA_CHECK(cudaEventRecord(e[kSplit], s));
        const std::uint32_t first_tile = static_cast<std::uint32_t>(rows.begin) * view.tiles_x;
        const std::uint32_t band_tiles = static_cast<std::uint32_t>(rows.end - rows.begin) * view.tiles_x;
        const std::uint64_t max_extra = split_used ? pass_total / k_min + 1 : 0;
        // Not in exact mode, the ground truth: there every Gaussian meets every pixel's own test.
        const TaskGrid grid{first_tile, band_tiles, split_used, shared_list, pass_total,
                            options.culling != Culling::exact};
        const std::uint64_t blocks = band_tiles + max_extra;
        if (blocks > 0) {
            rasterize_kernel<T><<<static_cast<unsigned>(blocks), dim3(kTileSize, kTileSize), 0, s>>>(
                grid, m.range_begin.data(), m.range_end.data(), m.split_slot.data(), m.labels.data(), task_counters,
                m.values[m.current].data(), m.projected.data(), view, bg, tail, m.partials.data(),
                rgb8 ? m.image_rgb8.data() : nullptr, rgb_float ? m.image_float.data() : nullptr);
            CATGS_CUDA_CHECK_LAUNCH("rasterize");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kRasterize], s));
        if (split_used) {
            const std::uint64_t merge_blocks = std::min<std::uint64_t>(tiles, max_extra);
            merge_kernel<T><<<static_cast<unsigned>(merge_blocks), dim3(kTileSize, kTileSize), 0, s>>>(
                m.split_tiles.data(), m.split_slot.data(), m.range_begin.data(), m.range_end.data(), task_counters,
                m.partials.data(), view, bg, rgb8 ? m.image_rgb8.data() : nullptr,
                rgb_float ? m.image_float.data() : nullptr);
            CATGS_CUDA_CHECK_LAUNCH("merge");
        }
        CATGS_CUDA_CHECK(cudaEventRecord(e[kMerge], s));
        CATGS_CUDA_CHECK(cudaEventSynchronize(e[kMerge]));
        float ms = 0;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kSplit], e[kRasterize]));
        raster_ms += ms;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, e[kRasterize], e[kMerge]));
        merge_ms += ms;
    }
    if (!plan.key) {
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&pre_ms, e[kStart], e[kPreprocess]));
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&emit_ms, e[kPreprocess], e[kEmit]));
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&sort_ms, e[kEmit], e[kSort]));
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ranges_ms, e[kSort], e[kRanges]));
    }

    // Copy-out through pinned staging buffers, plus the frame's counters.
    CATGS_CUDA_CHECK(cudaEventRecord(e[kCopyStart], s));
    if (rgb8) {
        if (m.host_rgb8_bytes < 3 * pixels) {
            cudaFreeHost(m.host_rgb8);
            m.host_rgb8 = nullptr;
            CATGS_CUDA_CHECK(cudaMallocHost(&m.host_rgb8, 3 * pixels));
            m.host_rgb8_bytes = 3 * pixels;
        }
        CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_rgb8, m.image_rgb8.data(), 3 * pixels, cudaMemcpyDeviceToHost, s));
    }
    if (rgb_float) {
        if (m.host_float_bytes < 3 * pixels * sizeof(float)) {
            cudaFreeHost(m.host_float);
            m.host_float = nullptr;
            CATGS_CUDA_CHECK(cudaMallocHost(&m.host_float, 3 * pixels * sizeof(float)));
            m.host_float_bytes = 3 * pixels * sizeof(float);
        }
        CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_float, m.image_float.data(), 3 * pixels * sizeof(float),
                                         cudaMemcpyDeviceToHost, s));
    }
    CATGS_CUDA_CHECK(cudaEventRecord(e[kCopy], s));
    CATGS_CUDA_CHECK(cudaMemcpyAsync(m.host_counters, m.counters.data(), sizeof(Counters), cudaMemcpyDeviceToHost, s));
    CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
    if (rgb8) {
        rgb8->width = view.width;
        rgb8->height = view.height;
        rgb8->rgb.assign(m.host_rgb8, m.host_rgb8 + 3 * pixels);
    }
    if (rgb_float) {
        rgb_float->width = view.width;
        rgb_float->height = view.height;
        rgb_float->rgb.assign(m.host_float, m.host_float + 3 * pixels);
    }
    const FrameCounters& c = m.host_counters->frame;
    const TaskCounters& tc = m.host_counters->tasks;

    // The planner learns about a key frame only when its lists cover the whole frame.
    if (plan.key) {
        m.cached_pairs = total;
        m.cached_split = split_used;
        m.cache_valid = frame_cache != CacheMode::off && bands.size() == 1;
        if (m.cache_valid) {
            KeyFrameSummary summary;
            float nearest = 0, extent = 0;
            std::memcpy(&nearest, &c.min_depth_bits, sizeof(float));
            std::memcpy(&extent, &c.max_extent_bits, sizeof(float));
            summary.min_depth = std::isfinite(nearest) ? nearest : options.near_plane;
            summary.max_extent_px = extent;
            summary.mean_inverse_depth = c.visible ? c.inverse_depth_sum / static_cast<double>(c.visible) : 0.0;
            m.planner.key_rendered(plan, summary);
        } else {
            m.planner.invalidate();
        }
    }

    float copy_ms = 0;
    CATGS_CUDA_CHECK(cudaEventElapsedTime(&copy_ms, e[kCopyStart], e[kCopy]));
    // Render length: the pairs inside the grid that the tiles' lists hold (ranges counted them;
    // cached frames that re-sort park the rest), else every pair of the list.
    const bool ranged = !shared_list && total > 0 && bands.size() == 1 && (plan.key || plan.resort);
    stats.pairs = ranged ? tc.rendered_pairs : total;
    stats.bands = static_cast<int>(bands.size());
    stats.chunks = scene.partitioned() ? chunk_count : 0;
    stats.chunks_culled = m.key_chunks_culled;
    stats.visible = c.visible;
    stats.split_k = split_used ? tc.split_k : 0;
    stats.split_tasks = split_used ? tc.extra_tasks : 0;
    stats.tasks = tiles + stats.split_tasks;
    stats.stage_ms[catgs::Stage::preprocess] = pre_ms;
    stats.stage_ms[catgs::Stage::scan] = scan_ms + scan_extra_ms;
    stats.stage_ms[catgs::Stage::keys] = emit_ms;
    stats.stage_ms[catgs::Stage::sort] = sort_ms;
    stats.stage_ms[catgs::Stage::ranges] = ranges_ms;
    stats.stage_ms[catgs::Stage::split] = split_ms;
    stats.stage_ms[catgs::Stage::rasterize] = raster_ms;
    stats.stage_ms[catgs::Stage::merge] = merge_ms;
    stats.stage_ms[catgs::Stage::copy_out] = copy_ms;
    stats.total_ms = stats.stage_ms.sum();
    stats.arena_bytes = m.arena_bytes();
    return stats;
}

template class CudaRenderer<float>;
template class CudaRenderer<double>;

}  // namespace catgs::cuda
