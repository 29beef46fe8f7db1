// merge: each split tile's sub-tasks composited front to back from their partial (R, A)
// (stages/blend.hpp), written as the tile's final pixels.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "catgs/math.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {

template <typename T>
struct MergeArgs {
    std::uint64_t blocks;  // at least the split tiles
    const std::uint32_t* split_tiles;
    const std::uint32_t* split_slot;
    const std::uint64_t* range_begin;
    const std::uint64_t* range_end;
    const TaskCounters* counters;
    const Partial<T>* partials;
    View<T> view;
    Vec3<T> background;
    PixelOutputs out;
};

template <typename T>
void merge(const MergeArgs<T>& args, cudaStream_t stream);

}  // namespace catgs::cuda
