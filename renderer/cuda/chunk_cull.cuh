// chunk_cull: the chunks that some pose of a key frame's window may see (stages/chunks.hpp),
// compacted in scene order, so that the later stages walk only those and pairs are still
// emitted in Gaussian order.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "catgs/scene.hpp"
#include "catgs/stages/view.hpp"
#include "frame_buffers.hpp"

namespace catgs::cuda {

template <typename T>
struct ChunkCullArgs {
    const Chunk* chunks;
    std::uint32_t count;
    View<T> first_view;         // the window's first pose (by value: a plain frame's only one)
    const View<T>* host_views;  // all of its poses in mapped pinned memory (HostStaging::views)
    View<T>* views;             // where the later stages read them: chunk_cull puts them there
    int window;
    T guard, guard_translation;       // the envelope (cache.hpp); 0 without speculation
    ChunkBuffers* buffers;            // flags and the selected chunks
    unsigned long long* live_chunks;  // device: their count (ListTotals, read back with the totals)
    unsigned int* ticket;             // 0 at the launch: the kernel's finished blocks
};

/// Flags and compacts the visible chunks into buffers->selected, their count into
/// *live_chunks. Does not wait for it: the host reads it back with the depth order's totals
/// (sort.cuh), and until then ChunkSpace::live_chunks bounds the slots on the device.
template <typename T>
void chunk_cull(const ChunkCullArgs<T>& args, cudaStream_t stream);

}  // namespace catgs::cuda
