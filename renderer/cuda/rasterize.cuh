// rasterize: one block per task (a 16x16 tile or a sub-task of a split tile), of 256 threads
// of one pixel each or 128 of two (RasterLayout), the Gaussians staged through shared memory a
// batch at a time and blended front to back per pixel (stages/blend.hpp). Tiles that are not
// split write their pixels; sub-tasks write partial (R, A), and the last of a tile's sub-tasks
// to finish merges them (merge.cuh).
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "catgs/math.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"
#include "cuda_renderer.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {

struct TaskGrid {
    std::uint32_t first_tile;  // tiles of this band: [first_tile, first_tile + band_tiles)
    std::uint32_t band_tiles;
    bool split;        // split_slot / labels / partials are valid
    bool shared_list;  // exact culling: one list for every tile
    std::uint64_t list_size;
    bool warp_skip;           // warps skip Gaussians whose visible_box misses their block
    std::uint64_t max_extra;  // room for extra sub-tasks (split): blocks [0, max_extra) hold them
    /// Room for the heavy lists (runs_first), whose blocks come next; 0: the tiles in row order.
    std::uint64_t max_heavy;
    const std::uint32_t* heavy_tiles;
    const std::uint8_t* runs_first;  // a listed tile's own block in row order returns at once
};

template <typename T>
struct RasterizeArgs {
    TaskGrid grid;
    std::uint64_t blocks;  // the band's tiles plus room for its extra sub-tasks and heavy lists
    RasterLayout layout;
    const std::uint64_t* range_begin;
    const std::uint64_t* range_end;
    const std::uint32_t* split_slot;
    const TaskLabel* labels;
    TaskCounters* counters;       // rasterize records the longest task
    const std::uint32_t* values;  // sorted
    const Projected<T>* projected;
    View<T> view;
    Vec3<T> background;
    T tail_transmittance;  // where a split tile's later sub-tasks stop
    Partial<T>* partials;
    /// Per tile: how many of a split tile's sub-tasks have finished (merge.cuh); zero between
    /// frames (the merging block clears its tile's).
    unsigned int* merge_tickets;
    PixelOutputs out;
    /// The occlusion cut (stages/occlusion.hpp): this frame's predicted cut a tile, which each
    /// tile checks its stop against (misses counted in counters), or null; and where each tile
    /// records the depth it stopped at for the next frame's prediction, or null.
    const float* predicted_cut = nullptr;
    float* recorded_cut = nullptr;
};

template <typename T>
void rasterize(const RasterizeArgs<T>& args, cudaStream_t stream);

/// How many tasks the current device holds at once in `layout` (multiprocessors times the
/// kernel's resident blocks).
template <typename T>
std::uint64_t resident_tasks(RasterLayout layout);

}  // namespace catgs::cuda
