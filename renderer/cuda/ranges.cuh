// ranges: each tile's [begin, end) in the sorted pairs, and the fresh task counters of the
// task list that split then builds.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "kernel_common.cuh"
#include "tile_key.cuh"

namespace catgs::cuda {

struct RangesArgs {
    std::uint64_t pairs;
    TileKeys keys;  // the sorted pairs' tiles
    std::uint32_t tiles;
    bool shared_list;             // exact culling: one list for every tile, no ranges
    std::uint32_t fixed_split_k;  // the task list's k unless split derives it (0)
    std::uint64_t* range_begin;
    std::uint64_t* range_end;
    TaskCounters* counters;
    RangesTally* tally;  // zero when the frame begins; ranges leaves it zero
};

void ranges(const RangesArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
