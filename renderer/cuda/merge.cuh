// merge: each split tile's sub-tasks composited front to back from their partial (R, A)
// (stages/split.hpp), written as the tile's final pixels. On the GPU it runs inside
// rasterize: the last of a split tile's sub-tasks to finish merges the tile (a ticket a tile
// counts them) and counts it drawn, so the copy band holding it is copied while the rest of
// the frame is still drawn. A merge kernel after rasterize held every band with a split tile
// until the whole frame was drawn, and on the garden at 1080p, where split tiles lie in most
// bands, nearly the whole image was copied after the last tile.
#pragma once

#include <cstdint>

#include "catgs/math.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/split.hpp"
#include "catgs/stages/view.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {

/// A partial another block wrote in this kernel, read from L2 (L1 is not coherent across
/// multiprocessors).
template <typename T>
__device__ inline Partial<T> load_partial(const Partial<T>* p) {
    return Partial<T>{{__ldcg(&p->colour.x), __ldcg(&p->colour.y), __ldcg(&p->colour.z)}, __ldcg(&p->transmittance)};
}

/// The sub-tasks of the split tile `tile` (with `parts` of them at partial slots slot ..
/// slot + parts - 1, in split order) merged into its final pixels, by the whole block of
/// `Threads` threads, after every sub-task's partials are visible to it (last_to_arrive).
template <typename T, int Threads>
__device__ void merge_split_tile(std::uint32_t tile, std::uint32_t slot, std::uint32_t parts,
                                 const Partial<T>* partials, const View<T>& view, Vec3<T> background,
                                 const PixelOutputs& out) {
    const int tile_x = static_cast<int>(tile % view.tiles_x), tile_y = static_cast<int>(tile / view.tiles_x);
    for (int rank = static_cast<int>(threadIdx.x); rank < kTilePixels; rank += Threads) {
        const int x = tile_x * kTileSize + rank % kTileSize, y = tile_y * kTileSize + rank / kTileSize;
        if (x >= view.width || y >= view.height) continue;
        const std::size_t base = static_cast<std::size_t>(slot) * kTilePixels + rank;
        MergeState<T> m;
        for (std::uint32_t i = 0; i < parts && !m.done; ++i)
            merge_partial(m, load_partial(partials + base + static_cast<std::size_t>(i) * kTilePixels));
        PixelAccumulator<T> acc;
        acc.colour = m.colour;
        acc.transmittance = m.transmittance;
        acc.done = m.done;
        write_pixel(acc, background, static_cast<std::size_t>(y) * view.width + x, out);
    }
}

}  // namespace catgs::cuda
