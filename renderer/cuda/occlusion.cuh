// occlusion: the occlusion cut's prediction (stages/occlusion.hpp) on the device: the last
// frame's recorded tile cuts widened over a neighbourhood into level 0 of the cut pyramid, then
// each level above as the max of the one below. preprocess reads the pyramid; rasterize checks
// each tile against level 0 and records this frame's cuts for the next.
#pragma once

#include <cuda_runtime_api.h>

#include "catgs/stages/occlusion.hpp"
#include "device_buffer.hpp"

namespace catgs::cuda {

/// The cut that preprocess and rasterize read: null `cuts` when the frame has none.
struct OcclusionCut {
    const float* cuts = nullptr;  // the pyramid, level 0 first
    OcclusionPyramid pyramid{};
    CATGS_HD bool active() const { return cuts != nullptr; }
};

/// The renderer's cut state across frames: the pyramid of this frame's prediction and the tile
/// cuts recorded by rasterize, twice: the last frame's feed this frame's prediction while this
/// frame records into the other.
struct OcclusionBuffers {
    DeviceArray<float> pyramid;
    DeviceArray<float> recorded[2];
    int current = 0;  // recorded[current]: the last frame's; this frame writes recorded[1 - current]

    float* last_records() const { return recorded[current].data(); }
    float* this_frame_records() const { return recorded[1 - current].data(); }

    std::size_t bytes() const { return pyramid.bytes() + recorded[0].bytes() + recorded[1].bytes(); }
};

/// Fills `pyramid_cells` (p.cells floats) from `recorded` (the last frame's cuts over the same
/// tile grid, p's level 0).
void predict_occlusion(const float* recorded, const OcclusionPyramid& p, const OcclusionMotion& motion,
                       float* pyramid_cells, cudaStream_t stream);

}  // namespace catgs::cuda
