#include "occlusion.cuh"

#include "cuda_check.hpp"
#include "kernel_common.cuh"

namespace catgs::cuda {
namespace {

__global__ void predict_occlusion_kernel(const float* recorded, int tiles_x, int tiles_y, OcclusionMotion motion,
                                         float* level0) {
    const int tile = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
    if (tile >= tiles_x * tiles_y) return;
    level0[tile] = predicted_cut(recorded, tiles_x, tiles_y, tile % tiles_x, tile / tiles_x, motion);
}

/// Level `level` of the pyramid from the level below.
__global__ void occlusion_level_kernel(OcclusionPyramid p, int level, float* cells) {
    const int cell = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
    const int w = p.width[level];
    if (cell >= w * p.height[level]) return;
    cells[p.at(level, cell % w, cell / w)] = pyramid_cell(p, cells, level, cell % w, cell / w);
}

}  // namespace

void predict_occlusion(const float* recorded, const OcclusionPyramid& p, const OcclusionMotion& motion,
                       float* pyramid_cells, cudaStream_t s) {
    const int tiles = p.width[0] * p.height[0];
    predict_occlusion_kernel<<<blocks_for(tiles, kThreads), kThreads, 0, s>>>(recorded, p.width[0], p.height[0], motion,
                                                                              pyramid_cells);
    CATGS_CUDA_CHECK_LAUNCH("predict_occlusion_kernel");
    for (int level = 1; level < p.levels; ++level) {
        const int cells = p.width[level] * p.height[level];
        occlusion_level_kernel<<<blocks_for(cells, kThreads), kThreads, 0, s>>>(p, level, pyramid_cells);
        CATGS_CUDA_CHECK_LAUNCH("occlusion_level_kernel");
    }
}

}  // namespace catgs::cuda
