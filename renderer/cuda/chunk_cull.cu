#include "chunk_cull.cuh"

#include <cub/block/block_scan.cuh>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/stages/chunks.hpp"
#include "cuda_check.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {
namespace {

// One launch for the whole stage: at a frame's start the GPU is idle and waits for each
// operation the host enqueues, so the poses' upload, the flags and CUB's two-kernel select
// cost their launches more than their work (a few thousand chunks).
constexpr int kCullThreads = 256;
// Flags the last block compacts per thread and step: 2048 a step, four steps on 7.4M Gaussians.
constexpr int kCompactItems = 8;

// The poses, read once per block from the host's mapped staging, as 32-bit words.
template <typename T>
__device__ void stage_views(const View<T>* host_views, int window, View<T>* shared, View<T>* device_views) {
    static_assert(sizeof(View<T>) % sizeof(std::uint32_t) == 0, "views are copied as 32-bit words");
    const int words = window * static_cast<int>(sizeof(View<T>) / sizeof(std::uint32_t));
    const auto* from = reinterpret_cast<const std::uint32_t*>(host_views);
    auto* to = reinterpret_cast<std::uint32_t*>(shared);
    for (int w = threadIdx.x; w < words; w += blockDim.x) to[w] = from[w];
    __syncthreads();
    // The later stages read the poses from device memory.
    if (blockIdx.x == 0) {
        auto* out = reinterpret_cast<std::uint32_t*>(device_views);
        for (int w = threadIdx.x; w < words; w += blockDim.x) out[w] = to[w];
    }
}

// The last block: every flag, in chunk order, into the selected list and its count.
__device__ void compact_flags(const std::uint8_t* flags, std::uint32_t count, std::uint32_t* selected,
                              unsigned long long* live_chunks) {
    using Scan = cub::BlockScan<std::uint32_t, kCullThreads>;
    __shared__ typename Scan::TempStorage scan;
    std::uint32_t base = 0;
    for (std::uint32_t first = 0; first < count; first += kCullThreads * kCompactItems) {
        const std::uint32_t mine = first + threadIdx.x * kCompactItems;
        std::uint8_t f[kCompactItems];
        std::uint32_t n = 0;
        for (int j = 0; j < kCompactItems; ++j) {
            // Past L1: the other blocks wrote these.
            f[j] = mine + j < count ? __ldcg(flags + mine + j) : 0;
            n += f[j];
        }
        std::uint32_t at = 0, step_total = 0;
        Scan(scan).ExclusiveSum(n, at, step_total);
        for (int j = 0; j < kCompactItems; ++j)
            if (f[j]) selected[base + at++] = mine + j;
        base += step_total;
        __syncthreads();  // the scan's storage, again
    }
    if (threadIdx.x == 0) *live_chunks = base;
}

// Flags the chunks that some pose of the window may see (stages/chunks.hpp); the last block
// to finish compacts them (the ticket counts finished blocks; FrameCounters resets it).
template <typename T>
__global__ void __launch_bounds__(kCullThreads)
    chunk_cull_kernel(const Chunk* chunks, std::uint32_t count, const View<T>* host_views, View<T>* device_views,
                      int window, T guard, T guard_translation, std::uint8_t* flags, std::uint32_t* selected,
                      unsigned long long* live_chunks, unsigned int* ticket) {
    __shared__ __align__(16) unsigned char views_raw[kMaxWindow * sizeof(View<T>)];
    View<T>* views = reinterpret_cast<View<T>*>(views_raw);
    stage_views(host_views, window, views, device_views);
    const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c < count) flags[c] = chunk_in_window(chunks[c], views, window, guard, guard_translation) ? 1 : 0;
    __threadfence();
    __shared__ bool last;
    __syncthreads();
    if (threadIdx.x == 0) last = atomicAdd(ticket, 1u) == gridDim.x - 1;
    __syncthreads();
    if (!last) return;
    __threadfence();
    compact_flags(flags, count, selected, live_chunks);
}

}  // namespace

template <typename T>
void chunk_cull(const ChunkCullArgs<T>& a, cudaStream_t s) {
    if (a.window < 1 || a.window > kMaxWindow) throw Error("cuda renderer: chunk_cull over a window outside 1..16");
    ChunkBuffers& b = *a.buffers;
    b.flags.reserve(a.count, s);
    b.selected.reserve(a.count, s);
    chunk_cull_kernel<T><<<blocks_for(a.count, kCullThreads), kCullThreads, 0, s>>>(
        a.chunks, a.count, a.host_views, a.views, a.window, a.guard, a.guard_translation, b.flags.data(),
        b.selected.data(), a.live_chunks, a.ticket);
    CATGS_CUDA_CHECK_LAUNCH("chunk_cull_kernel");
}

template void chunk_cull(const ChunkCullArgs<float>&, cudaStream_t);
template void chunk_cull(const ChunkCullArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
