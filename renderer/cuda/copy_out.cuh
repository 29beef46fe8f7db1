// copy_out: the image to host memory through pinned staging (RGB8 quantised on the device,
// and/or float RGB; a partial frame's transmittance and stops).
#pragma once

#include <cuda_runtime_api.h>

#include <cstddef>
#include <cstdint>

#include "frame_buffers.hpp"

namespace catgs::cuda {

struct CopyOutArgs {
    std::size_t pixels;
    const std::uint8_t* rgb8;  // device; null: not asked for
    const float* rgb_float;
    const float* transmittance;
    const std::uint8_t* stopped;
    PinnedArray<std::uint8_t>* host_rgb8;
    PinnedArray<float>* host_float;
    PinnedArray<float>* host_transmittance;
    PinnedArray<std::uint8_t>* host_stopped;
};

/// Enqueues the copies; the host buffers are complete once the stream is synchronised.
void copy_out(const CopyOutArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
