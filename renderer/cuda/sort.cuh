// sort: the pairs ordered by tile and, within a tile, front to back.
//
// The Gaussians are put in depth order first (depth_order: 32-bit keys of the slots that have
// pairs, not of every slot nor of the pairs), and keys then emits each Gaussian's pairs in that
// order (banded frames too, band by band). A stable radix sort of the pairs' tile ids then
// leaves every tile's pairs front to back, ties in Gaussian (slot) order: the order the CPU
// backend's sort of (tile | depth) keys gives (catgs/stages/keys.hpp), with 2 passes over 6
// bytes a pair (16-bit tile ids up to 65535 tiles, tile_key.cuh; else 8) instead of 6 over 12
// (32 depth bits + 13..15 tile bits, 8 bits a pass).
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "frame_buffers.hpp"

namespace catgs::cuda {

struct SortArgs {
    PairBuffers* pairs;  // sorts tiles/values[current] (tile ids of pairs->width); current then names the sorted pair
    std::uint64_t count;
    int tile_bits;  // sort_key_tile_bits of the grid: the parked tile included
};

void sort(const SortArgs& args, cudaStream_t stream);

struct DepthOrderArgs {
    ChunkSpace space;              // the key frame's slots (live_chunks: not yet read back)
    const std::uint64_t* touched;  // per slot: its pairs (0: in no list, left out of the order)
    const float* depth;            // per slot: the depth its keys carry
    DepthOrderBuffers* order;      // out: order.order(), order.ranked of them
    /// Keep the previous call's slots with pairs (a cached frame re-sorts its key frame's
    /// lists: same counts), so that nothing is read back.
    bool reuse_selection = false;
    /// Device: the frame's totals, where the select writes its count beside preprocess's pair
    /// total; pinned host: both read back at once. Needed unless reuse_selection.
    ListTotals* totals = nullptr;
    ListTotals* host_totals = nullptr;
};

/// The slots with pairs, front to back (a stable CUB select of them in slot order, whose count
/// is read back with the pair total, then a stable CUB radix sort of their depth bits, so equal depths keep slot
/// order), ready for the scan of their pair counts in that order. Slots without pairs are
/// most of a frame's on large scenes, and a sort over them all was 4 passes over every slot.
/// Returns how many slots the order holds (order.ranked).
std::uint64_t depth_order(const DepthOrderArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
