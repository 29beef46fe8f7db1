#include "copy_out.cuh"

#include "cuda_check.hpp"

namespace catgs::cuda {

void copy_out(const CopyOutArgs& a, cudaStream_t s) {
    if (a.rgb8) {
        a.host_rgb8->reserve(3 * a.pixels);
        CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_rgb8->data(), a.rgb8, 3 * a.pixels, cudaMemcpyDeviceToHost, s));
    }
    if (a.rgb_float) {
        a.host_float->reserve(3 * a.pixels);
        CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_float->data(), a.rgb_float, 3 * a.pixels * sizeof(float),
                                         cudaMemcpyDeviceToHost, s));
    }
    if (a.transmittance) {
        a.host_transmittance->reserve(a.pixels);
        CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_transmittance->data(), a.transmittance, a.pixels * sizeof(float),
                                         cudaMemcpyDeviceToHost, s));
    }
    if (a.stopped) {
        a.host_stopped->reserve(a.pixels);
        CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_stopped->data(), a.stopped, a.pixels, cudaMemcpyDeviceToHost, s));
    }
}

}  // namespace catgs::cuda
