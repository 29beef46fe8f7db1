#include "ranges.cuh"

#include <cub/block/block_reduce.cuh>

#include "cuda_check.hpp"

#include <cstddef>

namespace catgs::cuda {
namespace {

/// The first pair whose tile id is not below `tile` (ids sort ascending).
template <typename Key>
__device__ std::uint64_t first_pair_of(const Key* keys, std::uint64_t n, std::uint32_t tile) {
    std::uint64_t low = 0, high = n;
    while (low < high) {
        const std::uint64_t mid = low + (high - low) / 2;
        if (static_cast<std::uint32_t>(keys[mid]) < tile)
            low = mid + 1;
        else
            high = mid;
    }
    return low;
}

// Each tile's list: [first pair of its id, first pair of the next id), a thread a tile. A pass
// over the pairs (a thread a pair, writing the tiles where the id changes) read all 16 MB of
// ids at 4K, left the empty tiles to two memsets and needed its counters cleared by an upload
// first: 0.039 ms on garden low 4K (H100, session 37). Here every tile is written, empty ones
// [0, 0), and a warp's neighbouring tiles share most steps of their searches. Ids at or
// beyond the grid (parked pairs of a cached frame, or a corrupted key: gaussian-splatting#781)
// sort last, outside every tile's range. The last block to finish writes the fresh task
// counters that split then fills.
template <typename Key>
__global__ void ranges_kernel(std::uint64_t n, const Key* keys, std::uint32_t tiles, std::uint32_t fixed_split_k,
                              std::uint64_t* range_begin, std::uint64_t* range_end, TaskCounters* counters,
                              RangesTally* tally) {
    // first[j]: the first pair of tile base + j, for j up to kThreads (the next block's first).
    __shared__ std::uint64_t first[kThreads + 1];
    const std::uint64_t base = static_cast<std::uint64_t>(blockIdx.x) * kThreads;
    const std::uint64_t tile = base + threadIdx.x;
    if (tile <= tiles) first[threadIdx.x] = first_pair_of(keys, n, static_cast<std::uint32_t>(tile));
    if (threadIdx.x == 0 && base + kThreads <= tiles)
        first[kThreads] = first_pair_of(keys, n, static_cast<std::uint32_t>(base + kThreads));
    __syncthreads();
    unsigned nonempty = 0;
    if (tile < tiles) {
        const std::uint64_t begin = first[threadIdx.x], end = first[threadIdx.x + 1];
        nonempty = end > begin ? 1 : 0;
        range_begin[tile] = nonempty ? begin : 0;
        range_end[tile] = nonempty ? end : 0;
    }
    // The pairs inside the grid end where the first id past it begins (the last block holds it).
    if (tile == tiles) counters->rendered_pairs = first[threadIdx.x];
    if (threadIdx.x == 0 && base + kThreads == tiles) counters->rendered_pairs = first[kThreads];

    using Reduce = cub::BlockReduce<unsigned, kThreads>;
    __shared__ typename Reduce::TempStorage temp;
    const unsigned block_nonempty = Reduce(temp).Sum(nonempty);
    if (threadIdx.x == 0 && block_nonempty > 0) atomicAdd(&tally->nonempty_tiles, block_nonempty);
    if (!last_block_done(&tally->blocks_done) || threadIdx.x != 0) return;
    counters->nonempty_tiles = atomicExch(&tally->nonempty_tiles, 0u);
    start_task_list(*counters, fixed_split_k);
    tally->blocks_done = 0;
}

/// Exact culling's one shared list: no ranges, and the task counters cleared (split then
/// builds no list).
void clear_ranges(const RangesArgs& a, cudaStream_t s) {
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_begin, 0, a.tiles * sizeof(std::uint64_t), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_end, 0, a.tiles * sizeof(std::uint64_t), s));
    TaskCounters fresh{};
    start_task_list(fresh, a.fixed_split_k);
    // All but the last two, longest_list and occlusion_misses: they span the frame's bands
    // (cleared when a frame begins).
    static_assert(offsetof(TaskCounters, occlusion_misses) > offsetof(TaskCounters, longest_list) &&
                  offsetof(TaskCounters, occlusion_misses) + sizeof(fresh.occlusion_misses) + alignof(TaskCounters) >
                      sizeof(TaskCounters));
    CATGS_CUDA_CHECK(
        cudaMemcpyAsync(a.counters, &fresh, offsetof(TaskCounters, longest_list), cudaMemcpyHostToDevice, s));
}

}  // namespace

void ranges(const RangesArgs& a, cudaStream_t s) {
    if (a.shared_list) {
        clear_ranges(a, s);
        return;
    }
    with_tile_key(a.keys.width, [&](auto key) {
        using Key = decltype(key);
        ranges_kernel<<<blocks_for(a.tiles, kThreads), kThreads, 0, s>>>(a.pairs, key_data<const Key>(a.keys), a.tiles,
                                                                         a.fixed_split_k, a.range_begin, a.range_end,
                                                                         a.counters, a.tally);
    });
    CATGS_CUDA_CHECK_LAUNCH("ranges_kernel");
}

}  // namespace catgs::cuda
