// composite: a sharded frame's partials merged front to back on one GPU, one thread a pixel,
// with the split merge's operation (merge_shard_partial, stages/split.hpp) and the background
// added as rasterize adds it (write_pixel): the GPU twin of composite_partials
// (sharded_renderer.hpp), which the tests hold it to.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "catgs/math.hpp"
#include "catgs/shard_plan.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {

/// Each shard's partial on the compositing device, front to back. Passed by value (1.6 KB of
/// kernel parameters at kMaxShards), so a frame launches without uploading a pointer table.
struct CompositeArgs {
    std::uint64_t pixels;
    int shards;
    const float* colour[kMaxShards];  // C arrays: std::array's operator[] is host-only
    const float* transmittance[kMaxShards];
    const std::uint8_t* stopped[kMaxShards];
    Vec3<float> background;
    PixelOutputs out;  // rgb8 and/or rgb; no transmittance, stops or tile counts
};

void composite_partials(const CompositeArgs& args, cudaStream_t stream);

}  // namespace catgs::cuda
