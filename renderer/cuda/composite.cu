#include "catgs/stages/blend.hpp"
#include "catgs/stages/split.hpp"
#include "composite.cuh"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// A thread a pixel: the kernel is one pass over the partials (k x 17 bytes a pixel read, 3 or
// 12 written), memory-bound; 256 threads keep the loads of 8 warps in flight per block.
constexpr int kCompositeThreads = 256;

__global__ void composite_kernel(const CompositeArgs a) {
    const std::uint64_t pixel = static_cast<std::uint64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
    if (pixel >= a.pixels) return;
    MergeState<float> m;
    for (int s = 0; s < a.shards && !m.done; ++s) {
        const float* c = a.colour[s] + 3 * pixel;
        merge_shard_partial(m, Partial<float>{{c[0], c[1], c[2]}, a.transmittance[s][pixel]}, a.stopped[s][pixel] != 0);
    }
    PixelAccumulator<float> acc;
    acc.colour = m.colour;
    acc.transmittance = m.transmittance;
    write_pixel(acc, a.background, pixel, a.out);
}

}  // namespace

void composite_partials(const CompositeArgs& args, cudaStream_t stream) {
    if (args.pixels == 0) return;
    composite_kernel<<<blocks_for(args.pixels, kCompositeThreads), kCompositeThreads, 0, stream>>>(args);
    CATGS_CUDA_CHECK_LAUNCH("composite_kernel");
}

}  // namespace catgs::cuda
