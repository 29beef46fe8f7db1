// sort: the pairs ordered by key, by tile and then front to back.
//
// The Gaussians are put in depth order first (depth_order: N 32-bit keys, not pairs), and
// keys then emits each Gaussian's pairs in that order. A stable radix sort over the tile bits
// alone then leaves every tile's pairs front to back, ties in Gaussian (slot) order: the order
// a full sort of the (tile | depth) keys gives, with 2 passes over the pairs instead of 6
// (32 depth bits + 13..15 tile bits, 8 bits a pass). Banded frames emit in slot order and
// sort over every used key bit.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "frame_buffers.hpp"

namespace catgs::cuda {

struct SortArgs {
    PairBuffers* pairs;  // sorts keys/values[current]; current then names the sorted pair
    std::uint64_t count;
    int tile_bits;
    /// The pairs were emitted in depth order (depth_order): only the tile bits are sorted.
    bool depth_ordered = false;
};

void sort(const SortArgs& args, cudaStream_t stream);

struct DepthOrderArgs {
    std::uint64_t slots;
    const std::uint64_t* touched;  // per slot: its pairs (0: in no list, sorts last)
    const float* depth;            // per slot: the depth its keys carry
    DepthOrderBuffers* order;      // out: order.slots(), ranked_touched (n + 1 entries, the last 0)
};

/// The slots with pairs, front to back (a stable CUB radix sort of their depth bits, so equal
/// depths keep slot order), and their pair counts in that order, ready for the scan.
void depth_order(const DepthOrderArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
