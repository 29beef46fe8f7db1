#include "keys.cuh"

#include <algorithm>

#include "catgs/error.hpp"
#include "catgs/stages/keys.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// Keys' launch shape. Blocks of 256 at 2 an SM (128 registers): with the bare thread bound,
// ptxas held the window instance to 64 registers and spilled, which the build rejects; at 2
// the window instances take 80, without spilling. The single-frame float instance (66
// registers, every plain frame) runs in blocks of 128 at 7 an SM: 28 warps resident where 3
// blocks of 256 held 24, and a block waits on fewer long footprints. keys fell 4-13% on the
// kit's six paths (city_ring 4K 0.668 -> 0.641 ms, garden survey 1080p 0.387 -> 0.339; H200,
// session 18, plain, 300 frames). Since the rows are dealt out (emit_rows_flat) the owners'
// ellipses wait in shared memory (RowOwner), which keeps it at 68 registers and 7 an SM: with
// them shuffled it took 80 and ran at 6 (7 spilled), and keys was 3-4% slower on the kit's
// paths (H100, session 33).
template <typename T, int MaxWindow>
struct KeysShape {
    static constexpr int kThreads = 256, kMinBlocks = 2;
};
template <>
struct KeysShape<float, 1> {
    static constexpr int kThreads = 128, kMinBlocks = 7;
};

constexpr unsigned kFullWarp = 0xffffffffu;

/// The sum of `value` over lanes 0..lane (every lane of the warp takes part).
__device__ inline int inclusive_warp_scan(int value, int lane) {
    for (int d = 1; d < warpSize; d <<= 1) {
        const int n = __shfl_up_sync(kFullWarp, value, d);
        if (lane >= d) value += n;
    }
    return value;
}

/// One Gaussian's pairs of the single-pose predicate (for_each_touched_tile), by the whole warp:
/// lane r takes rows y0 + r, y0 + 32 + r, ...; a warp scan of the row widths puts each row
/// where the serial loop puts it, so the pairs land in the same places (row by row).
template <typename T, typename Key>
__device__ void emit_rows_by_warp(const Projected<T>& g, std::uint32_t gaussian, Culling culling, const View<T>& view,
                                  TileRows rows, std::uint64_t slot, std::uint64_t end, Key* keys,
                                  std::uint32_t* values) {
    const TileRect rect = tile_rect(g, culling, view.tiles_x, view.tiles_y);
    const int y0 = rect.y0 > rows.begin ? rect.y0 : rows.begin;
    const int y1 = rect.y1 < rows.end ? rect.y1 : rows.end;
    const EllipseRows<T> ellipse(g, opacity_level(g.opacity));
    const int lane = static_cast<int>(threadIdx.x % warpSize);
    for (int base = y0; base < y1; base += warpSize) {  // uniform across the warp
        const int ty = base + lane;
        const TileSpan s = ty < y1 ? footprint_row(g, culling, rect, ty, view, T(0), ellipse) : TileSpan{0, 0};
        const int width = s.x1 > s.x0 ? s.x1 - s.x0 : 0;
        const int through = inclusive_warp_scan(width, lane);
        const int total = __shfl_sync(kFullWarp, through, warpSize - 1);
        std::uint64_t at = slot + static_cast<std::uint64_t>(through - width);
        for (int tx = s.x0; tx < s.x1; ++tx, ++at)
            if (at < end) {
                keys[at] = static_cast<Key>(ty * view.tiles_x + tx);
                values[at] = gaussian;
            }
        slot += static_cast<std::uint64_t>(total);
    }
}

/// Where the lanes of a warp leave their Gaussian's rectangle and ellipse for the lanes that
/// walk its rows: in shared memory, not shuffled, so that the ten doubles are neither held in
/// registers across the walk nor moved by eighteen shuffles a round.
template <typename T>
struct RowOwner {
    EllipseRows<T> ellipse;
    TileRect rect;
};

/// The pairs of the warp's Gaussians that their own threads would emit (`mine`: at most
/// thread_pairs of them), a tile row a lane: the rows of lane 0's Gaussian, then lane 1's, ...
/// are dealt out 32 at a time, so a lane with a tall footprint no longer holds the warp while
/// the others idle (a thread per Gaussian walked up to 64 rows of double square roots). Each
/// row's pairs go where the thread's serial loop puts them: the Gaussian's first slot plus the
/// widths of its rows above, which count (the same predicate) made its pairs add up to.
template <typename T, typename Key>
__device__ void emit_rows_flat(const Projected<T>* projected, std::uint64_t gaussian, bool mine, std::uint64_t slot,
                               std::uint64_t end, std::uint64_t count, Culling culling, const View<T>& view,
                               TileRows rows, RowOwner<T>* warp_owners, Key* keys, std::uint32_t* values) {
    const int lane = static_cast<int>(threadIdx.x % warpSize);
    int y0 = 0, row_count = 0;
    if (mine) {  // set up once, read by the lanes that walk the rows (for_each_window_tile's single pose)
        const Projected<T>& g = projected[gaussian];
        RowOwner<T>& own = warp_owners[lane];
        own.rect = tile_rect(g, culling, view.tiles_x, view.tiles_y);
        y0 = own.rect.y0 > rows.begin ? own.rect.y0 : rows.begin;
        const int y1 = own.rect.y1 < rows.end ? own.rect.y1 : rows.end;
        if (!own.rect.empty() && y0 < y1) {
            row_count = y1 - y0;
            own.ellipse =
                culling == Culling::opacity_aware ? EllipseRows<T>(g, opacity_level(g.opacity)) : EllipseRows<T>();
        }
    }
    __syncwarp();
    const int rows_through = inclusive_warp_scan(row_count, lane);
    const int total_rows = __shfl_sync(kFullWarp, rows_through, warpSize - 1);
    // The pairs of lower lanes' rows: where this Gaussian's first row starts in the flat walk.
    const int own_pairs = mine ? static_cast<int>(count) : 0;
    const int pairs_before = inclusive_warp_scan(own_pairs, lane) - own_pairs;
    int walked_pairs = 0;                                      // of the flat rows before this round
    for (int base = 0; base < total_rows; base += warpSize) {  // uniform across the warp
        const int row = base + lane;
        int owner = 0, last = warpSize - 1;  // the first lane whose rows reach past `row`
        for (int half = warpSize / 2; half > 0; half /= 2) {
            const int mid = (owner + last) / 2;
            if (__shfl_sync(kFullWarp, rows_through, mid) > row)
                last = mid;
            else
                owner = mid + 1;
        }
        const int owner_first_row = __shfl_sync(kFullWarp, rows_through - row_count, owner);
        const int ty = __shfl_sync(kFullWarp, y0, owner) + (row - owner_first_row);
        const std::uint64_t owner_gaussian = __shfl_sync(kFullWarp, gaussian, owner);
        const RowOwner<T>& walked = warp_owners[owner];
        const TileSpan s = row < total_rows ? footprint_row(projected[owner_gaussian], culling, walked.rect, ty, view,
                                                            T(0), walked.ellipse)
                                            : TileSpan{0, 0};
        const int width = s.x1 > s.x0 ? s.x1 - s.x0 : 0;
        const int widths_through = inclusive_warp_scan(width, lane);
        const std::uint64_t owner_slot = __shfl_sync(kFullWarp, slot, owner);
        const std::uint64_t owner_end = __shfl_sync(kFullWarp, end, owner);
        const int owner_pairs_before = __shfl_sync(kFullWarp, pairs_before, owner);
        // Never negative while count and these rows agree; if they ever did not, no write
        // lands before the Gaussian's first slot either.
        const int offset = walked_pairs + widths_through - width - owner_pairs_before;
        std::uint64_t at = owner_slot + static_cast<std::uint64_t>(offset > 0 ? offset : 0);
        for (int tx = offset >= 0 ? s.x0 : s.x1; tx < s.x1; ++tx, ++at)
            if (at < owner_end) {
                keys[at] = static_cast<Key>(ty * view.tiles_x + tx);
                values[at] = static_cast<std::uint32_t>(owner_gaussian);
            }
        walked_pairs += __shfl_sync(kFullWarp, widths_through, warpSize - 1);
    }
}

// Keys (tile ids) at each Gaussian's offset: thread k emits the k-th nearest slot, so the pairs
// come out front to back, equal depths in slot order, and the stable sort by tile keeps that
// order within each tile (sort.cuh). `capacity` bounds every write. In the single-pose case a
// Gaussian of more than `thread_pairs` pairs is emitted by its whole warp (KeysArgs) and the
// others' rows are dealt out to its lanes (emit_rows_flat), so every lane, past `ordered` too,
// reaches the ballot and the shuffles.
template <typename T, int MaxWindow, typename Key>
__global__ void __launch_bounds__(KeysShape<T, MaxWindow>::kThreads, KeysShape<T, MaxWindow>::kMinBlocks)
    keys_kernel(DeviceSceneView scene, ChunkSpace space, const View<T>* views, int window, Culling culling, T guard,
                const Projected<T>* projected, const std::uint64_t* touched, const std::uint64_t* offsets,
                const std::uint32_t* order, std::uint64_t ordered, std::uint64_t* emission_offset, TileRows rows,
                bool band, bool reprojected, std::uint64_t capacity, Key* keys, std::uint32_t* values,
                std::uint64_t thread_pairs) {
    const std::uint64_t k = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    std::uint64_t i = 0, count = 0, slot = 0;
    if (k < ordered) {
        const std::uint64_t p = order[k];
        if (touched[p] != 0 && space.gaussian(p, i)) {
            count = touched[p];
            slot = offsets[k];
            if (emission_offset) emission_offset[p] = slot;
        }
    }
    const std::uint64_t end = min(slot + count, capacity);
    auto emit = [&](std::uint32_t tile) {
        if (slot < end) {
            keys[slot] = static_cast<Key>(tile);
            values[slot] = static_cast<std::uint32_t>(i);
        }
        ++slot;
    };
    if (band || (MaxWindow == 1 && !reprojected)) {  // uniform across the launch
        // One pose whose geometry preprocess stored (bands: caching is off for them).
        // Exact culling emits one pair (tile 0) a Gaussian: never the warp's.
        const bool by_warp = count > thread_pairs && culling != Culling::exact;
        if (culling == Culling::exact) {
            if (count > 0) for_each_touched_tile(projected[i], culling, views[0], emit, rows);
        } else {
            // Raw storage: a __shared__ variable cannot have EllipseRows' constructor.
            __shared__ alignas(
                RowOwner<T>) unsigned char owner_bytes[KeysShape<T, MaxWindow>::kThreads * sizeof(RowOwner<T>)];
            RowOwner<T>* warp_owners = reinterpret_cast<RowOwner<T>*>(owner_bytes) + threadIdx.x / warpSize * warpSize;
            emit_rows_flat(projected, i, count > 0 && !by_warp, slot, end, count, culling, views[0], rows, warp_owners,
                           keys, values);
        }
        for (unsigned many = __ballot_sync(kFullWarp, by_warp); many != 0; many &= many - 1) {
            const int leader = __ffs(static_cast<int>(many)) - 1;
            const std::uint64_t gaussian = __shfl_sync(kFullWarp, i, leader);
            const std::uint64_t first = __shfl_sync(kFullWarp, slot, leader);
            const std::uint64_t last = __shfl_sync(kFullWarp, end, leader);
            emit_rows_by_warp(projected[gaussian], static_cast<std::uint32_t>(gaussian), culling, views[0], rows, first,
                              last, keys, values);
        }
        return;
    }
    if (count == 0) return;
    Projected<T> poses[MaxWindow];
    const std::uint32_t valid = project_window<T, MaxWindow>(scene, i, views, window, poses);
    for_each_window_tile<MaxWindow>(poses, valid, window, culling, guard, views[0], emit, rows);
}

template <typename T>
__global__ void rekey_depth_kernel(ChunkSpace space, const std::uint64_t* touched, const Projected<T>* projected,
                                   float* depth) {
    const std::uint64_t p = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    std::uint64_t i = 0;
    if (p < space.slots && touched[p] > 0 && space.gaussian(p, i)) depth[p] = projected[i].key_depth;
}

// Cached frame, re-sort: every pair the key frame emitted keeps its tile or is parked past the
// grid (RekeyedTiles: sorts last, no range covers it). Thread k moves the pairs of the k-th
// nearest cached slot, so the tile sort leaves each list front to back with equal depths in
// slot order, as a full render does.
template <typename T, typename Key>
__global__ void rekey_kernel(ChunkSpace space, const std::uint64_t* touched, const std::uint32_t* order,
                             std::uint64_t ordered, const std::uint64_t* offsets, const std::uint64_t* emission_offset,
                             const Key* emitted_tiles, const Projected<T>* projected, View<T> view, Culling culling,
                             Key* keys, std::uint32_t* values) {
    const std::uint64_t k = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (k >= ordered) return;
    const std::uint64_t slot = order[k];
    std::uint64_t i = 0;
    const std::uint64_t count = touched[slot];
    if (count == 0 || !space.gaussian(slot, i)) return;
    const std::uint64_t from = emission_offset[slot], to = offsets[k];
    RekeyedTiles<T> rekeyed(projected[i], culling, view);
    for (std::uint64_t j = 0; j < count; ++j) {
        keys[to + j] = static_cast<Key>(rekeyed(emitted_tiles[from + j]));
        values[to + j] = static_cast<std::uint32_t>(i);
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
                        : for_each_touched_tile(
                              projected[i], culling, view, [](std::uint32_t) {}, rows);
}

}  // namespace

template <typename T>
void keys(const KeysArgs<T>& a, cudaStream_t s) {
    if (a.ordered == 0) return;
    with_tile_key(a.keys.width, [&](auto key) {
        using Key = decltype(key);
        const auto launch = [&](auto kernel, int threads) {
            kernel<<<blocks_for(a.ordered, threads), threads, 0, s>>>(
                a.scene, a.space, a.views, a.window, a.culling, a.guard, a.projected, a.touched, a.offsets, a.order,
                a.ordered, a.emission_offset, a.rows, a.band, a.reprojected, a.capacity, key_data<Key>(a.keys),
                a.values, a.thread_pairs);
        };
        if (a.window == 1)
            launch(keys_kernel<T, 1, Key>, KeysShape<T, 1>::kThreads);
        else if (a.window <= kUnrolledWindow)
            launch(keys_kernel<T, kSmallWindow<T>, Key>, KeysShape<T, kSmallWindow<T>>::kThreads);
        else
            launch(keys_kernel<T, kMaxWindow, Key>, KeysShape<T, kMaxWindow>::kThreads);
    });
    CATGS_CUDA_CHECK_LAUNCH("keys_kernel");
}

template <typename T>
void rekey_depth(const RekeyDepthArgs<T>& a, cudaStream_t s) {
    if (a.space.slots == 0) return;
    rekey_depth_kernel<T>
        <<<blocks_for(a.space.slots, kThreads), kThreads, 0, s>>>(a.space, a.touched, a.projected, a.depth);
    CATGS_CUDA_CHECK_LAUNCH("rekey_depth_kernel");
}

template <typename T>
void rekey(const RekeyArgs<T>& a, cudaStream_t s) {
    if (a.ordered == 0) return;
    if (a.keys.width != a.emitted_tiles.width) throw Error("cuda renderer: rekey between tile key widths");
    with_tile_key(a.keys.width, [&](auto key) {
        using Key = decltype(key);
        rekey_kernel<T, Key><<<blocks_for(a.ordered, kThreads), kThreads, 0, s>>>(
            a.space, a.touched, a.order, a.ordered, a.offsets, a.emission_offset, key_data<const Key>(a.emitted_tiles),
            a.projected, a.view, a.culling, key_data<Key>(a.keys), a.values);
    });
    CATGS_CUDA_CHECK_LAUNCH("rekey_kernel");
}

template <typename T>
void count_band(const CountBandArgs<T>& a, cudaStream_t s) {
    if (a.space.slots == 0) return;
    count_band_kernel<T><<<blocks_for(a.space.slots, kThreads), kThreads, 0, s>>>(a.space, a.projected, a.visible,
                                                                                  a.view, a.culling, a.rows, a.touched);
    CATGS_CUDA_CHECK_LAUNCH("count_band_kernel");
}

std::vector<TileRows> band_rows(std::uint64_t total, std::uint64_t budget, int tiles_y) {
    std::vector<TileRows> bands;
    const int band_count = static_cast<int>(std::min<std::uint64_t>(tiles_y, (total + budget - 1) / budget * 2));
    const int rows_per_band = (tiles_y + band_count - 1) / band_count;
    for (int r = 0; r < tiles_y; r += rows_per_band) bands.push_back({r, std::min(tiles_y, r + rows_per_band)});
    return bands;
}

template void keys(const KeysArgs<float>&, cudaStream_t);
template void keys(const KeysArgs<double>&, cudaStream_t);
template void rekey_depth(const RekeyDepthArgs<float>&, cudaStream_t);
template void rekey_depth(const RekeyDepthArgs<double>&, cudaStream_t);
template void rekey(const RekeyArgs<float>&, cudaStream_t);
template void rekey(const RekeyArgs<double>&, cudaStream_t);
template void count_band(const CountBandArgs<float>&, cudaStream_t);
template void count_band(const CountBandArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
