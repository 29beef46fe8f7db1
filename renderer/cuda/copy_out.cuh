// copy_out: the image to host memory through pinned staging (RGB8 quantised on the device,
// and/or float RGB).
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
    PinnedArray<std::uint8_t>* host_rgb8;
    PinnedArray<float>* host_float;
};

/// Enqueues the copies; the host buffers are complete once the stream is synchronised.
void copy_out(const CopyOutArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
