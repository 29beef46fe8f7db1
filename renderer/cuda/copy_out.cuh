// copy_out: the image to host memory through pinned staging (RGB8 quantised on the device,
// and/or float RGB; a partial frame's transmittance and stops), in bands of tile rows, each on
// a stream of its own. Each band's copy waits on the device's count of its drawn tiles
// (rasterize and merge count them: tile_drawn), so the copy runs while the rest of the image
// is drawn, in whatever order the bands finish (a horizon's long lists at the top of the image
// finish last, unless they are heavy lists, whose pixels reach the host on their own:
// PixelOutputs::heavy_rgb8), and only the last band's is left once the last pixel is written.
// Where the driver has no stream memory waits, a band waits for an event after the pass that
// drew it.
#pragma once

#include <cuda_runtime_api.h>

#include <array>
#include <cstddef>
#include <cstdint>

#include "frame_buffers.hpp"

namespace catgs::cuda {

struct CopyOutArgs {
    int width;
    const std::uint8_t* rgb8;  // device; null: not asked for
    const float* rgb_float;
    const float* transmittance;
    const std::uint8_t* stopped;
    PinnedArray<std::uint8_t>* host_rgb8;
    PinnedArray<float>* host_float;
    PinnedArray<float>* host_transmittance;
    PinnedArray<std::uint8_t>* host_stopped;
};

/// Sizes the host buffers for `pixels`; before the frame's first copy, since a pinned
/// reallocation synchronises the device.
void reserve_copy_out(const CopyOutArgs& args, std::size_t pixels);

/// Enqueues the copies of pixel rows [row_begin, row_end); the host buffers hold them once the
/// stream has passed them.
void copy_out(const CopyOutArgs& args, int row_begin, int row_end, cudaStream_t stream);

/// Makes `stream` wait until the device counter reaches `count` (a stream memory wait: no SM,
/// no host). False, with nothing enqueued, where the driver does not offer it.
bool wait_for_count(cudaStream_t stream, const unsigned int* counter, unsigned int count);

/// The streams copy_out's copies run on, one a copy band, and the events that order them with
/// the renderer's stream: `ready` once the frame's counts are reset, `drawn` after a pass (the
/// fallback), `copied[b]` after band b's copy, on which the host takes the band into the
/// caller's image while the next are drawn and copied, and the renderer's stream ends the frame.
struct CopyStreams {
    std::array<cudaStream_t, kMaxCopyBands> band{};
    cudaEvent_t ready = nullptr, drawn = nullptr;
    std::array<cudaEvent_t, kMaxCopyBands> copied{};
    /// Per copy band, its tiles drawn (tile_drawn). Plain device memory: the driver's stream
    /// memory waits refuse the stream-ordered pool's allocations (CUDA_ERROR_INVALID_VALUE on
    /// the H200's driver 580), where the renderer's arenas live.
    unsigned int* tiles_drawn = nullptr;

    CopyStreams();
    ~CopyStreams();
    CopyStreams(const CopyStreams&) = delete;
    CopyStreams& operator=(const CopyStreams&) = delete;
};

}  // namespace catgs::cuda
