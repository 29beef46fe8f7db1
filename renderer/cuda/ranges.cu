#include "ranges.cuh"

#include "cuda_check.hpp"

#include <cstddef>

namespace catgs::cuda {
namespace {

// Tile ranges; ids beyond the grid are ignored rather than written (defence against
// a corrupted key, the failure mode of gaussian-splatting#781).
template <typename Key>
__global__ void ranges_kernel(std::uint64_t n, const Key* keys, std::uint32_t tiles, std::uint64_t* range_begin,
                              std::uint64_t* range_end, TaskCounters* counters) {
    const std::uint64_t i = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    bool first = false, inside = false;
    if (i < n) {
        const std::uint32_t tile = keys[i];
        inside = tile < tiles;
        if (inside) {
            first = i == 0 || keys[i - 1] != tile;
            if (first) range_begin[tile] = i;
            if (i + 1 == n || keys[i + 1] != tile) range_end[tile] = i + 1;
        }
    }
    const int block_first = __syncthreads_count(first);
    const int block_inside = __syncthreads_count(inside);
    if (threadIdx.x == 0 && block_first > 0) atomicAdd(&counters->nonempty_tiles, static_cast<unsigned>(block_first));
    if (threadIdx.x == 0 && block_inside > 0)
        atomicAdd(&counters->rendered_pairs, static_cast<unsigned long long>(block_inside));
}

}  // namespace

void ranges(const RangesArgs& a, cudaStream_t s) {
    // Empty tiles keep [0, 0).
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_begin, 0, a.tiles * sizeof(std::uint64_t), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_end, 0, a.tiles * sizeof(std::uint64_t), s));
    TaskCounters fresh{};
    fresh.split_k = a.fixed_split_k;
    // All but longest_list, the last: it spans the frame's bands (cleared when a frame begins).
    static_assert(offsetof(TaskCounters, longest_list) + sizeof(fresh.longest_list) == sizeof(TaskCounters));
    CATGS_CUDA_CHECK(
        cudaMemcpyAsync(a.counters, &fresh, offsetof(TaskCounters, longest_list), cudaMemcpyHostToDevice, s));
    if (a.pairs == 0 || a.shared_list) return;
    with_tile_key(a.keys.width, [&](auto key) {
        using Key = decltype(key);
        ranges_kernel<<<blocks_for(a.pairs, kThreads), kThreads, 0, s>>>(a.pairs, key_data<const Key>(a.keys), a.tiles,
                                                                         a.range_begin, a.range_end, a.counters);
    });
    CATGS_CUDA_CHECK_LAUNCH("ranges_kernel");
}

}  // namespace catgs::cuda
