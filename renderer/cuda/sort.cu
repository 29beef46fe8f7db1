#include "sort.cuh"

#include <cub/device/device_radix_sort.cuh>

#include "catgs/stages/keys.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {

void sort(const SortArgs& a, cudaStream_t s) {
    if (a.count <= 1) return;
    PairBuffers& p = *a.pairs;
    cub::DoubleBuffer<std::uint64_t> kb(p.keys[p.current].data(), p.keys[1 - p.current].data());
    cub::DoubleBuffer<std::uint32_t> vb(p.values[p.current].data(), p.values[1 - p.current].data());
    const int end_bit = kSortKeyDepthBits + a.tile_bits;
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb, static_cast<std::int64_t>(a.count), 0,
                                                     end_bit, s));
    p.sort_temp.reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(p.sort_temp.data(), temp_bytes, kb, vb,
                                                     static_cast<std::int64_t>(a.count), 0, end_bit, s));
    p.current = kb.selector == 0 ? p.current : 1 - p.current;
}

}  // namespace catgs::cuda
