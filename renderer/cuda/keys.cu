#include "keys.cuh"

#include <algorithm>

#include "catgs/stages/keys.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// Keys at each Gaussian's offset, in Gaussian order, so that the stable sort keeps
// index order for equal depths. `capacity` bounds every write.
template <typename T, int MaxWindow>
__global__ void __launch_bounds__(kThreads)
    keys_kernel(DeviceSceneView scene, ChunkSpace space, const View<T>* views, int window, Culling culling, T guard,
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
    const unsigned blocks = blocks_for(a.space.slots, kThreads);
    if (a.window == 1)
        keys_kernel<T, 1><<<blocks, kThreads, 0, s>>>(a.scene, a.space, a.views, 1, a.culling, a.guard, a.projected,
                                                      a.touched, a.offsets, a.sort_depth, a.rows, a.band, a.reprojected,
                                                      a.capacity, a.keys, a.values);
    else
        keys_kernel<T, kMaxWindow><<<blocks, kThreads, 0, s>>>(a.scene, a.space, a.views, a.window, a.culling, a.guard,
                                                               a.projected, a.touched, a.offsets, a.sort_depth, a.rows,
                                                               a.band, a.reprojected, a.capacity, a.keys, a.values);
    CATGS_CUDA_CHECK_LAUNCH("keys_kernel");
}

template <typename T>
void rekey(const RekeyArgs<T>& a, cudaStream_t s) {
    rekey_kernel<T><<<blocks_for(a.pairs, kThreads), kThreads, 0, s>>>(
        a.pairs, a.emitted_keys, a.emitted_values, a.projected, a.view, a.culling, a.keys, a.values);
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
template void rekey(const RekeyArgs<float>&, cudaStream_t);
template void rekey(const RekeyArgs<double>&, cudaStream_t);
template void count_band(const CountBandArgs<float>&, cudaStream_t);
template void count_band(const CountBandArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
