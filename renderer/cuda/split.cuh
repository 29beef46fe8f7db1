// split: the task list, CaT-GS Algorithm 1 (stages/split.hpp): the lists longer than k cut
// into sub-tasks, appended through an atomic task counter with (tile, split index) labels; and
// the task order's heavy lists (runs_first), which rasterize starts before the rest.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "kernel_common.cuh"

namespace catgs::cuda {

struct SplitArgs {
    std::uint32_t tiles;
    const std::uint64_t* range_begin;
    const std::uint64_t* range_end;
    bool splitting;           // cut the long lists (else only the heavy lists are listed)
    std::uint64_t max_extra;  // room in labels
    bool auto_k;              // derive k from this frame's lists
    TaskCounters* counters;
    std::uint32_t* split_slot;
    TaskLabel* labels;
    /// The heavy lists: room for heavy_room tiles (0: none listed, runs_first not written) and
    /// every tile's flag.
    double heavy_factor;
    std::uint32_t heavy_room;
    std::uint32_t* heavy_tiles;
    std::uint8_t* runs_first;
};

void split(const SplitArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
