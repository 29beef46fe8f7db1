#include "split.cuh"

#include "catgs/cache.hpp"
#include "catgs/stages/split.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// Automatic k from this frame's lists: max(floor, factor x mean non-empty length).
__global__ void auto_split_kernel(TaskCounters* counters) {
    const unsigned nonempty = counters->nonempty_tiles;
    const double mean = nonempty ? static_cast<double>(counters->rendered_pairs) / nonempty : 0.0;
    counters->split_k = max(kAutoSplitFloor, static_cast<unsigned>(ceil(kAutoSplitFactor * mean)));
}

// CaT-GS Algorithm 1: a tile longer than k keeps its remainder-sized first
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

}  // namespace

void split(const SplitArgs& a, cudaStream_t s) {
    if (a.auto_k) {
        auto_split_kernel<<<1, 1, 0, s>>>(a.counters);
        CATGS_CUDA_CHECK_LAUNCH("auto_split_kernel");
    }
    split_kernel<<<blocks_for(a.tiles, kThreads), kThreads, 0, s>>>(a.tiles, a.range_begin, a.range_end, a.max_extra,
                                                                    a.counters, a.split_slot, a.labels, a.split_tiles);
    CATGS_CUDA_CHECK_LAUNCH("split_kernel");
}

}  // namespace catgs::cuda
