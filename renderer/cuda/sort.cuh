// sort: the pairs ordered by key, by tile and then front to back: a CUB radix sort over the
// used key bits only (32 depth bits + the bits of the tile ids).
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "frame_buffers.hpp"

namespace catgs::cuda {

struct SortArgs {
    PairBuffers* pairs;  // sorts keys/values[current]; current then names the sorted pair
    std::uint64_t count;
    int tile_bits;
};

void sort(const SortArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
