#include "scan.cuh"

#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/device/device_scan.cuh>
#include <limits>
#include <string>

#include "catgs/error.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {
namespace {

// The k-th count in depth order, and a 0 after the last so that offsets[n] is the total. Read
// by the scan itself: a kernel that wrote them out first cost 27 us a frame on the kit's city
// (2.8M slots, H200), more than the gather adds to the scan.
// 32-bit positions (depth_order holds at most 2^32 - 1 slots): with 64-bit ones CUB's scan
// kernel spilled.
struct RankedCount {
    const std::uint64_t* touched;
    const std::uint32_t* order;
    std::uint32_t n;
    __device__ std::uint64_t operator()(std::uint32_t k) const { return k < n ? touched[order[k]] : 0; }
};

}  // namespace

std::uint64_t scan(const ScanArgs& a, cudaStream_t s) {
    if (a.n >= std::numeric_limits<std::uint32_t>::max())
        throw Error("cuda renderer: " + std::to_string(a.n) + " slots to scan, more than 32-bit positions hold");
    const auto counts = thrust::make_transform_iterator(
        thrust::counting_iterator<std::uint32_t>(0), RankedCount{a.touched, a.order, static_cast<std::uint32_t>(a.n)});
    std::size_t temp_bytes = 0;
    CATGS_CUDA_CHECK(
        cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, counts, a.offsets, static_cast<std::int64_t>(a.n + 1), s));
    a.temp->reserve(temp_bytes, s);
    CATGS_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(a.temp->data(), temp_bytes, counts, a.offsets,
                                                   static_cast<std::int64_t>(a.n + 1), s));
    if (!a.host_total) return 0;
    CATGS_CUDA_CHECK(cudaMemcpyAsync(a.host_total, a.offsets + a.n, sizeof(std::uint64_t), cudaMemcpyDeviceToHost, s));
    CATGS_CUDA_CHECK(cudaStreamSynchronize(s));
    return *a.host_total;
}

}  // namespace catgs::cuda
