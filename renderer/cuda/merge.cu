#include "merge.cuh"

#include "catgs/stages/split.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// Composites each split tile's sub-tasks front to back.
template <typename T>
__global__ void __launch_bounds__(kTilePixels)
    merge_kernel(const std::uint32_t* split_tiles, const std::uint32_t* split_slot, const std::uint64_t* range_begin,
                 const std::uint64_t* range_end, const TaskCounters* counters, const Partial<T>* partials, View<T> view,
                 Vec3<T> background, PixelOutputs out) {
    if (blockIdx.x >= counters->split_tiles) return;
    const std::uint32_t tile = split_tiles[blockIdx.x];
    const int tile_y = static_cast<int>(tile / view.tiles_x);
    const int x = static_cast<int>(tile % view.tiles_x) * kTileSize + threadIdx.x;
    const int y = tile_y * kTileSize + threadIdx.y;
    if (x < view.width && y < view.height) {  // no return: tile_drawn waits for the whole block
        const std::uint32_t parts = split_count(range_end[tile] - range_begin[tile], counters->split_k) + 1;
        const std::size_t base =
            static_cast<std::size_t>(split_slot[tile]) * kTilePixels + threadIdx.y * kTileSize + threadIdx.x;
        MergeState<T> m;
        for (std::uint32_t i = 0; i < parts && !m.done; ++i)
            merge_partial(m, partials[base + static_cast<std::size_t>(i) * kTilePixels]);
        PixelAccumulator<T> acc;
        acc.colour = m.colour;
        acc.transmittance = m.transmittance;
        acc.done = m.done;
        write_pixel(acc, background, static_cast<std::size_t>(y) * view.width + x, out);
    }
    tile_drawn(out, tile_y);
}

}  // namespace

template <typename T>
void merge(const MergeArgs<T>& a, cudaStream_t s) {
    merge_kernel<T><<<static_cast<unsigned>(a.blocks), dim3(kTileSize, kTileSize), 0, s>>>(
        a.split_tiles, a.split_slot, a.range_begin, a.range_end, a.counters, a.partials, a.view, a.background, a.out);
    CATGS_CUDA_CHECK_LAUNCH("merge_kernel");
}

template void merge(const MergeArgs<float>&, cudaStream_t);
template void merge(const MergeArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
