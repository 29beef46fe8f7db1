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

// Lists an unsplit tile among the heavy ones when runs_first says so and there is room; the
// rest of the heavy ones keep their place in row order.
__device__ void list_if_heavy(const SplitArgs& a, std::uint32_t t, std::uint64_t size) {
    bool first = runs_first(size, a.counters->rendered_pairs, a.counters->nonempty_tiles, a.heavy_factor);
    if (first) {
        const unsigned at = atomicAdd(&a.counters->heavy_tiles, 1u);
        first = at < a.heavy_room;
        if (first) a.heavy_tiles[at] = t;
    }
    a.runs_first[t] = first ? 1 : 0;
}

// CaT-GS Algorithm 1: a tile longer than k keeps its remainder-sized first
// sub-task as task `tile`; its split_num extra sub-tasks are appended through the atomic
// task counter with (tile, split index) labels. Split tiles get split_num + 1 partial slots,
// which the last of their sub-tasks to finish merges (merge.cuh). Unsplit tiles may be listed
// as heavy (list_if_heavy).
__global__ void split_kernel(SplitArgs a) {
    const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
    if (t >= a.tiles) return;
    TaskCounters* counters = a.counters;
    const std::uint64_t size = a.range_end[t] - a.range_begin[t];
    const std::uint32_t splits = a.splitting ? split_count(size, counters->split_k) : 0u;
    if (splits == 0) {
        if (a.splitting) a.split_slot[t] = kNoSlot;
        if (a.heavy_room > 0) list_if_heavy(a, t, size);
        return;
    }
    if (a.heavy_room > 0) a.runs_first[t] = 0;
    const std::uint32_t first_extra = atomicAdd(&counters->extra_tasks, splits);
    a.split_slot[t] = atomicAdd(&counters->split_slots, splits + 1);
    atomicAdd(&counters->split_tiles, 1u);
    for (std::uint32_t i = 1; i <= splits; ++i)
        if (first_extra + i - 1 < a.max_extra) a.labels[first_extra + i - 1] = TaskLabel{t, i};
}

}  // namespace

void split(const SplitArgs& a, cudaStream_t s) {
    if (a.splitting && a.auto_k) {
        auto_split_kernel<<<1, 1, 0, s>>>(a.counters);
        CATGS_CUDA_CHECK_LAUNCH("auto_split_kernel");
    }
    if (!a.splitting && a.heavy_room == 0) return;
    split_kernel<<<blocks_for(a.tiles, kThreads), kThreads, 0, s>>>(a);
    CATGS_CUDA_CHECK_LAUNCH("split_kernel");
}

}  // namespace catgs::cuda
