#include "ranges.cuh"

#include <cub/block/block_reduce.cuh>

#include "cuda_check.hpp"

#include <cstddef>

namespace catgs::cuda {
namespace {

// Pairs a thread of ranges takes. One a thread made a block of 256 pairs, and every block adds
// its two counts to the same two words: at 4K (26M pairs) about 200k atomics on two addresses,
// which the L2 serialises (ranges took 0.113 ms at city_ring 4K). 16 a thread cut them
// sixteenfold: 0.069 ms (H200, session 18).
constexpr int kRangesItems = 16;
constexpr int kRangesPairsPerBlock = kThreads * kRangesItems;

// Tile ranges; ids beyond the grid are ignored rather than written (defence against
// a corrupted key, the failure mode of gaussian-splatting#781). A block's pairs are
// consecutive, taken a block-wide stride at a time so that each load is coalesced.
template <typename Key>
__global__ void ranges_kernel(std::uint64_t n, const Key* keys, std::uint32_t tiles, std::uint64_t* range_begin,
                              std::uint64_t* range_end, TaskCounters* counters) {
    const std::uint64_t first_pair = static_cast<std::uint64_t>(blockIdx.x) * kRangesPairsPerBlock;
    unsigned firsts = 0, insides = 0;
#pragma unroll
    for (int j = 0; j < kRangesItems; ++j) {
        const std::uint64_t i = first_pair + static_cast<std::uint64_t>(j) * kThreads + threadIdx.x;
        if (i >= n) break;
        const std::uint32_t tile = keys[i];
        if (tile >= tiles) continue;
        ++insides;
        if (i == 0 || keys[i - 1] != tile) {
            range_begin[tile] = i;
            ++firsts;
        }
        if (i + 1 == n || keys[i + 1] != tile) range_end[tile] = i + 1;
    }
    using Reduce = cub::BlockReduce<unsigned, kThreads>;
    __shared__ typename Reduce::TempStorage temp;
    const unsigned block_firsts = Reduce(temp).Sum(firsts);
    __syncthreads();
    const unsigned block_insides = Reduce(temp).Sum(insides);
    if (threadIdx.x == 0 && block_firsts > 0) atomicAdd(&counters->nonempty_tiles, block_firsts);
    if (threadIdx.x == 0 && block_insides > 0)
        atomicAdd(&counters->rendered_pairs, static_cast<unsigned long long>(block_insides));
}

}  // namespace

void ranges(const RangesArgs& a, cudaStream_t s) {
    // Empty tiles keep [0, 0).
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_begin, 0, a.tiles * sizeof(std::uint64_t), s));
    CATGS_CUDA_CHECK(cudaMemsetAsync(a.range_end, 0, a.tiles * sizeof(std::uint64_t), s));
    TaskCounters fresh{};
    fresh.split_k = a.fixed_split_k;
    // All but the last two, longest_list and occlusion_misses: they span the frame's bands
    // (cleared when a frame begins).
    static_assert(offsetof(TaskCounters, occlusion_misses) > offsetof(TaskCounters, longest_list) &&
                  offsetof(TaskCounters, occlusion_misses) + sizeof(fresh.occlusion_misses) + alignof(TaskCounters) >
                      sizeof(TaskCounters));
    CATGS_CUDA_CHECK(
        cudaMemcpyAsync(a.counters, &fresh, offsetof(TaskCounters, longest_list), cudaMemcpyHostToDevice, s));
    if (a.pairs == 0 || a.shared_list) return;
    with_tile_key(a.keys.width, [&](auto key) {
        using Key = decltype(key);
        ranges_kernel<<<blocks_for(a.pairs, kRangesPairsPerBlock), kThreads, 0, s>>>(
            a.pairs, key_data<const Key>(a.keys), a.tiles, a.range_begin, a.range_end, a.counters);
    });
    CATGS_CUDA_CHECK_LAUNCH("ranges_kernel");
}

}  // namespace catgs::cuda
