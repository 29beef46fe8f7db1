#include "chunk_cull.cuh"

#include <cub/device/device_select.cuh>

#include "catgs/stages/chunks.hpp"
#include "cuda_check.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {
namespace {

// Flags the chunks that some pose of the window may see (stages/chunks.hpp).
template <typename T>
__global__ void chunk_cull_kernel(const Chunk* chunks, std::uint32_t count, const View<T>* views, int window, T guard,
                                  T guard_translation, std::uint8_t* flags) {
    const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c < count) flags[c] = chunk_in_window(chunks[c], views, window, guard, guard_translation) ? 1 : 0;
}

}  // namespace

template <typename T>
void chunk_cull(const ChunkCullArgs<T>& a, cudaStream_t s) {
    ChunkBuffers& b = *a.buffers;
    b.flags.reserve(a.count, s);
    b.selected.reserve(a.count, s);
    chunk_cull_kernel<T><<<blocks_for(a.count, kThreads), kThreads, 0, s>>>(
        a.chunks, a.count, a.views, a.window, a.guard, a.guard_translation, b.flags.data());
    CATGS_CUDA_CHECK_LAUNCH("chunk_cull_kernel");
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, temp_bytes, a.all_chunks, b.flags.data(), b.selected.data(),
                                                a.live_chunks, static_cast<std::int64_t>(a.count), s));
    b.select_temp.reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceSelect::Flagged(b.select_temp.data(), temp_bytes, a.all_chunks, b.flags.data(),
                                                b.selected.data(), a.live_chunks, static_cast<std::int64_t>(a.count),
                                                s));
}

template void chunk_cull(const ChunkCullArgs<float>&, cudaStream_t);
template void chunk_cull(const ChunkCullArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
