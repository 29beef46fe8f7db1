#include "sort.cuh"

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_select.cuh>
#include <thrust/iterator/counting_iterator.h>

#include <algorithm>
#include <limits>
#include <string>

#include "catgs/error.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

struct HasPairs {
    const std::uint64_t* touched;
    // ChunkSpace::live_chunks: slots past the live chunks' were not preprocessed this frame.
    // Only the pointer, not the whole ChunkSpace: with it CUB's select kernel spilled.
    const unsigned long long* live_chunks;
    __device__ bool operator()(std::uint32_t slot) const {
        return (!live_chunks || slot < *live_chunks * kChunkGaussians) && touched[slot] > 0;
    }
};

// n: the slots the buffers hold; selected (when not null): how many the select kept, on the device.
__global__ void depth_keys_kernel(std::uint64_t n, const unsigned long long* selected, const std::uint32_t* with_pairs,
                                  const float* depth, std::uint32_t* keys, std::uint32_t* slots) {
    const std::uint64_t k = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (k >= n || (selected && k >= *selected)) return;
    const std::uint32_t slot = with_pairs[k];
    // The bits make_sort_key puts in the low half of a pair's key.
    keys[k] = ordered_depth_bits(depth[slot]);
    slots[k] = slot;
}

/// The slots with pairs, in slot order (a stable CUB select), and how many there are, copied
/// to the host with the pair total beside it; `totals_read` marks the copy's end, which
/// depth_order waits for.
void select_slots_with_pairs(const DepthOrderArgs& a, cudaStream_t s) {
    if (!a.totals || !a.host_totals) throw Error("cuda renderer: depth order selects slots without its list totals");
    DepthOrderBuffers& o = *a.order;
    o.with_pairs.reserve(a.space.slots, s);
    const thrust::counting_iterator<std::uint32_t> slots(0);
    unsigned long long* count = &a.totals->with_pairs;
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(cub::DeviceSelect::If(nullptr, temp_bytes, slots, o.with_pairs.data(), count,
                                           static_cast<std::int64_t>(a.space.slots),
                                           HasPairs{a.touched, a.space.live_chunks}, s));
    o.select_temp.reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceSelect::If(o.select_temp.data(), temp_bytes, slots, o.with_pairs.data(), count,
                                           static_cast<std::int64_t>(a.space.slots),
                                           HasPairs{a.touched, a.space.live_chunks}, s));
    CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_totals, a.totals, sizeof(ListTotals), cudaMemcpyDeviceToHost, s));
    CATGS_CUDA_CHECK(cudaEventRecord(o.totals_read.get(), s));
}

std::uint64_t depth_key_room(const DepthOrderBuffers& o) {
    return std::min({o.keys[0].capacity(), o.keys[1].capacity(), o.slots[0].capacity(), o.slots[1].capacity()});
}

void launch_depth_keys(std::uint64_t n, const unsigned long long* selected, const DepthOrderArgs& a, cudaStream_t s) {
    DepthOrderBuffers& o = *a.order;
    depth_keys_kernel<<<blocks_for(n, kThreads), kThreads, 0, s>>>(n, selected, o.with_pairs.data(), a.depth,
                                                                   o.keys[0].data(), o.slots[0].data());
    CATGS_CUDA_CHECK_LAUNCH("depth_keys_kernel");
}

}  // namespace

void sort(const SortArgs& a, cudaStream_t s) {
    if (a.count <= 1) return;
    PairBuffers& p = *a.pairs;
    with_tile_key(p.width, [&](auto key) {
        using Key = decltype(key);
        cub::DoubleBuffer<Key> kb(key_data<Key>(p.tile_keys(p.current)), key_data<Key>(p.tile_keys(1 - p.current)));
        cub::DoubleBuffer<std::uint32_t> vb(p.values[p.current].data(), p.values[1 - p.current].data());
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb,
                                                         static_cast<std::int64_t>(a.count), 0, a.tile_bits, s));
        p.sort_temp.reserve(temp_bytes, s);
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(p.sort_temp.data(), temp_bytes, kb, vb,
                                                         static_cast<std::int64_t>(a.count), 0, a.tile_bits, s));
        p.current = kb.selector == 0 ? p.current : 1 - p.current;
    });
}

std::uint64_t depth_order(const DepthOrderArgs& a, cudaStream_t s) {
    DepthOrderBuffers& o = *a.order;
    if (a.space.slots > std::numeric_limits<std::uint32_t>::max())
        throw Error("cuda renderer: " + std::to_string(a.space.slots) +
                    " Gaussian slots, more than 32-bit slot ids hold");
    // A key frame's count reaches the host while the GPU already writes the depth keys of as
    // many selected slots as the buffers hold (bounded by the count on the device): the host's
    // wake-up and its next launches then overlap work instead of an idle GPU.
    std::uint64_t keyed = 0;
    if (!a.reuse_selection) {
        select_slots_with_pairs(a, s);
        keyed = std::min<std::uint64_t>(depth_key_room(o), a.space.slots);
        if (keyed > 0) launch_depth_keys(keyed, &a.totals->with_pairs, a, s);
        CATGS_CUDA_CHECK(cudaEventSynchronize(o.totals_read.get()));
        o.ranked = a.host_totals->with_pairs;
    }
    const std::uint64_t m = o.ranked;
    o.ranked_offsets.reserve(m + 1, s);
    // Arenas grow by kArenaGrowth, so a count rising along a path seldom outgrows the room the
    // keys were written into before the wait (and is keyed again here when it does).
    for (int k = 0; k < 2; ++k) {
        o.keys[k].reserve(m, s);
        o.slots[k].reserve(m, s);
    }
    o.current = 0;
    if (m > 0) {
        if (m > keyed) launch_depth_keys(m, nullptr, a, s);
        cub::DoubleBuffer<std::uint32_t> kb(o.keys[0].data(), o.keys[1].data());
        cub::DoubleBuffer<std::uint32_t> vb(o.slots[0].data(), o.slots[1].data());
        std::size_t temp_bytes = 0;
        CATGS_CUDA_CHECK(
            cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, kb, vb, static_cast<std::int64_t>(m), 0, 32, s));
        o.sort_temp.reserve(temp_bytes, s);
        CATGS_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(o.sort_temp.data(), temp_bytes, kb, vb,
                                                         static_cast<std::int64_t>(m), 0, 32, s));
        o.current = kb.selector;
    }
    return m;
}

}  // namespace catgs::cuda
