// CudaRenderer::read_back_stages: the last frame's stage outputs copied to the host, for the
// stage-by-stage tests against the CPU backend (tests/gpu/test_cuda_stages.cpp).
#include <cuda_runtime_api.h>

#include <algorithm>
#include <cstddef>
#include <vector>

#include "catgs/error.hpp"
#include "catgs/stages/keys.hpp"
#include "catgs/stages/split.hpp"
#include "cuda_check.hpp"
#include "cuda_renderer.hpp"
#include "renderer_state.cuh"

namespace catgs::cuda {
namespace {

/// The depth each Gaussian's keys sorted by, by Gaussian index (the device's pairs carry only
/// their tile: sort.cuh).
__global__ void depth_by_gaussian_kernel(ChunkSpace space, const std::uint64_t* touched, const float* sort_depth,
                                         float* depth_of) {
    const std::uint64_t p = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    std::uint64_t i = 0;
    if (p < space.slots && touched[p] > 0 && space.gaussian(p, i)) depth_of[i] = sort_depth[p];
}

template <typename V>
std::vector<V> copy_to_host(const V* device, std::size_t count, cudaStream_t stream) {
    std::vector<V> host(count);
    if (count > 0)
        CATGS_CUDA_CHECK(cudaMemcpyAsync(host.data(), device, count * sizeof(V), cudaMemcpyDeviceToHost, stream));
    return host;
}

}  // namespace

static_assert(StageReadback<float>::kNoPartials == kNoSlot, "one marker of an unsplit tile");

template <typename T>
StageReadback<T> CudaRenderer<T>::read_back_stages() {
    Impl& m = *impl_;
    const LastFrame& last = m.last;
    if (!last.rendered) throw Error("cuda renderer: read_back_stages before the first frame");
    if (last.banded) throw Error("cuda renderer: read_back_stages after a frame rendered in bands");
    const cudaStream_t s = m.stream;
    const PairBuffers& p = m.buffers.pairs;
    const TileBuffers& t = m.buffers.tiles;
    StageReadback<T> r;
    std::vector<std::uint32_t> tiles;
    r.tile_key_bytes = static_cast<int>(tile_key_bytes(p.width));
    with_tile_key(p.width, [&](auto key) {
        using Key = decltype(key);
        const std::vector<Key> narrow = copy_to_host(key_data<Key>(p.sorted_tiles()), last.pairs, s);
        CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
        tiles.assign(narrow.begin(), narrow.end());
    });
    r.sorted_values = copy_to_host(p.values[p.current].data(), last.pairs, s);
    const std::uint64_t gaussians = m.scene->count();
    DeviceArray<float> depth_of;
    depth_of.reserve(gaussians, s);
    CATGS_CUDA_CHECK(cudaMemsetAsync(depth_of.data(), 0, gaussians * sizeof(float), s));
    if (m.key_space.slots > 0) {
        depth_by_gaussian_kernel<<<blocks_for(m.key_space.slots, kThreads), kThreads, 0, s>>>(
            m.key_space, m.buffers.gaussians.touched.data(), m.buffers.gaussians.sort_depth.data(), depth_of.data());
        CATGS_CUDA_CHECK_LAUNCH("depth_by_gaussian_kernel");
    }
    const std::vector<float> depth = copy_to_host(depth_of.data(), gaussians, s);
    const std::vector<std::uint64_t> begin = copy_to_host(t.range_begin.data(), last.tiles, s);
    const std::vector<std::uint64_t> end = copy_to_host(t.range_end.data(), last.tiles, s);
    const std::uint64_t labels = std::min<std::uint64_t>(last.tasks.extra_tasks, last.max_extra);  // as rasterize reads
    const std::vector<TaskLabel> extra = copy_to_host(t.labels.data(), labels, s);
    std::vector<std::uint32_t> slot = copy_to_host(t.split_slot.data(), last.split_used ? last.tiles : 0, s);
    const std::uint64_t heavy = last.heavy_used ? std::min<std::uint64_t>(last.tasks.heavy_tiles, m.heavy_room()) : 0;
    r.heavy_tiles = copy_to_host(t.heavy_tiles.data(), heavy, s);
    const std::size_t partial_count = last.split_used
                                          ? std::min<std::size_t>(std::size_t{last.tasks.split_slots} * kTilePixels,
                                                                  m.buffers.pixels.partials.capacity())
                                          : 0;
    std::vector<Partial<T>> partials = copy_to_host(m.buffers.pixels.partials.data(), partial_count, s);
    CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
    r.sorted_keys.resize(tiles.size());
    for (std::size_t j = 0; j < tiles.size(); ++j)
        r.sorted_keys[j] = make_sort_key(tiles[j], depth[r.sorted_values[j]]);

    r.tile_ranges.resize(last.tiles);
    for (std::size_t i = 0; i < last.tiles; ++i)
        r.tile_ranges[i] = last.shared_list ? TileRange{0, last.pairs} : TileRange{begin[i], end[i]};
    r.tasks.resize(last.tiles);
    for (std::uint32_t i = 0; i < last.tiles; ++i) r.tasks[i] = TileTask{i, 0};
    for (const TaskLabel& l : extra) r.tasks.push_back(TileTask{l.tile, l.index});
    std::sort(
        r.tasks.begin() + static_cast<std::ptrdiff_t>(last.tiles), r.tasks.end(),
        [](const TileTask& a, const TileTask& b) { return a.tile != b.tile ? a.tile < b.tile : a.index < b.index; });
    std::sort(r.heavy_tiles.begin(), r.heavy_tiles.end());
    if (!last.split_used) return r;
    r.split_k = last.tasks.split_k;
    r.split_slot = std::move(slot);
    r.partials = std::move(partials);
    return r;
}

template StageReadback<float> CudaRenderer<float>::read_back_stages();
template StageReadback<double> CudaRenderer<double>::read_back_stages();

}  // namespace catgs::cuda
