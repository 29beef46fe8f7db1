#include "sort.cuh"

#include <cub/device/device_radix_sort.cuh>

#include "catgs/stages/keys.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

/// Sorts after every real depth: slots without pairs go to the end of the order.
constexpr std::uint32_t kNoPairsDepthBits = 0xffffffffu;

__global__ void depth_keys_kernel(std::uint64_t n, const std::uint64_t* touched, const float* depth,
                                  std::uint32_t* keys, std::uint32_t* slots) {
    const std::uint64_t p = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (p >= n) return;
    // The bits make_sort_key puts in the low half of a pair's key (depth > 0 orders like them).
    keys[p] = touched[p] > 0 ? __float_as_uint(depth[p]) : kNoPairsDepthBits;
    slots[p] = static_cast<std::uint32_t>(p);
}

__global__ void rank_counts_kernel(std::uint64_t n, const std::uint32_t* order, const std::uint64_t* touched,
                                   std::uint64_t* ranked_touched) {
    const std::uint64_t k = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (k < n) ranked_touched[k] = touched[order[k]];
    if (k == n) ranked_touched[n] = 0;  // the scan's trailing entry holds the total
}

}  // namespace

void sort(const SortArgs& a, cudaStream_t s) {
    if (a.count <= 1) return;
    PairBuffers& p = *a.pairs;
    cub::DoubleBuffer<std::uint64_t> kb(p.keys[p.current].data(), p.keys[1 - p.current].data());
    cub::DoubleBuffer<std::uint32_t> vb(p.values[p.current].data(), p.values[1 - p.current].data());
    const int begin_bit = a.depth_ordered ? kSortKeyDepthBits : 0;
    const int end_bit = kSortKeyDepthBits + a.tile_bits;
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb, static_cast<std::int64_t>(a.count),
                                                     begin_bit, end_bit, s));
    p.sort_temp.reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(p.sort_temp.data(), temp_bytes, kb, vb,
                                                     static_cast<std::int64_t>(a.count), begin_bit, end_bit, s));
    p.current = kb.selector == 0 ? p.current : 1 - p.current;
}

void depth_order(const DepthOrderArgs& a, cudaStream_t s) {
    DepthOrderBuffers& o = *a.order;
    const std::uint64_t n = a.slots;
    o.ranked_touched.reserve(n + 1, s);
    o.ranked_offsets.reserve(n + 1, s);
    for (int k = 0; k < 2; ++k) {
        o.keys[k].reserve(n, s);
        o.slots[k].reserve(n, s);
    }
    o.current = 0;
    if (n > 0) {
        depth_keys_kernel<<<blocks_for(n, kThreads), kThreads, 0, s>>>(n, a.touched, a.depth, o.keys[0].data(),
                                                                       o.slots[0].data());
        CATGS_CUDA_CHECK_LAUNCH("depth_keys_kernel");
        cub::DoubleBuffer<std::uint32_t> kb(o.keys[0].data(), o.keys[1].data());
        cub::DoubleBuffer<std::uint32_t> vb(o.slots[0].data(), o.slots[1].data());
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(
            cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb, static_cast<std::int64_t>(n), 0, 32, s));
        o.sort_temp.reserve(temp_bytes, s);
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(o.sort_temp.data(), temp_bytes, kb, vb,
                                                         static_cast<std::int64_t>(n), 0, 32, s));
        o.current = kb.selector;
    }
    rank_counts_kernel<<<blocks_for(n + 1, kThreads), kThreads, 0, s>>>(n, o.slots[o.current].data(), a.touched,
                                                                        o.ranked_touched.data());
    CATGS_CUDA_CHECK_LAUNCH("rank_counts_kernel");
}

}  // namespace catgs::cuda
