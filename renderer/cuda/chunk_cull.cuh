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
    const std::uint32_t* all_chunks;  // 0..count-1: what the compaction picks from
    std::uint32_t count;
    const View<T>* views;  // the window's poses
    int window;
    T guard, guard_translation;    // the envelope (cache.hpp); 0 without speculation
    ChunkBuffers* buffers;         // flags, the selected chunks and their count
    std::uint32_t* host_selected;  // pinned: the count on its way to the host
};

/// Flags and compacts the visible chunks into buffers->selected; returns how many there are.
/// Synchronises the stream (the count sizes the rest of the frame).
template <typename T>
std::uint32_t chunk_cull(const ChunkCullArgs<T>& args, cudaStream_t stream);

}  // namespace catgs::cuda
