#include "chunk_cull.cuh"

#include <cub/block/block_scan.cuh>
#include <string>

#include "catgs/constants.hpp"
#include "catgs/error.hpp"
#include "catgs/stages/chunks.hpp"
#include "cuda_check.hpp"
#include "device_buffer.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {
namespace {

// One launch for the whole stage: at a frame's start the GPU is idle and waits for each
// operation the host enqueues, so the poses' upload, the flags and CUB's two-kernel select
// cost their launches more than their work (a few thousand chunks).
constexpr int kCullThreads = 512;
// Flags the last block compacts per thread and step, read as two 16-byte words: 16384 a step,
// one step up to 16M Gaussians (the last block's steps are the stage's serial part).
constexpr int kCompactItems = 32;
static_assert(kArenaGranularity % kCompactItems == 0, "a step's last words stay inside the flags' arena");

// The poses: the first by value (a plain frame's only one, with no read over the bus), the
// rest read once per block from the host's mapped staging, as 32-bit words.
template <typename T>
__device__ void stage_views(const View<T>& first, const View<T>* host_views, int window, View<T>* shared,
                            View<T>* device_views) {
    static_assert(sizeof(View<T>) % sizeof(std::uint32_t) == 0, "views are copied as 32-bit words");
    constexpr int kViewWords = static_cast<int>(sizeof(View<T>) / sizeof(std::uint32_t));
    const int words = window * kViewWords;
    const auto* param = reinterpret_cast<const std::uint32_t*>(&first);
    const auto* from = reinterpret_cast<const std::uint32_t*>(host_views);
    auto* to = reinterpret_cast<std::uint32_t*>(shared);
    for (int w = threadIdx.x; w < words; w += blockDim.x) to[w] = w < kViewWords ? param[w] : from[w];
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
    constexpr int kWords = kCompactItems / 4;
    std::uint32_t base = 0;
    for (std::uint32_t first = 0; first < count; first += kCullThreads * kCompactItems) {
        const std::uint32_t mine = first + threadIdx.x * kCompactItems;
        std::uint32_t word[kWords] = {};
        std::uint32_t n = 0;
        if (mine < count) {
            // Past L1: the other blocks wrote these. Bytes past `count` are masked below.
            const auto* at = reinterpret_cast<const uint4*>(flags + mine);
            for (int q = 0; q < kWords / 4; ++q) {
                const uint4 v = __ldcg(at + q);
                word[4 * q] = v.x, word[4 * q + 1] = v.y, word[4 * q + 2] = v.z, word[4 * q + 3] = v.w;
            }
            for (int j = 0; j < kCompactItems; ++j)
                if (mine + j >= count) word[j / 4] &= ~(0xffu << (8 * (j % 4)));
            for (int w = 0; w < kWords; ++w) n += __popc(word[w]);  // each flag is 0 or 1
        }
        std::uint32_t at = 0, step_total = 0;
        Scan(scan).ExclusiveSum(n, at, step_total);
        for (int j = 0; j < kCompactItems; ++j)
            if ((word[j / 4] >> (8 * (j % 4))) & 1u) selected[base + at++] = mine + j;
        base += step_total;
        __syncthreads();  // the scan's storage, again
    }
    if (threadIdx.x == 0) *live_chunks = base;
}

// Flags the chunks that some pose of the window may see (stages/chunks.hpp); the last block
// to finish compacts them (the ticket counts finished blocks; FrameCounters resets it).
template <typename T>
__global__ void __launch_bounds__(kCullThreads)
    chunk_cull_kernel(const Chunk* chunks, std::uint32_t count, const __grid_constant__ View<T> first_view,
                      const View<T>* host_views, View<T>* device_views, int window, T guard, T guard_translation,
                      std::uint8_t* flags, std::uint32_t* selected, unsigned long long* live_chunks,
                      unsigned int* ticket) {
    __shared__ __align__(16) unsigned char views_raw[kMaxWindow * sizeof(View<T>)];
    View<T>* views = reinterpret_cast<View<T>*>(views_raw);
    stage_views(first_view, host_views, window, views, device_views);
    const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
    if (c < count) flags[c] = chunk_in_window(chunks[c], views, window, guard, guard_translation) ? 1 : 0;
    if (!last_block_done(ticket)) return;
    compact_flags(flags, count, selected, live_chunks);
}

}  // namespace

template <typename T>
void chunk_cull(const ChunkCullArgs<T>& a, cudaStream_t s) {
    if (a.window < 1 || a.window > kMaxWindow)
        throw Error("cuda renderer: chunk_cull over a window of " + std::to_string(a.window) + " poses, outside 1.." +
                    std::to_string(kMaxWindow));
    ChunkBuffers& b = *a.buffers;
    b.flags.reserve(a.count, s);
    b.selected.reserve(a.count, s);
    chunk_cull_kernel<T><<<blocks_for(a.count, kCullThreads), kCullThreads, 0, s>>>(
        a.chunks, a.count, a.first_view, a.host_views, a.views, a.window, a.guard, a.guard_translation, b.flags.data(),
        b.selected.data(), a.live_chunks, a.ticket);
    CATGS_CUDA_CHECK_LAUNCH("chunk_cull_kernel");
}

template void chunk_cull(const ChunkCullArgs<float>&, cudaStream_t);
template void chunk_cull(const ChunkCullArgs<double>&, cudaStream_t);

}  // namespace catgs::cuda
