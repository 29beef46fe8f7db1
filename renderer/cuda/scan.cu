#include "scan.cuh"

#include <cub/device/device_scan.cuh>

#include "cuda_check.hpp"

namespace catgs::cuda {

std::uint64_t scan(const ScanArgs& a, cudaStream_t s) {
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(
        cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, a.counts, a.offsets, static_cast<std::int64_t>(a.n + 1), s));
    a.temp->reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(a.temp->data(), temp_bytes, a.counts, a.offsets,
                                                   static_cast<std::int64_t>(a.n + 1), s));
    if (!a.host_total) return 0;
    CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_total, a.offsets + a.n, sizeof(std::uint64_t), cudaMemcpyDeviceToHost, s));
    CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
    return *a.host_total;
}

}  // namespace catgs::cuda
